"""Does imm_carrier_node keep up with 32 satellites at 1 kHz? In-process bag replay, real-time factor.

Run (workspace built, venv and install/setup.bash sourced, src/ on PYTHONPATH as in the task notes):
    python benchmarks/imm_carrier_node_speed.py [--seconds 4] [--repeats 3]
Writes docs/imm_carrier/node_speed.md.

What is measured, for method imm, pll and both:
* replay: the bag (32 GPS satellites, T = 1 ms, rubidium clock, 51 dB-Hz) replayed through the
  node with rfi_experiments.replay.ReplayHarness at maximum rate (one message in flight, DDS
  in-process, one SingleThreadedExecutor); real-time factor = bag time / wall time (> 1 keeps up).
* callback: the node's on_correlators called directly on the decoded messages (no DDS, no
  executor): the node's own ceiling.
* where the time goes: cProfile of one callback-only run, split into the core
  (CarrierTracker.process), message conversion in and out, and publishing (serialisation).
Medians of the repeats are quoted. Machine: 2 shared cores (other engineers' jobs running).
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import statistics
import sys
import tempfile
import time
from pathlib import Path

import rclpy
from rclpy.context import Context
from rclpy.parameter import Parameter

from imm_carrier.imm_carrier_node import ImmCarrierNode
from rfi_experiments.bag_io import BagReader
from rfi_experiments.replay import ReplayHarness
from rfi_experiments.scenario import Scenario, write_scenario_bag

OUT = Path(__file__).resolve().parents[1] / 'docs' / 'imm_carrier' / 'node_speed.md'
N_SATELLITES = 32
METHODS = ('imm', 'pll', 'both')


def make_bag(path: Path, seconds: float) -> None:
    sats = [{'svid': s, 'cn0_drop_db': 0.0} for s in range(1, N_SATELLITES + 1)]
    scenario = Scenario(name='speed', description='32 satellites, T = 1 ms', seed=3, duration_s=seconds,
                        streams={'correlators': {'integration_time_s': 0.001, 'onset_s': 1e6, 'satellites': sats}})
    write_scenario_bag(scenario, path, overwrite=True)


def new_node(method: str) -> tuple[Context, ImmCarrierNode]:
    context = Context()
    rclpy.init(context=context)
    return context, ImmCarrierNode(context=context, parameter_overrides=[Parameter('method', value=method)])


def replay_rtf(bag: Path, method: str) -> tuple[float, int]:
    context, node = new_node(method)
    try:
        harness = ReplayHarness([node], context=context, collect=['/diagnostics'])
        result = harness.run(bag, topics=['/gnss/correlators'])
        harness.destroy()
        # 1 ms intervals: the log-time span of n arrays is (n - 1) ms; count n ms of bag time.
        n = result.inputs['/gnss/correlators']
        return n * 1e-3 / result.wall_time_s, node.counts['arrays_processed']
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


def callback_rtf(messages: list, method: str, profile: cProfile.Profile | None = None) -> float:
    context, node = new_node(method)
    try:
        t0 = time.perf_counter()
        if profile is not None:
            profile.enable()
        for msg in messages:
            node.on_correlators(msg)
        if profile is not None:
            profile.disable()
        return len(messages) * 1e-3 / (time.perf_counter() - t0)
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


def split(profile: cProfile.Profile) -> dict[str, float]:
    """Cumulative seconds in the node's parts (from cProfile; profiling overhead included)."""
    stats = pstats.Stats(profile)
    total = 0.0
    parts = {'core (CarrierTracker.process)': ('tracker.py', 'process'),
             'msg -> CorrelatorSample': ('imm_carrier_node.py', 'correlator_sample'),
             'estimate -> CarrierPhase msg': ('imm_carrier_node.py', 'carrier_phase_msg'),
             'publish (serialise + DDS write)': ('publisher.py', 'publish')}
    out = dict.fromkeys(parts, 0.0)
    for (filename, _, func), (_, _, _, cumtime, _) in stats.stats.items():  # type: ignore[attr-defined]
        if func == 'on_correlators':
            total = max(total, cumtime)
        for name, (file_end, fname) in parts.items():
            if filename.endswith(file_end) and func == fname:
                out[name] += cumtime
    out['rest of the callback (diagnostics, counters, list building)'] = total - sum(out.values())
    out['total callback'] = total
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seconds', type=float, default=4.0, help='bag duration, s')
    parser.add_argument('--repeats', type=int, default=3)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / 'bag'
        t0 = time.perf_counter()
        make_bag(bag, args.seconds)
        gen_s = time.perf_counter() - t0
        with BagReader(bag) as reader:
            messages = [m.decode() for m in reader.messages(['/gnss/correlators'])]
        rows = []
        splits = {}
        for method in METHODS:
            callback_rtf(messages[:200], method)  # warm-up: numba cache load
            replay = [replay_rtf(bag, method) for _ in range(args.repeats)]
            assert all(n == len(messages) for _, n in replay), 'not every array was processed'
            direct = [callback_rtf(messages, method) for _ in range(args.repeats)]
            rows.append((method, statistics.median(r for r, _ in replay), statistics.median(direct)))
            profile = cProfile.Profile()
            callback_rtf(messages, method, profile)
            splits[method] = split(profile)
            print(f'{method}: replay RTF {rows[-1][1]:.2f}, callback RTF {rows[-1][2]:.2f}', file=sys.stderr)
    updates = {'imm': N_SATELLITES, 'pll': N_SATELLITES, 'both': 2 * N_SATELLITES}
    lines = ['| method | filter updates / s needed | replay RTF (bag through DDS + executor) | callback-only RTF | '
             'keeps up (replay RTF >= 1) |', '|---|---|---|---|---|']
    for method, replay, direct in rows:
        lines.append(f'| {method} | {updates[method] * 1000:,} | {replay:.2f} | {direct:.2f} | '
                     f'{"yes" if replay >= 1.0 else "no"} |')
    lines += ['', '| part of the callback (cProfile, one run) | ' + ' | '.join(METHODS) + ' |',
              '|---|' + '---|' * len(METHODS)]
    for part in splits['imm']:
        cells = []
        for method in METHODS:
            s = splits[method]
            cells.append(f'{s[part]:.2f} s ({100 * s[part] / s["total callback"]:.0f} %)')
        lines.append(f'| {part} | ' + ' | '.join(cells) + ' |')
    load = ', '.join(f'{x:.1f}' for x in os.getloadavg())
    table = '\n'.join(lines)
    print(table)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(
        '# imm_carrier_node: 32 satellites at 1 kHz, in-process bag replay\n\n'
        f'Generated by benchmarks/imm_carrier_node_speed.py: a {args.seconds:g} s bag (32 GPS satellites, T = 1 ms, '
        f'{len(messages)} CorrelatorArrays; simulated in {gen_s:.1f} s) replayed at maximum rate, medians of '
        f'{args.repeats} repeats, on the development machine (2 cores shared with other jobs; '
        f'Python {sys.version.split()[0]}, {os.cpu_count()} CPUs seen, load average at the end {load}). '
        'RTF = bag time / wall time: above 1 the node keeps up in real time.\n\n' + table + '\n\n'
        'cProfile times include the profiler\'s own overhead (it slows Python-heavy parts most); the shares, '
        'not the seconds, are the point.\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
