"""Oracle tests of the shared position-error metrics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic
from rfi_sim.evaluation import (
    ecef_errors_enu,
    empirical_cdf,
    error_3d_m,
    error_stats,
    horizontal_error_m,
    interpolate_truth,
    time_to_recover_s,
)

ARL1_ECEF_M = np.array([-740289.918, -5457071.734, 3207245.542])
GEONET_0759_ECEF_M = np.array([-3976219.508, 3382372.567, 3652512.985])


def _enu_to_ecef_offset(ref: np.ndarray, enu: np.ndarray) -> np.ndarray:
    lat, lon, _ = ecef_to_geodetic(ref)
    return ecef_to_enu_rotation(lat, lon).T @ enu


def test_enu_errors_recover_known_offsets() -> None:
    enu = np.array([[1.0, 2.0, 3.0], [-4.0, 0.5, -0.25]])
    truth = np.stack([ARL1_ECEF_M, GEONET_0759_ECEF_M])
    est = truth + np.stack([_enu_to_ecef_offset(r, d) for r, d in zip(truth, enu, strict=True)])
    got = ecef_errors_enu(est, truth)
    np.testing.assert_allclose(got, enu, atol=1e-8)
    np.testing.assert_allclose(horizontal_error_m(got), [math.sqrt(5.0), math.sqrt(16.25)], atol=1e-8)
    np.testing.assert_allclose(error_3d_m(got), np.linalg.norm(enu, axis=1), atol=1e-8)
    # a static truth given as (3,) broadcasts; NaN estimates give NaN rows, not a crash
    est2 = np.stack([est[0], np.full(3, np.nan)])
    got2 = ecef_errors_enu(est2, ARL1_ECEF_M)
    np.testing.assert_allclose(got2[0], enu[0], atol=1e-8)
    assert np.all(np.isnan(got2[1]))
    with pytest.raises(ValueError, match="does not match"):
        ecef_errors_enu(np.zeros((3, 3)) + ARL1_ECEF_M, truth)


def test_interpolate_truth_is_exact_on_linear_motion() -> None:
    t0 = 1_734_501_485_500_326_730
    t_truth = t0 + np.arange(0, 10) * 125_000_000
    v = np.array([1.5, -0.5, 0.1])
    truth = (t_truth - t0)[:, None] * 1e-9 * v + np.array([10.0, 20.0, 1.0])
    q = np.array([t0 - 1, t0, t0 + 333_333_333, t_truth[-1], t_truth[-1] + 1])
    got = interpolate_truth(t_truth, truth, q)
    assert np.all(np.isnan(got[0])) and np.all(np.isnan(got[-1]))
    expected = (q[1:4] - t0)[:, None] * 1e-9 * v + np.array([10.0, 20.0, 1.0])
    np.testing.assert_allclose(got[1:4], expected, atol=1e-12)
    with pytest.raises(ValueError, match="strictly increasing"):
        interpolate_truth(t_truth[::-1], truth, q)


def test_error_stats_closed_forms() -> None:
    e = np.array([3.0, 4.0, np.nan, 0.0, 12.0, np.inf])
    s = error_stats(e)
    assert s.count == 4 and s.rejected_non_finite == 2
    assert s.rms_m == pytest.approx(math.sqrt((9 + 16 + 0 + 144) / 4))
    assert s.max_m == 12.0 and s.mean_m == pytest.approx(19.0 / 4)
    # linear-interpolation percentile of sorted [0, 3, 4, 12]: position 0.95 * 3 = 2.85
    assert s.p95_m == pytest.approx(4.0 + 0.85 * (12.0 - 4.0))
    with pytest.raises(ValueError, match="no finite"):
        error_stats(np.array([np.nan]))
    with pytest.raises(ValueError, match="norms"):
        error_stats(np.array([-1.0, 2.0]))


def test_empirical_cdf() -> None:
    rng = np.random.default_rng(7)
    e = rng.rayleigh(1.0, 2000)
    x, p = empirical_cdf(np.append(e, np.nan))
    assert x.size == 2000 and np.all(np.diff(x) >= 0) and p[-1] == 1.0 and p[0] == 1.0 / 2000
    # Rayleigh(1) CDF 1 - exp(-x^2/2): Kolmogorov-Smirnov distance small for 2000 samples
    assert np.max(np.abs(p - (1.0 - np.exp(-(x**2) / 2.0)))) < 0.04


def _burst_series(tau_s: float, dt_s: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(0.0, 60.0, dt_s)
    e = np.ones_like(t)
    e[(t >= 10.0) & (t < 20.0)] = 10.0
    after = t >= 20.0
    e[after] = 1.0 + 9.0 * np.exp(-(t[after] - 20.0) / tau_s)
    return t, e


def test_time_to_recover_matches_exponential_closed_form() -> None:
    tau = 3.0
    t, e = _burst_series(tau)
    # 1 + 9 exp(-x / tau) <= 2  <=>  x >= tau ln 9; sampled every 10 ms
    got = time_to_recover_s(t, e, 10.0, 20.0, k=2.0)
    assert tau * math.log(9.0) <= got < tau * math.log(9.0) + 0.01 + 1e-9
    # k = 10 is met at the burst end already
    assert time_to_recover_s(t, e, 10.0, 20.0, k=10.0) == 0.0


def test_time_to_recover_requires_staying_within() -> None:
    t, e = _burst_series(1.0)
    e[(t >= 30.0) & (t < 30.5)] = 5.0  # relapse after a first recovery
    assert time_to_recover_s(t, e, 10.0, 20.0) == pytest.approx(30.5 - 20.0)
    # with a 2 s hold, the first recovery (before 28 s) already counts
    assert time_to_recover_s(t, e, 10.0, 20.0, hold_s=2.0) == pytest.approx(math.log(9.0), abs=0.011)
    e[t >= 50.0] = np.nan  # estimates stop: never recovered for good
    assert time_to_recover_s(t, e, 10.0, 20.0) == math.inf


def test_time_to_recover_rejects_bad_input() -> None:
    t, e = _burst_series(1.0)
    with pytest.raises(ValueError, match="pre-burst"):
        time_to_recover_s(t, e, 0.0, 5.0)
    with pytest.raises(ValueError, match="strictly increasing"):
        time_to_recover_s(t[::-1], e, 10.0, 20.0)
    with pytest.raises(ValueError, match="k must be"):
        time_to_recover_s(t, e, 10.0, 20.0, k=0.0)
    with pytest.raises(ValueError, match="burst_start_s <= burst_end_s"):
        time_to_recover_s(t, e, 20.0, 10.0)
