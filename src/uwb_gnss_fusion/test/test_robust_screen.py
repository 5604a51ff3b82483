"""Common-mode innovation screen (uwb_gnss_fusion.robust_screen)."""

import math

import numpy as np
import pytest
from scipy.stats import chi2

from uwb_gnss_fusion.robust_screen import common_mode_screen, projected_variance

GATE = float(chi2.ppf(0.9999, 1))


def test_outlier_hidden_by_a_large_clock_innovation_is_found():
    # 8 satellites, 1 m noise, a 40 m common clock innovation (a crystal clock after a gap) and one
    # 25 m outlier: the per-measurement CKF gate with a 10 m clock sigma would pass it
    # (25^2 < 15.1 * (1 + 100)); the common-mode screen does not.
    rng = np.random.default_rng(1)
    nu = 40.0 + rng.normal(0.0, 1.0, 8)
    nu[3] += 25.0
    assert 25.0**2 < GATE * (1.0 + 10.0**2)
    keep = common_mode_screen(nu, np.ones(8), GATE)
    assert keep.tolist() == [True, True, True, False, True, True, True, True]


def test_a_minority_of_outliers_is_removed_together():
    rng = np.random.default_rng(2)
    nu = -300.0 + rng.normal(0.0, 2.0, 9)
    nu[[0, 5, 7]] += np.array([60.0, -150.0, 30.0])
    keep = common_mode_screen(nu, np.full(9, 4.0), GATE)
    assert np.flatnonzero(~keep).tolist() == [0, 5, 7]


def test_false_rejections_match_the_gate_probability():
    rng = np.random.default_rng(3)
    n_epochs, n_sat = 20000, 8
    sigma = rng.uniform(0.5, 5.0, (n_epochs, n_sat))
    nu = rng.normal(0.0, 1.0, (n_epochs, n_sat)) * sigma + rng.normal(0.0, 50.0, (n_epochs, 1))
    rejected = sum(int((~common_mode_screen(nu[k], sigma[k] ** 2, GATE)).sum()) for k in range(n_epochs))
    rate = rejected / (n_epochs * n_sat)
    # the statistic is close to chi-square(1) (median and var_med approximations); measured 5e-5
    # here: at most twice the nominal 1e-4
    assert rate <= 2e-4


def test_too_few_measurements_are_all_kept_and_non_finite_never():
    assert common_mode_screen(np.array([0.0, 500.0]), np.ones(2), GATE).tolist() == [True, True]
    keep = common_mode_screen(np.array([0.0, math.nan, 0.5, 1.0]), np.ones(4), GATE)
    assert keep.tolist() == [True, False, True, True]
    assert common_mode_screen(np.array([0.0, 1e3, 2.0]), np.ones(3), math.inf).all()


def test_bad_arguments_raise():
    with pytest.raises(ValueError, match="one shape"):
        common_mode_screen(np.zeros(3), np.ones(4), GATE)
    with pytest.raises(ValueError, match="> 0"):
        common_mode_screen(np.zeros(3), np.array([1.0, 0.0, 1.0]), GATE)
    with pytest.raises(ValueError, match="min_count"):
        common_mode_screen(np.zeros(3), np.ones(3), GATE, min_count=2)


def test_projected_variance_is_e_p_e():
    e = np.array([[1.0, 0.0, 0.0], [0.0, 0.6, 0.8]])
    p = np.diag([4.0, 9.0, 16.0])
    np.testing.assert_allclose(projected_variance(e, p), [4.0, 0.36 * 9.0 + 0.64 * 16.0])
