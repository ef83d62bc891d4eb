"""S3: a rotation projected on a floor (sweeping process). Simulates with FESD, prints the
contact and leaving times against the closed form 5pi/12 and 5pi/12 + sqrt(3), and plots.

    /usr/bin/python3 examples/python/s3_sweeping.py [out.png]
"""
import math
import sys

import moreau

result = moreau.simulate(moreau.scene("S3"), integrator="fesd", stages=3, h=0.05)
contact, leave = 5 * math.pi / 12, 5 * math.pi / 12 + math.sqrt(3)
print(result)
for event, exact in zip(result.events, (contact, leave)):
    print(f"{event.kind:6s} {event.what}: t = {event.t:.15f}  (exact {exact:.15f}, "
          f"error {abs(event.t - exact):.1e})")
import numpy as np  # noqa: E402

print("largest multiplier (the floor's reaction):", np.nanmax(result.algebraic[:, 0]))
if len(sys.argv) > 1:
    result.plot().savefig(sys.argv[1], dpi=100)
