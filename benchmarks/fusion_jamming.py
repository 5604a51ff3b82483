"""Benchmark: GNSS/UWB tightly-coupled CKF under simulated chirp jamming (Cao et al., Fig. 5 and 8).

Per J/S scenario (no jamming, -10, -2, 6, 14, 22, 30 dB; 6 minutes each; seeded) it runs
SPP (uwb_gnss_fusion.spp), the GNSS-only filter, and GNSS+UWB with 1, 2 and 3 anchors, and reports
horizontal / 3D error statistics, recovery after outlier bursts and the replay speed. It also runs
the UWB-only mode on the real Hanyang outdoor dataset and compares with the dataset authors' LS
and ESKF results.

Usage:
    PYTHONPATH=src/gnss_common:src/uwb_gnss_fusion:src/rfi_experiments \\
        python benchmarks/fusion_jamming.py [--duration-s 360] [--hanyang /path/to/uwb_outdoor_hanyang]

Writes docs/uwb_gnss_fusion/fusion_jamming.md and the figures next to it; prints the tables.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic  # noqa: E402
from gnss_common.observations import GnssEpoch, UwbRangeMeasurement  # noqa: E402
from rfi_experiments.sim.gnss_uwb import (  # noqa: E402
    JSR_SCENARIOS_DB,
    BroadcastGeometry,
    GnssUwbScenario,
    simulate,
)
from uwb_gnss_fusion.fusion_filter import FusionFilter, FusionParams  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
NAV = ROOT / "src" / "gnss_common" / "test" / "data" / "arlm2000.15n"
OUT = ROOT / "docs" / "uwb_gnss_fusion"
CONVERGENCE_S = 10.0
METHODS = ("SPP", "GNSS filter", "GNSS+UWB 1 anchor", "GNSS+UWB 2 anchors", "GNSS+UWB 3 anchors")
ANCHOR_SETS = {
    "GNSS+UWB 1 anchor": ("A1",),
    "GNSS+UWB 2 anchors": ("A1", "A2"),
    "GNSS+UWB 3 anchors": ("A1", "A2", "A3"),
}
STATIC_ACCEL_PSD = 0.01  # m^2/s^3: the paper's static receiver (constant-velocity model, low q)


def _label(jsr):
    return "no jamming" if jsr is None else f"{jsr:+.0f} dB"


def run_filter(run, anchors):
    """Replay one run through a FusionFilter; returns (stamps_ns, positions (n,3), valid mask, stats)."""
    params = FusionParams(use_uwb=anchors is not None, accel_psd_m2ps3=STATIC_ACCEL_PSD)
    f = FusionFilter(params)
    msgs = run.messages(anchor_ids=anchors if anchors is not None else (), gnss=True)
    pos = np.full((len(run.gnss_epochs), 3), np.nan)
    k = 0
    t0 = time.perf_counter()
    out = None
    for m in msgs:
        out = f.process(m)
        if isinstance(m, GnssEpoch):
            if out.initialized and out.frame_id == "earth":
                pos[k] = out.position_m
            k += 1
    wall = time.perf_counter() - t0
    return pos, {
        "wall_s": wall,
        "messages": len(msgs),
        "reinit": out.reinitializations,
        "counts": dict(out.rejection_counts),
    }


def run_spp(run):
    from uwb_gnss_fusion.spp import SinglePointPositioner

    spp = SinglePointPositioner()
    pos = np.full((len(run.gnss_epochs), 3), np.nan)
    for k, ep in enumerate(run.gnss_epochs):
        res = spp.process(ep)
        if res.valid:
            pos[k] = res.position_ecef_m
    return pos


def error_stats(err_h, err_3d):
    ok = np.isfinite(err_3d)
    if not ok.any():
        return dict(
            avail=0.0,
            h_rms=math.nan,
            h_p95=math.nan,
            h_max=math.nan,
            d3_rms=math.nan,
            d3_p95=math.nan,
            d3_max=math.nan,
        )
    h, d = err_h[ok], err_3d[ok]
    return dict(
        avail=float(ok.mean()),
        h_rms=float(np.sqrt(np.mean(h**2))),
        h_p95=float(np.percentile(h, 95)),
        h_max=float(h.max()),
        d3_rms=float(np.sqrt(np.mean(d**2))),
        d3_p95=float(np.percentile(d, 95)),
        d3_max=float(d.max()),
    )


def burst_recovery(err_3d, outlier_mask, rate_hz):
    """For each outlier episode: error 5 s after its end <= 2 x RMS of the 5 s before its start.

    ``err_3d`` may be any error series (3D or horizontal); episodes too close to the start
    (convergence) or the end of the run are skipped.
    """
    n5 = int(5 * rate_hz)
    bad = outlier_mask > 0
    starts = np.flatnonzero(bad & ~np.r_[False, bad[:-1]])
    ends = np.flatnonzero(bad & ~np.r_[bad[1:], False])
    ok = total = 0
    worst = 0.0
    for s, e in zip(starts, ends, strict=True):
        if s < n5 + int(CONVERGENCE_S * rate_hz) or e + n5 >= err_3d.size:
            continue
        pre = err_3d[s - n5 : s]
        if not np.all(np.isfinite(pre)):
            continue
        pre_rms = float(np.sqrt(np.mean(pre**2)))
        post = float(err_3d[e + n5])
        total += 1
        if math.isfinite(post) and post <= 2.0 * pre_rms:
            ok += 1
        worst = max(worst, post / pre_rms if math.isfinite(post) else math.inf)
    return ok, total, worst


def simulate_all(duration_s):
    geo = BroadcastGeometry(NAV)
    results = {}
    speed = []
    for idx, jsr in enumerate(JSR_SCENARIOS_DB):
        sc = GnssUwbScenario(jsr_db=jsr, duration_s=duration_s, seed=100 + idx)
        run = simulate(sc, geo, geo.iono_alpha, geo.iono_beta)
        truth = run.truth.receiver_ecef_m
        lat, lon, _ = ecef_to_geodetic(truth)
        rot = ecef_to_enu_rotation(lat, lon)
        per = {}
        positions = {"SPP": run_spp(run)}
        extra = {}
        pos, info = run_filter(run, None)
        positions["GNSS filter"] = pos
        extra["GNSS filter"] = info
        for name, anchors in ANCHOR_SETS.items():
            pos, info = run_filter(run, anchors)
            positions[name] = pos
            extra[name] = info
            if name == "GNSS+UWB 3 anchors":
                speed.append((info["messages"] / info["wall_s"], duration_s / info["wall_s"]))
        t_s = (run.truth.gnss_stamps_ns - run.truth.gnss_stamps_ns[0]) / 1e9
        keep = t_s >= CONVERGENCE_S
        for name in METHODS:
            enu = (positions[name] - truth) @ rot.T
            err_h = np.hypot(enu[:, 0], enu[:, 1])
            err_3d = np.linalg.norm(enu, axis=1)
            st = error_stats(err_h[keep], err_3d[keep])
            rec = burst_recovery(err_3d, run.truth.outlier_mask, sc.gnss_rate_hz)
            rec_h = burst_recovery(err_h, run.truth.outlier_mask, sc.gnss_rate_hz)
            st.update(rec_ok=rec[0], rec_total=rec[1], rec_worst=rec[2], rec_h_ok=rec_h[0], enu=enu[keep])
            if name in extra:
                st.update(reinit=extra[name]["reinit"])
            per[name] = st
        per["_sats"] = float(np.mean(run.truth.satellites_tracked))
        per["_outlier_epochs"] = int((run.truth.outlier_mask > 0).sum())
        results[jsr] = per
        print(f"simulated and solved {_label(jsr)}", flush=True)
    return results, speed


def hanyang(root: Path):
    """UWB-only filter on the real dataset vs the authors' LS and ESKF (same metric for all)."""
    cases = ["LOS/Trajectory_A/Case_1", "LOS/Trajectory_B/Case_3", "NLOS/Trajectory_A/Case_1"]
    rows = []
    for case in cases:
        base = root / "Dynamic_measurements" / case
        if not base.exists():
            continue
        msgs = []
        for f in sorted(base.glob("A*.csv")):
            d = np.genfromtxt(f, delimiter=",", skip_header=1)
            for r in d:
                msgs.append(
                    UwbRangeMeasurement(
                        stamp_ns=int(r[1]),
                        anchor_id=str(int(r[2])),
                        anchor_position_m=r[3:6].copy(),
                        frame_id="map",
                        range_m=float(r[6]),
                    )
                )
        msgs.sort(key=lambda m: m.stamp_ns)
        truth = np.genfromtxt(base / "trajectory.csv", delimiter=",", skip_header=1)

        def metric(ts, xyz, truth=truth):
            m = (ts >= truth[0, 0]) & (ts <= truth[-1, 0]) & np.all(np.isfinite(xyz), axis=1)
            t = np.stack([np.interp(ts[m], truth[:, 0], truth[:, i]) for i in (1, 2, 3)], axis=1)
            e = xyz[m] - t
            return float(np.sqrt(np.mean((e**2).sum(1)))), float(np.sqrt(np.mean((e[:, :2] ** 2).sum(1))))

        f = FusionFilter(FusionParams(use_gnss=False, accel_psd_m2ps3=1.0, uwb_range_std_m=0.1))
        ts, xs = [], []
        t0 = time.perf_counter()
        for m in msgs:
            out = f.process_uwb(m)
            if out.initialized:
                ts.append(out.stamp_ns)
                xs.append(out.position_m)
        wall = time.perf_counter() - t0
        row = {
            "case": case,
            "ckf": metric(np.array(ts, float), np.array(xs)),
            "updates_per_s": len(msgs) / wall,
            "reinit": out.reinitializations,
        }
        for name in ("LS", "ESKF"):
            d = np.genfromtxt(base / f"{name}.csv", delimiter=",", skip_header=1)
            row[name] = metric(d[:, 0], d[:, 1:4])
        rep = (base / "RMSD_results.txt").read_text().split()
        nums = [float(x) for x in rep if x.replace(".", "").isdigit()]
        row["reported"] = nums  # LS 3D, LS 2D, ESKF 3D, ESKF 2D
        rows.append(row)
    return rows


