"""Benchmark: the fusion filter with GPS alone against GPS + Galileo + BeiDou + GLONASS (+ QZSS).

Station ESBC00DNK (EUREF/IGS, Esbjerg; Septentrio PolaRx5), 2020-06-25, RINEX 3.05 mixed obs
(Hatanaka + gzip) and mixed broadcast nav; the measurements are built as in
benchmarks/multignss_spp.py (gnss_common.measurements: GPS L1 C/A, Galileo E1, BeiDou B1I, GLONASS
G1 per channel, QZSS L1; broadcast orbits, Klobuchar scaled to each carrier, Saastamoinen). Truth:
the station's published coordinate (header APPROX POSITION XYZ, 3582105.2910 532589.7313
5232754.8054 m ECEF).

Each epoch goes through ``uwb_gnss_fusion.fusion_filter.FusionFilter`` (GNSS only,
``use_uwb=False``, otherwise the default parameters), once with ``multi_gnss=False`` (GPS alone,
the filter before issue 15 item 1: the other systems skipped) and once with ``multi_gnss=True``
(one inter-system bias state per system other than GPS). The elevation mask of the filter is
raised from the default 10 deg to 30, 35 and 40 deg as a stand-in for an obstructed (urban canyon)
or partly jammed sky: fewer satellites of each system.

Per configuration: the epochs where the filter had a *fix* (initialised and the epoch's update
applied at least 3 + (number of systems in use above the mask) pseudoranges, i.e. a position
determined by that epoch alone), the epochs with any estimate, and the error of the estimate in
ENU at the truth over all epochs with an estimate (the filter predicts through epochs without a
fix): horizontal and 3D RMS, 95th percentile and maximum, and the share of epochs within 5 m (3D).

Jamming (semi-simulated, the default 10 deg mask): the real measurements degraded as a jammer of
a given J/S would degrade them under the project's tracking model (Cao et al. eq. 4 per signal,
with the signal's chip rate and quality factor Q = 1, i.e. a jammer of equal J/S over every band
from BeiDou B1I to GLONASS G1, e.g. a wideband noise jammer): each satellite's effective C/N0 from
its reported C/N0; a satellite whose effective C/N0 is below ``LOCK_CN0_DBHZ`` is lost; the others
get seeded white noise of the *additional* DLL (FLL) jitter ``sqrt(s(C/N0_eff)^2 - s(C/N0)^2)`` on
the pseudorange (rate), in the signal's chip length (wavelength), and report the effective C/N0;
the filter is told the J/S (``set_jammer_to_signal``). This is the filter's own noise model, so the
filter's weights are right by construction: the table shows what the extra satellites and the
per-signal spectral separation give, not robustness to model errors (the GPS-only simulator
rfi_sim.gnss_uwb, with outliers and correlated errors, is not multi-GNSS).

Constellations added one at a time (issue 27 item 4: adding a system must never worsen horizontal or
3D RMS), 10 deg mask: GPS, GPS + Galileo, GPS + Galileo + BeiDou, + QZSS, then every system (i.e.
+ GLONASS), each with ``multi_gnss=True`` on the epochs reduced to those systems (the shipped GLONASS
model: ``glonass_pseudorange_error_factor`` and a code-bias state per GLONASS satellite,
``glonass_satellite_bias_std_m``; a last row with the model before, GLONASS weighted as GPS and no
such states, outside the verdict); and the project's
GPS single point solution (``gnss_common.spp.SinglePointPositioner``, default parameters) for
reference. Below the ladder, the spread of the per-satellite broadcast biases of each system
(:func:`broadcast_bias_spread`): a bias per satellite, which the filter's one inter-system bias
per system cannot absorb and its white measurement noise does not describe.

Data: the one-hour cut in src/gnss_common/test/data (always), and the whole day when given
(``--day OBS.crx.gz NAV.rnx.gz``, from ../shared/data/multignss_esbc_2020/).
Writes docs/uwb_gnss_fusion/fusion_multignss.md.
Run: PYTHONPATH=src/gnss_common:src/uwb_gnss_fusion python benchmarks/fusion_multignss.py [--day OBS NAV]
"""

from __future__ import annotations

import argparse
import math
import platform
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from bench_progress import CaseLog, add_quiet_argument, case_log

