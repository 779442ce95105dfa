#!/usr/bin/env python3
"""Checks that no C++, CUDA or proto source line is longer than the project's column limit.

.clang-format sets ColumnLimit 100, but clang-format is run by hand on changed files only, so
nothing stops a long line from being merged. This script does: it reads every .cc, .h, .cu,
.cuh, .inc and .proto file under the root, prints `path:line: N columns (max M)` for each line
over the limit, and exits 1 when there is one.

Columns are counted as clang-format counts them: one per Unicode code point, a tab up to the
next multiple of 8. Skipped: hidden folders (.git, ...), node_modules and __pycache__, and every
CMake build tree (a folder holding CMakeCache.txt, such as build/ and build-asan/), which is
where the generated protobuf sources live. The repository vendors no third-party sources, so
nothing else is excluded.

Run by CTest as the `line_length` test; by hand: python3 scripts/check_line_length.py
[--root DIR] [--max COLUMNS]. Standard library only.
"""

import argparse
import os
import sys

SOURCE_EXTENSIONS = (".cc", ".h", ".cu", ".cuh", ".inc", ".proto")
SKIP_DIRS = {"node_modules", "__pycache__"}
TAB_WIDTH = 8


def source_files(root):
    """Relative, '/'-separated paths of the checked files under `root`, sorted."""
    found = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = [
            d for d in dirnames
            if not d.startswith(".") and d not in SKIP_DIRS
            and not os.path.isfile(os.path.join(dirpath, d, "CMakeCache.txt"))
        ]
        for filename in filenames:
            if filename.endswith(SOURCE_EXTENSIONS):
                path = os.path.relpath(os.path.join(dirpath, filename), root)
                found.append(path.replace(os.sep, "/"))
    return sorted(found)


def long_lines(path, max_columns):
    """(line number, columns) of each line of the file at `path` wider than `max_columns`."""
    with open(path, encoding="utf-8", errors="replace", newline="") as f:
        text = f.read()
    found = []
    # Split on "\n" only: str.splitlines would also break at form feeds and the like, and
    # the line numbers would no longer be the editor's.
    for number, line in enumerate(text.split("\n"), start=1):
        columns = len(line.rstrip("\r").expandtabs(TAB_WIDTH))
        if columns > max_columns:
            found.append((number, columns))
    return found


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--root", default=os.path.join(os.path.dirname(__file__), ".."),
                        help="repository root (default: this script's parent folder)")
    parser.add_argument("--max", type=int, default=100, dest="max_columns",
                        help="the column limit (default: 100, .clang-format's ColumnLimit)")
    args = parser.parse_args()
    root = os.path.abspath(args.root)
    if not os.path.isdir(root):
        print(f"line_length: {root} is not a folder", file=sys.stderr)
        return 2

    files = source_files(root)
    offending = 0
    for rel in files:
        for number, columns in long_lines(os.path.join(root, rel), args.max_columns):
            print(f"{rel}:{number}: {columns} columns (max {args.max_columns})")
            offending += 1
    if offending:
        print(f"line_length: {offending} line(s) over {args.max_columns} columns in "
              f"{len(files)} files; wrap them by hand (or clang-format --lines=N:N FILE)",
              file=sys.stderr)
        return 1
    print(f"line_length: {len(files)} files, no line over {args.max_columns} columns")
    return 0


if __name__ == "__main__":
    sys.exit(main())
