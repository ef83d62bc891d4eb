"""Figures of a run and of a sweep with matplotlib (Result.plot, plot_sweep).

A run's figure is built from what the scene contains (the same figure as ``moreau run``'s
trajectory.png): the states with their labels and units (along FESD's collocation polynomials
when the run recorded its stages, ``record_stages=True``, as ``moreau run`` does); the
multipliers of moving sets and complementarity pairs (with recorded stages, lines through the
stage values that jump at switches; otherwise each value held on the interval that ends at its
time, so that a jump is drawn as a jump); active constraints, Filippov modes and relay memories as bands; the events as
marks in rows named by constraint, surface or relay (by kind when there are too many), shaped
by kind. Scenes with two states get their phase portrait with the set boundaries C(t) at the
event times and the switching surfaces. The lowering's internal variables (Filippov theta,
lambda, mu; time-freezing variables) appear only with ``internal=True``. Time axes end at the
run's final time.
"""

from __future__ import annotations

import numpy as np

from . import _moreau

# Most rows of named bands or events, multiplier lines and event lines through the panels;
# beyond these, counts and kinds keep the figure readable over long horizons.
_MAX_ROWS = 10
_MAX_MULTIPLIER_LINES = 8
_MAX_EVENT_LINES = 20
_MAX_BOUNDARY_TIMES = 8
# A constraint is active where its multiplier exceeds this fraction of the largest one (the
# integrators put inactive multipliers at 0 up to their Newton tolerance).
_ACTIVE_FRACTION = 1e-9
_KIND_STYLE = {
    "enter": ("^", "#E45756"), "leave": ("v", "#4C78A8"), "mode_switch": ("o", "#54A24B"),
    "slide_start": ("s", "#F58518"), "slide_end": ("D", "#F58518"),
    "relay_switch": ("d", "#B279A2"), "ambiguous": ("x", "#000000"),
}
_BOUNDARY_COLOR = "#D62728"


def _stages_per_element(result):
    """FESD's s if the run recorded its stages (``record_stages=True``) as whole elements."""
    stage = result.stage_trajectory
    s = int(result.options.get("stages", 0) or 0) if result.integrator == "fesd" else 0
    points = len(stage["t"]) if stage else 0
    return s if s > 0 and points > 0 and points % s == 0 else 0


