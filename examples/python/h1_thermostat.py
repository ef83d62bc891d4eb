"""H1: a thermostat with hysteresis, simulated by time-freezing and reported in physical
time: relay jumps, the memory signal w(t), and a plot with the memory panel.

    /usr/bin/python3 examples/python/h1_thermostat.py [out.png]
"""
import sys

import moreau

result = moreau.simulate(moreau.scene("H1"), integrator="fesd", stages=3, h=0.1)
print(result)
relay = result.relays[0]
print(f"relay {relay.name}: w0 = {relay.initial}, jumps at "
      + ", ".join(f"{t:.6f}" for t in relay.jump_times[:6]) + " ...")
print("frozen numerical time:", result.stats["frozen_time"])
if len(sys.argv) > 1:
    result.plot().savefig(sys.argv[1], dpi=100)
