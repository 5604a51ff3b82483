"""What limits the GNSS-only filter on the real stations (issue 27 item 4), measured.

Used by benchmarks/fusion_real_gnss.py, whose document gets the section this module writes. Five
measurements, each on the stations' epochs as ``rinex_to_bag.convert_rinex`` builds them:

1. **Error spectrum of SPP.** Our SPP's horizontal error (ENU at the surveyed truth) split into a
   slow part, its centred (non-causal) moving average over ``W`` minutes, and the rest. No filter
   that averages the epochs of the last ``W`` minutes, not even a non-causal one, removes the slow
   part: ``1 - rms(slow) / rms(SPP)`` is the gain a ``W``-minute average can give at best.
2. **Common mode between GEONET 0759 and 3040** (3.34 km apart): the correlation of the two SPP
   error series per axis. Receiver noise and multipath are independent at two sites; the
   broadcast-model errors (orbit, clock, ionosphere, troposphere) are shared.
3. **The filter told the antenna is static** (no detector), and the detector's static model, over
   a range of static process noise (white-acceleration PSD): whether any motion model setting
   reaches the 20 % goal. The filter core (``FusionFilter``, GNSS only) on the epochs, as the node
   runs it (same figures as the node rows of the table at the shipped defaults).
4. **Ionosphere-free pseudoranges.** ``PR_IF = (f1^2 P_L1 - f2^2 P_L2) / (f1^2 - f2^2)``
   (:func:`gnss_common.corrections.ionosphere_free_pseudorange_m`, IS-GPS-200 20.3.3.3.3.3) with no
   ionospheric model (``ionosphere_delay_m`` 0) and the broadcast clock without T_GD (the clock
   polynomial refers to the P1/P2 combination, 20.3.3.3.3.2): our SPP and the filter core on these
   epochs (weights as for L1: the combination's 3x larger noise not modelled). ``P1``: the shipped
   conversion, ``convert_rinex(..., ionosphere_free=True)`` (``rinex_to_bag --ionosphere-free``).
   ``C1``: C/A with P2, which the conversion refuses, formed here to show why: T_GD refers to
   P1/P2, so each satellite's P1-C1 code bias (a few dm, in no broadcast message) stays, amplified
   by f1^2 / (f1^2 - f2^2) = 2.55. ARL1 has P1 and C1 (both shown); GEONET only C1 and P2.
5. **The slow error as a state.** The filter core with one first-order Gauss-Markov error state per
   satellite (``pseudorange_correlated_std_m`` / ``pseudorange_correlated_tau_s``, Brown & Hwang sec.
   4.2; off in the shipped defaults) for a few (sigma, tau) around the correlation times section 1 shows:
   whether estimating the slow per-satellite error, rather than averaging it as white, gains.

Run through benchmarks/fusion_real_gnss.py (no command line of its own).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from gnss_common.constants import GPS_L1_FREQUENCY_HZ, GPS_L2_FREQUENCY_HZ, SPEED_OF_LIGHT_MPS
from gnss_common.corrections import ionosphere_free_pseudorange_m
from gnss_common.gps_time import gps_to_ros_stamp_ns
from gnss_common.observations import GPS, GnssEpoch
from gnss_common.rinex_nav import read_rinex_navs
from gnss_common.rinex_obs import read_rinex_obs
from gnss_common.spp import SinglePointPositioner
from rfi_experiments.rinex_to_bag import convert_rinex
from rfi_sim.evaluation import ecef_errors_enu, error_3d_m, horizontal_error_m
from uwb_gnss_fusion.fusion_filter import FusionFilter
from uwb_gnss_fusion.fusion_params import FusionParams

EPOCH_S = 30.0
"""Observation interval of the three stations, s."""
SLOW_WINDOWS_MIN = (5.0, 10.0, 20.0)
"""Moving-average windows of the spectrum split, min."""
CORRELATED_SCAN = ((0.0, 60.0), (0.3, 600.0), (0.5, 600.0), (1.0, 600.0), (1.0, 1800.0))
"""(sigma m, tau s) of the per-satellite Gauss-Markov error states tried in section 5 (0: off, shipped)."""
STATIC_PSD_SCAN_M2PS3 = (1.0e-10, 1.0e-9, 1.0e-8, 1.0e-7, 1.0e-6)
"""Static white-acceleration PSDs tried, m^2/s^3 (1e-8 is the shipped ``static_accel_psd_m2ps3``)."""


@dataclass(frozen=True)
class StationData:
    """One station's epochs and truth."""

    name: str
    obs_path: Path
    nav_path: Path
    epochs: tuple[GnssEpoch, ...]
    truth_ecef_m: np.ndarray


def rms_h_3d(err_enu: np.ndarray) -> tuple[float, float]:
    """(horizontal RMS, 3D RMS), m, of ENU errors (N, 3)."""
    if err_enu.size == 0:
        return math.nan, math.nan
    return (float(np.sqrt(np.mean(horizontal_error_m(err_enu) ** 2))),
            float(np.sqrt(np.mean(error_3d_m(err_enu) ** 2))))


