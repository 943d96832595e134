"""Rewrite build-machine paths in the ROS wheels' exported CMake files.

The ROS 2 Jazzy wheels on PyPI were built under /opt/python/cp311-cp311 and their exported
CMake targets name that interpreter's include directory and its numpy include directory.
CMake refuses imported targets with non-existent include paths, so interface packages do not
build until those two paths name this interpreter's. Idempotent: a second run changes nothing.
Run with the virtual environment's python.
"""

from __future__ import annotations

import pathlib
import sys
import sysconfig

import numpy

BUILD_PYTHON = "/opt/python/cp311-cp311"
REPLACEMENTS = {
    f"{BUILD_PYTHON}/include/python3.11": sysconfig.get_paths()["include"],
    f"{BUILD_PYTHON}/lib/python3.11/site-packages/numpy/_core/include": numpy.get_include(),
}


def main() -> int:
    share = pathlib.Path(sys.prefix) / "share"
    changed = 0
    for path in share.rglob("*.cmake"):
        text = path.read_text(encoding="utf-8", errors="surrogateescape")
        if BUILD_PYTHON not in text:
            continue
        new = text
        for old, repl in REPLACEMENTS.items():
            new = new.replace(old, repl)
        if new != text:
            path.write_text(new, encoding="utf-8", errors="surrogateescape")
            changed += 1
    left = [p for p in share.rglob("*.cmake") if BUILD_PYTHON in p.read_text(errors="ignore")]
    if left:
        print(f"fix_cmake_paths: unknown build paths remain in {left[0]} and {len(left) - 1} more",
              file=sys.stderr)
        return 1
    print(f"fix_cmake_paths: {changed} CMake files rewritten")
    return 0


if __name__ == "__main__":
    sys.exit(main())
