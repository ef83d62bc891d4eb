"""moreau.sweep: the same table (bit for bit) on 1 and 2 local threads and on a Dask
LocalCluster with 2 worker processes, also when a worker dies mid-sweep; bad specifications
raise ValueError."""

import os
import signal
import threading
import time

import numpy as np
import pandas as pd
import pytest

import moreau

# Seeded Monte Carlo on H1 (thermostat with hysteresis): heater power and heat-loss rate.
H1_SAMPLES = {"heat": ("normal", 5.0, 0.4), "decay": ("uniform", 0.15, 0.25)}
H1_OPTIONS = {"integrator": "fesd", "h": 0.2}
H1_RUNS = 24


def _h1(n=H1_RUNS, **kw):
    return moreau.sweep(moreau.scene("H1"), samples=H1_SAMPLES, n_samples=n, seed=11,
                        **H1_OPTIONS, **kw)


def _assert_same_table(a: pd.DataFrame, b: pd.DataFrame):
    assert list(a.columns) == list(b.columns)
    assert len(a) == len(b)
    timing = {"cpu_seconds", "run_cpu_seconds"}
    for column in a.columns:
        if column in timing:
            continue
        left, right = a[column].to_numpy(), b[column].to_numpy()
        if left.dtype.kind == "f":
            # bit for bit, NaN where both are NaN
            assert np.array_equal(left.view(np.int64), right.view(np.int64)), column
        else:
            assert (left == right).all(), column


@pytest.fixture(scope="module")
def reference():
    return _h1(jobs=1)


def test_local_threads_give_the_same_table(reference):
    assert len(reference) == H1_RUNS
    assert reference["success"].all(), reference["message"].tolist()
    assert list(reference["index"]) == list(range(H1_RUNS))
    _assert_same_table(reference, _h1(jobs=2))


def test_grid_product_and_failure_rows():
    table = moreau.sweep(moreau.scene("S3"), grid={"x0.x2": [-2.0, 1.0], "floor": (-1.0, -0.5, 2)},
                         integrator="fesd")
    assert len(table) == 4
    assert list(table["x0.x2"]) == [-2.0, -2.0, 1.0, 1.0]  # the first grid varies slowest
    assert list(table["floor"]) == [-1.0, -0.5, -1.0, -0.5]
    assert (table["status"][:2] == "invalid_input").all()  # x0 below the floor: rows, not errors
    assert table["success"][2:].all()


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=40) as local:
        with distributed.Client(local) as client:
            yield client


def test_dask_cluster_gives_the_same_table(reference, cluster):
    _assert_same_table(reference, _h1(client=cluster, chunk_size=5))


def test_a_worker_killed_mid_sweep_still_gives_the_complete_table(reference, cluster):
    killed = threading.Event()
    before = set(cluster.scheduler_info()["workers"])
    pids = cluster.run(os.getpid)  # worker address -> process id

    def kill_one_worker(done, total):
        # After the first chunk arrives, kill one worker process (SIGKILL): its running and
        # queued chunks, and results it held, are lost with it and re-run by Dask.
        if killed.is_set():
            return
        killed.set()
        os.kill(pids[sorted(pids)[0]], signal.SIGKILL)

    table = _h1(client=cluster, chunk_size=2, progress=kill_one_worker)
    assert killed.is_set()
    _assert_same_table(reference, table)
    # The worker really died (the scheduler lost it; its nanny starts a new one).
    deadline = time.monotonic() + 30
    while before <= set(cluster.scheduler_info()["workers"]) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not before <= set(cluster.scheduler_info()["workers"])


def test_bad_specifications_raise_value_error():
    s3 = moreau.scene("S3")
    with pytest.raises(ValueError, match="expected name=start:stop:count|count must be"):
        moreau.sweep(s3, grid={"floor": (0.0, 1.0, 0)})
    with pytest.raises(ValueError, match="has no value named 'radius' to vary"):
        moreau.sweep(s3, grid={"radius": (0.0, 1.0, 3)})
    with pytest.raises(ValueError, match="expected \\('normal', mean, std\\) or \\('uniform'"):
        moreau.sweep(s3, samples={"floor": ("gauss", 0.0, 1.0)}, n_samples=3)
    # A 3-tuple is (start, stop, count): a float count is an error, never three values.
    with pytest.raises(ValueError, match="count must be an integer, got 3.0; pass several "
                                         "values as a list"):
        moreau.sweep(s3, grid={"floor": (-1.0, 0.0, 3.0)})
    with pytest.raises(ValueError, match="expected \\('normal', mean, std\\)"):
        moreau.sweep(s3, samples={"floor": ("normal", 0.0)}, n_samples=3)
    with pytest.raises(ValueError, match="needs n_samples >= 1"):
        moreau.sweep(s3, samples={"floor": ("normal", -1.0, 0.1)})
    with pytest.raises(ValueError, match="a sweep needs grid= or samples="):
        moreau.sweep(s3)
    with pytest.raises(ValueError, match="non-empty 1-D"):
        moreau.sweep(s3, grid={"floor": [[1.0, 2.0]]})
    with pytest.raises(ValueError, match="option 'rho' does not apply"):
        moreau.sweep(s3, grid={"floor": (-1.0, -0.5, 2)}, integrator="fesd", rho=0.5)
    with pytest.raises(ValueError, match="n_samples must be a non-negative integer"):
        moreau.sweep(s3, grid={"floor": (-1.0, -0.5, 2)}, n_samples=-1)


def test_table_round_trips_through_hdf5(tmp_path):
    # HDF5 is the Debian-packaged binary table format (pandas with python3-tables; Debian 12
    # has no Parquet writer): the table comes back identical.
    pytest.importorskip("tables")
    table = moreau.sweep(moreau.scene("S3"), grid={"floor": (-1.0, -0.5, 3)}, integrator="fesd")
    path = tmp_path / "sweep.h5"
    table.to_hdf(path, key="sweep", format="table")
    assert pd.read_hdf(path, "sweep").equals(table)
