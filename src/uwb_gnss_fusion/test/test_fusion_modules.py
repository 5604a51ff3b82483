"""Unit tests of the fusion filter's pieces: CKF covariance operations, divergence rules, re-ordering
window policy, initialisation helpers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uwb_gnss_fusion.ckf import CubatureKalmanFilter
from uwb_gnss_fusion.divergence import GatedWindow, clock_reset_variances, gnss_epoch_inconsistent, position_lost
from uwb_gnss_fusion.fusion_params import FRAME_EARTH, FRAME_MAP, FusionParams
from uwb_gnss_fusion.initialisation import initial_drift, multilaterate, uwb_init_ready
from uwb_gnss_fusion.input_admission import DuplicateFilter, admit_jammer_state
from uwb_gnss_fusion.measurement_models import constant_velocity_transition, white_acceleration_noise
from uwb_gnss_fusion.reorder_buffer import widened_window_ns

NS = 1_000_000_000


def _spd(n: int, seed: int) -> np.ndarray:
    a = np.random.default_rng(seed).normal(size=(n, n))
    return a @ a.T + n * np.eye(n)


def test_compiled_time_update_equals_the_linear_kalman_one():
    p0 = _spd(8, 1)
    phi = constant_velocity_transition(0.05)
    q = np.zeros((8, 8))
    q[0:6, 0:6] = white_acceleration_noise(0.1, 0.05)
    nominal = np.arange(8.0)
    compiled = CubatureKalmanFilter(np.zeros(8), p0)
    compiled.predict_with_nominal(nominal, phi, q)
    linear = CubatureKalmanFilter(np.arange(8.0), p0)
    linear.predict_linear(phi, q)
    np.testing.assert_allclose(nominal, linear.x, rtol=1e-14)
    np.testing.assert_allclose(compiled.p, linear.p, rtol=1e-13)
    assert not compiled.x.any()


def test_reset_block_decorrelates_and_sets_variances():
    f = CubatureKalmanFilter(np.zeros(8), _spd(8, 2))
    before = f.p.copy()
    f.reset_block(slice(6, 8), np.array([4.0, 9.0]))
    assert f.p[6, 6] == 4.0 and f.p[7, 7] == 9.0 and f.p[6, 7] == f.p[7, 6] == 0.0
    assert not f.p[6, :6].any() and not f.p[:6, 7].any()
    np.testing.assert_array_equal(f.p[:6, :6], before[:6, :6])


def test_reset_error_state_returns_the_mean_and_zeroes_it():
    f = CubatureKalmanFilter(np.arange(3.0), np.eye(3))
    np.testing.assert_array_equal(f.reset_error_state(), [0.0, 1.0, 2.0])
    np.testing.assert_array_equal(f.x, np.zeros(3))


def test_clock_reset_variance_adds_the_position_variance():
    p = np.diag([1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 5.0, 6.0])
    np.testing.assert_array_equal(clock_reset_variances(p, 10.0, 0.5), [100.0 + 6.0, 0.25])


def test_position_lost():
    p = np.eye(8)
    assert not position_lost(p, np.zeros(8), 2.0)
    p[1, 1] = 4.01
    assert position_lost(p, np.zeros(8), 2.0)
    assert position_lost(np.eye(8), np.full(8, math.nan), 2.0)


def test_gnss_epoch_inconsistent_needs_four_and_half_gated():
    assert not gnss_epoch_inconsistent(3, 0, 3)
    assert gnss_epoch_inconsistent(4, 0, 2)
    assert not gnss_epoch_inconsistent(4, 0, 1)
    assert gnss_epoch_inconsistent(3, 1, 1)


def test_gated_window_counts_over_the_last_ranges():
    w = GatedWindow(4)
    for ok in (False, False, True):
        w.push(ok)
    assert w.gated == 2 and len(w) == 3 and not w.diverged(0.5)
    assert not w.agrees(0.5)  # 2 of 3 gated
    w.push(True)
    assert w.diverged(0.5) and not w.agrees(0.5)
    w.push(True)  # the first gated range leaves the window
    assert w.gated == 1 and not w.diverged(0.5) and w.agrees(0.5)


@pytest.mark.parametrize(
    ("window", "late", "maximum", "expected"),
    [(0, 100, 1000, 150), (200, 100, 1000, None), (0, 900, 1000, 1000), (0, 1001, 1000, None), (100, 101, 1000, 152)],
)
def test_reorder_window_grows_to_one_and_a_half_times_the_lateness(window, late, maximum, expected):
    assert widened_window_ns(window, late, maximum) == expected


def test_initial_drift_prefers_given_then_remembered_then_unobserved():
    p = FusionParams()
    assert initial_drift(3.0, 7.0, p) == (3.0, p.init_clock_drift_std_mps)
    assert initial_drift(math.nan, 7.0, p) == (7.0, p.init_clock_drift_std_mps)
    assert initial_drift(math.nan, None, p) == (0.0, p.init_clock_drift_unobserved_std_mps)


def test_multilateration_finds_the_tag_and_waits_for_a_fourth_anchor():
    tag = np.array([3.0, 4.0, 1.0])
    anchors = {"a": [0.0, 0.0, 3.0], "b": [10.0, 0.0, 2.5], "c": [0.0, 10.0, 2.0], "d": [10.0, 10.0, 3.5]}
    recent = {k: (0, np.array(a), float(np.linalg.norm(tag - np.array(a))), FRAME_MAP) for k, a in anchors.items()}
    np.testing.assert_allclose(multilaterate(recent, 0, FRAME_MAP, 1.0, np.zeros(3)), tag, atol=1e-6)
    assert multilaterate(recent, 0, FRAME_EARTH, 1.0, np.zeros(3)) is None
    three = {k: v for k, v in recent.items() if k != "d"}
    assert uwb_init_ready(recent, 0, FRAME_MAP, 0, 1.0)
    assert not uwb_init_ready(three, 0, FRAME_MAP, 0, 1.0)
    assert uwb_init_ready(three, NS, FRAME_MAP, 0, 1.0)


def test_jammer_state_admission():
    known = frozenset((0, 1, 2, 3, 4))
    assert math.isnan(admit_jammer_state(0, 12.0, 0, known)[0])
    assert admit_jammer_state(2, 12.0, 0, known) == (12.0, None)
    assert admit_jammer_state(9, 12.0, 0, known) == (None, 'jammer_state_unknown_type')
    assert admit_jammer_state(2, math.nan, 0, known) == (None, 'jammer_state_nan')
    assert admit_jammer_state(2, math.inf, 0, known) == (None, 'jammer_state_nonphysical')
    assert admit_jammer_state(2, 151.0, 0, known) == (None, 'jammer_state_nonphysical')


def test_duplicate_filter_forgets_by_stamp():
    seen = DuplicateFilter()
    seen.add(('uwb', 5, 'a'), 5)
    seen.add(('gnss', 9, ''), 9)
    assert ('uwb', 5, 'a') in seen and ('uwb', 5, 'b') not in seen
    seen.forget_older_than(6)
    assert ('uwb', 5, 'a') not in seen and ('gnss', 9, '') in seen and len(seen) == 1
    seen.clear()
    assert len(seen) == 0
