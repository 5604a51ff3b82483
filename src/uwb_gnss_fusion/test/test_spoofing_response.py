"""What the fusion does with a spoofing detection: the filter's snapshot and restore, the roll-back
history, and SpoofingResponse's exclusion, roll-back or re-anchor, and parameters while GNSS is out."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gnss_common.integrity_codes import SCOPE_ALL, SCOPE_CONSTELLATIONS, STATE_DETECTED, STATE_NONE
from gnss_common.observations import GPS, UwbRangeMeasurement
from uwb_gnss_fusion.fusion_filter import FusionFilter
from uwb_gnss_fusion.fusion_params import FusionParams
from uwb_gnss_fusion.integrity_policy import IntegrityVerdict
from uwb_gnss_fusion.rollback import RollbackHistory
from uwb_gnss_fusion.spoofing_response import SpoofingResponse

S = 1_000_000_000
ANCHORS = {'a': np.array([10.0, 0.0, 2.0]), 'b': np.array([-5.0, 9.0, 1.0]), 'c': np.array([-5.0, -9.0, 3.0]),
           'd': np.array([0.0, 0.0, 8.0])}


def ranges(t0_s: float, t1_s: float, tag=np.array([1.0, 2.0, 0.5]), rate_hz: float = 10.0):
    """UWB ranges (map frame) from every anchor to a static tag, in stamp order."""
    out = []
    for k in range(int(round((t1_s - t0_s) * rate_hz))):
        for j, (aid, a) in enumerate(ANCHORS.items()):
            t = t0_s + k / rate_hz + j * 0.01
            out.append(UwbRangeMeasurement(int(round(t * S)), aid, a, 'map', float(np.linalg.norm(tag - a)), 0.05))
    return out


def uwb_filter() -> FusionFilter:
    return FusionFilter(dataclasses.replace(FusionParams(), use_gnss=False))


def test_snapshot_and_restore_go_back_in_time_but_never_back_in_counts():
    f = uwb_filter()
    for m in ranges(0.0, 3.0):
        f.process_uwb(m)
    assert f.initialized
    snap, t_snap, x_snap = f.snapshot(), f.time_ns, f.process_uwb(ranges(3.0, 3.1)[0]).position_m.copy()
    f.restore(snap)
    assert f.time_ns == t_snap
    counts_before = dict(f.rejection_counts)
    for m in ranges(3.0, 6.0, tag=np.array([4.0, 2.0, 0.5])):  # the tag moved: the state follows
        f.process_uwb(m)
    moved = f.process_uwb(ranges(6.0, 6.1, tag=np.array([4.0, 2.0, 0.5]))[0]).position_m
    assert np.linalg.norm(moved - x_snap) > 2.0
    f.restore(snap)  # a snapshot can be restored again
    again = f.process_uwb(ranges(3.0, 3.1)[0]).position_m
    np.testing.assert_allclose(again, x_snap, atol=1e-9)
    assert f.rejection_counts['rolled_back'] == counts_before.get('rolled_back', 0) + 1
    assert all(f.rejection_counts.get(k, 0) >= v for k, v in counts_before.items())


def test_the_history_keeps_a_snapshot_per_period_and_the_ranges_after_it():
    f = uwb_filter()
    history = RollbackHistory(period_s=1.0, keep_s=5.0)
    stream = ranges(0.0, 10.0)
    for m in stream:
        f.process_uwb(m)
        history.add_range(m)
        history.note(m.stamp_ns, f)
    assert history.roll_back(f, before_ns=2 * S) is None  # older than the 5 s kept
    replay = history.roll_back(f, before_ns=int(7.5 * S))
    assert replay is not None and history.restores == 1
    assert 7 * S - S // 2 < f.time_ns <= int(7.5 * S)
    assert [m.stamp_ns for m in replay] == [m.stamp_ns for m in stream if m.stamp_ns > f.time_ns]
    assert history.roll_back(f, before_ns=int(9.5 * S)) is None  # cleared: that past was replaced
    with pytest.raises(ValueError):
        RollbackHistory(period_s=0.0, keep_s=1.0)


def verdict(t_s: float, state: int, scope: int = SCOPE_ALL, first_s: float = 0.0) -> IntegrityVerdict:
    constellations = (GPS,) if scope == SCOPE_CONSTELLATIONS else ()
    return IntegrityVerdict(int(t_s * S), state, scope, constellations, first_alarm_ns=int(first_s * S))


def run_until(response: SpoofingResponse, f: FusionFilter, t0_s: float, t1_s: float) -> None:
    for m in ranges(t0_s, t1_s):
        f.process_uwb(m)
        response.after_message(m.stamp_ns, f, m)


def test_an_exclusion_of_all_gnss_rolls_back_and_runs_without_gnss_until_readmitted():
    base = FusionParams()  # with GNSS
    f = FusionFilter(base)
    f.params = dataclasses.replace(base, use_gnss=False)  # UWB drives this test's filter
    response = SpoofingResponse(readmit_clean_s=2.0, act=True, rollback_s=1.0)
    run_until(response, f, 0.0, 8.0)
    done = response.apply(verdict(8.0, STATE_DETECTED, first_s=6.5), f, base)
    assert done.change == 'excluded' and done.rolled_back_to_ns is not None
    assert done.rolled_back_to_ns <= int(5.5 * S) and done.ranges_replayed > 0 and not done.reanchored
    assert f.time_ns >= int(7.9 * S)  # the ranges since the copy were applied again
    assert f.params.use_gnss is False and response.counts['rollbacks'] == 1
    assert response.filter_params(base).use_gnss is False
    run_until(response, f, 8.0, 9.0)
    assert response.apply(verdict(9.0, STATE_NONE), f, base).change is None  # the clean period starts
    assert response.apply(verdict(11.0, STATE_NONE), f, base).change == 'readmitted'
    assert f.params == base


def test_without_history_it_re_anchors_and_a_partial_exclusion_keeps_gnss():
    base = FusionParams()
    f = FusionFilter(dataclasses.replace(base, use_gnss=False))
    response = SpoofingResponse(readmit_clean_s=2.0, act=True, rollback_s=1.0)
    for m in ranges(0.0, 4.0):
        f.process_uwb(m)  # the history was not fed: nothing to go back to
    done = response.apply(verdict(4.0, STATE_DETECTED, first_s=3.5), f, base)
    assert done.rolled_back_to_ns is None and done.reanchored and response.counts['rollbacks_unavailable'] == 1
    other = SpoofingResponse(readmit_clean_s=2.0, act=True, rollback_s=1.0)
    g = FusionFilter(base)
    out = other.apply(verdict(4.0, STATE_DETECTED, scope=SCOPE_CONSTELLATIONS, first_s=3.5), g, base)
    assert out.change == 'excluded' and g.params.use_gnss is True  # one constellation out: GNSS still used


def test_switching_acting_off_readmits_at_once():
    base = FusionParams()
    f = FusionFilter(dataclasses.replace(base, use_gnss=False))
    response = SpoofingResponse(readmit_clean_s=30.0, act=True, rollback_s=0.0)
    for m in ranges(0.0, 4.0):
        f.process_uwb(m)
    response.apply(verdict(4.0, STATE_DETECTED), f, base)
    assert response.exclusion.all_gnss() and f.params.use_gnss is False
    assert response.set_acting(False, f, base) and not response.exclusion.active and f.params == base
    assert response.apply(verdict(5.0, STATE_DETECTED), f, base).change is None  # not acting: counted only