from gnss_common.constants import GPS_CA_CHIP_RATE_HZ
from gnss_common.coordinates import azimuth_elevation, ecef_to_enu_rotation, ecef_to_geodetic
from gnss_common.ephemeris import earth_rotation_correction
from gnss_common.jamming_weights import dll_jitter_m, effective_cn0_dbhz, fll_jitter_mps
from gnss_common.measurements import GnssEpochBuilder
from gnss_common.observations import BEIDOU, GALILEO, GLONASS, GPS, QZSS, GnssEpoch
from gnss_common.rinex import read_rinex_nav, read_rinex_obs
from gnss_common.spp import SinglePointPositioner
from uwb_gnss_fusion.fusion_filter import FusionFilter, FusionParams
from uwb_gnss_fusion.gnss_update import signal_scales
from uwb_gnss_fusion.input_checks import used_constellations

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "src" / "gnss_common" / "test" / "data"
OUT = ROOT / "docs" / "uwb_gnss_fusion" / "fusion_multignss.md"
CUT = (DATA / "ESBC00DNK_R_20201770000_01H_30S_MO.crx.gz", DATA / "ESBC00DNK_R_20201770000_01H_MN.rnx.gz")
TRUTH_ECEF_M = np.array([3582105.2910, 532589.7313, 5232754.8054])
MASKS_DEG = (10.0, 30.0, 35.0, 40.0)
WITHIN_M = 5.0
JS_DB = (25.0, 30.0, 33.0, 35.0)
LOCK_CN0_DBHZ = 26.0
"""Tracking threshold of the semi-simulated jamming, dB-Hz (a receiver loses a signal below it)."""
JAM_SEED = 15


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def build_epochs(obs_path: Path, nav_path: Path) -> list[GnssEpoch]:
    obs = read_rinex_obs(obs_path)
    nav = read_rinex_nav(nav_path)
    builder = GnssEpochBuilder.from_rinex(obs, nav)
    return [builder.build(e).epoch for e in obs.epochs]


def systems_above(epoch: GnssEpoch, mask_deg: float, multi: bool) -> int:
    """Number of systems in use with a satellite above the mask (seen from the truth)."""
    used = used_constellations(multi)
    obs = [o for o in epoch.observations if o.constellation in used]
    if not obs:
        return 0
    _, el = azimuth_elevation(TRUTH_ECEF_M, np.array([o.satellite_position_ecef_m for o in obs]))
    el = np.degrees(np.atleast_1d(el))
    return len({o.constellation for o, e in zip(obs, el, strict=True) if e >= mask_deg})


def jam(epochs: list[GnssEpoch], js_db: float, seed: int) -> list[GnssEpoch]:
    """The epochs as a jammer of ``js_db`` would leave them (module docstring)."""
    rng = np.random.default_rng(seed)
    loop = FusionParams().loop
    out = []
    for epoch in epochs:
        obs = epoch.observations
        if not obs:
            out.append(epoch)
            continue
        system = np.array([o.constellation for o in obs])
        chip, lam = signal_scales(system, np.array([o.carrier_frequency_hz for o in obs], dtype=float))
        cn0 = np.array([o.cn0_dbhz if math.isfinite(o.cn0_dbhz) else 45.0 for o in obs])
        eff = np.array([float(effective_cn0_dbhz(c, js_db, 1.0, float(f))) for c, f in zip(cn0, chip, strict=True)])
        scale = GPS_CA_CHIP_RATE_HZ / chip
        add_pr = np.sqrt(np.maximum((dll_jitter_m(eff, loop) ** 2 - dll_jitter_m(cn0, loop) ** 2), 0.0)) * scale
        add_rate = np.sqrt(np.maximum(fll_jitter_mps(eff, loop) ** 2 - fll_jitter_mps(cn0, loop) ** 2, 0.0)) * lam
        n_pr = rng.standard_normal(len(obs))
        n_rate = rng.standard_normal(len(obs))
        kept = tuple(
            replace(o, pseudorange_m=o.pseudorange_m + add_pr[i] * n_pr[i],
                    pseudorange_rate_mps=o.pseudorange_rate_mps + add_rate[i] * n_rate[i], cn0_dbhz=float(eff[i]))
            for i, o in enumerate(obs) if eff[i] >= LOCK_CN0_DBHZ
        )
        out.append(replace(epoch, observations=kept))
    return out


