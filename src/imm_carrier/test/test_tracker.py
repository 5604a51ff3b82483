"""Tests of the per-channel manager: life cycle, counters, bad input, agreement with the batch filter."""

import math

import numpy as np
import pytest

from imm_carrier.imm import ImmCarrierFilter, ImmParams
from imm_carrier.measurement_model import METHOD_IMM, METHOD_PLL, CorrelatorSample
from imm_carrier.pll import CostasPll
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


@pytest.mark.parametrize("method", ["imm", "pll"])
def test_compiled_multichannel_epoch_equals_one_filter_per_channel(method):
    # 70 channels (more than the 64 initial slots: the bank grows), T = 1 ms on the GPS bit grid, arrays in
    # shuffled order, one satellite missing every 7th interval (gap restart) and NaN C/N0 now and then:
    # every row must equal an independent ImmCarrierFilter / CostasPll driven step by step.
    rng = np.random.default_rng(21)
    t_s, t_ns, n_ep = 0.001, 1_000_000, 45
    keys = [(1, sv) for sv in range(1, 33)] + [(3, sv) for sv in range(1, 39)]
    params = TrackerParams(method=method)
    tr = CarrierTracker(params)
    ref: dict = {}
    last_cn0: dict = {}
    t0 = 1_400_000_000 * 1_000_000_000  # a multiple of 20 ms
    for e in range(1, n_ep + 1):
        stamp = t0 + e * t_ns
        order = rng.permutation(len(keys))
        order = [j for j in order if not (j == 5 and e % 7 == 0)]
        const = np.array([keys[j][0] for j in order])
        svid = np.array([keys[j][1] for j in order])
        n = len(order)
        cn0 = rng.uniform(30, 50, n)
        cn0[rng.random(n) < 0.1] = math.nan
        dphi = rng.uniform(-3, 3, n)
        zi, zq = rng.normal(0.3, 1.0, n), rng.normal(-0.2, 1.0, n)
        batch = tr.process_arrays(stamp, const, svid, np.full(n, t_s), zi, zq, cn0, dphi)
        rows = {(int(r[0]), int(r[1])): r for r in batch.values}
        for j in range(n):
            key = (int(const[j]), int(svid[j]))
            c = cn0[j] if not math.isnan(cn0[j]) else last_cn0.get(key, math.nan)
            if math.isnan(c):
                assert key not in rows
                continue
            last_cn0[key] = c
            row = rows[key]
            gap = key in ref and stamp - ref[key][1] > 1.5 * t_ns
            if key not in ref or gap:
                f = ImmCarrierFilter(params.imm) if method == "imm" else CostasPll(params.pll)
                f.initialize_from_correlator(zi[j], zq[j], dphi[j])
                ref[key] = [f, stamp]
                assert row[2] == pytest.approx(f.residual_phase_rad, abs=1e-12) and row[10] == 0.0
                continue
            f = ref[key][0]
            ref[key][1] = stamp
            if method == "imm":
                p = tr._transition_probability(stamp, t_s)
                r = f.update(zi[j], zq[j], c, t_s, dphi[j], bit_transition_probability=p)
                expected = [r.phase_rad, r.phase_std_rad, r.frequency_hz, r.frequency_std_hz, r.data_bit,
                            r.data_bit_probability, *r.mode_probabilities, float(r.locked)]
            else:
                r = f.update(zi[j], zq[j], c, t_s, dphi[j])
                expected = [r.phase_rad, math.nan, r.frequency_hz, math.nan]
            np.testing.assert_allclose(row[2:2 + len(expected)], expected, rtol=1e-12, atol=1e-12)
    c = tr.counters
    assert c["channels_started"] == len(keys) + c["channels_restarted_gap"] and c["channels_restarted_gap"] == 6
    assert len(tr.channel_keys) == tr.channel_count == len(keys)
    # Every correlator offered is processed or rejected (only a new channel without C/N0 is rejected here).
    offered = n_ep * len(keys) - n_ep // 7
    assert c["processed"] + c["rejected_cn0_missing"] == offered and c["cn0_missing_used_last"] > 0


