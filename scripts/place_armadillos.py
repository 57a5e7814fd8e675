#!/usr/bin/env python3
"""Places the nine armadillos of the shipped scenes and prints their "liquid" entries.

    python3 scripts/place_armadillos.py side-by-side [MESH]   # scenes/armadillos.json
    python3 scripts/place_armadillos.py pile [MESH]           # scenes/armadillo_pile.json
    python3 scripts/place_armadillos.py --check               # both against the shipped files

MESH defaults to data/meshes/armadillo.obj beside this script. Both layouts draw the same nine
uniformly random orientations from the seed 20210509 (Shoemake's unit quaternion, written as
extrinsic x, then y, then z angles) and scale the armadillo to 0.25 m tall:

- side-by-side: each at a random place in the 1 x 1.6 x 1 m box, 3 cm from the walls, its bounding
  box at least 10 cm above the floor, bounding spheres 2 cm apart;
- pile: each at a random (x, z) in the 0.34 x 0.34 m container, 2.5 cm from the walls, lowered
  until its bounding box rests 2 cm above the floor gap (10 cm) or above the boxes placed before
  it, as if dropped one at a time: a column in which each lands on those below.

--check exits with status 1 when a shipped scene's liquid entries differ from what this prints.
"""
import json
import math
import os
import random
import sys

SEED = 20210509
HEIGHT = 0.25  # metres, armadillo height after scaling
HERE = os.path.dirname(os.path.abspath(__file__))
MESH = os.path.join(HERE, "..", "data", "meshes", "armadillo.obj")
SCENES = {"side-by-side": "armadillos.json", "pile": "armadillo_pile.json"}


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def rx(t):
    c, s = math.cos(t), math.sin(t)
    return [[1, 0, 0], [0, c, -s], [0, s, c]]


def ry(t):
    c, s = math.cos(t), math.sin(t)
    return [[c, 0, s], [0, 1, 0], [-s, 0, c]]


def rz(t):
    c, s = math.cos(t), math.sin(t)
    return [[c, -s, 0], [s, c, 0], [0, 0, 1]]


def random_rotation_degrees(rng):
    """A uniform random rotation as extrinsic x, y, z angles in degrees (rounded to 0.1)."""
    u1, u2, u3 = rng.random(), rng.random(), rng.random()
    x, y = math.sqrt(1 - u1) * math.sin(2 * math.pi * u2), math.sqrt(1 - u1) * math.cos(2 * math.pi * u2)
    z, w = math.sqrt(u1) * math.sin(2 * math.pi * u3), math.sqrt(u1) * math.cos(2 * math.pi * u3)
    r = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    b = math.asin(max(-1.0, min(1.0, -r[2][0])))
    a, c = math.atan2(r[2][1], r[2][2]), math.atan2(r[1][0], r[0][0])
    return [round(math.degrees(t), 1) for t in (a, b, c)]


def rotated(points, scale, deg):
    """The mesh points scaled and turned by deg (x, then y, then z), with their bounding box."""
    r = matmul(rz(math.radians(deg[2])), matmul(ry(math.radians(deg[1])), rx(math.radians(deg[0]))))
    q = [[sum(r[i][k] * scale * p[k] for k in range(3)) for i in range(3)] for p in points]
    lo = [min(v[i] for v in q) for i in range(3)]
    hi = [max(v[i] for v in q) for i in range(3)]
    return q, lo, hi


def side_by_side(rng, points, scale):
    domain = ((0.0, 0.0, 0.0), (1.0, 1.6, 1.0))
    floor_gap, gap, wall_gap = 0.1, 0.02, 0.03
    placed, out = [], []
    for n in range(9):
        deg = random_rotation_degrees(rng)
        q, lo, hi = rotated(points, scale, deg)
        c = [(lo[i] + hi[i]) / 2 for i in range(3)]
        radius = max(math.dist(v, c) for v in q)
        for _ in range(100000):
            t = [rng.uniform(domain[0][i] + wall_gap - lo[i], domain[1][i] - wall_gap - hi[i]) for i in range(3)]
            if t[1] + lo[1] < domain[0][1] + floor_gap:
                continue
            centre = [t[i] + c[i] for i in range(3)]
            if all(math.dist(centre, pc) >= radius + pr + gap for pc, pr in placed):
                break
        else:
            sys.exit("could not place armadillo %d" % n)
        placed.append((centre, radius))
        out.append((deg, t))
    return out


def pile(rng, points, scale):
    width = 0.34  # the container's floor, width x width (the domain's walls)
    floor_gap, gap, wall_gap = 0.1, 0.02, 0.025
    boxes, out = [], []
    for _ in range(9):
        deg = random_rotation_degrees(rng)
        _, lo, hi = rotated(points, scale, deg)
        t = [rng.uniform(wall_gap - lo[i], width - wall_gap - hi[i]) if i != 1 else 0.0 for i in range(3)]
        bottom = floor_gap
        for blo, bhi in boxes:
            if all(t[i] + lo[i] < bhi[i] and t[i] + hi[i] > blo[i] for i in (0, 2)):
                bottom = max(bottom, bhi[1] + gap)
        t[1] = bottom - lo[1]
        boxes.append(([t[i] + lo[i] for i in range(3)], [t[i] + hi[i] for i in range(3)]))
        out.append((deg, t))
    print("top of the column: %.3f m" % max(b[1][1] for b in boxes), file=sys.stderr)
    return out


def liquid_entries(layout, mesh):
    """The nine "liquid" entries (dicts) of the layout, as the scene files hold them."""
    points = [tuple(map(float, line.split()[1:4])) for line in open(mesh) if line.startswith("v ")]
    ys = [p[1] for p in points]
    scale = round(HEIGHT / (max(ys) - min(ys)), 7)
    rng = random.Random(SEED)
    placements = side_by_side(rng, points, scale) if layout == "side-by-side" else pile(rng, points, scale)
    return [{"shape": "mesh", "file": "../data/meshes/armadillo.obj", "scale": scale, "rotation_degrees": deg,
             "translation": [round(v, 4) for v in t]} for deg, t in placements]


def print_entries(entries):
    for n, e in enumerate(entries):
        print('    {"shape": "mesh", "file": "%s", "scale": %s,\n'
              '     "rotation_degrees": [%s, %s, %s], "translation": [%s, %s, %s]}%s'
              % (e["file"], e["scale"], *e["rotation_degrees"], *e["translation"], "," if n < 8 else ""))


def check():
    """Each shipped scene's liquid entries against the layout's (numbers compared exactly)."""
    status = 0
    for layout, name in SCENES.items():
        path = os.path.join(HERE, "..", "scenes", name)
        shipped = json.load(open(path))["liquid"]
        made = liquid_entries(layout, MESH)
        if shipped != made:
            status = 1
            print("%s: its liquid entries differ from `place_armadillos.py %s`" % (name, layout), file=sys.stderr)
        else:
            print("%s: the nine armadillos of `place_armadillos.py %s`" % (name, layout))
    return status


def main(argv):
    if argv[1:] == ["--check"]:
        return check()
    if len(argv) not in (2, 3) or argv[1] not in SCENES:
        print("usage: %s side-by-side|pile [MESH] | --check" % os.path.basename(argv[0]), file=sys.stderr)
        return 2
    print_entries(liquid_entries(argv[1], argv[2] if len(argv) == 3 else MESH))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
