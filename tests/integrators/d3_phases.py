#!/usr/bin/python3
"""Independent reference for the built-in scene D3 (re-entry with a heat-flux limit) under the
alpha stepper's default objective (the angle of attack follows w = 0.35 wherever no active
constraint needs it), solved phase by phase with scipy (not the stepper):

  1. alpha = w until the heat flux C_H sqrt(rho) V^3.05 reaches heat_max (t1);
  2. on the limit, alpha = max(w, alpha*(x)), alpha* the value with d/dt heat flux = 0
     (explicit: V'/V = h'/(6.1 H) fixes the drag, hence C_D and alpha), until alpha* falls to
     w (t2, where the constraint's multiplier vanishes and it lets go);
  3. alpha = w to T = 200 (the heat flux does not return; the other constraints stay inactive,
     checked along phase 2).

Each phase by DOP853 at rtol = atol = 1e-13 with event location. Prints t1, t2, x(T) and the
offset sqrt(2 tol / |phi''(t2)|) after t2 at which phi falls below -tol (tol = 1e-8, the
stepper's activity tolerance: where its working set drops the constraint). The numbers are in
tests/integrators/alpha_dai_test.cpp (AlphaDaiErrorControlTest.D3HeatFluxArcMatchesThePhases).

Run: /usr/bin/python3 tests/integrators/d3_phases.py
"""
import numpy as np
from scipy.integrate import solve_ivp

# The scene's parameters (examples/scenes/dai.cpp, MakeD3).
RHO0, H, RE, G0, MASS, S = 1.225, 7.2, 6371.0, 9.80665, 1750.0, 6.4
CL_ALPHA, CD0, K, C_H, HEAT_MAX, Q_MAX, N_MAX, ALPHA_MAX = 1.2, 0.05, 1.0, 1.8e-8, 18.5, 25.0, 5.0, 0.7
W = 0.35  # nominal angle of attack
X0, TF = [70.0, 2.0, -0.05], 200.0
ACTIVITY_TOLERANCE = 1e-8
TOL = dict(rtol=1e-13, atol=1e-13, method="DOP853")


def aero(x, alpha):
    density = RHO0 * np.exp(-x[0] / H)
    speed = 1000.0 * x[1]
    cl = CL_ALPHA * alpha
    pressure = 0.5 * density * speed * speed
    return density, speed, pressure * S * cl / MASS, pressure * S * (CD0 + K * cl * cl) / MASS


def gravity(x):
    return 1e-3 * G0 * (RE / (RE + x[0])) ** 2


def f(x, alpha):
    _, speed, lift, drag = aero(x, alpha)
    r = RE + x[0]
    g = gravity(x)
    return np.array([x[1] * np.sin(x[2]), -1e-3 * drag - g * np.sin(x[2]),
                     lift / speed + np.cos(x[2]) * (x[1] / r - g / x[1])])


def heat_flux(x):
    return C_H * np.sqrt(RHO0 * np.exp(-x[0] / H)) * (1000.0 * x[1]) ** 3.05 - HEAT_MAX


def alpha_star(x):
    """alpha with d/dt heat flux = 0: -h'/(2H) + 3.05 V'/V = 0."""
    density = RHO0 * np.exp(-x[0] / H)
    pressure = 0.5 * density * (1000.0 * x[1]) ** 2
    h_dot = x[1] * np.sin(x[2])
    v_dot = x[1] * h_dot / (6.1 * H)
    cd = (-v_dot - gravity(x) * np.sin(x[2])) * 1e3 * MASS / (pressure * S)
    return np.sqrt(max(cd - CD0, 0.0) / K) / CL_ALPHA


def main():
    reach = lambda t, x: heat_flux(x)
    reach.terminal, reach.direction = True, 1
    free1 = solve_ivp(lambda t, x: f(x, W), (0.0, TF), X0, events=reach, **TOL)
    t1, x1 = free1.t_events[0][0], free1.y_events[0][0]
    release = lambda t, x: alpha_star(x) - W
    release.terminal, release.direction = True, -1
    arc = solve_ivp(lambda t, x: f(x, max(W, alpha_star(x))), (t1, TF), x1, events=release, **TOL)
    t2, x2 = arc.t_events[0][0], arc.y_events[0][0]
    for x in arc.y.T:
        alpha = max(W, alpha_star(x))
        density, speed, lift, drag = aero(x, alpha)
        assert 0.5e-3 * density * speed ** 2 < Q_MAX
        assert (lift * np.cos(alpha) + drag * np.sin(alpha)) / G0 < N_MAX and alpha < ALPHA_MAX
    free2 = solve_ivp(lambda t, x: f(x, W), (t2, TF), x2, events=reach, **TOL, dense_output=True)
    assert free2.t_events[0].size == 0, "the heat flux returns"
    step = 1e-3
    p0, p1, p2 = (heat_flux(free2.sol(t2 + k * step)) for k in range(3))
    curvature = abs(p2 - 2.0 * p1 + p0) / step ** 2
    print("t1 = %.17g (heat flux reaches its limit)" % t1)
    print("t2 = %.17g (alpha* falls to w: the limit lets go)" % t2)
    print("x(T) = [%.17g, %.17g, %.17g]" % tuple(free2.y[:, -1]))
    print("|phi''(t2)| = %.6g, phi < -%g after t2 + %.6g" %
          (curvature, ACTIVITY_TOLERANCE, np.sqrt(2.0 * ACTIVITY_TOLERANCE / curvature)))


if __name__ == "__main__":
    main()
