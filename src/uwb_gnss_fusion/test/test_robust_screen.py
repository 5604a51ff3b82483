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


def test_two_outliers_of_one_sign_among_four_defeat_the_median_not_the_consensus():
    # the median of [0.3, -0.4, 80, 150] is 40: the median screen rejected all four
    keep = common_mode_screen(np.array([0.3, -0.4, 80.0, 150.0]), np.ones(4), GATE)
    assert keep.tolist() == [True, True, False, False]


def test_a_marginal_outlier_inside_the_consensus_does_not_pull_the_reference():
    # 25 m off, sigma 5 m: compatible pairwise with the good 5 m-sigma one (24.9^2 < 15.1 * 50), so
    # inside the first consensus, but not with the refined common mode of the 1 m-sigma majority
    nu = np.array([0.2, -0.5, 0.4, 0.1, 25.0])
    sig = np.array([1.0, 1.0, 1.0, 5.0, 5.0])
    keep = common_mode_screen(nu, sig**2, GATE)
    assert keep.tolist() == [True, True, True, True, False]


@pytest.mark.parametrize(("n_sat", "n_out"), [(4, 2), (5, 3), (6, 3), (8, 3)])
def test_several_outliers_per_epoch_monte_carlo(n_sat, n_out):
    """Oracle: known outliers (20-300 m, log-uniform, either sign, as the jamming simulator draws
    them) on n_out of n_sat satellites over a 50 m common clock innovation. Detectable outliers
    (> 6 sigma) must be caught and good satellites kept; measured (seed 5, 2,000 epochs) for
    (n_sat, n_out) = (4,2), (5,3), (6,3), (8,3): good rejected 2.7 / 8.8 / 0.3 / 0.1 %, detectable
    outliers missed 3.6 / 7.1 / 0.7 / 0.2 %. The median screen this replaced: good rejected 41 / 26
    / 21 / 0.3 %."""
    rng = np.random.default_rng(5)
    n_epochs = 2000
    good_rejected = outliers_missed = detectable = 0
    for _ in range(n_epochs):
        sig = rng.uniform(0.5, 5.0, n_sat)
        nu = rng.normal(0.0, 1.0, n_sat) * sig + rng.normal(0.0, 50.0)
        out = rng.choice(n_sat, n_out, replace=False)
        mag = 20.0 * 15.0 ** rng.random(n_out) * np.where(rng.random(n_out) < 0.5, 1.0, -1.0)
        big = np.abs(mag) > 6.0 * sig[out]
        nu[out] += mag
        keep = common_mode_screen(nu, sig**2, GATE)
        good = np.ones(n_sat, bool)
        good[out] = False
        good_rejected += int((~keep[good]).sum())
        outliers_missed += int(keep[out][big].sum())
        detectable += int(big.sum())
    # bounds: the measured rates above plus a margin for last-bit differences between CPUs that may
    # flip a decision at the gate (the median screen fails the first three bounds by 3x or more)
    bound_good = {(4, 2): 0.033, (5, 3): 0.090, (6, 3): 0.010, (8, 3): 0.0015}[(n_sat, n_out)]
    bound_missed = {(4, 2): 0.042, (5, 3): 0.072, (6, 3): 0.010, (8, 3): 0.0015}[(n_sat, n_out)]
    assert good_rejected / (n_epochs * (n_sat - n_out)) <= bound_good
    assert outliers_missed / detectable <= bound_missed
