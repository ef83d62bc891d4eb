"""Thermostat period against heater power and heat-loss rate (docs/ensembles.md): a 2-D
sweep of H1, the period read off the relay's event times (one on and one off switch per
period), as a table and a heat map.

    /usr/bin/python3 examples/python/thermostat_period.py [out.png] [tcp://scheduler:8786]
"""
import sys

import numpy as np

import moreau

client = None
if len(sys.argv) > 2:
    from dask.distributed import Client
    client = Client(sys.argv[2])

scene = moreau.scene("H1").set(tf=40.0)
table = moreau.sweep(scene, grid={"heat": (4.5, 8.0, 15), "decay": (0.15, 0.3, 13)},
                     integrator="fesd", stages=3, h=0.2, events=8, client=client)
# Events come in pairs (on, off); after the first transient pair the period is the distance
# between the 3rd and 5th events (two switches later the relay is in the same state again).
table["period"] = table["event_5"] - table["event_3"]
print(table[["heat", "decay", "status", "num_events", "period"]].to_string(max_rows=12))
print("runs without a periodic regime (heater too weak or too strong):",
      int(table["period"].isna().sum()))
if len(sys.argv) > 1:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    grid = table.pivot(index="decay", columns="heat", values="period")
    fig, ax = plt.subplots(figsize=(7, 5))
    image = ax.pcolormesh(grid.columns, grid.index, grid.values, shading="nearest")
    fig.colorbar(image, label="period")
    ax.set_xlabel("heater power (heat)")
    ax.set_ylabel("heat-loss rate (decay)")
    ax.set_title("H1: thermostat period")
    fig.savefig(sys.argv[1], dpi=100)
