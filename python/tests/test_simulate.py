"""The Python front end against the command line and the C++ library: same entry point
(moreau::Simulate), so the same numbers bit for bit; sensitivities against central
differences of Python-level runs; bad input raises ValueError naming the problem."""

import math

import numpy as np
import pytest

import moreau

# (scene, integrator, options) with the settings the command line gets as flags.
SAME_SETTINGS = [
    ("S3", "fesd", {"stages": 3, "h": 0.05}),
    ("F1", "fesd", {"stages": 2, "h": 0.1, "fe": 3}),
    ("H1", "fesd", {"stages": 3, "h": 0.1}),
    ("D2", "alpha", {"h": 0.1, "rho": 0.5}),
    ("S3", "ida", {"rtol": 1e-8, "atol": 1e-10}),
    ("F1", "fesd", {"rtol": 1e-8, "atol": 1e-10}),
]


def _flags(options):
    flags = []
    for name, value in options.items():
        flags += ["--" + name.replace("_", "-"), repr(value) if isinstance(value, float)
                  else str(value)]
    return flags


@pytest.mark.parametrize("name,integrator,options", SAME_SETTINGS)
def test_python_equals_cli_summary_bit_for_bit(cli, tmp_path, name, integrator, options):
    summary = cli(["run", name, "--integrator", integrator, *_flags(options)], tmp_path)
    result = moreau.simulate(moreau.scene(name), integrator=integrator, **options)
    assert result.status == summary["status"] == "success"
    assert result.final_time == summary["t_final"]  # exact: JSON keeps 17 digits
    for i, state in enumerate(result.state_names):
        assert result.final_state[i] == summary["x_final"][state], state
    assert [(e.t, e.kind, e.what) for e in result.events] == [
        (e["t"], e["kind"], e["what"]) for e in summary["events"]]
    for stat, value in result.stats.items():
        if stat != "cpu_seconds":
            assert value == summary["stats"][stat], stat
    # Timing (not comparable between runs): the run's CPU time and the call's elapsed time.
    assert result.cpu_seconds > 0 and result.wall_seconds > 0 and summary["wall_seconds"] > 0
    for option, value in result.options.items():
        if option != "record_stages":  # the command line records FESD's stages
            expected = summary["options"][option]
            assert value == expected or (value == math.inf and expected == "inf"), option
    # The trajectory's last point is the final state.
    np.testing.assert_array_equal(result.x[-1], result.final_state)
    assert result.t[-1] == result.final_time


def test_integrator_object_reuses_settings_and_matches_simulate():
    scene = moreau.scene("S3")
    integrator = moreau.Integrator(scene, "fesd", stages=3, h=0.1)
    first = integrator.simulate()
    again = integrator.simulate()
    direct = moreau.simulate(scene, integrator="fesd", stages=3, h=0.1)
    np.testing.assert_array_equal(first.x, again.x)
    np.testing.assert_array_equal(first.x, direct.x)
    moved = integrator.simulate(x0=[-0.5, 1.5])
    expected = moreau.simulate(scene.copy().set(**{"x0.x1": -0.5, "x0.x2": 1.5}),
                               integrator="fesd", stages=3, h=0.1)
    np.testing.assert_array_equal(moved.final_state, expected.final_state)


# Central differences of runs whose discrete solution map is smooth at the point: relative
# step 1e-6 gives truncation O(1e-12) and round-off O(1e-16/1e-6) = 1e-10 relative, well inside
# the issue's 1e-6 (the integrators' Newton tolerance is 1e-12 on O(1) residuals).
SENSITIVITY_STEP = 1e-6
SENSITIVITY_TOLERANCE = 1e-6