def run(epochs: list[GnssEpoch], mask_deg: float, multi: bool, js_db: float = math.nan,
        params: dict[str, object] | None = None) -> dict[str, object]:
    f = FusionFilter(FusionParams(use_uwb=False, multi_gnss=multi, elevation_mask_deg=mask_deg,
                                  **(params or {})))  # type: ignore[arg-type]
    lat, lon, _ = ecef_to_geodetic(TRUTH_ECEF_M)
    rot = ecef_to_enu_rotation(lat, lon)
    enu, fixes, n_sats = [], 0, []
    t0 = time.perf_counter()
    for epoch in epochs:
        if math.isfinite(js_db):
            f.set_jammer_to_signal(epoch.stamp_ns, js_db)
        out = f.process_gnss(epoch)
        if not out.initialized:
            continue
        enu.append(rot @ (out.position_m - TRUTH_ECEF_M))
        n_sys = systems_above(epoch, mask_deg, multi)
        if n_sys and out.satellites_used >= 3 + n_sys:
            fixes += 1
        n_sats.append(out.satellites_used)
    wall = time.perf_counter() - t0
    e = np.array(enu).reshape(-1, 3)
    d3 = np.linalg.norm(e, axis=1)
    h = np.linalg.norm(e[:, :2], axis=1)
    return {
        "fixes": fixes,
        "estimates": len(e),
        "h_rms": float(np.sqrt(np.mean(h**2))) if len(e) else math.nan,
        "rms": float(np.sqrt(np.mean(d3**2))) if len(e) else math.nan,
        "p95": float(np.percentile(d3, 95)) if len(e) else math.nan,
        "max": float(d3.max()) if len(e) else math.nan,
        "within": float(np.mean(d3 <= WITHIN_M)) * len(e) if len(e) else 0.0,
        "sats": float(np.median(n_sats)) if n_sats else 0.0,
        "ms_per_epoch": 1000.0 * wall / max(len(epochs), 1),
        "biases": f.inter_system_biases_m,
        "reference": f.reference_system,
        "counts": f.rejection_counts,
    }


LADDER = (("GPS", (GPS,)), ("GPS + Galileo", (GPS, GALILEO)), ("GPS + Galileo + BeiDou", (GPS, GALILEO, BEIDOU)),
          ("GPS + Galileo + BeiDou + QZSS", (GPS, GALILEO, BEIDOU, QZSS)), ("every system (+ GLONASS)", None))
BIAS_MIN_ELEVATION_DEG = 20.0
"""Satellites above this elevation enter the per-satellite residual means of :func:`broadcast_bias_spread`."""
BIAS_EPOCH_STRIDE = 4
"""Every this many epochs enter :func:`broadcast_bias_spread` (2 min apart at 30 s)."""


GLONASS_BEFORE: dict[str, object] = {"glonass_pseudorange_error_factor": 1.0, "glonass_satellite_bias_std_m": 0.0}
"""The GLONASS model before issue 27 item 4 (the ladder's last row, not in its verdict)."""
GLONASS_BEFORE_LABEL = "error factor 1, no code-bias states"


def only(epochs: list[GnssEpoch], systems: tuple[int, ...] | None) -> list[GnssEpoch]:
    """The epochs with the observations of ``systems`` alone (None: all)."""
    if systems is None:
        return epochs
    return [replace(e, observations=tuple(o for o in e.observations if o.constellation in systems)) for e in epochs]


def spp_rms(epochs: list[GnssEpoch]) -> tuple[float, float, int]:
    """Horizontal and 3D RMS of the project's GPS SPP, m, and its number of fixes."""
    lat, lon, _ = ecef_to_geodetic(TRUTH_ECEF_M)
    rot = ecef_to_enu_rotation(lat, lon)
    spp = SinglePointPositioner()
    enu = []
    for e in epochs:
        r = spp.process(e)
        if r.valid:
            enu.append(rot @ (r.position_ecef_m - TRUTH_ECEF_M))
    a = np.array(enu).reshape(-1, 3)
    return (float(np.sqrt(np.mean(a[:, 0] ** 2 + a[:, 1] ** 2))), float(np.sqrt(np.mean((a**2).sum(axis=1)))),
            len(a))