def figures(results):
    OUT.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(2, 4, figsize=(18, 9))
    for ax, jsr in zip(axes.flat, JSR_SCENARIOS_DB, strict=False):
        for name in ("SPP", "GNSS filter", "GNSS+UWB 3 anchors"):
            enu = results[jsr][name]["enu"]
            ax.plot(enu[:, 0], enu[:, 1], ".", ms=2, label=name)
        ax.set_title(_label(jsr))
        ax.set_xlim(-6, 6)
        ax.set_ylim(-6, 6)
        ax.set_aspect("equal")
        ax.set_xlabel("east error, m")
        ax.set_ylabel("north error, m")
        ax.grid(True)
    axes.flat[0].legend(markerscale=5)
    axes.flat[-1].axis("off")
    fig.suptitle("Horizontal error after 10 s convergence (cf. Cao et al., Fig. 5)")
    fig.tight_layout()
    fig.savefig(OUT / "horizontal_scatter.png", dpi=90)
    plt.close(fig)
    fig, axes = plt.subplots(2, 4, figsize=(18, 9))
    for ax, jsr in zip(axes.flat, JSR_SCENARIOS_DB, strict=False):
        for name in METHODS:
            e = np.linalg.norm(results[jsr][name]["enu"], axis=1)
            e = np.sort(e[np.isfinite(e)])
            if e.size:
                ax.semilogx(np.maximum(e, 1e-3), np.arange(1, e.size + 1) / e.size, label=name)
        ax.set_title(_label(jsr))
        ax.set_xlabel("3D error, m")
        ax.set_ylabel("CDF")
        ax.grid(True, which="both")
    axes.flat[0].legend(fontsize=8)
    axes.flat[-1].axis("off")
    fig.suptitle("3D error CDF (cf. Cao et al., Fig. 8)")
    fig.tight_layout()
    fig.savefig(OUT / "error_cdf_3d.png", dpi=90)
    plt.close(fig)


