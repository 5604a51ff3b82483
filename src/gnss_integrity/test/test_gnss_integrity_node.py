"""In-process tests of GnssIntegrityNode: one Context per test, a SingleThreadedExecutor, bounded spins."""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

from gnss_integrity import outcome
from gnss_integrity.gnss_integrity_node import GnssIntegrityNode, IntegrityNodeParams
from rfi_msgs.msg import (
    GnssIntegrity,
    GnssMeasurementArray,
    IntegrityTest,
    JammerState,
    ReceiverInterference,
    ReceiverSpectrum,
    UwbRange,
)
from rfi_node_common import testing
from rfi_node_common.conversions import epoch_to_msg, uwb_to_msg
from rfi_node_common.qos import DATA_QOS
from rfi_node_common.testing import NodeRig
from rfi_sim.gnss_uwb import BroadcastGeometry, GnssUwbScenario, simulate
from rfi_sim.spoofing import apply_attack
from rfi_sim.spoofing_attack import SpoofingAttack

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'gnss_integrity.yaml'
NAV = Path(__file__).resolve().parents[2] / 'rfi_experiments' / 'data' / 'arlm2000.15n'
TOPICS = {'/gnss/measurements': GnssMeasurementArray, '/uwb/ranges': UwbRange,
          '/gnss/receiver_interference': ReceiverInterference, '/gnss/receiver_spectrum': ReceiverSpectrum,
          '/rfi/jammer_state': JammerState}


class Rig(NodeRig):
    def __init__(self, params: dict | None = None, args: list[str] | None = None) -> None:
        params = dict(params or {})
        if args is None:
            params.setdefault('input_timeout_s', 0.0)  # no wall-clock STALE report in the middle of a test
        for topic in TOPICS:
            params.setdefault(f'qos_overrides.{topic}.subscription.reliability', 'reliable')
        super().__init__(lambda context, overrides: GnssIntegrityNode(context=context, parameter_overrides=overrides),
                         inputs={t: (c, DATA_QOS) for t, c in TOPICS.items()},
                         outputs={'/gnss/integrity': GnssIntegrity, '/diagnostics': DiagnosticArray},
                         params=params, args=args, name='gnss_integrity_test_io')
        self.sent = 0

    def send(self, topic: str, msg) -> None:
        self.pubs[topic].publish(msg)
        self.sent += 1
        self.settle_until(lambda: sum(self.node.counts[f'{k}_received'] for k in
                                      ('gnss', 'uwb', 'receiver', 'spectrum', 'sdr')) == self.sent)

    def last_values(self) -> dict[str, str]:
        return {kv.key: kv.value for kv in self.out['/diagnostics'][-1].status[0].values}


@pytest.fixture
def rig_factory():
    with testing.rig_factory(Rig) as make:
        yield make


@cache
def _run():
    geo = BroadcastGeometry(NAV)
    return simulate(GnssUwbScenario(duration_s=40.0, seed=5, uwb_rate_hz=5.0), geo, geo.iono_alpha, geo.iono_beta)


def _feed(rig: Rig, epochs, run) -> None:
    items = sorted([(e.stamp_ns, 0, e) for e in epochs] + [(u.stamp_ns, 1, u) for u in run.uwb_ranges],
                   key=lambda t: t[:2])
    for _, kind, m in items:
        if kind:
            rig.send('/uwb/ranges', uwb_to_msg(m))
        else:
            rig.send('/gnss/measurements', epoch_to_msg(m))


