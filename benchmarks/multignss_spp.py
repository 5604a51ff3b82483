"""Benchmark: single-point position from each constellation alone on a real multi-GNSS station.

Station ESBC00DNK (EUREF/IGS, Esbjerg; Septentrio PolaRx5), 2020-06-25, RINEX 3.05 mixed obs
(Hatanaka + gzip) and mixed broadcast nav. Truth: the header APPROX POSITION XYZ, the station's
published coordinate (cm level).

Pipeline: gnss_common.rinex (decompression, RINEX 3 mixed) -> gnss_common.measurements (broadcast
orbits: GPS / Galileo / BeiDou Keplerian, GLONASS integrated; Klobuchar scaled to each carrier;
Saastamoinen) -> per epoch and per system a plain unweighted least-squares fix from that system's
satellites alone (own receiver clock, 10 deg mask at the truth, >= 5 satellites), with
gnss_common.positioning.least_squares_position. GPS L1, Galileo E1, BeiDou B1I, GLONASS G1, each
on the tracking attribute gnss_common.observation_codes picks per satellite (ESBC: C1C, C1C, C2I,
C1C; GLONASS C1P where a satellite has no C1C range); the doc counts the codes used.

Data: the one-hour cut in src/gnss_common/test/data (always), and the whole day from the
project's data collection when given: ``--day OBS.crx.gz NAV.rnx.gz``.
Writes docs/gnss_common/multignss_spp.md.
Run: PYTHONPATH=src/gnss_common python benchmarks/multignss_spp.py [--day OBS NAV]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from gnss_common.coordinates import azimuth_elevation, ecef_to_enu_rotation, ecef_to_geodetic
from gnss_common.ephemeris import earth_rotation_correction
from gnss_common.measurements import GnssEpochBuilder
from gnss_common.observations import BEIDOU, GALILEO, GLONASS, GPS, QZSS
from gnss_common.positioning import CONVERGED, least_squares_position
from gnss_common.rinex import SYSTEM_NAMES, read_rinex_nav, read_rinex_obs

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "src" / "gnss_common" / "test" / "data"
OUT = ROOT / "docs" / "gnss_common" / "multignss_spp.md"
CUT = (DATA / "ESBC00DNK_R_20201770000_01H_30S_MO.crx.gz", DATA / "ESBC00DNK_R_20201770000_01H_MN.rnx.gz")
SYSTEMS = ((GPS, "GPS L1 C/A"), (GALILEO, "Galileo E1"), (BEIDOU, "BeiDou B1I"), (GLONASS, "GLONASS G1"))
MASK_DEG = 10.0


def fix(observations: list, truth: np.ndarray) -> np.ndarray | None:
    """Unweighted least-squares position from these satellites alone, or None."""
    if len(observations) < 5:
        return None
    sat = np.array([o.satellite_position_ecef_m for o in observations])
    _, el = azimuth_elevation(truth, earth_rotation_correction(sat, truth)[0])
    keep = np.atleast_1d(el) > math.radians(MASK_DEG)
    if keep.sum() < 5:
        return None
    sat = sat[keep]
    rho = np.array([o.pseudorange_m + o.satellite_clock_bias_m - o.ionosphere_delay_m - o.troposphere_delay_m
                    for o, k in zip(observations, keep, strict=True) if k])
    w = np.ones(rho.size)

    def model(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        diff = earth_rotation_correction(sat, x[:3])[0] - x[:3]
        rng = np.linalg.norm(diff, axis=1)
        return rng + x[3], diff / rng[:, None], w

    sol = least_squares_position(model, rho, np.zeros(4), 20, 1.0e-4, max_variance_m2=np.inf)
    return sol.x[:3].copy() if sol.status == CONVERGED else None


def evaluate(
    obs_path: Path, nav_path: Path
) -> tuple[list[str], int, dict[str, dict[str, int]], tuple[int, int], dict[str, dict[str, int]]]:
    obs = read_rinex_obs(obs_path)
    nav = read_rinex_nav(nav_path)
    truth = np.asarray(obs.header.approx_position_ecef_m)
    lat, lon, _ = ecef_to_geodetic(truth)
    rot = ecef_to_enu_rotation(lat, lon)
    builder = GnssEpochBuilder.from_rinex(obs, nav)
    enu: dict[int, list[np.ndarray]] = {c: [] for c, _ in SYSTEMS}
    skipped: dict[str, dict[str, int]] = {}
    codes: dict[str, dict[str, int]] = {}
    qzss_total = qzss_max = 0
    for epoch in obs.epochs:
        r = builder.build(epoch)
        n_qzss = sum(1 for o in r.epoch.observations if o.constellation == QZSS)
        qzss_total, qzss_max = qzss_total + n_qzss, max(qzss_max, n_qzss)
        for sat, used in r.signal_codes.items():
            dst = codes.setdefault(SYSTEM_NAMES[sat[0]], {})
            dst[used] = dst.get(used, 0) + 1
        for name, reasons in r.skipped_by_constellation.items():
            dst = skipped.setdefault(name, {})
            for reason, n in reasons.items():
                dst[reason] = dst.get(reason, 0) + n
        for code, _ in SYSTEMS:
            x = fix([o for o in r.epoch.observations if o.constellation == code], truth)
            if x is not None:
                enu[code].append(rot @ (x - truth))
    rows = []
    for code, label in SYSTEMS:
        e = np.array(enu[code]).reshape(-1, 3)
        d3 = np.linalg.norm(e, axis=1)
        h = np.linalg.norm(e[:, :2], axis=1)
        rows.append(
            f"| {label} | {len(e)} / {len(obs.epochs)} | {np.sqrt(np.mean(h**2)):.2f} | "
            f"{np.sqrt(np.mean(e[:, 2]**2)):.2f} | {np.sqrt(np.mean(d3**2)):.2f} | {np.median(d3):.2f} | "
            f"{np.percentile(d3, 95):.2f} | {d3.max():.2f} |"
        )
    return rows, len(obs.epochs), skipped, (qzss_total, qzss_max), codes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--day", nargs=2, type=Path, metavar=("OBS", "NAV"), help="the whole-day files")
    args = parser.parse_args()
    head = ("| system (signal) | epochs with a fix | horizontal RMS m | vertical RMS m | 3D RMS m | "
            "3D median m | 3D 95 % m | 3D max m |\n|---|---|---|---|---|---|---|---|")
    text = [
        "# Single-point position per constellation on a real multi-GNSS station (ESBC00DNK)",
        "",
        "Generated by `benchmarks/multignss_spp.py`. Each system alone: broadcast orbits and clocks",
        "(GLONASS integrated), Klobuchar scaled to the carrier, standard-atmosphere Saastamoinen, an",
        f"unweighted least-squares fix with its own receiver clock, {MASK_DEG:g} deg mask, >= 5 satellites.",
        "Error against the station's published coordinate (header APPROX POSITION XYZ). A plain",
        "single-frequency broadcast solution: the residual errors are the broadcast ionosphere model,",
        "the broadcast orbits and clocks, and multipath.",
        "",
    ]
    sections = [("one hour (test data cut, 2020-06-25 00:00-01:00 GPST)", CUT)]
    if args.day:
        sections.append(("whole day (2020-06-25, 2,880 epochs)", tuple(args.day)))
    for title, (obs_path, nav_path) in sections:
        rows, n, skipped, (qzss_total, qzss_max), codes = evaluate(obs_path, nav_path)
        text += [f"## {title}", "", head, *rows, "",
                 f"QZSS L1 C/A: {qzss_total} measurements built, at most {qzss_max} satellites in one epoch "
                 "(too few for a fix from QZSS alone).", "",
                 "Satellite measurements skipped, by constellation:", ""]
        for name, reasons in sorted(skipped.items()):
            text.append(f"- {name}: " + ", ".join(f"{r} {c}" for r, c in sorted(reasons.items())))
        text += ["", "Observation codes the measurements were built from (pseudorange, Doppler and C/N0 of one",
                 "tracking attribute, by the priority of gnss_common.observation_codes; before the mask):", ""]
        for name, used in sorted(codes.items()):
            text.append(f"- {name}: " + ", ".join(f"{c} {k}" for c, k in sorted(used.items(), key=lambda kv: -kv[1])))
        text.append("")
        print("\n".join(text[-len(rows) - 4:]))
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text("\n".join(text))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
