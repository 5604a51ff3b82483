"""Tests of the per-channel manager: life cycle, counters, bad input, agreement with the batch filter."""

import math

import numpy as np
import pytest

from imm_carrier.imm import ImmCarrierFilter, ImmParams
from imm_carrier.measurement_model import METHOD_IMM, METHOD_PLL, CorrelatorSample
from imm_carrier.tracker import CarrierTracker, TrackerParams

T = 0.02
T_NS = 20_000_000


def _sample(svid=5, i=1.0, q=0.0, cn0=45.0, t=T, dphi=0.1):
    return CorrelatorSample(
        constellation=1,
        svid=svid,
        integration_time_s=t,
        in_phase=i,
        quadrature=q,
        cn0_dbhz=cn0,
        predicted_phase_change_rad=dphi,
    )


def test_tracker_equals_the_batch_filter_on_one_channel():
    rng = np.random.default_rng(1)
    n = 300
    dphi = rng.uniform(-3, 3, n)
    theta = np.cumsum(dphi) + 0.4
    bits = np.where(rng.random(n) < 0.5, 1.0, -1.0)
    zi = bits * np.cos(theta) + 0.05 * rng.standard_normal(n)
    zq = bits * np.sin(theta) + 0.05 * rng.standard_normal(n)
    tr = CarrierTracker(TrackerParams())
    outs = [tr.process((k + 1) * T_NS, [_sample(i=zi[k], q=zq[k], dphi=dphi[k])])[0] for k in range(n)]
    ref = ImmCarrierFilter(ImmParams())
    ref.initialize_from_correlator(zi[0], zq[0], dphi[0])
    b = ref.process_batch(zi[1:], zq[1:], 45.0, T, dphi[1:])
    np.testing.assert_allclose([o.phase_rad for o in outs[1:]], b.phase_rad, rtol=0, atol=1e-12)
    assert not outs[0].locked and all(o.locked for o in outs[10:])
    assert all(o.method == METHOD_IMM and len(o.mode_probabilities) == 2 for o in outs)
    assert tr.counters["channels_started"] == 1 and tr.counters["processed"] == n


def test_channel_life_cycle_and_counters():
    tr = CarrierTracker(TrackerParams(channel_timeout_s=0.5))
    tr.process(T_NS, [_sample(svid=3), _sample(svid=7)])
    assert set(tr.channel_keys) == {(1, 3), (1, 7)}
    tr.process(2 * T_NS, [_sample(svid=3)])
    # svid 7 missing for longer than the timeout: dropped; a jump to a new svid starts a channel.
    tr.process(2 * T_NS + 600_000_000, [_sample(svid=9)])
    assert set(tr.channel_keys) == {(1, 9)}
    c = tr.counters
    assert c["channels_dropped_timeout"] == 2 and c["channels_started"] == 3


def test_bad_inputs_are_counted_never_crash_never_locked_nan():
    tr = CarrierTracker(TrackerParams())
    tr.process(T_NS, [_sample()])
    bad = [
        (2 * T_NS, _sample(i=math.nan), "rejected_nonfinite_iq"),
        (2 * T_NS, _sample(q=math.inf), "rejected_nonfinite_iq"),
        (2 * T_NS, _sample(t=0.0), "rejected_integration_time"),
        (2 * T_NS, _sample(t=-T), "rejected_integration_time"),
        (2 * T_NS, _sample(cn0=75.0), "rejected_cn0_range"),
        (2 * T_NS, _sample(cn0=-1.0), "rejected_cn0_range"),
        (2 * T_NS, _sample(dphi=math.nan), "rejected_predicted_phase"),
        (2 * T_NS, _sample(svid=0), "rejected_invalid_svid"),
        (2 * T_NS, _sample(svid=-4), "rejected_invalid_svid"),
        (T_NS, _sample(), "rejected_stamp_backwards"),
        (2 * T_NS, _sample(svid=8, cn0=math.nan), "rejected_cn0_missing"),
    ]
    for stamp, s, key in bad:
        before = tr.counters[key]
        assert tr.process(stamp, [s]) == ()
        assert tr.counters[key] == before + 1, key
    out = tr.process(2 * T_NS, [_sample(cn0=math.nan), _sample()])
    assert len(out) == 1 and tr.counters["cn0_missing_used_last"] == 1
    assert tr.counters["rejected_duplicate_channel"] == 1
    # A gap of several intervals loses the satellite-motion phase: the channel restarts.
    out = tr.process(10 * T_NS, [_sample()])
    assert tr.counters["channels_restarted_gap"] == 1 and not out[0].locked
    for o in out:
        assert not (o.locked and not math.isfinite(o.phase_rad))


def test_pll_method_outputs_pll_fields():
    tr = CarrierTracker(TrackerParams(method="pll"))
    outs = [tr.process((k + 1) * T_NS, [_sample(dphi=0.0)])[0] for k in range(100)]
    last = outs[-1]
    assert last.method == METHOD_PLL and math.isnan(last.phase_std_rad) and last.mode_probabilities == ()
    assert last.data_bit == 1 and last.locked
    assert abs(last.phase_rad) < 1e-3


def test_bit_transitions_only_at_bit_edges_for_short_integration():
    tr = CarrierTracker(TrackerParams())
    p = tr.params.imm.bit_transition_probability
    # 1 ms intervals: the interval starting at a multiple of 20 ms may change bit, the others not.
    assert tr._transition_probability(22_000_000, 0.001) == 0.0  # interval 21..22 ms
    assert tr._transition_probability(21_000_000, 0.001) == p  # interval 20..21 ms starts a bit
    assert tr._transition_probability(40_000_000, 0.02) == p


def test_params_validation():
    with pytest.raises(ValueError):
        TrackerParams(method="kf")
    with pytest.raises(ValueError):
        TrackerParams(channel_timeout_s=0.0)
    with pytest.raises(ValueError):
        TrackerParams(max_gap_intervals=1.0)
