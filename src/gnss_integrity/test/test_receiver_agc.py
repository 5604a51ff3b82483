"""receiver_agc and receiver_jam_flag: learned baselines, thresholds from the false-alarm
probability, the receiver's flag, staleness, learning gates and rate limits."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from gnss_integrity.outcome import (
    CATEGORY_JAMMING,
    DECISION_ALARM,
    DECISION_PASS,
    DECISION_SUSPECT,
    DECISION_UNKNOWN,
    normal_threshold,
)
from gnss_integrity.receiver_agc import (
    ANTENNA_OPEN,
    JAMMING_CRITICAL,
    JAMMING_OK,
    JAMMING_UNKNOWN,
    JAMMING_WARNING,
    SOURCE_MON_RF,
    Baseline,
    ReceiverAgcMonitor,
    ReceiverAgcParams,
    ReceiverInterferenceReport,
)

S = 1_000_000_000  # ns per second


def report(t_s: float, agc: float = 5000.0, cw: float = 12.0, state: int = JAMMING_OK,
           **kw) -> ReceiverInterferenceReport:
    return ReceiverInterferenceReport(stamp_ns=int(t_s * S), jamming_state=state,
                                      jamming_detection_enabled=state != JAMMING_UNKNOWN, agc_count=agc,
                                      jam_indicator=cw, antenna_status=2, antenna_power=1, **kw)


def learned_monitor(n: int = 60, seed: int = 0) -> tuple[ReceiverAgcMonitor, float]:
    """A monitor after n clean 1 Hz reports (AGC 5000 +- 30 counts, CW 12 +- 2)."""
    rng = np.random.default_rng(seed)
    mon = ReceiverAgcMonitor()
    for k in range(n):
        mon.update(report(k, 5000.0 + 30.0 * rng.standard_normal(), 12.0 + 2.0 * rng.standard_normal()))
    return mon, float(n)


def test_unknown_until_a_baseline_is_learned_then_pass():
    mon = ReceiverAgcMonitor()
    first = mon.update(report(0.0))
    assert first.agc.decision == DECISION_UNKNOWN and math.isnan(first.agc.statistic)
    assert first.jam_flag.decision == DECISION_PASS and first.looks_clean
    for k in range(1, 10):
        res = mon.update(report(k))
    assert res.agc.decision == DECISION_UNKNOWN  # judged before the 10th report is learned
    res = mon.update(report(10.0))
    assert res.agc.decision == DECISION_PASS and res.agc.category == CATEGORY_JAMMING
    assert res.agc.suspect_threshold == pytest.approx(normal_threshold(1e-4))
    assert res.agc.alarm_threshold == pytest.approx(normal_threshold(1e-7))


def test_an_agc_drop_is_jamming_a_small_one_is_not():
    mon, t = learned_monitor()
    assert mon.update(report(t, 4800.0)).agc.decision == DECISION_PASS  # 200 counts: 2 sigma (floor 100)
    res = mon.update(report(t + 1, 4000.0))
    assert res.agc.decision == DECISION_ALARM and res.agc.statistic == pytest.approx(10.0, abs=0.5)
    assert not res.looks_clean and res.evidence_available
    res = mon.update(report(t + 2, 4580.0))  # 4.2 sigma
    assert res.agc.decision == DECISION_SUSPECT


def test_a_cw_indicator_rise_is_jamming():
    mon, t = learned_monitor()
    res = mon.update(report(t, cw=90.0))
    assert res.agc.decision == DECISION_ALARM and res.agc.statistic == pytest.approx(7.8, abs=0.5)


@pytest.mark.parametrize("state,decision", [(JAMMING_OK, DECISION_PASS), (JAMMING_WARNING, DECISION_SUSPECT),
                                            (JAMMING_CRITICAL, DECISION_ALARM), (JAMMING_UNKNOWN, DECISION_UNKNOWN)])
def test_the_receivers_own_flag(state, decision):
    res = ReceiverAgcMonitor().update(report(0.0, state=state))
    assert res.jam_flag.name == "receiver_jam_flag" and res.jam_flag.decision == decision
    assert res.looks_clean is (decision <= DECISION_PASS)
    if decision == DECISION_UNKNOWN:
        assert math.isnan(res.jam_flag.statistic)
    else:
        assert res.jam_flag.statistic == state


def test_stale_reports_leave_both_tests_unknown():
    mon, t = learned_monitor()
    assert mon.judge(int((t + 4.0) * S)).agc.decision == DECISION_PASS
    late = mon.judge(int((t + 6.0) * S))
    assert late.agc.decision == DECISION_UNKNOWN and late.jam_flag.decision == DECISION_UNKNOWN
    assert late.looks_clean and not late.evidence_available


def test_learning_gates_and_rate_limits():
    mon, t = learned_monitor()
    # The receiver's flag, an open antenna or the C/N0 evidence keep reports out of the baseline.
    for r in (report(t, 3000.0, state=JAMMING_WARNING), replace(report(t + 1, 3000.0), antenna_status=ANTENNA_OPEN)):
        assert not mon.update(r).looks_clean
    mon.update(report(t + 2, 3000.0), other_clean=False)
    assert mon.update(report(t + 3)).agc.statistic == pytest.approx(0.0, abs=0.5)
    # A jammer that ramps up slowly stops being learned at 2 sigma and goes on to ALARM.
    t += 4
    for k in range(300):
        mon.update(report(t + k, 5000.0 - 3.0 * k, 12.0 + 0.2 * k))
    res = mon.update(report(t + 300, 5000.0 - 900.0, 72.0))
    assert res.agc.decision == DECISION_ALARM


def test_baseline_moves_freely_the_harmless_way_and_slowly_the_harmful_way():
    agc = Baseline()
    for k in range(20):
        agc.learn(5000.0, k * S, memory=10.0, max_step_per_s=2.0, harmful_sign=-1.0)
    for k in range(20, 30):  # the running mean falls 1000 counts in 10 s; the published level 20
        agc.learn(4000.0, k * S, memory=10.0, max_step_per_s=2.0, harmful_sign=-1.0)
    assert agc.mean < 4400.0 and agc.published == pytest.approx(5000.0 - 2.0 * 10, abs=1e-9)
    for k in range(30, 60):  # back up: the published level follows the mean at once
        agc.learn(5100.0, k * S, memory=10.0, max_step_per_s=2.0, harmful_sign=-1.0)
    assert agc.published == pytest.approx(agc.mean) and agc.mean > 5000.0


def test_rf_blocks_are_judged_separately():
    mon = ReceiverAgcMonitor()
    for k in range(30):
        for block, level in ((0, 5000.0), (1, 2500.0)):
            mon.update(ReceiverInterferenceReport(int(k * S), SOURCE_MON_RF, block, JAMMING_OK, True, 10.0, level))
    quiet = mon.update(ReceiverInterferenceReport(30 * S, SOURCE_MON_RF, 0, JAMMING_OK, True, 10.0, 5000.0))
    assert quiet.agc.decision == DECISION_PASS
    jam_l5 = mon.update(ReceiverInterferenceReport(30 * S, SOURCE_MON_RF, 1, JAMMING_OK, True, 10.0, 1500.0))
    assert jam_l5.agc.decision == DECISION_ALARM  # L2/L5 block 1000 counts down; L1 unchanged


def test_out_of_order_reports_are_not_learned_and_params_validated():
    mon, t = learned_monitor()
    mon.update(report(t))
    old = mon.update(report(t - 30.0, 100.0))
    assert old.agc.decision == DECISION_UNKNOWN  # no report of its block at or before its stamp
    assert mon.update(report(t + 1)).agc.decision == DECISION_PASS
    with pytest.raises(ValueError):
        ReceiverAgcParams(agc_min_std_counts=0.0)
    with pytest.raises(ValueError):
        ReceiverAgcParams(false_alarm_probability=1e-8)
