"""Start-up time and replay speed of rfi_monitor_node, fusion_node and imm_carrier_node: this tree against a base
commit, in one run, interleaved (issue 28, "done when": "node start-up time and the three node speed benchmarks no
slower, measured old against new in one run").

The base commit (default 4c5248c, main before issue 28's first commit) is put in a temporary ``git worktree``
(:func:`compare_fusion_outputs.base_worktree`, as ``compare_node_outputs.py`` does). Every measurement runs in a
fresh Python process whose ``sys.path`` starts with one tree's ``src/<package>`` folders of the node's pure-Python
packages (the node's package, ``gnss_common``, ``rfi_node_common``; the child checks that it imported them from
there); the messages (``rfi_msgs``) and the replay harness come from the install tree, the same for both trees.
The two trees alternate (which goes first alternates too), so a change of the machine's load hits both alike.

* **start-up**: wall time from the parent's ``Popen`` of ``python -c "...; main()"`` (the node's console entry
  point, default parameters) to the moment the parent reads the node's ``<executable> ready`` log line
  (``rfi_node_common.main.run_node`` logs it once the node is built: parameters declared, publishers and
  subscriptions made, compiled kernels loaded and warmed up); the node is then stopped with SIGINT. The child also
  reports when its import of the node module finished (CLOCK_MONOTONIC is one clock for all processes), which
  splits the start-up into interpreter + imports and construction. One unmeasured start of each tree first fills
  numba's on-disk cache of the fresh base worktree (and checks this tree's), and so does one unmeasured replay
  (kernels compiled on first use): the numbers are warm-cache starts.
* **replay speed**: the workloads of the node speed benchmarks, as fast as possible through
  ``rfi_experiments.replay.ReplayHarness`` (direct transport, nothing collected): rfi_monitor_node on
  ``bags/default`` ``/rfi/if_samples`` (the node rows of the monitor: the whole node, not the core alone as
  ``rfi_monitor_speed.py``'s live-stream rows), fusion_node on ``bags/default`` ``/gnss/measurements`` +
  ``/uwb/ranges`` (``fusion_node_speed.py``'s replay), imm_carrier_node with method both on the 4 s, 32-satellite,
  1 kHz bag of ``imm_carrier_node_speed.py`` (its "replay, direct" row). The time is the wall time of
  ``harness.run`` (the node is built before it); speed = bag time / wall time.

The table gives, per node, the medians of each tree and the median of the per-repeat ratios new / base (time
ratios: above 1 the new tree is slower). Run (install tree sourced)::

    python benchmarks/node_speed_against_base.py [--base 4c5248c] [--repeats 7]

Writes docs/reference/node_speed_against_base.md.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

OUT = ROOT / 'docs' / 'reference' / 'node_speed_against_base.md'
BASE = '4c5248c'
NODES = {
    # key: (package, module, class, executable, replay topics, bag (None: the carrier bag), parameters of the replay)
    'monitor': ('rfi_monitor', 'rfi_monitor.rfi_monitor_node', 'RfiMonitorNode', 'rfi_monitor_node',
                ('/rfi/if_samples',), 'default', {}),
    'fusion': ('uwb_gnss_fusion', 'uwb_gnss_fusion.fusion_node', 'FusionNode', 'fusion_node',
               ('/gnss/measurements', '/uwb/ranges'), 'default', {}),
    'carrier': ('imm_carrier', 'imm_carrier.imm_carrier_node', 'ImmCarrierNode', 'imm_carrier_node',
                ('/gnss/correlators',), None, {'method': 'both'}),
}
CARRIER_SECONDS = 4.0
"""Length of the imm_carrier bag, s (imm_carrier_node_speed.py's default)."""
NODE_BY_NODE = True
"""The nodes are measured one after the other (each with its warm-up), not alternated within a repeat: with the
nodes alternated, every base carrier replay recompiled 7 kernels of the base's rfi_node_common.cdr after a base
fusion replay (NUMBA_DEBUG_CACHE: 'data saved'), 8-13 s instead of 1.3-3.8 s, and the base fusion replays were
slowed alike (the cause was not found; a likely one: the base processes import the install tree's replay harness
and with it this tree's gnss_common.numba_cache hook). The two trees still alternate in every repeat."""
NOTES = """
Notes (measured beside the run of 2026-12-07; numbers from other runs than the table's):

* Where the new tree is slower: rfi_monitor_node's construction. Its warm-up loads 38 compiled kernels from
  numba's cache where 4c5248c loaded 30 (NUMBA_DEBUG_CACHE=1, 'data loaded'; which commits added them was not
  traced): warm_up() alone 0.74-0.90 s against 0.45-0.60 s, three alternated runs each. Everything else is
  within the machine's noise (ratios 0.85-1.08).
* A first run with the nodes alternated within each repeat gave the base fusion and carrier replays 2x and 5x
  slower than this tree's; that was an artefact of the benchmark (NODE_BY_NODE in the script), not a speed-up.
"""
"""Appended to the generated page."""
START_TIMEOUT_S = 600.0
"""Longest wait for a node's ready line (the first start of the base worktree compiles its kernels)."""


def _packages(package: str) -> tuple[str, ...]:
    return (package, 'gnss_common', 'rfi_node_common')


def _use_tree(src: Path, package: str) -> None:
    """Put the tree's packages first on sys.path (in a child)."""
    for pkg in reversed(_packages(package)):
        sys.path.insert(0, str(src / pkg))


def _check_tree(src: Path, package: str) -> None:
    import importlib

    for name in _packages(package):
        module = importlib.import_module(name)
        if not Path(module.__file__).resolve().is_relative_to(src.resolve()):
            raise RuntimeError(f'{name} imported from {module.__file__}, not from {src}')


STARTER = """
import sys, time
sys.path[:0] = {paths!r}
import {module} as node_module
for name, src in {checks!r}:
    mod = __import__(name)
    if not mod.__file__.startswith(src):
        raise SystemExit(f'{{name}} imported from {{mod.__file__}}, not from {{src}}')
print('IMPORTED', time.monotonic(), flush=True)
sys.exit(node_module.main(['{executable}']))
"""


def start_up(src: Path, node: str) -> dict[str, float]:
    """One start of the node of tree ``src``: seconds to the import of its module and to its ready line."""
    package, module, _, executable, _, _, _ = NODES[node]
    paths = [str(src / pkg) for pkg in _packages(package)]
    checks = [(pkg, str(src / pkg)) for pkg in _packages(package)]
    code = STARTER.format(paths=paths, module=module, checks=checks, executable=executable)
    env = dict(os.environ, RCUTILS_LOGGING_BUFFERED_STREAM='0', PYTHONUNBUFFERED='1')
    t0 = time.monotonic()
    proc = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, env=env, cwd=ROOT)
    imported = ready = None
    lines = []
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line)
            if line.startswith('IMPORTED '):
                imported = float(line.split()[1]) - t0
            elif f'{executable} ready' in line:
                ready = time.monotonic() - t0
                break
            if time.monotonic() - t0 > START_TIMEOUT_S:
                break
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    if ready is None or imported is None:
        raise RuntimeError(f'{node} of {src} did not start:\n' + ''.join(lines[-30:]))
    return {'import_s': imported, 'ready_s': ready}