def test_core_constants_equal_the_messages():
    for name in ('CATEGORY_JAMMING', 'CATEGORY_CN0', 'CATEGORY_CLOCK', 'CATEGORY_KINEMATICS', 'CATEGORY_CONSISTENCY',
                 'CATEGORY_EXTERNAL', 'DECISION_UNKNOWN', 'DECISION_PASS', 'DECISION_SUSPECT', 'DECISION_ALARM'):
        assert getattr(outcome, name) == getattr(IntegrityTest, name), name
    for name in ('STATE_UNKNOWN', 'STATE_NONE', 'STATE_SUSPECTED', 'STATE_DETECTED', 'SCOPE_NONE', 'SCOPE_SATELLITES',
                 'SCOPE_CONSTELLATIONS', 'SCOPE_ALL', 'EVIDENCE_CN0_ELEVATION', 'EVIDENCE_CN0_COMMON_DROP',
                 'EVIDENCE_RECEIVER_AGC', 'EVIDENCE_RECEIVER_FLAG', 'EVIDENCE_RECEIVER_SPECTRUM',
                 'EVIDENCE_SDR_MONITOR'):
        assert getattr(outcome, name) == getattr(GnssIntegrity, name), name


@pytest.mark.slow
def test_one_report_per_epoch_and_a_push_detected(rig_factory):
    run = _run()
    attack = SpoofingAttack(kind='position_push', start_s=20.0, push_velocity_enu_mps=(1.0, 0.0, 0.0))
    epochs, _ = apply_attack(run.gnss_epochs, attack, run.truth.receiver_ecef_m, seed=1)
    rig = rig_factory()
    _feed(rig, epochs, run)
    reports = rig.out['/gnss/integrity']
    assert len(reports) == len(epochs) and rig.node.counts['published'] == len(epochs)
    t0 = epochs[0].stamp_ns
    stamps = [(r.header.stamp.sec * 10**9 + r.header.stamp.nanosec - t0) / 1e9 for r in reports]
    before = [r for r, t in zip(reports, stamps, strict=True) if t < 20.0]
    after = [r for r, t in zip(reports, stamps, strict=True) if t >= 30.0]
    assert all(r.spoofing_state in (GnssIntegrity.STATE_NONE, GnssIntegrity.STATE_UNKNOWN) for r in before)
    assert all(r.spoofing_state == GnssIntegrity.STATE_DETECTED for r in after)
    assert after[-1].first_detection_stamp.sec > 0 and after[-1].spoofing_scope == GnssIntegrity.SCOPE_ALL
    assert {t.name for t in after[-1].tests} >= {'uwb_displacement', 'clock_step', 'cn0_too_high'}
    diag = rig.out['/diagnostics'][-1].status[0]
    assert diag.level == DiagnosticStatus.WARN, diag.message
    assert diag.level == DiagnosticStatus.WARN and 'spoofing DETECTED' in diag.message
    assert rig.last_values()['accounting_ok'] == 'True'


def test_bad_inputs_are_counted_and_never_kill_the_node(rig_factory):
    run = _run()
    rig = rig_factory()
    good = epoch_to_msg(run.gnss_epochs[0])
    rig.send('/gnss/measurements', good)
    rig.send('/gnss/measurements', good)  # the same stamp again: not increasing
    wrong = epoch_to_msg(run.gnss_epochs[1])
    wrong.header.frame_id = 'map'
    rig.send('/gnss/measurements', wrong)
    uwb = uwb_to_msg(run.uwb_ranges[0])
    uwb.header.frame_id = 'map'
    rig.send('/uwb/ranges', uwb)
    uwb = uwb_to_msg(run.uwb_ranges[1])
    uwb.range_m = math.nan
    rig.send('/uwb/ranges', uwb)
    spectrum = ReceiverSpectrum(center_frequency_hz=1.5834e9, span_hz=1.28e8, resolution_hz=5e5,
                                power_db=[30.0] * 100)  # 100 bins, not 256
    rig.send('/gnss/receiver_spectrum', spectrum)
    rig.send('/rfi/jammer_state', JammerState(type=9))
    c = rig.node.counts
    assert c['gnss_processed'] == 1 and c['gnss_rejected'] == 2
    assert rig.node.reasons['stamp_not_increasing'] == 1 and rig.node.reasons['gnss_frame_id'] == 1
    assert rig.node.reasons['uwb_frame_unsupported'] == 1 and rig.node.reasons['nonfinite_range'] == 1
    assert rig.node.reasons['spectrum_invalid'] == 1 and rig.node.reasons['jammer_state_unknown_type'] == 1
    assert rig.node.accounting()['accounting_ok'] and c['core_exceptions'] == 0
    assert len(rig.out['/gnss/integrity']) == 1


