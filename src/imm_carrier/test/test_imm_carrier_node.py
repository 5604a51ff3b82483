"""In-process tests of ImmCarrierNode: one Context per test, a SingleThreadedExecutor, bounded spins.

Each test publishes CorrelatorArrays from a test node and spins until the node has taken every one
and everything it published has arrived (counted, never slept for).
"""

from __future__ import annotations

import math
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import rclpy
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from gnss_common.gps_time import gps_to_stamp_ns
from imm_carrier import tracker as tracker_module
from imm_carrier.imm_carrier_node import CarrierNodeParams, ImmCarrierNode
from rfi_msgs.msg import CarrierPhase, CarrierPhaseArray, Correlator, CorrelatorArray
from rfi_node_common.qos import DATA_QOS
from rfi_node_common.stamps import ns_to_stamp

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'imm_carrier.yaml'
START_NS = gps_to_stamp_ns(2300, 345600.0)  # on the 20 ms GPS bit grid
T_S = 0.02
T_NS = 20_000_000
SPIN_DEADLINE_S = 10.0


class Rig:
    """The node under test plus a test node that publishes correlators and collects the outputs."""

    def __init__(self, params: dict | None = None, args: list[str] | None = None) -> None:
        self.context = Context()
        rclpy.init(args=args, context=self.context)
        overrides = [Parameter(k, value=v) for k, v in (params or {}).items()]
        self.node = ImmCarrierNode(context=self.context, parameter_overrides=overrides)
        self.io = Node('imm_carrier_test_io', context=self.context)
        self.pub = self.io.create_publisher(CorrelatorArray, '/gnss/correlators', DATA_QOS)
        self.estimates: list[CarrierPhaseArray] = []
        self.diagnostics: list[DiagnosticArray] = []
        self.io.create_subscription(CarrierPhaseArray, '/carrier/estimates', self.estimates.append, DATA_QOS)
        self.io.create_subscription(DiagnosticArray, '/diagnostics', self.diagnostics.append, DATA_QOS)
        self.published: Counter[str] = Counter()
        for pub in (self.node.estimates_pub, self.node.diag_pub):
            pub.publish = self._counting(pub.publish, pub.topic_name)
        self.sent = 0
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.io)
        self._spin_until(lambda: self.pub.get_subscription_count() >= 1
                         and self.node.estimates_pub.get_subscription_count() >= 1
                         and self.node.diag_pub.get_subscription_count() >= 1)

    def _counting(self, publish, topic):
        def counted(msg):
            self.published[topic] += 1
            publish(msg)
        return counted

    def _spin_until(self, done) -> None:
        deadline = time.monotonic() + SPIN_DEADLINE_S
        while not done():
            assert time.monotonic() < deadline, 'graph did not settle'
            self.executor.spin_once(timeout_sec=0.05)

    def send(self, msg: CorrelatorArray) -> None:
        """Publish one array and spin until the node has answered it completely."""
        self.pub.publish(msg)
        self.sent += 1
        self._spin_until(lambda: self.node.counts['arrays_received'] == self.sent
                         and len(self.estimates) == self.published['/carrier/estimates']
                         and len(self.diagnostics) == self.published['/diagnostics'])

    def last_values(self) -> dict[str, str]:
        return {kv.key: kv.value for kv in self.diagnostics[-1].status[0].values}

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.io.destroy_node()
        rclpy.shutdown(context=self.context)


@pytest.fixture
def rig_factory():
    rigs = []

    def make(params=None, args=None):
        rig = Rig(params, args)
        rigs.append(rig)
        return rig

    yield make
    for rig in rigs:
        rig.close()


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
    values = rig.last_values()
    assert values['arrays_received'] == '14'
    assert values['rejected_arrays_stamp_not_increasing'] == '2'
    assert values['correlators_in_rejected_arrays'] == '4'
    assert values['arrays_processed'] == '12' and len(rig.estimates) == 12
    for m in ('imm', 'pll'):
        assert values[f'{m}.rejected_nonfinite_iq'] == '2'
        assert values[f'{m}.rejected_integration_time'] == '2'
        assert values[f'{m}.rejected_cn0_range'] == '2'
        assert values[f'{m}.rejected_invalid_svid'] == '1'
        assert values[f'{m}.rejected_predicted_phase'] == '1'
        assert values[f'{m}.rejected_duplicate_channel'] == '1'
        # 10 clean arrays of 2 + the duplicate array's 2 accepted samples.
        assert values[f'{m}.processed'] == '22'
    assert values['correlators_received'] == str(20 + 8 + 3 + 4)
    assert values['accounting_ok'] == 'True'
    # The array with only bad samples is answered with an empty array; nothing NaN is locked.
    assert len(rig.estimates[10].estimates) == 0
    for out in rig.estimates:
        for e in out.estimates:
            assert not e.locked or (math.isfinite(e.phase_rad) and math.isfinite(e.frequency_hz))
    # A later clean array is processed normally and the level returns to OK.
    rig.send(clean_array(k + 1))
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


def test_config_file_values_equal_the_dataclass_defaults(rig_factory):
    fields = CarrierNodeParams.__dataclass_fields__
    data = yaml.safe_load(CONFIG.read_text())['imm_carrier']['ros__parameters']
    assert set(data) == set(fields)
    rig = rig_factory(args=['imm_carrier_node', '--ros-args', '--params-file', str(CONFIG)])
    assert rig.node.params == CarrierNodeParams()
    for name in fields:
        assert rig.node.get_parameter(name).value == getattr(CarrierNodeParams(), name), name


@pytest.mark.parametrize('params, words', [
    ({'method': 'kalman'}, 'method'),
    ({'pll_start_bandwidth_hz': 2.0, 'pll_end_bandwidth_hz': 5.0}, 'end_bandwidth_hz'),
    ({'clock_h0': 1e-21}, 'clock_h0'),
    ({'channel_timeout_s': 0.0}, 'channel_timeout_s'),
    ({'bit_transition_probability': 1.5}, 'bit_transition_probability'),
])
def test_invalid_parameters_give_one_line_errors(params, words):
    context = Context()
    rclpy.init(context=context)
    try:
        with pytest.raises(ValueError) as err:
            ImmCarrierNode(context=context, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
        assert words in str(err.value) and '\n' not in str(err.value)
    finally:
        rclpy.shutdown(context=context)


def test_custom_clock_is_used(rig_factory):
    rig = rig_factory({'clock_preset': 'custom', 'clock_h0': 1e-21, 'clock_h_minus2': 2e-20})
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
    """T = 1 ms at 60 dB-Hz with one sign-flipped correlator inside a data bit (up to commit 8350ac4 the IMM core
    raised ZeroDivisionError here: see imm._imm_step). The node must answer every array, account for every
    correlator, never publish a non-finite locked estimate, and (since the fix) see no core fault."""
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
