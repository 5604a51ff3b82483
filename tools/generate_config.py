#!/usr/bin/env python3
"""Write (or check) the nodes' config files from their parameter dataclasses.

Each node's parameters are written once, as dataclass fields with
:func:`rfi_node_common.params.parameter` (default, description, range, settable or not, group); the
shipped ``src/<package>/config/<node>.yaml`` is generated from them
(:class:`rfi_node_common.params.ConfigFile`). Run after changing a default or a description::

    source /work/main/.venv/bin/activate && source install/setup.bash
    python tools/generate_config.py           # rewrite the files
    python tools/generate_config.py --check   # exit 1 if a shipped file differs (what the tests check)

The modules are imported from the source tree (``src/<package>``), not the install tree, so the files
follow the code just edited.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CONFIG_FILES = (
    'uwb_gnss_fusion.fusion_node_params:CONFIG_FILE',
)
"""``module:attribute`` of each node's :class:`rfi_node_common.params.ConfigFile`."""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--check', action='store_true', help='compare, do not write; exit 1 on a difference')
    args = ap.parse_args(argv)
    for package in ('rfi_node_common', 'gnss_common', 'uwb_gnss_fusion', 'imm_carrier'):
        sys.path.insert(0, str(ROOT / 'src' / package))
    stale = []
    for ref in CONFIG_FILES:
        module, attr = ref.split(':')
        config = getattr(importlib.import_module(module), attr)
        path = ROOT / 'src' / config.package / config.path
        text = config.text()
        if path.exists() and path.read_text() == text:
            continue
        stale.append(path)
        if not args.check:
            path.write_text(text)
            print(f'wrote {path.relative_to(ROOT)}')
    if args.check and stale:
        names = ', '.join(str(p.relative_to(ROOT)) for p in stale)
        print(f'out of date (run python tools/generate_config.py): {names}')
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
