"""Oracle tests for gnss_common.ephemeris (IS-GPS-200 broadcast orbits and clocks)."""

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gnss_common.constants import EARTH_GM_M3PS2, EARTH_ROTATION_RATE_RADPS, SPEED_OF_LIGHT_MPS
from gnss_common.ephemeris import (
    EphemerisStore,
    GpsEphemeris,
    earth_rotation_correction,
    pack_ephemerides,
    sagnac_range_correction_m,
    satellite_states,
    satellite_states_at_transmit,
)
from gnss_common.rinex import read_rinex_nav

DATA = Path(__file__).parent / "data"
ARL1_ECEF_M = np.array([-740289.918, -5457071.734, 3207245.542])


@pytest.fixture(scope="module")
def nav():
    return read_rinex_nav(DATA / "arlm2000.15n")


def _kepler_eph(e=0.0, **kw):
    base = dict(
        prn=7,
        toc_week=1854,
        toc_s=7200.0,
        af0_s=1e-4,
        af1_s_per_s=1e-11,
        af2_s_per_s2=0.0,
        iode=1,
        crs_m=0.0,
        delta_n_radps=0.0,
        m0_rad=0.4,
        cuc_rad=0.0,
        e=e,
        cus_rad=0.0,
        sqrt_a_sqrt_m=5153.6,
        toe_s=7200.0,
        cic_rad=0.0,
        omega0_rad=1.1,
        cis_rad=0.0,
        i0_rad=0.96,
        crc_m=0.0,
        omega_rad=-0.7,
        omega_dot_radps=0.0,
        idot_radps=0.0,
        week=1854,
        tgd_s=-5e-9,
    )
    base.update(kw)
    return GpsEphemeris(**base)


def _r1(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, s], [0, -s, c]])


def _r3(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])


def test_circular_orbit_at_toe_matches_rotation_matrices():
    eph = _kepler_eph()
    st = satellite_states(pack_ephemerides([eph]), 1854, 7200.0)
    a = eph.sqrt_a_sqrt_m**2
    u = eph.m0_rad + eph.omega_rad  # e = 0: nu = E = M
    big_omega = eph.omega0_rad - EARTH_ROTATION_RATE_RADPS * eph.toe_s
    expected = _r3(-big_omega) @ _r1(-eph.i0_rad) @ np.array([a * math.cos(u), a * math.sin(u), 0.0])
    np.testing.assert_allclose(st.position_ecef_m[0], expected, atol=1e-6)
    # inertial speed of a circular orbit is sqrt(mu/a); the ECEF velocity adds -w x r
    v_inertial = st.velocity_ecef_mps[0] + np.cross([0.0, 0.0, EARTH_ROTATION_RATE_RADPS], expected)
    assert np.linalg.norm(v_inertial) == pytest.approx(math.sqrt(EARTH_GM_M3PS2 / a), rel=1e-12)


def test_orbit_repeats_after_one_period_in_inertial_space():
    eph = _kepler_eph(e=0.02)
    n = math.sqrt(EARTH_GM_M3PS2 / eph.sqrt_a_sqrt_m**6)
    period = 2 * math.pi / n
    arr = pack_ephemerides([eph])
    p0 = satellite_states(arr, 1854, 7200.0).position_ecef_m[0]
    p1 = satellite_states(arr, 1854, 7200.0 + period).position_ecef_m[0]
    # same inertial point, seen from an Earth that turned by w T
    np.testing.assert_allclose(p1, _r3(EARTH_ROTATION_RATE_RADPS * period) @ p0, atol=1e-5)


def test_relativistic_term_equals_minus_two_r_dot_v_over_c2():
    eph = _kepler_eph(e=0.015)
    arr = pack_ephemerides([eph])
    for t in (7200.0, 9000.0, 12000.0, 3000.0):
        st = satellite_states(arr, 1854, t)
        r, v = st.position_ecef_m[0], st.velocity_ecef_mps[0]
        assert st.relativistic_s[0] == pytest.approx(-2.0 * r @ v / SPEED_OF_LIGHT_MPS**2, rel=1e-9)


def test_velocity_and_drift_equal_numerical_derivatives(nav):
    ephs = [e for e in nav.ephemerides if e.health == 0]
    arr = pack_ephemerides(ephs)
    for offset in (-5000.0, 0.0, 3000.0):
        t = np.array([e.toe_s for e in ephs]) + offset
        h = 0.5
        st = satellite_states(arr, 1854, t)
        plus = satellite_states(arr, 1854, t + h)
        minus = satellite_states(arr, 1854, t - h)
        num_v = (plus.position_ecef_m - minus.position_ecef_m) / (2 * h)
        assert np.max(np.abs(st.velocity_ecef_mps - num_v)) < 1.0e-3  # 1 mm/s
        num_d = (plus.clock_bias_s - minus.clock_bias_s) / (2 * h)
        assert np.max(np.abs(st.clock_drift_s_per_s - num_d)) * SPEED_OF_LIGHT_MPS < 1.0e-5
        radius = np.linalg.norm(st.position_ecef_m, axis=1)
        assert np.all((radius > 2.5e7) & (radius < 2.8e7))
        speed = np.linalg.norm(st.velocity_ecef_mps, axis=1)
        assert np.all((speed > 1.0e3) & (speed < 4.5e3))


