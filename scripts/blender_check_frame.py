# Imports a frame of `stokesvdb run` into Blender (background mode) and checks where it lands:
#
#   blender -b --factory-startup --python-exit-code 1 --python scripts/blender_check_frame.py -- \
#       FRAME.ply FRAME.vdb XMIN YMIN ZMIN XMAX YMAX ZMAX TOLERANCE
#
# The mesh (Blender's PLY importer) must have a world bounding box within TOLERANCE of the expected
# one, in Blender's z-up frame; the volume (Object > Add > Volume > Import OpenVDB), whose box holds
# the level set's narrow band, must be centred there and hold it.
# Prints one line per object; raises (exit code 1) on a mismatch.
import sys

import bpy
from mathutils import Vector


def world_bbox(obj):
    corners = [obj.matrix_world @ Vector(c) for c in obj.bound_box]
    lo = [min(c[a] for c in corners) for a in range(3)]
    hi = [max(c[a] for c in corners) for a in range(3)]
    return lo, hi


def check(name, obj, expected_lo, expected_hi, tol, band=False):
    """The object's world bounding box against the expected one. With `band` (a level set volume,
    whose box holds its narrow band around the surface) its centre must match and it must hold the
    expected box."""
    lo, hi = world_bbox(obj)
    print(f"{name}: {obj.type} bounding box {[round(v, 4) for v in lo]} .. {[round(v, 4) for v in hi]}")
    for a, axis in enumerate("xyz"):
        if band:
            got, want = 0.5 * (lo[a] + hi[a]), 0.5 * (expected_lo[a] + expected_hi[a])
            if abs(got - want) > tol:
                raise RuntimeError(f"{name}: centre {axis} is {got:.4f}, expected {want:.4f} +- {tol}")
            if lo[a] > expected_lo[a] + tol or hi[a] < expected_hi[a] - tol:
                raise RuntimeError(f"{name}: its box does not hold the liquid along {axis}")
            continue
        for got, want, side in ((lo[a], expected_lo[a], "min"), (hi[a], expected_hi[a], "max")):
            if abs(got - want) > tol:
                raise RuntimeError(f"{name}: {side} {axis} is {got:.4f}, expected {want:.4f} +- {tol}")


args = sys.argv[sys.argv.index("--") + 1:]
ply, vdb = args[0], args[1]
numbers = [float(v) for v in args[2:9]]
expected_lo, expected_hi, tol = numbers[0:3], numbers[3:6], numbers[6]

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_mesh.ply(filepath=ply)
mesh = bpy.context.selected_objects[0]
check("mesh", mesh, expected_lo, expected_hi, tol)

bpy.ops.object.volume_import(filepath=vdb, files=[{"name": vdb.split("/")[-1]}],
                             directory=vdb[: vdb.rfind("/") + 1])
volume = [o for o in bpy.context.scene.objects if o.type == "VOLUME"][0]
volume.data.grids.load()
bpy.context.view_layer.update()
check("volume", volume, expected_lo, expected_hi, tol, band=True)
print("blender_check_frame: OK")