def broadcast_bias_spread(epochs: list[GnssEpoch]) -> dict[int, tuple[float, float, int]]:
    """Per system: (spread of the per-satellite mean residuals, mean within-satellite std, satellites), m.

    Residual of each satellite above :data:`BIAS_MIN_ELEVATION_DEG` at the truth: pseudorange minus
    the modelled range, satellite clock, Klobuchar and troposphere, minus the epoch's median GPS
    residual (the receiver clock). Its mean over the day per satellite holds the satellite's
    broadcast clock/orbit bias plus the system's inter-system bias; the spread (standard deviation)
    of these means within a system leaves the inter-system bias out: a per-satellite bias that one
    inter-system bias state cannot absorb.
    """
    per_sat: dict[tuple[int, int], list[float]] = {}
    for e in epochs[::BIAS_EPOCH_STRIDE]:
        obs = e.observations
        if not obs:
            continue
        pos, _, _ = earth_rotation_correction(np.array([o.satellite_position_ecef_m for o in obs]), TRUTH_ECEF_M)
        _, el = azimuth_elevation(TRUTH_ECEF_M, pos)
        el = np.degrees(np.atleast_1d(el))
        r = np.array([o.pseudorange_m - np.linalg.norm(pos[i] - TRUTH_ECEF_M) + o.satellite_clock_bias_m
                      - o.ionosphere_delay_m - o.troposphere_delay_m for i, o in enumerate(obs)])
        gps = np.array([o.constellation == GPS for o in obs]) & (el >= BIAS_MIN_ELEVATION_DEG)
        if gps.sum() < 3:
            continue
        clock = float(np.median(r[gps]))
        for i, o in enumerate(obs):
            if el[i] >= BIAS_MIN_ELEVATION_DEG and math.isfinite(r[i]):
                per_sat.setdefault((o.constellation, o.svid), []).append(float(r[i]) - clock)
    out = {}
    for system in sorted({k[0] for k in per_sat}):
        vals = [v for k, v in per_sat.items() if k[0] == system and len(v) >= 10]
        if len(vals) >= 2:
            out[system] = (float(np.std([np.mean(v) for v in vals])), float(np.mean([np.std(v) for v in vals])),
                           len(vals))
    return out


SYSTEM_LABELS = {GPS: "GPS", GLONASS: "GLONASS", GALILEO: "Galileo", BEIDOU: "BeiDou", QZSS: "QZSS"}


def ladder(epochs: list[GnssEpoch], log: CaseLog) -> list[str]:
    """Systems added one at a time, 10 deg mask (module docstring); ``log`` gets each row."""
    n = len(epochs)
    lines = ["Systems added one at a time, 10 deg mask (multi_gnss=True on the reduced epochs):", "",
             "| systems | median satellites used | epochs with an estimate | horizontal RMS m | 3D RMS m | "
             "static model entered / left |", "|---|---|---|---|---|---|"]
    h, d, k = spp_rms(epochs)
    lines.append(f"| our SPP (GPS, gnss_common.spp) | - | {k} / {n} | {h:.2f} | {d:.2f} | - |")
    log.done("ladder: our SPP")
    log.say(lines[-1])
    prev: tuple[float, float] | None = None
    never_worse = True
    for name, systems in LADDER:
        r = run(only(epochs, systems), 10.0, True)
        c = r["counts"]
        assert isinstance(c, dict)
        lines.append(f"| {name} | {r['sats']:.0f} | {r['estimates']} / {n} | {r['h_rms']:.2f} | {r['rms']:.2f} | "
                     f"{c.get('motion_static_entered', 0)} / {c.get('motion_static_left', 0)} |")
        log.done(f"ladder: {name}")
        log.say(lines[-1])
        cur = (float(r["h_rms"]), float(r["rms"]))  # type: ignore[arg-type]
        if prev is not None and (round(cur[0], 2) > round(prev[0], 2) or round(cur[1], 2) > round(prev[1], 2)):
            never_worse = False
        prev = cur
    r = run(epochs, 10.0, True, params=GLONASS_BEFORE)
    lines.append(f"| every system, GLONASS weighted as GPS (before: {GLONASS_BEFORE_LABEL}) | {r['sats']:.0f} | "
                 f"{r['estimates']} / {n} | {r['h_rms']:.2f} | {r['rms']:.2f} | - |")
    log.done("ladder: GLONASS as before")
    log.say(lines[-1])
    verdict = "met" if never_worse else "NOT met"
    lines += ["", f"Adding a system never worsens horizontal or 3D RMS (to the cm): **{verdict}**.", ""]
    spread = broadcast_bias_spread(epochs)
    lines += ["Per-satellite broadcast biases (`broadcast_bias_spread`: residuals at the truth above "
              f"{BIAS_MIN_ELEVATION_DEG:g} deg, one epoch in {BIAS_EPOCH_STRIDE}): spread of the per-satellite "
              "means / mean std within a satellite: "
              + "; ".join(f"{SYSTEM_LABELS.get(k, str(k))} {v[0]:.2f} / {v[1]:.2f} m ({v[2]} satellites)"
                          for k, v in spread.items()) + ".", ""]
    return lines


