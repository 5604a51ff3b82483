"""Behaviour check of a refactor of uwb_gnss_fusion: the node's outputs of this tree against a base commit's.

How. ``git worktree add --detach`` puts the base commit (default 6657d8c, the commit before the
restructuring of issue 28) in a temporary directory. Each bag is then replayed through
:class:`uwb_gnss_fusion.fusion_node.FusionNode` twice, each time in a child Python process whose
``sys.path`` starts with one tree's ``src/<package>`` directories of the pure-Python packages
(``uwb_gnss_fusion``, ``gnss_common``, ``rfi_node_common``; the child checks that it imported them
from there); the messages (``rfi_msgs``) and the replay harness
(:class:`rfi_experiments.replay.ReplayHarness`, direct transport, as fast as possible, end of
input flushed) come from the install tree. Every message published on /fusion/odometry,
/fusion/local_odometry, /fusion/fix, /fusion/status and /diagnostics is flattened field by field (rosidl
introspection: every number, string and array element, headers included), and so is the node's
final :meth:`FusionNode.accounting`. The two runs must publish the same number of messages on
each topic, and every field must agree: strings, integers and booleans exactly, floats both NaN
or within ``--rtol`` (default 1e-9) relative (``|a - b| <= rtol * max(|a|, |b|)``).

Bags (each with GNSS and UWB): ``default`` (jammer J/S from /truth/jammer remapped to
/rfi/jammer_state, so the eq. 4 weighting acts), ``spoofed`` (/truth/integrity remapped to
/gnss/integrity: exclusion, roll-back through ``FusionFilter.snapshot/restore``, re-anchoring),
``arl1_jammed`` (real 30 s GNSS epochs, /truth/jammer_state as the J/S, the bag's fusion
parameters).

Usage::

    source /work/main/.venv/bin/activate && source install/setup.bash
    python benchmarks/compare_fusion_outputs.py [--base 6657d8c] [--bags default spoofed arl1_jammed]

Exit status 0 when every bag agrees, 1 otherwise. The result is printed (nothing is written to docs/).
"""

from __future__ import annotations

import argparse
import math
import os
import pickle
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ('uwb_gnss_fusion', 'gnss_common', 'rfi_node_common')
"""Pure-Python packages taken from the tree under test (the others come from the install tree)."""
TOPICS = ('/fusion/odometry', '/fusion/local_odometry', '/fusion/fix', '/fusion/status', '/diagnostics')
BAGS = {
    # bag: (input topics, remappings, parameters file or None)
    'default': (('/gnss/measurements', '/uwb/ranges', '/truth/jammer'),
                ('/rfi/jammer_state:=/truth/jammer',), None),
    'spoofed': (('/gnss/measurements', '/uwb/ranges', '/truth/integrity'),
                ('/gnss/integrity:=/truth/integrity',), None),
    'arl1_jammed': (('/gnss/measurements', '/uwb/ranges', '/truth/jammer_state'),
                    ('/rfi/jammer_state:=/truth/jammer_state',), 'bags/arl1_jammed.params.yaml'),
}

EXERCISED = ('jammer_processed', 'integrity_processed', 'satellites_excluded_spoofing', 'filter.rolled_back',
             'filter.reanchor_on_uwb', 'filter.divergence', 'filter.reinit_from_uwb', 'filter.innovation_gate_uwb',
             'filter.innovation_gate_pseudorange', 'filter.common_mode_pseudorange', 'filter.motion_static_entered',
             'filter.receiver_clock_step_ms', 'filter.uwb_side_prior_flip', 'filter.uwb_mirror_switch')
"""Counters printed for each bag: which paths of the filter and the node the replay went through."""


def flatten(msg, prefix: str = '') -> list[tuple[str, object]]:
    """Every leaf field of a ROS message as (path, value), arrays element by element."""
    out: list[tuple[str, object]] = []
    if hasattr(msg, 'get_fields_and_field_types'):
        for name in msg.get_fields_and_field_types():
            out.extend(flatten(getattr(msg, name), f'{prefix}.{name}' if prefix else name))
        return out
    if isinstance(msg, (str, bytes, bool, int, float)):
        return [(prefix, msg)]
    try:
        items = list(msg)
    except TypeError:
        return [(prefix, msg)]
    out.append((f'{prefix}.len', len(items)))
    for i, item in enumerate(items):
        out.extend(flatten(item.item() if hasattr(item, 'item') else item, f'{prefix}[{i}]'))
    return out


