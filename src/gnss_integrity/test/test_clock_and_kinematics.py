"""Tests for gnss_integrity.clock_test and kinematics_test: the clock against its oscillator model,
the GNSS position against UWB ranges and against its own Doppler (pure, seeded)."""

import math

import numpy as np
import pytest

from gnss_common.clock_model import TCXO, simulate_clock
from gnss_common.constants import SPEED_OF_LIGHT_MPS
from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic
from gnss_integrity.clock_test import MILLISECOND_M, ClockTest, ClockTestParams
from gnss_integrity.kinematics_test import AnchorRange, KinematicsTest, KinematicsTestParams
from gnss_integrity.outcome import (
    DECISION_ALARM,
    DECISION_PASS,
    DECISION_SUSPECT,
    DECISION_UNKNOWN,
)

S = 1_000_000_000
T0 = 1_437_267_583 * S
RX = np.array([-740289.918, -5457071.734, 3207245.542])
ROT = ecef_to_enu_rotation(*ecef_to_geodetic(RX)[:2])


def _clock_series(n, dt, seed, push_ns_per_s=0.0, start=None):
    x, y = simulate_clock(TCXO, dt, n - 1, seed=seed, x0_s=1e-6, y0=5e-8)
    bias = SPEED_OF_LIGHT_MPS * x[:n]
    drift = SPEED_OF_LIGHT_MPS * y[:n]
    rng = np.random.default_rng(seed + 1)
    bias = bias + 0.8 * rng.standard_normal(n)
    drift = drift + 0.05 * rng.standard_normal(n)
    if start is not None:
        t = np.arange(n) * dt
        on = t >= start
        bias[on] += SPEED_OF_LIGHT_MPS * push_ns_per_s * 1e-9 * (t[on] - start)
        drift[on] += SPEED_OF_LIGHT_MPS * push_ns_per_s * 1e-9
    return bias, drift


def _run_clock(bias, drift, dt, test=None):
    test = test or ClockTest()
    out = []
    for k, (b, d) in enumerate(zip(bias, drift, strict=True)):
        out.append(test.update(T0 + int(round(k * dt * S)), b, 0.8, d, 0.05, 1))
    return test, out


def test_clean_tcxo_clock_never_alarms_and_rarely_suspects():
    suspects = alarms = decided = 0
    for seed in range(5):
        bias, drift = _clock_series(3000, 0.2, seed)
        _, out = _run_clock(bias, drift, 0.2)
        for pair in out:
            for o in pair:
                decided += o.decision != DECISION_UNKNOWN
                suspects += o.decision == DECISION_SUSPECT
                alarms += o.decision == DECISION_ALARM
    assert alarms == 0 and decided > 25000
    assert suspects <= 2  # per-epoch probability 1e-6 each: 0 expected in 30,000


@pytest.mark.parametrize("push", [10.0, 100.0, 1000.0])
def test_consistent_time_push_is_detected_at_once(push):
    bias, drift = _clock_series(1500, 0.2, 7, push, start=120.0)
    _, out = _run_clock(bias, drift, 0.2)
    first = next(k for k, (step, rate) in enumerate(out) if max(step.decision, rate.decision) == DECISION_ALARM)
    assert 120.0 <= first * 0.2 <= 121.0  # within a second of the onset


def test_a_ramped_push_of_100_ns_per_s_is_detected_within_60_s():
    # the careful spoofer: the push rate grows linearly from 0 to 100 ns/s over 60 s
    n, dt, start = 3000, 0.2, 200.0
    bias, drift = _clock_series(n, dt, 11)
    t = np.arange(n) * dt
    tau = np.clip(t - start, 0.0, None)
    rate = np.minimum(tau / 60.0, 1.0) * 100e-9 * SPEED_OF_LIGHT_MPS  # m/s
    drift = drift + rate
    bias = bias + np.cumsum(rate) * dt
    _, out = _run_clock(bias, drift, dt)
    first = next(k for k, pair in enumerate(out) if max(o.decision for o in pair) >= DECISION_SUSPECT)
    assert start < first * dt <= start + 60.0


def test_receiver_millisecond_steps_are_not_spoofing():
    bias, drift = _clock_series(1000, 0.2, 3)
    bias[400:] += MILLISECOND_M
    bias[700:] -= 2 * MILLISECOND_M
    test, out = _run_clock(bias, drift, 0.2)
    assert all(o.decision in (DECISION_PASS, DECISION_UNKNOWN) for pair in out for o in pair)
    assert test.counts["receiver_millisecond_steps"] == 2


