"""Does imm_carrier_node keep up with 32 satellites at 1 kHz? In-process bag replay, real-time factor.

Run (workspace built, venv and install/setup.bash sourced, src/ on PYTHONPATH as in the task notes):
    python benchmarks/imm_carrier_node_speed.py [--seconds 4] [--repeats 3]
Writes docs/imm_carrier/node_speed.md.

What is measured, for method imm, pll and both (real-time factor RTF = bag time / wall time; above 1
the node keeps up):
* replay, dds: the bag (32 GPS satellites, T = 1 ms, rubidium clock, 51 dB-Hz) replayed through the
  node with rfi_experiments.replay.ReplayHarness at maximum rate, transport 'dds' (middleware
  in-process, one SingleThreadedExecutor, one message in flight, spin until settled).
* replay, direct: the same harness with transport 'direct' (same node and callbacks, messages handed
  over in-process without the middleware; serialisation kept).
* callback: the node's on_correlators called directly on the serialised messages, as its raw
  subscription receives them (no harness, no executor): the node's own ceiling.
* reference: a fixed pure-Python + numpy workload timed right before every measurement. Its time
  over the fastest time seen in the whole run is the load slowdown of that moment (another process
  shares the 2 cores); "normalised RTF" = RTF x slowdown estimates the RTF on an idle machine.
* where the time goes: cProfile of one callback-only run, split into decoding, the core, encoding,
  publishing and the rest of the callback.
Medians of the repeats are quoted.
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

import numpy as np
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
MODES = ('dds', 'direct', 'callback')


def make_bag(path: Path, seconds: float) -> None:
    sats = [{'svid': s, 'cn0_drop_db': 0.0} for s in range(1, N_SATELLITES + 1)]
    scenario = Scenario(name='speed', description='32 satellites, T = 1 ms', seed=3, duration_s=seconds,
                        streams={'correlators': {'integration_time_s': 0.001, 'onset_s': 1e6, 'satellites': sats}})
    write_scenario_bag(scenario, path, overwrite=True)


def reference_time_s() -> float:
    """Wall time of a fixed mixed workload (Python loop + small numpy calls), s; the load probe."""
    t0 = time.perf_counter()
    acc = 0.0
    a = np.arange(64, dtype=float)
    for k in range(20_000):
        acc += float(np.sum(a * k)) * 1e-9 + (k % 7)
    return time.perf_counter() - t0


def new_node(method: str) -> tuple[Context, ImmCarrierNode]:
    context = Context()
    rclpy.init(context=context)
    return context, ImmCarrierNode(context=context, parameter_overrides=[Parameter('method', value=method)])


def replay_rtf(bag: Path, method: str, transport: str) -> tuple[float, int]:
    context, node = new_node(method)
    try:
        harness = ReplayHarness([node], context=context, collect=['/diagnostics'], transport=transport)
        result = harness.run(bag, topics=['/gnss/correlators'])
        harness.destroy()
        # 1 ms intervals: the log-time span of n arrays is (n - 1) ms; count n ms of bag time.
        n = result.inputs['/gnss/correlators']
        return n * 1e-3 / result.wall_time_s, node.counts['arrays_processed']
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


def callback_rtf(raws: list[bytes], method: str, profile: cProfile.Profile | None = None) -> tuple[float, int]:
    context, node = new_node(method)
    try:
        t0 = time.perf_counter()
        if profile is not None:
            profile.enable()
        for raw in raws:
            node.on_correlators(raw)
        if profile is not None:
            profile.disable()
        return len(raws) * 1e-3 / (time.perf_counter() - t0), node.counts['arrays_processed']
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


def split(profile: cProfile.Profile) -> dict[str, float]:
    """Cumulative seconds in the node's parts (from cProfile; profiling overhead included)."""
    stats = pstats.Stats(profile)
    total = 0.0
    parts = {'decode (CDR -> arrays)': ('cdr.py', 'decode_correlator_array'),
             'core (CarrierTracker.process_arrays)': ('tracker.py', 'process_arrays'),
             'encode (table -> CDR)': ('cdr.py', 'encode_carrier_phase_array'),
             'publish (DDS write of the bytes)': ('publisher.py', 'publish')}
    out = dict.fromkeys(parts, 0.0)
    for (filename, _, func), (_, _, _, cumtime, _) in stats.stats.items():  # type: ignore[attr-defined]
        if func == 'on_correlators':
            total = max(total, cumtime)
        for name, (file_end, fname) in parts.items():
            if filename.endswith(file_end) and func == fname:
                out[name] += cumtime
    out['rest of the callback (diagnostics, counters)'] = total - sum(out.values())
    out['total callback'] = total
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seconds', type=float, default=4.0, help='bag duration, s')
    parser.add_argument('--repeats', type=int, default=3)
    args = parser.parse_args(argv)
    reference_time_s()
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / 'bag'
        t0 = time.perf_counter()
        make_bag(bag, args.seconds)
        gen_s = time.perf_counter() - t0
        with BagReader(bag) as reader:
            raws = [m.raw for m in reader.messages(['/gnss/correlators'])]
        runs: dict[tuple[str, str], list[tuple[float, float]]] = {}  # (method, mode) -> [(rtf, ref_s)]
        splits = {}
        for method in METHODS:
            callback_rtf(raws[:200], method)  # warm-up: numba cache load
            for _ in range(args.repeats):
                for mode in MODES:
                    ref = reference_time_s()
                    if mode == 'callback':
                        rtf, n = callback_rtf(raws, method)
                    else:
                        rtf, n = replay_rtf(bag, method, mode)
                    assert n == len(raws), 'not every array was processed'
                    runs.setdefault((method, mode), []).append((rtf, ref))
            profile = cProfile.Profile()
            callback_rtf(raws, method, profile)
            splits[method] = split(profile)
            print(method, {m: [round(r, 2) for r, _ in runs[(method, m)]] for m in MODES}, file=sys.stderr)
    ref_best = min(ref for v in runs.values() for _, ref in v)
    updates = {'imm': N_SATELLITES, 'pll': N_SATELLITES, 'both': 2 * N_SATELLITES}
    lines = ['| method | filter updates / s needed | replay RTF, dds | replay RTF, direct | callback-only RTF | '
             'load slowdown (median) | normalised RTF dds / direct / callback | keeps up through DDS (RTF >= 1) |',
             '|---|---|---|---|---|---|---|---|']
    for method in METHODS:
        med = {m: statistics.median(r for r, _ in runs[(method, m)]) for m in MODES}
        norm = {m: statistics.median(r * ref / ref_best for r, ref in runs[(method, m)]) for m in MODES}
        slow = statistics.median(ref / ref_best for m in MODES for _, ref in runs[(method, m)])
        lines.append(f'| {method} | {updates[method] * 1000:,} | {med["dds"]:.2f} | {med["direct"]:.2f} | '
                     f'{med["callback"]:.2f} | {slow:.2f} | {norm["dds"]:.2f} / {norm["direct"]:.2f} / '
                     f'{norm["callback"]:.2f} | {"yes" if med["dds"] >= 1.0 else "no"} |')
    lines += ['', '| part of the callback (cProfile, one run) | ' + ' | '.join(METHODS) + ' |',
              '|---|' + '---|' * len(METHODS)]
    for part in splits['imm']:
        cells = []
        for method in METHODS:
            s = splits[method]
            us = 1e6 * s[part] / len(raws)
            cells.append(f'{us:.0f} us ({100 * s[part] / s["total callback"]:.0f} %)')
        lines.append(f'| {part} | ' + ' | '.join(cells) + ' |')
    load = ', '.join(f'{x:.1f}' for x in os.getloadavg())
    table = '\n'.join(lines)
    print(table)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(
        '# imm_carrier_node: 32 satellites at 1 kHz, in-process bag replay\n\n'
        f'Generated by benchmarks/imm_carrier_node_speed.py: a {args.seconds:g} s bag (32 GPS satellites, T = 1 ms, '
        f'{len(raws)} CorrelatorArrays; simulated in {gen_s:.1f} s) replayed at maximum rate, medians of '
        f'{args.repeats} repeats, on the development machine (2 cores shared with other jobs; '
        f'Python {sys.version.split()[0]}, {os.cpu_count()} CPUs seen, load average at the end {load}). '
        'RTF = bag time / wall time: above 1 the node keeps up in real time. dds: ReplayHarness through the '
        'middleware (one message in flight); direct: ReplayHarness transport direct (no middleware); callback: '
        'on_correlators on the serialised messages. Load slowdown: time of a fixed reference workload just '
        f'before each measurement over its fastest time in this run ({ref_best * 1e3:.0f} ms); normalised RTF = '
        'RTF x slowdown.\n\n' + table + '\n\n'
        'Per-message times in the second table are cProfile cumulative times over the messages (the profiler adds '
        'overhead to each Python call); the shares are the point.\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
