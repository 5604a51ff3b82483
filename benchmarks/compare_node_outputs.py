"""Behaviour check of a refactor of gnss_integrity, rfi_monitor or imm_carrier: the node's outputs of this tree
against a base commit's.

The same method as ``benchmarks/compare_fusion_outputs.py`` (whose flattening and comparison it uses): the base
commit is put in a temporary ``git worktree``; each bag is replayed through the node twice, each time in a child
Python process whose ``sys.path`` starts with one tree's ``src/<package>`` directories of the pure-Python packages
(the node's package, ``gnss_common``, ``rfi_node_common``; the child checks it imported them from there), the
messages and the replay harness (:class:`rfi_experiments.replay.ReplayHarness`, direct transport, as fast as
possible) from the install tree (the harness is imported first, with the install tree's ``rfi_node_common`` and
``gnss_common``, which the node's imports then replace: a base older than the harness's imports, e.g. 4c5248c
without ``rfi_node_common.qos.VIEW_QOS``, would break it otherwise). Every message the node publishes is flattened
field by field and so is its final accounting; both runs must publish as many messages per topic and every field
must agree (strings, integers and booleans exactly, floats both NaN or within ``--rtol`` relative, default 1e-9).

Cases (node: bag):

* ``integrity:default``: gnss_integrity_node on bags/default (GNSS, UWB, /truth/jammer as the SDR verdict);
* ``integrity:spoofed``: gnss_integrity_node on bags/spoofed (GNSS and UWB, the spoofer from 60 s);
* ``monitor:default``: rfi_monitor_node on bags/default (/rfi/if_samples, 180 blocks);
* ``carrier:default``: imm_carrier_node on bags/default (/gnss/correlators), method both (the IMM and the PLL).

Usage::

    source .venv/bin/activate && source install/setup.bash
    python benchmarks/compare_node_outputs.py --base 4c5248c [--cases integrity:default carrier:default]

Exit status 0 when every case agrees, 1 otherwise. The result is printed (nothing is written to docs/).
"""

from __future__ import annotations

import argparse
import os
import pickle
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from compare_fusion_outputs import base_worktree, replay_to_file, report  # noqa: E402

NODES = {
    # node: (package, module, class, topics published)
    'integrity': ('gnss_integrity', 'gnss_integrity.gnss_integrity_node', 'GnssIntegrityNode',
                  ('/gnss/integrity', '/diagnostics')),
    'monitor': ('rfi_monitor', 'rfi_monitor.rfi_monitor_node', 'RfiMonitorNode',
                ('/rfi/jammer_state', '/diagnostics')),
    'carrier': ('imm_carrier', 'imm_carrier.imm_carrier_node', 'ImmCarrierNode',
                ('/carrier/estimates', '/diagnostics')),
}
CASES = {
    # case: (input topics, remappings, parameters)
    'integrity:default': (('/gnss/measurements', '/uwb/ranges', '/truth/jammer'),
                          ('/rfi/jammer_state:=/truth/jammer',), {}),
    'integrity:spoofed': (('/gnss/measurements', '/uwb/ranges'), (), {}),
    'monitor:default': (('/rfi/if_samples',), (), {}),
    'carrier:default': (('/gnss/correlators',), (), {'method': 'both'}),
}


def child(src: Path, case: str, out_path: Path) -> None:
    """Replay the case's bag through the node of the tree ``src`` and pickle the flattened outputs."""
    import importlib

    import rfi_experiments.replay  # noqa: F401 - this tree's harness, with this tree's rfi_node_common and gnss_common

    node_key, bag = case.split(':')
    package, module_name, class_name, collect = NODES[node_key]
    packages = (package, 'gnss_common', 'rfi_node_common')
    for name in [m for m in sys.modules if m.split('.')[0] in packages]:
        del sys.modules[name]  # the node imports the tree's copies; the harness keeps the objects it took (its QoS)
    for pkg in reversed(packages):
        sys.path.insert(0, str(src / pkg))
    node_cls = getattr(importlib.import_module(module_name), class_name)
    for name in packages:
        module = importlib.import_module(name)
        if not Path(module.__file__).resolve().is_relative_to(src.resolve()):
            raise RuntimeError(f'{name} imported from {module.__file__}, not from {src}')
    from rclpy.parameter import Parameter

    topics, remaps, params = CASES[case]
    cli_args = ['--ros-args'] + [a for r in remaps for a in ('-r', r)]
    overrides = [Parameter(name, value=value) for name, value in params.items()]
    replay_to_file(lambda context: node_cls(context=context, cli_args=cli_args, parameter_overrides=overrides),
                   bag, topics, collect, out_path)


def run_tree(src: Path, case: str, out: Path) -> dict:
    subprocess.run([sys.executable, __file__, '--child', '--src', str(src), '--case', case, '--out', str(out)],
                   check=True, env=dict(os.environ), cwd=ROOT)
    with open(out, 'rb') as f:
        return pickle.load(f)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--base', help='the commit to compare with (required)')
    ap.add_argument('--cases', nargs='+', default=list(CASES), choices=list(CASES))
    ap.add_argument('--rtol', type=float, default=1e-9, help='relative tolerance of float fields')
    ap.add_argument('--child', action='store_true', help=argparse.SUPPRESS)
    ap.add_argument('--src', type=Path, help=argparse.SUPPRESS)
    ap.add_argument('--case', help=argparse.SUPPRESS)
    ap.add_argument('--out', type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(args.src, args.case, args.out)
        return 0
    if not args.base:
        ap.error('--base is required')
    failed = False
    with base_worktree(args.base, args.rtol, 'node_compare_') as (base_tree, tmp):
        for case in args.cases:
            base = run_tree(base_tree / 'src', case, tmp / f'{case}_base.pkl')
            new = run_tree(ROOT / 'src', case, tmp / f'{case}_new.pkl')
            failed = not report(case, base, new, args.rtol) or failed
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