def test_config_file_is_generated_and_gives_the_defaults(rig_factory):
    """config/gnss_integrity.yaml is written by tools/generate_config.py from the parameter definitions."""
    from gnss_integrity.node_params import CONFIG_FILE

    testing.check_config_file(rig_factory, CONFIG_FILE, CONFIG, 'gnss_integrity_node')


def test_test_parameters_are_defined_once_in_the_core():
    """The node's test parameters take default, description and range from the core dataclasses (one definition
    each; ``oscillator`` offers a subset of the core's choices), and the default node parameters give the core's
    default parameters."""
    import dataclasses

    from gnss_integrity.clock_test import ClockTestParams
    from gnss_integrity.integrity_state import StateParams
    from gnss_integrity.kinematics_test import KinematicsTestParams
    from gnss_integrity.monitor import MonitorParams
    from gnss_integrity.uwb_range_rate import UwbRangeRateParams

    node = {f.name: f for f in dataclasses.fields(IntegrityNodeParams)}
    pairs = {'oscillator': (ClockTestParams, 'oscillator'),
             'gnss_error_std_m': (KinematicsTestParams, 'error_std_m'),
             'uwb_std_m': (KinematicsTestParams, 'uwb_std_m'),
             'detection_persistence_s': (StateParams, 'persistence_s'),
             'clean_period_s': (StateParams, 'clean_period_s')}
    for name, (owner, core_name) in pairs.items():
        core = {f.name: f for f in dataclasses.fields(owner)}[core_name]
        node_doc, core_doc = dict(node[name].metadata['rfi_doc']), dict(core.metadata['rfi_doc'])
        if name == 'oscillator':
            assert set(node_doc.pop('choices')) < set(core_doc.pop('choices'))
        assert node_doc == core_doc, name
        assert node[name].default == core.default, name
    assert UwbRangeRateParams().uwb_std_m == KinematicsTestParams().uwb_std_m
    assert IntegrityNodeParams().monitor_params() == MonitorParams()


def test_diagnostics_parameters_are_settable_while_running(rig_factory):
    """hardware_id and the diagnostics thresholds are declared settable: a change is applied before the next
    message; the tests' parameters are read-only."""
    from rfi_node_common.params import set_parameters_remotely

    rig = rig_factory()

    def param_set(**values):
        return set_parameters_remotely(rig.io, rig.executor, '/gnss_integrity', values)

    assert all(r.successful for r in param_set(hardware_id='receiver#2', warn_rejected_fraction=0.3,
                                               diagnostics_window_s=20.0))
    epoch = _run().gnss_epochs[0]
    rig.send('/gnss/measurements', epoch_to_msg(epoch))
    assert rig.out['/diagnostics'][-1].status[0].hardware_id == 'receiver#2'
    assert rig.node.params.warn_rejected_fraction == 0.3 and rig.node._window.window_ns == 20 * 10**9
    for name, value in (('gnss_error_std_m', 3.0), ('oscillator', 'ocxo'), ('max_stamp_jump_s', 10.0)):
        (result,) = param_set(**{name: value})
        assert not result.successful and 'read-only' in result.reason, name
    (result,) = param_set(warn_lost_fraction=1.5)
    assert not result.successful and 'out of range' in result.reason


@pytest.mark.parametrize('params, words', [
    ({'oscillator': 'quartz'}, 'oscillator'),
    ({'save_cn0_model': True}, 'cn0_model_file'),
    ({'gnss_error_std_m': 0.0}, 'gnss_error_std_m'),
])
def test_invalid_parameters_give_one_line_errors(params, words):
    error = testing.start_error(
        lambda context, overrides: GnssIntegrityNode(context=context, parameter_overrides=overrides), params)
    assert words in error and '\n' not in error


