"""Oracle tests for gnss_common.coordinates (WGS 84 closed forms and round trips)."""

import math

import numpy as np
import pytest

from gnss_common.constants import WGS84_ECCENTRICITY_SQUARED, WGS84_SEMI_MAJOR_AXIS_M
from gnss_common.coordinates import (
    azimuth_elevation,
    ecef_to_enu,
    ecef_to_enu_rotation,
    ecef_to_geodetic,
    ecef_to_geodetic_scalar,
    enu_to_ecef,
    geodetic_and_enu_covariance_scalar,
    geodetic_to_ecef,
    rotate_covariance_ecef_to_enu,
    rotate_covariance_ecef_to_enu_scalar,
)

ARL1_ECEF_M = np.array([-740289.918, -5457071.734, 3207245.542])


def test_round_trip_below_one_millimetre():
    rng = np.random.default_rng(20240917)
    n = 2000
    lat = rng.uniform(-math.pi / 2, math.pi / 2, n)
    lon = rng.uniform(-math.pi, math.pi, n)
    h = rng.uniform(-1000.0, 2.5e7, n)
    xyz = geodetic_to_ecef(lat, lon, h)
    back = ecef_to_geodetic(xyz)
    again = geodetic_to_ecef(back[:, 0], back[:, 1], back[:, 2])
    assert np.max(np.linalg.norm(again - xyz, axis=1)) < 1.0e-3
    assert np.max(np.abs(back[:, 2] - h)) < 1.0e-3
    assert np.max(np.abs(back[:, 0] - lat)) < 1.0e-10


