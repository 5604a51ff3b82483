"""Repair a venv that holds ROS 2 Jazzy PyPI wheels so that colcon can build interface packages.

The wheels were built on a manylinux machine and carry two defects for building on top of them:

(b) their CMake exports (``<prefix>/share/*/cmake/*Export.cmake``) name that machine's Python and
    numpy include directories (``/opt/python/cp3XX-cp3XX/...``); they are rewritten to this
    interpreter's include directory and this numpy's include directory;
(c) some ``package.xml`` files carry a maintainer e-mail that catkin_pkg rejects; it is replaced
    with a valid placeholder address so that colcon can parse the package.

Repair (a) of the set-up (cmake packages that the wheels' metadata does not pull in) is a
matter of the requirements file, not of this script.

The script is idempotent: running it twice changes nothing the second time.

Usage: python tools/repair_ros_wheels.py [PREFIX]   (PREFIX defaults to sys.prefix)
"""

from __future__ import annotations

import re
import sys
import sysconfig
from pathlib import Path

BUILD_PYTHON_INCLUDE = re.compile(r"/opt/python/cp3\d+-cp3\d+/include/python3\.\d+")
BUILD_NUMPY_INCLUDE = re.compile(
    r"/opt/python/cp3\d+-cp3\d+/lib/python3\.\d+/site-packages/numpy/(?:_core|core)/include")
MAINTAINER_EMAIL = re.compile(r'(<maintainer\b[^>]*\bemail=")([^"]*)(")')
VALID_EMAIL = re.compile(r"^[^@\s]+@[^@\s]+\.[^@\s]+$")


def repair_cmake_exports(prefix: Path, python_include: str, numpy_include: str) -> int:
    """Rewrite the build machine's include paths in every CMake export file; return files changed."""
    changed = 0
    for path in sorted(prefix.glob("share/*/cmake/*Export*.cmake")):
        text = path.read_text()
        new = BUILD_NUMPY_INCLUDE.sub(numpy_include, text)
        new = BUILD_PYTHON_INCLUDE.sub(python_include, new)
        if new != text:
            path.write_text(new)
            changed += 1
    return changed


def repair_maintainer_emails(prefix: Path) -> int:
    """Replace maintainer e-mails that catkin_pkg would reject; return files changed."""
    changed = 0
    for path in sorted(prefix.glob("share/*/package.xml")):
        text = path.read_text()

        def fix(match: re.Match[str]) -> str:
            email = match.group(2)
            if VALID_EMAIL.match(email):
                return match.group(0)
            return f"{match.group(1)}unknown@example.com{match.group(3)}"

        new = MAINTAINER_EMAIL.sub(fix, text)
        if new != text:
            path.write_text(new)
            changed += 1
    return changed


def main(argv: list[str]) -> int:
    prefix = Path(argv[1]) if len(argv) > 1 else Path(sys.prefix)
    if not (prefix / "share").is_dir():
        print(f"repair_ros_wheels: {prefix}/share does not exist: is this the venv with the ROS wheels?",
              file=sys.stderr)
        return 2
    try:
        import numpy
    except ImportError:
        print("repair_ros_wheels: numpy is not installed in this interpreter", file=sys.stderr)
        return 2
    python_include = sysconfig.get_paths()["include"]
    if not Path(python_include, "Python.h").is_file():
        print(f"repair_ros_wheels: Python headers not found in {python_include}: install the Python "
              "development headers (e.g. python3-dev)", file=sys.stderr)
        return 2
    n_cmake = repair_cmake_exports(prefix, python_include, numpy.get_include())
    n_xml = repair_maintainer_emails(prefix)
    print(f"repair_ros_wheels: {n_cmake} CMake export file(s) and {n_xml} package.xml file(s) repaired in {prefix}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
