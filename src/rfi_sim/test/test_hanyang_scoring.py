"""hanyang_authors_rmse on hand-made paths: window, tag height, |z| filter, interpolation."""

from __future__ import annotations

import numpy as np
import pytest

from rfi_sim.evaluation import HanyangWindowRule, hanyang_authors_rmse

RULE = HanyangWindowRule(start_x_gt_m=1.5, end_x_gt_m=7.5)


def _truth() -> np.ndarray:
    t = np.arange(11) * 1e9  # 1 s steps, x = 0..10 m, y = 0, z = 0
    return np.column_stack([t, np.arange(11.0), np.zeros(11), np.zeros(11)])


def test_window_height_and_interpolation():
    truth = _truth()
    # solution every 0.5 s over the whole run, 0.3 m north of the path and 1 m up (the tag height)
    ts = np.arange(21) * 0.5e9
    xyz = np.column_stack([ts / 1e9, np.full(21, 0.3), np.ones(21)])
    r3, r2, n = hanyang_authors_rmse(truth, ts, xyz, RULE)
    assert n == 13  # stamps 2.0 .. 8.0 s: the window opens at x = 2 and closes at x = 8
    assert r2 == pytest.approx(0.3, abs=1e-12)
    assert r3 == pytest.approx(0.3, abs=1e-12)  # z = truth z + 1 m is no error


def test_truth_rows_with_large_z_are_skipped():
    truth = _truth()
    truth[4, 3] = 3.0  # an RTK height outlier at t = 4 s is left out, not interpolated through
    ts = np.array([4.0e9])
    r3, r2, _ = hanyang_authors_rmse(truth, ts, np.array([[4.0, 0.0, 1.0]]), RULE)
    assert r3 == pytest.approx(0.0, abs=1e-12) and r2 == pytest.approx(0.0, abs=1e-12)


def test_window_that_never_opens_is_an_error():
    with pytest.raises(ValueError, match="never starts"):
        hanyang_authors_rmse(_truth(), np.array([1e9]), np.zeros((1, 3)), HanyangWindowRule(start_x_gt_m=50.0))
    with pytest.raises(ValueError, match="never ends"):
        hanyang_authors_rmse(_truth(), np.array([1e9]), np.zeros((1, 3)), HanyangWindowRule(start_x_gt_m=1.0,
                                                                                          end_x_gt_m=50.0))