def child(src: Path, bag: str, out_path: Path) -> None:
    """Replay ``bag`` through the FusionNode of the tree ``src`` and pickle the flattened outputs."""
    for pkg in reversed(PACKAGES):
        sys.path.insert(0, str(src / pkg))
    import rclpy
    from rclpy.parameter import Parameter

    import uwb_gnss_fusion
    from rfi_experiments.replay import ReplayHarness
    from uwb_gnss_fusion.fusion_node import FusionNode

    for module in (uwb_gnss_fusion, __import__('gnss_common'), __import__('rfi_node_common')):
        if not Path(module.__file__).resolve().is_relative_to(src.resolve()):
            raise RuntimeError(f'{module.__name__} imported from {module.__file__}, not from {src}')
    topics, remaps, params_file = BAGS[bag]
    overrides = []
    if params_file is not None:
        import yaml
        with open(ROOT / params_file, encoding='utf-8') as f:
            loaded = yaml.safe_load(f)
        for node_params in loaded.values():
            for name, value in node_params.get('ros__parameters', {}).items():
                overrides.append(Parameter(name, value=value))
    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    try:
        node = FusionNode(context=context, parameter_overrides=overrides,
                          cli_args=['--ros-args'] + [a for r in remaps for a in ('-r', r)])
        harness = ReplayHarness([node], context=context, collect=TOPICS, transport='direct')
        result = harness.run(ROOT / 'bags' / bag, topics=topics)
        accounting = node.accounting()
        harness.destroy()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    flat = {t: [flatten(m) for m in result.messages(t)] for t in TOPICS}
    flat['accounting'] = [sorted((k, v) for k, v in accounting.items())]
    with open(out_path, 'wb') as f:
        pickle.dump(flat, f)


def agree(a: object, b: object, rtol: float) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        if math.isnan(a) or math.isnan(b):
            return math.isnan(a) and math.isnan(b)
        return a == b or abs(a - b) <= rtol * max(abs(a), abs(b))
    return type(a) is type(b) and a == b


def compare(base: dict, new: dict, rtol: float) -> tuple[list[str], dict[str, int], float]:
    """Differences (text), messages per topic, and the largest relative difference of a float field."""
    problems: list[str] = []
    counts: dict[str, int] = {}
    worst = 0.0
    for topic in sorted(set(base) | set(new)):
        a, b = base.get(topic, []), new.get(topic, [])
        counts[topic] = len(a)
        if len(a) != len(b):
            problems.append(f'{topic}: {len(a)} messages in the base, {len(b)} now')
            continue
        for i, (ma, mb) in enumerate(zip(a, b, strict=True)):
            if [k for k, _ in ma] != [k for k, _ in mb]:
                problems.append(f'{topic}[{i}]: different fields')
                continue
            for (key, va), (_, vb) in zip(ma, mb, strict=True):
                if isinstance(va, float) and isinstance(vb, float) and math.isfinite(va) and math.isfinite(vb):
                    scale = max(abs(va), abs(vb))
                    if scale > 0.0:
                        worst = max(worst, abs(va - vb) / scale)
                if not agree(va, vb, rtol):
                    if len(problems) < 20:
                        problems.append(f'{topic}[{i}].{key}: {va!r} (base) != {vb!r} (now)')
                    else:
                        problems.append('...')
                        return problems, counts, worst
    return problems, counts, worst


def run_tree(src: Path, bag: str, out: Path) -> dict:
    env = dict(os.environ)
    subprocess.run([sys.executable, __file__, '--child', '--src', str(src), '--bag', bag, '--out', str(out)],
                   check=True, env=env, cwd=ROOT)
    with open(out, 'rb') as f:
        return pickle.load(f)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--base', default='6657d8c', help='the commit to compare with (default 6657d8c)')
    ap.add_argument('--bags', nargs='+', default=list(BAGS), choices=list(BAGS))
    ap.add_argument('--rtol', type=float, default=1e-9, help='relative tolerance of float fields')
    ap.add_argument('--child', action='store_true', help=argparse.SUPPRESS)
    ap.add_argument('--src', type=Path, help=argparse.SUPPRESS)
    ap.add_argument('--bag', help=argparse.SUPPRESS)
    ap.add_argument('--out', type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(args.src, args.bag, args.out)
        return 0
    failed = False
    with tempfile.TemporaryDirectory(prefix='fusion_compare_') as tmp:
        base_tree = Path(tmp) / 'base'
        subprocess.run(['git', 'worktree', 'add', '--detach', '--quiet', str(base_tree), args.base],
                       check=True, cwd=ROOT)
        try:
            head = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True, text=True,
                                  cwd=ROOT, check=True).stdout.strip()
            dirty = subprocess.run(['git', 'status', '--porcelain', '--', 'src'], capture_output=True, text=True,
                                   cwd=ROOT, check=True).stdout.strip()
            print(f'base {args.base} against this tree (HEAD {head}{", src/ modified" if dirty else ""}), '
                  f'rtol {args.rtol:g}')
            for bag in args.bags:
                base = run_tree(base_tree / 'src', bag, Path(tmp) / f'{bag}_base.pkl')
                new = run_tree(ROOT / 'src', bag, Path(tmp) / f'{bag}_new.pkl')
                problems, counts, worst = compare(base, new, args.rtol)
                summary = ', '.join(f'{t} {n}' for t, n in counts.items())
                verdict = 'EQUAL' if not problems else 'DIFFERENT'
                print(f'{bag}: {verdict}; messages: {summary}; largest relative difference {worst:.3g}')
                exercised = {k: v for k, v in new['accounting'][0] if k in EXERCISED and v}
                print(f'    paths exercised (this tree): {exercised}')
                for line in problems:
                    print('   ', line)
                failed = failed or bool(problems)
        finally:
            subprocess.run(['git', 'worktree', 'remove', '--force', str(base_tree)], check=False, cwd=ROOT)
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
