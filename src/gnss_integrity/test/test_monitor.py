"""Tests for gnss_integrity.monitor: every test on the simulated scenario, clean and attacked (pure, seeded)."""

import math
from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from gnss_integrity.monitor import IntegrityMonitor
from gnss_integrity.outcome import (
    DECISION_UNKNOWN,
    SCOPE_ALL,
    STATE_DETECTED,
    STATE_NONE,
    STATE_SUSPECTED,
    STATE_UNKNOWN,
)
from rfi_sim.gnss_uwb import BroadcastGeometry, GnssUwbScenario, simulate
from rfi_sim.spoofing import apply_attack
from rfi_sim.spoofing_attack import SpoofingAttack

NAV = Path(__file__).resolve().parents[2] / "rfi_experiments" / "data" / "arlm2000.15n"
ATTACK_S = 60.0


@cache
def _run(seed: int = 3):
    geo = BroadcastGeometry(NAV)
    return simulate(GnssUwbScenario(duration_s=150.0, seed=seed), geo, geo.iono_alpha, geo.iono_beta)


def _replay(epochs, run, anchors: int):
    mon = IntegrityMonitor()
    ids = {f"A{j + 1}" for j in range(anchors)}
    items = sorted([(e.stamp_ns, 0, e) for e in epochs]
                   + [(u.stamp_ns, 1, u) for u in run.uwb_ranges if u.anchor_id in ids], key=lambda t: t[:2])
    reports = []
    for _, kind, m in items:
        if kind:
            mon.add_uwb(m)
        else:
            reports.append(mon.process_epoch(m))
    return mon, reports


def _first(reports, state, t0_ns):
    for r in reports:
        if r.spoofing_state >= state:
            return (r.stamp_ns - t0_ns) / 1e9
    return math.inf


@pytest.mark.slow
def test_clean_run_is_none_after_its_start_and_reports_every_test():
    run = _run()
    _, reports = _replay(run.gnss_epochs, run, 3)
    assert all(r.spoofing_state in (STATE_NONE, STATE_UNKNOWN) for r in reports)
    assert sum(r.spoofing_state == STATE_NONE for r in reports) > 0.9 * len(reports)
    assert all(r.jamming_state in (STATE_NONE, STATE_UNKNOWN) for r in reports)
    names = {o.name for o in reports[-1].tests}
    assert {"cn0_drop", "clock_step", "uwb_displacement", "raim_subset", "receiver_spoofing_flag"} <= names
    # inputs that are missing are unknown, never pass: no receiver report, no SDR, no spectrum
    by_name = {o.name: o for o in reports[-1].tests}
    for name in ("receiver_agc", "receiver_spoofing_flag", "sdr_power_rise", "constellation_agreement"):
        assert by_name[name].decision == DECISION_UNKNOWN, name


@pytest.mark.slow
@pytest.mark.parametrize("anchors", [0, 3])
def test_the_issues_push_is_detected_within_10_s(anchors):
    run = _run()
    attack = SpoofingAttack(kind="position_push", start_s=ATTACK_S, push_velocity_enu_mps=(1.0, 0.0, 0.0))
    epochs, _ = apply_attack(run.gnss_epochs, attack, run.truth.receiver_ecef_m, seed=1)
    _, reports = _replay(epochs, run, anchors)
    t0 = run.gnss_epochs[0].stamp_ns
    assert _first(reports, STATE_SUSPECTED, t0) >= ATTACK_S
    assert _first(reports, STATE_DETECTED, t0) <= ATTACK_S + 10.0
    detected = [r for r in reports if r.spoofing_state == STATE_DETECTED]
    assert detected[0].spoofing_scope == SCOPE_ALL and detected[0].first_alarm_ns > 0


@pytest.mark.slow
def test_a_push_without_power_advantage_is_seen_by_the_anchors():
    run = _run()
    attack = SpoofingAttack(kind="position_push", start_s=ATTACK_S, push_velocity_enu_mps=(1.0, 0.0, 0.0),
                            power_advantage_db=0.0, cn0_mode="matched", cn0_common_std_db=0.0)
    epochs, _ = apply_attack(run.gnss_epochs, attack, run.truth.receiver_ecef_m, seed=1)
    _, reports = _replay(epochs, run, 3)
    t0 = run.gnss_epochs[0].stamp_ns
    assert ATTACK_S <= _first(reports, STATE_DETECTED, t0) <= ATTACK_S + 15.0
    names = {o.name for r in reports if r.spoofing_state == STATE_DETECTED for o in r.tests if o.decision >= 2}
    assert names & {"uwb_displacement", "uwb_level"}


