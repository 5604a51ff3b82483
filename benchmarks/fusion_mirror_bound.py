"""Benchmark: how well can GNSS pick the side of three coplanar UWB anchors? (issue 15, item 2)

Three anchors lie in a plane; the tag's mirror image across it fits the ranges exactly as well as
the tag (Cao et al. eq. 7 has two solutions), so only GNSS (or a prior) can tell the two apart.
On the runs of ``fusion_never_worse.py`` (same scenarios, seeds, anchors; 360 s, static receiver)
this script measures how much the GNSS evidence can do: it runs the GNSS-only filter, projects
each epoch's position error onto the unit vector ``u`` from the truth to its mirror (separation
``d``), and scores three side decisions that any GNSS-based test approximates:

* instantaneous: the epoch's error along ``u`` beyond ``d / 2`` (the current GNSS position is
  nearer the mirror);
* running mean: the mean of that error from the start to the epoch beyond ``d / 2`` (all the
  GNSS evidence so far, equally weighted; about what an accumulated likelihood ratio does);
* whole run: the mean over the run beyond ``d / 2`` (a decision taken with hindsight).

"Implied 3D RMS": a fused filter that is perfect except for the side, on the side the running
mean says, scored per seed as ``sqrt(f d^2 + e0^2)`` (``f`` the fraction of epochs on the wrong
side, ``e0`` the median 3D RMS of the UWB-only runs of the J/S whose RMS is below ``d / 2``, i.e.
on the right side, over both layouts) and averaged over the seeds. Next to it, measured on the
same runs: the fused filter with three anchors and UWB alone with three anchors (as in
``fusion_never_worse.md``).

Usage:
    PYTHONPATH=src/gnss_common:src/rfi_sim:src/uwb_gnss_fusion \\
        python benchmarks/fusion_mirror_bound.py [--seeds 8] [--duration-s 360] [--workers 2] [--out FILE]

Writes docs/uwb_gnss_fusion/fusion_mirror_bound.md (both anchor layouts: the paper's and the tag
on the other side of anchors 1-3, ``--flip-anchor-heights`` of ``fusion_never_worse.py``).
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from bench_progress import add_quiet_argument, case_log

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fusion_never_worse as nw  # noqa: E402  (the runs, anchors and scoring of item 2)

from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic  # noqa: E402
from gnss_common.observations import GnssEpoch  # noqa: E402
from rfi_sim.gnss_uwb import JSR_SCENARIOS_DB, BroadcastGeometry, GnssUwbScenario, simulate  # noqa: E402
from uwb_gnss_fusion.fusion_filter import FusionFilter, FusionParams  # noqa: E402
from uwb_gnss_fusion.mirror_test import anchor_plane, reflect  # noqa: E402

OUT = nw.ROOT / "docs" / "uwb_gnss_fusion" / "fusion_mirror_bound.md"


def gnss_only_errors(run, truth: np.ndarray) -> np.ndarray:
    """ECEF position errors (n, 3), m, of the GNSS-only filter at the GNSS epochs after the
    convergence time (set up as ``fusion_never_worse.run_case`` with 0 anchors)."""
    f = FusionFilter(FusionParams(use_uwb=False, accel_psd_m2ps3=nw.STATIC_ACCEL_PSD))
    t_first = run.gnss_epochs[0].stamp_ns
    errs = []
    for m in run.messages(anchor_ids=(), gnss=True):
        out = f.process(m)
        if isinstance(m, GnssEpoch) and (m.stamp_ns - t_first) / 1e9 >= nw.CONVERGENCE_S:
            ok = out.initialized and out.frame_id == "earth" and np.all(np.isfinite(out.position_m))
            errs.append(np.asarray(out.position_m, float) - truth if ok else np.full(3, np.nan))
    e = np.array(errs)
    return e[np.all(np.isfinite(e), axis=1)]


def run_one(task: tuple[int, int, float, bool]) -> tuple[int, int, dict]:
    """One simulated run: the GNSS-only error along the mirror direction, the three decisions, and
    the fused and UWB-only three-anchor 3D RMS."""
    idx, k, duration_s, flip = task
    geo = BroadcastGeometry(nw.NAV)
    sc = GnssUwbScenario(jsr_db=JSR_SCENARIOS_DB[idx], duration_s=duration_s, seed=100 + idx + 10 * k,
                         **nw.anchor_layout(flip))
    run = simulate(sc, geo, geo.iono_alpha, geo.iono_beta)
    truth = np.asarray(run.truth.receiver_ecef_m, dtype=float)
    lat, lon, _ = ecef_to_geodetic(truth)
    rot = ecef_to_enu_rotation(lat, lon)
    plane = anchor_plane(np.asarray(run.truth.anchor_ecef_m, dtype=float)[:3])
    assert plane is not None
    dvec = reflect(truth, *plane) - truth
    d = float(np.linalg.norm(dvec))
    u = dvec / d
    e = gnss_only_errors(run, truth) @ u
    running = np.cumsum(e) / np.arange(1, e.size + 1)
    return idx, k, dict(
        d=d, u_enu=rot @ u, rms_e=float(np.sqrt(np.mean(e**2))), mean_e=float(e.mean()),
        frac_running=float(np.mean(running > d / 2)), frac_instant=float(np.mean(e > d / 2)),
        whole_wrong=bool(e.mean() > d / 2),
        fused3=nw.run_case(run, 3, rot, truth)[0], uwb3=nw.uwb_only(run, 3, rot, truth)[0],
    )


def table(results: dict[int, dict[int, dict]], seeds: int, flip: bool, e0_m: list[float]) -> list[str]:
    up = nw.anchor_layout(flip)["anchor_up_m"][:3]
    lines = [
        f"### Anchors 1-3 at {', '.join(f'{v:+.1f}' for v in up)} m above the tag"
        + (" (flipped: `--flip-anchor-heights`)" if flip else " (the paper's layout)"),
        "",
        "| J/S | d, m | u (E, N, U) | GNSS error along u: RMS / run means ± sd, m | wrong, instantaneous "
        "| wrong, running mean | whole run wrong | implied 3D RMS, m | fused 3 anchors, m | UWB only 3, m |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for i, jsr in enumerate(JSR_SCENARIOS_DB):
        rs = [results[i][k] for k in range(seeds)]
        d = np.array([r["d"] for r in rs])
        u = np.mean([r["u_enu"] for r in rs], axis=0)
        means = np.array([r["mean_e"] for r in rs])
        fr = np.array([r["frac_running"] for r in rs])
        fi = np.array([r["frac_instant"] for r in rs])
        fused = np.array([r["fused3"] for r in rs])
        uwb = np.array([r["uwb3"] for r in rs])
        implied = float(np.mean(np.sqrt(fr * d**2 + e0_m[i] ** 2)))
        sd = means.std(ddof=1) if means.size > 1 else 0.0
        lines.append(
            f"| {nw._label(jsr)} | {d.mean():.2f} | {u[0]:+.2f}, {u[1]:+.2f}, {u[2]:+.2f} "
            f"| {math.sqrt(np.mean([r['rms_e'] ** 2 for r in rs])):.2f} / {means.mean():+.2f} ± {sd:.2f} "
            f"| {fi.mean():.0%} | {fr.mean():.0%} | {sum(r['whole_wrong'] for r in rs)} of {seeds} "
            f"| {implied:.2f} | {fused.mean():.2f} | {uwb.mean():.2f} |"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration-s", type=float, default=360.0)
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--workers", type=int, default=2, help="processes (at most 2 on the shared machine)")
    ap.add_argument("--out", type=Path, default=OUT)
    add_quiet_argument(ap)
    args = ap.parse_args(argv)
    workers = max(1, min(args.workers, 2))
    t0 = time.perf_counter()
    log = case_log(__file__, total=2 * args.seeds, quiet=args.quiet)  # one case: the J/S rows of one seed
    layouts: dict[bool, dict[int, dict[int, dict]]] = {}
    for flip in (False, True):
        tasks = [(i, k, args.duration_s, flip) for k in range(args.seeds) for i in range(len(JSR_SCENARIOS_DB))]
        results: dict[int, dict[int, dict]] = {i: {} for i in range(len(JSR_SCENARIOS_DB))}
        with multiprocessing.get_context("fork").Pool(workers) as pool:
            for n_done, (i, k, row) in enumerate(pool.imap_unordered(run_one, tasks), 1):
                results[i][k] = row
                if n_done % len(JSR_SCENARIOS_DB) == 0:
                    log.done(f"{'flipped' if flip else 'paper'} layout: {n_done}/{len(tasks)} runs")
        layouts[flip] = results
    # e0: the UWB-only 3D RMS of the runs on the right side (error below d / 2), median per J/S over both layouts
    e0_m = []
    for i in range(len(JSR_SCENARIOS_DB)):
        right = [r["uwb3"] for lay in layouts.values() for r in lay[i].values() if r["uwb3"] < r["d"] / 2]
        e0_m.append(float(np.median(right)) if right else math.nan)
    body: list[str] = []
    for flip, results in layouts.items():
        body += table(results, args.seeds, flip, e0_m) + [""]
    wall_s = time.perf_counter() - t0
    lines = [
        "# Three anchors: how well can GNSS pick the side of their plane? (issue 15, item 2)",
        "",
        f"Generated by `benchmarks/fusion_mirror_bound.py` ({args.duration_s:.0f} s per run, {args.seeds} seeds per "
        f"J/S as `fusion_never_worse.py`; {workers} worker processes, {wall_s:.0f} s wall time, "
        f"{os.cpu_count()} cores; Python {platform.python_version()}, numpy {np.__version__}).",
        "d: distance from the tag to its mirror across the plane of anchors 1-3; u: the unit vector from the tag "
        "to the mirror (local east, north, up). \"wrong\": the share of epochs (after 10 s) at which the decision "
        "picks the mirror, mean over the seeds; \"whole run wrong\": seeds whose whole-run mean error along u is "
        "beyond d / 2. Implied 3D RMS: a filter perfect but for the side, on the side of the running mean (see the "
        "script's docstring). The GNSS-only errors are the same in both layouts (same seeds); only u changes sign.",
        "",
        *body,
    ]
    text = "\n".join(lines)
    args.out.write_text(text)
    log.say(text)
    log.finish(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
