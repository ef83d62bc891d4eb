"""Direct multiple shooting of the wave rider in plain Python: SciPy's trust-constr as the NLP solver,
moreau (FESD) as the integrator of every shooting interval with its exact Jacobians
(docs/sensitivities.md, "Demonstrations").

    min  int_0^T u^2 dt   s.t.  x' in (0, u) - N_C(t)(x),  C(t) = {x1 + cos(x2 - t) >= 0},
         |u| <= 1,  x(0) = (0.2163, 1.7888) (the projection of (0, 2) onto C(0)),  x(T) = (1, 4)

with T = 8 and u piecewise constant on N intervals. Unknowns: the controls u_k and the node
states s_1..s_N; constraints s_{k+1} = Phi_k(s_k, u_k) (one FESD run per interval: s = 3
stages, 3 elements, the interval as the step, as `moreau ocp wave_rider` integrates) and
s_N = (1, 4). dPhi_k/ds_k and dPhi_k/du_k are the run's sensitivities (switch times and the
moving boundary included). The terminal constraint x1(T) = 1 is degenerate (x1 <= 1 is the
most the boundary can push), so, as the C++ layer does, two relaxed levels |s_N - (1, 4)| <=
eps (eps = 1e-2, 1e-4) precede the exact problem.

    /usr/bin/python3 examples/python/wave_rider_shooting.py [--intervals N]

Prints the cost, the iterations and the time; `moreau ocp wave_rider` reports 0.336357343835
for N = 10.
"""
import argparse
import math
import time
import warnings

import numpy as np
from scipy.optimize import minimize

import moreau

T = 8.0
TARGET = np.array([1.0, 4.0])
CATALOG_COST = 0.336357343835  # `moreau ocp wave_rider` (docs/ocp.md)


def interval_scene(t0, t1):
    """The wave rider on [t0, t1] with the control u as a parameter (dPhi/du = dx/dp)."""
    return moreau.scene_from_dict(
        name="wave_rider_interval", states=["x1", "x2"],
        # A feasible placeholder start (runs set their own, projected when outside).
        x0=[f"1 - cos(2 - {t0!r}) + 1", "2"], t0=t0, tf=t1,
        dynamics=["0", "u"], parameters={"u": 0.5},
        effects=[{"kind": "moving_set", "name": "wave", "constraints": ["x1 + cos(x2 - t)"]}])


def projected_start():
    """(0, 2) projected onto C(0): the nearest point with x1 + cos(x2) = 0."""
    from scipy.optimize import brentq
    # Stationarity of cos(x2)^2 + (x2 - 2)^2, the squared distance along x1 = -cos(x2).
    x2 = brentq(lambda x2: (x2 - 2.0) - math.cos(x2) * math.sin(x2), 1.0, 2.0)
    return np.array([-math.cos(x2), x2])