def _curve(result):
    """The states as drawn: with FESD's recorded stages, the collocation polynomial of each
    element (degree s through its start and its s Radau IIA stages; c_s = 1 is its end) at
    up to twelve points inside it, so that long error-controlled steps are not drawn as a
    polygon; elements whose physical time stands still (time-freezing) keep their points.
    Otherwise the recorded trajectory."""
    s = _stages_per_element(result)
    if s == 0:
        return np.asarray(result.t), np.asarray(result.x)
    stage = result.stage_trajectory
    st, sx, step = np.asarray(stage["t"]), np.asarray(stage["x"]), np.asarray(stage["step"])
    elements = len(st) // s
    inside = min(12, 4000 // elements)
    t_out, x_out = [result.t[0]], [np.asarray(result.x[0])]
    t_start, x_start = result.t[0], np.asarray(result.x[0])
    for e in range(elements):
        rows = slice(e * s, (e + 1) * s)
        span = st[rows][-1] - t_start
        if inside > 0 and span > 0.5 * step[rows][-1]:
            nodes = np.concatenate([[0.0], (st[rows] - t_start) / span])
            values = np.vstack([x_start, sx[rows]])
            theta = np.union1d(np.arange(1, inside + 1) / (inside + 1), nodes[1:])
            basis = np.ones((len(theta), s + 1))
            for i in range(s + 1):
                for k in range(s + 1):
                    if k != i:
                        basis[:, i] *= (theta - nodes[k]) / (nodes[i] - nodes[k])
            t_out.extend(t_start + theta * span)
            x_out.extend(basis @ values)
        else:
            t_out.extend(st[rows])
            x_out.extend(sx[rows])
        t_start, x_start = st[rows][-1], sx[rows][-1]
    return np.asarray(t_out), np.vstack(x_out)


def _multiplier_lines(result, times, column):
    """FESD with recorded stages: lines through the stage values; at a switch (switches end
    elements) a jump to the next element's first stage value, held up to that stage."""
    s = _stages_per_element(result)
    events = np.sort([e.t for e in result.events])
    t_out, v_out = [], []
    start = result.t[0]
    for k in range(len(times)):
        if k % s == 0:
            near = np.abs(events - start) <= 1e-12 * max(1.0, abs(start)) if len(events) else []
            if k == 0 or np.any(near):
                t_out.append(start)
                v_out.append(column[k])
        t_out.append(times[k])
        v_out.append(column[k])
        if (k + 1) % s == 0:
            start = times[k]
    return np.asarray(t_out), np.asarray(v_out)


def _label(view, name):
    text = f"{view['labels'][name]} ({name})" if name in view["labels"] else name
    unit = view["units"].get(name, "")
    return f"{text} [{unit}]" if unit else text


def _bands(t, active):
    """(start, width) of the runs of True in ``active``, a value per time of ``t`` that holds
    on the interval ending there (t_{k-1}, t_k], as multipliers at stage points do."""
    spans = []
    k = 0
    n = len(t)
    while k < n:
        if not active[k]:
            k += 1
            continue
        j = k
        while j + 1 < n and active[j + 1]:
            j += 1
        start = t[k - 1] if k > 0 else t[k]
        if t[j] > start:
            spans.append((start, t[j] - start))
        k = j + 1
    return spans


def plot_result(result, states=None, multipliers=True, events=True, ax=None, internal=False,
                phase=None):
    import matplotlib.pyplot as plt

    scene = getattr(result, "_scene", None)
    view = (_moreau._scene_view(scene._native) if scene is not None
            else {"units": {}, "labels": {}})
    names = list(result.state_names)
    chosen = list(states) if states is not None else names[:8]
    for name in chosen:
        if name not in names:
            raise ValueError(f"unknown state '{name}'; states: {', '.join(names)}")
    t_end = result.final_time
    # Multipliers: the effects' own, or everything with internal=True.
    own = set(_moreau._multiplier_names(scene._native)) if scene is not None else set()
    stage = result.stage_trajectory
    dense_t = np.asarray(stage["t"]) if stage and len(stage["t"]) else result.t
    dense_a = np.asarray(stage["algebraic"]) if stage and len(stage["t"]) else result.algebraic
    dense_names = list(stage["algebraic_names"]) if stage and len(stage["t"]) else \
        list(result.algebraic_names)
    shown = [i for i, name in enumerate(dense_names) if internal or name in own]
    if not multipliers:
        shown = []
    # Bands: active constraints from their multipliers, relay memories.
    band_rows = []
    for i in shown:
        name = dense_names[i]
        if name not in own:
            continue
        column = np.nan_to_num(dense_a[:, i])
        scale = max(np.max(np.abs(column)), 1e-300)
        band_rows.append((name.replace(".lambda_", ".") + " active",
                          _bands(dense_t, column > _ACTIVE_FRACTION * scale)))
    counts = None
    if len(band_rows) > _MAX_ROWS:
        counts = sum((np.nan_to_num(dense_a[:, i]) > 0).astype(float) for i in shown
                     if dense_names[i] in own)
        band_rows = []
    for relay in result.relays:
        times = [result.t[0]] + list(relay.jump_times) + [t_end]
        values = [relay.initial] + list(relay.values)
        spans = [(times[k], times[k + 1] - times[k]) for k in range(len(values))
                 if values[k] == 1 and times[k + 1] > times[k]]
        band_rows.append((f"{relay.name}: w = 1", spans))
    band_rows = band_rows[:_MAX_ROWS]
    event_list = list(result.events) if events else []
    two_states = len(names) == 2 if phase is None else bool(phase)

    effects_panel = len(shown) > 0
    panels = 1 + int(effects_panel) + int(len(band_rows) > 0) + int(len(event_list) > 0)
    if ax is None:
        fig = plt.figure(figsize=(13 if two_states else 10, 2.4 * panels + 0.8))
        if two_states:
            grid = fig.add_gridspec(panels, 2, width_ratios=[1.5, 1])
            axes = [fig.add_subplot(grid[0, 0])]
            axes += [fig.add_subplot(grid[k, 0], sharex=axes[0]) for k in range(1, panels)]
            phase_ax = fig.add_subplot(grid[:, 1])
        else:
            grid = fig.add_gridspec(panels, 1)
            axes = [fig.add_subplot(grid[0, 0])]
            axes += [fig.add_subplot(grid[k, 0], sharex=axes[0]) for k in range(1, panels)]
            phase_ax = None
    else:
        axes = [ax] if panels == 1 else list(ax)
        if len(axes) != panels:
            raise ValueError(f"this result needs {panels} axes, got {len(axes)}")
        fig = axes[0].figure
        phase_ax = None
    panel = 0
    top = axes[panel]
    curve_t, curve_x = _curve(result)
    for name in chosen:
        top.plot(curve_t, curve_x[:, names.index(name)], lw=1.8, label=_label(view, name))
    units = {view["units"].get(name, "") for name in chosen}
    top.set_ylabel(f"state [{units.pop()}]" if len(units) == 1 and "" not in units else "state")
    top.set_title(f"{result.scene} ({result.integrator}, {result.status})")
    top.legend(loc="best", fontsize="small")
    panel += 1
    if effects_panel:
        mult = axes[panel]
        panel += 1
        if counts is not None:
            mult.step(dense_t, counts, where="pre", lw=1.4, label="active constraints")
            mult.set_ylabel("active constraints")
        else:
            lines = stage and len(stage["t"]) and _stages_per_element(result) > 0
            for i in shown[:_MAX_MULTIPLIER_LINES]:
                column = dense_a[:, i]
                if lines:
                    mult.plot(*_multiplier_lines(result, dense_t, column), lw=1.4,
                              label=dense_names[i])
                    continue
                keep = np.isfinite(column)
                # The value at t_k holds on (t_{k-1}, t_k]: steps, so jumps stay jumps.
                mult.step(dense_t[keep], column[keep], where="pre", lw=1.4,
                          label=dense_names[i])
            mult.set_ylabel("multiplier")
        mult.legend(loc="best", fontsize="small")
    if band_rows:
        bands = axes[panel]
        panel += 1
        colors = ["#4C78A8", "#F58518", "#54A24B", "#B279A2"]
        for row, (name, spans) in enumerate(band_rows):
            bands.broken_barh(spans, (row - 0.35, 0.7), facecolors=colors[row % 4])
        bands.set_yticks(range(len(band_rows)))
        bands.set_yticklabels([name for name, _ in band_rows], fontsize="small")
        bands.set_ylim(len(band_rows) - 0.5, -0.5)
    if event_list:
        marks = axes[panel]
        whats = sorted({e.what for e in event_list})
        by_what = len(whats) <= _MAX_ROWS
        rows = whats if by_what else sorted({e.kind for e in event_list})
        for kind, (marker, color) in _KIND_STYLE.items():
            picked = [e for e in event_list if e.kind == kind]
            if not picked:
                continue
            marks.scatter([e.t for e in picked],
                          [rows.index(e.what if by_what else e.kind) for e in picked],
                          marker=marker, color=color, s=30, label=kind, zorder=3)
        marks.set_yticks(range(len(rows)))
        marks.set_yticklabels(rows, fontsize="small")
        marks.set_ylim(len(rows) - 0.5, -0.5)
        marks.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")
        if len(event_list) <= _MAX_EVENT_LINES:
            for event in event_list:
                for a in axes[:-1]:
                    a.axvline(event.t, color="0.7", ls="--", lw=0.8)
    for a in axes:
        a.grid(True, alpha=0.3)
        a.set_xlim(result.t[0], t_end)
    for a in axes[:-1]:
        plt.setp(a.get_xticklabels(), visible=False)
    axes[-1].set_xlabel("t" + (f" [{view['units']['t']}]" if "t" in view["units"] else ""))
    if phase_ax is not None:
        _phase_portrait(phase_ax, result, scene, view)
    fig.tight_layout()
    return fig


def _phase_portrait(ax, result, scene, view):
    x = _curve(result)[1]
    lo, hi = np.min(x, axis=0), np.max(x, axis=0)
    pad = np.where(hi > lo, 0.12 * (hi - lo), 0.5 * np.maximum(1.0, np.abs(lo)))
    lo, hi = lo - pad, hi + pad
    ax.plot(x[:, 0], x[:, 1], color="#4C78A8", lw=1.8, label="x(t)", zorder=3)
    ax.plot(x[0, 0], x[0, 1], "ko", label="x(t0)", zorder=4)
    if scene is not None:
        gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], 241), np.linspace(lo[1], hi[1], 241))
        points = np.column_stack([gx.ravel(), gy.ravel()])
        times = [result.t[0]] + [e.t for e in result.events if e.kind in ("enter", "leave")]
        if len(times) > _MAX_BOUNDARY_TIMES:
            pick = np.linspace(0, len(times) - 1, _MAX_BOUNDARY_TIMES).round().astype(int)
            times = [times[k] for k in pick]
        labelled = False
        for kind, name in scene.effects:
            if kind not in ("moving set", "switching surfaces"):
                continue
            for t in (times if kind == "moving set" else [result.t[0]]):
                values = _moreau._effect_values(scene._native, name, float(t), points)
                for j in range(values.shape[1]):
                    field = values[:, j].reshape(gx.shape)
                    if np.nanmin(field) < 0.0 < np.nanmax(field):
                        ax.contour(gx, gy, field, levels=[0.0], colors=_BOUNDARY_COLOR,
                                   linewidths=1.6)
                        if not labelled:
                            ax.plot([], [], color=_BOUNDARY_COLOR,
                                    label="set boundary C(t) at events" if kind == "moving set"
                                    else "switching surfaces")
                            labelled = True
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    names = list(result.state_names)
    ax.set_xlabel(_label(view, names[0]))
    ax.set_ylabel(_label(view, names[1]))
    ax.set_title("phase portrait")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")


