"""Oracle tests of ``uwb_range_rate``: the Doppler velocity against the UWB ranges' rates.

A tag near ARL1 (ECEF), three anchors around it, ranges at 20 Hz per anchor with 3 cm noise, a GNSS
velocity at 5 Hz with 3 cm/s noise and the fix's prior covariance (0.1 m/s per axis): clean static
and turning tags pass; a 1 m/s push in the velocity (a careful spoofer) is an ALARM within a second;
a non-line-of-sight jump leaves its anchor out; missing inputs are UNKNOWN.
"""

import math

import numpy as np
import pytest

from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic_scalar
from gnss_integrity.kinematics_test import AnchorRange
from gnss_integrity.outcome import DECISION_ALARM, DECISION_PASS, DECISION_UNKNOWN
from gnss_integrity.uwb_range_rate import UwbRangeRateParams, UwbRangeRateTest

BASE = np.array([-740289.9, -5457071.7, 3207245.6])  # ARL1, m
LAT, LON, _ = ecef_to_geodetic_scalar(*BASE)
ENU_TO_ECEF = ecef_to_enu_rotation(LAT, LON).T
ANCHORS_ENU = {'a0': np.array([12.0, 0.0, 1.5]), 'a1': np.array([-6.0, 10.0, 0.5]), 'a2': np.array([-6.0, -10.0, 2.0])}
NS = 1_000_000_000
PRIOR_COV = np.eye(3) * 0.1**2


def ecef(enu):
    return BASE + ENU_TO_ECEF @ enu


def run(trajectory, duration_s, *, push_enu_mps=np.zeros(3), push_from_s=math.inf, anchors=ANCHORS_ENU,
        seed=1, jump=None, test=None):
    """Feed the test; ``trajectory(t) -> (position ENU, velocity ENU)``. Returns [(t s, outcome)]."""
    rng = np.random.default_rng(seed)
    test = test or UwbRangeRateTest()
    out = []
    uwb_dt, gnss_dt = 0.05, 0.2
    n = int(round(duration_s / uwb_dt))
    for i in range(n + 1):
        t = i * uwb_dt
        pos, vel = trajectory(t)
        for j, (name, a) in enumerate(anchors.items()):
            tj = t + j * uwb_dt / len(anchors)
            p_j, _ = trajectory(tj)
            r = float(np.linalg.norm(p_j - a)) + 0.03 * rng.standard_normal()
            if jump is not None and name == jump[0] and tj >= jump[1]:
                r += jump[2]
            test.add_range(AnchorRange(int(round(tj * NS)), name, ecef(a), r))
        if i % int(round(gnss_dt / uwb_dt)) == 0:
            pushed = push_enu_mps if t >= push_from_s else np.zeros(3)
            offset = push_enu_mps * max(0.0, t - push_from_s)
            v = vel + pushed + 0.03 * rng.standard_normal(3)
            p = pos + offset + rng.standard_normal(3)
            out.append((t, test.update(int(round(t * NS)), ecef(p), ENU_TO_ECEF @ v, PRIOR_COV)))
    return out


def static(t):
    return np.array([1.0, 2.0, 1.0]), np.zeros(3)


def turning(t):
    """A robot on a 6 m circle at 1.5 m/s (0.375 m/s^2 centripetal), nodding 0.3 m in height."""
    w = 1.5 / 6.0
    pos = np.array([6.0 * math.cos(w * t), 6.0 * math.sin(w * t), 1.0 + 0.3 * math.sin(0.5 * t)])
    vel = np.array([-6.0 * w * math.sin(w * t), 6.0 * w * math.cos(w * t), 0.15 * math.cos(0.5 * t)])
    return pos, vel


def decisions(out, after_s=0.0):
    return [o.decision for t, o in out if t >= after_s]


@pytest.mark.parametrize('trajectory', [static, turning])
def test_clean_tags_pass(trajectory):
    out = run(trajectory, 120.0)
    tested = [d for d in decisions(out) if d != DECISION_UNKNOWN]
    assert len(tested) > 550  # every epoch after the first window
    assert all(d == DECISION_PASS for d in tested)
    assert out[0][1].decision == DECISION_UNKNOWN  # no window of velocities yet


@pytest.mark.parametrize('trajectory', [static, turning])
def test_a_1_mps_push_is_an_alarm_within_a_second(trajectory):
    out = run(trajectory, 90.0, push_enu_mps=np.array([1.0, 0.0, 0.0]), push_from_s=60.0)
    before = [o.decision for t, o in out if 1.0 <= t < 60.0]
    assert before and all(d == DECISION_PASS for d in before)
    first_alarm = min(t for t, o in out if o.decision == DECISION_ALARM)
    assert 60.0 <= first_alarm <= 61.0
    # the evidence stays: the statistic's median above the alarm threshold, never two PASS in a row
    late = [o for t, o in out if t >= 61.0]
    assert np.median([o.statistic for o in late]) > late[0].alarm_threshold
    assert not any(a.decision == b.decision == DECISION_PASS for a, b in zip(late, late[1:], strict=False))


