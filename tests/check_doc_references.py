#!/usr/bin/env python3
"""Citations of docs/NOTES.md (and links into docs/design.md) resolve to headings that exist.

    check_doc_references.py ROOT          fails (exit 1) naming each broken reference as FILE:LINE
    check_doc_references.py --self-test   shows that a missing heading and a section number are caught

docs/NOTES.md has one section per topic and no section numbers, so other files cite it by the
heading's anchor, `docs/NOTES.md#the-free-surface-and-liquid-weights`, and never by number. Checked,
in every *.md file and every source file (.h, .cpp, .py, .sh, CMakeLists.txt, .json):
- `NOTES.md#slug` names a heading of docs/NOTES.md (GitHub's anchors: lower case, punctuation other
  than '-' and '_' dropped, spaces to '-', a repeated heading gets -1, -2, ...);
- a section-number citation (`NOTES §3`, `NOTES.md §3`, `NOTES.md, §3`) is an error;
- a markdown link `[text](path.md#slug)` (or `(#slug)` inside the file) that resolves to docs/NOTES.md
  or docs/design.md names one of its headings, and a link to either file points at a file that exists.
The file list comes from `git ls-files` (tracked and untracked, not ignored) in a git checkout, else
from walking ROOT (build*/ and out/ skipped). This file, whose examples cite on purpose, is skipped.
"""
import os
import re
import subprocess
import sys
import tempfile

NOTES = "docs/NOTES.md"
CHECKED_TARGETS = {NOTES, "docs/design.md"}
SOURCE_SUFFIXES = (".md", ".h", ".hpp", ".cpp", ".py", ".sh", ".json")
SKIP_DIRS = {".git", "out"}
SECTION = "\u00a7"  # the section sign

NUMBER = SECTION + r"\s*\d+(?:\.\d+)*(?:\s*[-\u2013]\s*\d+)?"
NUMBERED = re.compile(r"NOTES(?:\.md)?\s*,?\s*" + NUMBER + r"(?:\s*,\s*" + NUMBER + r")*")
PLAIN_ANCHOR = re.compile(r"NOTES\.md#([\w\-]*)")
MD_LINK = re.compile(r"\]\(\s*([^)\s#]*\.md)?(#[^)\s]*)?\s*\)")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
FENCE = re.compile(r"^\s*(```|~~~)")