def test_batch_rows_convert_to_estimates():
    tr = CarrierTracker(TrackerParams())
    b = tr.process_arrays(T_NS, np.array([1, 1]), np.array([4, 0]), np.full(2, T), np.ones(2), np.zeros(2),
                          np.full(2, 45.0), np.zeros(2))
    assert len(b) == 1 and tr.counters["rejected_invalid_svid"] == 1
    (e,) = b.to_estimates()
    assert (e.constellation, e.svid, e.method, e.mode_probabilities, e.locked) == (1, 4, METHOD_IMM, (0.5, 0.5), False)
    assert b.column("svid").tolist() == [4.0]
    with pytest.raises(ValueError):
        tr.process_arrays(T_NS, np.array([1]), np.array([4, 5]), np.full(2, T), np.ones(2), np.zeros(2),
                          np.full(2, 45.0), np.zeros(2))


@pytest.mark.parametrize("method", ["imm", "pll"])
def test_overflowing_correlator_restarts_the_channel_unlocked(method):
    # The magnitude check (rejected_iq_magnitude) normally stops |I|, |Q| ~ 1e300 before the filter: opened up
    # here to test the net behind it.
    tr = CarrierTracker(TrackerParams(method=method, max_iq_magnitude_ratio=1e308))
    for k in range(1, 30):
        tr.process(k * T_NS, [_sample(dphi=0.0)])
    (bad,) = tr.process(30 * T_NS, [_sample(i=1e300, q=-1e300, dphi=0.0)])
    # |I|, |Q| ~ 1e300 overflow the IMM's covariance and the PLL's lock averages: the answer is unlocked and
    # the channel restarts from its next correlator (counted), then locks again.
    assert not bad.locked and tr.counters["channels_restarted_nonfinite"] == 1
    (first,) = tr.process(31 * T_NS, [_sample(dphi=0.0)])
    assert math.isfinite(first.phase_rad) and not first.locked and tr.counters["channels_started"] == 2
    outs = [tr.process(k * T_NS, [_sample(dphi=0.0)])[0] for k in range(32, 60)]
    assert outs[-1].locked and math.isfinite(outs[-1].phase_rad)


def _locked_run(tr, k_end, theta=0.4, rng=None, sigma=0.05):
    """Intervals 1..k_end of a residual phase theta (rad) with noise (satellite phase change 0)."""
    outs = []
    for k in range(1, k_end + 1):
        n = rng.normal(0.0, sigma, 2) if rng is not None else (0.0, 0.0)
        outs.append(tr.process(k * T_NS, [_sample(i=math.cos(theta) + n[0], q=math.sin(theta) + n[1], dphi=0.0)]))
    return outs


def _valid_if_locked(e):
    """The output rule: locked only with finite phase/frequency and (IMM) finite standard deviations > 0."""
    if not e.locked:
        return True
    stds_ok = e.method != METHOD_IMM or (0 < e.phase_std_rad < math.inf and 0 < e.frequency_std_hz < math.inf)
    return math.isfinite(e.phase_rad) and math.isfinite(e.frequency_hz) and stds_ok