# Steps that keep every switch away from a step boundary (F1 switches at t = 1 + 2e-6: with
# h = 0.1 a perturbation of 1e-6 moves it across the boundary at t = 1, where the discrete map
# has a kink; tests/integrators/fesd_test.cpp covers that case with the saltation matrix).
@pytest.mark.parametrize("name,integrator,h", [("F1", "fesd", 0.049), ("S3", "fesd", 0.05)])
def test_sensitivities_match_central_differences(name, integrator, h):
    scene = moreau.scene(name)
    options = {"stages": 3, "h": h}
    result = moreau.simulate(scene, integrator=integrator, sensitivities=True, **options)
    assert result.success
    sens = result.sensitivities
    n = len(scene.state_names)
    assert sens.dx_dx0.shape == (n, n)
    run = moreau.Integrator(scene, integrator, **options)
    x0 = scene.x0
    for j in range(n):
        step = SENSITIVITY_STEP * max(1.0, abs(x0[j]))
        up, down = x0.copy(), x0.copy()
        up[j] += step
        down[j] -= step
        column = (run.simulate(x0=up).final_state - run.simulate(x0=down).final_state) / (2 * step)
        scale = max(1.0, np.max(np.abs(sens.dx_dx0[:, j])))
        np.testing.assert_allclose(sens.dx_dx0[:, j], column, rtol=0,
                                   atol=SENSITIVITY_TOLERANCE * scale, err_msg=f"column {j}")
    for j, (pname, value) in enumerate(scene.parameters.items()):
        step = SENSITIVITY_STEP * max(1.0, abs(value))
        up = run.simulate(parameters={pname: value + step}).final_state
        down = run.simulate(parameters={pname: value - step}).final_state
        column = (up - down) / (2 * step)
        scale = max(1.0, np.max(np.abs(sens.dx_dp[:, j])))
        np.testing.assert_allclose(sens.dx_dp[:, j], column, rtol=0,
                                   atol=SENSITIVITY_TOLERANCE * scale, err_msg=pname)


def test_fesd_adaptive_steps_and_their_replay():
    """rtol switches FESD's adaptive steps on; the accepted steps replay bit for bit."""
    f1 = moreau.scene("F1")
    run = moreau.simulate(f1, integrator="fesd", rtol=1e-8, atol=1e-10)
    assert run.success, run.message
    assert run.options["adaptive"]
    assert len(run.step_sequence) == run.stats["num_steps"]
    exact = np.array([-1.5974603774506984, 0.7614936206060108])  # F1's closed form
    scale = 1.7  # max |x| over F1's solution (the tolerance bound of issue 16)
    assert np.max(np.abs(run.x[-1] - exact)) <= 10 * 1e-8 * scale
    replay = moreau.simulate(f1, integrator="fesd", step_sequence=run.step_sequence)
    assert replay.success, replay.message
    assert np.array_equal(replay.x[-1], run.x[-1])
    assert replay.step_sequence == run.step_sequence


def test_numerical_failure_is_a_status_not_an_exception():
    # FESD s = 3 with H = 0.1 on the stiff set: the documented event-location failure at t = 0
    # (README, hard cases).
    result = moreau.simulate(moreau.scene("hard_stiff_set"), integrator="fesd", stages=3, h=0.1)
    assert not result.success
    assert result.status == "event_location_failure"
    assert "t = 0" in result.message or "t=0" in result.message or result.message


def test_progress_callback_is_called_and_its_exception_propagates():
    times = []
    moreau.simulate(moreau.scene("hopf"), integrator="radau", h=1e-4,
                    progress=times.append)
    assert times and all(b >= a for a, b in zip(times, times[1:]))

    def fail(t):
        raise KeyError("stop")

    with pytest.raises(KeyError):
        moreau.simulate(moreau.scene("hopf"), integrator="radau", h=1e-4, progress=fail)


def test_listing_functions():
    names = moreau.scenes()
    assert "S3" in names and "H1" in names
    specs = {spec["name"]: spec for spec in moreau.integrators()}
    assert set(specs) == {"radau", "timestepping", "fesd", "ida", "alpha"}
    fesd = {o["name"]: o for o in specs["fesd"]["options"]}
    assert fesd["stages"]["default"] == 3 and fesd["stages"]["type"] == "integer"
    assert moreau.scene("S3").integrators() == ["timestepping", "fesd", "ida"]


# --- bad input: one test per class, each a ValueError naming the problem -------------------