def test_one_anchor_sees_a_push_along_its_line_of_sight_only():
    along = {'a0': ANCHORS_ENU['a0']}  # east of the tag: an east push changes its range
    out = run(static, 80.0, push_enu_mps=np.array([1.0, 0.0, 0.0]), push_from_s=60.0, anchors=along)
    assert any(o.decision == DECISION_ALARM for t, o in out if 60.0 <= t <= 61.0)
    # north of the tag: the blind spot, until the dragged GNSS position turns the line of sight
    # (one anchor: no multilateration, the line of sight comes from GNSS)
    across = {'a0': np.array([1.0, 14.0, 1.0])}
    out = run(static, 80.0, push_enu_mps=np.array([1.0, 0.0, 0.0]), push_from_s=60.0, anchors=across)
    assert all(o.decision == DECISION_PASS for t, o in out if 60.0 <= t <= 62.0)


def test_a_non_line_of_sight_jump_leaves_its_anchor_out():
    test = UwbRangeRateTest()
    out = run(static, 60.0, jump=('a1', 30.0, 1.5), test=test)
    assert test.counts['anchors_unfit'] > 0
    assert all(d in (DECISION_PASS, DECISION_UNKNOWN) for d in decisions(out))


def test_unknown_without_inputs():
    test = UwbRangeRateTest()
    pos = ecef(np.zeros(3))
    assert test.update(NS, pos, None, None).decision == DECISION_UNKNOWN  # no velocity
    for k in range(10):  # velocities but no anchor
        o = test.update(NS + k * NS // 5, pos, np.zeros(3), None)
    assert o.decision == DECISION_UNKNOWN and math.isnan(o.statistic)
    assert test.update(3 * NS, np.full(3, np.nan), np.zeros(3), None).decision == DECISION_UNKNOWN


@pytest.mark.parametrize('field,value', [('window_s', 0.0), ('min_ranges', 2), ('uwb_std_m', math.nan),
                                         ('alarm_false_alarm_probability', 1e-3), ('scale_history', 5)])
def test_bad_parameters_are_refused(field, value):
    with pytest.raises(ValueError, match=field if field != 'alarm_false_alarm_probability' else 'alarm'):
        UwbRangeRateParams(**{field: value})


def test_the_line_fit_and_the_predicted_rates_equal_their_numpy_forms():
    from gnss_integrity.uwb_range_rate import line_fit, predicted_rates
    rng = np.random.default_rng(5)
    t_ns = rng.permutation(np.arange(40, dtype=np.int64) * 50_000_000)  # a ring: any order
    r = 10.0 + 0.7 * t_ns / 1e9 + 0.03 * rng.standard_normal(40)
    s = np.full(40, 0.05)
    start, now = 300_000_000, 1_500_000_000
    sel = (t_ns >= start) & (t_ns <= now)
    tau = (t_ns[sel] - now) / 1e9
    slope, intercept = np.polyfit(tau, r[sel], 1)
    n, b, var, line0, tau0, tau1, rms, sig = line_fit(t_ns, r, s, start, now)
    assert n == sel.sum() and b == pytest.approx(slope, rel=1e-10) and line0 == pytest.approx(intercept, rel=1e-12)
    assert var == pytest.approx(0.05**2 / np.sum((tau - tau.mean()) ** 2), rel=1e-12)
    assert (tau0, tau1) == (tau.min(), tau.max()) and sig == pytest.approx(0.05)
    assert rms == pytest.approx(np.sqrt(np.mean((r[sel] - (slope * tau + intercept)) ** 2)), rel=1e-8)
    # a straight walk past an anchor: the mean range rate over a span is the range change over it
    ts = np.linspace(-1.0, 0.0, 6)
    v = np.array([1.2, -0.4, 0.1])
    tag = np.array([3.0, 4.0, 1.0])
    anchors = np.array([[0.0, 0.0, 0.0], [10.0, -2.0, 3.0]])
    pred, u, dist, s_v, speed = predicted_rates(ts, np.tile(v, (6, 1)), np.tile(np.eye(3) * 0.01, (6, 1, 1)),
                                                tag, anchors, np.array([-0.9, -0.8]), np.array([-0.1, 0.0]), -1.0)
    for j, (t0, t1) in enumerate(((-0.9, -0.1), (-0.8, 0.0))):
        r0, r1 = (np.linalg.norm(tag + v * t - anchors[j]) for t in (t0, t1))
        assert pred[j] == pytest.approx((r1 - r0) / (t1 - t0), rel=1e-3)  # trapezoids of a smooth rate
    np.testing.assert_allclose(dist, np.linalg.norm(tag - anchors, axis=1))
    np.testing.assert_allclose(u, (tag - anchors) / dist[:, None])
    np.testing.assert_allclose(s_v, np.eye(3) * 0.01)
    assert speed == pytest.approx(np.linalg.norm(v))