def spp_errors(epochs: Sequence[GnssEpoch], truth: np.ndarray) -> np.ndarray:
    """ENU errors of our SPP (default parameters) at every epoch, NaN rows where it has no fix, (N, 3)."""
    spp = SinglePointPositioner()
    out = np.full((len(epochs), 3), math.nan)
    for i, e in enumerate(epochs):
        r = spp.process(e)
        if r.valid:
            out[i] = ecef_errors_enu(np.asarray(r.position_ecef_m)[None, :], truth)[0]
    return out


def filter_errors(epochs: Sequence[GnssEpoch], truth: np.ndarray, **params: object) -> np.ndarray:
    """ENU errors of the GNSS-only filter core (defaults but ``params``) at every initialised epoch, (M, 3)."""
    f = FusionFilter(FusionParams(use_uwb=False, **params))  # type: ignore[arg-type]
    pos = []
    for e in epochs:
        o = f.process_gnss(e)
        if o.initialized:
            pos.append(o.position_m)
    return ecef_errors_enu(np.array(pos).reshape(-1, 3), truth)


def slow_part(err_enu: np.ndarray, window_min: float) -> np.ndarray:
    """Centred moving average of the east and north errors over ``window_min`` (NaN rows ignored), (N, 2)."""
    w = max(1, int(round(window_min * 60.0 / EPOCH_S)))
    ok = np.isfinite(err_enu[:, 0])
    kernel = np.ones(w)
    count = np.convolve(ok.astype(float), kernel, mode="same")
    out = np.empty((err_enu.shape[0], 2))
    for k in range(2):
        out[:, k] = np.convolve(np.where(ok, err_enu[:, k], 0.0), kernel, mode="same") / np.maximum(count, 1.0)
    return out[ok]


def ionosphere_free_epochs(station: StationData, l1_code: str) -> tuple[tuple[GnssEpoch, ...], int]:
    """The station's GPS epochs with ionosphere-free pseudoranges from ``l1_code`` and P2 (module docstring).

    Returns:
        (epochs, satellites dropped for a missing code). ``P1``: the shipped conversion; ``C1``: the
        L1 epochs with the C1/P2 combination (satellite states, troposphere, Doppler, C/N0 kept).
    """
    if l1_code == "P1":
        conv = convert_rinex(station.obs_path, station.nav_path, ionosphere_free=True)
        return conv.epochs, conv.skipped["missing_dual_frequency"]
    obs = read_rinex_obs(station.obs_path)
    tgd = {e.prn: e.tgd_s for e in read_rinex_navs([station.nav_path]).keplerian_ephemerides if e.system == "G"}
    by_stamp = {e.stamp_ns: e for e in station.epochs}
    out = []
    dropped = 0
    for rinex_epoch in obs.epochs:
        epoch = by_stamp.get(gps_to_ros_stamp_ns(rinex_epoch.gps_week, rinex_epoch.tow_s))
        if epoch is None:
            continue
        kept = []
        for o in epoch.observations:
            values = rinex_epoch.observations.get(f"G{o.svid:02d}", {})
            p1, p2 = values.get(l1_code, math.nan), values.get("P2", math.nan)
            if o.constellation != GPS or not (math.isfinite(p1) and math.isfinite(p2)):
                dropped += 1
                continue
            pr_if = float(ionosphere_free_pseudorange_m(p1, p2, GPS_L1_FREQUENCY_HZ, GPS_L2_FREQUENCY_HZ))
            kept.append(replace(o, pseudorange_m=pr_if, ionosphere_delay_m=0.0,
                                satellite_clock_bias_m=o.satellite_clock_bias_m
                                + SPEED_OF_LIGHT_MPS * tgd.get(o.svid, 0.0)))
        out.append(replace(epoch, observations=tuple(kept)))
    return tuple(out), dropped