@pytest.mark.parametrize("method", ["imm", "pll"])
def test_physically_impossible_correlators_are_rejected_and_counted(method):
    """Faults found by fuzzing (issue 12): unchecked, T = 1e6 s gives the IMM a phase jump of -6062 rad
    with phase_std 0 and locked, and the PLL a frequency of -2.8e14 Hz for good. Each impossible value is
    rejected before the filter, under its own counter, and the channel goes on locked and sane."""
    tr = CarrierTracker(TrackerParams(method=method))
    rng = np.random.default_rng(4)
    _locked_run(tr, 40, rng=rng)
    t_max, t_min = tr.params.max_integration_time_s, tr.params.min_integration_time_s
    assert (t_min, t_max) == (1e-4, 0.1)
    dphi_max = 2 * math.pi * 1e5 * T
    bad = [
        (_sample(t=1e6), "rejected_integration_time"),
        (_sample(t=0.2), "rejected_integration_time"),
        (_sample(t=5e-5), "rejected_integration_time"),
        (_sample(t=5e-324), "rejected_integration_time"),
        (_sample(t=math.nan), "rejected_integration_time"),
        (_sample(i=1e300), "rejected_iq_magnitude"),
        (_sample(q=-1e300), "rejected_iq_magnitude"),
        (_sample(i=150.0), "rejected_iq_magnitude"),  # 150 x the RMS of a 45 dB-Hz correlator (~1)
        (_sample(cn0=1e300), "rejected_cn0_range"),
        (_sample(dphi=math.inf), "rejected_predicted_phase"),
        (_sample(dphi=1.01 * dphi_max), "rejected_predicted_phase"),
        (_sample(dphi=-1e9), "rejected_predicted_phase"),
    ]
    for k, (sample, key) in enumerate(bad, start=41):
        before = tr.counters
        assert tr.process(k * T_NS, [sample]) == (), key
        after = tr.counters
        assert after[key] == before[key] + 1, key
        assert sum(after.values()) == sum(before.values()) + 1, key  # nothing else counted, no channel touched
    assert tr.channel_count == 1 and tr.counters["channels_started"] == 1
    # The bounds themselves are accepted (a new channel each, not to disturb the locked one).
    edge = [CorrelatorSample(1, sv, t, 1.0, 0.0, 45.0, d) for sv, t, d in
            ((20, t_min, 0.0), (21, t_max, 0.0), (22, T, 0.99 * dphi_max), (23, T, -0.99 * dphi_max))]
    assert len(tr.process(60 * T_NS, edge)) == 4
    k0 = 60
    outs = [tr.process((k0 + j) * T_NS, [_sample(i=math.cos(0.4), q=math.sin(0.4), dphi=0.0)])[0] for j in range(1, 6)]
    # The channel was not thrown off: after the gap (restart) it locks again on the same phase.
    outs += [tr.process((k0 + j) * T_NS, [_sample(i=math.cos(0.4), q=math.sin(0.4), dphi=0.0)])[0]
             for j in range(6, 40)]
    assert outs[-1].locked and abs(math.remainder(outs[-1].phase_rad - 0.4, math.pi)) < 0.05
    assert abs(outs[-1].frequency_hz) < 1.0


@pytest.mark.parametrize("method", ["imm", "pll"])
def test_a_tracker_thrown_off_by_an_accepted_input_restarts_instead_of_publishing_garbage(method):
    """With the T check opened up (max 1e7 s), T = 1e6 s reaches the filter, as before the fix: the IMM's
    covariance cancels to 0 and the PLL's integrators run away. The final check publishes that answer
    unlocked (counted) and restarts the channel (channels_restarted_diverged); the next estimates are sane
    and lock again."""
    tr = CarrierTracker(TrackerParams(method=method, max_integration_time_s=1e7))
    rng = np.random.default_rng(9)
    _locked_run(tr, 40, rng=rng)
    (wild,) = tr.process(41 * T_NS, [_sample(t=1e6, i=0.9, q=0.5, dphi=0.0)])
    assert not wild.locked
    c = tr.counters
    assert c["channels_restarted_diverged"] + c["channels_restarted_nonfinite"] == 1
    outs = [tr.process(k * T_NS, [_sample(i=math.cos(0.4) + rng.normal(0, 0.05), q=math.sin(0.4)
                                          + rng.normal(0, 0.05), dphi=0.0)])[0] for k in range(42, 90)]
    assert all(_valid_if_locked(e) for e in outs)
    assert all(math.isfinite(e.phase_rad) and abs(e.frequency_hz) * T <= 1.0 for e in outs)
    assert outs[-1].locked and abs(math.remainder(outs[-1].phase_rad - 0.4, math.pi)) < 0.1


def test_a_collapsed_imm_covariance_is_never_published_locked():
    """phase_std 0 with locked = true was the fuzzer's finding: the final check suppresses it (counted)."""
    tr = CarrierTracker(TrackerParams(max_integration_time_s=1e7))
    _locked_run(tr, 30)
    (e,) = tr.process(31 * T_NS, [_sample(t=1e6, i=math.cos(0.4), q=math.sin(0.4), dphi=0.0)])
    assert e.phase_std_rad == 0.0 and not e.locked
    assert tr.counters["locked_suppressed_invalid"] == 1 and tr.counters["channels_restarted_diverged"] == 1


