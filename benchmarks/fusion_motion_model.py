"""Benchmark: the stationarity detector of the GNSS-only filter on simulated static and moving receivers.

``uwb_gnss_fusion.motion_model`` switches the filter between its moving (constant-velocity,
``accel_psd_m2ps3``) and static models. This compares the shipped defaults (``motion_detection``
true) with the moving model alone (``motion_detection`` false, the filter before issue 27 item 4)
on rfi_sim.gnss_uwb runs (ARL1 broadcast geometry, 5 Hz GNSS with Doppler, no jammer, seeded),
GNSS only: a static receiver, constant velocities of 0.2, 1 and 5 m/s east, a receiver that stands
120 s and then drives at 1 m/s, and one that drives 180 s at 1 m/s and then stops. The two pieces of
the last two are separate simulator runs joined at the same position and time (the receiver clock
of the second run starts afresh: a clock step the filter handles, the same for both rows).

A second table: the static receiver under the 30 dB J/S chirp jamming of Cao et al. (the scenario of
benchmarks/fusion_never_worse.py, its 8 seeds, its accel_psd_m2ps3 = 0.01, GNSS alone): the case
where the measurement errors (outlier bursts, time-correlated tracking errors) make the detector
leave and re-enter the static model often.

Errors in ENU at the true antenna position of each epoch, after 10 s of convergence: horizontal and
3D RMS and maximum; the detector's decisions are the filter's counts.

Writes docs/uwb_gnss_fusion/motion_model.md.
Run: PYTHONPATH=src/gnss_common:src/uwb_gnss_fusion:src/rfi_sim python benchmarks/fusion_motion_model.py
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from bench_progress import case_log

from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic
from rfi_sim.gnss_uwb import (
    JSR_SCENARIOS_DB,
    PAPER_ANCHOR_RANGES_M,
    BroadcastGeometry,
    GnssUwbScenario,
    receiver_velocity_ecef,
    simulate,
)
from uwb_gnss_fusion.fusion_filter import FusionFilter, FusionParams

ROOT = Path(__file__).resolve().parents[1]
NAV = ROOT / "src" / "gnss_common" / "test" / "data" / "arlm2000.15n"
OUT = ROOT / "docs" / "uwb_gnss_fusion" / "motion_model.md"
CONVERGENCE_S = 10.0
NEVER_WORSE_ANCHORS = {"anchor_ranges_m": (*PAPER_ANCHOR_RANGES_M, 12.0),
                       "anchor_azimuths_deg": (20.0, 140.0, 260.0, 80.0), "anchor_up_m": (1.5, -0.5, 0.8, 2.5)}
"""The anchors of benchmarks/fusion_never_worse.py (unused here, GNSS alone, but part of its runs' draws)."""
SEED = 27


def pieces(geo: BroadcastGeometry, parts: list[tuple[float, tuple[float, float, float]]]):
    """Join runs of (duration s, velocity ENU m/s): (epochs, true positions (n, 3))."""
    base = GnssUwbScenario(jsr_db=None, seed=SEED)
    rx = np.asarray(base.receiver_ecef_m, dtype=float)
    tow = base.start_tow_s
    epochs, truth = [], []
    for k, (duration, v) in enumerate(parts):
        sc = dataclasses.replace(base, duration_s=duration, receiver_velocity_enu_mps=v, receiver_ecef_m=tuple(rx),
                                 start_tow_s=tow, seed=SEED + k, anchor_origin_ecef_m=tuple(base.receiver_ecef_m))
        run = simulate(sc, geo, geo.iono_alpha, geo.iono_beta)
        epochs.extend(run.gnss_epochs)
        truth.append(run.truth.receiver_ecef_m_per_epoch)
        rx = rx + receiver_velocity_ecef(rx, v) * duration
        tow += duration
    return epochs, np.vstack(truth)


def run_filter(epochs, truth: np.ndarray, detect: bool, **extra: float) -> dict[str, object]:
    f = FusionFilter(FusionParams(use_uwb=False, motion_detection=detect, **extra))
    lat, lon, _ = ecef_to_geodetic(truth[0])
    rot = ecef_to_enu_rotation(lat, lon)
    t0 = epochs[0].stamp_ns
    err = []
    for e, x in zip(epochs, truth, strict=True):
        out = f.process_gnss(e)
        if out.initialized and (e.stamp_ns - t0) / 1e9 >= CONVERGENCE_S:
            err.append(rot @ (out.position_m - x))
    enu = np.array(err)
    h = np.hypot(enu[:, 0], enu[:, 1])
    d = np.linalg.norm(enu, axis=1)
    counts = {k: v for k, v in f.rejection_counts.items() if k.startswith("motion_")}
    return {"h_rms": float(np.sqrt(np.mean(h**2))), "h_max": float(h.max()), "d_rms": float(np.sqrt(np.mean(d**2))),
            "d_max": float(d.max()), "n": len(enu), "counts": counts}


CASES = (
    ("static, 300 s", [(300.0, (0.0, 0.0, 0.0))]),
    ("0.2 m/s east, 300 s", [(300.0, (0.2, 0.0, 0.0))]),
    ("1 m/s east, 300 s", [(300.0, (1.0, 0.0, 0.0))]),
    ("5 m/s east, 300 s", [(300.0, (5.0, 0.0, 0.0))]),
    ("static 120 s, then 1 m/s east 180 s", [(120.0, (0.0, 0.0, 0.0)), (180.0, (1.0, 0.0, 0.0))]),
    ("1 m/s east 180 s, then static 120 s", [(180.0, (1.0, 0.0, 0.0)), (120.0, (0.0, 0.0, 0.0))]),
)


def main() -> None:
    log = case_log(__file__, total=2 * len(CASES) + 8)  # -q/--quiet: nothing on stdout or stderr but errors
    geo = BroadcastGeometry(NAV)
    lines = ["| scenario | motion model | horiz. RMS m | horiz. max m | 3D RMS m | 3D max m | detector decisions |",
             "|---|---|---|---|---|---|---|"]
    for name, parts in CASES:
        epochs, truth = pieces(geo, parts)
        for detect in (False, True):
            r = run_filter(epochs, truth, detect)
            label = "detector (default)" if detect else "moving only (before)"
            counts = ", ".join(f"{k} {v}" for k, v in sorted(r["counts"].items())) or "-"
            lines.append(f"| {name} | {label} | {r['h_rms']:.3f} | {r['h_max']:.3f} | {r['d_rms']:.3f} "
                         f"| {r['d_max']:.3f} | {counts} |")
            log.done(f"{name}, {label}")
    table = "\n".join(lines)
    log.say(table)
    jam = ["| seed | moving only (before) 3D RMS m | detector (default) 3D RMS m | static model entered / left |",
           "|---|---|---|---|"]
    means = [[], []]
    for k in range(8):
        sc = GnssUwbScenario(jsr_db=30.0, duration_s=360.0, seed=100 + JSR_SCENARIOS_DB.index(30.0) + 10 * k,
                             **NEVER_WORSE_ANCHORS)
        run = simulate(sc, geo, geo.iono_alpha, geo.iono_beta)
        truth = np.tile(np.asarray(run.truth.receiver_ecef_m, dtype=float), (len(run.gnss_epochs), 1))
        r = [run_filter(list(run.gnss_epochs), truth, d, accel_psd_m2ps3=0.01) for d in (False, True)]
        means[0].append(r[0]["d_rms"])
        means[1].append(r[1]["d_rms"])
        c = r[1]["counts"]
        jam.append(f"| {sc.seed} | {r[0]['d_rms']:.2f} | {r[1]['d_rms']:.2f} "
                   f"| {c.get('motion_static_entered', 0)} / {c.get('motion_static_left', 0)} |")
        log.done(f"30 dB J/S, seed {sc.seed}")
    jam.append(f"| mean | {np.mean(means[0]):.2f} | {np.mean(means[1]):.2f} | |")
    jam_table = "\n".join(jam)
    log.say(jam_table)
    OUT.write_text(
        "# The motion model's stationarity detector on simulated receivers\n\n"
        "Generated by `benchmarks/fusion_motion_model.py` (method in its docstring). GNSS-only filter,\n"
        "5 Hz GNSS with Doppler, no jammer; `moving only` is `motion_detection: false` (the filter before\n"
        "issue 27 item 4), `detector` the shipped defaults (`uwb_gnss_fusion/motion_model.py`).\n\n"
        + table + "\n\n## Static receiver, 30 dB J/S, GNSS alone (accel_psd_m2ps3 0.01, 360 s, after 10 s)\n\n"
        + jam_table + "\n")
    log.finish(f"wrote {OUT}")


if __name__ == "__main__":
    main()
