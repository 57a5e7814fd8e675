#!/usr/bin/env python3
"""Scene files against scenes/scene.schema.json, and the schema against the parser.

    python3 tests/scene_schema_test.py SOURCE_DIR STOKESVDB_BINARY

1. Every scenes/*.json validates against the schema (the schema only: running the shipped scenes
   would be long; tests/sim/test_scene.cpp parses them).
2. Mutated scenes, each a valid minimal scene with one thing broken (an unknown key at each level,
   a wrong type, a number just outside each end of its range, a bad enum string, a missing
   required key, a bad shape kind, ...): the schema must reject each, and so must the parser,
   `stokesvdb run FILE --out DIR --frames 1` exiting with status 2 (bad scene) and a message that
   names the broken key's path.
3. Valid variants (every key, the inclusive ends of the ranges, integers written 8.0, ...): the
   schema must accept each, and so must the parser: `run` at resolution 8 for 1 frame of a few
   milliseconds must not exit with 2 and must print its start line. (`--frames 0` would be
   quicker, but the override is checked against the same [1, 1e6] as the file's value.)
4. Semantic checks that a JSON Schema cannot express (max > min, liquid inside the domain, padding
   < tile, stop > start, ...; listed in the schema's "$comment"): the parser must reject each; the
   schema accepts them, which is reported, not an error.
5. Every key documented: at each level (top, domain, material, model, solver, output, camera, each
   shape and emitter kind) the keys the parser lists for an unknown key ("expected one of: ...")
   must be the schema's properties there, each with a "description", and each must be written
   `key` in scenes/README.md. A key the parser reads but the schema or the page leaves out fails,
   and so does a schema key the parser does not read.

`--frames 1` replaces the file's `frames` without reading it, so the cases that break `frames`
run without it (their files say `"frames": 1` otherwise).

Exit status: 0 when schema and parser agree on every case, 1 on any disagreement (named), 77
(skipped) when the jsonschema module is missing (Debian: python3-jsonschema).
"""
import copy
import glob
import json
import os
import re
import subprocess
import sys
import tempfile

try:
    import jsonschema
except ImportError:
    print("scene_schema_test: the jsonschema module is missing (Debian: python3-jsonschema): skipped")
    sys.exit(77)

DELETE = object()  # a mutation that removes the key


class Case:
    def __init__(self, name, scene, override_frames=True, where=None):
        self.name = name
        self.scene = scene
        self.override_frames = override_frames
        self.where = where  # the key path the parser's message must name ("liquid[0].radius")


def parser_path(path):
    """"liquid.0.radius" -> "liquid[0].radius", as the parser's messages write it."""
    out = ""
    for k in path.split("."):
        out += "[%s]" % k if k.isdigit() else ("." if out else "") + k
    return out


