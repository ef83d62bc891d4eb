"""F1 (Filippov oscillator switching at the unit circle): observed orders of FESD for
s = 1..4 against the closed form, beside the time-stepping baseline (order 1).

    /usr/bin/python3 examples/python/f1_order_study.py
"""
import math

import numpy as np

import moreau

scene = moreau.scene("F1")
# Closed form: x = e^(t-1) (cos wt, sin wt) inside the unit circle until the switch at t = 1,
# then e^(t-1) (cos w(t-1), -sin w(t-1)); w = 2 pi; tf = pi/2.
w, tf = 2 * math.pi, scene.tf
reference = math.exp(tf - 1) * np.array([math.cos(w * (tf - 1)), -math.sin(w * (tf - 1))])


def error(integrator, stages, h):
    r = moreau.simulate(scene, integrator=integrator, stages=stages, h=h, newton_tol=1e-14)
    return float(np.max(np.abs(r.final_state - reference)))


for integrator, stage_list in (("fesd", (1, 2, 3, 4)), ("timestepping", (1, 2, 3))):
    for s in stage_list:
        # Step sizes in each method's asymptotic range above round-off (docs/report).
        steps = [{1: 0.008, 2: 0.1, 3: 0.1, 4: 0.24}[s] / 2 ** k for k in range(3)]
        if integrator == "timestepping":
            # Off the switch time t = 1: a grid point exactly on it would hide the baseline's
            # O(h) switch-time error.
            steps = [0.049 / 2 ** k for k in range(5)] if s > 1 else [0.0033 / 2 ** k
                                                                       for k in range(5)]
        errors = [error(integrator, s, h) for h in steps]
        # Least-squares slope of log(error) over log(h).
        slope = np.polyfit(np.log(steps), np.log(errors), 1)[0]
        theory = f"2s-1 = {2 * s - 1}" if integrator == "fesd" else "about 1 across switches"
        print(f"{integrator:12s} s={s}: errors " + ", ".join(f"{e:.2e}" for e in errors)
              + f"; observed order {slope:.2f} (theory: {theory})")