def section(title: str, epochs: list[GnssEpoch], log: CaseLog) -> list[str]:
    n = len(epochs)
    lines = [
        f"## {title}",
        "",
        "| mask deg | filter | median satellites used | epochs with a fix | epochs with an estimate | "
        "horizontal RMS m | 3D RMS m | 3D 95 % m | 3D max m | epochs within 5 m (3D) | ms / epoch |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    notes = []
    for mask in MASKS_DEG:
        for multi in (False, True):
            r = run(epochs, mask, multi)
            name = "GPS + Galileo + BeiDou + GLONASS + QZSS" if multi else "GPS only"
            lines.append(
                f"| {mask:g} | {name} | {r['sats']:.0f} | {r['fixes']} / {n} ({100 * r['fixes'] / n:.0f} %) | "
                f"{r['estimates']} / {n} | {r['h_rms']:.2f} | {r['rms']:.2f} | {r['p95']:.2f} | {r['max']:.2f} | "
                f"{r['within']:.0f} / {n} ({100 * r['within'] / n:.0f} %) | {r['ms_per_epoch']:.2f} |"
            )
            if multi:
                b = ", ".join(f"{k} {v[0]:.2f} +- {v[1]:.2f} m" for k, v in r["biases"].items())
                events = {k: v for k, v in r["counts"].items() if k.startswith("inter_system_bias")}
                notes.append(f"- mask {mask:g} deg: reference clock {r['reference']}; inter-system biases at the "
                             f"end: {b}; {events}")
            log.done(f"mask {mask:g} deg, {name}")
            log.say(lines[-1])
    lines += ["", "Multi-GNSS filter, inter-system bias estimates (relative to the reference clock):", "",
              *notes, ""]
    lines += [
        f"Semi-simulated jamming (module docstring), 10 deg mask, signals lost below {LOCK_CN0_DBHZ:g} dB-Hz "
        "effective C/N0, seed " + str(JAM_SEED) + ":",
        "",
        "| J/S dB | filter | median satellites used | epochs with a fix | epochs with an estimate | "
        "horizontal RMS m | 3D RMS m | 3D 95 % m | 3D max m | epochs within 5 m (3D) | ms / epoch |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for js in JS_DB:
        jammed = jam(epochs, js, JAM_SEED)
        for multi in (False, True):
            r = run(jammed, 10.0, multi, js)
            name = "GPS + Galileo + BeiDou + GLONASS + QZSS" if multi else "GPS only"
            lines.append(
                f"| {js:g} | {name} | {r['sats']:.0f} | {r['fixes']} / {n} ({100 * r['fixes'] / n:.0f} %) | "
                f"{r['estimates']} / {n} | {r['h_rms']:.2f} | {r['rms']:.2f} | {r['p95']:.2f} | {r['max']:.2f} | "
                f"{r['within']:.0f} / {n} ({100 * r['within'] / n:.0f} %) | {r['ms_per_epoch']:.2f} |"
            )
            log.done(f"J/S {js:g} dB, {name}")
            log.say(lines[-1])
    return lines + [""] + ladder(epochs, log)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--day", nargs=2, type=Path, metavar=("OBS", "NAV"), help="the whole-day files")
    add_quiet_argument(parser)
    args = parser.parse_args()
    log = case_log(__file__, quiet=args.quiet)
    text = [
        "# Fusion filter: GPS alone against multi-GNSS on a real station (ESBC00DNK)",
        "",
        "Generated by `benchmarks/fusion_multignss.py` (method in its docstring). GNSS-only fusion",
        "filter (default parameters, no UWB), GPS alone (`multi_gnss=False`) against every system the",
        "input carries (`multi_gnss=True`: one inter-system bias state per system other than GPS).",
        "Error against the station's published coordinate. A raised elevation mask stands in for an",
        "obstructed or partly jammed sky. *Fix*: the epoch's update applied at least 3 + (systems in",
        "use above the mask) pseudoranges. Single-system snapshot positions of the same data:",
        "docs/gnss_common/multignss_spp.md.",
        f"Machine: {cpu_model()}, Python {platform.python_version()}. `ms / epoch` is the wall time of one",
        "process on a shared machine: compare rows of one run only, not runs.",
        "",
    ]
    sections = [("one hour (test data cut, 2020-06-25 00:00-01:00 GPST, 120 epochs)", CUT)]
    if args.day:
        sections.append(("whole day (2020-06-25, 2,880 epochs)", tuple(args.day)))
    for title, (obs_path, nav_path) in sections:
        text += section(title, build_epochs(obs_path, nav_path), log)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text("\n".join(text))
    log.finish(f"wrote {OUT}")


if __name__ == "__main__":
    main()
