"""moreau.sweep: parameter grids and Monte Carlo over a scene's named values, on local threads
(the C++ thread pool, GIL released) or on a Dask cluster (dask.distributed.Client).

Run i of a sweep is determined by the specification and i alone (see
include/moreau/ensemble/sweep.hpp), so a cluster computes chunks of run indices anywhere, in
any order, and any number of times (a worker that dies has its chunks re-run by Dask): the
table is the same, bit for bit, as a local run with any number of threads.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _moreau

GridSpec = Union[Tuple[float, float, int], Sequence[float], np.ndarray]
SampleSpec = Tuple[str, float, float]


def _grid_arguments(grid: Optional[Mapping[str, GridSpec]]) -> List[Tuple[str, List[float]]]:
    """(name, values) in the given order: (start, stop, count) tuples go through the library's
    grid parser (the points of ``--grid name=start:stop:count``), value lists as they are."""
    values: List[Tuple[str, List[float]]] = []
    if grid is None:
        return values
    if not isinstance(grid, Mapping):
        raise ValueError("grid must be a dict name -> (start, stop, count) or a list of values")
    for name, spec in grid.items():
        if not isinstance(name, str):
            raise ValueError(f"grid names must be strings, got {type(name).__name__}")
        # A 3-tuple is always (start, stop, count); values come as a list or an array. A
        # count that is not an integer is an error, never three values read as a list.
        if isinstance(spec, tuple) and len(spec) == 3:
            start, stop, count = spec
            if isinstance(count, bool) or not isinstance(count, (int, np.integer)):
                raise ValueError(f"grid '{name}': a tuple is (start, stop, count) and count must "
                                 f"be an integer, got {count!r}; pass several values as a list "
                                 f"[{', '.join(repr(v) for v in spec)}]")
            if count < 1:
                raise ValueError(f"grid '{name}': count must be >= 1, got {count}")
            for part, value in (("start", start), ("stop", stop)):
                if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
                    raise ValueError(f"grid '{name}': {part} must be a number, got {value!r}")
                if not math.isfinite(float(value)):
                    raise ValueError(f"grid '{name}': {part} must be finite, got {value!r}")
            values.append(_moreau._parse_grid(f"{name}={float(start)!r}:{float(stop)!r}:"
                                              f"{int(count)}"))
            continue
        try:
            array = np.asarray(spec, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"grid '{name}': expected (start, stop, count) or a list of "
                             f"numbers, got {spec!r}") from None
        if array.ndim != 1 or array.size == 0 or not np.all(np.isfinite(array)):
            raise ValueError(f"grid '{name}': expected (start, stop, count) or a non-empty 1-D "
                             f"list of finite numbers, got shape {array.shape}")
        values.append((name, [float(v) for v in array]))
    return values


def _sample_arguments(samples: Optional[Mapping[str, SampleSpec]]) -> List[str]:
    texts: List[str] = []
    if samples is None:
        return texts
    if not isinstance(samples, Mapping):
        raise ValueError("samples must be a dict name -> ('normal', mean, std) or "
                         "('uniform', a, b)")
    for name, spec in samples.items():
        if not isinstance(name, str):
            raise ValueError(f"sample names must be strings, got {type(name).__name__}")
        if not (isinstance(spec, tuple) and len(spec) == 3 and spec[0] in ("normal", "uniform")):
            raise ValueError(f"sample '{name}': expected ('normal', mean, std) or "
                             f"('uniform', a, b), got {spec!r}")
        kind, a, b = spec
        for value in (a, b):
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
                raise ValueError(f"sample '{name}': parameters must be numbers, got {value!r}")
            if not math.isfinite(float(value)):
                raise ValueError(f"sample '{name}': parameters must be finite, got {value!r}")
        if kind == "normal" and b < 0:
            raise ValueError(f"sample '{name}': the standard deviation must be >= 0, got {b!r}")
        if kind == "uniform" and not a < b:
            raise ValueError(f"sample '{name}': ('uniform', a, b) needs a < b, got a = {a!r}, "
                             f"b = {b!r}")
        texts.append(f"{name}={kind}:{float(a)!r}:{float(b)!r}")
    return texts


def _frame(columns: Dict[str, Any]):
    """The library's columns as a pandas DataFrame (one row per run, in index order)."""
    import pandas as pd

    data: Dict[str, Any] = {"index": columns["index"]}
    for i, name in enumerate(columns["varied_names"]):
        data[name] = columns["varied"][:, i]
    data["status"] = columns["status"]
    data["success"] = columns["success"]
    data["message"] = columns["message"]
    data["final_time"] = columns["final_time"]
    for i, name in enumerate(columns["state_names"]):
        data["x." + name] = columns["final_state"][:, i]
    data["num_events"] = columns["num_events"]
    for k in range(columns["event_times"].shape[1]):
        data[f"event_{k + 1}"] = columns["event_times"][:, k]
    for i, name in enumerate(columns["stat_names"]):
        data[name] = columns["stats"][:, i]
    data["run_cpu_seconds"] = columns["run_cpu_seconds"]
    return pd.DataFrame(data)


