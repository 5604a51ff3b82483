"""The local ENU frame and the base_link solution (uwb_gnss_fusion.local_frame), pure."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gnss_common.coordinates import ecef_to_enu, ecef_to_enu_rotation, ecef_to_geodetic, geodetic_to_ecef
from uwb_gnss_fusion.local_frame import LocalFrame, base_link_solution

ARL1_ECEF_M = np.array([-742080.4125, -5462031.7412, 3198339.6909])
RNG = np.random.default_rng(11)


def random_covariance(n: int, scale: float) -> np.ndarray:
    a = RNG.normal(size=(n, n)) * scale
    return a @ a.T + np.eye(n) * scale * scale * 0.1


def test_local_frame_equals_gnss_common_enu_and_rotates_velocity_and_covariance():
    frame = LocalFrame()
    assert not frame.defined
    with pytest.raises(RuntimeError):
        frame.from_ecef(ARL1_ECEF_M, np.zeros(3), np.eye(6))
    frame.set_origin_ecef(ARL1_ECEF_M)
    lat, lon, _ = ecef_to_geodetic(ARL1_ECEF_M)
    r = ecef_to_enu_rotation(lat, lon)
    p = ARL1_ECEF_M + np.array([120.0, -35.0, 48.0])
    v = np.array([1.0, -2.0, 0.5])
    cov = random_covariance(6, 0.3)
    pos, vel, cov_enu = frame.from_ecef(p, v, cov)
    np.testing.assert_allclose(pos, ecef_to_enu(p, ARL1_ECEF_M), atol=1e-9)   # the one ENU conversion
    np.testing.assert_allclose(vel, r @ v, atol=1e-12)
    big = np.zeros((6, 6))
    big[:3, :3] = big[3:, 3:] = r
    np.testing.assert_allclose(cov_enu, big @ cov @ big.T, atol=1e-12)
    np.testing.assert_allclose(frame.from_ecef(ARL1_ECEF_M, v, cov)[0], 0.0, atol=1e-9)


def test_datum_origin_is_the_geodetic_point_given():
    lat_deg, lon_deg, alt_m = 30.4, -97.7, 150.0
    frame = LocalFrame((lat_deg, lon_deg, alt_m))
    origin = geodetic_to_ecef(math.radians(lat_deg), math.radians(lon_deg), alt_m)
    np.testing.assert_allclose(frame.origin_ecef_m, origin, atol=1e-6)
    assert frame.origin_geodetic == (lat_deg, lon_deg, alt_m)
    up = origin + 10.0 * np.array([math.cos(math.radians(lat_deg)) * math.cos(math.radians(lon_deg)),
                                   math.cos(math.radians(lat_deg)) * math.sin(math.radians(lon_deg)),
                                   math.sin(math.radians(lat_deg))])
    np.testing.assert_allclose(frame.from_ecef(up, np.zeros(3), np.eye(6))[0], [0.0, 0.0, 10.0], atol=1e-6)


def test_zero_lever_arm_keeps_the_antenna_solution():
    p, v, cov = np.array([1.0, 2.0, 3.0]), np.array([0.3, -0.1, 0.0]), random_covariance(6, 0.2)
    for source in ('none', 'velocity'):
        sol = base_link_solution(7, p, v, cov, np.zeros(3), source, 1.0)   # 0.32 m/s: yaw unknown
        np.testing.assert_allclose(sol.position_m, p)
        np.testing.assert_allclose(sol.position_covariance_m2, cov[:3, :3])
        assert math.isnan(sol.yaw_rad) and sol.stamp_ns == 7


def test_unknown_yaw_spreads_the_horizontal_lever_arm_and_velocity():
    """Yaw uniform on [0, 2 pi): the variances per axis are those of a point uniform on a circle."""
    lever = np.array([0.6, -0.8, 1.5])      # horizontal length 1 m
    p, v = np.array([10.0, 20.0, 5.0]), np.array([3.0, 4.0, -0.2])
    cov = np.diag([0.01, 0.01, 0.04, 0.001, 0.001, 0.002])
    sol = base_link_solution(0, p, v, cov, lever, 'none', 0.5)
    np.testing.assert_allclose(sol.position_m, [10.0, 20.0, 3.5])        # vertical lever arm applied
    np.testing.assert_allclose(np.diag(sol.position_covariance_m2), [0.51, 0.51, 0.04])
    np.testing.assert_allclose(sol.velocity_body_mps, [0.0, 0.0, -0.2])
    np.testing.assert_allclose(np.diag(sol.velocity_covariance_m2ps2), [(25.0 + 0.002) / 2, (25.0 + 0.002) / 2, 0.002])
    # Monte Carlo of the same statement
    yaw = RNG.uniform(0.0, 2.0 * math.pi, 200_000)
    base_e = p[0] - (np.cos(yaw) * lever[0] - np.sin(yaw) * lever[1])
    fwd = np.cos(yaw) * v[0] + np.sin(yaw) * v[1]
    assert np.var(base_e) == pytest.approx(0.5, rel=0.02) and np.var(fwd) == pytest.approx(12.5, rel=0.02)


def test_velocity_heading_rotates_lever_arm_and_velocity_into_base_link():
    lever = np.array([0.5, 0.2, 1.0])
    yaw = math.radians(30.0)
    v = np.array([2.0 * math.cos(yaw), 2.0 * math.sin(yaw), 0.1])
    p = np.array([0.0, 0.0, 0.0])
    cov = np.diag([0.01, 0.01, 0.02, 0.0004, 0.0004, 0.001])
    sol = base_link_solution(0, p, v, cov, lever, 'velocity', 0.5)
    assert sol.yaw_rad == pytest.approx(yaw)
    c, s = math.cos(yaw), math.sin(yaw)
    np.testing.assert_allclose(sol.position_m, [-(c * 0.5 - s * 0.2), -(s * 0.5 + c * 0.2), -1.0], atol=1e-12)
    np.testing.assert_allclose(sol.velocity_body_mps, [2.0, 0.0, 0.1], atol=1e-12)   # forward, no side slip
    # yaw variance: across-course velocity variance / speed^2
    assert sol.yaw_variance_rad2 == pytest.approx(0.0004 / 4.0)
    # position covariance: antenna covariance + lever-arm swing from the yaw error (numerical Jacobian)
    def base(x):
        return base_link_solution(0, x[:3], x[3:], cov, lever, 'velocity', 0.5).position_m
    x0 = np.concatenate([p, v])
    jac = np.column_stack([(base(x0 + e) - base(x0 - e)) / 2e-6 for e in np.eye(6) * 1e-6])
    np.testing.assert_allclose(sol.position_covariance_m2, jac @ cov @ jac.T, rtol=1e-5, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(sol.position_covariance_m2) > 0)
    # below the minimum speed the yaw is unknown
    slow = base_link_solution(0, p, v * 0.1, cov, lever, 'velocity', 0.5)
    assert math.isnan(slow.yaw_rad) and slow.position_covariance_m2[0, 0] > cov[0, 0]


def test_unknown_heading_source_is_refused():
    with pytest.raises(ValueError, match='heading_source'):
        base_link_solution(0, np.zeros(3), np.zeros(3), np.eye(6), np.zeros(3), 'compass', 0.5)


def _reference_base_link(p, v, cov, lever, heading_source, min_speed):
    """The base_link solution written with numpy matrices (the compiled kernel's oracle)."""
    speed = math.hypot(v[0], v[1])
    cov_p, cov_v = cov[:3, :3], cov[3:, 3:]
    if heading_source == 'velocity' and speed >= min_speed and speed > 0.0:
        yaw = math.atan2(v[1], v[0])
        c, s = math.cos(yaw), math.sin(yaw)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        g = np.array([-s * lever[0] - c * lever[1], c * lever[0] - s * lever[1], 0.0])
        h = np.array([-v[1], v[0], 0.0]) / (speed * speed)
        jac = np.hstack([np.eye(3), -np.outer(g, h)])
        return (p - rot @ lever, jac @ cov @ jac.T, rot.T @ v, rot.T @ cov_v @ rot, yaw, float(h @ cov_v @ h))
    r2 = lever[0] ** 2 + lever[1] ** 2
    pos_cov = cov_p + np.diag([r2 / 2.0, r2 / 2.0, 0.0])
    horizontal = (v[0] ** 2 + v[1] ** 2 + cov_v[0, 0] + cov_v[1, 1]) / 2.0
    return (p - np.array([0.0, 0.0, lever[2]]), pos_cov, np.array([0.0, 0.0, v[2]]),
            np.diag([horizontal, horizontal, cov_v[2, 2]]), math.nan, math.nan)


@pytest.mark.parametrize('heading_source', ['none', 'velocity'])
def test_compiled_base_link_equals_the_matrix_formulas(heading_source):
    for _ in range(50):
        p, v = RNG.normal(size=3) * 100.0, RNG.normal(size=3) * 3.0
        cov, lever = random_covariance(6, 0.5), RNG.normal(size=3)
        sol = base_link_solution(3, p, v, cov, lever, heading_source, 0.5)
        ref = _reference_base_link(p, v, cov, lever, heading_source, 0.5)
        got = (sol.position_m, sol.position_covariance_m2, sol.velocity_body_mps, sol.velocity_covariance_m2ps2)
        for a, b in zip(got, ref[:4], strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose([sol.yaw_rad, sol.yaw_variance_rad2], ref[4:], rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize('heading_source', ['none', 'velocity'])
def test_frame_base_link_from_ecef_is_from_ecef_then_base_link(heading_source):
    """The node's one-call path (ECEF estimate, or one already in the local frame) equals the two steps."""
    frame = LocalFrame()
    frame.set_origin_ecef(ARL1_ECEF_M)
    lever = np.array([0.4, -0.2, 1.1])
    for _ in range(20):
        p, v, cov = ARL1_ECEF_M + RNG.normal(size=3) * 50.0, RNG.normal(size=3) * 2.0, random_covariance(6, 0.4)
        one = frame.base_link_solution(9, p, v, cov, True, tuple(lever), heading_source, 0.5)
        two = base_link_solution(9, *frame.from_ecef(p, v, cov), lever, heading_source, 0.5)
        for a, b in zip(one, two, strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
        local = frame.base_link_solution(9, p - ARL1_ECEF_M, v, cov, False, lever, heading_source, 0.5)
        same = base_link_solution(9, p - ARL1_ECEF_M, v, cov, lever, heading_source, 0.5)
        for a, b in zip(local, same, strict=True):
            np.testing.assert_array_equal(a, b)
    with pytest.raises(RuntimeError):
        LocalFrame().base_link_solution(0, ARL1_ECEF_M, np.zeros(3), np.eye(6), True, lever, 'none', 0.5)
    with pytest.raises(ValueError, match='heading_source'):
        frame.base_link_solution(0, ARL1_ECEF_M, np.zeros(3), np.eye(6), True, lever, 'compass', 0.5)
