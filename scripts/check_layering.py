#!/usr/bin/env python3
"""Checks that the project's #include lines follow its CMake target graph.

Every folder's headers are included from one include root ("core/grid/x.h", "app/flags.h"),
so the compiler accepts an include of any folder whether or not the including target links it.
This script closes that gap. It

  1. reads the CMake dependencies between the project's targets (every
     `target_link_libraries(plx_x PUBLIC|PRIVATE|INTERFACE ...)` and
     `plx_add_test_binary(name ... DEPS ...)` in the CMakeLists.txt files),
  2. maps each source folder to the target that compiles it (FOLDER_TARGETS below; core/<f>
     is always plx_<f>),
  3. fails when a file includes a project folder that its folder's target does not reach: the
     target itself, its direct dependencies, and what those export (their PUBLIC and INTERFACE
     dependencies, transitively), as CMake propagates usage requirements; and
  4. fails when the folders' include graph, or the targets' graph, has a cycle.

Run by CTest as the `layering` test; by hand: python3 scripts/check_layering.py [--root DIR]
[--graph] (--graph prints the folder graph that was found). Standard library only.
"""

import argparse
import os
import re
import sys

# Folders (relative to the repository root) whose #include lines are checked, and the target
# that compiles each; core/<folder> maps to plx_<folder> without an entry here. A file belongs
# to the longest folder that contains it. Conditional targets (plx_cuda, plx_server, ...) are
# read from their CMakeLists.txt whether or not this build configures them.
FOLDER_TARGETS = {
    "app": "plx_app",
    "web": "plx_web",
    "cuda": "plx_cuda",
    "server": "plx_server",
    "clients/plenox": "plx_cli_lib",
    "tests/core": "plx_core_tests",
    "tests/backends": "plx_backend_tests",
    "tests/app": "plx_app_tests",
    "tests/web": "plx_web_tests",
    "tests/clients": "plx_client_tests",
    "tests/server": "plx_server_tests",
}

# The shared test helpers at the top of tests/ (test_util, backend_test_util, io_fixtures, ...)
# are compiled into several test binaries; they may include what any test binary may.
TEST_HELPERS = "tests"

# Include prefixes that name project folders (others, like "absl/" or generated "plenoxd/v1/",
# are not ours to check).
PROJECT_ROOTS = ("core", "cuda", "server", "app", "web", "clients", "tests")
SOURCE_EXTENSIONS = (".h", ".cc", ".cu", ".cuh", ".inc")
SKIP_DIRS = {".git", "build", "node_modules", "__pycache__"}

INCLUDE_RE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.MULTILINE)
SCOPES = {"PUBLIC", "PRIVATE", "INTERFACE"}


def cmake_files(root):
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = [d for d in dirnames if d not in SKIP_DIRS and not d.startswith("build")]
        if "CMakeLists.txt" in filenames:
            yield os.path.join(dirpath, "CMakeLists.txt")


def strip_cmake_comments(text):
    # CMake comments run from '#' to the end of the line; none of our lists quote a '#'.
    return "\n".join(line.split("#", 1)[0] for line in text.splitlines())


def calls(text, command):
    """The argument lists of every `command(...)` call (no nested parentheses in ours)."""
    pattern = re.compile(r"\b" + command + r"\s*\(([^)]*)\)", re.IGNORECASE)
    return [m.group(1).split() for m in pattern.finditer(text)]


def read_target_graph(root):
    """{target: {"public": set, "private": set}} over the project's (plx_*) targets."""
    graph = {}

    def node(name):
        return graph.setdefault(name, {"public": set(), "private": set()})

    for path in cmake_files(root):
        text = strip_cmake_comments(open(path, encoding="utf-8").read())
        for args in calls(text, "target_link_libraries"):
            if not args:
                continue
            target, scope = args[0], "PUBLIC"  # the plain signature propagates like PUBLIC
            entry = node(target)
            for arg in args[1:]:
                if arg in SCOPES:
                    scope = arg
                elif arg.startswith("plx_"):
                    node(arg)
                    entry["private" if scope == "PRIVATE" else "public"].add(arg)
        for args in calls(text, "plx_add_test_binary"):
            if "DEPS" not in args:
                continue
            entry = node(args[0])
            for arg in args[args.index("DEPS") + 1:]:
                if arg in ("SOURCES",):
                    break
                if arg.startswith("plx_"):
                    node(arg)
                    entry["private"].add(arg)  # executables export nothing
    return graph


def exported(graph, target, seen=None):
    """`target` and everything its PUBLIC/INTERFACE dependencies carry to a dependent."""
    seen = set() if seen is None else seen
    if target in seen:
        return seen
    seen.add(target)
    for dep in graph.get(target, {}).get("public", ()):
        exported(graph, dep, seen)
    return seen


def reachable(graph, target):
    """The targets whose headers `target`'s sources may include."""
    allowed = {target}
    entry = graph.get(target, {"public": set(), "private": set()})
    for dep in entry["public"] | entry["private"]:
        allowed |= exported(graph, dep)
    return allowed


