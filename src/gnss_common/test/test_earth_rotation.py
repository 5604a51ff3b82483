"""Oracle tests of gnss_common.earth_rotation: the Sagnac correction against the closed-form rotation."""

from __future__ import annotations

import math

import numpy as np

from gnss_common.constants import EARTH_ROTATION_RATE_RADPS, SPEED_OF_LIGHT_MPS
from gnss_common.earth_rotation import (
    flight_rotation,
    rotate_about_z,
    sagnac_range_correction_m,
    sagnac_range_rate_correction_mps,
    sagnac_rotate,
)

RX = np.array([-740289.918, -5457071.734, 3207245.542])
SATS = np.array([[-1.2e7, -2.0e7, 1.1e7], [1.5e7, -2.1e7, 0.5e7], [-2.0e7, -1.0e7, 1.6e7], [2.6e6, -1.5e7, 2.1e7]])


def _r3(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def test_rotation_equals_the_closed_form_rotation_by_omega_tau():
    for iterations in (1, 2, 3):
        rotated, c, s, tau = sagnac_rotate(SATS, RX, iterations)
        for i, sat in enumerate(SATS):
            t = np.linalg.norm(sat - RX) / SPEED_OF_LIGHT_MPS
            for _ in range(iterations - 1):
                t = np.linalg.norm(_r3(EARTH_ROTATION_RATE_RADPS * t) @ sat - RX) / SPEED_OF_LIGHT_MPS
            expected = _r3(EARTH_ROTATION_RATE_RADPS * t) @ sat
            np.testing.assert_allclose(rotated[i], expected, rtol=0.0, atol=1e-7)
            assert abs(c[i] - math.cos(EARTH_ROTATION_RATE_RADPS * t)) < 1e-15
            assert abs(s[i] - math.sin(EARTH_ROTATION_RATE_RADPS * t)) < 1e-15
            assert abs(tau[i] - np.linalg.norm(rotated[i] - RX) / SPEED_OF_LIGHT_MPS) < 1e-15


def test_flight_rotation_is_the_angle_of_omega_tau_on_any_shape():
    """The angle a light-time iteration of its own (rfi_sim's moving satellites) takes from here: R3 of
    omega_e tau, over a 75 ms flight about 5.5e-6 rad."""
    tau = np.array([[0.067, 0.075], [0.086, 0.0]])
    c, s = flight_rotation(tau)
    assert c.shape == s.shape == tau.shape
    for t, ci, si in zip(tau.ravel(), c.ravel(), s.ravel(), strict=True):
        assert abs(ci - math.cos(EARTH_ROTATION_RATE_RADPS * t)) < 1e-16
        assert abs(si - math.sin(EARTH_ROTATION_RATE_RADPS * t)) < 1e-16
    assert abs(s[0, 1] - 5.469e-6) < 1e-9
    np.testing.assert_allclose(rotate_about_z(SATS[:1], *flight_rotation(np.array([0.075]))),
                               (_r3(EARTH_ROTATION_RATE_RADPS * 0.075) @ SATS[0])[None, :], rtol=0.0, atol=1e-7)


def test_rotation_keeps_norm_and_z_and_converges():
    one, _, _, _ = sagnac_rotate(SATS, RX, 1)
    two, _, _, _ = sagnac_rotate(SATS, RX, 2)
    three, _, _, _ = sagnac_rotate(SATS, RX, 3)
    np.testing.assert_allclose(np.linalg.norm(one, axis=1), np.linalg.norm(SATS, axis=1), rtol=1e-15)
    np.testing.assert_array_equal(one[:, 2], SATS[:, 2])
    assert np.max(np.abs(one - SATS)) > 1.0                 # tens of metres: not negligible
    assert np.max(np.abs(two - one)) < 1e-3                 # the second iteration moves < 1 mm
    assert np.max(np.abs(three - two)) < 1e-6               # and the third < 1 um


def test_rotate_about_z_is_r3():
    rng = np.random.default_rng(3)
    v = rng.normal(size=(5, 3))
    a = rng.uniform(-1.0, 1.0, 5)
    out = rotate_about_z(v, np.cos(a), np.sin(a))
    for i in range(5):
        np.testing.assert_allclose(out[i], _r3(a[i]) @ v[i], atol=1e-15)


def test_first_order_range_term_matches_the_rotation():
    exact = np.linalg.norm(sagnac_rotate(SATS, RX, 3)[0] - RX, axis=1)
    first_order = np.linalg.norm(SATS - RX, axis=1) + sagnac_range_correction_m(SATS, RX)
    np.testing.assert_allclose(first_order, exact, rtol=0.0, atol=1e-3)
    assert np.all(np.abs(sagnac_range_correction_m(SATS, RX)) > 1.0)


def test_first_order_terms_broadcast_over_receiver_states():
    rx = RX + np.array([[0.0, 0.0, 0.0], [10.0, -3.0, 2.0]])
    batch = sagnac_range_correction_m(SATS[None, :, :], rx[:, None, :])
    assert batch.shape == (2, 4)
    for j in range(2):
        np.testing.assert_array_equal(batch[j], sagnac_range_correction_m(SATS, rx[j]))


def test_range_rate_term_is_the_time_derivative_of_the_range_term():
    vs = np.array([[1200.0, -2500.0, 800.0], [-3000.0, 100.0, 1500.0], [500.0, 2800.0, -900.0], [0.0, 0.0, 3000.0]])
    vr = np.array([3.0, -4.0, 1.0])
    dt = 1e-3
    numeric = (sagnac_range_correction_m(SATS + vs * dt, RX + vr * dt)
               - sagnac_range_correction_m(SATS - vs * dt, RX - vr * dt)) / (2 * dt)
    np.testing.assert_allclose(sagnac_range_rate_correction_mps(SATS, vs, RX, vr), numeric, rtol=1e-6, atol=1e-12)