def plot_sweep(table, varied=None, quantities=None):
    """Figures of a sweep table (moreau.sweep): one per varied value, every quantity against
    it as points (one per run; never the run index), failed runs as red crosses, constant
    columns titled as constant. Returns {varied name: figure}."""
    import matplotlib.pyplot as plt

    columns = list(table.columns)
    start = columns.index("index") + 1
    varied = list(varied) if varied is not None else columns[start:columns.index("status")]
    if quantities is None:
        quantities = [c for c in columns if c.startswith("x.")][:6] + ["num_events"]
        if "event_1" in columns:
            quantities.append("event_1")
    for name in list(varied) + list(quantities):
        if name not in columns:
            raise ValueError(f"unknown column '{name}'; columns: {', '.join(columns)}")
    ok = table["success"].to_numpy(dtype=bool)
    figures = {}
    for v in varied:
        n = len(quantities)
        cols = 3 if n > 4 else 2
        rows = (n + cols - 1) // cols
        fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.0 * rows), squeeze=False)
        fig.suptitle(f"{len(table)} runs against {v}")
        for k, q in enumerate(quantities):
            a = axes[k // cols][k % cols]
            values = table[q].to_numpy(dtype=float)
            finite = values[np.isfinite(values)]
            a.scatter(table[v][ok], values[ok], s=6, color="#4C78A8", label="runs")
            if (~ok).any():
                a.scatter(table[v][~ok], values[~ok], marker="x", color="#D62728",
                          label=f"failed runs ({int((~ok).sum())})")
            title = q
            if finite.size and np.ptp(finite) <= 1e-12 * max(1.0, abs(finite[0])):
                title += f" (constant: {finite[0]:.6g})"
                half = 0.1 * max(1.0, abs(finite[0]))
                a.set_ylim(finite[0] - half, finite[0] + half)
            a.set_title(title, fontsize="medium")
            a.set_xlabel(v)
            a.grid(True, alpha=0.3)
            a.legend(fontsize="x-small")
        for k in range(n, rows * cols):
            axes[k // cols][k % cols].set_visible(False)
        fig.tight_layout()
        figures[v] = fig
    return figures
