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

    source .venv/bin/activate && source install/setup.bash
    python benchmarks/compare_fusion_outputs.py [--base 6657d8c] [--bags default spoofed arl1_jammed]

Exit status 0 when every bag agrees, 1 otherwise. The result is printed (nothing is written to docs/).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import pickle
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

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
    import rfi_experiments.replay  # noqa: F401 - this tree's harness, with this tree's rfi_node_common and gnss_common

    for name in [m for m in sys.modules if m.split('.')[0] in PACKAGES]:
        del sys.modules[name]  # the node imports the tree's copies; the harness keeps the objects it took (its QoS)
    for pkg in reversed(PACKAGES):
        sys.path.insert(0, str(src / pkg))
    from rclpy.parameter import Parameter

    import uwb_gnss_fusion
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
    cli_args = ['--ros-args'] + [a for r in remaps for a in ('-r', r)]
    replay_to_file(lambda context: FusionNode(context=context, parameter_overrides=overrides, cli_args=cli_args),
                   bag, topics, TOPICS, out_path)


def replay_to_file(make_node: Callable[[Any], Any], bag: str, topics: tuple[str, ...], collect: tuple[str, ...],
                   out_path: Path) -> None:
    """Replay ``topics`` of bags/``bag`` through the node ``make_node(context)`` (direct transport, as fast as
    possible) and pickle the flattened messages it published on ``collect`` and its final accounting."""
    import rclpy

    from rfi_experiments.replay import ReplayHarness

    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    try:
        node = make_node(context)
        harness = ReplayHarness([node], context=context, collect=collect, transport='direct')
        result = harness.run(ROOT / 'bags' / bag, topics=topics)
        accounting = node.accounting()
        harness.destroy()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    flat = {t: [flatten(m) for m in result.messages(t)] for t in collect}
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


@contextlib.contextmanager
def base_worktree(base: str, rtol: float, prefix: str) -> Iterator[tuple[Path, Path]]:
    """A temporary ``git worktree`` of commit ``base`` and a scratch directory, both removed afterwards; prints
    what is compared with what."""
    with tempfile.TemporaryDirectory(prefix=prefix) as tmp:
        tree = Path(tmp) / 'base'
        subprocess.run(['git', 'worktree', 'add', '--detach', '--quiet', str(tree), base], check=True, cwd=ROOT)
        try:
            head = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True, text=True,
                                  cwd=ROOT, check=True).stdout.strip()
            dirty = subprocess.run(['git', 'status', '--porcelain', '--', 'src'], capture_output=True, text=True,
                                   cwd=ROOT, check=True).stdout.strip()
            print(f'base {base} against this tree (HEAD {head}{", src/ modified" if dirty else ""}), rtol {rtol:g}')
            yield tree, Path(tmp)
        finally:
            subprocess.run(['git', 'worktree', 'remove', '--force', str(tree)], check=False, cwd=ROOT)


def report(case: str, base: dict, new: dict, rtol: float, extra: str = '') -> bool:
    """Compare the outputs of one case, print the verdict (and ``extra``, then the differences); True if equal."""
    problems, counts, worst = compare(base, new, rtol)
    summary = ', '.join(f'{t} {n}' for t, n in counts.items())
    verdict = 'EQUAL' if not problems else 'DIFFERENT'
    print(f'{case}: {verdict}; messages: {summary}; largest relative difference {worst:.3g}')
    if extra:
        print(f'    {extra}')
    for line in problems:
        print('   ', line)
    return not problems


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
    with base_worktree(args.base, args.rtol, 'fusion_compare_') as (base_tree, tmp):
        for bag in args.bags:
            base = run_tree(base_tree / 'src', bag, tmp / f'{bag}_base.pkl')
            new = run_tree(ROOT / 'src', bag, tmp / f'{bag}_new.pkl')
            exercised = {k: v for k, v in new['accounting'][0] if k in EXERCISED and v}
            failed = not report(bag, base, new, args.rtol, f'paths exercised (this tree): {exercised}') or failed
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
