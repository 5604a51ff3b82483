"""Multi-constellation snapshot solution: the synthetic-sky oracle (two and three constellations with
inter-system biases), subsets, NaN and bad input, the w-test, cost, and a real multi-GNSS station hour."""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np
import pytest

from gnss_common.coordinates import ecef_to_enu
from gnss_common.measurements import build_epochs
from gnss_common.multi_gnss_fix import (
    REJECTION_REASONS,
    MultiGnssFixParams,
    solve_multi_gnss,
    subset_solution,
)
from gnss_common.observations import BEIDOU, GALILEO, GLONASS, GPS, QZSS, SBAS, GnssEpoch
from gnss_common.rinex import read_rinex_nav, read_rinex_obs
from gnss_common.spp import SppParams
from gnss_common.synthetic_sky import (
    CLOCK_BIAS_M,
    CLOCK_DRIFT_MPS,
    RECEIVER_ECEF_M,
    RECEIVER_VELOCITY_ECEF_MPS,
    SKY_AZ_EL_DEG,
    synthetic_epoch,
)

DATA = Path(__file__).resolve().parent / "data"
GAL_SKY = ((20, 50), (70, 25), (130, 65), (170, 30), (250, 40), (300, 70))
BDS_SKY = ((55, 40), (110, 15), (160, 75), (210, 28), (260, 62))
ISB = {GALILEO: 37.5, BEIDOU: -81.25}


def multi_epoch(systems=(GPS, GALILEO), noise_m=None, **kwargs) -> GnssEpoch:
    skies = {GPS: SKY_AZ_EL_DEG, GALILEO: GAL_SKY, BEIDOU: BDS_SKY}
    sky = [azel for c in systems for azel in skies[c]]
    cons = [c for c in systems for _ in skies[c]]
    svids = [k + 1 for c in systems for k in range(len(skies[c]))]
    return synthetic_epoch(sky=sky, constellations=cons, svids=svids, clock_offsets_m=ISB, noise_m=noise_m, **kwargs)


def test_two_constellations_recover_truth():
    fix = solve_multi_gnss(multi_epoch())
    assert fix.valid and fix.status == "ok"
    assert fix.clock_constellations == (GPS, GALILEO)
    assert np.linalg.norm(fix.position_ecef_m - RECEIVER_ECEF_M) < 1e-3
    assert fix.clock_bias_m(GPS) == pytest.approx(CLOCK_BIAS_M, abs=1e-3)
    assert fix.clock_bias_m(GALILEO) - fix.clock_bias_m(GPS) == pytest.approx(ISB[GALILEO], abs=1e-3)
    assert math.isnan(fix.clock_bias_m(BEIDOU))
    assert fix.velocity_valid
    np.testing.assert_allclose(fix.velocity_ecef_mps, RECEIVER_VELOCITY_ECEF_MPS, atol=1e-6)
    assert fix.clock_drift_mps == pytest.approx(CLOCK_DRIFT_MPS, abs=1e-6)
    assert fix.dof == 15 - 3 - 2 and fix.rate_dof == 15 - 4
    assert fix.sse < 1e-9 and fix.rate_sse < 1e-9
    assert np.all(np.abs(fix.residuals_m) < 1e-3) and np.all(np.abs(fix.rate_residuals_mps) < 1e-6)
    assert np.all(np.abs(fix.standardised_residuals) < 1e-3)
    assert all(n == 0 for n in fix.rejection_counts.values()) and set(fix.rejection_counts) == set(REJECTION_REASONS)
    # azimuth and elevation of the sky it was built from
    i = fix.satellites.index((GALILEO, 3))
    assert math.degrees(fix.elevations_rad[i]) == pytest.approx(65.0, abs=1e-6)
    assert math.degrees(fix.azimuths_rad[i]) == pytest.approx(130.0, abs=1e-6)
    enu = fix.enu_rotation @ fix.covariance[:3, :3] @ fix.enu_rotation.T
    np.testing.assert_allclose(enu, fix.covariance_enu_m2)


def test_three_constellations_and_warm_start():
    epoch = multi_epoch((GPS, GALILEO, BEIDOU))
    cold = solve_multi_gnss(epoch)
    warm = solve_multi_gnss(epoch, initial_position_ecef_m=cold.position_ecef_m)
    for fix in (cold, warm):
        assert np.linalg.norm(fix.position_ecef_m - RECEIVER_ECEF_M) < 1e-3
        np.testing.assert_allclose(fix.clock_biases_m - fix.clock_biases_m[0], [0.0, ISB[GALILEO], ISB[BEIDOU]],
                                   atol=1e-3)
    assert warm.iterations < cold.iterations