def test_missing_clock_and_gaps_are_unknown_then_restart():
    test = ClockTest()
    assert all(o.decision == DECISION_UNKNOWN for o in test.update(T0, math.nan, 1.0, 0.0, 0.1, 1))
    bias, drift = _clock_series(100, 0.2, 5)
    _run_clock(bias, drift, 0.2, test)
    step, _ = test.update(T0 + 3600 * S, bias[-1], 1.0, drift[-1], 0.1, 1)
    assert step.decision == DECISION_UNKNOWN and test.counts["restarts"] == 1


def test_clock_params_validation():
    with pytest.raises(ValueError, match="oscillator"):
        ClockTestParams(oscillator="quartz")
    with pytest.raises(ValueError, match="alarm_false_alarm_probability"):
        ClockTestParams(alarm_false_alarm_probability=1e-3)


# ------------------------------------------------------------------------------ kinematics
ANCHORS_ENU = np.array([[4.0, 11.0, 1.5], [8.0, -9.9, -0.5], [-11.0, -2.0, 0.8]])


def _gnss_error(n, dt, seed, sigma=1.5, tau=60.0):
    rng = np.random.default_rng(seed)
    phi = math.exp(-dt / tau)
    e = np.zeros((n, 3))
    e[0] = sigma * rng.standard_normal(3) * [1, 1, 2]
    for k in range(1, n):
        e[k] = phi * e[k - 1] + sigma * math.sqrt(1 - phi**2) * rng.standard_normal(3) * [1, 1, 2]
    return e + 0.5 * rng.standard_normal((n, 3))


def _run_kinematics(n_anchors, push_enu_mps=(0.0, 0.0, 0.0), start_s=None, seed=0, n=1500, dt=0.2,
                    consistent=True):
    test = KinematicsTest()
    err = _gnss_error(n, dt, seed)
    rng = np.random.default_rng(seed + 100)
    push = np.asarray(push_enu_mps, float)
    out = []
    for k in range(n):
        t = k * dt
        stamp = T0 + int(round(t * S))
        off = push * max(0.0, t - start_s) if start_s is not None else np.zeros(3)
        for j in range(n_anchors):
            a = RX + ROT.T @ ANCHORS_ENU[j]
            r = float(np.linalg.norm(RX - a)) + 0.03 * rng.standard_normal()
            test.add_range(AnchorRange(stamp - 10_000_000, f"A{j + 1}", a, r))
        pos = RX + ROT.T @ (err[k] + off)
        vel_enu = (push if (consistent and start_s is not None and t >= start_s) else np.zeros(3))
        vel = ROT.T @ (vel_enu + 0.05 * rng.standard_normal(3))
        out.append(test.update(stamp, pos, vel))
    return out


@pytest.mark.parametrize("n_anchors", [0, 1, 3])
def test_clean_gnss_with_anchors_never_alarms(n_anchors):
    for seed in range(3):
        out = _run_kinematics(n_anchors, seed=seed)
        for uwb, level, motion in out:
            assert uwb.decision != DECISION_ALARM and level.decision != DECISION_ALARM
            assert motion.decision != DECISION_ALARM
            if n_anchors == 0:
                assert uwb.decision == DECISION_UNKNOWN and level.decision == DECISION_UNKNOWN
        suspects = sum(o.decision == DECISION_SUSPECT for triple in out for o in triple)
        assert suspects <= 1


@pytest.mark.parametrize("n_anchors, within_s", [(1, 60.0), (3, 10.0)])
def test_a_1_mps_push_is_seen_by_the_anchors(n_anchors, within_s):
    # one anchor at azimuth 20 deg sees only sin(20 deg) = 0.34 of an eastward push: slower
    start = 120.0
    out = _run_kinematics(n_anchors, (1.0, 0.0, 0.0), start)
    first = next(k for k, (uwb, level, _) in enumerate(out)
                 if max(uwb.decision, level.decision) >= DECISION_SUSPECT)
    assert start < first * 0.2 <= start + within_s


def test_an_inconsistent_push_is_seen_by_the_doppler_without_anchors():
    start = 120.0
    out = _run_kinematics(0, (1.0, 0.0, 0.0), start, consistent=False)
    first = next(k for k, (_, _, motion) in enumerate(out) if motion.decision >= DECISION_SUSPECT)
    assert start < first * 0.2 <= start + 15.0


def test_a_consistent_push_without_anchors_is_the_blind_spot():
    out = _run_kinematics(0, (1.0, 0.0, 0.0), 120.0, consistent=True)
    assert all(motion.decision < DECISION_ALARM for _, _, motion in out)


def test_kinematics_params_validation():
    with pytest.raises(ValueError, match="lags_s"):
        KinematicsTestParams(lags_s=())
    with pytest.raises(ValueError, match="error_std_m"):
        KinematicsTestParams(error_std_m=0.0)
