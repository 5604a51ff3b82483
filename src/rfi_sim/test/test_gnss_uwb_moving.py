"""The GNSS/UWB simulator with a moving receiver: a straight line at constant velocity, pseudoranges,
rates and UWB ranges of the moving antenna, anchors left at the start, and velocity zero drawing
exactly what the static simulator draws."""

from __future__ import annotations

import math
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from gnss_common.constants import EARTH_ROTATION_RATE_RADPS, SPEED_OF_LIGHT_MPS
from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic
from gnss_common.earth_rotation import rotate_about_z
from gnss_common.spp import SinglePointPositioner
from rfi_sim.gnss_uwb import PAPER_ANCHOR_RANGES_M, BroadcastGeometry, GnssUwbScenario, simulate

DATA = Path(__file__).resolve().parents[2] / "gnss_common" / "test" / "data"
V_ENU = (6.0, -8.0, 0.5)


@pytest.fixture(scope="module")
def geometry():
    return BroadcastGeometry(DATA / "arlm2000.15n")


@pytest.fixture(scope="module")
def moving(geometry):
    return simulate(GnssUwbScenario(duration_s=30.0, seed=5, receiver_velocity_enu_mps=V_ENU), geometry)


def _enu_rotation(rx):
    lat, lon, _ = ecef_to_geodetic(np.asarray(rx, float))
    return ecef_to_enu_rotation(lat, lon)


def test_truth_is_a_straight_line_at_the_given_velocity(moving):
    tr = moving.truth
    rot = _enu_rotation(tr.receiver_ecef_m)
    np.testing.assert_allclose(rot @ tr.receiver_velocity_ecef_mps, V_ENU, atol=1e-12)
    t = (tr.gnss_stamps_ns - tr.gnss_stamps_ns[0]) * 1e-9
    np.testing.assert_allclose(tr.receiver_ecef_m_per_epoch,
                               tr.receiver_ecef_m + t[:, None] * tr.receiver_velocity_ecef_mps, atol=1e-9)
    assert np.linalg.norm(tr.receiver_ecef_m_per_epoch[-1] - tr.receiver_ecef_m) > 290.0  # 10 m/s for 29.8 s
    # the anchors stay around the start
    np.testing.assert_allclose(np.linalg.norm(tr.anchor_ecef_m - tr.receiver_ecef_m, axis=1),
                               PAPER_ANCHOR_RANGES_M, atol=1e-9)


def test_pseudoranges_and_rates_follow_the_moving_antenna(moving):
    tr = moving.truth
    res_moving, res_static, rate_moving, rate_static = [], [], [], []
    for k, ep in enumerate(moving.gnss_epochs):
        rx = tr.receiver_ecef_m_per_epoch[k]
        for o in ep.observations:
            sp = o.satellite_position_ecef_m
            rest = tr.clock_bias_m[k] - o.satellite_clock_bias_m + o.ionosphere_delay_m + o.troposphere_delay_m
            for x, out in ((rx, res_moving), (tr.receiver_ecef_m, res_static)):
                sagnac = EARTH_ROTATION_RATE_RADPS / SPEED_OF_LIGHT_MPS * (sp[0] * x[1] - sp[1] * x[0])
                rho = np.linalg.norm(sp - x) + sagnac
                out.append(o.pseudorange_m - rho - rest)
            tau = np.linalg.norm(sp - rx) / SPEED_OF_LIGHT_MPS
            ang = EARTH_ROTATION_RATE_RADPS * tau
            c, s = np.array([math.cos(ang)]), np.array([math.sin(ang)])
            p_rot = rotate_about_z(sp[None, :], c, s)[0]
            v_rot = rotate_about_z(o.satellite_velocity_ecef_mps[None, :], c, s)[0]
            e = (p_rot - rx) / np.linalg.norm(p_rot - rx)
            rest_rate = tr.clock_drift_mps[k] - o.satellite_clock_drift_mps
            rate_moving.append(o.pseudorange_rate_mps - (e @ (v_rot - tr.receiver_velocity_ecef_mps) + rest_rate))
            rate_static.append(o.pseudorange_rate_mps - (e @ v_rot + rest_rate))
    res_moving, res_static = np.array(res_moving), np.array(res_static)
    assert abs(res_moving.mean()) < 1.0 and res_moving.std() < 2.5  # the static simulator's bounds
    assert np.abs(res_static).max() > 100.0
    assert abs(np.mean(rate_moving)) < 0.05 and np.std(rate_moving) < 0.5
    assert np.sqrt(np.mean(np.square(rate_static))) > 3.0