def tables(results, speed, hy):
    lines = [
        "| J/S | sats (mean) | outlier epochs | method | avail | horiz RMS m | horiz p95 m | horiz max m "
        "| 3D RMS m | 3D p95 m | 3D max m | bursts recovered in 5 s (3D; horiz) | reinit |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for jsr in JSR_SCENARIOS_DB:
        r = results[jsr]
        for name in METHODS:
            s = r[name]
            rec = (
                f"{s['rec_ok']}/{s['rec_total']}; {s['rec_h_ok']}/{s['rec_total']}" if s["rec_total"] else "-"
            )
            lines.append(
                f"| {_label(jsr)} | {r['_sats']:.1f} | {r['_outlier_epochs']} | {name} | {s['avail']:.2f} "
                f"| {s['h_rms']:.3f} | {s['h_p95']:.3f} | {s['h_max']:.3f} | {s['d3_rms']:.3f} "
                f"| {s['d3_p95']:.3f} | {s['d3_max']:.3f} | {rec} | {s.get('reinit', '-')} |"
            )
    ups = np.median([s[0] for s in speed])
    rt = np.median([s[1] for s in speed])
    speed_line = (
        f"GNSS+UWB (3 anchors) replay: median {ups:.0f} filter updates/s, "
        f"{rt:.0f}x real time (6-min scenario; single core, shared machine)."
    )
    hy_lines = [
        "| case | CKF 3D / 2D RMSE m | LS.csv 3D / 2D | ESKF.csv 3D / 2D "
        "| authors' reported LS, ESKF 3D / 2D | CKF updates/s |",
        "|---|---|---|---|---|---|",
    ]
    for row in hy:
        rep = row["reported"]
        rep_s = f"{rep[0]:.2f}/{rep[1]:.2f}, {rep[2]:.2f}/{rep[3]:.2f}" if len(rep) == 4 else "-"
        hy_lines.append(
            f"| {row['case']} | {row['ckf'][0]:.2f} / {row['ckf'][1]:.2f} | {row['LS'][0]:.2f} / "
            f"{row['LS'][1]:.2f} | {row['ESKF'][0]:.2f} / {row['ESKF'][1]:.2f} | {rep_s} "
            f"| {row['updates_per_s']:.0f} |"
        )
    return "\n".join(lines), speed_line, "\n".join(hy_lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration-s", type=float, default=360.0)
    ap.add_argument("--hanyang", type=Path, default=Path("/work/shared/data/uwb_outdoor_hanyang"))
    args = ap.parse_args()
    results, speed = simulate_all(args.duration_s)
    figures(results)
    hy = hanyang(args.hanyang) if args.hanyang.exists() else []
    table, speed_line, hy_table = tables(results, speed, hy)
    print(table)
    print()
    print(speed_line)
    print()
    print(hy_table)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "fusion_jamming_table.md").write_text(
        f"<!-- generated by benchmarks/fusion_jamming.py --duration-s {args.duration_s:g} -->\n\n"
        f"## Simulated jamming (errors after {CONVERGENCE_S:.0f} s convergence)\n\n"
        f"{table}\n\n{speed_line}\n\n"
        f"## UWB-only, real data (Hanyang outdoor UWB dataset)\n\n{hy_table}\n"
    )


if __name__ == "__main__":
    main()