def test_cn0_model_file_round_trip(rig_factory, tmp_path):
    path = tmp_path / 'cn0.json'
    rig = rig_factory({'cn0_model_file': str(path), 'save_cn0_model': True})
    for e in _run().gnss_epochs[:60]:
        rig.send('/gnss/measurements', epoch_to_msg(e))
    rig.node.destroy_node()
    assert path.exists() and 'version' in path.read_text()


def _order_test_messages(seconds: float = 12.0) -> list[tuple[int, int, str, object]]:
    """(stamp ns, tie order, topic, message) of the first ``seconds`` of the simulated run: GNSS epochs at 5 Hz,
    ranges of three anchors at 5 Hz each (A1 on the epochs' stamps) and, from the middle on, an SDR state 0.1 s
    after each epoch whose J/S is different each time (so a verdict that used a newer or older state shows it).
    At equal stamps a side input comes first (tie order 0; epochs 1)."""
    run = _run()
    t0 = run.gnss_epochs[0].stamp_ns
    end = t0 + int(seconds * 1e9)
    epochs = [e for e in run.gnss_epochs if e.stamp_ns < end]
    items = [(e.stamp_ns, 1, '/gnss/measurements', epoch_to_msg(e)) for e in epochs]
    last = epochs[-1].stamp_ns
    items += [(u.stamp_ns, 0, '/uwb/ranges', uwb_to_msg(u)) for u in run.uwb_ranges if u.stamp_ns <= last]
    for k, e in enumerate(epochs[len(epochs) // 2:-1]):
        stamp = e.stamp_ns + 100_000_000
        state = JammerState(type=JammerState.WIDEBAND, confidence=0.9, jammer_to_noise_db=20.0 + k,
                            jammer_to_signal_db=10.0 + k)
        state.header.stamp.sec, state.header.stamp.nanosec = divmod(stamp, 10**9)
        state.header.frame_id = 'if'
        items.append((stamp, 0, '/rfi/jammer_state', state))
    return sorted(items, key=lambda item: item[:2])


def _fields(value, path: str = '') -> list[tuple[str, str]]:
    """(path, repr) of every field of a message, recursively: equal for equal values, NaN included (the serialised
    bytes are not: the padding between fields is not defined)."""
    if hasattr(value, 'get_fields_and_field_types'):
        names = value.get_fields_and_field_types()
        return [f for name in names for f in _fields(getattr(value, name), f'{path}.{name}')]
    if isinstance(value, (list, tuple)) or (hasattr(value, '__len__') and not isinstance(value, (str, bytes))):
        return [f for i, v in enumerate(value) for f in _fields(v, f'{path}[{i}]')]
    return [(path, repr(float(value)) if isinstance(value, float) else repr(value))]


def _verdicts(rig: Rig) -> list[list[tuple[str, str]]]:
    return [_fields(m) for m in rig.out['/gnss/integrity']]


@pytest.mark.slow
def test_verdicts_depend_on_stamps_not_on_arrival_order(rig_factory):
    """Issue 27 item 6: the same messages in two arrival orders give the same verdicts, field for field.

    In order: one message at a time, in stamp order. In bursts: for each epoch, the side inputs stamped within
    0.1 s of it and the epoch are published together before the executor spins, those stamped after the epoch
    first, then the epoch, then those stamped at or before it. rclpy's executor then serves the GNSS subscription
    first (it was created first), as under load in test_two_suites: before the fix the epoch was judged without
    the ranges of its own burst and with an SDR state stamped after it."""
    items = _order_test_messages()
    epochs = [(stamp, msg) for stamp, _, topic, msg in items if topic == '/gnss/measurements']

    first = rig_factory()
    for _, _, topic, msg in items:
        first.send(topic, msg)
    in_order = _verdicts(first)
    assert first.node.counts['side_inputs_taken_before_epoch'] == 0
    first.close()

    second = rig_factory()
    for k, (t_ns, epoch) in enumerate(epochs):
        side = [(stamp, topic, msg) for stamp, _, topic, msg in items if topic != '/gnss/measurements'
                and (k == 0 or stamp > t_ns - 100_000_000) and stamp <= t_ns + 100_000_000]
        for _, topic, msg in [s for s in side if s[0] > t_ns] + [(t_ns, '/gnss/measurements', epoch)] + [
                s for s in reversed(side) if s[0] <= t_ns]:
            second.pubs[topic].publish(msg)
            second.sent += 1
        for pub in second.pubs.values():  # in the node's queues before its executor looks: all ready at once
            assert pub.wait_for_all_acked(rclpy.duration.Duration(seconds=10.0))
        second.settle_until(lambda n=k + 1: second.node.counts['published'] == n and sum(
            second.node.counts[f'{kind}_received'] for kind in ('gnss', 'uwb', 'receiver', 'spectrum', 'sdr'))
            == second.sent)
    in_bursts = _verdicts(second)
    assert second.sent == len(items)
    assert len(in_order) == len(in_bursts) == len(epochs)
    differing = [k for k, (a, b) in enumerate(zip(in_order, in_bursts, strict=True)) if a != b]
    assert not differing, (f'{len(differing)} of {len(epochs)} verdicts differ; at epoch {differing[0]}: '
                           f'{sorted(set(in_order[differing[0]]) ^ set(in_bursts[differing[0]]))[:6]}')
    # the bursts did what they are for: the executor handed each epoch over before side inputs that came with it
    assert second.node.counts['side_inputs_taken_before_epoch'] >= 2 * len(epochs)
    assert first.node.accounting()['accounting_ok'] and second.node.accounting()['accounting_ok']


def test_corrupt_fields_are_rejected_before_the_monitor(rig_factory):
    """Issue 27 (the long fuzz): a UWB range of 1e300 m or 5e-324 m, a 1-sigma of 1e300 m or an anchor off the Earth
    was kept as its anchor's newest range and made every later epoch raise in the monitor (a counted core exception,
    no verdict) until the anchor was heard again; a pseudorange 1-sigma of 5e-324 m divided by zero in the fix. Now
    they are named rejections (the ranges) or a dropped satellite (the epoch is judged on the rest)."""
    run = _run()
    rig = rig_factory()
    epochs = run.gnss_epochs[:6]
    ranges = [u for u in run.uwb_ranges if u.stamp_ns <= epochs[2].stamp_ns]
    items = sorted([(e.stamp_ns, 1, '/gnss/measurements', epoch_to_msg(e)) for e in epochs[:3]]
                   + [(u.stamp_ns, 0, '/uwb/ranges', uwb_to_msg(u)) for u in ranges], key=lambda t: t[:2])
    for _, _, topic, msg in items:
        rig.send(topic, msg)
    last = ranges[-1]
    corrupt = []
    for field, value in (('range_m', 1e300), ('range_m', 5e-324), ('range_std_m', 1e300), ('range_std_m', 5e-324),
                         ('range_std_m', -math.inf)):
        msg = uwb_to_msg(last)
        setattr(msg, field, value)
        corrupt.append(msg)
    msg = uwb_to_msg(last)
    msg.anchor_position.x = 1e300
    corrupt.append(msg)
    msg = uwb_to_msg(last)
    msg.anchor_position.y = math.nan
    corrupt.append(msg)
    for k, msg in enumerate(corrupt):  # newer than every valid range of the anchor
        stamp = last.stamp_ns + 1000 * (k + 1)
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 10**9)
        rig.send('/uwb/ranges', msg)
    bad_sat = epoch_to_msg(epochs[3])
    bad_sat.measurements[0].pseudorange_std_m = 5e-324
    rig.send('/gnss/measurements', bad_sat)
    for e in epochs[4:]:
        rig.send('/gnss/measurements', epoch_to_msg(e))
    c, reasons = rig.node.counts, rig.node.reasons
    assert c['core_exceptions'] == 0 and c['published'] == len(epochs)
    assert reasons['range_too_long'] == 1 and reasons['range_too_short'] == 1 and reasons['invalid_range_std'] == 3
    assert reasons['nonphysical_anchor_position'] == 1 and reasons['nonfinite_anchor_position'] == 1
    assert rig.node.dropped_satellites['invalid_measurement_std'] == 1
    assert rig.node.accounting()['accounting_ok']
