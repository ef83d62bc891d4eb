"""Result.plot(): states and multipliers over time with matplotlib, switch events marked."""

from __future__ import annotations

import numpy as np


def plot_result(result, states=None, multipliers=True, events=True, ax=None):
    import matplotlib.pyplot as plt

    names = list(result.state_names)
    chosen = list(states) if states is not None else names[:8]
    for name in chosen:
        if name not in names:
            raise ValueError(f"unknown state '{name}'; states: {', '.join(names)}")
    has_multipliers = multipliers and result.algebraic.shape[1] > 0
    has_relays = len(result.relays) > 0
    panels = 1 + int(has_multipliers) + int(has_relays)
    if ax is None:
        fig, axes = plt.subplots(panels, 1, sharex=True, figsize=(9, 2.8 * panels + 0.6),
                                 squeeze=False)
        axes = list(axes[:, 0])
    else:
        axes = [ax] if panels == 1 else list(ax)
        if len(axes) != panels:
            raise ValueError(f"this result needs {panels} axes, got {len(axes)}")
        fig = axes[0].figure
    top = axes[0]
    for name in chosen:
        top.plot(result.t, result.x[:, names.index(name)], lw=1.8, label=name)
    top.set_ylabel("state")
    top.set_title(f"{result.scene} ({result.integrator}, {result.status})")
    top.legend(loc="best", fontsize="small")
    panel = 1
    if has_multipliers:
        mult = axes[panel]
        panel += 1
        shown = result.algebraic_names[:8]
        for i, name in enumerate(shown):
            column = result.algebraic[:, i]
            keep = np.isfinite(column)
            mult.plot(result.t[keep], column[keep], lw=1.4, label=name)
        mult.set_ylabel("algebraic")
        mult.legend(loc="best", fontsize="small")
    if has_relays:
        relay_ax = axes[panel]
        for relay in result.relays:
            times = [result.t[0]] + list(relay.jump_times) + [result.final_time]
            values = [relay.initial] + list(relay.values) + [relay.values[-1] if relay.values
                                                              else relay.initial]
            relay_ax.step(times, values, where="post", lw=1.8, label=f"{relay.name}.w")
        relay_ax.set_ylabel("memory w")
        relay_ax.set_ylim(-0.1, 1.1)
        relay_ax.legend(loc="best", fontsize="small")
    if events:
        for event in result.events:
            for a in axes:
                a.axvline(event.t, color="0.6", ls="--", lw=0.8)
    for a in axes:
        a.grid(True, alpha=0.3)
    axes[-1].set_xlabel("t")
    return fig