@pytest.mark.slow
def test_a_time_push_is_detected_by_the_clock():
    run = _run()
    attack = SpoofingAttack(kind="time_push", start_s=ATTACK_S, time_push_ns_per_s=100.0, power_advantage_db=0.0,
                            cn0_mode="matched", cn0_common_std_db=0.0)
    epochs, _ = apply_attack(run.gnss_epochs, attack, run.truth.receiver_ecef_m, seed=1)
    _, reports = _replay(epochs, run, 0)
    t0 = run.gnss_epochs[0].stamp_ns
    assert ATTACK_S <= _first(reports, STATE_DETECTED, t0) <= ATTACK_S + 2.0


def test_epochs_without_satellite_states_leave_spoofing_unknown():
    run = _run()
    nan3 = np.full(3, math.nan)
    stateless = [replace(e, observations=tuple(replace(o, satellite_position_ecef_m=nan3,
                                                       satellite_velocity_ecef_mps=nan3)
                                               for o in e.observations)) for e in run.gnss_epochs[:100]]
    mon = IntegrityMonitor()
    reports = [mon.process_epoch(e) for e in stateless]
    assert all(r.spoofing_state in (STATE_UNKNOWN, STATE_NONE) for r in reports)
    assert all(not r.cn0_elevation_model_in_use for r in reports)
    assert all(np.all(np.isnan(r.position_ecef_m)) for r in reports)


def _report_fields(report) -> list:
    """A report as comparable values (NaN equal to NaN)."""
    return [repr(v) if not isinstance(v, np.ndarray) else repr(v.tolist()) for v in report.__dict__.values()]


@pytest.mark.slow
def test_side_inputs_count_by_stamp_not_by_when_they_are_given():
    """Issue 27 item 6: ranges stamped after an epoch that are given before it (a GNSS receiver's epochs often come
    later than the UWB ranges of the same instant) are held for the next epoch: the reports equal those of a replay
    in stamp order. Before, the epoch used them (the newest range of each anchor)."""
    run = _run()
    epochs = run.gnss_epochs[:100]
    ranges = [u for u in run.uwb_ranges if u.stamp_ns <= epochs[-1].stamp_ns]
    in_order = IntegrityMonitor()
    items = sorted([(e.stamp_ns, 1, e) for e in epochs] + [(u.stamp_ns, 0, u) for u in ranges], key=lambda t: t[:2])
    expected = [in_order.process_epoch(m) if kind else in_order.add_uwb(m) for _, kind, m in items]
    expected = [_report_fields(r) for r in expected if r is not None]
    early = IntegrityMonitor()
    got, given = [], 0
    for e in epochs:  # every range up to 0.3 s after the epoch first (newest first), then the epoch
        due = [u for u in ranges[given:] if u.stamp_ns <= e.stamp_ns + 300_000_000]
        for u in reversed(due):
            early.add_uwb(u)
        given += len(due)
        assert early.held_inputs > 0 or e is epochs[-1]
        got.append(_report_fields(early.process_epoch(e)))
    assert len(got) == len(expected) == len(epochs)
    differing = [k for k, (a, b) in enumerate(zip(got, expected, strict=True)) if a != b]
    assert not differing, f'{len(differing)} of {len(epochs)} reports differ (first: epoch {differing[0]})'


def test_held_side_inputs_are_bounded():
    run = _run()
    mon = IntegrityMonitor(replace(IntegrityMonitor().params, max_held_inputs=2))
    for u in run.uwb_ranges[:5]:
        mon.add_uwb(u)
    assert mon.held_inputs == 2 and mon.counts["inputs_applied_before_an_epoch"] == 3
    mon.process_epoch(run.gnss_epochs[-1])
    assert mon.held_inputs == 0
    with pytest.raises(ValueError, match="max_held_inputs"):
        replace(IntegrityMonitor().params, max_held_inputs=-1)