def test_clock_model_and_tgd():
    eph = _kepler_eph(e=0.0, af2_s_per_s2=1e-18)
    arr = pack_ephemerides([eph])
    with_tgd = satellite_states(arr, 1854, 7300.0)
    without = satellite_states(arr, 1854, 7300.0, include_tgd=False)
    assert without.clock_bias_s[0] - with_tgd.clock_bias_s[0] == pytest.approx(eph.tgd_s, abs=1e-20)
    # e = 0: no relativistic term, pure polynomial
    assert without.clock_bias_s[0] == pytest.approx(1e-4 + 1e-11 * 100 + 1e-18 * 100**2, abs=1e-18)


def test_week_crossover_gives_same_state():
    eph = _kepler_eph(toe_s=604000.0, toc_s=604000.0)
    arr = pack_ephemerides([eph])
    a = satellite_states(arr, 1855, 200.0)  # next week, 1000 s after toe
    b = satellite_states(arr, 1854, 605000.0)  # same instant, unnormalised time of week
    np.testing.assert_allclose(a.position_ecef_m, b.position_ecef_m, atol=1e-6)


def test_transmit_time_fixed_point(nav):
    store = EphemerisStore(nav.ephemerides)
    ephs = [store.select(p, 1854, 600.0)[0] for p in (2, 5, 12, 20, 25)]
    arr = pack_ephemerides(ephs)
    pr = np.array([2.1e7, 2.05e7, 2.2e7, 2.3e7, 2.15e7])
    st, t_tx = satellite_states_at_transmit(arr, 1854, 600.0, pr)
    np.testing.assert_allclose(t_tx, 600.0 - pr / SPEED_OF_LIGHT_MPS - st.clock_bias_s, atol=1e-12)
    again = satellite_states(arr, 1854, t_tx)
    np.testing.assert_allclose(again.position_ecef_m, st.position_ecef_m, atol=1e-9)


def test_earth_rotation_correction():
    lat_sat = np.array([[1.5e7, -2.0e7, 1.0e7], [-2.2e7, 5.0e6, 1.4e7]])
    rot, vel, tau = earth_rotation_correction(
        lat_sat, ARL1_ECEF_M, satellite_velocity_ecef_mps=np.ones((2, 3))
    )
    np.testing.assert_allclose(np.linalg.norm(rot, axis=1), np.linalg.norm(lat_sat, axis=1), rtol=1e-15)
    np.testing.assert_allclose(rot[:, 2], lat_sat[:, 2])
    np.testing.assert_allclose(
        tau, np.linalg.norm(rot - ARL1_ECEF_M, axis=1) / SPEED_OF_LIGHT_MPS, rtol=1e-12
    )
    exact = np.linalg.norm(rot - ARL1_ECEF_M, axis=1)
    first_order = np.linalg.norm(lat_sat - ARL1_ECEF_M, axis=1) + sagnac_range_correction_m(
        lat_sat, ARL1_ECEF_M
    )
    np.testing.assert_allclose(exact, first_order, atol=5e-3)
    assert np.all(np.abs(sagnac_range_correction_m(lat_sat, ARL1_ECEF_M)) > 1.0)
    np.testing.assert_allclose(np.linalg.norm(vel, axis=1), math.sqrt(3.0))


def test_store_selection(nav):
    store = EphemerisStore(nav.ephemerides)
    e, why = store.select(2, 1854, 600.0)
    assert why == "ok"
    candidates = [x for x in nav.ephemerides if x.prn == 2]
    assert abs(e.toe_s - 600.0) == min(abs(x.toe_s - 600.0) for x in candidates)
    assert store.select(10, 1854, 600.0) == (None, "unhealthy")  # health 63 all day
    assert store.select(6, 1854, 600.0) == (None, "stale_ephemeris")  # first PRN 6 record at 20:00
    assert store.select(31, 1854, 600.0)[1] in ("ok", "no_ephemeris", "stale_ephemeris")
    assert store.select(40, 1854, 600.0) == (None, "no_ephemeris")
    tight = EphemerisStore(nav.ephemerides, max_age_s=60.0)
    assert tight.select(2, 1854, 600.0) == (None, "stale_ephemeris")
    with pytest.raises(ValueError):
        EphemerisStore(nav.ephemerides, max_age_s=-1.0)


def test_invalid_ephemeris_rejected():
    with pytest.raises(ValueError, match="eccentricity"):
        _kepler_eph(e=1.2)
    with pytest.raises(ValueError, match="not finite"):
        replace(_kepler_eph(), m0_rad=float("nan"))
    with pytest.raises(ValueError, match="PRN"):
        _kepler_eph(prn=0)
