#!/usr/bin/python3
"""A frame of the default scene read back as a renderer would, with python3-openvdb (Debian 12).

    frame_grids_test.py ROOT STOKESVDB

Runs scenes/default.json for one frame (no preview) and reads frame_0001.vdb:
- the grids are "surface" (a level set) and "vel" (Vec3f, cell-centred); the points grid that
  output.particles adds is one pyopenvdb cannot read (tests/sim/test_geometry.cpp reads it);
- every grid carries the frame's metadata: time 1/24 s, frame 1, dx 0.2 / 32 m, scene "default",
  up axis "y" and the program's version (as `stokesvdb --version` prints it);
- the ball is in free fall until t = 0.064 s (it starts 2 cm above the floor): the mean of "vel"
  over the voxels inside the surface is (0, -g t, 0) to 2e-4 of g t, and its rms difference from
  it stays below 1e-2 of g t (printed): what is left is the volume control's divergence target,
  which moves the surface along its normal (keep_volume).
Exits 77 (skipped) where the pyopenvdb module is missing (Debian: python3-openvdb).
"""
import json
import math
import os
import subprocess
import sys
import tempfile


def main():
    if len(sys.argv) != 3:
        print(__doc__)
        return 2
    root, program = sys.argv[1:]
    try:
        import pyopenvdb as vdb
    except ImportError:
        print("frame_grids_test: the pyopenvdb module is missing (Debian: python3-openvdb): skipped")
        return 77
    with tempfile.TemporaryDirectory() as tmp:
        scene = json.load(open(os.path.join(root, "scenes", "default.json")))
        scene["output"].update({"particles": False, "preview": False})
        path = os.path.join(tmp, "default.json")
        json.dump(scene, open(path, "w"))
        out = os.path.join(tmp, "out")
        subprocess.run([program, "run", path, "--out", out, "--frames", "1", "--threads", "2"], check=True,
                       stdout=subprocess.DEVNULL)
        version = subprocess.run([program, "--version"], check=True, capture_output=True, text=True).stdout.split()[-1]
        frame = os.path.join(out, "frame_0001.vdb")
        failures = []
        names = [g.name for g in vdb.readAllGridMetadata(frame)]
        if names != ["surface", "vel"]:
            failures.append("grid names %s, expected surface, vel" % names)
        t, dx = 1.0 / 24.0, 0.2 / 32.0
        expected = {"time": t, "frame": 1, "dx": dx, "scene": "default", "up_axis": "y", "stokesvdb_version": version}
        for g in vdb.readAllGridMetadata(frame):
            for key, value in expected.items():
                got = g.metadata.get(key)
                ok = abs(got - value) <= 1e-12 * abs(value) if isinstance(value, float) and got is not None else got == value
                if not ok:
                    failures.append("grid %s: metadata %s = %r, expected %r" % (g.name, key, got, value))
        surface = vdb.read(frame, "surface")
        vel = vdb.read(frame, "vel")
        if surface.gridClass != vdb.GridClass.LEVEL_SET:
            failures.append("surface: class %s, not a level set" % surface.gridClass)
        phi = surface.getConstAccessor()
        fall = -9.81 * t
        sum2, mean, count = 0.0, [0.0, 0.0, 0.0], 0
        for item in vel.citerOnValues():
            if not item.active or item.count != 1 or phi.getValue(item.min) >= 0.0:
                continue
            v = item.value
            sum2 += v[0] ** 2 + (v[1] - fall) ** 2 + v[2] ** 2
            mean = [m + c for m, c in zip(mean, v)]
            count += 1
        if count < 1000:
            failures.append("vel: %d voxels inside the surface, expected the ball's ~2,000" % count)
        count = max(count, 1)
        rms = math.sqrt(sum2 / count) / abs(fall)
        mean = [m / count for m in mean]
        drift = math.sqrt(mean[0] ** 2 + (mean[1] - fall) ** 2 + mean[2] ** 2) / abs(fall)
        print("frame 1: grids %s; vel on %d voxels inside: mean (%.6f, %.6f, %.6f) m/s against (0, %.6f, 0), "
              "off by %.2e; rms of vel - (0, -g t, 0) %.2e of g t" % (", ".join(names), count, *mean, fall, drift, rms))
        if not drift < 2e-4:
            failures.append("the mean of vel differs from free fall by %.2e of g t" % drift)
        if not rms < 1e-2:
            failures.append("vel differs from free fall by %.2e (relative rms)" % rms)
        for f in failures:
            print("FAIL: " + f)
        return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
