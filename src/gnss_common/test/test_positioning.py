"""Oracle tests of gnss_common.positioning: least-squares position on known geometries."""

from __future__ import annotations

import numpy as np

from gnss_common.positioning import (
    CONVERGED,
    NOT_CONVERGED,
    SINGULAR,
    least_squares_position,
    weighted_least_squares,
)

TRUTH = np.array([-740289.918, -5457071.734, 3207245.542])
CLOCK_M = 1234.5
SATS = np.array([
    [-1.2e7, -2.0e7, 1.1e7], [1.5e7, -2.1e7, 0.5e7], [-2.0e7, -1.0e7, 1.6e7],
    [2.6e6, -1.5e7, 2.1e7], [-8.0e6, -2.4e7, -2.0e6], [5.0e6, -1.9e7, 1.7e7],
])


def _straight_line_model(sats, weights):
    def model(x):
        d = sats - x[:3]
        r = np.linalg.norm(d, axis=1)
        return r + x[3], d / r[:, None], weights
    return model


def test_recovers_a_known_position_and_clock_from_the_earth_centre():
    y = np.linalg.norm(SATS - TRUTH, axis=1) + CLOCK_M
    sol = least_squares_position(_straight_line_model(SATS, np.ones(len(SATS))), y, np.zeros(4), 12, 1e-6)
    assert sol.status == CONVERGED
    np.testing.assert_allclose(sol.x[:3], TRUTH, rtol=0.0, atol=1e-5)
    assert abs(sol.x[3] - CLOCK_M) < 1e-5
    # covariance of the last linearisation = (H^T W H)^-1 at the solution
    np.testing.assert_allclose(sol.covariance, np.linalg.inv(sol.h.T @ sol.h), rtol=1e-9)


def test_weighted_solution_equals_the_closed_form_on_a_linear_model():
    rng = np.random.default_rng(7)
    h = rng.normal(size=(8, 4))
    x_true = np.array([1.0, -2.0, 3.0, 0.5])
    w = rng.uniform(0.5, 4.0, 8)
    y = h @ x_true + rng.normal(size=8) / np.sqrt(w)
    sol, cov = weighted_least_squares(h, y, w)
    wm = np.diag(w)
    expected_cov = np.linalg.inv(h.T @ wm @ h)
    np.testing.assert_allclose(cov, expected_cov, rtol=1e-12)
    np.testing.assert_allclose(sol, expected_cov @ h.T @ wm @ y, rtol=1e-10)


def test_noise_on_one_satellite_is_down_weighted():
    y = np.linalg.norm(SATS - TRUTH, axis=1) + CLOCK_M
    y[0] += 50.0
    heavy = least_squares_position(_straight_line_model(SATS, np.ones(6)), y, np.zeros(4), 12, 1e-6)
    w = np.ones(6)
    w[0] = 1e-8
    light = least_squares_position(_straight_line_model(SATS, w), y, np.zeros(4), 12, 1e-6)
    assert np.linalg.norm(light.x[:3] - TRUTH) < 0.01 < 1.0 < np.linalg.norm(heavy.x[:3] - TRUTH)


def test_singular_geometry_and_iteration_cap_are_reported():
    sats = np.repeat(SATS[:1], 4, axis=0)
    y = np.linalg.norm(sats - TRUTH, axis=1)
    assert least_squares_position(_straight_line_model(sats, np.ones(4)), y, np.zeros(4), 12, 1e-6).status == SINGULAR
    y = np.linalg.norm(SATS - TRUTH, axis=1)
    sol = least_squares_position(_straight_line_model(SATS, np.ones(6)), y, np.zeros(4), 1, 1e-6)
    assert sol.status == NOT_CONVERGED and sol.iterations == 1