def replay_child(src: Path, node: str, bag: Path) -> None:
    """(child) Replay the node's workload once through the node of tree ``src``; print the timing as JSON."""
    import importlib

    import rclpy
    from rclpy.parameter import Parameter

    from rfi_experiments.replay import ReplayHarness  # this tree's harness (its own rfi_node_common, gnss_common)

    package, module, class_name, _, topics, _, params = NODES[node]
    for name in [m for m in sys.modules if m.split('.')[0] in _packages(package)]:
        del sys.modules[name]  # the node imports the tree's copies; the harness keeps the objects it took
    _use_tree(src, package)
    node_cls = getattr(importlib.import_module(module), class_name)
    _check_tree(src, package)

    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    try:
        instance = node_cls(context=context, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
        harness = ReplayHarness([instance], context=context, collect={}, transport='direct')
        t0 = time.perf_counter()
        result = harness.run(str(bag), topics=list(topics))
        wall = time.perf_counter() - t0
        inputs = sum(result.inputs.values())
        bag_s = (result.inputs['/gnss/correlators'] * 1e-3 if node == 'carrier' else result.bag_duration_s)
        harness.destroy()
        instance.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    print(json.dumps({'wall_s': wall, 'bag_s': bag_s, 'inputs': inputs}))


def replay(src: Path, node: str, bag: Path) -> dict[str, float]:
    done = subprocess.run([sys.executable, __file__, '--child', '--src', str(src), '--node', node, '--bag', str(bag)],
                          capture_output=True, text=True, env=dict(os.environ), cwd=ROOT)
    if done.returncode != 0:
        raise RuntimeError(f'replay of {node} of {src} failed:\n{done.stderr[-3000:]}')
    return json.loads(done.stdout.strip().splitlines()[-1])


def carrier_bag(path: Path) -> Path:
    """imm_carrier_node_speed.py's bag: 32 GPS satellites, T = 1 ms, CARRIER_SECONDS long."""
    from rfi_experiments.scenario import Scenario, write_scenario_bag

    sats = [{'svid': s, 'cn0_drop_db': 0.0} for s in range(1, 33)]
    scenario = Scenario(name='speed', description='32 satellites, T = 1 ms', seed=3, duration_s=CARRIER_SECONDS,
                        streams={'correlators': {'integration_time_s': 0.001, 'onset_s': 1e6, 'satellites': sats}})
    write_scenario_bag(scenario, path, overwrite=True)
    return path


def _median_ratio(new: list[float], base: list[float]) -> float:
    return statistics.median(n / b for n, b in zip(new, base, strict=True))


def table(runs: dict, base: str, head: str) -> str:
    lines = [f'| node | measurement | base {base}, median | this tree ({head}), median | new / base (median of the '
             'per-repeat ratios) |', '|---|---|---|---|---|']
    for node in runs:
        executable = NODES[node][3]
        r = runs[node]
        for key, what, unit in (('ready_s', 'start-up: process start to ready log', 's'),
                                ('import_s', '  of which interpreter + imports', 's'),
                                ('build_s', '  of which node construction (ready - import)', 's'),
                                ('wall_s', 'replay wall time', 's')):
            b, n = r['base'][key], r['new'][key]
            lines.append(f'| {executable} | {what} | {statistics.median(b):.3f} {unit} | '
                         f'{statistics.median(n):.3f} {unit} | {_median_ratio(n, b):.3f} |')
        b_rtf = [s / w for s, w in zip(r['base']['bag_s'], r['base']['wall_s'], strict=True)]
        n_rtf = [s / w for s, w in zip(r['new']['bag_s'], r['new']['wall_s'], strict=True)]
        lines.append(f'| {executable} | replay speed (bag time / wall time) | {statistics.median(b_rtf):.2f}x | '
                     f'{statistics.median(n_rtf):.2f}x | {_median_ratio(n_rtf, b_rtf):.3f} (speed ratio) |')
    return '\n'.join(lines) + '\n'


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--base', default=BASE, help=f'the commit to compare with (default {BASE})')
    ap.add_argument('--repeats', type=int, default=7)
    ap.add_argument('--nodes', nargs='+', default=list(NODES), choices=list(NODES))
    ap.add_argument('--no-write', action='store_true', help='print the table only')
    ap.add_argument('--base-tree', type=Path, help='an existing checkout of --base to use (its numba caches kept)')
    ap.add_argument('--child', action='store_true', help=argparse.SUPPRESS)
    ap.add_argument('--src', type=Path, help=argparse.SUPPRESS)
    ap.add_argument('--node', help=argparse.SUPPRESS)
    ap.add_argument('--bag', type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        replay_child(args.src, args.node, args.bag)
        return 0
    from compare_fusion_outputs import base_worktree

    head = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True, text=True, cwd=ROOT,
                          check=True).stdout.strip()
    dirty = subprocess.run(['git', 'status', '--porcelain', '--', 'src'], capture_output=True, text=True, cwd=ROOT,
                           check=True).stdout.strip()
    head += ' + changes in src/' if dirty else ''
    runs: dict = {node: {'base': {}, 'new': {}} for node in args.nodes}
    t_start = time.monotonic()
    if args.base_tree is not None:
        import contextlib
        import tempfile

        worktree: Any = contextlib.nullcontext((args.base_tree, Path(tempfile.mkdtemp(prefix='node_speed_'))))
    else:
        worktree = base_worktree(args.base, 0.0, 'node_speed_')
    with worktree as (base_tree, tmp):
        trees = {'base': base_tree / 'src', 'new': ROOT / 'src'}
        bags = {node: (ROOT / 'bags' / NODES[node][5] if NODES[node][5] else carrier_bag(tmp / 'carrier_bag'))
                for node in args.nodes}
        for node in args.nodes:  # one node after the other (see NODE_BY_NODE)
            for name, src in trees.items():  # fill numba's on-disk caches: a start and a replay (not measured)
                t0 = time.monotonic()
                start_up(src, node)
                replay(src, node, bags[node])
                print(f'warm-up {node} {name}: {time.monotonic() - t0:.1f} s', file=sys.stderr)
            for rep in range(args.repeats):
                order = ('base', 'new') if rep % 2 == 0 else ('new', 'base')
                for name in order:
                    s = start_up(trees[name], node)
                    r = replay(trees[name], node, bags[node])
                    row = runs[node][name]
                    for key, value in {**s, 'build_s': s['ready_s'] - s['import_s'], **r}.items():
                        row.setdefault(key, []).append(value)
                    print(f'[{rep + 1}/{args.repeats}] {node} {name}: ready {s["ready_s"]:.2f} s '
                          f'(import {s["import_s"]:.2f} s), replay {r["wall_s"]:.2f} s', file=sys.stderr)
                if runs[node]['base']['inputs'][-1] != runs[node]['new']['inputs'][-1]:
                    raise RuntimeError(f'{node}: the trees replayed different input counts')
    text = table({n: runs[n] for n in args.nodes}, args.base, head)
    print(text)
    if args.no_write:
        return 0
    load = ', '.join(f'{x:.1f}' for x in os.getloadavg())
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(
        f'# Node start-up and replay speed: this tree against {args.base}\n\n'
        'Generated by benchmarks/node_speed_against_base.py (its docstring says what is timed and how). '
        f'Base {args.base} (main before issue 28; a git worktree of it) against this tree ({head}), node by node, '
        f'{args.repeats} repeats, the two trees alternated in each, every measurement in a fresh process; '
        f'the whole run took {(time.monotonic() - t_start) / 60:.0f} min on the development machine (2 cores '
        f'shared with other jobs; load average at the end {load}; Python {sys.version.split()[0]}). '
        'Ratios new / base of times: above 1 the new tree is slower; of speeds: below 1 it is slower. '
        'Start-up: process start to the node\'s ready log line, warm numba cache, default parameters. '
        'Replay: rfi_monitor_node on bags/default /rfi/if_samples, fusion_node on bags/default GNSS + UWB, '
        f'imm_carrier_node (method both) on a {CARRIER_SECONDS:g} s 32-satellite 1 kHz bag; direct transport.\n\n'
        + text + NOTES)
    print(f'wrote {OUT.relative_to(ROOT)}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
