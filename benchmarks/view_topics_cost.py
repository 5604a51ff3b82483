"""What the topics made to be drawn (issue 30) cost the nodes: node speed with and without them, nobody subscribed.

Two nodes, each run by the current code and by the code before issue 30's drawn topics (``--baseline-commit``, its
``src/rfi_monitor``, ``src/uwb_gnss_fusion`` and ``src/gnss_common`` exported with ``git archive`` and put first on
PYTHONPATH), alternated, each run in a fresh interpreter; the figure is the median of the per-repeat time ratios
current / baseline (robust to the load of the shared machine), 1.00 meaning no cost:

* rfi_monitor_node, node level: ``RfiMonitorNode.on_block`` on 400 simulated 1 ms blocks of 38.192 MS/s 2-bit real IF
  (20 jammer-free, then the paper's saw-tooth chirp at J/S 40 dB; rfi_sim, seeded) after 20 warm-up blocks, timed
  with the thread's CPU time (the shipped parameters, ``max_cpu_load`` 0: every block analysed in full). Also the
  current code with a subscriber on /rfi/spectrum/waterfall at the default 5 Hz and at a row per block (1000 Hz),
  against the current code without one: what drawing costs while someone looks.
* fusion_node: the existing ``benchmarks/fusion_node_speed.py --single`` (bags/default, 180 s, 11,700 inputs,
  in-process direct transport, nobody subscribed to anything), its wall time.

Run (workspace sourced)::

    python benchmarks/view_topics_cost.py [--repeats 7] [--baseline-commit 4c5248c]

Writes docs/guide/visualisation_cost.md and prints its table.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_progress import add_quiet_argument, case_log

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / 'docs' / 'guide' / 'visualisation_cost.md'
BASELINE_COMMIT = '4c5248c'
"""The last commit before the drawn topics (issue 30 item 2)."""
PACKAGES = ('rfi_monitor', 'uwb_gnss_fusion', 'gnss_common')
BLOCKS, WARM_UP, CLEAN = 400, 20, 20
START_NS = 1_700_000_000_000_000_000


def monitor_single(subscribed_rate_hz: float) -> dict:
    """One monitor run in this interpreter (``subscribed_rate_hz`` > 0: a subscriber on the waterfall and that
    spectrum_rate_hz)."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from rfi_monitor.rfi_monitor_node import RfiMonitorNode
    from rfi_msgs.msg import IfSamples
    from rfi_node_common.stamps import ns_to_stamp
    from rfi_sim.if_signal import ChirpJammer, FrontEndConfig, IfSimulator

    fe = FrontEndConfig(noise_bandwidth_hz=2.0e6)
    size = round(1e-3 * fe.sample_rate_hz)
    clean, jammed = IfSimulator(fe, (), seed=3), IfSimulator(fe, (ChirpJammer(js_db=40.0),), seed=4)
    msgs = []
    for k in range(WARM_UP + BLOCKS):
        blk = (clean if k < WARM_UP + CLEAN else jammed).generate(size)
        m = IfSamples(sample_rate_hz=blk.sample_rate_hz, intermediate_frequency_hz=blk.intermediate_frequency_hz,
                      center_frequency_hz=1575.42e6, is_complex=False, first_sample_index=k * size,
                      scale=float(blk.scale), bits_per_sample=blk.bits, sample_format=IfSamples.INT8)
        m.header.stamp = ns_to_stamp(START_NS + k * 1_000_000)
        m.samples = blk.counts.astype('<i1').tobytes()
        msgs.append(m)
    ctx = Context()
    rclpy.init(context=ctx)
    try:
        params = [Parameter('max_cpu_load', value=0.0), Parameter('input_timeout_s', value=0.0)]
        if subscribed_rate_hz > 0:
            params.append(Parameter('spectrum_rate_hz', value=float(subscribed_rate_hz)))
        node = RfiMonitorNode(context=ctx, parameter_overrides=params)
        if subscribed_rate_hz > 0:
            from sensor_msgs.msg import Image
            viewer = Node('viewer', context=ctx)
            viewer.create_subscription(Image, '/rfi/spectrum/waterfall', lambda _m: None, 5)
            ex = SingleThreadedExecutor(context=ctx)
            ex.add_node(viewer)
            deadline = time.monotonic() + 30.0
            while node.spectrum.image_pub.get_subscription_count() == 0:
                if time.monotonic() > deadline:
                    raise RuntimeError('the viewer was not discovered within 30 s')
                ex.spin_once(timeout_sec=0.05)
        for m in msgs[:WARM_UP]:
            node.on_block(m)
        t0 = time.thread_time()
        for m in msgs[WARM_UP:]:
            node.on_block(m)
        cpu_s = time.thread_time() - t0
        spectrum = getattr(node, 'spectrum', None)
        out = {'cpu_s': cpu_s, 'blocks': BLOCKS, 'processed': node.counts['blocks_processed'] - WARM_UP,
               'images': spectrum.published if spectrum is not None else 0}
        node.destroy_node()
        return out
    finally:
        rclpy.shutdown(context=ctx)


