"""Initial covariance from a snapshot fix (fusion_filter._with_solution_covariance, snapshot_fix)."""

from __future__ import annotations

import numpy as np
import pytest

from uwb_gnss_fusion.fusion_filter import FusionFilter, FusionParams, _with_solution_covariance


def _fix_cov() -> np.ndarray:
    # a weak vertical (30 m) correlated with the clock, as a 5-satellite fix under jamming gives
    a = np.array([[3.0, 0.0, 0.0, 0.0], [0.0, 4.0, 0.0, 0.0], [0.0, 0.0, 30.0, 0.0], [0.0, 0.0, 25.0, 8.0]])
    return a @ a.T


def test_weak_directions_kept_strong_ones_floored_and_result_dominates_the_fix():
    cov0 = np.diag([100.0] * 3 + [1.0] * 3 + [100.0, 1.0])
    out = _with_solution_covariance(cov0, _fix_cov(), clock_ok=True)
    assert np.allclose(out, out.T)
    lam = np.linalg.eigvalsh(out[0:3, 0:3])
    assert lam.min() == pytest.approx(100.0)  # never more confident than init_position_std_m
    assert out[2, 2] == pytest.approx(900.0)  # the fix's 30 m vertical kept
    assert out[2, 6] == pytest.approx(_fix_cov()[2, 3])  # position-clock correlation kept
    # only variances were raised: out - fix (embedded) is positive semi-definite
    idx = [0, 1, 2, 6]
    assert np.linalg.eigvalsh(out[np.ix_(idx, idx)] - _fix_cov()).min() > -1e-9
    assert np.linalg.eigvalsh(out).min() > 0.0


def test_without_a_clock_no_cross_terms_and_bad_input_refused():
    cov0 = np.diag([100.0] * 3 + [1.0] * 3 + [100.0, 1.0])
    out = _with_solution_covariance(cov0, _fix_cov(), clock_ok=False)
    assert np.all(out[0:3, 6] == 0.0) and out[6, 6] == 100.0
    with pytest.raises(ValueError, match="finite"):
        _with_solution_covariance(cov0, np.full((4, 4), np.nan), clock_ok=True)
    with pytest.raises(ValueError, match="semi-definite"):
        _with_solution_covariance(cov0, -np.eye(4), clock_ok=True)


def test_initialize_with_a_fix_covariance_reports_it():
    f = FusionFilter(FusionParams())
    out = f.initialize(1_000_000_000, np.array([-740289.9, -5457071.7, 3207245.5]), clock_bias_m=10.0,
                       position_clock_covariance_m2=_fix_cov())
    assert out.initialized
    assert np.trace(out.covariance_pv[0:3, 0:3]) > 900.0  # the 30 m vertical, not 3 x 10 m^2
