"""Directional and adjoint sensitivities from Python (NumPy in, NumPy out;
docs/sensitivities.md): against the full matrices, through moreau.simulate and
moreau.Integrator, with kept reverse sweeps and bad input."""
import numpy as np
import pytest

import moreau

# The same implicit-function-theorem solves, chained in another order: round-off only.
PRODUCT_TOLERANCE = 1e-10


def _relative(value, expected):
    return np.abs(value - expected).max() / max(1.0, np.abs(expected).max())


def _full(sensitivities):
    return np.hstack([sensitivities.dx_dx0, sensitivities.dx_dp, sensitivities.dx_du])


@pytest.mark.parametrize("name", ["F1", "S3", "H1"])
def test_directions_and_weights_as_arrays(name):
    scene = moreau.scene(name)
    rng = np.random.default_rng(3)
    full = _full(moreau.simulate(scene, "fesd", h=0.05, sensitivities=True).sensitivities)
    n_x, n_theta = full.shape
    v = rng.standard_normal((n_theta, 4))
    w = rng.standard_normal((n_x, 2))
    result = moreau.simulate(scene, "fesd", h=0.05, directions=v, adjoint_weights=w)
    assert result.success, result.message
    s = result.sensitivities
    assert s.directional.shape == (n_x, 4)
    assert s.adjoint.shape == (2, n_theta)
    assert s.dx_dx0.size == 0  # full matrices only with sensitivities=True
    assert _relative(s.directional, full @ v) <= PRODUCT_TOLERANCE
    assert _relative(s.adjoint, w.T @ full) <= PRODUCT_TOLERANCE
    assert result.stats["adjoint_memory_bytes"] > 0


def test_gradient_of_a_scalar_objective_with_a_kept_sweep():
    """f = |x(T) - target|^2 + |x(1) - target|^2 on F1 through moreau.Integrator: one run with
    keep_adjoint, then result.adjoint with the partial derivatives of f."""
    scene = moreau.scene("F1")
    target = np.array([0.5, -0.2])
    run = moreau.Integrator(scene, "fesd", h=0.05, keep_adjoint=True, sample_times=[1.0])
    result = run.simulate(x0=[0.35, 0.02])
    assert result.sample_states.shape == (1, 2)
    gradient = result.adjoint(2 * (result.final_state - target),
                              2 * (result.sample_states - target))
    assert gradient.shape == (1, 3)  # (x1, x2, omega)
    full_run = moreau.Integrator(scene, "fesd", h=0.05, sensitivities=True)
    scene_at_one = scene.copy().set(tf=1.0)
    sample_run = moreau.Integrator(scene_at_one, "fesd", h=0.05, sensitivities=True)
    full = _full(full_run.simulate(x0=[0.35, 0.02]).sensitivities)
    at_one = sample_run.simulate(x0=[0.35, 0.02])
    expected = (2 * (result.final_state - target) @ full
                + 2 * (at_one.final_state - target) @ _full(at_one.sensitivities))
    assert _relative(gradient[0], expected) <= PRODUCT_TOLERANCE


def test_time_stepping_sample_times_and_kept_sweep():
    """Time-stepping keeps its step transfers (keep_adjoint) and samples the state at step ends
    (a sample time becomes a stop time): the gradient of f = |x(T) - target|^2 +
    |x(t1) - target|^2 from one kept sweep equals the products with the full matrices of the
    runs stopped at T and at t1 on the same grid."""
    scene = moreau.scene("F1")
    target = np.array([0.5, -0.2])
    t1 = 0.77  # not a multiple of h: a step ends there
    run = moreau.Integrator(scene, "timestepping", h=0.05, keep_adjoint=True, sample_times=[t1])
    result = run.simulate(x0=[0.35, 0.02])
    assert result.success, result.message
    assert result.sample_states.shape == (1, 2)
    gradient = result.adjoint(2 * (result.final_state - target),
                              2 * (result.sample_states - target))
    assert gradient.shape == (1, 3)  # (x1, x2, omega)
    full = moreau.Integrator(scene, "timestepping", h=0.05, tstops=[t1],
                             sensitivities=True).simulate(x0=[0.35, 0.02])
    at_t1 = moreau.Integrator(scene.copy().set(tf=t1), "timestepping", h=0.05,
                              sensitivities=True).simulate(x0=[0.35, 0.02])
    assert np.array_equal(result.sample_states[0], at_t1.final_state)
    expected = (2 * (result.final_state - target) @ _full(full.sensitivities)
                + 2 * (at_t1.final_state - target) @ _full(at_t1.sensitivities))
    assert _relative(gradient[0], expected) <= PRODUCT_TOLERANCE


def test_bad_input_raises_value_error():
    scene = moreau.scene("F1")
    with pytest.raises(ValueError, match="sensitivity directions"):
        moreau.simulate(scene, "fesd", h=0.05, directions=np.ones((5, 2)))
    with pytest.raises(ValueError, match="sample time"):
        moreau.simulate(scene, "fesd", h=0.05, keep_adjoint=True, sample_times=[0.33])
    result = moreau.simulate(scene, "fesd", h=0.05)
    with pytest.raises(ValueError, match="keep_adjoint"):
        result.adjoint([1.0, 0.0])
    kept = moreau.simulate(scene, "fesd", h=0.05, keep_adjoint=True)
    with pytest.raises(ValueError, match="adjoint weights"):
        kept.adjoint(np.ones(5))  # n_x = 2, n_y = 3: 5 weights fit neither
