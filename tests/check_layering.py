#!/usr/bin/env python3
"""The layering of the source tree (docs/design.md §2), checked on every include.

    check_layering.py ROOT            fails (exit 1) naming each include that breaks a rule
    check_layering.py ROOT --graph    prints the include graph between folders
    check_layering.py --self-test     shows that a breaking include is caught

Rules: a file may include its own folder and folders of lower rank; analytic/ and sim/ are peers
that never include each other; include/ (the umbrella header) sits over sim/; app/, python/,
bench/, examples/ and tests/ sit on top. A folder that holds
sources but has no rank here fails too, so that a new folder gets its place in the layers.
Namespaces mirror the folders as `namespace stokes::sim { inline namespace step {`: the C++20
spelling `namespace stokes::sim::inline step {` fails, because ctags-based code browsers do not
parse it and see no definitions inside. OpenVDB comes in through sparse_grid/vdb_trees.h, whose
explicit instantiation declarations must precede any use of the trees: `#include <openvdb/openvdb.h>`
anywhere else fails.
"""
import os
import re
import sys
import tempfile

RANK = {
    "parallel": -1,
    "sparse_grid": 0,
    "kernels": 1,
    "solver/krylov": 2,
    "solver/problem": 3,
    "solver/reduced": 4,
    "solver/systems": 5,
    "solver/multigrid": 6,
    "solver/petsc": 7,
    "solver/step": 8,
    "analytic": 9,
    "sim/scene": 9,
    "sim/geometry": 10,
    "sim/particles": 11,
    "sim/ranks": 12,
    "sim/step": 13,
    "sim/output": 14,
    "sim/run": 15,
    "include": 16,  # the umbrella header <stokesvdb/stokesvdb.h>: the public API, over sim/
    "app": 20,
    "python": 20,
    "bench": 20,
    "examples": 20,
    "tests": 21,
}
PEERS_APART = [("analytic", "sim")]  # (a, b): nothing under a includes b, nor b a
SKIP = {"build", "build-tsan", ".git", "cmake", "scripts", "docs", "scenes"}
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)
NESTED_INLINE_NAMESPACE = re.compile(r'^\s*namespace\s+[\w:]*::\s*inline\s+\w+', re.M)
DIRECT_OPENVDB = re.compile(r'^\s*#\s*include\s+<openvdb/openvdb\.h>', re.M)
VDB_FRONT_DOOR = "sparse_grid/vdb_trees.h"


def folder_of(path):
    """The ranked folder a repository path belongs to (the longest matching prefix), or None."""
    best = None
    for f in RANK:
        if path == f or path.startswith(f + "/"):
            if best is None or len(f) > len(best):
                best = f
    return best


def sources(root):
    for dirpath, dirnames, filenames in os.walk(root):
        rel = os.path.relpath(dirpath, root)
        dirnames[:] = [d for d in dirnames if (d if rel == "." else rel + "/" + d).split("/")[0] not in SKIP
                       and not d.startswith("build")]
        for name in filenames:
            if name.endswith((".h", ".hpp", ".cpp")):
                yield os.path.normpath(os.path.join(rel, name))


def edges(root):
    """(from_file, from_folder, to_file, to_folder) for every project include."""
    for src in sources(root):
        text = open(os.path.join(root, src), encoding="utf-8", errors="replace").read()
        for inc in INCLUDE.findall(text):
            target = inc if "/" in inc else os.path.normpath(os.path.join(os.path.dirname(src), inc))
            if not os.path.isfile(os.path.join(root, target)):
                continue  # a system or generated header
            yield src, folder_of(src), target, folder_of(target)


def top(folder):
    return folder.split("/")[0]


def violations(root):
    found = []
    for src in sources(root):
        if folder_of(src) is None and os.path.dirname(src):
            found.append(f"{src}: its folder has no place in the layers (tests/check_layering.py RANK)")
        text = open(os.path.join(root, src), encoding="utf-8", errors="replace").read()
        if NESTED_INLINE_NAMESPACE.search(text):
            found.append(f"{src}: spell 'namespace a::inline b {{' as 'namespace a {{ inline namespace b {{' "
                         "(code browsers do not parse the first)")
        if src != VDB_FRONT_DOOR and DIRECT_OPENVDB.search(text):
            found.append(f"{src}: include \"{VDB_FRONT_DOOR}\" instead of <openvdb/openvdb.h> "
                         "(it declares the trees compiled once)")
    for src, a, target, b in edges(root):
        if a is None or b is None or a == b:
            continue
        if any({top(a), top(b)} == {x, y} for x, y in PEERS_APART):
            found.append(f"{src} includes {target}: {top(a)}/ and {top(b)}/ are peers and never include each other")
        elif RANK[b] >= RANK[a]:
            found.append(f"{src} includes {target}: {a}/ (rank {RANK[a]}) may include only lower layers, "
                         f"not {b}/ (rank {RANK[b]})")
    return found


def graph(root):
    counts = {}
    for _, a, _, b in edges(root):
        if a and b and a != b:
            counts[(a, b)] = counts.get((a, b), 0) + 1
    for (a, b), n in sorted(counts.items(), key=lambda e: (RANK[e[0][0]], e[0][0], RANK[e[0][1]], e[0][1])):
        print(f"{a:16s} -> {b:16s} {n:3d} include(s)")


def self_test():
    with tempfile.TemporaryDirectory() as root:
        for path, text in {"sparse_grid/a.h": '#include "kernels/b.h"\n', "kernels/b.h": "",
                           "sim/scene/c.h": '#include "analytic/d.h"\n', "analytic/d.h": "",
                           "solver/krylov/e.h": '#include "sparse_grid/a.h"\n', "misc/f.h": "",
                           "kernels/g.h": "namespace stokes::kernels::inline x {\n}\n",
                           "sim/scene/h.h": "#include <openvdb/openvdb.h>\n"}.items():
            os.makedirs(os.path.join(root, os.path.dirname(path)), exist_ok=True)
            open(os.path.join(root, path), "w").write(text)
        found = violations(root)
        expected = ["sparse_grid/a.h includes kernels/b.h", "sim/scene/c.h includes analytic/d.h", "misc/f.h",
                    "kernels/g.h: spell", "sim/scene/h.h: include"]
        missing = [e for e in expected if not any(v.startswith(e) for v in found)]
        if missing or len(found) != len(expected):
            print("self-test failed: expected", expected, "got", found)
            return 1
        print("self-test: the five breaking cases are caught, the downward include passes")
        return 0


def main(argv):
    if argv[1:] == ["--self-test"]:
        return self_test()
    root = argv[1] if len(argv) > 1 else "."
    if "--graph" in argv:
        graph(root)
        return 0
    found = violations(root)
    for v in found:
        print(v)
    if found:
        print(f"{len(found)} break(s) of the layering or the namespace spelling (docs/design.md §2)")
        return 1
    print("layering: every include goes down the layers")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