def test_bad_input_unknown_keyword_is_named():
    with pytest.raises(ValueError, match="unknown option 'stage' for integrator 'fesd'; "
                                         "did you mean 'stages'"):
        moreau.simulate(moreau.scene("S3"), integrator="fesd", stage=3)
    with pytest.raises(ValueError, match="option 'h' does not apply to integrator 'ida'"):
        moreau.simulate(moreau.scene("S3"), integrator="ida", h=0.1)
    with pytest.raises(ValueError, match="unknown integrator 'fsed'"):
        moreau.simulate(moreau.scene("S3"), integrator="fsed")
    with pytest.raises(ValueError, match="unknown scene 'S33'"):
        moreau.scene("S33")
    with pytest.raises(ValueError, match="has no value named 'radius'"):
        moreau.scene("S3").set(radius=1.0)


def test_bad_input_wrong_types():
    s3 = moreau.scene("S3")
    with pytest.raises(ValueError, match="option 'stages' expects an integer"):
        moreau.simulate(s3, integrator="fesd", stages="three")
    # Strings are never parsed as numbers or bools (the command line's text is).
    with pytest.raises(ValueError, match="option 'h' expects a number, got the string '0.1'"):
        moreau.simulate(s3, integrator="fesd", h="0.1")
    with pytest.raises(ValueError, match="option 'sensitivities' expects True or False"):
        moreau.simulate(s3, integrator="fesd", sensitivities="no")
    with pytest.raises(ValueError, match="expected a number"):
        moreau.simulate(s3, integrator="fesd", h=[0.1])
    with pytest.raises(ValueError, match="expected one of stewart, heaviside"):
        moreau.simulate(s3, integrator="fesd", switching=1)
    with pytest.raises(ValueError, match="expected a number, bool, string or list"):
        moreau.simulate(s3, integrator="fesd", h={"a": 1})
    with pytest.raises(ValueError, match="must be a moreau.Scene"):
        moreau.simulate("S3")
    with pytest.raises(ValueError, match="must be a number"):
        s3.set(floor="low")
    with pytest.raises(ValueError, match="progress must be callable"):
        moreau.simulate(s3, progress=3)


def test_bad_input_wrong_array_shapes():
    run = moreau.Integrator(moreau.scene("S3"), "fesd")
    with pytest.raises(ValueError, match=r"x0 must have shape \(2,\)"):
        run.simulate(x0=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match=r"x0 must have shape \(2,\)"):
        run.simulate(x0=np.zeros((2, 1)))


def test_bad_input_nan_and_out_of_range():
    s3 = moreau.scene("S3")
    with pytest.raises(ValueError, match="must be finite"):
        s3.set(floor=float("nan"))
    with pytest.raises(ValueError, match="must be finite"):
        moreau.Integrator(s3, "fesd").simulate(x0=[np.nan, 0.0])
    with pytest.raises(ValueError, match="step size h must be positive"):
        moreau.simulate(s3, integrator="fesd", h=float("nan"))
    with pytest.raises(ValueError, match="stages must be in"):
        moreau.simulate(s3, integrator="fesd", stages=9)
    with pytest.raises(ValueError, match="does not support the moving set 'floor'"):
        moreau.simulate(s3, integrator="radau")


# --- fixed steps estimate their error; a warning far above the tolerance ------------------


def test_fixed_step_error_estimate_and_warning():
    hopf = moreau.scene("hopf")
    with pytest.warns(moreau.SimulationWarning, match="estimated error of this fixed-step run"):
        coarse = moreau.simulate(hopf, integrator="radau", h=0.5, stages=1)
    assert coarse.success
    # kErrorWarningFactor (10) times the default rtol (1e-6), docs/accuracy.md
    assert coarse.error_estimate > 1e-5
    assert len(coarse.warnings) == 1
    fine = moreau.simulate(hopf, integrator="radau", h=0.002)
    assert fine.error_estimate is not None and fine.error_estimate <= 1e-5
    assert fine.warnings == []
    # IDA has no estimate of its own.
    assert moreau.simulate(moreau.scene("S3"), integrator="ida").error_estimate is None


def test_cli_summary_carries_the_estimate_and_the_warning(cli, tmp_path):
    summary = cli(["run", "hopf", "--integrator", "radau", "--h", "0.5", "--stages", "1"],
                  tmp_path)
    assert summary["error_estimate"] > 1e-5
    assert len(summary["warnings"]) == 1
    assert "estimated error of this fixed-step run" in summary["warnings"][0]