def test_subset_by_mask_and_by_constellation():
    rng = np.random.default_rng(1)
    epoch = multi_epoch((GPS, GALILEO, BEIDOU), noise_m=rng.normal(0.0, 1.0, 20))
    full = solve_multi_gnss(epoch)
    gal = solve_multi_gnss(epoch, constellations=(GALILEO,))
    assert gal.valid and gal.clock_constellations == (GALILEO,)
    assert gal.rejection_counts["not_selected"] == 14 and int(gal.used.sum()) == 6
    use = np.array([o.constellation != GALILEO for o in epoch.observations])
    others = solve_multi_gnss(epoch, use=use)
    assert others.clock_constellations == (GPS, BEIDOU) and others.rejection_counts["not_selected"] == 6
    # rows left out keep their geometry and get the predicted residual where their clock is solved
    out = ~others.used
    assert np.all(np.isfinite(others.elevations_rad[out])) and np.all(np.isnan(others.residuals_m[out]))
    # the linearised subsets of the full fix equal the iterated ones (sub-millimetre)
    system = full.constellation_of_row
    for fix, rows in ((gal, system == GALILEO), (others, system != GALILEO)):
        sub = subset_solution(full, full.used & rows)
        assert sub.valid and sub.clock_constellations == fix.clock_constellations
        assert np.linalg.norm(sub.position_ecef_m - fix.position_ecef_m) < 1e-3
        np.testing.assert_allclose(sub.clock_biases_m, fix.clock_biases_m, atol=1e-3)
        np.testing.assert_allclose(sub.covariance, fix.covariance, rtol=1e-4)
        assert sub.sse == pytest.approx(fix.sse, rel=1e-6) and sub.dof == fix.dof
        assert np.all(np.diag(sub.noise_covariance) < np.diag(sub.covariance))
    two = np.zeros(system.size, dtype=bool)
    two[np.flatnonzero(system == GALILEO)[:2]] = True
    assert not subset_solution(full, two).valid  # 2 rows cannot fix position and a clock


def test_nan_states_and_bad_input_are_skipped_and_counted():
    epoch = multi_epoch()
    obs = list(epoch.observations)
    obs[0] = dataclasses.replace(obs[0], satellite_position_ecef_m=np.full(3, math.nan))
    obs[3] = dataclasses.replace(obs[3], pseudorange_m=math.nan)
    obs[5] = dataclasses.replace(obs[5], satellite_clock_bias_m=math.nan)
    obs[6] = dataclasses.replace(obs[6], satellite_velocity_ecef_mps=np.zeros(2))  # malformed: no rate, still a range
    obs[10] = dataclasses.replace(obs[10], pseudorange_rate_mps=math.nan)
    obs.append(dataclasses.replace(obs[1], constellation=SBAS, svid=120))
    obs.append(dataclasses.replace(obs[2], svid=30, pseudorange_m=1.0e5))
    fix = solve_multi_gnss(dataclasses.replace(epoch, observations=tuple(obs)))
    assert fix.valid and np.linalg.norm(fix.position_ecef_m - RECEIVER_ECEF_M) < 1e-3
    c = fix.rejection_counts
    assert c["invalid_input"] == 3 and c["unsupported_constellation"] == 1 and c["non_physical"] == 1
    assert (GPS, 1) not in fix.satellites and (GPS, 7) in fix.satellites
    assert fix.velocity_valid and int(fix.rate_used.sum()) == 15 - 3 - 2
    # a duplicated satellite is ambiguous: both copies rejected
    dup = solve_multi_gnss(dataclasses.replace(epoch, observations=(*epoch.observations, epoch.observations[4])))
    assert dup.rejection_counts["duplicate_svid"] == 2
    with pytest.raises(ValueError):
        solve_multi_gnss(epoch, use=np.ones(3, dtype=bool))
    with pytest.raises(ValueError):
        solve_multi_gnss(epoch, initial_position_ecef_m=np.array([math.nan, 0.0, 0.0]))
    empty = solve_multi_gnss(GnssEpoch(1, 1854, 0.0, ()))
    assert not empty.valid and empty.status == "too_few_satellites" and np.all(np.isnan(empty.position_ecef_m))
    few = solve_multi_gnss(multi_epoch(), constellations=(QZSS,))
    assert not few.valid and few.status == "too_few_satellites"


