"""The fusion filter on a run of the rfi_sim GNSS/UWB simulator (seeded, 30 s, no jamming)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rfi_sim.gnss_uwb import BroadcastGeometry, GnssUwbScenario, simulate
from uwb_gnss_fusion.fusion_filter import FusionFilter, FusionParams

NAV = Path(__file__).resolve().parents[2] / 'gnss_common' / 'test' / 'data' / 'arlm2000.15n'
"""ARL1 broadcast ephemeris, 2015-07-19 (the copy of the gnss_common tests)."""


def test_broadcast_geometry_run_and_fusion_filter_consume_it():
    geo = BroadcastGeometry(NAV)
    run = simulate(GnssUwbScenario(duration_s=30.0, seed=1), geo, geo.iono_alpha, geo.iono_beta)
    assert min(run.truth.satellites_tracked) >= 6
    f = FusionFilter(FusionParams(accel_psd_m2ps3=0.01))
    for m in run.messages():
        out = f.process(m)
    assert out.initialized
    assert np.linalg.norm(out.position_m - run.truth.receiver_ecef_m) < 2.0


def test_a_wrong_first_fix_is_not_started_from_when_fixes_must_agree():
    """divergence_fix_confirm_s (issue 15; a fix inside an outlier burst is wrong): the first 0.6 s of
    pseudoranges are those of a receiver 100 m away (a consistent set: the snapshot fix passes its own test).
    At once (0) the filter starts about 100 m off; with 1.0 (the default since session 7) it waits for a fix that a
    fix 1 s earlier agrees with, and no position it publishes is more than a few metres off."""
    import dataclasses

    from gnss_common.observations import GnssEpoch
    geo = BroadcastGeometry(NAV)
    run = simulate(GnssUwbScenario(duration_s=8.0, seed=1), geo, geo.iono_alpha, geo.iono_beta)
    truth = np.asarray(run.truth.receiver_ecef_m, dtype=float)
    shift = np.array([60.0, -50.0, 60.0])
    t0 = run.gnss_epochs[0].stamp_ns
    msgs = []
    for m in run.messages(anchor_ids=(), gnss=True):
        if isinstance(m, GnssEpoch) and m.stamp_ns - t0 < 600_000_000:
            obs = []
            for o in m.observations:
                sat = np.asarray(o.satellite_position_ecef_m, dtype=float)
                extra = float(np.linalg.norm(sat - truth - shift) - np.linalg.norm(sat - truth))
                obs.append(dataclasses.replace(o, pseudorange_m=o.pseudorange_m + extra))
            m = dataclasses.replace(m, observations=tuple(obs))
        msgs.append(m)

    def worst(confirm_s: float) -> tuple[float, float, int]:
        f = FusionFilter(FusionParams(use_uwb=False, accel_psd_m2ps3=0.01, divergence_fix_confirm_s=confirm_s))
        errs = []
        for m in msgs:
            out = f.process(m)
            if out.initialized:
                errs.append(float(np.linalg.norm(out.position_m - truth)))
        return max(errs), errs[-1], dict(out.rejection_counts).get("gnss_init_unconfirmed", 0)

    worst0, end0, _ = worst(0.0)
    worst1, end1, unconfirmed = worst(1.0)
    assert worst0 > 80.0 and end0 < 5.0
    assert worst1 < 10.0 and end1 < 5.0 and unconfirmed > 0


def _moving_epochs(velocity_enu_mps, dt_s: float, n: int, with_rates: bool, seed: int = 5):
    """Epochs of a receiver moving at a constant velocity under eight satellites fixed in the sky (1 m
    pseudorange noise, 0.05 m/s rate noise), and the receiver's true positions."""
    from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic, enu_to_ecef
    from gnss_common.observations import GnssEpoch, SatelliteObservation

    rx0 = np.array([-740289.918, -5457071.734, 3207245.542])
    lat, lon, _ = ecef_to_geodetic(rx0)
    rot = ecef_to_enu_rotation(lat, lon)
    vel = rot.T @ np.asarray(velocity_enu_mps, dtype=float)
    sats = []
    for az, el in [(0, 75), (60, 35), (130, 50), (200, 25), (250, 60), (310, 30), (100, 15), (170, 80)]:
        a, e = np.radians(az), np.radians(el)
        sats.append(enu_to_ecef(np.array([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)]) * 2.2e7, rx0))
    rng = np.random.default_rng(seed)
    epochs, truth = [], []
    for k in range(n):
        rx = rx0 + vel * k * dt_s
        obs = []
        for i, sp in enumerate(sats):
            los = (sp - rx) / np.linalg.norm(sp - rx)
            rho = np.linalg.norm(sp - rx) + 7.2921151467e-5 / 299792458.0 * (sp[0] * rx[1] - sp[1] * rx[0])
            rate = float(-los @ vel + 0.05 * rng.standard_normal()) if with_rates else float("nan")
            obs.append(SatelliteObservation(
                constellation=1, svid=i + 1, pseudorange_m=float(rho + 150.0 + rng.standard_normal()),
                pseudorange_rate_mps=rate, cn0_dbhz=45.0, satellite_position_ecef_m=sp.copy(),
                satellite_velocity_ecef_mps=np.zeros(3), satellite_clock_bias_m=0.0, satellite_clock_drift_mps=0.0))
        stamp = 1_000_000_000_000 + int(round(k * dt_s * 1e9))
        epochs.append(GnssEpoch(stamp_ns=stamp, gps_week=2000, gps_time_of_week_s=stamp / 1e9, observations=tuple(obs)))
        truth.append(rx)
    return epochs, truth


def _first_initialised(epochs, **params) -> int | None:
    f = FusionFilter(FusionParams(use_uwb=False, **params))
    for k, e in enumerate(epochs):
        if f.process(e).initialized:
            return k
    return None


def test_fix_confirmation_follows_a_moving_receiver_and_a_slow_one():
    """divergence_fix_confirm_s (default 1 s) on inputs a user has: a car at 25 m/s reporting at 1 Hz starts on
    its second epoch, with Dopplers (the held fix moved by its velocity) and without (30 m/s per axis allowed);
    a static receiver reporting every 30 s (RINEX files) starts on its second epoch too. Before, the 25 m between
    the fixes refused every pair, and fixes more than 10 s apart were never compared: the filter never started."""
    for with_rates in (True, False):
        epochs, _ = _moving_epochs((20.0, 15.0, 0.0), 1.0, 6, with_rates)
        assert _first_initialised(epochs) == 1
        assert _first_initialised(epochs, divergence_fix_confirm_s=0.0) == 0
    slow, _ = _moving_epochs((0.0, 0.0, 0.0), 30.0, 4, True)
    assert _first_initialised(slow) == 1