def minimal_scene():
    """The valid scene every case starts from: a ball of liquid, 8^3 cells, one 1 ms frame."""
    return {
        "name": "schema_case",
        "domain": {"min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 1.0]},
        "resolution": 8,
        "frames": 1,
        "fps": 1000,
        "material": {"density": 1000.0, "viscosity": 1.0},
        "liquid": [{"shape": "sphere", "center": [0.5, 0.5, 0.5], "radius": 0.25}],
        "output": {"preview": False},
    }


def with_changes(changes, base=None):
    """A copy of `base` (default: the minimal scene) with {"a.b.0.c": value} applied; missing objects
    on the way are created, DELETE removes the key."""
    scene = copy.deepcopy(minimal_scene() if base is None else base)
    for path, value in changes.items():
        keys = [int(k) if k.isdigit() else k for k in path.split(".")]
        node = scene
        for k in keys[:-1]:
            if isinstance(k, str) and k not in node:
                node[k] = {}
            node = node[k]
        if value is DELETE:
            del node[keys[-1]]
        else:
            node[keys[-1]] = value
    return scene


def mesh_file(src):
    return os.path.join(src, "data", "meshes", "armadillo_lowres.obj")


def shapes(src):
    """One valid example of each shape, emitter and camera, to break one key of."""
    return {
        "box": {"shape": "box", "min": [0.3, 0.3, 0.3], "max": [0.7, 0.7, 0.7]},
        "sphere": {"shape": "sphere", "center": [0.5, 0.5, 0.5], "radius": 0.25},
        "plane": {"shape": "plane", "point": [0.0, 0.1, 0.0], "normal": [0.0, 1.0, 0.0]},
        # the low-resolution armadillo (1 unit tall) scaled to 0.4 m, in the middle of the domain
        "mesh": {"shape": "mesh", "file": mesh_file(src), "scale": 0.4, "translation": [0.6, 0.35, 0.4]},
        "disc": {"shape": "disc", "center": [0.5, 0.8, 0.5], "radius": 0.1, "normal": [0.0, -1.0, 0.0],
                 "velocity": [0.0, -0.5, 0.0]},
        "box_emitter": {"shape": "box", "min": [0.4, 0.7, 0.4], "max": [0.6, 0.8, 0.6], "velocity": [0.0, -0.5, 0.0]},
        "camera": {"eye": [2.0, 1.5, 2.0], "target": [0.5, 0.5, 0.5]},
    }


def shape_with(src, kind, changes):
    return with_changes(changes, shapes(src)[kind])


def mutated_cases(src):
    """Each breaks one thing of the minimal scene; schema and parser must both reject it."""
    c = []

    def add(name, changes, override_frames=True):
        c.append(Case(name, with_changes(changes), override_frames, parser_path(next(iter(changes)))))

    # -- an unknown key at each level
    add("unknown top-level key", {"resolutoin": 8})
    add("unknown key in domain", {"domain.open-top": True})
    add("unknown key in material", {"material.mu": 1.0})
    add("unknown key in model", {"model.tiles": 8})
    add("unknown key in solver", {"solver.tol": 1e-6})
    add("unknown key in output", {"output.previews": False})
    add("unknown key in output.camera", {"output.camera": dict(shapes(src)["camera"], up=[0.0, 1.0, 0.0])})
    add("box key on a liquid sphere", {"liquid.0.min": [0.0, 0.0, 0.0]})
    add("sphere key on a liquid box", {"liquid": [shape_with(src, "box", {"radius": 0.1})]})
    add("sphere key on a solid plane", {"solids": [shape_with(src, "plane", {"radius": 0.1})]})
    add("plane key on a liquid mesh", {"liquid": [shape_with(src, "mesh", {"normal": [0.0, 1.0, 0.0]})]})
    add("box key on a disc emitter", {"emitters": [shape_with(src, "disc", {"min": [0.0, 0.0, 0.0]})]})
    add("disc key on a box emitter", {"emitters": [shape_with(src, "box_emitter", {"radius": 0.1})]})
    add("a top-level key in the wrong case", {"Name": "x"})

    # -- wrong types
    add("resolution as a string", {"resolution": "8"})
    add("resolution not an integer", {"resolution": 8.5})
    add("name as a number", {"name": 5})
    add("reseed as a string", {"reseed": "yes"})
    add("keep_volume as a number", {"keep_volume": 1})
    add("fps as a boolean", {"fps": True})
    add("gravity with 2 components", {"gravity": [0.0, -9.81]})
    add("gravity with 4 components", {"gravity": [0.0, -9.81, 0.0, 0.0]})
    add("domain.min as an object", {"domain.min": {"x": 0.0, "y": 0.0, "z": 0.0}})
    add("material.density as a string", {"material.density": "1000"})
    add("model as a string", {"model": "quadratic"})
    add("solver.warm_start null", {"solver.warm_start": None})
    add("output as an array", {"output": []})
    add("output.preview as a number", {"output.preview": 0})
    add("liquid as an object", {"liquid": shapes(src)["sphere"]})
    add("a liquid item as a string", {"liquid": ["sphere"]})
    add("a velocity component as a string", {"liquid.0.velocity": [0.0, "1", 0.0]})
    add("seed as a float with a fraction", {"seed": 1.5})
    c.append(Case("the top level as an array", [minimal_scene()], where="top level"))

    # -- a number just outside each end of its range
    for path, values in [
        ("resolution", [0, 4097]),
        ("frames", [0, 1000001]),
        ("fps", [0, -1, 100001]),
        ("cfl", [0, 100.5]),
        ("max_substeps", [0, 100001]),
        ("material.density", [0, -0.0, 1.00001e7]),
        ("material.viscosity", [-0.001, 1.00001e12]),
        ("volume_control", [-0.01, 1.01]),
        ("particles_per_cell_axis", [0, 9]),
        ("model.tile", [1, 257]),
        ("model.padding", [0, 256]),
        ("model.band_air", [-1, 65]),
        ("model.band_solid", [-1, 65]),
        ("model.min_region", [0, 4097]),
        ("solver.tolerance", [0, 0.5000001]),
        ("solver.max_iterations", [0, 100000001]),
        ("solver.multigrid_degree", [-1, 17]),
        ("solver.retries", [-1, 11]),
        ("output.preview_width", [15, 16385]),
        ("output.preview_height", [15, 16385]),
        ("output.checkpoint_every", [-1, 1000001]),
        ("output.mesh_subdivisions", [-1, 4]),
        ("seed", [-1, 2**63]),
        ("liquid.0.radius", [0, -0.25, 1000001]),
    ]:
        for v in values:
            add("%s = %r" % (path, v), {path: v}, override_frames=path != "frames")
    add("a gravity component above 1e4", {"gravity": [0.0, 10001.0, 0.0]})
    add("a gravity component below -1e4", {"gravity": [0.0, -10000.5, 0.0]})
    add("a domain coordinate below -1e6", {"domain.min": [-1000000.5, 0.0, 0.0]})
    add("a camera coordinate above 1e6", {"output.camera": {"eye": [1000001.0, 1.0, 1.0], "target": [0.5, 0.5, 0.5]}})
    add("a liquid velocity above 1e4", {"liquid.0.velocity": [10001.0, 0.0, 0.0]})
    add("emitter thickness = 0", {"emitters": [shape_with(src, "disc", {"thickness": 0})]})
    add("emitter start = -1", {"emitters": [shape_with(src, "disc", {"start": -1})]})
    add("emitter stop above 1e7", {"emitters": [shape_with(src, "box_emitter", {"stop": 10000001})]})
    add("mesh scale = 0", {"liquid": [shape_with(src, "mesh", {"scale": 0})]})
    add("mesh rotation above 36000 degrees",
        {"liquid": [shape_with(src, "mesh", {"rotation_degrees": [0, 36001, 0]})]})
    add("mesh rotation below -36000 degrees",
        {"liquid": [shape_with(src, "mesh", {"rotation_degrees": [-36001, 0, 0]})]})
    add("mesh translation above 1e6", {"liquid": [shape_with(src, "mesh", {"translation": [2e6, 0.5, 0.5]})]})
    add("plane normal component above 1e6", {"solids": [shape_with(src, "plane", {"normal": [0.0, 2e6, 0.0]})]})

    # -- bad enum strings
    add("viscosity \"Coupled\"", {"viscosity": "Coupled"})
    add("model.type \"cubic\"", {"model.type": "cubic"})
    add("model.tile_cache \"all\"", {"model.tile_cache": "all"})
    add("solver.preconditioner \"ilu\"", {"solver.preconditioner": "ilu"})
    add("solver.rows \"dense\"", {"solver.rows": "dense"})
    add("solver.stencils \"row\"", {"solver.stencils": "row"})
    add("solver.multigrid_method \"cg\"", {"solver.multigrid_method": "cg"})
    add("output.up_axis \"x\"", {"output.up_axis": "x"})
    add("output.up_axis \"Z\"", {"output.up_axis": "Z"})

    # -- bad shape kinds
    add("a liquid plane (solids only)", {"liquid": [shapes(src)["plane"]]})
    add("a liquid cylinder", {"liquid.0.shape": "cylinder"})
    add("a solid disc (emitters only)", {"solids": [shape_with(src, "sphere", {"shape": "disc"})]})
    add("a sphere emitter", {"emitters": [shape_with(src, "sphere", {"velocity": [0.0, 0.0, 0.0]})]})
    add("a shape without \"shape\"", {"liquid.0.shape": DELETE})
    add("\"shape\" as a number", {"liquid.0.shape": 1})

    # -- missing required keys
    for path in ["name", "domain", "resolution", "frames", "material", "material.density", "material.viscosity",
                 "domain.max", "liquid.0.radius", "liquid.0.center"]:
        add("missing " + path, {path: DELETE}, override_frames=path != "frames")
    add("missing box max", {"liquid": [shape_with(src, "box", {"max": DELETE})]})
    add("missing plane normal", {"solids": [shape_with(src, "plane", {"normal": DELETE})]})
    add("missing mesh file", {"liquid": [shape_with(src, "mesh", {"file": DELETE})]})
    add("missing camera target", {"output.camera": {"eye": [2.0, 1.5, 2.0]}})
    add("missing emitter velocity", {"emitters": [shape_with(src, "disc", {"velocity": DELETE})]})
    add("missing disc normal", {"emitters": [shape_with(src, "disc", {"normal": DELETE})]})
    add("missing emitter box min", {"emitters": [shape_with(src, "box_emitter", {"min": DELETE})]})

    # -- other things the schema can say
    add("a zero plane normal", {"solids": [shape_with(src, "plane", {"normal": [0.0, 0.0, 0.0]})]})
    add("a zero disc normal", {"emitters": [shape_with(src, "disc", {"normal": [0, 0, 0]})]})
    add("neither liquid nor emitters", {"liquid": DELETE})
    add("an empty liquid list and no emitters", {"liquid": []})
    add("an empty liquid list and an empty emitter list", {"liquid": [], "emitters": []})
    add("a control character in name", {"name": "a\u0001b"})
    add("a newline in name", {"name": "a\nb"})
    add("a DEL character in name", {"name": "a\u007fb"})
    add("a carriage return in description", {"description": "line 1\r\nline 2"})
    add("a name of 4097 characters", {"name": "n" * 4097})
    add("an empty mesh file name", {"liquid": [shape_with(src, "mesh", {"file": ""})]})
    add("10001 liquid shapes", {"liquid": [shapes(src)["sphere"]] * 10001})
    return c


def valid_variants(src):
    """Each must be accepted by both. Kept tiny: 8^3 cells, one frame of at most 1 ms."""
    s = shapes(src)
    full = with_changes({
        "name": "schema_full \u00e9",  # non-ASCII is fine
        "description": "every key:\n\tthe inclusive ends of the ranges",
        "domain.open_top": True,
        "resolution": 8.0,  # integers may be written 8.0
        "fps": 1000.0,
        "cfl": 100,
        "max_substeps": 100000,
        "material.viscosity": 0,
        "gravity": [0.0, -9.81, 0.0],
        "viscosity": "decoupled",
        "model": {"type": "uniform", "tile": 256, "padding": 255, "band_air": 0, "band_solid": 64, "min_region": 4096,
                  "tile_cache": "none"},
        "solver": {"tolerance": 0.5, "max_iterations": 100000000, "preconditioner": "none", "rows": "padded",
                   "stencils": "blocks", "multigrid_degree": 16, "multigrid_method": "minres", "warm_start": False,
                   "retries": 10},
        "particles_per_cell_axis": 1,
        "reseed": False,
        "keep_volume": False,
        "volume_control": 1,
        "liquid": [dict(s["box"], velocity=[0.0, -0.1, 0.0]), s["sphere"]],
        "solids": [{"shape": "box", "min": [-1000000, -1.0, -1.0], "max": [1000000, 0.1, 2.0]}, s["plane"],
                   dict(s["sphere"], center=[0.9, 0.9, 0.9], radius=1e-9, velocity=[-10000, 0, 10000.0])],
        "emitters": [dict(s["disc"], thickness=0.05, start=0, stop=10000000), dict(s["box_emitter"], start=1e7)],
        "output": {"particles": True, "preview": False, "preview_width": 16, "preview_height": 16384,
                   "camera": s["camera"]},
        "seed": 2**63 - 1,
    })
    return [
        Case("the minimal scene", minimal_scene()),
        Case("every key but \"$schema\" and the output mesh and checkpoint keys", full),
        Case("a \"$schema\" key", dict([("$schema", "scene.schema.json")] + list(minimal_scene().items()))),
        Case("output.mesh, up_axis, checkpoint_every",
             with_changes({"output": {"preview": False, "mesh": True, "up_axis": "z", "checkpoint_every": 0}})),
        Case("checkpoint_every at its upper end", with_changes({"output.checkpoint_every": 1000000})),
        Case("emitters only", with_changes({"liquid": DELETE, "emitters": [s["disc"]]})),
        Case("a liquid mesh, a solid mesh and the other model choices",
             with_changes({"liquid": [dict(s["mesh"], rotation_degrees=[36000, -36000, 90.5], velocity=[0, 1, 0])],
                           "solids": [dict(s["mesh"], scale=0.001, translation=[0.1, 0.1, 0.1])],
                           "model": {"type": "quadratic", "tile": 2, "padding": 1, "tile_cache": "shapes"},
                           "solver": {"tolerance": 1e-12, "max_iterations": 100000, "preconditioner": "jacobi",
                                      "rows": "compact", "stencils": "rows", "multigrid_degree": 0, "retries": 0,
                                      "multigrid_method": "gmres"},
                           "viscosity": "none", "particles_per_cell_axis": 8, "seed": 0,
                           "fps": 100000, "cfl": 1e-9, "max_substeps": 1})),
    ]


def semantic_cases(src):
    """Errors a JSON Schema cannot express: the parser rejects them, the schema accepts them."""
    s = shapes(src)
    return [
        Case("domain max not above min", with_changes({"domain.max": [1.0, 0.0, 1.0]})),
        Case("liquid box max not above min", with_changes({"liquid": [dict(s["box"], max=[0.7, 0.3, 0.7])]})),
        Case("liquid sphere outside the domain", with_changes({"liquid.0.center": [5.0, 5.0, 5.0]})),
        Case("model.padding = model.tile", with_changes({"model": {"tile": 8, "padding": 8}})),
        Case("emitter stop = start", with_changes({"emitters": [dict(s["disc"], start=1, stop=1)]})),
        Case("disc emitter centred outside the domain",
             with_changes({"emitters": [dict(s["disc"], center=[2, 2, 2])]})),
        Case("camera eye = target", with_changes({"output.camera": {"eye": [1, 1, 1], "target": [1, 1, 1]}})),
        Case("a mesh file that does not exist", with_changes({"liquid": [dict(s["mesh"], file="no_such.obj")]})),
        Case("a direction shorter than 1e-12", with_changes({"solids": [dict(s["plane"], normal=[1e-13, 0, 0])]})),
    ]


UNDOCUMENTED = "zz_undocumented_key"


def documentation_levels(src):
    """(level name, a scene with UNDOCUMENTED at that level, the schema node's JSON pointer)."""
    s = shapes(src)
    levels = [
        ("top level", with_changes({UNDOCUMENTED: 1}), "#"),
        ("domain", with_changes({"domain." + UNDOCUMENTED: 1}), "#/properties/domain"),
        ("material", with_changes({"material." + UNDOCUMENTED: 1}), "#/properties/material"),
        ("model", with_changes({"model." + UNDOCUMENTED: 1}), "#/properties/model"),
        ("solver", with_changes({"solver." + UNDOCUMENTED: 1}), "#/properties/solver"),
        ("output", with_changes({"output." + UNDOCUMENTED: 1}), "#/properties/output"),
        ("output.camera", with_changes({"output.camera": dict(s["camera"], **{UNDOCUMENTED: 1})}),
         "#/properties/output/properties/camera"),
    ]
    for kind, where, definition in [("box", "liquid", "boxShape"), ("sphere", "liquid", "sphereShape"),
                                     ("plane", "solids", "planeShape"), ("mesh", "liquid", "meshShape"),
                                     ("disc", "emitters", "discEmitter"), ("box_emitter", "emitters", "boxEmitter")]:
        levels.append(("%s %s" % (where, kind), with_changes({where: [dict(s[kind], **{UNDOCUMENTED: 1})]}),
                       "#/definitions/" + definition))
    return levels


def schema_node(schema, pointer):
    node = schema
    for key in pointer.lstrip("#/").split("/") if pointer != "#" else []:
        node = node[key]
    return node


def parser_keys(message):
    """The keys a parser message lists after 'expected one of: ' (a, b, c), or None."""
    m = re.search(r"expected one of: (.*)$", message)
    return [k.strip() for k in m.group(1).split(",")] if m else None


def documentation_failures(src, binary, schema, directory):
    """Section 5 of the module comment: parser, schema and scenes/README.md name the same keys."""
    with open(os.path.join(src, "scenes", "README.md"), encoding="utf-8") as f:
        page = f.read()
    failures, checked = [], 0
    for index, (level, scene, pointer) in enumerate(documentation_levels(src)):
        rc, first, _ = run_parser(binary, Case(level, scene), directory, 900 + index)
        listed = parser_keys(first)
        if rc != 2 or listed is None:
            failures.append("documentation, %s: the parser did not list its keys (exit %s): %s" % (level, rc, first))
            continue
        properties = schema_node(schema, pointer).get("properties", {})
        in_schema = set(properties)
        for key in sorted(set(listed) - in_schema):
            failures.append("documentation, %s: the parser reads \"%s\", the schema does not list it" % (level, key))
        for key in sorted(in_schema - set(listed)):
            failures.append("documentation, %s: the schema lists \"%s\", the parser does not read it" % (level, key))
        for key in sorted(set(listed) & in_schema):
            checked += 1
            node = properties[key]
            if not node.get("description") and "$ref" not in node:
                failures.append("documentation, %s: the schema's \"%s\" has no description" % (level, key))
            if "`%s`" % key not in page and '`"%s"' % key not in page:
                failures.append("documentation, %s: scenes/README.md never writes `%s`" % (level, key))
    return failures, checked


def run_parser(binary, case, directory, index):
    """Runs `stokesvdb run` on the case; returns (exit status, first line of stderr, stderr)."""
    path = os.path.join(directory, "case_%03d.json" % index)
    with open(path, "w", encoding="utf-8") as f:
        json.dump(case.scene, f, ensure_ascii=True)
    command = [binary, "run", path, "--out", os.path.join(directory, "out_%03d" % index), "--threads", "1"]
    if case.override_frames:
        command += ["--frames", "1"]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    try:
        p = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, timeout=300)
    except subprocess.TimeoutExpired:
        return None, "(timed out after 300 s)", ""
    err = p.stderr.decode("utf-8", "replace")
    return p.returncode, (err.splitlines() or [""])[0], err


