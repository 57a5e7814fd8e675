#!/usr/bin/env python3
"""The Python module `stokesvdb` (python/stokesvdb_module.cpp), imported from the build tree.

    PYTHONPATH=build/python /usr/bin/python3 tests/python_module_test.py SOURCE_DIR

On the default scene at its resolution, 32:
1. a scene from a file and the same scene from a dict are the same run: the particles after one
   frame are bit-identical;
2. after the first frame (t = 1/24 s, before the ball lands) the particles' mean velocity is free
   fall, -g t, to 1e-3 of g t, and the dense level set is negative at the ball's centre and
   positive in the box's corner;
3. the stats dicts hold the stats.csv columns (docs/output.md);
4. a bad key raises stokesvdb.SceneError (a ValueError) with the command line's message;
5. a checkpoint after frame 1 resumed for frame 2 gives the uninterrupted run's particles bit for
   bit;
6. SIGINT during a step raises KeyboardInterrupt there; the simulation is left at its last complete
   step and, advanced again, ends bit-identical to the uninterrupted run;
7. write_frame writes a .vdb with the grids "surface" and "vel" (read back with python3-openvdb,
   where installed).
"""
import json
import os
import signal
import sys
import tempfile

import numpy as np
import stokesvdb

SRC = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..")
SCENE = os.path.join(SRC, "scenes", "default.json")
RES = 32
failures = []


def check(ok, what):
    print(("ok   " if ok else "FAIL ") + what)
    if not ok:
        failures.append(what)


def scene(frames=2):
    return stokesvdb.load_scene(SCENE, resolution=RES, frames=frames)


def main():
    stokesvdb.set_threads(2)
    # 1. file and dict
    sim = stokesvdb.Simulation(scene())
    steps = sim.advance(1)
    x, v = sim.particles()
    with open(SCENE) as f:
        as_dict = json.load(f)
    from_dict = stokesvdb.Simulation(stokesvdb.scene_from_dict(as_dict, base_dir=os.path.dirname(SCENE),
                                                               resolution=RES, frames=2))
    from_dict.advance(1)
    xd, vd = from_dict.particles()
    check(x.shape == (len(x), 3) and len(x) > 100 and np.array_equal(x, xd) and np.array_equal(v, vd),
          "a scene from a file and from a dict: %d particles, bit-identical after a frame" % len(x))

    # 2. free fall, the level set's sign
    g = -as_dict["gravity"][1]
    t = sim.time
    mean_v = v[:, 1].mean()
    check(abs(t - 1.0 / 24.0) < 1e-12 and abs(mean_v + g * t) < 1e-3 * g * t,
          "frame 1 at t = %.6f s: mean velocity %.6f m/s against free fall %.6f" % (t, mean_v, -g * t))
    phi = sim.level_set()
    values, origin, dx = phi["values"], np.array(phi["origin"]), phi["dx"]
    centre = np.array(as_dict["liquid"][0]["center"]) + np.array([0.0, -0.5 * g * t * t, 0.0])
    i, j, k = np.round((centre - origin) / dx).astype(int)
    check(values.dtype == np.float32 and values[i, j, k] < 0.0 and values[0, 0, 0] > 0.0,
          "level set %s, dx %.5f: phi %.4f at the ball's centre, %.4f in the band's corner"
          % (values.shape, dx, values[i, j, k], values[0, 0, 0]))

    # 3. stats
    with open(os.path.join(SRC, "docs", "output.md")) as f:
        documented = [line.split("`")[1] for line in f if line.startswith("| `")]
    keys = set(steps[0])
    required = {"frame", "step", "t", "dt", "iterations", "krylov_s", "solver", "liquid_volume"}
    check(required <= keys and keys <= set(documented),
          "stats dicts: %d keys, each a documented stats.csv column" % len(keys))

    # 4. errors
    bad = dict(as_dict, resolutoin=8)
    try:
        stokesvdb.scene_from_dict(bad)
        check(False, "a bad key raises SceneError")
    except stokesvdb.SceneError as e:
        check(isinstance(e, ValueError) and "resolutoin: unknown key" in str(e), "a bad key: %s" % str(e)[:80])

    # 5. checkpoint and resume
    whole = stokesvdb.Simulation(scene())
    whole.advance(2)
    xw, vw = whole.particles()
    with tempfile.TemporaryDirectory() as d:
        path = sim.checkpoint(d)
        resumed = stokesvdb.Simulation.resume(scene(), d)
        resumed.advance(1)
        xr, vr = resumed.particles()
        check(os.path.exists(path) and resumed.frame == 2 and np.array_equal(xr, xw) and np.array_equal(vr, vw),
              "resumed from %s: frame 2 bit-identical" % os.path.basename(path))

    # 6. KeyboardInterrupt inside a step
    part = stokesvdb.Simulation(scene())
    seen = []

    def progress(stats):
        seen.append(stats["step"])
        if len(seen) == 3:
            signal.raise_signal(signal.SIGINT)  # Python's handler raises at the next iteration's poll

    try:
        part.advance(2, progress=progress)
        check(False, "SIGINT raises KeyboardInterrupt")
    except KeyboardInterrupt:
        check(part.steps == 3, "SIGINT after step 3: KeyboardInterrupt, %d steps kept" % part.steps)
    part.advance(2 - part.frame)
    xp, vp = part.particles()
    check(np.array_equal(xp, xw) and np.array_equal(vp, vw),
          "advanced again after the interrupt: frame 2 bit-identical")

    # 7. frames
    with tempfile.TemporaryDirectory() as d:
        vdb = whole.write_frame(d)
        names = []
        try:
            import pyopenvdb
            names = sorted(grid.name for grid in pyopenvdb.readAllGridMetadata(vdb))
            check(names == ["surface", "vel"], "write_frame: %s holds %s" % (os.path.basename(vdb), names))
        except ImportError:
            check(os.path.getsize(vdb) > 0, "write_frame: %s written (python3-openvdb absent)" % vdb)

    if failures:
        print("%d failed" % len(failures))
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
