"""In-process tests of ImmCarrierNode: one Context per test, a SingleThreadedExecutor, bounded spins.

Each test publishes CorrelatorArrays from a test node and spins until the node has taken every one
and everything it published has arrived (counted, never slept for).
"""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.context import Context
from rclpy.parameter import Parameter

from gnss_common.gps_time import gps_to_ros_stamp_ns
from imm_carrier import tracker as tracker_module
from imm_carrier.imm_carrier_node import CarrierNodeParams, ImmCarrierNode
from rfi_msgs.msg import CarrierPhase, CarrierPhaseArray, Correlator, CorrelatorArray
from rfi_node_common import testing
from rfi_node_common.qos import DATA_QOS
from rfi_node_common.stamps import ns_to_stamp
from rfi_node_common.testing import NodeRig

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'imm_carrier.yaml'
START_NS = gps_to_ros_stamp_ns(2300, 345600.0)  # on the 20 ms GPS bit grid (ROS = GPS - 18 s)
T_S = 0.02
T_NS = 20_000_000
TOPIC = '/gnss/correlators'


class Rig(NodeRig):
    """The node under test plus a test node that publishes correlators and collects the outputs."""

    def __init__(self, params: dict | None = None, args: list[str] | None = None, *, reliable: bool = True,
                 publisher_qos=DATA_QOS) -> None:
        params = dict(params or {})
        if args is None:
            params.setdefault('input_timeout_s', 0.0)  # no wall-clock STALE report in the middle of a test
        if 'diagnostics_period_s' in params:
            # levels over the last report only (window = period), as the level tests below are written;
            # test_levels_use_fractions_over_the_window checks the window itself
            params.setdefault('diagnostics_window_s', params['diagnostics_period_s'])
        if reliable:  # the tests count every message: make the (best-effort by default) input reliable
            params.setdefault(f'qos_overrides.{TOPIC}.subscription.reliability', 'reliable')
        super().__init__(lambda context, overrides: ImmCarrierNode(context=context, parameter_overrides=overrides),
                         inputs={TOPIC: (CorrelatorArray, publisher_qos)},
                         outputs={'/carrier/estimates': CarrierPhaseArray, '/diagnostics': DiagnosticArray},
                         params=params, args=args, name='imm_carrier_test_io')
        self.pub = self.pubs[TOPIC]
        self.estimates: list[CarrierPhaseArray] = self.out['/carrier/estimates']
        self.diagnostics: list[DiagnosticArray] = self.out['/diagnostics']
        self.sent = 0

    def send(self, msg: CorrelatorArray) -> None:
        """Publish one array and spin until the node has answered it completely."""
        self.pub.publish(msg)
        self.sent += 1
        self.settle_until(lambda: self.node.counts['arrays_received'] == self.sent)

    def last_values(self) -> dict[str, str]:
        return {kv.key: kv.value for kv in self.diagnostics[-1].status[0].values}


@pytest.fixture
def rig_factory():
    with testing.rig_factory(Rig) as make:
        yield make


def correlator(svid, i=1.0, q=0.0, t=T_S, cn0=45.0, dphi=0.3) -> Correlator:
    return Correlator(constellation=1, svid=svid, integration_time_s=t, in_phase=i, quadrature=q, cn0_dbhz=cn0,
                      predicted_phase_change_rad=dphi)


def array(stamp_ns: int, correlators) -> CorrelatorArray:
    msg = CorrelatorArray(correlators=list(correlators))
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = 'gnss_receiver'
    return msg


def clean_array(k: int, svids=(3, 7), cn0=45.0, rng=None) -> CorrelatorArray:
    """Interval k of a noise-light signal: satellite phase 0.3 rad per interval, residual phase 0.4 rad."""
    theta = 0.3 * k + 0.4
    noise = rng.normal(0.0, 0.05, 2) if rng is not None else (0.0, 0.0)
    return array(START_NS + k * T_NS, [correlator(s, i=math.cos(theta) + noise[0], q=math.sin(theta) + noise[1],
                                                  cn0=cn0) for s in svids])


