"""S3 contact time over a grid of initial states (docs/ensembles.md), on local threads or on
a Dask cluster given its scheduler address:

    /usr/bin/python3 examples/python/s3_contact_sweep.py [tcp://scheduler:8786]
"""
import math
import sys

import numpy as np

import moreau

client = None
if len(sys.argv) > 1:
    from dask.distributed import Client
    client = Client(sys.argv[1])

table = moreau.sweep(moreau.scene("S3").set(tf=7.0),
                     grid={"x0.x1": (1.0, 2.0, 21), "x0.x2": (0.5, 1.5, 21)},
                     integrator="fesd", stages=3, h=0.05, client=client)
r = np.hypot(table["x0.x1"], table["x0.x2"])
contact = np.arctan2(table["x0.x2"], table["x0.x1"]) + np.arcsin(1 / r)  # closed form
print(table[["x0.x1", "x0.x2", "status", "event_1", "event_2"]].head())
print("max |contact time - closed form| over the grid:",
      float(np.max(np.abs(table["event_1"] - contact))))
print("max |leaving time - closed form| over the grid:",
      float(np.max(np.abs(table["event_2"] - (contact + np.sqrt(r * r - 1))))))