def added_work() -> dict:
    """The work the drawn topics add per input while nobody subscribes, timed directly in this interpreter (thread
    CPU time over many calls; far less sensitive to the machine's load than the end-to-end ratio): the monitor's
    ``_draw`` per block and the ``BlockSpectrum`` its estimator keeps, against the node's own time per block; the
    fusion's ``_draw`` per input at the input rate of bags/default."""
    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter

    from rfi_monitor.estimate import BlockSpectrum
    from rfi_monitor.rfi_monitor_node import RfiMonitorNode
    from rfi_msgs.msg import IfSamples
    from rfi_node_common.stamps import ns_to_stamp
    from rfi_sim.if_signal import ChirpJammer, FrontEndConfig, IfSimulator
    from uwb_gnss_fusion.fusion_node import FusionNode
    from uwb_gnss_fusion.input_admission import Item

    fe = FrontEndConfig(noise_bandwidth_hz=2.0e6)
    size = round(1e-3 * fe.sample_rate_hz)
    sim = IfSimulator(fe, (ChirpJammer(js_db=40.0),), seed=4)
    msgs = []
    for k in range(WARM_UP + 200):
        blk = sim.generate(size)
        m = IfSamples(sample_rate_hz=blk.sample_rate_hz, intermediate_frequency_hz=blk.intermediate_frequency_hz,
                      center_frequency_hz=1575.42e6, is_complex=False, first_sample_index=k * size,
                      scale=float(blk.scale), bits_per_sample=blk.bits, sample_format=IfSamples.INT8)
        m.header.stamp = ns_to_stamp(START_NS + k * 1_000_000)
        m.samples = blk.counts.astype('<i1').tobytes()
        msgs.append(m)
    ctx = Context()
    rclpy.init(context=ctx)
    try:
        node = RfiMonitorNode(context=ctx, parameter_overrides=[Parameter('max_cpu_load', value=0.0),
                                                                Parameter('input_timeout_s', value=0.0)])
        for m in msgs[:WARM_UP]:
            node.on_block(m)
        t0 = time.thread_time()
        for m in msgs[WARM_UP:]:
            node.on_block(m)
        block_s = (time.thread_time() - t0) / (len(msgs) - WARM_UP)
        spec = node.monitor.last_spectrum
        est = node.monitor.process(np.frombuffer(bytes(msgs[-1].samples), dtype='<i1').astype(np.float64),
                                   msgs[-1].sample_rate_hz, msgs[-1].intermediate_frequency_hz,
                                   msgs[-1].first_sample_index + size, START_NS + 10**9)
        n = 100_000
        t0 = time.thread_time()
        for k in range(n):
            node._draw(START_NS + k, est, msgs[-1])
        draw_s = (time.thread_time() - t0) / n
        t0 = time.thread_time()
        for k in range(n):
            BlockSpectrum(k, spec.psd, spec.sample_rate_hz, spec.intermediate_frequency_hz, spec.cplx)
        keep_s = (time.thread_time() - t0) / n
        assert node.spectrum.published == 0 and node.counts['spectrum_errors'] == 0
        node.destroy_node()
        fusion = FusionNode(context=ctx, parameter_overrides=[Parameter('idle_flush_s', value=0.0),
                                                             Parameter('input_timeout_s', value=0.0)])
        period_ns = round(180e9 / 11700)                  # bags/default: 11,700 inputs in 180 s
        items = [Item(START_NS + k * period_ns, 'uwb', None) for k in range(n)]   # the node makes these anyway
        t0 = time.thread_time()
        for item in items:
            fusion._draw(item, None)
        fusion_s = (time.thread_time() - t0) / n
        assert fusion.view.published == 0 and fusion.counts['view_errors'] == 0
        fusion.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)
    return {'block_s': block_s, 'draw_s': draw_s, 'keep_s': keep_s, 'fusion_draw_s': fusion_s, 'calls': n}