def stamp_of(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def test_method_both_publishes_imm_and_pll_entries(rig_factory):
    rig = rig_factory({'method': 'both', 'diagnostics_period_s': 0.01})
    rng = np.random.default_rng(3)
    for k in range(1, 41):
        rig.send(clean_array(k, rng=rng))
    assert len(rig.estimates) == 40
    for k, out in enumerate(rig.estimates, start=1):
        assert stamp_of(out) == START_NS + k * T_NS
        assert out.header.frame_id == 'gnss_receiver'
        assert sorted((e.method, e.svid) for e in out.estimates) == [
            (CarrierPhase.IMM, 3), (CarrierPhase.IMM, 7), (CarrierPhase.PLL, 3), (CarrierPhase.PLL, 7)]
    last = rig.estimates[-1].estimates
    for e in last:
        if e.method == CarrierPhase.IMM:
            assert e.locked and len(e.mode_probabilities) == 2 and math.isfinite(e.phase_std_rad)
            # Residual phase 0.4 rad, up to the pi ambiguity of an unknown data bit.
            assert abs(math.remainder(e.phase_rad - 0.4, math.pi)) < 0.05
        else:
            assert len(e.mode_probabilities) == 0 and math.isnan(e.phase_std_rad)
            assert abs(math.remainder(e.phase_rad - 0.4, math.pi)) < 0.1
    # First sight of a channel only initialises it: not locked.
    assert not any(e.locked for e in rig.estimates[0].estimates)
    values = rig.last_values()
    assert values['imm.channels_started'] == values['pll.channels_started'] == '2'
    assert values['imm.processed'] == values['pll.processed'] == '80'
    assert values['accounting_ok'] == 'True' and rig.diagnostics[-1].status[0].level == DiagnosticStatus.OK


def test_correlators_reported_unlocked_are_counted_in_diagnostics(rig_factory):
    """Correlator.carrier_lock reaches the trackers through the compiled decoder: LOST ones are counted per
    tracker (and in the summary line), UNKNOWN ones apart; tracked as any other (the default), so the level stays
    OK and the IMM keeps its lock."""
    rig = rig_factory({'method': 'both', 'diagnostics_period_s': 0.01})
    rng = np.random.default_rng(5)
    for k in range(1, 41):
        msg = clean_array(k, rng=rng)
        msg.correlators[0].carrier_lock = Correlator.CARRIER_LOCK_LOST if k > 30 else Correlator.CARRIER_LOCK_HELD
        rig.send(msg)  # svid 7 leaves it unset: CARRIER_LOCK_UNKNOWN
    values = rig.last_values()
    for method in ('imm', 'pll'):
        assert values[f'{method}.correlator_unlocked'] == '10'
        assert values[f'{method}.correlator_lock_unknown'] == '40'
    assert values['imm.locked_on_correlator_unlocked'] == '10'  # the IMM held lock through them
    assert values['imm.coasted_correlator_unlocked'] == '0'
    status = rig.diagnostics[-1].status[0]
    assert status.level == DiagnosticStatus.OK and '10 correlators came with the correlator unlocked' in status.message
    assert all(e.locked for e in rig.estimates[-1].estimates)


def test_bad_input_is_counted_in_diagnostics_and_never_locked_nan(rig_factory):
    rig = rig_factory({'method': 'both', 'diagnostics_period_s': 0.01})
    k = 0
    for k in range(1, 11):
        rig.send(clean_array(k))
    assert rig.diagnostics[-1].status[0].level == DiagnosticStatus.OK
    bad = [
        correlator(3, i=math.nan),            # NaN I
        correlator(7, q=math.inf),             # inf Q
        correlator(9, t=0.0),                  # T <= 0
        correlator(10, t=-0.02),
        correlator(11, cn0=95.0),              # C/N0 outside 0..70 dB-Hz
        correlator(12, cn0=-3.0),
        correlator(0),                         # svid 0 is not a satellite
        correlator(13, dphi=math.nan),         # predicted phase change not finite
    ]
    k += 1
    rig.send(array(START_NS + k * T_NS, bad))
    assert rig.diagnostics[-1].status[0].level == DiagnosticStatus.WARN
    # The same satellite twice in one array: the second is rejected.
    k += 1
    rig.send(array(START_NS + k * T_NS, [correlator(3), correlator(3), correlator(7)]))
    # Stamps going backwards, or repeating: the whole array is rejected.
    rig.send(array(START_NS + (k - 5) * T_NS, [correlator(3), correlator(7)]))
    rig.send(array(START_NS + k * T_NS, [correlator(3), correlator(7)]))
    # A refused stamp never drives the diagnostics timer: the next accepted array reports the rejections.
    n_diagnostics = len(rig.diagnostics)
    rig.send(clean_array(k + 1))
    assert len(rig.diagnostics) == n_diagnostics + 1
    values = rig.last_values()
    assert values['arrays_received'] == '15'
    assert values['rejected_arrays_stamp_not_increasing'] == '2'
    assert values['correlators_in_rejected_arrays'] == '4'
    assert values['arrays_processed'] == '13' and len(rig.estimates) == 13
    for m in ('imm', 'pll'):
        assert values[f'{m}.rejected_nonfinite_iq'] == '2'
        assert values[f'{m}.rejected_integration_time'] == '2'
        assert values[f'{m}.rejected_cn0_range'] == '2'
        assert values[f'{m}.rejected_invalid_svid'] == '1'
        assert values[f'{m}.rejected_predicted_phase'] == '1'
        assert values[f'{m}.rejected_duplicate_channel'] == '1'
        # 10 clean arrays of 2 + the duplicate array's 2 accepted samples + the last clean array.
        assert values[f'{m}.processed'] == '24'
    assert values['correlators_received'] == str(20 + 8 + 3 + 4 + 2)
    assert values['accounting_ok'] == 'True'
    assert rig.diagnostics[-1].status[0].level == DiagnosticStatus.WARN
    # The array with only bad samples is answered with an empty array; nothing NaN is locked.
    assert len(rig.estimates[10].estimates) == 0
    for out in rig.estimates:
        for e in out.estimates:
            assert not e.locked or (math.isfinite(e.phase_rad) and math.isfinite(e.frequency_hz))
    # A later clean array is processed normally and the level returns to OK.
    rig.send(clean_array(k + 2))
    assert rig.diagnostics[-1].status[0].level == DiagnosticStatus.OK


def test_a_satellite_that_disappears_is_dropped_after_the_timeout(rig_factory):
    rig = rig_factory({'method': 'both', 'channel_timeout_s': 0.5, 'diagnostics_period_s': 0.01})
    for k in range(1, 11):
        rig.send(clean_array(k, svids=(3, 7)))
    # Satellite 7 disappears at interval 11. It is kept while unseen for up to 0.5 s (25 intervals) ...
    for k in range(11, 36):
        rig.send(clean_array(k, svids=(3,)))
    values = rig.last_values()
    assert values['imm.channels'] == values['pll.channels'] == '2'
    assert values['imm.channels_dropped_timeout'] == '0'
    # ... and dropped on the first array more than 0.5 s after its last sample.
    rig.send(clean_array(36, svids=(3,)))
    values = rig.last_values()
    assert values['imm.channels'] == values['pll.channels'] == '1'
    assert values['imm.channels_dropped_timeout'] == values['pll.channels_dropped_timeout'] == '1'
    assert all(e.svid == 3 for out in rig.estimates[10:] for e in out.estimates)
    # When it comes back it starts afresh (counted), first estimate unlocked.
    rig.send(clean_array(37, svids=(3, 7)))
    values = rig.last_values()
    assert values['imm.channels_started'] == values['pll.channels_started'] == '3'
    assert not any(e.locked for e in rig.estimates[-1].estimates if e.svid == 7)


def test_config_file_is_generated_and_gives_the_defaults(rig_factory):
    """config/imm_carrier.yaml is written by tools/generate_config.py from the parameter definitions."""
    from imm_carrier.node_params import CONFIG_FILE

    testing.check_config_file(rig_factory, CONFIG_FILE, CONFIG, 'imm_carrier_node')


def test_tracker_parameters_are_defined_once_in_the_core():
    """The node's tracker parameters take default, description and range from the core dataclasses (one
    definition each), and the default node parameters give the cores' default parameters."""
    import dataclasses

    from imm_carrier.imm import ImmParams
    from imm_carrier.pll import PllParams
    from imm_carrier.tracker import TrackerParams

    node = {f.name: f for f in dataclasses.fields(CarrierNodeParams)}
    pairs = [(f'pll_{f.name}', f) for f in dataclasses.fields(PllParams) if 'rfi_doc' in f.metadata]
    pairs += [('carrier_frequency_hz' if f.name == 'carrier_hz' else f.name, f)
              for f in dataclasses.fields(ImmParams) if 'rfi_doc' in f.metadata]
    pairs += [(f.name, f) for f in dataclasses.fields(TrackerParams) if 'rfi_doc' in f.metadata]
    assert len(pairs) == 21
    for name, core in pairs:
        assert node[name].metadata['rfi_doc'] == core.metadata['rfi_doc'], name
        assert node[name].default == core.default, name
    for method in ('imm', 'pll'):
        assert CarrierNodeParams().tracker_params(method) == TrackerParams(method=method)


@pytest.mark.parametrize('params, words', [
    ({'method': 'kalman'}, 'method'),
    ({'pll_start_bandwidth_hz': 2.0, 'pll_end_bandwidth_hz': 5.0}, 'end_bandwidth_hz'),
    ({'clock_h0_s': 1e-21}, 'clock_h0_s'),
    ({'channel_timeout_s': 0.0}, 'channel_timeout_s'),
    ({'bit_transition_probability': 1.5}, 'bit_transition_probability'),
])
def test_invalid_parameters_give_one_line_errors(params, words):
    error = testing.start_error(
        lambda context, overrides: ImmCarrierNode(context=context, parameter_overrides=overrides), params)
    assert words in error and '\n' not in error


def test_custom_clock_is_used(rig_factory):
    rig = rig_factory({'clock_preset': 'custom', 'clock_h0_s': 1e-21, 'clock_h_minus2_hz': 2e-20})
    clock = rig.node.trackers['imm'].params.imm.clock
    assert (clock.h0, clock.h_minus2) == (1e-21, 2e-20)


def test_a_core_fault_is_counted_and_the_node_keeps_going(rig_factory, monkeypatch):
    """If the core raises an ArithmeticError on accepted input, the node counts it, restarts that tracker's
    channels, goes to ERROR and keeps answering; the PLL beside it is untouched."""
    rig = rig_factory({'method': 'both', 'diagnostics_period_s': 0.01})
    process_arrays = tracker_module.CarrierTracker.process_arrays
    calls = Counter()

    def faulty(self, *args, **kwargs):
        if self.params.method == 'imm':
            calls['n'] += 1
            if calls['n'] == 8:  # interval 8
                raise ZeroDivisionError('injected')
        return process_arrays(self, *args, **kwargs)

    monkeypatch.setattr(tracker_module.CarrierTracker, 'process_arrays', faulty)
    for k in range(1, 8):
        rig.send(clean_array(k))
    rig.send(clean_array(8))
    values = rig.last_values()
    assert rig.diagnostics[-1].status[0].level == DiagnosticStatus.ERROR
    assert values['imm.core_faults'] == '1' and values['imm.dropped_core_fault'] == '2'
    assert values['accounting_ok'] == 'True'
    assert [e.method for e in rig.estimates[-1].estimates] == [CarrierPhase.PLL, CarrierPhase.PLL]
    for k in range(9, 12):
        rig.send(clean_array(k))
    values = rig.last_values()
    assert values['imm.channels_started'] == '4' and values['imm.processed'] == str(2 * 10)
    assert values['pll.processed'] == str(2 * 11) and values['accounting_ok'] == 'True'
    assert rig.diagnostics[-1].status[0].level == DiagnosticStatus.OK
    assert len(rig.estimates) == 11 and len(rig.estimates[-1].estimates) == 4


def test_half_cycle_glitch_at_high_cn0_and_1ms_does_not_stop_the_node(rig_factory):
    """T = 1 ms at 60 dB-Hz with one sign-flipped correlator inside a data bit (a mode probability that
    underflows to 0 must not make the IMM core divide by zero: see imm.imm_step). The node must answer every
    array, account for every correlator, never publish a non-finite locked estimate, and see no core fault."""
    rig = rig_factory({'method': 'imm', 'diagnostics_period_s': 0.01})
    rng = np.random.default_rng(5)
    sigma = 1.0 / math.sqrt(2 * 0.001 * 1e6)
    n = 61  # the last array falls on a diagnostics report (every 10 ms of stamp time)
    for k in range(1, n + 1):
        theta = 0.01 * k + 0.4
        sign = -1.0 if k == 30 else 1.0
        i, q = sign * math.cos(theta) + sigma * rng.normal(), sign * math.sin(theta) + sigma * rng.normal()
        rig.send(array(START_NS + k * 1_000_000, [correlator(5, i=i, q=q, t=0.001, cn0=60.0, dphi=0.01)]))
    values = rig.last_values()
    assert len(rig.estimates) == n and values['accounting_ok'] == 'True'
    assert 'imm.core_faults' not in values and values['imm.processed'] == str(n)
    assert rig.diagnostics[-1].status[0].level == DiagnosticStatus.OK
    for out in rig.estimates:
        for e in out.estimates:
            assert not e.locked or (math.isfinite(e.phase_rad) and math.isfinite(e.frequency_hz))
    assert rig.estimates[-1].estimates[0].locked


# ------------------------------------------------------------------ hostile input (issue 12)
def array_at(sec: int, nanosec: int, correlators) -> CorrelatorArray:
    """An array with any header stamp, also one that is not a valid ROS time (negative, nanosec >= 1e9)."""
    msg = CorrelatorArray(correlators=list(correlators))
    msg.header.stamp.sec = sec
    msg.header.stamp.nanosec = nanosec
    msg.header.frame_id = 'gnss_receiver'
    return msg


def level(rig) -> bytes:
    return rig.diagnostics[-1].status[0].level


def assert_no_invalid_locked(rig) -> None:
    for out in rig.estimates:
        for e in out.estimates:
            if e.locked:
                assert math.isfinite(e.phase_rad) and math.isfinite(e.frequency_hz), e
                if e.method == CarrierPhase.IMM:
                    assert 0 < e.phase_std_rad < math.inf and 0 < e.frequency_std_hz < math.inf, e


def test_a_negative_or_unset_stamp_is_counted_and_the_node_keeps_running(rig_factory):
    """Fuzzer finding: a negative header.stamp killed the node (ns_to_stamp raised while publishing diagnostics)."""
    rig = rig_factory({'method': 'both', 'diagnostics_period_s': 0.01})
    for k in range(1, 6):
        rig.send(clean_array(k))
    n_diagnostics = len(rig.diagnostics)
    rig.send(array_at(-5, 0, [correlator(3), correlator(7)]))
    rig.send(array_at(-2**31, 999_999_999, [correlator(3)]))
    rig.send(array_at(0, 0, [correlator(3), correlator(7)]))
    assert len(rig.diagnostics) == n_diagnostics  # a refused stamp never reaches the diagnostics timer
    assert len(rig.estimates) == 5
    rig.send(clean_array(6))
    values = rig.last_values()
    assert values['rejected_arrays_stamp_not_positive'] == '3'
    assert values['correlators_in_rejected_arrays'] == '5'
    assert values['arrays_received'] == '9' and values['arrays_processed'] == '6'
    assert values['accounting_ok'] == 'True' and values[f'input.{TOPIC}.callback_errors'] == '0'
    assert level(rig) == DiagnosticStatus.WARN
    rig.send(clean_array(7))
    assert level(rig) == DiagnosticStatus.OK and len(rig.estimates) == 7


def test_malformed_bytes_are_counted_and_the_node_keeps_running(rig_factory):
    """Fuzzer finding: malformed bytes killed the node (rclpy's deserialize_message raised RMWError, even for a
    4-byte payload). Every such payload is counted as rejected_arrays_malformed; no handler raises."""
    from rclpy.serialization import serialize_message

    rig = rig_factory({'method': 'both', 'diagnostics_period_s': 0.01})
    for k in range(1, 6):
        rig.send(clean_array(k))
    rng = np.random.default_rng(31)
    valid = serialize_message(clean_array(6))
    payloads = [b'\x00\x01\x00\x00', b'\x00\x01\x00\x00' + bytes(4), b'\x00\x00\x00\x00' + b'\xff' * 40,
                rng.integers(0, 256, 3, dtype=np.uint8).tobytes(),
                b'\x00\x01\x00\x00' + rng.integers(0, 256, 200, dtype=np.uint8).tobytes(),
                valid[:len(valid) - 7], valid[:17], valid[:12] + b'\xff\xff\xff\x7f' + valid[16:]]
    for payload in payloads:
        rig.send(payload)
    for k in range(6, 9):
        rig.send(clean_array(k))
    values = rig.last_values()
    assert values['rejected_arrays_malformed'] == str(len(payloads))
    assert values[f'input.{TOPIC}.received'] == str(5 + len(payloads) + 3)
    assert values[f'input.{TOPIC}.callback_errors'] == '0'
    assert values['arrays_processed'] == '8' and values['accounting_ok'] == 'True'
    assert len(rig.estimates) == 8 and all(len(out.estimates) == 4 for out in rig.estimates)


def test_one_far_future_stamp_does_not_stall_the_node(rig_factory):
    """Fuzzer finding: one far-future stamp made every later valid array 'not increasing', for good."""
    rig = rig_factory({'method': 'both', 'diagnostics_period_s': 0.01})
    for k in range(1, 21):
        rig.send(clean_array(k))
    rig.send(array_at(2**31 - 1, 0, [correlator(3), correlator(7)]))
    rig.send(array_at(1, 0, [correlator(3), correlator(7)]))  # far past
    rig.send(array_at(5, 2_000_000_000, [correlator(3)]))  # nanosec >= 1e9: not a ROS time
    for k in range(21, 31):
        rig.send(clean_array(k))
    values = rig.last_values()
    assert values['rejected_arrays_stamp_far_future'] == '1'
    assert values['rejected_arrays_stamp_far_past'] == '1'
    assert values['rejected_arrays_stamp_malformed'] == '1'
    assert values['stamp_restarts'] == '0' and values['arrays_processed'] == '30'
    assert values['accounting_ok'] == 'True'
    assert all(e.locked for e in rig.estimates[-1].estimates)
    assert [stamp_of(m) for m in rig.estimates] == [START_NS + k * T_NS for k in range(1, 31)]


def test_a_confirmed_stamp_jump_starts_a_new_time_line_and_restarts_the_channels(rig_factory):
    rig = rig_factory({'method': 'both', 'diagnostics_period_s': 0.01, 'max_stamp_jump_s': 10.0,
                       'stamp_jump_confirmations': 3})
    for k in range(1, 21):
        rig.send(clean_array(k))
    jump = 50_000  # intervals: 1000 s later (a receiver clock reset)
    for k in range(jump + 1, jump + 4):
        rig.send(clean_array(k))
    values = rig.last_values()
    assert values['rejected_arrays_stamp_far_future'] == '2' and values['stamp_restarts'] == '1'
    assert values['imm.channels_restarted_stamp_jump'] == values['pll.channels_restarted_stamp_jump'] == '2'
    assert stamp_of(rig.estimates[-1]) == START_NS + (jump + 3) * T_NS
    assert not any(e.locked for e in rig.estimates[-1].estimates)  # restarted channels start unlocked
    for k in range(jump + 4, jump + 30):
        rig.send(clean_array(k))
    assert all(e.locked for e in rig.estimates[-1].estimates)
    assert rig.last_values()['accounting_ok'] == 'True'


def test_physically_impossible_correlators_are_rejected_and_never_published_locked(rig_factory):
    """Fuzzer finding: integration_time_s = 1e6 gave the IMM a -6062 rad phase jump with phase_std 0 and locked,
    and the PLL a frequency of -2.8e14 Hz that never recovered. Each fault of the issue, in every correlator of
    one array, is rejected per correlator under its reason; the trackers stay locked and sane."""
    rig = rig_factory({'method': 'both', 'diagnostics_period_s': 0.01})
    rng = np.random.default_rng(8)
    for k in range(1, 31):
        rig.send(clean_array(k, rng=rng))
    faults = [('integration_time_s', 1e6), ('in_phase', 1e300), ('quadrature', -1e300), ('integration_time_s', 0.0),
              ('integration_time_s', -0.001), ('in_phase', math.nan), ('cn0_dbhz', 1e300),
              ('predicted_phase_change_rad', math.inf), ('integration_time_s', 5e-324),
              ('predicted_phase_change_rad', 1e9)]
    k = 30
    for name, value in faults:
        k += 1
        msg = clean_array(k, rng=rng)
        for c in msg.correlators:
            setattr(c, name, value)
        rig.send(msg)
        assert rig.estimates[-1].estimates == []
    for j in range(k + 1, k + 21):
        rig.send(clean_array(j, rng=rng))
    values = rig.last_values()
    for m in ('imm', 'pll'):
        assert values[f'{m}.rejected_integration_time'] == str(2 * 4)
        assert values[f'{m}.rejected_iq_magnitude'] == str(2 * 2)
        assert values[f'{m}.rejected_nonfinite_iq'] == '2'
        assert values[f'{m}.rejected_cn0_range'] == '2'
        assert values[f'{m}.rejected_predicted_phase'] == str(2 * 2)
        # Nothing reached the filters (the 10 intervals without an accepted correlator restart each channel once,
        # as any gap does), so no channel was thrown off.
        assert values[f'{m}.channels_restarted_gap'] == '2' and values[f'{m}.channels_started'] == '4'
        assert values[f'{m}.channels_restarted_diverged'] == values[f'{m}.channels_restarted_nonfinite'] == '0'
        assert values[f'{m}.locked_suppressed_invalid'] == '0'
    assert values['accounting_ok'] == 'True'
    assert_no_invalid_locked(rig)
    last = rig.estimates[-1].estimates
    assert len(last) == 4 and all(e.locked and abs(e.frequency_hz) < 1.0 for e in last)


def test_an_estimate_with_a_zero_std_is_never_published_locked(rig_factory):
    """With the T range opened up to 1e7 s, T = 1e6 s reaches the IMM as before the fix: its covariance cancels
    to 0. The final check publishes it unlocked (counted), the channel restarts and locks again; level WARN."""
    rig = rig_factory({'method': 'both', 'diagnostics_period_s': 0.01, 'max_integration_time_s': 10.0})
    rig.node.trackers['imm'] = tracker_module.CarrierTracker(  # the node's parameter stops at 10 s
        tracker_module.TrackerParams(method='imm', max_integration_time_s=1e7))
    rig.node.trackers['pll'] = tracker_module.CarrierTracker(
        tracker_module.TrackerParams(method='pll', max_integration_time_s=1e7))
    rng = np.random.default_rng(2)
    for k in range(1, 31):
        rig.send(clean_array(k, rng=rng))
    msg = clean_array(31, rng=rng)
    for c in msg.correlators:
        c.integration_time_s = 1e6
    rig.send(msg)
    assert not any(e.locked for e in rig.estimates[-1].estimates)
    values = rig.last_values()
    assert int(values['imm.locked_suppressed_invalid']) == 2 and values['imm.channels_restarted_diverged'] == '2'
    assert level(rig) == DiagnosticStatus.WARN
    for k in range(32, 60):
        rig.send(clean_array(k, rng=rng))
    assert_no_invalid_locked(rig)
    assert all(e.locked and abs(e.frequency_hz) < 1.0 for e in rig.estimates[-1].estimates)
    assert level(rig) == DiagnosticStatus.OK


def test_a_best_effort_publisher_reaches_the_node_and_is_processed(rig_factory):
    """A sensor driver publishes best effort (qos_profile_sensor_data); a reliable subscription refused it."""
    from rclpy.qos import ReliabilityPolicy, qos_profile_sensor_data

    rig = rig_factory({'method': 'imm', 'diagnostics_period_s': 0.01}, reliable=False,
                      publisher_qos=qos_profile_sensor_data)
    assert rig.node.subscription.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
    for k in range(1, 21):
        rig.send(clean_array(k))
    values = rig.last_values()
    assert values[f'input.{TOPIC}.received'] == '20' and values[f'input.{TOPIC}.lost'] == '0'
    assert values['arrays_processed'] == '20' and len(rig.estimates) == 20
    assert all(e.locked for e in rig.estimates[-1].estimates)


def test_a_silent_node_reports_stale_with_its_counters(rig_factory):
    rig = rig_factory({'input_timeout_s': 0.2, 'diagnostics_period_s': 0.01})
    rig.spin_until(lambda: any(d.status[0].level == DiagnosticStatus.STALE for d in rig.diagnostics))
    stale = next(d for d in rig.diagnostics if d.status[0].level == DiagnosticStatus.STALE)
    values = {kv.key: kv.value for kv in stale.status[0].values}
    assert 'no input' in stale.status[0].message and stale.status[0].name == 'imm_carrier'
    assert values[f'input.{TOPIC}.received'] == '0' and values['arrays_received'] == '0'
    assert values['accounting_ok'] == 'True'
    assert stamp_of(stale) > 0  # the node clock's now: the only wall-clock use
    n = len(rig.diagnostics)
    for k in range(1, 4):
        rig.send(clean_array(k))
    assert any(d.status[0].level == DiagnosticStatus.OK and stamp_of(d) == START_NS + T_NS
               for d in rig.diagnostics[n:])


def test_a_handler_error_is_counted_reported_as_error_and_accounted(rig_factory, monkeypatch):
    """The subscription's guard is the last net: should the node itself raise, the array is counted
    (arrays_dropped_handler_error), the accounting still adds up, the next report is ERROR, the node goes on."""
    from imm_carrier import imm_carrier_node

    rig = rig_factory({'method': 'imm', 'diagnostics_period_s': 0.01})
    for k in range(1, 4):
        rig.send(clean_array(k))
    encode = imm_carrier_node.encode_carrier_phase_array
    calls = Counter()

    def failing(*args):
        calls['n'] += 1
        if calls['n'] == 1:
            raise RuntimeError('injected')
        return encode(*args)

    monkeypatch.setattr(imm_carrier_node, 'encode_carrier_phase_array', failing)
    rig.send(clean_array(4))
    rig.send(clean_array(5))
    values = rig.last_values()
    assert values[f'input.{TOPIC}.callback_errors'] == '1' and values['arrays_dropped_handler_error'] == '1'
    assert values['arrays_received'] == '5' and values['arrays_processed'] == '4'
    assert values['accounting_ok'] == 'True' and level(rig) == DiagnosticStatus.ERROR
    rig.send(clean_array(6))
    assert level(rig) == DiagnosticStatus.OK


def test_lost_messages_raise_the_level_to_warn(rig_factory):
    rig = rig_factory({'method': 'imm', 'diagnostics_period_s': 0.01})
    for k in range(1, 4):
        rig.send(clean_array(k))
    assert level(rig) == DiagnosticStatus.OK
    rig.node.health.middleware_lost(TOPIC, 3)  # what the subscription's message-lost event handler records
    rig.send(clean_array(4))
    assert level(rig) == DiagnosticStatus.WARN and 'messages lost 3/' in rig.diagnostics[-1].status[0].message
    assert rig.last_values()[f'input.{TOPIC}.middleware_lost'] == '3'
    rig.send(clean_array(5))
    assert level(rig) == DiagnosticStatus.OK


HOSTILE_FLOATS = (math.nan, math.inf, -math.inf, 1e300, -1e300, 5e-324, -5e-324, 0.0, -1.0, 1e150, -1e9, 1e9,
                  1e-4, 0.1, 99.0, 70.0, 1e5)
FIELDS = ('integration_time_s', 'in_phase', 'quadrature', 'cn0_dbhz', 'predicted_phase_change_rad')


def test_fuzzed_arrays_never_raise_and_never_publish_an_invalid_locked_estimate():
    """Seeded in-process fuzz of the whole handler (no DDS: on_correlators called with the bytes): 3000 arrays,
    a third clean, the rest with hostile correlator fields (on newer stamps, so that they reach the trackers),
    hostile ids, random or truncated bytes, or hostile stamps. Nothing raises, every array is accounted, no
    published estimate is locked unless valid, and clean input afterwards is tracked and locked again."""
    from rclpy.serialization import deserialize_message, serialize_message

    context = Context()
    rclpy.init(context=context)
    node = ImmCarrierNode(context=context, parameter_overrides=[
        Parameter('method', value='both'), Parameter('input_timeout_s', value=0.0)])
    published: list[bytes] = []
    node.estimates_pub.publish = published.append
    node.diag_pub.publish = lambda msg: None
    rng = np.random.default_rng(20261201)
    try:
        k = 0
        for _ in range(3000):
            kind = rng.integers(6)
            k += 1
            msg = clean_array(k, svids=(3, 7, 11), rng=rng)
            if kind in (1, 2):  # hostile field values
                for _ in range(int(rng.integers(1, 4))):
                    c = msg.correlators[int(rng.integers(3))]
                    setattr(c, FIELDS[int(rng.integers(len(FIELDS)))],
                            HOSTILE_FLOATS[int(rng.integers(len(HOSTILE_FLOATS)))])
            elif kind == 3:  # hostile ids and sizes
                c = msg.correlators[int(rng.integers(3))]
                c.svid = int(rng.choice([0, 255, 256, 65535]))
                c.constellation = int(rng.choice([0, 255]))
                if rng.random() < 0.3:
                    msg.correlators = msg.correlators + [msg.correlators[0]]
            raw = serialize_message(msg)
            if kind == 4:  # bytes: random, truncated or overwritten
                choice = rng.integers(3)
                if choice == 0:
                    raw = rng.integers(0, 256, int(rng.integers(1, 300)), dtype=np.uint8).tobytes()
                elif choice == 1:
                    raw = raw[:int(rng.integers(0, len(raw)))]
                else:
                    buf = bytearray(raw)
                    for _ in range(int(rng.integers(1, 6))):
                        buf[int(rng.integers(len(buf)))] = int(rng.integers(256))
                    raw = bytes(buf)
            elif kind == 5:  # hostile stamps
                sec = int(rng.choice([0, -1, -2**31, 2**31 - 1, 1, 2 * 10**9]))
                raw = serialize_message(array_at(sec, int(rng.integers(10**9)), msg.correlators))
            node.on_correlators(raw)
        for j in range(k + 1, k + 60):
            node.on_correlators(serialize_message(clean_array(j, svids=(3, 7, 11), rng=rng)))
        values = node.accounting()
        assert values['accounting_ok'] is True and values['arrays_received'] == 3000 + 59
        assert values['arrays_dropped_handler_error'] == 0
        assert values['rejected_arrays_malformed'] > 100
        for m in ('imm', 'pll'):
            for key in ('rejected_integration_time', 'rejected_nonfinite_iq', 'rejected_cn0_range',
                        'rejected_predicted_phase', 'rejected_iq_magnitude', 'rejected_invalid_svid'):
                assert values[f'{m}.{key}'] > 10, (m, key, values)
        outs = [deserialize_message(raw, CarrierPhaseArray) for raw in published]
        for out in outs:
            for e in out.estimates:
                if e.locked:
                    assert math.isfinite(e.phase_rad) and math.isfinite(e.frequency_hz), e
                    assert e.method == CarrierPhase.PLL or (0 < e.phase_std_rad < math.inf
                                                             and 0 < e.frequency_std_hz < math.inf), e
        assert len(outs[-1].estimates) == 6 and all(e.locked for e in outs[-1].estimates)
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


def test_levels_use_fractions_over_the_window_and_name_the_hardware(rig_factory):
    """One rejected array in 50 (2 %) over the 0.4 s window stays OK; a burst of rejections is WARN until it
    leaves the window. hardware_id is the parameter, not the node name."""
    rig = rig_factory({'method': 'imm', 'diagnostics_period_s': 0.02, 'diagnostics_window_s': 0.4,
                       'hardware_id': 'ublox-zed#1'})
    k = 0
    for k in range(1, 41):
        rig.send(clean_array(k))
        if k == 20:
            rig.send(array(START_NS + (k - 3) * T_NS, [correlator(3), correlator(7)]))   # stamp going back
    status = rig.diagnostics[-1].status[0]
    assert status.level == DiagnosticStatus.OK and status.hardware_id == 'ublox-zed#1'
    assert rig.last_values()['rejected_arrays_stamp_not_increasing'] == '1'
    for _ in range(4):   # 4 of the next ~20 arrays rejected: 20 %
        k += 1
        rig.send(clean_array(k))
        rig.send(array(START_NS + (k - 3) * T_NS, [correlator(3), correlator(7)]))
    k += 1
    rig.send(clean_array(k))   # a refused stamp never drives the report: the next accepted one does
    status = rig.diagnostics[-1].status[0]
    assert status.level == DiagnosticStatus.WARN and 'arrays rejected 4/' in status.message
    for _ in range(25):   # 0.5 s of clean arrays: the burst leaves the window
        k += 1
        rig.send(clean_array(k))
    assert rig.diagnostics[-1].status[0].level == DiagnosticStatus.OK


def test_settable_parameters_change_while_running_and_tracker_parameters_stay_read_only(rig_factory):
    from rfi_node_common.params import set_parameters_remotely

    rig = rig_factory({'method': 'imm', 'diagnostics_period_s': 0.01})
    for k in range(1, 6):
        rig.send(clean_array(k))

    def param_set(**values):
        return set_parameters_remotely(rig.io, rig.executor, '/imm_carrier', values)

    assert all(r.successful for r in param_set(hardware_id='receiver#2', warn_rejected_fraction=0.3))
    rig.send(clean_array(6))
    assert rig.diagnostics[-1].status[0].hardware_id == 'receiver#2' and rig.node.params.warn_rejected_fraction == 0.3
    for name, value in (('lock_phase_std_max_rad', 0.3), ('method', 'pll'), ('channel_timeout_s', 2.0)):
        (result,) = param_set(**{name: value})
        assert not result.successful and 'read-only' in result.reason, name
    (result,) = param_set(warn_lost_fraction=1.5)
    assert not result.successful and 'out of range' in result.reason
    assert rig.node.params.lock_phase_std_max_rad == 0.5
