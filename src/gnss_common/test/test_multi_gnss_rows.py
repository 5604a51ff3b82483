"""Oracle tests of the compiled row kernels of ``gnss_common.multi_gnss_rows``: each equals the numpy
expression its docstring quotes, on random inputs with NaN and out-of-range rows."""

import math

import numpy as np
import pytest

from gnss_common import multi_gnss_rows as rows
from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_enu_rotation_scalar
from gnss_common.spp import SppParams, cn0_factor, code_noise_variance_m2, code_variance_m2

RNG_SEED = 20261207


@pytest.fixture
def rng():
    return np.random.default_rng(RNG_SEED)


def test_screen_flags_match_the_numpy_screen(rng):
    n = 40
    s = np.column_stack([rng.uniform(5e6, 6e7, n), rng.uniform(-4e6, 4e6, n), rng.uniform(-10, 250, n),
                         rng.uniform(-10, 120, n), rng.uniform(-2e5, 2e5, n), rng.normal(0, 1, n)])
    pos = rng.normal(0, 1, (n, 3)) * rng.uniform(1e7, 6e7, (n, 1)) / math.sqrt(3)
    vel = rng.normal(0, 3e3, (n, 3))
    for arr, col in ((s, 0), (s, 4), (pos, 1), (vel, 2)):
        arr[rng.integers(0, n, 4), col] = np.nan
    finite, physical, rate_ok = rows.screen_flags(s, pos, vel)
    want_finite = np.isfinite(s[:, :4]).all(axis=1) & np.isfinite(pos).all(axis=1)
    r = np.sqrt(np.sum(pos * pos, axis=1))
    with np.errstate(invalid='ignore'):
        want_physical = ((s[:, 0] >= 1e7) & (s[:, 0] <= 5e7) & (r >= 2e7) & (r <= 5e7) & (np.abs(s[:, 1]) < 3e6)
                         & (s[:, 2] >= 0) & (s[:, 2] <= 200) & (s[:, 3] >= 0) & (s[:, 3] <= 100))
        want_rate = (np.isfinite(s[:, 4]) & np.isfinite(s[:, 5]) & np.isfinite(vel).all(axis=1)
                     & (np.abs(s[:, 4]) < 1e5))
    np.testing.assert_array_equal(finite, want_finite)
    np.testing.assert_array_equal(physical, want_physical)
    np.testing.assert_array_equal(rate_ok, want_rate)
    assert want_physical.any() and not want_physical.all() and not want_rate.all()


def test_rotations_match_the_numpy_forms(rng):
    sat = rng.normal(0, 1.5e7, (12, 3))
    pos = np.array([4.0e6, 1.0e6, 4.8e6])
    rotated, c, s = rows.sagnac_rotate(sat, pos)
    ang = 7.2921151467e-5 * (np.sqrt(np.sum((sat - pos) ** 2, axis=1)) / 299792458.0)
    np.testing.assert_allclose(c, np.cos(ang), rtol=0, atol=1e-15)
    np.testing.assert_allclose(s, np.sin(ang), rtol=1e-14)
    want = np.column_stack([c * sat[:, 0] + s * sat[:, 1], -s * sat[:, 0] + c * sat[:, 1], sat[:, 2]]) - pos
    np.testing.assert_array_equal(rotated, want)
    for lat, lon in ((0.5, 0.5), (-1.2, 2.9), (0.0, -3.0)):
        np.testing.assert_allclose(ecef_to_enu_rotation_scalar(lat, lon), ecef_to_enu_rotation(lat, lon),
                                   rtol=0, atol=1e-15)


def test_row_variances_equal_the_weight_model(rng):
    params = SppParams()
    n = 30
    sin_el = rng.uniform(-0.1, 1.0, n)
    cn0 = rng.uniform(20, 50, n)
    cn0[:3] = np.nan
    iono = rng.uniform(0, 20, n)
    sisre = rng.uniform(0.3, 3, n)
    stated = np.full(n, np.nan)
    stated[5:8] = [1.5, 2.0, 0.7]
    k = cn0_factor(params, cn0)
    got = rows.row_variances(sin_el, k, iono, sisre, stated**2, params.sigma_code_a_m**2, params.sigma_code_b_m,
                             params.iono_error_fraction, params.sigma_tropo_zenith_m, False)
    want = code_variance_m2(params, sin_el, cn0, iono, sisre)
    want[5:8] = stated[5:8] ** 2
    np.testing.assert_allclose(got, want, rtol=1e-14)
    white = rows.row_variances(sin_el, k, iono, sisre, np.full(n, np.nan), params.sigma_code_a_m**2,
                               params.sigma_code_b_m, params.iono_error_fraction, params.sigma_tropo_zenith_m, True)
    np.testing.assert_allclose(white, code_noise_variance_m2(params, sin_el, cn0), rtol=1e-14)


def test_design_normal_rows_and_residuals(rng):
    n, k = 10, 2
    los = rng.normal(0, 1, (n, 3))
    clock = rng.integers(-1, k, n)
    clock[:2] = [0, 1]
    h = rows.design(los, clock, k)
    want = np.zeros((n, 3 + k))
    want[:, :3] = -los
    for i, c in enumerate(clock):
        if c >= 0:
            want[i, 3 + c] = 1.0
    np.testing.assert_array_equal(h, want)
    idx = np.flatnonzero(clock >= 0)
    var, rng_m, y = rng.uniform(1, 9, n), rng.uniform(2e7, 2.5e7, n), rng.uniform(2e7, 2.5e7, n)
    x = np.array([1.0, 2.0, 3.0, 150.0, -40.0])
    hh, w, r = rows.normal_rows(var, los, rng_m, y, x, clock, idx)
    np.testing.assert_array_equal(hh, want[idx])
    np.testing.assert_array_equal(w, 1.0 / var[idx])
    np.testing.assert_array_equal(r, y[idx] - (rng_m[idx] + want[idx, 3:] @ x[3:]))
    res = rows.residuals(y, rng_m, x, clock)
    np.testing.assert_array_equal(res[idx], (y[idx] - rng_m[idx]) - x[3 + clock[idx]])
    assert np.isnan(res[clock < 0]).all()


def test_screened_and_rate_variances(rng):
    n = 9
    s = rng.normal(0, 1, (n, 9))
    s[2, 7] = np.nan
    s[3, 7] = -1.0
    rate_ok = rng.integers(0, 2, n).astype(bool)
    idx = np.array([0, 2, 3, 5, 8])
    y, rate, stated2 = rows.screened(s, idx, rate_ok)
    np.testing.assert_array_equal(y, s[idx, 0] + s[idx, 1] - s[idx, 2] - s[idx, 3])
    np.testing.assert_array_equal(rate, np.where(rate_ok[idx], s[idx, 4] + s[idx, 5], np.nan))
    sd = s[idx, 7]
    with np.errstate(invalid='ignore'):
        np.testing.assert_array_equal(stated2, np.where(np.isfinite(sd) & (sd > 0), sd**2, np.nan))
    k = rng.uniform(1, 10, n)
    sin_el = rng.uniform(0.01, 1, n)
    std = rng.uniform(0.05, 0.5, n)
    std[[1, 4]] = [np.nan, 0.0]
    scales, var = rows.rate_variances(k, sin_el, std, 0.1)
    want_scales = np.sqrt(k) / np.maximum(sin_el, 0.05)
    np.testing.assert_allclose(scales, want_scales, rtol=1e-15)
    np.testing.assert_allclose(var, np.where(np.isfinite(std) & (std > 0), std, 0.1 * want_scales) ** 2, rtol=1e-15)