def run(env_src: Path | None, args: list[str]) -> dict:
    """A fresh interpreter running ``args`` (``env_src``: baseline packages first on PYTHONPATH); its last stdout
    line as JSON."""
    env = dict(os.environ)
    if env_src is not None:
        env['PYTHONPATH'] = os.pathsep.join([str(env_src / p) for p in PACKAGES] + [env.get('PYTHONPATH', '')])
    done = subprocess.run([sys.executable, *args], env=env, check=True, capture_output=True, text=True, cwd=ROOT)
    return json.loads(done.stdout.strip().splitlines()[-1])


def export_baseline(commit: str, into: Path) -> Path:
    """``src/<pkg>`` of ``commit`` for the packages above, under ``into``; returns ``into / 'src'``."""
    archive = subprocess.run(['git', 'archive', commit] + [f'src/{p}' for p in PACKAGES], cwd=ROOT, check=True,
                             capture_output=True).stdout
    subprocess.run(['tar', '-x', '-C', str(into)], input=archive, check=True)
    return into / 'src'


ADDED_START = '<!-- added work: start -->'
ADDED_END = '<!-- added work: end -->'


def added_work_section(r: dict) -> str:
    """The generated section of the direct timing (between ADDED_START and ADDED_END)."""
    mon_us = 1e6 * (r['draw_s'] + r['keep_s'])
    fus_us = 1e6 * r['fusion_draw_s']
    return (
        f'{ADDED_START}\n## The added work, timed directly (nobody subscribed)\n\n'
        'The end-to-end ratios above are as noisy as the shared machine (the same code with and without a viewer at '
        '5 Hz differs by as much). The work the drawn topics add per input while nobody subscribes, timed over '
        f'{r["calls"]:,} calls in one interpreter (thread CPU time, `--added-work-only`):\n\n'
        '| quantity | value |\n|---|---|\n'
        f'| rfi_monitor_node: its own time per 1 ms block (38.192 MS/s, chirp, full analysis) | '
        f'{1e6 * r["block_s"]:.0f} us |\n'
        f'| rfi_monitor_node: `_draw` per block (two subscription counts, nothing else) | '
        f'{1e6 * r["draw_s"]:.2f} us |\n'
        f'| rfi_monitor core: the `BlockSpectrum` the estimator keeps per block (a reference, no copy) | '
        f'{1e6 * r["keep_s"]:.2f} us |\n'
        f'| **rfi_monitor_node: added / own time per block** | **{mon_us / (1e6 * r["block_s"]):.2%}** |\n'
        f'| fusion_node: `_draw` per input at the 65 Hz input rate of bags/default (one comparison; three '
        f'subscription counts per 1/view_rate_hz) | {fus_us:.2f} us |\n'
        f'| **fusion_node: added / own time per input** (178 us per input, docs/uwb_gnss_fusion/node_speed.md) | '
        f'**{fus_us / 178.0:.2%}** |\n{ADDED_END}\n')


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--repeats', type=int, default=7)
    ap.add_argument('--baseline-commit', default=BASELINE_COMMIT)
    ap.add_argument('--monitor-single', type=float, default=None, help='internal: one monitor run, print JSON')
    ap.add_argument('--added-work-only', action='store_true',
                    help='only the direct timing of the added work: rewrite that section of the output')
    ap.add_argument('--added-work-json', action='store_true', help='internal: added_work() as JSON')
    add_quiet_argument(ap)
    args = ap.parse_args()
    if args.added_work_json:
        print(json.dumps(added_work()))
        return
    if args.monitor_single is not None:
        print(json.dumps(monitor_single(args.monitor_single)))
        return
    if args.added_work_only:
        section = added_work_section(run(None, [str(Path(__file__).resolve()), '--added-work-json']))
        text = OUT.read_text()
        head, _, rest = text.partition(ADDED_START)
        _, _, tail = rest.partition(ADDED_END)
        OUT.write_text(head + section + tail)
        print(section)
        return
    tmp = Path(tempfile.mkdtemp(prefix='view_topics_cost_'))
    base = export_baseline(args.baseline_commit, tmp)
    me = str(Path(__file__).resolve())
    fusion = [str(ROOT / 'benchmarks' / 'fusion_node_speed.py'), '--single']
    cases = [('monitor', 'current, nobody subscribed', None, [me, '--monitor-single', '0']),
             ('monitor', 'baseline', base, [me, '--monitor-single', '0']),
             ('monitor', 'current, waterfall subscribed, 5 Hz', None, [me, '--monitor-single', '5']),
             ('monitor', 'current, waterfall subscribed, a row per block', None, [me, '--monitor-single', '1000']),
             ('fusion', 'current, nobody subscribed', None, fusion),
             ('fusion', 'baseline', base, fusion)]
    log = case_log(__file__, total=len(cases) * (args.repeats + 1), quiet=args.quiet)
    for _, label, src, cmd in cases:          # warm-up: numba caches of both codes compiled, not timed
        run(src, cmd)
        log.done(f'warm-up {label}')
    times: dict[tuple[str, str], list[float]] = {(n, lb): [] for n, lb, _, _ in cases}
    extra: dict[tuple[str, str], dict] = {}
    for k in range(args.repeats):
        for node, label, src, cmd in cases:
            r = run(src, cmd)
            times[(node, label)].append(r['cpu_s'] if node == 'monitor' else r['wall_s'])
            extra[(node, label)] = r
            log.done(f'repeat {k + 1} {node} {label}: {times[(node, label)][-1]:.3f} s')

    def ratio(node: str, a: str, b: str) -> float:
        return statistics.median(x / y for x, y in zip(times[(node, a)], times[(node, b)], strict=True))

    idle, sub5, sub_all = ('current, nobody subscribed', 'current, waterfall subscribed, 5 Hz',
                           'current, waterfall subscribed, a row per block')
    mon = extra[('monitor', idle)]
    fus = extra[('fusion', idle)]
    rows = ['| node, case | median time | time / reference case, median of per-repeat ratios |', '|---|---|---|']
    rows += [
        f'| rfi_monitor_node, {BLOCKS} blocks (CPU s), baseline code | '
        f'{statistics.median(times[("monitor", "baseline")]):.3f} s | reference |',
        f'| rfi_monitor_node, current code, nobody subscribed | {statistics.median(times[("monitor", idle)]):.3f} s | '
        f'**{ratio("monitor", idle, "baseline"):.3f}** (vs baseline) |',
        f'| rfi_monitor_node, current, waterfall subscribed at 5 Hz ({extra[("monitor", sub5)]["images"]} images) | '
        f'{statistics.median(times[("monitor", sub5)]):.3f} s | {ratio("monitor", sub5, idle):.3f} (vs nobody) |',
        f'| rfi_monitor_node, current, a row per block ({extra[("monitor", sub_all)]["images"]} images) | '
        f'{statistics.median(times[("monitor", sub_all)]):.3f} s | {ratio("monitor", sub_all, idle):.3f} (vs nobody) |',
        f'| fusion_node, bags/default ({fus["inputs"]} inputs, wall s), baseline code | '
        f'{statistics.median(times[("fusion", "baseline")]):.3f} s | reference |',
        f'| fusion_node, current code, nobody subscribed | {statistics.median(times[("fusion", idle)]):.3f} s | '
        f'**{ratio("fusion", idle, "baseline"):.3f}** (vs baseline) |',
    ]
    table = '\n'.join(rows)
    log.say(table)
    cpu = next((ln.split(':', 1)[1].strip() for ln in Path('/proc/cpuinfo').read_text().splitlines()
                if ln.startswith('model name')), 'unknown')
    OUT.write_text(
        '# What the drawn topics cost the nodes (issue 30)\n\n'
        'Produced by `benchmarks/view_topics_cost.py` (do not edit by hand): the current code against the code '
        f'before the drawn topics (commit {args.baseline_commit}), alternated, each run in a fresh interpreter, '
        f'{args.repeats} repeats; a ratio is the median of the per-repeat time ratios (1.00: no cost). '
        f'rfi_monitor_node: `on_block` over {BLOCKS} simulated 1 ms blocks (38.192 MS/s, 2-bit real IF, a chirp '
        f'after {CLEAN} jammer-free blocks; {mon["processed"]} analysed), thread CPU time. fusion_node: '
        '`benchmarks/fusion_node_speed.py --single` (bags/default, in-process direct transport), wall time. '
        f'Machine: {cpu}, shared with other jobs (2 cores; load {os.getloadavg()[0]:.1f} at the end).\n\n'
        + table + '\n\n'
        'Nobody subscribed, the monitor asks its two drawn publishers for their subscription count per block '
        '(about 1.6 us each, measured with rclpy on this machine) and does nothing else; the fusion node compares '
        'one integer per input and asks its three publishers once per 1/view_rate_hz of stamp time.\n\n'
        + added_work_section(run(None, [me, '--added-work-json'])))
    log.finish(f'wrote {OUT.relative_to(ROOT)}')


if __name__ == '__main__':
    main()