def limits_section(stations: Sequence[StationData], goal_gain: float) -> tuple[str, dict[str, object]]:
    """The Markdown section of the five measurements (module docstring) and its figures."""
    figures: dict[str, object] = {}
    spp_err = {s.name: spp_errors(s.epochs, s.truth_ecef_m) for s in stations}
    spp_rms = {n: rms_h_3d(e[np.isfinite(e[:, 0])]) for n, e in spp_err.items()}

    lines = ["### 1. The SPP error is slow", "",
             "Our SPP's horizontal error split into its centred moving average over W minutes (the slow part)",
             "and the rest. Best gain: what removing everything faster than W minutes would give, even",
             "without causality.", "",
             "| station | SPP horiz. RMS m | " + " | ".join(f"slow part, W = {w:.0f} min: RMS m (best gain)"
                                                       for w in SLOW_WINDOWS_MIN) + " |",
             "|---|---|" + "---|" * len(SLOW_WINDOWS_MIN)]
    for s in stations:
        err = spp_err[s.name]
        h = spp_rms[s.name][0]
        cells = []
        for w in SLOW_WINDOWS_MIN:
            slow = float(np.sqrt(np.mean(np.sum(slow_part(err, w) ** 2, axis=1))))
            cells.append(f"{slow:.2f} ({100 * (1 - slow / h):.0f} %)")
            figures[f"slow_{s.name}_{w:.0f}"] = slow
        lines.append(f"| {s.name} | {h:.2f} | " + " | ".join(cells) + " |")

    geonet = [s for s in stations if s.name.startswith("GEONET")]
    if len(geonet) == 2:
        a, b = spp_err[geonet[0].name], spp_err[geonet[1].name]
        ok = np.isfinite(a[:, 0]) & np.isfinite(b[:, 0])
        corr = [float(np.corrcoef(a[ok, k], b[ok, k])[0, 1]) for k in range(3)]
        figures["geonet_corr_enu"] = corr
        lines += ["", "### 2. Shared by two stations 3.34 km apart", "",
                  f"Correlation of the SPP error series of {geonet[0].name} and {geonet[1].name}: east "
                  f"{corr[0]:.2f}, north {corr[1]:.2f}, up {corr[2]:.2f}."]

    lines += ["", "### 3. Told static, or a slower static model", "",
              "Filter core, horizontal RMS m (gain over SPP). `told static`: `motion_detection` false and the",
              "white-acceleration PSD from the first epoch; `detector`: the shipped detector with that",
              "`static_accel_psd_m2ps3` (1e-8 is the default).", "",
              "| PSD m^2/s^3 | " + " | ".join(f"{s.name} told static | {s.name} detector" for s in stations) + " |",
              "|---|" + "---|---|" * len(stations)]
    best: dict[str, float] = {s.name: 0.0 for s in stations}
    for q in STATIC_PSD_SCAN_M2PS3:
        cells = []
        for s in stations:
            h_spp = spp_rms[s.name][0]
            for params in ({"motion_detection": False, "accel_psd_m2ps3": q}, {"static_accel_psd_m2ps3": q}):
                h = rms_h_3d(filter_errors(s.epochs, s.truth_ecef_m, **params))[0]
                best[s.name] = max(best[s.name], 1 - h / h_spp)
                cells.append(f"{h:.2f} ({100 * (1 - h / h_spp):.0f} %)")
        lines.append(f"| {q:g} | " + " | ".join(cells) + " |")
    figures["best_motion_gain"] = best
    reach = [n for n, g in best.items() if g >= goal_gain]
    lines += ["", "Best gain over the scan: " + ", ".join(f"{n} {100 * g:.0f} %" for n, g in best.items())
              + f"; {100 * goal_gain:.0f} % reached on: {', '.join(reach) if reach else 'none'}."]

    lines += ["", "### 4. Ionosphere-free pseudoranges", "",
              "| station | L1 code with P2 | satellites dropped (no code) | SPP horiz. / 3D RMS m "
              "| filter horiz. / 3D RMS m | filter gain over L1 SPP |", "|---|---|---|---|---|---|"]
    for s in stations:
        h_spp, d_spp = spp_rms[s.name]
        h_f, d_f = rms_h_3d(filter_errors(s.epochs, s.truth_ecef_m))
        lines.append(f"| {s.name} | none (L1 + Klobuchar, as shipped) | - | {h_spp:.2f} / {d_spp:.2f} "
                     f"| {h_f:.2f} / {d_f:.2f} | {100 * (1 - h_f / h_spp):.0f} % |")
        header = read_rinex_obs(s.obs_path).header
        codes = [c for c in ("P1", "C1") if c in header.obs_types.get("G", ())]
        for code in codes:
            eps, dropped = ionosphere_free_epochs(s, code)
            err = spp_errors(eps, s.truth_ecef_m)
            h, d = rms_h_3d(err[np.isfinite(err[:, 0])])
            hf, df = rms_h_3d(filter_errors(eps, s.truth_ecef_m))
            figures[f"if_{s.name}_{code}"] = (h, d, hf, df)
            lines.append(f"| {s.name} | {code} | {dropped} | {h:.2f} / {d:.2f} | {hf:.2f} / {df:.2f} "
                         f"| {100 * (1 - hf / h_spp):.0f} % |")
    lines += ["", "### 5. The slow error as a state of the filter", "",
              "Filter core with a first-order Gauss-Markov error state per satellite "
              "(`pseudorange_correlated_std_m`, `pseudorange_correlated_tau_s`; off in the shipped defaults), "
              "horizontal / 3D RMS m (horizontal gain over SPP).", "",
              "| station | " + " | ".join(f"sigma {sd:g} m, tau {tau:g} s" for sd, tau in CORRELATED_SCAN) + " |",
              "|---|" + "---|" * len(CORRELATED_SCAN)]
    for s in stations:
        h_spp = spp_rms[s.name][0]
        cells = []
        for sd, tau in CORRELATED_SCAN:
            params = {"pseudorange_correlated_std_m": sd, "pseudorange_correlated_tau_s": tau} if sd > 0 else {}
            h, d = rms_h_3d(filter_errors(s.epochs, s.truth_ecef_m, **params))
            figures[f"gm_{s.name}_{sd:g}_{tau:g}"] = (h, d)
            cells.append(f"{h:.2f} / {d:.2f} ({100 * (1 - h / h_spp):.0f} %)")
        lines.append(f"| {s.name} | " + " | ".join(cells) + " |")
    return "\n".join(lines), figures
