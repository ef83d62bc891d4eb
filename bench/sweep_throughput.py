"""Sweep throughput (opt-in benchmark, run by scripts/bench-sweep): runs per second of
`moreau sweep` on H1 and S3 with 1 and 2 threads, of moreau.sweep on a 2-process Dask
LocalCluster, the parallel efficiency and the Dask overhead per run. Medians of repeats,
all in one run; prints a markdown table."""

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

import moreau

REPEATS = 5
CASES = {
    # H1: Monte Carlo over heater power and heat-loss rate (FESD s = 3, h = 0.2).
    "H1": {"cli": ["--sample", "heat=normal:5:0.4", "--sample", "decay=uniform:0.15:0.25",
                   "--samples", "400", "--seed", "1", "--integrator", "fesd", "--h", "0.2"],
           "py": dict(samples={"heat": ("normal", 5.0, 0.4), "decay": ("uniform", 0.15, 0.25)},
                      n_samples=400, seed=1, integrator="fesd", h=0.2)},
    # S3: a 40 x 40 grid of initial states (FESD s = 3, h = 0.1).
    "S3": {"cli": ["--grid", "x0.x1=1:2:40", "--grid", "x0.x2=0.5:1.5:40", "--integrator",
                   "fesd"],
           "py": dict(grid={"x0.x1": (1.0, 2.0, 40), "x0.x2": (0.5, 1.5, 40)},
                      integrator="fesd")},
}


def cli_rate(cli, scene, arguments, jobs):
    rates = []
    with tempfile.TemporaryDirectory() as out:
        for _ in range(REPEATS):
            subprocess.run([cli, "sweep", scene, *arguments, "--jobs", str(jobs), "--quiet",
                            "--no-plot", "--out", out], check=False, capture_output=True)
            with open(os.path.join(out, "summary.json"), encoding="utf-8") as f:
                rates.append(json.load(f)["runs_per_second"])
    return statistics.median(rates)


def dask_rate(client, scene, kwargs):
    rates = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        table = moreau.sweep(moreau.scene(scene), client=client, **kwargs)
        rates.append(len(table) / (time.perf_counter() - start))
    return statistics.median(rates)


def main():
    cli = sys.argv[1]
    import distributed

    rows = []
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=40) as cluster, \
            distributed.Client(cluster) as client:
        for scene, case in CASES.items():
            one = cli_rate(cli, scene, case["cli"], 1)
            two = cli_rate(cli, scene, case["cli"], 2)
            dask = dask_rate(client, scene, case["py"])
            # Overhead per run on the cluster: its time per run against the 2-thread pool's.
            overhead_us = (1 / dask - 1 / two) * 1e6
            rows.append((scene, one, two, two / (2 * one), dask, overhead_us))
    print("| scene | 1 thread (runs/s) | 2 threads (runs/s) | parallel efficiency | "
          "Dask 2 workers (runs/s) | Dask overhead per run |")
    print("|---|---|---|---|---|---|")
    for scene, one, two, eff, dask, overhead in rows:
        print(f"| {scene} | {one:.0f} | {two:.0f} | {eff:.2f} | {dask:.0f} | {overhead:.0f} µs |")


if __name__ == "__main__":
    main()