def folder_of(path, folders):
    """The checked folder that owns `path` (relative, '/'-separated), or None."""
    parts = path.split("/")
    if parts[0] == "core" and len(parts) > 2:
        return "core/" + parts[1]
    best = None
    for folder in folders:
        if path.startswith(folder + "/") and (best is None or len(folder) > len(best)):
            best = folder
    if best is None and parts[0] == TEST_HELPERS and len(parts) == 2:
        return TEST_HELPERS
    return best


def target_of(folder):
    if folder.startswith("core/"):
        return "plx_" + folder.split("/", 1)[1]
    return FOLDER_TARGETS.get(folder)


def find_cycle(edges):
    """One cycle of the directed graph {node: set(nodes)} as a list, or None."""
    white, grey, black = 0, 1, 2
    colour = {n: white for n in edges}
    stack = []

    def visit(n):
        colour[n] = grey
        stack.append(n)
        for m in sorted(edges.get(n, ())):
            if colour.get(m, white) == grey:
                return stack[stack.index(m):] + [m]
            if colour.get(m, white) == white:
                colour.setdefault(m, white)
                found = visit(m)
                if found:
                    return found
        stack.pop()
        colour[n] = black
        return None

    for n in sorted(edges):
        if colour[n] == white:
            found = visit(n)
            if found:
                return found
    return None


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--root", default=os.path.join(os.path.dirname(__file__), ".."),
                        help="repository root (default: this script's parent folder)")
    parser.add_argument("--graph", action="store_true", help="print the folder include graph")
    args = parser.parse_args()
    root = os.path.abspath(args.root)

    graph = read_target_graph(root)
    folders = set(FOLDER_TARGETS)
    core = os.path.join(root, "core")
    for name in sorted(os.listdir(core)):
        if os.path.isdir(os.path.join(core, name)):
            folders.add("core/" + name)

    errors = []
    for folder in sorted(folders):
        target = target_of(folder)
        if os.path.isdir(os.path.join(root, folder)) and target not in graph:
            errors.append(f"{folder}/: no CMake target {target} with target_link_libraries "
                          f"(add one, or map the folder in scripts/check_layering.py)")

    test_targets = {target_of(f) for f in folders if f.startswith("tests/")}
    helper_allowed = set()
    for t in test_targets:
        helper_allowed |= reachable(graph, t)

    folder_edges = {}  # folder -> {included folder: first "file:line" seen}
    for top in PROJECT_ROOTS:
        for dirpath, dirnames, filenames in os.walk(os.path.join(root, top)):
            dirnames[:] = sorted(d for d in dirnames if d not in SKIP_DIRS)
            for filename in sorted(filenames):
                if not filename.endswith(SOURCE_EXTENSIONS):
                    continue
                path = os.path.join(dirpath, filename)
                rel = os.path.relpath(path, root).replace(os.sep, "/")
                owner = folder_of(rel, folders)
                if owner is None:
                    continue  # e.g. clients/python: no C++ target
                text = open(path, encoding="utf-8", errors="replace").read()
                for match in INCLUDE_RE.finditer(text):
                    included = match.group(1)
                    if included.split("/", 1)[0] not in PROJECT_ROOTS:
                        continue
                    line = text.count("\n", 0, match.start()) + 1
                    where = f"{rel}:{line}"
                    dest = folder_of(included, folders)
                    if dest is None:
                        errors.append(f"{where}: includes \"{included}\", which is in no "
                                      f"folder with a target")
                        continue
                    if dest != owner:
                        folder_edges.setdefault(owner, {}).setdefault(dest, where)
                    if dest == owner or dest == TEST_HELPERS and owner.startswith("tests"):
                        continue
                    allowed = (helper_allowed if owner == TEST_HELPERS
                               else reachable(graph, target_of(owner)))
                    if target_of(dest) not in allowed:
                        errors.append(
                            f"{where}: {owner}/ includes \"{included}\", but "
                            f"{target_of(owner) or owner} does not link "
                            f"{target_of(dest)} (directly or through a PUBLIC dependency); "
                            f"add it to target_link_libraries if the layering allows the edge, "
                            f"else move the code")

    cycle = find_cycle({f: set(d) for f, d in folder_edges.items()})
    if cycle:
        hops = [f"{a} -> {b} ({folder_edges[a][b]})" for a, b in zip(cycle, cycle[1:])]
        errors.append("the folders' includes form a cycle: " + "; ".join(hops))
    target_cycle = find_cycle({t: e["public"] | e["private"] for t, e in graph.items()})
    if target_cycle:
        errors.append("the CMake targets form a cycle: " + " -> ".join(target_cycle))

    if args.graph:
        for folder in sorted(folder_edges):
            print(f"{folder} -> {', '.join(sorted(folder_edges[folder]))}")
    if errors:
        for error in errors:
            print("layering: " + error, file=sys.stderr)
        print(f"layering: {len(errors)} problem(s); the layering is drawn in "
              f"docs/ARCHITECTURE.md", file=sys.stderr)
        return 1
    print(f"layering: OK ({len(folders)} folders, {len(graph)} targets, "
          f"{sum(len(d) for d in folder_edges.values())} folder edges)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