class Shooting:
    def __init__(self, intervals):
        self.n = intervals
        self.grid = np.linspace(0.0, T, intervals + 1)
        self.start = projected_start()
        self.runs = [moreau.Integrator(interval_scene(self.grid[k], self.grid[k + 1]), "fesd",
                                       stages=3, fe=3, h=self.grid[k + 1] - self.grid[k],
                                       sensitivities=True, project_initial_state=True,
                                       keep_elements_after_early_switch=True)
                     for k in range(intervals)]
        self.cache_key = None
        self.simulations = 0

    def split(self, z):
        return z[:self.n], z[self.n:].reshape(self.n, 2)  # u_k, s_1..s_N

    def intervals(self, z):
        """Phi_k and its Jacobians at z (cached: SLSQP asks for values and Jacobians apart)."""
        if self.cache_key is not None and np.array_equal(z, self.cache_key):
            return self.cache
        u, nodes = self.split(z)
        starts = np.vstack([self.start, nodes[:-1]])
        ends, d_start, d_u = [], [], []
        for k in range(self.n):
            result = self.runs[k].simulate(x0=starts[k], parameters={"u": u[k]})
            if not result.success:
                raise RuntimeError(f"interval {k} from {starts[k]!r} with u = {u[k]!r}: {result.message}")
            self.simulations += 1
            ends.append(result.final_state)
            d_start.append(result.sensitivities.dx_dx0)
            d_u.append(result.sensitivities.dx_dp[:, 0])
        self.cache_key, self.cache = z.copy(), (np.array(ends), d_start, d_u)
        return self.cache

    def cost(self, z):
        u, _ = self.split(z)
        dt = np.diff(self.grid)
        return float(np.sum(dt * u * u)), np.concatenate([2 * dt * u, np.zeros(2 * self.n)])

    def continuity(self, z):
        """s_{k+1} - Phi_k(s_k, u_k), k = 0..N-1 (2N rows)."""
        _, nodes = self.split(z)
        ends, _, _ = self.intervals(z)
        return (nodes - ends).ravel()

    def continuity_jacobian(self, z):
        _, d_start, d_u = self.intervals(z)
        jac = np.zeros((2 * self.n, 3 * self.n))
        for k in range(self.n):
            rows = slice(2 * k, 2 * k + 2)
            jac[rows, k] = -d_u[k]
            jac[rows, self.n + 2 * k:self.n + 2 * k + 2] = np.eye(2)
            if k > 0:
                jac[rows, self.n + 2 * (k - 1):self.n + 2 * k] = -d_start[k]
        return jac

    def terminal(self, z):
        return self.split(z)[1][-1] - TARGET

    def terminal_jacobian(self, z):
        jac = np.zeros((2, 3 * self.n))
        jac[:, -2:] = np.eye(2)
        return jac

    def initial_guess(self):
        """u = 0.5 (the catalog's start) and the nodes of its forward simulation."""
        u = np.full(self.n, 0.5)
        nodes, s = [], self.start
        for k in range(self.n):
            s = self.runs[k].simulate(x0=s, parameters={"u": u[k]}).final_state
            nodes.append(s)
        return np.concatenate([u, np.ravel(nodes)])

    def solve(self, levels=(1e-2, 1e-4, 0.0)):
        """trust-constr (SciPy's equality-constrained SQP with a trust region, an interior
        point for the bounds and inequalities) through the relaxation levels, each level
        warm-started from the previous one."""
        from scipy.optimize import Bounds, NonlinearConstraint
        z = self.initial_guess()
        iterations = 0
        # Box bounds on the nodes (generous: the optimum's x1 stays in [0, 1], x2 in [1, 5])
        # keep the first steps, taken on a degenerate linearization, where the wave is resolved.
        lower = np.concatenate([-np.ones(self.n), np.tile([-2.0, -2.0], self.n)])
        upper = np.concatenate([np.ones(self.n), np.tile([2.0, 12.0], self.n)])
        continuity = NonlinearConstraint(self.continuity, 0.0, 0.0, jac=self.continuity_jacobian,
                                         hess=lambda z, v: np.zeros((z.size, z.size)))
        for eps in levels:
            terminal = NonlinearConstraint(self.terminal, -eps, eps, jac=self.terminal_jacobian,
                                           hess=lambda z, v: np.zeros((z.size, z.size)))
            solution = minimize(self.cost, z, jac=True, method="trust-constr",
                                hess=lambda z: np.diag(np.concatenate(
                                    [2 * np.diff(self.grid), np.zeros(2 * self.n)])),
                                bounds=Bounds(lower, upper), constraints=[continuity, terminal],
                                options={"maxiter": 500, "xtol": 1e-12, "gtol": 1e-10})
            iterations += solution.nit
            z = solution.x
            print(f"  level eps = {eps:g}: {solution.nit} iterations, cost {solution.fun:.12f}, "
                  f"constraint violation {solution.constr_violation:.1e}, {solution.message}")
        return z, solution, iterations

def main():
    # x1(T) = 1 is a maximum of x1(T): the terminal constraint's gradient vanishes there and
    # trust-constr's projections fall back to an SVD (it says so for every iteration).
    warnings.filterwarnings("ignore", message="Singular Jacobian matrix")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--intervals", type=int, default=10)
    args = parser.parse_args()
    start = time.process_time()
    shooting = Shooting(args.intervals)
    z, solution, iterations = shooting.solve()
    seconds = time.process_time() - start
    u, nodes = shooting.split(z)
    defect = np.abs(shooting.continuity(z)).max()
    print(f"wave rider, N = {args.intervals}: cost {solution.fun:.12f} after {iterations} trust-constr "
          f"iterations, {shooting.simulations} interval simulations, {seconds:.2f} s CPU")
    print(f"  continuity defect {defect:.1e}, x(T) - (1, 4) = {np.abs(nodes[-1] - TARGET).max():.1e}")
    print(f"  controls: {np.array2string(u, precision=4)}")
    if args.intervals == 10:
        print(f"  `moreau ocp wave_rider`: {CATALOG_COST}; difference "
              f"{abs(solution.fun - CATALOG_COST):.1e}")
    if not solution.success or defect > 1e-8:
        raise SystemExit("multiple shooting did not converge")


if __name__ == "__main__":
    main()