def test_closed_form_points():
    a = WGS84_SEMI_MAJOR_AXIS_M
    b = a * math.sqrt(1.0 - WGS84_ECCENTRICITY_SQUARED)
    np.testing.assert_allclose(geodetic_to_ecef(0.0, 0.0, 0.0), [a, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(geodetic_to_ecef(math.pi / 2, 0.3, 100.0), [0.0, 0.0, b + 100.0], atol=1e-6)
    llh = ecef_to_geodetic(np.array([0.0, a + 10.0, 0.0]))
    np.testing.assert_allclose(llh, [0.0, math.pi / 2, 10.0], atol=1e-9)
    pole = ecef_to_geodetic(np.array([0.0, 0.0, -(b + 5.0)]))
    assert pole[0] == pytest.approx(-math.pi / 2, abs=1e-12)
    assert pole[2] == pytest.approx(5.0, abs=1e-6)


def test_arl1_is_in_austin():
    lat, lon, h = ecef_to_geodetic(ARL1_ECEF_M)
    assert math.degrees(lat) == pytest.approx(30.39, abs=0.05)
    assert math.degrees(lon) == pytest.approx(-97.73, abs=0.05)
    assert -100.0 < h < 400.0


def test_enu_rotation_is_orthonormal_with_up_along_normal():
    lat, lon = 0.7, -1.9
    r = ecef_to_enu_rotation(lat, lon)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(r) == pytest.approx(1.0)
    # up = normalised derivative of the ECEF point with respect to height
    d = geodetic_to_ecef(lat, lon, 1.0) - geodetic_to_ecef(lat, lon, 0.0)
    np.testing.assert_allclose(r[2], d / np.linalg.norm(d), atol=1e-9)
    # north = direction of increasing latitude
    dn = geodetic_to_ecef(lat + 1e-7, lon, 0.0) - geodetic_to_ecef(lat, lon, 0.0)
    np.testing.assert_allclose(r[1], dn / np.linalg.norm(dn), atol=1e-6)


def test_enu_round_trip_and_up_offset():
    enu = np.array([[10.0, -20.0, 30.0], [0.0, 0.0, 0.0], [1e4, 2e4, -5e3]])
    back = ecef_to_enu(enu_to_ecef(enu, ARL1_ECEF_M), ARL1_ECEF_M)
    np.testing.assert_allclose(back, enu, atol=1e-8)
    lat, lon, h = ecef_to_geodetic(ARL1_ECEF_M)
    above = geodetic_to_ecef(lat, lon, h + 123.0)
    np.testing.assert_allclose(ecef_to_enu(above, ARL1_ECEF_M), [0.0, 0.0, 123.0], atol=1e-6)


def test_azimuth_elevation_cardinal_directions():
    lat, lon, h = ecef_to_geodetic(ARL1_ECEF_M)
    zenith = geodetic_to_ecef(lat, lon, h + 2.0e7)
    az, el = azimuth_elevation(ARL1_ECEF_M, zenith)
    assert el == pytest.approx(math.pi / 2, abs=1e-9)
    east = enu_to_ecef(np.array([1000.0, 0.0, 0.0]), ARL1_ECEF_M)
    north = enu_to_ecef(np.array([0.0, 1000.0, 1000.0]), ARL1_ECEF_M)
    az_e, el_e = azimuth_elevation(ARL1_ECEF_M, east)
    az_n, el_n = azimuth_elevation(ARL1_ECEF_M, north)
    assert az_e == pytest.approx(math.pi / 2, abs=1e-12)
    assert el_e == pytest.approx(0.0, abs=1e-12)
    assert math.remainder(az_n, 2.0 * math.pi) == pytest.approx(0.0, abs=1e-12)  # north: 0 == 2 pi
    assert el_n == pytest.approx(math.pi / 4, abs=1e-12)
    both = azimuth_elevation(ARL1_ECEF_M, np.vstack([east, north]))
    np.testing.assert_allclose(both[0], [az_e, az_n], atol=1e-12)
    assert np.all((both[0] >= 0.0) & (both[0] < 2.0 * math.pi))


def test_covariance_rotation_properties():
    lat, lon = 0.5, 2.0
    r = ecef_to_enu_rotation(lat, lon)
    iso = 4.0 * np.eye(3)
    np.testing.assert_allclose(rotate_covariance_ecef_to_enu(iso, lat, lon), iso, atol=1e-12)
    up = r[2]
    vertical = 9.0 * np.outer(up, up)
    np.testing.assert_allclose(
        rotate_covariance_ecef_to_enu(vertical, lat, lon), np.diag([0.0, 0.0, 9.0]), atol=1e-12
    )
    rng = np.random.default_rng(7)
    a = rng.normal(size=(3, 3))
    cov = a @ a.T
    out = rotate_covariance_ecef_to_enu(cov, lat, lon)
    assert np.trace(out) == pytest.approx(np.trace(cov))
    np.testing.assert_allclose(out, out.T, atol=1e-12)


def test_bad_shapes_and_values_raise():
    with pytest.raises(ValueError):
        ecef_to_geodetic(np.zeros(4))
    with pytest.raises(ValueError):
        ecef_to_geodetic(np.array([np.nan, 1.0, 2.0]))
    with pytest.raises(ValueError):
        ecef_to_geodetic(np.array([1.0, 2.0, 3.0]))  # at the Earth's centre
    with pytest.raises(ValueError):
        rotate_covariance_ecef_to_enu(np.eye(4), 0.0, 0.0)


def test_scalar_geodetic_equals_vectorised_over_global_grid():
    # Global grid of seeded points: every latitude/longitude band, heights from below the geoid to GNSS orbits.
    rng = np.random.default_rng(20261122)
    lat = np.concatenate([rng.uniform(-math.pi / 2, math.pi / 2, 3000), [-math.pi / 2, 0.0, math.pi / 2]])
    lon = np.concatenate([rng.uniform(-math.pi, math.pi, 3000), [0.0, math.pi, -0.5]])
    h = np.concatenate([rng.uniform(-1000.0, 2.5e7, 3000), [0.0, 100.0, -50.0]])
    xyz = geodetic_to_ecef(lat, lon, h)
    vec = ecef_to_geodetic(xyz)
    sca = np.array([ecef_to_geodetic_scalar(*p) for p in xyz.tolist()])
    # Same algorithm on floats: only last-place rounding differs (math vs numpy transcendental functions).
    # 1e-14 rad is 6e-8 m on the ellipsoid; heights to a few ulp of a 3e7 m number.
    assert np.max(np.abs(sca[:, 0] - vec[:, 0])) < 1.0e-14
    assert np.max(np.abs(sca[:, 1] - vec[:, 1])) < 1.0e-14
    assert np.max(np.abs(sca[:, 2] - vec[:, 2])) < 1.0e-7
    back = geodetic_to_ecef(sca[:, 0], sca[:, 1], sca[:, 2])
    assert np.max(np.linalg.norm(back - xyz, axis=1)) < 1.0e-3
    assert all(isinstance(v, float) for v in ecef_to_geodetic_scalar(*xyz[0]))


def test_scalar_geodetic_rejects_like_vectorised():
    for bad in ([math.nan, 0.0, 7.0e6], [0.0, math.inf, 7.0e6], [10.0, 20.0, 30.0]):
        with pytest.raises(ValueError):
            ecef_to_geodetic(np.array(bad))
        with pytest.raises(ValueError):
            ecef_to_geodetic_scalar(*bad)


def test_scalar_covariance_rotation_equals_validated_one():
    rng = np.random.default_rng(7)
    a = rng.normal(size=(3, 3))
    cov = a @ a.T + np.eye(3)
    for lat, lon in ((0.3, -1.2), (-1.5, 3.0), (0.0, 0.0)):
        fast = rotate_covariance_ecef_to_enu_scalar(cov, lat, lon)
        np.testing.assert_allclose(fast, rotate_covariance_ecef_to_enu(cov, lat, lon), rtol=0.0, atol=1e-14)
        np.testing.assert_allclose(np.trace(fast), np.trace(cov), rtol=1e-14)


def test_geodetic_and_enu_covariance_in_one_call_equals_the_two_validated_functions():
    rng = np.random.default_rng(12)
    for _ in range(200):
        lat, lon, h = rng.uniform(-1.5, 1.5), rng.uniform(-3.1, 3.1), rng.uniform(-100.0, 2.0e4)
        xyz = geodetic_to_ecef(lat, lon, h)
        a = rng.normal(size=(6, 6))
        cov = a @ a.T
        got_lat, got_lon, got_h, got_cov = geodetic_and_enu_covariance_scalar(xyz, cov)
        ref = ecef_to_geodetic(xyz)
        assert abs(got_lat - ref[0]) < 1e-14 and abs(got_lon - ref[1]) < 1e-14 and abs(got_h - ref[2]) < 1e-7
        np.testing.assert_allclose(got_cov, rotate_covariance_ecef_to_enu(cov[:3, :3], ref[0], ref[1]),
                                   rtol=0.0, atol=1e-12)
    for bad in ([math.nan, 0.0, 7.0e6], [10.0, 20.0, 30.0]):
        with pytest.raises(ValueError):
            geodetic_and_enu_covariance_scalar(np.array(bad), np.eye(3))
