"""Single shooting on the Stewart-Anitescu problem with exact FESD sensitivities and SciPy:

    min over x0 of  int_0^2 x^2 dt + (x(2) - 5/3)^2,   x' in 2 - sign(x),

whose optimum x0* = (9 - sqrt(417))/8 lies before the switch (docs/ocp.md derives it). The
running cost is a quadrature state q' = x^2; the scene is built from a Python dict with the
scene-file expression language. dJ/dx0 = dq(T)/dx0 + 2 (x(T) - 5/3) dx(T)/dx0 comes from
result.sensitivities (exact derivatives of the discrete solution map, switch time included).

    /usr/bin/python3 examples/python/shooting_stewart_anitescu.py
"""
import math

import numpy as np
from scipy.optimize import minimize

import moreau

scene = moreau.scene_from_dict(
    name="stewart_anitescu",
    states=["x", "q"],
    x0=[-1.0, 0.0],
    tf=2.0,
    dynamics=["0", "x^2"],                 # q' = x^2: the running cost
    effects=[{"kind": "switching", "name": "sign", "surfaces": ["x"],
              "below": [["3", "0"]],       # x' = 3 where x < 0
              "above": [["1", "0"]]}],     # x' = 1 where x > 0
)
run = moreau.Integrator(scene, "fesd", stages=3, h=0.05, sensitivities=True)
calls = []


def cost_and_gradient(z):
    result = run.simulate(x0=[z[0], 0.0])
    if not result.success:
        raise RuntimeError(result.message)
    x_t, q_t = result.final_state
    d = result.sensitivities.dx_dx0[:, 0]        # d(x(T), q(T)) / d x0
    cost = q_t + (x_t - 5 / 3) ** 2
    gradient = d[1] + 2 * (x_t - 5 / 3) * d[0]
    calls.append(cost)
    return cost, np.array([gradient])


solution = minimize(cost_and_gradient, x0=[-1.0], jac=True, method="L-BFGS-B",
                    bounds=[(-5.0, 5.0)], options={"gtol": 1e-12, "ftol": 1e-15})
exact = (9 - math.sqrt(417)) / 8
print(f"x0* = {solution.x[0]:.12f} (closed form {exact:.12f}, error "
      f"{abs(solution.x[0] - exact):.1e}); J = {solution.fun:.12f}; {len(calls)} simulations; "
      f"{solution.message}")
