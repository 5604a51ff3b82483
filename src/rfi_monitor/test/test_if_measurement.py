"""Oracle tests of the three-sample IF measurement (Kang et al., eq. 8, 10, complex counterpart)."""

import math

import numpy as np
import pytest

from rfi_monitor.if_measurement import (
    STATUS_DOMAIN,
    STATUS_NEAR_ZERO,
    STATUS_NON_FINITE,
    STATUS_OK,
    measure_complex,
    measure_if,
    measure_real,
)


@pytest.mark.parametrize("f", [0.01, 0.1832, 0.25, 0.37, 0.49])
def test_eq8_exact_for_a_real_tone(f):
    n = np.arange(500)
    x = 3.0 * np.cos(2 * np.pi * f * n + 0.4)
    z, st = measure_if(x, min_abs=1e-9)
    ok = st == STATUS_OK
    assert ok.mean() > 0.99
    np.testing.assert_allclose(z[ok], f, atol=1e-7)


def _chirp_real(f0, df, n, phase=0.3):
    k = np.arange(n)
    return np.cos(2 * np.pi * (f0 * k + 0.5 * df * k * k) + phase), f0 + df * k


def test_eq10_chirp_correction_beats_eq8():
    df = 1e12 / 38.192e6 ** 2
    x, f_true = _chirp_real(0.1832, df, 190)
    z8, s8 = measure_if(x, delta_f=df, chirp_correction=False)
    z10, s10 = measure_if(x, delta_f=df, chirp_correction=True)
    ok = (s8 == STATUS_OK) & (s10 == STATUS_OK)
    e8 = np.sqrt(np.mean((z8[ok] - f_true[1:-1][ok]) ** 2))
    e10 = np.sqrt(np.mean((z10[ok] - f_true[1:-1][ok]) ** 2))
    assert e10 < e8 / 5


def test_eq10_reduces_to_eq8_without_sweep():
    x = np.cos(2 * np.pi * 0.3 * np.arange(100))
    a, _ = measure_if(x, delta_f=0.0, chirp_correction=True)
    b, _ = measure_if(x, delta_f=0.0, chirp_correction=False)
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("f0,df", [(0.1, 0.0), (-0.3, 4e-4), (0.2, -7e-4)])
def test_complex_counterpart_exact_for_a_linear_chirp(f0, df):
    k = np.arange(300)
    x = 2.0 * np.exp(2j * np.pi * (f0 * k + 0.5 * df * k * k) + 1j)
    f_true = f0 + df * k
    z, st = measure_if(x)
    assert np.all(st == STATUS_OK)
    err = (z - f_true[1:-1] + 0.5) % 1.0 - 0.5
    assert np.max(np.abs(err)) < 1e-9


def test_guards():
    assert measure_real(1.0, 0.0, 1.0, 0.0, False, 0.0, 0.05)[1] == STATUS_NEAR_ZERO
    assert measure_real(1.0, 0.01, 1.0, 0.0, False, 0.05, 0.05)[1] == STATUS_NEAR_ZERO
    assert measure_real(2.0, 0.5, 2.0, 0.0, False, 0.0, 0.05)[1] == STATUS_DOMAIN
    z, s = measure_real(1.02, 1.0, 1.02, 0.0, False, 0.0, 0.05)   # inside the margin: clipped
    assert s == STATUS_OK and z == 0.0
    assert measure_real(math.nan, 1.0, 1.0, 0.0, False, 0.0, 0.05)[1] == STATUS_NON_FINITE
    assert measure_complex(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0)[1] == STATUS_NEAR_ZERO
    assert measure_complex(1.0, 0.0, math.inf, 0.0, 1.0, 0.0, 0.0)[1] == STATUS_NON_FINITE
    z, s = measure_real(2.0, 0.5, 2.0, 0.0, False, 0.0, 0.05)
    assert math.isnan(z)


def test_bad_arguments():
    with pytest.raises(ValueError):
        measure_if(np.zeros((3, 3)))
    with pytest.raises(ValueError):
        measure_if(np.zeros(10), min_abs=-1.0)


def test_atan2_fast_matches_libm_in_every_octant():
    from rfi_monitor.if_measurement import atan2_fast
    rng = np.random.default_rng(6)
    ang = np.r_[np.linspace(-math.pi, math.pi, 4001), rng.uniform(-math.pi, math.pi, 2000)]
    mag = 10.0 ** rng.uniform(-6, 6, ang.size)
    for y, x in zip(mag * np.sin(ang), mag * np.cos(ang), strict=True):
        ref = math.atan2(y, x)
        err = (atan2_fast(y, x) - ref + math.pi) % (2 * math.pi) - math.pi   # +-pi are the same angle
        assert abs(err) <= 1e-12
    assert atan2_fast(0.0, 1.0) == 0.0 and math.isclose(atan2_fast(1.0, 0.0), math.pi / 2, rel_tol=1e-15)
    assert math.isclose(atan2_fast(0.0, -1.0), math.pi, rel_tol=1e-15)


def test_noise_compensation_removes_the_bias_towards_fs_over_4():
    # tone at J/N 11.2 dB: eq. 8 is compressed towards 0.25 by kappa = J / (J + N); dividing the
    # ratio by kappa removes the bias away from the band edges (module docstring)
    rng = np.random.default_rng(7)
    n = 200000
    jn = 10 ** 1.12
    kappa = jn / (jn + 1.0)
    for f in (0.2, 0.3):
        x = math.sqrt(2.0) * np.cos(2 * np.pi * f * np.arange(n) + 0.3) + rng.normal(0.0, math.sqrt(1 / jn), n)
        plain = np.nanmedian(measure_if(x)[0]) - f
        comp = np.nanmedian(measure_if(x, tone_power_fraction=kappa)[0]) - f
        assert abs(plain) > 0.0025 and abs(comp) < 0.001
        assert np.sign(plain) == np.sign(0.25 - f)
    with pytest.raises(ValueError, match="tone_power_fraction"):
        measure_if(np.ones(10), tone_power_fraction=0.0)