@pytest.mark.parametrize("method", ["imm", "pll"])
def test_random_accepted_extremes_never_give_an_invalid_locked_estimate(method):
    """Seeded property test: correlators anywhere inside the accepted ranges (T over its whole range, C/N0 0..70,
    I/Q up to the magnitude bound, predicted phase up to its bound) mixed with good ones: no locked estimate is
    ever invalid, every estimate is finite or the channel restarted, and after each extreme input the channel's
    next estimate is sane (|f| <= 1/T) or it restarted."""
    rng = np.random.default_rng(77)
    params = TrackerParams(method=method)
    tr = CarrierTracker(params)
    stamp = 0
    for step in range(3000):
        extreme = rng.random() < 0.2
        if extreme:
            log_t = rng.uniform(math.log(params.min_integration_time_s), math.log(params.max_integration_time_s))
            t = float(np.exp(log_t))
            cn0 = float(rng.uniform(0, 70))
            rms = math.sqrt(1.0 + 2.0 / (2 * t * 10 ** (cn0 / 10)))
            mag = float(rng.uniform(0, 0.99 * params.max_iq_magnitude_ratio * rms))
            ang = float(rng.uniform(-math.pi, math.pi))
            i, q = mag * math.cos(ang), mag * math.sin(ang)
            dphi = float(rng.uniform(-0.99, 0.99) * 2 * math.pi * 1e5 * t)
        else:
            t, cn0, dphi = T, 45.0, 0.0
            i, q = math.cos(0.4) + rng.normal(0, 0.05), math.sin(0.4) + rng.normal(0, 0.05)
        stamp += int(round(t * 1e9))
        before = tr.counters
        out = tr.process(stamp, [_sample(i=i, q=q, t=t, cn0=cn0, dphi=dphi)])
        assert len(out) == 1, (step, tr.counters)
        (e,) = out
        assert _valid_if_locked(e), (step, e)
        after = tr.counters
        restarted = sum(after[k] - before[k] for k in ("channels_restarted_nonfinite", "channels_restarted_diverged"))
        assert restarted or (math.isfinite(e.phase_rad) and abs(e.frequency_hz) * t <= 1.0), (step, e)
    assert tr.counters["processed"] == 3000


def test_reset_channels_restarts_every_channel_counted():
    tr = CarrierTracker(TrackerParams())
    tr.process(T_NS, [_sample(svid=3), _sample(svid=7)])
    assert tr.reset_channels() == 2 and tr.channel_count == 0
    assert tr.counters["channels_restarted_stamp_jump"] == 2
    out = tr.process(2 * T_NS, [_sample(svid=3)])
    assert not out[0].locked and tr.counters["channels_started"] == 3


def test_integration_time_range_is_validated():
    with pytest.raises(ValueError):
        TrackerParams(min_integration_time_s=0.1, max_integration_time_s=0.01)
    with pytest.raises(ValueError):
        TrackerParams(min_integration_time_s=0.0)
    with pytest.raises(ValueError):
        TrackerParams(max_iq_magnitude_ratio=1.0)


def _noisy_channel(n, seed):
    """I/Q, predicted changes of one channel at 45 dB-Hz, T = 20 ms, unit amplitude (seeded)."""
    rng = np.random.default_rng(seed)
    dphi = rng.uniform(-3, 3, n)
    theta = np.cumsum(dphi) + 0.4
    sigma = 1.0 / math.sqrt(2 * T * 10 ** 4.5)
    zi = np.cos(theta) + sigma * rng.standard_normal(n)
    zq = np.sin(theta) + sigma * rng.standard_normal(n)
    return zi, zq, dphi


