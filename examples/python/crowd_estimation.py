"""Parameter estimation on the crowd with adjoint gradients (docs/sensitivities.md,
"Demonstrations"): recover the desired speed s and the smoothing length eps of the crowd's
desired velocity U(q) = s (e - q) / sqrt(|e - q|^2 + eps^2) from noisy final positions, by
L-BFGS (SciPy) on

    J(s, eps) = 1/2 sum_i |q_i(T; s, eps) - data_i|^2,

each gradient one FESD run that keeps its adjoint and one reverse sweep (keep_adjoint,
Result.adjoint), whatever the number of agents. The data: the run at the true values
(s, eps) = (1.0, 4.0) plus Gaussian noise of standard deviation 0.01 (seeded). The exit point
sits at the door (exit_distance = 0), where eps shapes the agents' speeds.

    /usr/bin/python3 examples/python/crowd_estimation.py [--agents 1000] [--tf 2]

Prints the iterations, the estimate against the truth, and the times.
"""
import argparse
import time

import numpy as np
from scipy.optimize import minimize

import moreau

TRUE = {"speed": 1.0, "smoothing": 4.0}
START = {"speed": 0.7, "smoothing": 2.5}
NOISE = 0.01


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=1000)
    parser.add_argument("--tf", type=float, default=2.0)
    parser.add_argument("--h", type=float, default=0.1)
    args = parser.parse_args()
    scene = moreau.scene(f"crowd:N={args.agents},exit_distance=0,tf={args.tf}")
    names = list(scene.parameters)
    columns = [len(scene.state_names) + names.index(p) for p in ("speed", "smoothing")]
    run = moreau.Integrator(scene, "fesd", stages=2, h=args.h, keep_adjoint=True)
    rng = np.random.default_rng(2026)
    truth = run.simulate(parameters=TRUE)
    if not truth.success:
        raise SystemExit(truth.message)
    data = truth.final_state + NOISE * rng.standard_normal(truth.final_state.shape)
    evaluations = []
    start = time.process_time()

    def objective(z):
        result = run.simulate(parameters={"speed": z[0], "smoothing": z[1]})
        if not result.success:
            raise RuntimeError(result.message)
        residual = result.final_state - data
        gradient = result.adjoint(residual)[0, columns]  # dJ/d(s, eps)
        evaluations.append(z.copy())
        print(f"    s = {z[0]:.6f}, eps = {z[1]:.6f}: J = {0.5 * residual @ residual:.6e}", flush=True)
        return 0.5 * residual @ residual, gradient

    solution = minimize(objective, [START["speed"], START["smoothing"]], jac=True,
                        method="L-BFGS-B", bounds=[(0.5, 2.0), (1.0, 10.0)],
                        options={"gtol": 1e-10, "ftol": 1e-14, "maxiter": 100})
    seconds = time.process_time() - start
    s, eps = solution.x
    print(f"crowd of {args.agents} agents, tf = {args.tf}: {solution.nit} L-BFGS iterations, "
          f"{len(evaluations)} runs with gradients, {seconds:.1f} s CPU "
          f"({seconds / len(evaluations):.2f} s per run and sweep)")
    print(f"  estimate s = {s:.6f} (true {TRUE['speed']}), eps = {eps:.6f} "
          f"(true {TRUE['smoothing']}); J = {solution.fun:.6e}; {solution.message}")
    # The noise moves the least-squares estimate by about its standard deviation over the
    # square root of the data's information; both parameters must come back to 1 %.
    if abs(s - TRUE["speed"]) > 0.01 * TRUE["speed"] or \
            abs(eps - TRUE["smoothing"]) > 0.01 * TRUE["smoothing"]:
        raise SystemExit("the estimate did not recover the true parameters")


if __name__ == "__main__":
    main()