def test_elevation_mask_and_weights():
    params = MultiGnssFixParams(weights=SppParams(elevation_mask_deg=22.0), sigma_broadcast_m=((GALILEO, 0.3),))
    fix = solve_multi_gnss(multi_epoch(), params)
    assert fix.rejection_counts["below_elevation_mask"] == 3  # GPS at 20, 15 and 12 deg
    assert np.linalg.norm(fix.position_ecef_m - RECEIVER_ECEF_M) < 1e-3
    low = ~fix.used
    assert np.all(np.degrees(fix.elevations_rad[low]) < 22.0) and np.all(np.isnan(fix.standardised_residuals[low]))
    default = solve_multi_gnss(multi_epoch())
    gal = default.constellation_of_row == GALILEO
    high = [default.satellites.index((GPS, 1)), default.satellites.index((GALILEO, 3))]
    assert np.all(fix.weights[gal & fix.used] > default.weights[gal & fix.used])  # smaller SISRE
    assert np.all(default.noise_variances_m2[high] < 1.0 / default.weights[high])
    with pytest.raises(ValueError):
        MultiGnssFixParams(sigma_broadcast_m=((GALILEO, -1.0),))
    with pytest.raises(ValueError):
        MultiGnssFixParams(constellations=())


def test_w_test_points_at_the_outlier():
    rng = np.random.default_rng(2)
    noise = rng.normal(0.0, 0.5, 20)
    noise[7] += 40.0
    fix = solve_multi_gnss(multi_epoch((GPS, GALILEO, BEIDOU), noise_m=noise))
    assert fix.satellites[int(np.nanargmax(np.abs(fix.standardised_residuals)))] == (GPS, 8)
    clean = solve_multi_gnss(multi_epoch((GPS, GALILEO, BEIDOU), noise_m=noise - np.eye(20)[7] * 40.0))
    assert fix.sse > 10.0 * clean.sse


def test_cost_per_epoch_30_satellites():
    rng = np.random.default_rng(3)
    sky = tuple((float(a), float(e)) for a, e in zip(rng.uniform(0, 360, 30), rng.uniform(12, 85, 30), strict=True))
    epoch = synthetic_epoch(sky=sky, constellations=[GPS] * 11 + [GALILEO] * 10 + [BEIDOU] * 9,
                            svids=list(range(1, 31)), clock_offsets_m=ISB, noise_m=rng.normal(0, 1, 30))
    x0 = solve_multi_gnss(epoch).position_ecef_m
    best = math.inf
    for _ in range(5):
        t = time.perf_counter()
        for _ in range(50):
            solve_multi_gnss(epoch, initial_position_ecef_m=x0)
        best = min(best, (time.perf_counter() - t) / 50)
    assert best < 3e-3  # about 0.5 ms on an idle core; bound loose for loaded CI machines


@pytest.fixture(scope="module")
def esbc_fixes():
    obs = read_rinex_obs(DATA / "ESBC00DNK_R_20201770000_01H_30S_MO.crx.gz")
    nav = read_rinex_nav(DATA / "ESBC00DNK_R_20201770000_01H_MN.rnx.gz")
    fixes, x0 = [], None
    for r in build_epochs(obs, nav):
        fix = solve_multi_gnss(r.epoch, initial_position_ecef_m=x0)
        x0 = fix.position_ecef_m if fix.valid else x0
        fixes.append(fix)
    return obs.header.approx_position_ecef_m, fixes


def test_real_multi_gnss_hour(esbc_fixes):
    truth, fixes = esbc_fixes
    assert all(f.valid and f.velocity_valid for f in fixes)
    assert all(f.clock_constellations == (GPS, GLONASS, GALILEO, BEIDOU) for f in fixes)
    enu = np.array([ecef_to_enu(f.position_ecef_m, truth) for f in fixes])
    assert math.sqrt(np.mean(np.sum(enu**2, axis=1))) < 2.5  # 1.4 m 3D RMS measured
    assert np.median([np.linalg.norm(f.velocity_ecef_mps) for f in fixes]) < 0.02  # static station
    # the weight model over-bounds this geodetic station: SSE well under its dof
    assert np.mean([f.sse / f.dof for f in fixes]) < 1.0


def test_real_common_drift(esbc_fixes):
    """One oscillator: per constellation, the mean rate residual against the one common drift is
    a few mm/s at most (measured: |mean| < 1 mm/s, max 13 mm/s over the hour)."""
    _, fixes = esbc_fixes
    for f in fixes:
        system = f.constellation_of_row
        for c in f.clock_constellations:
            rows = f.rate_used & (system == c)
            if rows.sum() >= 3:
                w = f.rate_weights[rows]
                assert abs(np.sum(w * f.rate_residuals_mps[rows]) / np.sum(w)) < 0.03