@pytest.mark.parametrize("method", ["imm", "pll"])
def test_correlator_lock_is_counted_and_tracked_through_by_default(method):
    """carrier_lock LOST (the correlator's own loop unlocked) changes no estimate with the default 'track': the
    same outputs as HELD or UNKNOWN, bit for bit; each code counted, and the locked outputs and slips on the
    unlocked intervals counted apart."""
    n = 200
    zi, zq, dphi = _noisy_channel(n, 3)
    codes = np.where(np.arange(n) % 3 == 0, 1, 2)  # LOST every third interval, HELD otherwise
    codes[:10] = 0  # UNKNOWN (e.g. the correlator's lock window not full yet)
    runs = {}
    for name, lock in (("codes", codes), ("none", None), ("held", np.full(n, 2))):
        tr = CarrierTracker(TrackerParams(method=method))
        rows = [tr.process_arrays((k + 1) * T_NS, [1], [5], [T], [zi[k]], [zq[k]], [45.0], [dphi[k]],
                                  None if lock is None else lock[k:k + 1]).values[0] for k in range(n)]
        runs[name] = (np.array(rows), tr.counters)
    np.testing.assert_array_equal(runs["codes"][0], runs["none"][0])
    np.testing.assert_array_equal(runs["codes"][0], runs["held"][0])
    values, c = runs["codes"]
    lost = codes == 1
    assert c["correlator_unlocked"] == lost.sum() and c["correlator_lock_unknown"] == 10
    assert runs["none"][1]["correlator_lock_unknown"] == n and runs["held"][1]["correlator_unlocked"] == 0
    locked = values[:, 10] > 0.5
    assert c["locked_on_correlator_unlocked"] == np.count_nonzero(locked & lost) > 0
    assert c["slips_on_correlator_unlocked"] == 0 and c["coasted_correlator_unlocked"] == 0


def test_imm_coasts_over_unlocked_correlators_when_asked():
    """correlator_unlocked 'coast': on a LOST correlator the IMM only predicts (its I/Q unused: any I/Q gives the
    same estimate, the phase std grows by the clock model's process noise); HELD and UNKNOWN ones update."""
    n = 60
    zi, zq, dphi = _noisy_channel(n, 4)
    outs = []
    for garbage in (0.0, 1.0):
        tr = CarrierTracker(TrackerParams(correlator_unlocked="coast"))
        rows = []
        for k in range(n):
            lost = k >= 50
            i, q = (zi[k] + garbage * 5.0, zq[k] - garbage * 3.0) if lost else (zi[k], zq[k])
            rows.append(tr.process_arrays((k + 1) * T_NS, [1], [5], [T], [i], [q], [45.0], [dphi[k]],
                                          [1 if lost else 2]).values[0])
        outs.append((np.array(rows), tr.counters))
    (a, ca), (b, _) = outs
    np.testing.assert_array_equal(a, b)
    assert ca["coasted_correlator_unlocked"] == 10 and ca["correlator_unlocked"] == 10
    std = a[:, 3]
    assert np.all(np.diff(std[50:]) > 0) and std[49] < std[50]  # prediction only: the covariance grows
    tracked = CarrierTracker(TrackerParams())  # 'track' uses the garbage and moves away
    rows = [tracked.process_arrays((k + 1) * T_NS, [1], [5], [T], [zi[k] + (5.0 if k >= 50 else 0.0)], [zq[k]],
                                   [45.0], [dphi[k]], [1 if k >= 50 else 2]).values[0] for k in range(n)]
    assert not np.array_equal(np.array(rows)[50:, 2], a[50:, 2])
    with pytest.raises(ValueError, match="correlator_unlocked"):
        TrackerParams(correlator_unlocked="reset")
    with pytest.raises(ValueError, match="equal length"):
        tracked.process_arrays(0, [1], [5], [T], [1.0], [0.0], [45.0], [0.1], [1, 2])


def test_correlator_sample_carries_the_lock():
    tr = CarrierTracker(TrackerParams())
    for k in range(3):
        s = CorrelatorSample(1, 5, T, 1.0, 0.0, 45.0, 0.1, carrier_lock=1)
        tr.process((k + 1) * T_NS, [s])
    assert tr.counters["correlator_unlocked"] == 3