def _run_chunk(scene_data: Dict[str, Any], spec: Dict[str, Any], indices: List[int]):
    """One Dask task: rebuild the scene from data, run the given run indices on one thread."""
    from . import scene_from_data

    scene = scene_from_data(scene_data)
    columns = _moreau._sweep(scene._native, spec["grids"], spec["samples"],
                             spec["num_samples"], spec["seed"], spec["events"],
                             spec["integrator"], spec["options"], 1, indices, None)
    return _frame(columns)


def sweep(scene, grid: Optional[Mapping[str, GridSpec]] = None,
          samples: Optional[Mapping[str, SampleSpec]] = None, n_samples: int = 0, seed: int = 0,
          integrator: str = "auto", client=None, jobs: int = 0,
          chunk_size: Optional[int] = None, events: int = 5,
          progress: Optional[Callable[[int, int], Any]] = None, **options: Any):
    """Runs ``scene`` over grids and samples of its named values (the ``--set`` names) and
    returns a pandas DataFrame with one row per run: ``index``, the varied values, ``status``,
    ``success``, ``message``, ``final_time``, ``x.<state>``, ``num_events``,
    ``event_1..event_K``, the integrator's statistics and ``run_cpu_seconds``.

    - ``grid={"heat": (4.0, 6.0, 11)}`` (start, stop, count) or ``{"heat": [4.0, 5.0]}``;
      several grids form a product (the first varies slowest).
    - ``samples={"decay": ("normal", 0.2, 0.02)}`` or ``("uniform", a, b)``, with
      ``n_samples`` draws per grid point and ``seed``.
    - ``integrator`` and ``**options`` as for :func:`simulate`.
    - ``client``: a ``dask.distributed.Client``: runs on its cluster in chunks of
      ``chunk_size`` runs (default: about four chunks per worker thread, at most 1000 runs);
      otherwise on ``jobs`` local threads (0: all cores).
    - ``progress(done, total)`` is called as runs (local) or chunks (Dask) finish.

    The table is identical, bit for bit, whatever ``jobs``, the cluster and the order in which
    chunks finish. A run that fails is a row with its status; bad specifications raise
    ValueError.
    """
    from . import Scene

    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a moreau.Scene, got {type(scene).__name__}")
    for name, value in (("n_samples", n_samples), ("seed", seed), ("jobs", jobs),
                        ("events", events)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise ValueError(f"{name} must be a non-negative integer, got {value!r}")
    if progress is not None and not callable(progress):
        raise ValueError("progress must be callable (it is called with done, total)")
    # The library's own checks name the command line's flags; these say it in Python.
    if not grid and not samples:
        raise ValueError("a sweep needs grid= or samples=")
    if samples and n_samples < 1:
        raise ValueError(f"samples= needs n_samples >= 1 draws per grid point, got {n_samples}")
    if not samples and n_samples != 0:
        raise ValueError("n_samples applies only with samples=")
    spec = {
        "grids": _grid_arguments(grid),
        "samples": _sample_arguments(samples),
        "num_samples": int(n_samples),
        "seed": int(seed),
        "events": int(events),
        "integrator": integrator,
        "options": dict(options),
    }
    if client is None:
        columns = _moreau._sweep(scene._native, spec["grids"], spec["samples"],
                                 spec["num_samples"], spec["seed"],
                                 spec["events"], integrator, spec["options"], int(jobs), [],
                                 progress)
        return _frame(columns)

    # Validate everything and count the runs locally (an empty index list runs nothing: the
    # first run only, which is cheap, checks the settings) before shipping work.
    probe = _moreau._sweep(scene._native, spec["grids"], spec["samples"],
                           spec["num_samples"], spec["seed"], 0, integrator, spec["options"], 1,
                           [0], None)
    del probe
    total = _count_runs(spec)
    workers = max(1, sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values()))
    if chunk_size is None:
        chunk_size = max(1, min(1000, math.ceil(total / (4 * workers))))
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) \
            or chunk_size < 1:
        raise ValueError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    chunks = [list(range(start, min(start + chunk_size, total)))
              for start in range(0, total, chunk_size)]
    scene_data = scene.to_data()
    from dask.distributed import as_completed

    futures = client.map(_run_chunk, [scene_data] * len(chunks), [spec] * len(chunks), chunks,
                         pure=False)
    pieces = []
    done = 0
    for future in as_completed(futures):
        piece = future.result()
        pieces.append(piece)
        done += len(piece)
        if progress is not None:
            progress(done, total)
    import pandas as pd

    frame = pd.concat(pieces, ignore_index=True).sort_values("index", kind="stable")
    return frame.reset_index(drop=True)


def _count_runs(spec: Dict[str, Any]) -> int:
    runs = 1
    for _, values in spec["grids"]:
        runs *= len(values)
    if spec["samples"]:
        runs *= spec["num_samples"]
    return runs