def test_snapshot_velocity_is_the_receiver_velocity(moving):
    spp = SinglePointPositioner()
    vel = np.array([spp.process(ep).velocity_ecef_mps for ep in moving.gnss_epochs])
    rot = _enu_rotation(moving.truth.receiver_ecef_m)
    np.testing.assert_allclose(np.median(vel @ rot.T, axis=0), V_ENU, atol=0.1)


def test_uwb_ranges_follow_the_moving_tag(moving):
    tr = moving.truth
    t0 = tr.gnss_stamps_ns[0]
    err = []
    for u in moving.uwb_ranges:
        tag = tr.receiver_ecef_m + (u.stamp_ns - t0) * 1e-9 * tr.receiver_velocity_ecef_mps
        err.append(u.range_m - np.linalg.norm(u.anchor_position_m - tag))
    assert abs(np.mean(err)) < 0.005 and np.std(err) == pytest.approx(0.03, rel=0.1)
    assert max(u.range_m for u in moving.uwb_ranges) > 250.0


def test_zero_velocity_is_the_static_simulator(geometry):
    a = simulate(GnssUwbScenario(duration_s=10.0, seed=2, jsr_db=14.0), geometry)
    b = simulate(GnssUwbScenario(duration_s=10.0, seed=2, jsr_db=14.0, receiver_velocity_enu_mps=(0.0, -0.0, 0.0),
                                 anchor_origin_ecef_m=GnssUwbScenario().receiver_ecef_m), geometry)
    assert len(a.gnss_epochs) == len(b.gnss_epochs)
    for x, y in zip(a.gnss_epochs, b.gnss_epochs, strict=True):
        assert x.stamp_ns == y.stamp_ns and len(x.observations) == len(y.observations)
        for o, q in zip(x.observations, y.observations, strict=True):
            for f in fields(o):  # bit for bit (NaN fields equal as arrays with equal_nan)
                assert np.array_equal(getattr(o, f.name), getattr(q, f.name), equal_nan=True), f.name
    assert [u.range_m for u in a.uwb_ranges] == [u.range_m for u in b.uwb_ranges]
    for f in fields(a.truth):
        assert np.array_equal(getattr(a.truth, f.name), getattr(b.truth, f.name)), f.name
    assert np.all(a.truth.receiver_ecef_m_per_epoch == a.truth.receiver_ecef_m)


def test_anchor_origin_places_the_anchors(geometry):
    origin = np.array(GnssUwbScenario().receiver_ecef_m) + np.array([30.0, -20.0, 10.0])
    run = simulate(GnssUwbScenario(duration_s=1.0, anchor_origin_ecef_m=tuple(origin)), geometry)
    np.testing.assert_allclose(np.linalg.norm(run.truth.anchor_ecef_m - origin, axis=1), PAPER_ANCHOR_RANGES_M,
                               atol=1e-9)


@pytest.mark.parametrize("kw", [{"receiver_velocity_enu_mps": (1.0, 2.0)},
                                {"receiver_velocity_enu_mps": (1.0, math.nan, 0.0)},
                                {"anchor_origin_ecef_m": (1.0, 2.0)}])
def test_motion_validation(kw):
    with pytest.raises(ValueError):
        GnssUwbScenario(**kw)
