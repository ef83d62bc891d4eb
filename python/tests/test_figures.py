"""Figures and animations from Python: Result.plot() built from the scene (no internal variable
of the lowering unless asked for, the S3 floor drawn at x2 = -1 in the phase portrait, checked
on the saved PNG), Result.animate() on a small crowd, and plot_sweep() with points per run."""

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.image  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import moreau  # noqa: E402

# Internal variables of the lowering (Filippov and time-freezing): never in a default figure.
INTERNAL = ("theta", "lambda_mode", "lambda_to", ".mu", "algebraic")


def figure_texts(fig):
    texts = [t.get_text() for t in fig.findobj(matplotlib.text.Text)]
    texts += [line.get_label() for line in fig.findobj(matplotlib.lines.Line2D)]
    return texts


def test_h1_figure_has_no_internal_variable(tmp_path):
    result = moreau.simulate(moreau.scene("H1"))
    assert any("theta" in name for name in result.algebraic_names)  # they exist ...
    fig = result.plot()
    path = tmp_path / "h1.png"
    fig.savefig(path)
    assert matplotlib.image.imread(path).shape[0] > 100
    texts = figure_texts(fig)
    for internal in INTERNAL:
        assert not any(internal in text for text in texts), (internal, texts)
    assert "temperature (x) [°C]" in texts  # ... and the figure shows the state with its unit
    assert "thermostat: w = 1" in texts     # ... and the relay memory as a band
    plt.close(fig)
    internal_fig = result.plot(internal=True)
    assert any("theta_mode_A" in text for text in figure_texts(internal_fig))
    plt.close(internal_fig)


def test_s3_phase_portrait_has_the_floor_at_minus_one(tmp_path):
    result = moreau.simulate(moreau.scene("S3"))
    fig = result.plot()
    phase = [a for a in fig.axes if a.get_title() == "phase portrait"]
    assert len(phase) == 1
    ax = phase[0]
    path = tmp_path / "s3.png"
    fig.savefig(path, dpi=fig.dpi)
    image = matplotlib.image.imread(path)
    height = image.shape[0]
    red = np.array([0xD6, 0x27, 0x28]) / 255.0

    def is_red(column, row):
        # The contour line is 1.6 pt wide: look 2 px around the expected row.
        for r in range(row - 2, row + 3):
            if np.abs(image[r, column, :3] - red).max() < 0.08:
                return True
        return False

    checked = 0
    for x1 in np.linspace(ax.get_xlim()[0] + 0.05, -0.45, 8):
        column, row = ax.transData.transform((x1, -1.0))
        assert is_red(int(column), int(round(height - row))), f"no floor at x1 = {x1}"
        _, row_above = ax.transData.transform((x1, -0.7))
        assert not is_red(int(column), int(round(height - row_above)))
        checked += 1
    assert checked == 8
    # Time axes end at tf.
    assert fig.axes[0].get_xlim()[1] == pytest.approx(result.final_time)
    plt.close(fig)


def test_multiplier_jumps_are_steps():
    result = moreau.simulate(moreau.scene("S3"))
    fig = result.plot()
    lines = [line for a in fig.axes for line in a.get_lines()
             if line.get_label() == "floor.lambda_c"]
    assert len(lines) == 1
    assert lines[0].get_drawstyle() == "steps-pre"
    plt.close(fig)


def test_animate_a_small_crowd(tmp_path):
    scene = moreau.scene("crowd:N=4,tf=2")
    result = moreau.simulate(scene)
    frames = tmp_path / "frames"
    files = result.animate(str(tmp_path / "crowd.gif"), fps=4, duration=1, width=160,
                           gif_width=80, frames=str(frames), snapshots=str(tmp_path / "snap"))
    assert str(tmp_path / "crowd.gif") in files
    assert os.path.getsize(tmp_path / "crowd.gif") > 100
    assert len(list(frames.glob("frame_*.png"))) == 5
    with pytest.raises(ValueError, match="declares no bodies"):
        moreau.simulate(moreau.scene("F1")).animate(str(tmp_path / "f1.mp4"))
    with pytest.raises(ValueError, match="must end in .mp4 or .gif"):
        result.animate(str(tmp_path / "crowd.avi"))


def test_plot_sweep_points_per_run_and_constant_columns():
    # The floor below -2 is never reached: the final state is the same in every run.
    table = moreau.sweep(moreau.scene("S3"), grid={"floor": (-3.0, -2.5, 6)})
    figures = moreau.plot_sweep(table)
    assert list(figures) == ["floor"]
    fig = figures["floor"]
    titles = [a.get_title() for a in fig.axes]
    assert any(t.startswith("x.x1 (constant:") for t in titles), titles
    for a in fig.axes:
        for line in a.get_lines():  # points, never lines joining runs
            assert len(line.get_xdata()) == 0
        for collection in a.collections:
            # One point per run at its varied value (rows without a value are masked).
            offsets = np.ma.getdata(collection.get_offsets())
            if len(offsets):
                assert np.allclose(np.sort(offsets[:, 0]), np.sort(table["floor"]))
    plt.close(fig)


def test_recorded_stages_draw_the_collocation_polynomials():
    # With the stages recorded (as `moreau run` does), the states are drawn along FESD's
    # collocation polynomials: S3's 17 error-controlled elements as a polygon are 1.9e-2 off
    # the closed form between the steps, the drawn curve 1.3e-5 (O(h^(s+1)) between the
    # nodes). The multiplier lambda = x1 on the floor is drawn as a line, falling to 0.
    result = moreau.simulate(moreau.scene("S3"), record_stages=True)
    fig = result.plot()
    t1, t2 = 5 * np.pi / 12, 5 * np.pi / 12 + np.sqrt(3.0)

    def exact(t):
        if t <= t1:
            return np.array([2 * np.cos(np.pi / 4 - t), 2 * np.sin(np.pi / 4 - t)])
        if t <= t2:
            return np.array([np.sqrt(3.0) - (t - t1), -1.0])
        return np.array([-np.sin(t - t2), -np.cos(t - t2)])

    tolerance = 1e-4  # a hundredth of a pixel of the state panel
    lines = {line.get_label(): line for line in fig.axes[0].get_lines()}
    for index, name in enumerate(("x1", "x2")):
        t, x = lines[name].get_data()
        assert len(t) >= 10 * len(result.t)
        error = max(abs(x[k] - exact(t[k])[index]) for k in range(len(t)))
        assert error <= tolerance, (name, error)
    (multiplier,) = [line for a in fig.axes for line in a.get_lines()
                     if line.get_label() == "floor.lambda_c"]
    assert multiplier.get_drawstyle() == "default"
    t, lam = multiplier.get_data()
    on_floor = (t > t1 + 1e-5) & (t < t2 - 1e-5)
    assert on_floor.sum() > 5
    assert np.abs(lam[on_floor] - np.array([exact(tk)[0] for tk in t[on_floor]])).max() <= tolerance
    plt.close(fig)