def slug(text):
    """GitHub's anchor for a heading's text."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", text)  # links keep their text
    text = re.sub(r"<[^>]+>", "", text)  # inline HTML
    text = text.strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path):
    """Every anchor the headings of a markdown file define, duplicates numbered as GitHub does."""
    found, seen, fenced = set(), {}, False
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            if FENCE.match(line):
                fenced = not fenced
                continue
            m = None if fenced else HEADING.match(line)
            if not m:
                continue
            base = slug(m.group(2))
            n = seen.get(base, 0)
            seen[base] = n + 1
            found.add(base if n == 0 else f"{base}-{n}")
    return found


def is_checked_file(path):
    name = os.path.basename(path)
    if name == os.path.basename(__file__):
        return False
    return name == "CMakeLists.txt" or name.endswith(SOURCE_SUFFIXES)


def files(root):
    try:
        out = subprocess.run(["git", "-C", root, "ls-files", "-z", "--cached", "--others", "--exclude-standard"], capture_output=True, check=True)
        listed = [p for p in out.stdout.decode("utf-8", "replace").split("\0") if p]
        if listed:
            return sorted(p for p in listed if is_checked_file(p) and os.path.isfile(os.path.join(root, p)))
    except (OSError, subprocess.CalledProcessError):
        pass
    found = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if d not in SKIP_DIRS and not d.startswith("build"))
        rel = os.path.relpath(dirpath, root)
        for name in sorted(filenames):
            path = os.path.normpath(os.path.join(rel, name))
            if is_checked_file(path):
                found.append(path)
    return found


def check(root):
    """(broken references as 'file:line: message', number of references to NOTES.md that resolve)."""
    cache = {}

    def anchors_of(target):
        if target not in cache:
            full = os.path.join(root, target)
            cache[target] = anchors(full) if os.path.isfile(full) else None
        return cache[target]

    broken, resolved = [], 0
    for src in files(root):
        try:
            text = open(os.path.join(root, src), encoding="utf-8", errors="replace").read()
        except OSError:
            continue
        is_md = src.endswith(".md")
        for lineno, line in enumerate(text.splitlines(), 1):
            where = f"{src}:{lineno}"
            for m in NUMBERED.finditer(line):
                broken.append(f"{where}: '{m.group(0)}' cites {NOTES} by section number; "
                              f"its sections have none: link the heading, {NOTES}#slug")
            link_spans = []
            if is_md:
                for m in MD_LINK.finditer(line):
                    path, frag = m.group(1), m.group(2)
                    if path is None and frag is None:
                        continue
                    if path is None:
                        target = os.path.normpath(src)
                    elif re.match(r"^[a-z][a-z0-9+.-]*:", path):
                        continue  # a URL
                    else:
                        target = os.path.normpath(os.path.join(os.path.dirname(src), path))
                    if target not in CHECKED_TARGETS:
                        if path and os.path.basename(path) in {"NOTES.md", "design.md"}:
                            broken.append(f"{where}: link '{path}' does not lead to {NOTES} or docs/design.md")
                        continue
                    link_spans.append(m.span())
                    known = anchors_of(target)
                    if known is None:
                        broken.append(f"{where}: link '{path}' names a missing file")
                    elif frag and frag[1:] not in known:
                        broken.append(f"{where}: '{target}{frag}' names no heading of {target}")
                    elif target == NOTES:
                        resolved += 1
            for m in PLAIN_ANCHOR.finditer(line):
                if any(a <= m.start() < b for a, b in link_spans):
                    continue  # checked above as a link
                known = anchors_of(NOTES)
                if known is None:
                    broken.append(f"{where}: cites {NOTES}, which does not exist")
                elif m.group(1) not in known:
                    broken.append(f"{where}: '{NOTES}#{m.group(1)}' names no heading of {NOTES}")
                else:
                    resolved += 1
    return broken, resolved


def self_test():
    with tempfile.TemporaryDirectory() as root:
        tree = {
            "docs/NOTES.md": "# Notes\n\n## The free surface\n\n## PETSc and MPI\n\n```\n## not a heading\n```\n",
            "docs/design.md": "# Design\n\n## 3. The discretisation (checked)\n",
            "README.md": "[ok](docs/NOTES.md#the-free-surface) and [bad](docs/NOTES.md#the-free-surfaces)\n"
                         "[design](docs/design.md#3-the-discretisation-checked) [nowhere](doc/NOTES.md)\n",
            "docs/other.md": "See [it](NOTES.md#petsc-and-mpi); see NOTES " + SECTION + "3.\n",
            "src/a.cpp": "// docs/NOTES.md#petsc-and-mpi and docs/NOTES.md#not-a-heading\n"
                         "// docs/NOTES.md, " + SECTION + "12\n",
            "build/b.cpp": "// docs/NOTES.md " + SECTION + "4 (a build folder: not checked)\n",
        }
        for path, text in tree.items():
            os.makedirs(os.path.join(root, os.path.dirname(path)), exist_ok=True)
            with open(os.path.join(root, path), "w", encoding="utf-8") as f:
                f.write(text)
        broken, resolved = check(root)
        expected = ["README.md:1: 'docs/NOTES.md#the-free-surfaces'", "README.md:2: link 'doc/NOTES.md'",
                    "docs/other.md:1: 'NOTES " + SECTION + "3'", "src/a.cpp:1: 'docs/NOTES.md#not-a-heading'",
                    "src/a.cpp:2: 'NOTES.md, " + SECTION + "12'"]
        missing = [e for e in expected if not any(b.startswith(e) for b in broken)]
        if missing or len(broken) != len(expected) or resolved != 3:
            print("self-test failed: expected", expected, "and 3 resolved; got", broken, resolved)
            return 1
        print("self-test: a missing heading, a section number, a wrong path and a fenced heading are caught")
        return 0


def main(argv):
    if argv[1:] == ["--self-test"]:
        return self_test()
    root = argv[1] if len(argv) > 1 else "."
    broken, resolved = check(root)
    for b in broken:
        print(b)
    if broken:
        print(f"{len(broken)} reference(s) to docs/NOTES.md or docs/design.md are broken "
              f"({resolved} resolve)")
        return 1
    print(f"{resolved} references to docs/NOTES.md resolve")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
