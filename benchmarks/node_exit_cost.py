"""What a node process's exit costs once the node has shut down, with and without its heap frozen.

``rfi_node_common.main.run_node`` freezes the heap (``gc.freeze``) at exit, so that the interpreter's final garbage
collection does not traverse the node's numba kernels, their type objects and scipy. On a loaded machine that
collection lasted longer than ros2 launch waits between its SIGINT and its SIGTERM (5 s), and gnss_integrity_node
was killed in CI (docs/testing.md).

Each node is built in a fresh child process (rclpy.init, the node with its kernels warmed up, destroy_node,
rclpy.try_shutdown), which then exits as the node does after Ctrl-C, either as before (``collected``) or with its heap
frozen (``frozen``). The parent reads the child's CPU time (user + system, ``os.wait4``) and subtracts what the child
had used when it began to exit: the CPU time of the exit alone, which load does not stretch as it does wall time.
Medians of --repeats children per node and mode.

Usage (workspace sourced): python benchmarks/node_exit_cost.py [--repeats N]
Writes docs/node_exit.md.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / 'docs' / 'node_exit.md'

NODES: dict[str, str] = {
    'gnss_integrity_node': 'from gnss_integrity.gnss_integrity_node import GnssIntegrityNode as N',
    'fusion_node': 'from uwb_gnss_fusion.fusion_node import FusionNode as N',
    'rfi_monitor_node': 'from rfi_monitor.rfi_monitor_node import RfiMonitorNode as N',
    'imm_carrier_node': 'from imm_carrier.imm_carrier_node import ImmCarrierNode as N',
}
"""Each node's class, as its executable builds it."""

CHILD = '''
import gc, os, sys
import rclpy
{import_node}
rclpy.init()
node = N()
node.destroy_node()
rclpy.try_shutdown()
if sys.argv[1] == 'frozen':
    gc.freeze()
t = os.times()
print('CPU', t.user + t.system, flush=True)
'''


def exit_cpu_s(import_node: str, mode: str) -> float:
    """CPU time of one child's exit, s."""
    proc = subprocess.Popen([sys.executable, '-c', CHILD.format(import_node=import_node), mode],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    assert proc.stdout is not None
    line = proc.stdout.readline().split()
    _, status, usage = os.wait4(proc.pid, 0)
    if status != 0 or not line or line[0] != 'CPU':
        raise RuntimeError(f'the child of {import_node!r} failed (status {status})')
    return usage.ru_utime + usage.ru_stime - float(line[1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeats', type=int, default=5)
    args = parser.parse_args()
    rows = []
    for name, import_node in NODES.items():
        medians = {mode: statistics.median(exit_cpu_s(import_node, mode) for _ in range(args.repeats))
                   for mode in ('collected', 'frozen')}
        rows.append((name, medians['collected'], medians['frozen']))
        print(f'{name}: exit CPU {medians["collected"]:.3f} s collected, {medians["frozen"]:.3f} s frozen', flush=True)
    lines = ['# What a node process\'s exit costs', '',
             'Written by `benchmarks/node_exit_cost.py` (its docstring says how it measures). CPU time of the exit',
             'of a node process after its node has shut down (user + system, medians of '
             f'{args.repeats} processes per cell).',
             'The heap frozen before the interpreter\'s final collection is what `run_node` does since the exit of',
             'gnss_integrity_node outlasted ros2 launch\'s SIGINT-to-SIGTERM wait in CI ([testing.md](testing.md)).',
             '', '| node | exit CPU, heap collected (before), s | exit CPU, heap frozen (now), s | ratio |',
             '|---|---|---|---|']
    for name, before, after in rows:
        lines.append(f'| {name} | {before:.3f} | {after:.3f} | {before / after:.1f} |')
    lines += ['', 'On a loaded machine the wall time of the exit is a multiple of its CPU time (measured beside two',
              'busy loops and three other sessions\' work: gnss_integrity_node exited 1.6-1.8 s after its last',
              'Python line as before, 0.3 s frozen).', '']
    OUT.write_text('\n'.join(lines))
    print(f'wrote {OUT.relative_to(ROOT)}')


if __name__ == '__main__':
    main()
