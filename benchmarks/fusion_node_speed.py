"""Speed of the GNSS/UWB fusion NODE replaying bags/default in-process (direct transport).

Replays /gnss/measurements + /uwb/ranges of ``bags/default`` through
:class:`uwb_gnss_fusion.fusion_node.FusionNode` with
``ReplayHarness(transport='direct')`` several times and reports the median speed (bag seconds per
wall second). The machine is shared, so each repeat also times a fixed reference workload (20,000
single-point calls of the vectorised :func:`gnss_common.coordinates.ecef_to_geodetic`, the old
per-output cost) right before the replay; the ratio replay time / reference time is much less
sensitive to the load of the moment than the raw time.

One extra instrumented replay splits the time into the core (``FusionFilter.process_*``), the SPP
(``SinglePointPositioner.process``) and the rest (message conversion, ordering, output messages,
harness), and checks the published messages against the core's :class:`FusionOutput` converted
with the validated vectorised functions (the pre-optimisation output path): odometry must be
bit-identical, the fix equal to within 1e-9 m-ish rounding (reported).

With ``--baseline-src DIR`` (a directory holding an older copy of the ``gnss_common`` and
``uwb_gnss_fusion`` package folders, e.g. exported from an earlier commit), every repeat also
replays with that code, in alternation with the current code, each in its own subprocess; the
median of the per-repeat time ratios is the speed-up, robust to the machine's load.

Run (workspace environment, see docs/uwb_gnss_fusion/node_speed.md)::

    python benchmarks/fusion_node_speed.py [--repeats 5] [--baseline-src DIR]

Writes docs/uwb_gnss_fusion/node_speed.md and prints the Markdown table.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import rclpy
from rclpy.context import Context

from gnss_common.coordinates import ecef_to_geodetic, rotate_covariance_ecef_to_enu
from rfi_experiments.replay import ReplayHarness
from uwb_gnss_fusion.fusion_filter import FRAME_EARTH
from uwb_gnss_fusion.fusion_node import FusionNode

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / 'bags' / 'default'
TOPICS = ['/gnss/measurements', '/uwb/ranges']
OUT_MD = ROOT / 'docs' / 'uwb_gnss_fusion' / 'node_speed.md'
M_PER_DEG = 111_320.0
"""Metres per degree of latitude (equatorial longitude), only to express angle differences in m."""


def reference_workload_s(n: int = 20000) -> float:
    """Seconds for ``n`` single-point vectorised geodetic conversions (machine-speed reference)."""
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(64, 3)) * 1.0e3 + np.array([-740289.9, -5457071.7, 3207245.5])
    t0 = time.perf_counter()
    for i in range(n):
        ecef_to_geodetic(pts[i % 64])
    return time.perf_counter() - t0


def replay(instrument: bool = False) -> dict:
    """One replay; with ``instrument`` the core/SPP times and the output check are gathered too."""
    ctx = Context()
    rclpy.init(context=ctx)
    node = FusionNode(context=ctx)
    info: dict = {'core_s': 0.0, 'spp_s': 0.0, 'outs': []}
    if instrument:
        def timed(fn, key):
            def wrapper(*args, **kwargs):
                t0 = time.perf_counter()
                try:
                    return fn(*args, **kwargs)
                finally:
                    info[key] += time.perf_counter() - t0
            return wrapper
        node.filter.process_gnss = timed(node.filter.process_gnss, 'core_s')  # type: ignore[method-assign]
        node.filter.process_uwb = timed(node.filter.process_uwb, 'core_s')  # type: ignore[method-assign]
        node.spp.process = timed(node.spp.process, 'spp_s')  # type: ignore[method-assign]
        publish = node._publish

        def capture(out, stamp_ns):
            info['outs'].append(out)
            publish(out, stamp_ns)
        node._publish = capture  # type: ignore[method-assign]
    try:
        harness = ReplayHarness([node], context=ctx, transport='direct')
        t0 = time.perf_counter()
        result = harness.run(str(BAG), topics=TOPICS)
        info['wall_s'] = time.perf_counter() - t0
        info['bag_s'] = result.bag_duration_s
        info['inputs'] = sum(result.inputs.values())
        if instrument:
            info['odometry'] = result.messages('/fusion/odometry')
            info['fix'] = result.messages('/fusion/fix')
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    return info


def check_outputs(info: dict) -> dict[str, float]:
    """Largest differences between the published messages and the core outputs converted with the
    vectorised reference functions (m; angles converted to m)."""
    outs = [o for o in info['outs'] if o.initialized and o.frame_id == FRAME_EARTH
            and np.isfinite(o.position_m).all()]
    odo, fix = info['odometry'], info['fix']
    if len(outs) != len(odo) or len(outs) != len(fix):
        raise RuntimeError(f'{len(outs)} outputs but {len(odo)} odometry / {len(fix)} fix messages')
    worst = {'odometry_position_m': 0.0, 'odometry_covariance': 0.0, 'fix_horizontal_m': 0.0,
             'fix_altitude_m': 0.0, 'fix_covariance_m2': 0.0}
    for o, m, f in zip(outs, odo, fix, strict=True):
        p = m.pose.pose.position
        worst['odometry_position_m'] = max(worst['odometry_position_m'],
                                           float(np.max(np.abs(np.array([p.x, p.y, p.z]) - o.position_m))))
        worst['odometry_covariance'] = max(worst['odometry_covariance'], float(np.max(np.abs(
            np.asarray(m.pose.covariance).reshape(6, 6)[:3, :3] - o.covariance_pv[:3, :3]))))
        lat, lon, h = ecef_to_geodetic(o.position_m)
        d_lat = abs(f.latitude - math.degrees(lat)) * M_PER_DEG
        d_lon = abs(f.longitude - math.degrees(lon)) * M_PER_DEG * math.cos(lat)
        worst['fix_horizontal_m'] = max(worst['fix_horizontal_m'], math.hypot(d_lat, d_lon))
        worst['fix_altitude_m'] = max(worst['fix_altitude_m'], abs(f.altitude - float(h)))
        ref_cov = rotate_covariance_ecef_to_enu(o.covariance_pv[:3, :3], lat, lon).ravel()
        worst['fix_covariance_m2'] = max(worst['fix_covariance_m2'],
                                         float(np.max(np.abs(np.asarray(f.position_covariance) - ref_cov))))
    worst['outputs_checked'] = float(len(outs))
    return worst


def replay_subprocess(baseline_src: str | None) -> dict:
    """One plain replay in a fresh interpreter; ``baseline_src`` packages shadow the current ones."""
    env = dict(os.environ)
    if baseline_src:
        extra = [str(Path(baseline_src) / pkg) for pkg in ('gnss_common', 'uwb_gnss_fusion')]
        env['PYTHONPATH'] = os.pathsep.join(extra + [env.get('PYTHONPATH', '')])
    done = subprocess.run([sys.executable, __file__, '--single'], env=env, check=True,
                          capture_output=True, text=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--repeats', type=int, default=5)
    ap.add_argument('--baseline-src', default=None, help='folder with older gnss_common/ and uwb_gnss_fusion/')
    ap.add_argument('--single', action='store_true', help='internal: one replay, print JSON')
    args = ap.parse_args()
    if args.single:
        r = replay()
        print(json.dumps({'wall_s': r['wall_s'], 'bag_s': r['bag_s']}))
        return
    rows = []
    base_rows = []
    for k in range(args.repeats):
        ref_s = reference_workload_s()
        r = replay_subprocess(None)
        rows.append((r['wall_s'], ref_s, r['bag_s'] / r['wall_s']))
        line = (f'repeat {k + 1}: {r["wall_s"]:.3f} s, {r["bag_s"] / r["wall_s"]:.1f}x real time, '
                f'reference {ref_s:.3f} s')
        if args.baseline_src:
            b = replay_subprocess(args.baseline_src)
            base_rows.append((b['wall_s'], b['wall_s'] / r['wall_s']))
            line += f'; baseline {b["wall_s"]:.3f} s'
        print(line, flush=True)
    inst = replay(instrument=True)
    check = check_outputs(inst)
    wall = statistics.median(r[0] for r in rows)
    ref = statistics.median(r[1] for r in rows)
    speed = statistics.median(r[2] for r in rows)
    ratio = statistics.median(r[0] / r[1] for r in rows)
    rest = inst['wall_s'] - inst['core_s'] - inst['spp_s']
    table = [
        '| quantity | value |',
        '|---|---|',
        f'| bag | bags/default, {inst["bag_s"]:.1f} s, {inst["inputs"]} inputs ({", ".join(TOPICS)}) |',
        f'| repeats | {args.repeats} |',
        f'| replay wall time, median | {wall:.3f} s |',
        f'| speed, median | **{speed:.1f}x real time** |',
        f'| reference workload (20k vectorised ecef_to_geodetic), median | {ref:.3f} s |',
        f'| replay / reference, median | {ratio:.2f} |',
        f'| instrumented run: core FusionFilter.process_* | {inst["core_s"]:.3f} s |',
        f'| instrumented run: SPP | {inst["spp_s"]:.3f} s |',
        f'| instrumented run: everything else (conversion, ordering, messages, harness) | {rest:.3f} s |',
        f'| instrumented run: wall | {inst["wall_s"]:.3f} s |',
        f'| outputs checked against the vectorised reference path | {int(check["outputs_checked"])} |',
        f'| max odometry position difference | {check["odometry_position_m"]:.3g} m |',
        f'| max odometry covariance difference | {check["odometry_covariance"]:.3g} m^2 |',
        f'| max fix horizontal difference | {check["fix_horizontal_m"]:.3g} m |',
        f'| max fix altitude difference | {check["fix_altitude_m"]:.3g} m |',
        f'| max fix ENU covariance difference | {check["fix_covariance_m2"]:.3g} m^2 |',
    ]
    if base_rows:
        base_wall = statistics.median(b[0] for b in base_rows)
        speedup = statistics.median(b[1] for b in base_rows)
        table += [
            f'| baseline code (interleaved), replay wall time, median | {base_wall:.3f} s |',
            f'| baseline speed, median | {inst["bag_s"] / base_wall:.1f}x real time |',
            f'| speed-up baseline / current, median of per-repeat ratios | **{speedup:.2f}x** |',
        ]
    text = '\n'.join(table)
    print(text)
    OUT_MD.parent.mkdir(parents=True, exist_ok=True)
    OUT_MD.write_text(
        '# Fusion node speed (in-process replay)\n\n'
        'Produced by `benchmarks/fusion_node_speed.py`: bags/default replayed through FusionNode with\n'
        "`ReplayHarness(transport='direct')`, median of the repeats. The machine (2 cores) is shared, so\n"
        'the ratio to a fixed reference workload timed before each repeat is given too.\n\n'
        'Reproduce (workspace environment: venv, install/setup.bash, PYTHONPATH with the src packages):\n'
        f'`python benchmarks/fusion_node_speed.py --repeats {args.repeats}'
        + (' --baseline-src <older gnss_common/ + uwb_gnss_fusion/>' if args.baseline_src else '') + '`\n\n'
        + text + '\n\n'
        'Baseline: the code before the output-path work (vectorised `ecef_to_geodetic` twice per output,\n'
        '`np.all` reductions, per-element message lists), run interleaved with the current code when\n'
        '`--baseline-src` is given. Goal (issue): 100x real time. The remaining time is mostly the core\n'
        '(CKF update), the SPP, rclpy message construction and the harness (deserialisation), see the\n'
        'instrumented split above.\n')


if __name__ == '__main__':
    main()