def schema_enum(schema, dotted):
    """The "enum" of the schema's property at a parser key path ("solver.preconditioner"), or None."""
    node = schema
    for key in dotted.split("."):
        node = node.get("properties", {}).get(key) if isinstance(node, dict) else None
        if node is None:
            return None
    return node.get("enum")


def parser_names(message):
    """The names a parser message lists after 'expected one of' ("a", "b"), or None."""
    m = re.search(r'expected one of ((?:"[^"]*"(?:, )?)+)', message)
    return re.findall(r'"([^"]*)"', m.group(1)) if m else None


def schema_errors(validator, scene):
    return sorted(validator.iter_errors(scene), key=lambda e: [str(p) for p in e.absolute_path])


def where(error):
    return ".".join(str(p) for p in error.absolute_path) or "top level"


def main():
    if len(sys.argv) != 3:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    src, binary = sys.argv[1], sys.argv[2]
    schema_path = os.path.join(src, "scenes", "scene.schema.json")
    with open(schema_path, encoding="utf-8") as f:
        schema = json.load(f)
    validator_class = jsonschema.validators.validator_for(schema)
    validator_class.check_schema(schema)
    validator = validator_class(schema)
    failures = []

    # 1. the shipped scenes
    shipped = sorted(p for p in glob.glob(os.path.join(src, "scenes", "*.json")) if p != schema_path)
    for path in shipped:
        with open(path, encoding="utf-8") as f:
            errors = schema_errors(validator, json.load(f))
        for e in errors:
            failures.append("%s: %s: %s" % (os.path.relpath(path, src), where(e), e.message))
    print("%d shipped scenes validated against %s" % (len(shipped), os.path.relpath(schema_path, src)))

    mutated, valid, semantic = mutated_cases(src), valid_variants(src), semantic_cases(src)
    names = [c.name for c in mutated + valid + semantic]
    assert len(names) == len(set(names)), "duplicate case names"
    schema_gaps = []
    with tempfile.TemporaryDirectory(prefix="scene_schema_test.") as directory:
        index = 0
        # 2. schema and parser must both reject
        for case in mutated:
            index += 1
            errors = schema_errors(validator, case.scene)
            rc, first, _ = run_parser(binary, case, directory, index)
            if not errors:
                failures.append("mutated \"%s\": the schema accepts it (the parser: exit %s, %s)" %
                                (case.name, rc, first))
            if rc != 2:
                failures.append("mutated \"%s\": the parser exits with %s, not 2 (schema: %s)" %
                                (case.name, rc, errors[0].message if errors else "accepted"))
            elif not re.search(": " + re.escape(case.where) + r"[:.\[]", first):
                failures.append("mutated \"%s\": the parser rejects it, but not at %s: %s" %
                                (case.name, case.where, first))
            else:
                # a bad name: the parser lists its table's names (solver/step/names.h), which must be
                # the schema's enum
                listed, enum = parser_names(first), schema_enum(schema, case.where)
                if listed is not None and enum is not None and sorted(listed) != sorted(enum):
                    failures.append("mutated \"%s\": the parser's names %s differ from the schema's enum %s" %
                                    (case.name, listed, enum))
        # 3. schema and parser must both accept
        for case in valid:
            index += 1
            errors = schema_errors(validator, case.scene)
            rc, first, err = run_parser(binary, case, directory, index)
            for e in errors:
                failures.append("valid \"%s\": the schema rejects it: %s: %s" % (case.name, where(e), e.message))
            started = first.startswith("stokesvdb run: %s at res " % case.scene["name"])
            if rc == 2 or rc is None or not started:
                failures.append("valid \"%s\": the parser rejects it or did not start (exit %s): %s" %
                                (case.name, rc, first))
        # 4. semantic errors only the parser sees
        for case in semantic:
            index += 1
            errors = schema_errors(validator, case.scene)
            rc, first, _ = run_parser(binary, case, directory, index)
            if rc != 2:
                failures.append("semantic \"%s\": the parser exits with %s, not 2" % (case.name, rc))
            if not errors:
                schema_gaps.append(case.name)
        # 5. every key documented
        documentation, documented = documentation_failures(src, binary, schema, directory)
        failures += documentation

    print("%d mutated scenes: schema and parser must both reject each" % len(mutated))
    print("%d valid variants: schema and parser must both accept each" % len(valid))
    print("%d semantic errors only the parser can see (schema accepts %d of them: expected)" %
          (len(semantic), len(schema_gaps)))
    print("%d keys over %d levels: the parser, the schema and scenes/README.md name each" %
          (documented, len(documentation_levels(src))))
    if failures:
        print("%d disagreements:" % len(failures))
        for f in failures:
            print("  " + f)
        return 1
    print("schema and parser agree on all %d cases" % (len(mutated) + len(valid) + len(semantic)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
