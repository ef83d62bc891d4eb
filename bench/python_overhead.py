"""Python calling overhead: the 1-element FESD run of bench/simulate_bench.cpp (S3, tf = h =
0.05, N_fe = 1) from Python, median microseconds per call over repeated timing loops.
Run by scripts/bench-python next to the C++ benchmark; prints one JSON object."""

import json
import statistics
import sys
import time

import moreau


def main(repeats: int = 15, calls: int = 2000) -> None:
    scene = moreau.scene("S3").set(tf=0.05)
    integrator = moreau.Integrator(scene, "fesd", h=0.05, fe=1)
    cases = {
        "simulate": lambda: moreau.simulate(scene, integrator="fesd", h=0.05, fe=1),
        "integrator_object": integrator.simulate,
        "simulate_and_final_state": lambda: moreau.simulate(scene, integrator="fesd", h=0.05,
                                                            fe=1).final_state,
    }
    for run in cases.values():
        assert run() is not None
    out = {}
    for name, run in cases.items():
        samples = []
        for _ in range(repeats):
            start = time.perf_counter()
            for _ in range(calls):
                run()
            samples.append((time.perf_counter() - start) / calls * 1e6)
        out[name + "_us"] = statistics.median(samples)
    json.dump(out, sys.stdout)
    print()


if __name__ == "__main__":
    main()
