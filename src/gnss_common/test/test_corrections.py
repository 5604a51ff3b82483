"""Property and closed-form tests for gnss_common.corrections (Klobuchar, Saastamoinen)."""

import math

import numpy as np
import pytest

from gnss_common.constants import SPEED_OF_LIGHT_MPS
from gnss_common.corrections import (
    black_eisner_mapping,
    klobuchar_delay_s,
    saastamoinen_zenith_delays_m,
    standard_atmosphere,
    troposphere_delay_m,
)

# ARL1 broadcast parameters (arlm2000.15n header)
ALPHA = np.array([0.745058e-08, 0.711478e-08, -0.603921e-08, -0.384468e-08])
BETA = np.array([0.901120e05, 0.365063e05, -0.664019e04, -0.169091e05])
ZERO = np.zeros(4)


def _f_obliquity(el_rad):
    e = el_rad / math.pi
    return 1.0 + 16.0 * (0.53 - e) ** 3


def test_night_time_floor_is_five_nanoseconds_times_obliquity():
    # receiver at lon 0, lat 0: local time at the pierce point ~ GPS time of day; 02:00 is night
    for el_deg in (90.0, 45.0, 15.0):
        el = math.radians(el_deg)
        d = klobuchar_delay_s(ALPHA, BETA, 0.0, 0.0, 0.0, el, 2 * 3600.0)
        assert d == pytest.approx(5.0e-9 * _f_obliquity(el), rel=1e-12)


def test_zenith_peak_at_14h_local_equals_floor_plus_amplitude():
    lat = 0.0
    d = klobuchar_delay_s(ALPHA, BETA, lat, 0.0, 0.0, math.pi / 2, 14 * 3600.0)
    # at zenith psi = 0.0137/0.61 - 0.022 (sc), azimuth 0 moves the pierce point north
    psi = 0.0137 / 0.61 - 0.022
    phi_i = lat / math.pi + psi
    lam_i = 0.0
    phi_m = phi_i + 0.064 * math.cos((lam_i - 1.617) * math.pi)
    amp = ALPHA @ phi_m ** np.arange(4)
    t_local = (4.32e4 * lam_i + 14 * 3600.0) % 86400.0
    per = max(BETA @ phi_m ** np.arange(4), 72000.0)
    x = 2 * math.pi * (t_local - 50400.0) / per
    assert x == pytest.approx(0.0)
    assert d == pytest.approx(_f_obliquity(math.pi / 2) * (5e-9 + amp), rel=1e-12)


def test_negative_amplitude_is_clipped_to_the_floor():
    d = klobuchar_delay_s(-np.abs(ALPHA) * np.array([1, 0, 0, 0]), BETA, 0.3, 0.2, 1.0, 0.6, 50400.0)
    assert d == pytest.approx(5e-9 * _f_obliquity(0.6), rel=1e-12)


def test_minimum_period_gives_documented_day_window():
    # beta = 0 -> PER = 72000 s; the cosine term is active while |x| < 1.57
    half_width_s = 1.57 * 72000.0 / (2 * math.pi)
    alpha = np.array([1e-8, 0, 0, 0])
    inside = klobuchar_delay_s(alpha, ZERO, 0.0, 0.0, 0.0, math.pi / 2, 50400.0 + half_width_s - 1.0)
    outside = klobuchar_delay_s(alpha, ZERO, 0.0, 0.0, 0.0, math.pi / 2, 50400.0 + half_width_s + 1.0)
    f = _f_obliquity(math.pi / 2)
    assert outside == pytest.approx(5e-9 * f, rel=1e-12)
    assert inside > outside
    x = 2 * math.pi * (half_width_s - 1.0) / 72000.0
    assert inside == pytest.approx(f * (5e-9 + 1e-8 * (1 - x**2 / 2 + x**4 / 24)), rel=1e-9)


def test_slant_delay_grows_toward_the_horizon_and_is_realistic():
    el = np.radians([90.0, 60.0, 30.0, 15.0, 5.0])
    lat, lon = math.radians(30.39), math.radians(-97.73)
    d = SPEED_OF_LIGHT_MPS * klobuchar_delay_s(ALPHA, BETA, lat, lon, np.zeros(5), el, 20 * 3600.0)
    assert np.all(np.diff(d) > 0)
    assert np.all((d > 1.0) & (d < 40.0))
    assert d[0] == pytest.approx(
        SPEED_OF_LIGHT_MPS * klobuchar_delay_s(ALPHA, BETA, lat, lon, 0.0, el[0], 20 * 3600.0)
    )
    below = klobuchar_delay_s(ALPHA, BETA, lat, lon, 0.0, -0.1, 0.0)
    assert below == pytest.approx(klobuchar_delay_s(ALPHA, BETA, lat, lon, 0.0, 0.0, 0.0))


def test_klobuchar_bad_input_raises():
    with pytest.raises(ValueError):
        klobuchar_delay_s(ALPHA[:3], BETA, 0.0, 0.0, 0.0, 1.0, 0.0)
    with pytest.raises(ValueError):
        klobuchar_delay_s(np.full(4, np.nan), BETA, 0.0, 0.0, 0.0, 1.0, 0.0)
    with pytest.raises(ValueError):
        klobuchar_delay_s(ALPHA, BETA, 0.0, 0.0, np.nan, 1.0, 0.0)


def test_standard_atmosphere_sea_level_and_zenith_delays():
    p, t, e = standard_atmosphere(0.0)
    assert p == pytest.approx(1013.25)
    assert t == pytest.approx(288.16)
    assert 10.0 < e < 14.0  # 70 % humidity at 15 C: 0.7 * 17.0 hPa
    zhd, zwd = saastamoinen_zenith_delays_m(math.radians(45.0), 0.0)
    assert zhd == pytest.approx(0.0022768 * 1013.25, rel=1e-12)  # cos(90 deg) = 0
    assert 0.05 < zwd < 0.2
    high = saastamoinen_zenith_delays_m(math.radians(45.0), 2000.0)
    assert high[0] < zhd and high[0] == pytest.approx(
        0.0022768 * standard_atmosphere(2000.0)[0] / (1 - 0.00028 * 2.0), rel=1e-12
    )


def test_mapping_and_slant_troposphere():
    assert float(black_eisner_mapping(math.pi / 2)) == pytest.approx(1.001 / math.sqrt(1.002001))
    el = np.radians([90.0, 45.0, 20.0, 10.0, 5.0, 0.0])
    m = black_eisner_mapping(el)
    assert np.all(np.diff(m) > 0)
    assert m[1] == pytest.approx(1.001 / math.sqrt(0.002001 + 0.5), rel=1e-12)
    assert 9.0 < m[4] < 11.5
    d = troposphere_delay_m(math.radians(35.0), 50.0, el)
    zhd, zwd = saastamoinen_zenith_delays_m(math.radians(35.0), 50.0)
    np.testing.assert_allclose(d, (zhd + zwd) * m)
    assert 2.2 < d[0] < 2.6
    with pytest.raises(ValueError):
        standard_atmosphere(0.0, relative_humidity=1.5)
