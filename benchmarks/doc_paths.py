"""Paths as the pages in docs/ may print them: never the prefix of the machine that ran a benchmark.

A page in docs/ is read on other machines and regenerated on others again, so a path in it is
relative to the checkout (``src/rfi_monitor/rfi_monitor``), to the installed packages
(``rosbags/rosbag2/storage_mcap.py``) or to the standard library (``functools.py``).
test/test_docs.py checks that no page holds a machine path.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_STDLIB = re.compile(r'/lib/python3\.\d+/(?P<rest>.+)$')


def portable_path(path: str | Path, root: Path = ROOT) -> str:
    """``path`` without the machine's prefix.

    In this order: relative to ``root`` (the checkout); ``install/...`` of another checkout's colcon
    install tree; what follows the last ``site-packages/`` or ``dist-packages/`` (the module path as
    Python imports it from a venv); what follows ``lib/python3.X/`` (the standard library);
    ``src/...`` of another checkout; else the file name alone. A name that is not a path (pstats's
    ``~`` or ``<string>``) is returned as it is.
    """
    text = str(path)
    if not text.startswith('/'):
        return text
    resolved = Path(text).resolve()
    try:
        return resolved.relative_to(root.resolve()).as_posix()
    except ValueError:
        pass
    posix = resolved.as_posix()
    if '/install/' in posix:  # a colcon install tree (of another checkout)
        return 'install/' + posix.rsplit('/install/', 1)[1]
    for marker in ('/site-packages/', '/dist-packages/'):
        if marker in posix:
            return posix.rsplit(marker, 1)[1]
    stdlib = _STDLIB.search(posix)
    if stdlib:
        return stdlib.group('rest')
    if '/src/' in posix:
        return 'src/' + posix.rsplit('/src/', 1)[1]
    return resolved.name


def portable_text(text: str, paths: list[str], root: Path = ROOT) -> str:
    """``text`` with each of ``paths`` replaced by its :func:`portable_path` (longest first)."""
    for path in sorted(set(paths), key=len, reverse=True):
        if path.startswith('/'):
            text = text.replace(path, portable_path(path, root))
    return text
