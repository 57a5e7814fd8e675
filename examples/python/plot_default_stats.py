#!/usr/bin/env python3
"""Runs the default scene through the Python module and plots its statistics.

    PYTHONPATH=build/python /usr/bin/python3 examples/python/plot_default_stats.py [OUT.png]

Advances scenes/default.json (a ball of honey dropped into a box) frame by frame, printing one line
per frame, then plots the Krylov iterations and the liquid volume of every step (matplotlib:
Debian's python3-matplotlib; without it the numbers are printed only). Ctrl-C stops it within one
solver iteration, with the frames done so far kept.
"""
import os
import sys

import stokesvdb

HERE = os.path.dirname(os.path.abspath(__file__))
scene = stokesvdb.load_scene(os.path.join(HERE, "..", "..", "scenes", "default.json"))
sim = stokesvdb.Simulation(scene)
steps = []
try:
    for frame in range(1, scene.frames + 1):
        done = sim.advance(1)
        steps += done
        print("frame %d: t = %.3f s, %d steps, %d iterations, liquid volume %.4g m^3"
              % (frame, sim.time, len(done), sum(s["iterations"] for s in done), done[-1]["liquid_volume"]))
except KeyboardInterrupt:
    print("stopped at t = %.3f s after %d steps" % (sim.time, sim.steps))

try:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError:
    print("matplotlib is missing (Debian: python3-matplotlib): no plot")
    sys.exit(0)
t = [s["t"] for s in steps]
fig, (a, b) = plt.subplots(2, 1, sharex=True, figsize=(6, 5))
a.plot(t, [s["iterations"] for s in steps])
a.set_ylabel("Krylov iterations")
b.plot(t, [s["liquid_volume"] * 1e6 for s in steps])
b.set_ylabel("liquid volume (cm^3)")
b.set_xlabel("t (s)")
out = sys.argv[1] if len(sys.argv) > 1 else "default_stats.png"
fig.savefig(out, dpi=120)
print("wrote", out)
