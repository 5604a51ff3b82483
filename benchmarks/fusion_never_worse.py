"""Benchmark: does adding UWB ever make the fusion worse? (issue 15, item 2)

For every J/S scenario of Cao et al. (no jamming, -10 ... 30 dB; 6 minutes each, seeded, the same
simulator as ``fusion_jamming.py``) and every number of UWB anchors from 0 to 4, the fusion filter's
3D and horizontal RMS error after a 10 s convergence, next to GNSS alone (0 anchors) and UWB alone
(the filter without GNSS, with 3 or 4 anchors; fewer anchors cannot fix a 3D position). The "never
worse" column checks, for each anchor count, ``fused <= min(GNSS only, UWB only)`` with an
allowance of 2 % or 2 cm (the larger) for the run's own noise. The first three anchors are the
paper's (Sec. IV-1: 11.71, 13.00, 11.26 m); the fourth is ours (12.0 m at azimuth 80 deg, 2.5 m
above the tag).

A second table gives the filter's consistency: the RMS over the run of error / reported 1-sigma,
per axis (east, north, up), for each anchor count (1 for a consistent filter).

Usage:
    PYTHONPATH=src/gnss_common:src/rfi_sim:src/uwb_gnss_fusion \\
        python benchmarks/fusion_never_worse.py [--duration-s 360] [--correlated-std-m S] [--correlated-tau-s T]
        [--out FILE]

(``--correlated-std-m`` / ``--correlated-tau-s``: the filter's Gauss-Markov pseudorange-error
model, ``FusionParams.pseudorange_correlated_std_m`` / ``_tau_s``; default: the filter's defaults.)

Writes docs/uwb_gnss_fusion/fusion_never_worse.md and prints it.
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np

from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic
from gnss_common.observations import GnssEpoch
from rfi_sim.gnss_uwb import JSR_SCENARIOS_DB, PAPER_ANCHOR_RANGES_M, BroadcastGeometry, GnssUwbScenario, simulate
from uwb_gnss_fusion.fusion_filter import FusionFilter, FusionParams

ROOT = Path(__file__).resolve().parents[1]
NAV = ROOT / "src" / "gnss_common" / "test" / "data" / "arlm2000.15n"
OUT = ROOT / "docs" / "uwb_gnss_fusion" / "fusion_never_worse.md"
CONVERGENCE_S = 10.0
STATIC_ACCEL_PSD = 0.01  # m^2/s^3, as fusion_jamming.py (static receiver)
ANCHORS = dict(
    anchor_ranges_m=(*PAPER_ANCHOR_RANGES_M, 12.0),
    anchor_azimuths_deg=(20.0, 140.0, 260.0, 80.0),
    anchor_up_m=(1.5, -0.5, 0.8, 2.5),
)
ALLOWANCE = 1.02
ALLOWANCE_M = 0.02


def _label(jsr):
    return "no jamming" if jsr is None else f"{jsr:+.0f} dB"


FILTER_EXTRA: dict = {}  # FusionParams overrides from the command line


def run_case(run, n_anchors: int, rot: np.ndarray, truth: np.ndarray) -> tuple[float, float, float, np.ndarray]:
    """GNSS + n anchors: 3D RMS, horizontal RMS (m) after convergence, availability, at the GNSS epochs,
    and the RMS of error / reported 1-sigma per ENU axis."""
    ids = tuple(f"A{i + 1}" for i in range(n_anchors))
    f = FusionFilter(FusionParams(use_uwb=n_anchors > 0, accel_psd_m2ps3=STATIC_ACCEL_PSD, **FILTER_EXTRA))
    errs = []
    sds = []
    t_first = run.gnss_epochs[0].stamp_ns
    for m in run.messages(anchor_ids=ids, gnss=True):
        out = f.process(m)
        if isinstance(m, GnssEpoch) and (m.stamp_ns - t_first) / 1e9 >= CONVERGENCE_S:
            ok = out.initialized and out.frame_id == "earth"
            errs.append(rot @ (out.position_m - truth) if ok else np.full(3, np.nan))
            sds.append(np.sqrt(np.diag(rot @ out.covariance_pv[0:3, 0:3] @ rot.T)) if ok else np.full(3, np.nan))
    e = np.array(errs)
    good = np.all(np.isfinite(e), axis=1)
    if not good.any():
        return math.nan, math.nan, 0.0, np.full(3, np.nan)
    ratio = np.sqrt(np.mean((e[good] / np.array(sds)[good]) ** 2, axis=0))
    e = e[good]
    return (float(np.sqrt(np.mean(np.sum(e**2, axis=1)))), float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1)))),
            float(good.mean()), ratio)


def uwb_only(run, n_anchors: int, rot: np.ndarray, truth: np.ndarray) -> tuple[float, float, float]:
    """The filter on the ranges alone (ECEF anchors), scored at the UWB output stamps."""
    ids = tuple(f"A{i + 1}" for i in range(n_anchors))
    f = FusionFilter(FusionParams(use_gnss=False, accel_psd_m2ps3=STATIC_ACCEL_PSD))
    t_first = run.gnss_epochs[0].stamp_ns
    errs = []
    for m in run.messages(anchor_ids=ids, gnss=False):
        out = f.process(m)
        if (m.stamp_ns - t_first) / 1e9 >= CONVERGENCE_S:
            ok = out.initialized and np.all(np.isfinite(out.position_m))
            errs.append(rot @ (out.position_m - truth) if ok else np.full(3, np.nan))
    e = np.array(errs)
    good = np.all(np.isfinite(e), axis=1)
    if not good.any():
        return math.nan, math.nan, 0.0
    e = e[good]
    return (float(np.sqrt(np.mean(np.sum(e**2, axis=1)))), float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1)))),
            float(good.mean()))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration-s", type=float, default=360.0)
    ap.add_argument("--correlated-std-m", type=float, default=None)
    ap.add_argument("--correlated-tau-s", type=float, default=None)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    if args.correlated_std_m is not None:
        FILTER_EXTRA["pseudorange_correlated_std_m"] = args.correlated_std_m
    if args.correlated_tau_s is not None:
        FILTER_EXTRA["pseudorange_correlated_tau_s"] = args.correlated_tau_s
    fp = FusionParams(**FILTER_EXTRA)
    geo = BroadcastGeometry(NAV)
    rows = []
    t0 = time.perf_counter()
    for idx, jsr in enumerate(JSR_SCENARIOS_DB):
        sc = GnssUwbScenario(jsr_db=jsr, duration_s=args.duration_s, seed=100 + idx, **ANCHORS)
        run = simulate(sc, geo, geo.iono_alpha, geo.iono_beta)
        truth = np.asarray(run.truth.receiver_ecef_m, dtype=float)
        lat, lon, _ = ecef_to_geodetic(truth)
        rot = ecef_to_enu_rotation(lat, lon)
        row = {"jsr": jsr, "fused": {}, "uwb": {}}
        for n in range(5):
            row["fused"][n] = run_case(run, n, rot, truth)
        for n in (3, 4):
            row["uwb"][n] = uwb_only(run, n, rot, truth)
        rows.append(row)
        print(f"{_label(jsr)} done ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
    lines = [
        "# Adding UWB never makes it worse? (issue 15, item 2)",
        "",
        f"Generated by `benchmarks/fusion_never_worse.py` ({args.duration_s:.0f} s per scenario, seeds 100-106;",
        f"Python {platform.python_version()}, numpy {np.__version__}). 3D / horizontal RMS error, m, after",
        f"{CONVERGENCE_S:.0f} s; GNSS only = 0 anchors; UWB only = the filter without GNSS (3 or 4 anchors).",
        "\"never worse\": fused <= the better of GNSS only and UWB only (3D), per anchor count, with an allowance",
        f"of {ALLOWANCE - 1:.0%} or {ALLOWANCE_M * 100:.0f} cm, whichever is larger, for the run's own noise.",
        "Filter: defaults except accel_psd_m2ps3 = 0.01 (static receiver); correlated pseudorange errors "
        f"modelled with std {fp.pseudorange_correlated_std_m:g} m, tau {fp.pseudorange_correlated_tau_s:g} s "
        "(std 0: white pseudorange errors).",
        "",
        "| J/S | GNSS only | 1 anchor | 2 anchors | 3 anchors | 4 anchors | UWB only 3 | UWB only 4 "
        "| never worse (3D), anchors 1/2/3/4 |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    misses = []
    for row in rows:
        f, u = row["fused"], row["uwb"]
        cells = [f"{f[n][0]:.2f} / {f[n][1]:.2f}" for n in range(5)]
        cells += [f"{u[n][0]:.2f} / {u[n][1]:.2f}" for n in (3, 4)]
        verdict = []
        for n in range(1, 5):
            best = f[0][0]
            if n in u and math.isfinite(u[n][0]):
                best = min(best, u[n][0])
            ok = math.isfinite(f[n][0]) and f[n][0] <= max(ALLOWANCE * best, best + ALLOWANCE_M)
            verdict.append("yes" if ok else f"NO ({f[n][0]:.2f} > {best:.2f})")
            if not ok:
                misses.append((row["jsr"], n, f[n][0], best))
        lines.append(f"| {_label(row['jsr'])} | " + " | ".join(cells) + " | " + " / ".join(verdict) + " |")
    lines += ["", f"Cells where UWB made the 3D error worse: {len(misses)} of {4 * len(rows)}."]
    lines += [
        "",
        "Consistency: RMS of error / reported 1-sigma, east / north / up (1: consistent; > 1: overconfident).",
        "",
        "| J/S | GNSS only | 1 anchor | 2 anchors | 3 anchors | 4 anchors |",
        "|---|---|---|---|---|---|",
    ]
    for row in rows:
        cells = [" / ".join(f"{v:.1f}" for v in row["fused"][n][3]) for n in range(5)]
        lines.append(f"| {_label(row['jsr'])} | " + " | ".join(cells) + " |")
    args.out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
