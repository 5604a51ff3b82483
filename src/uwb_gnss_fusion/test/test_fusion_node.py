"""In-process tests of FusionNode: one Context per test, a SingleThreadedExecutor, bounded spins.

Each test publishes inputs from a test node and spins until the node has taken every one and every
message it published has arrived (counted, never slept for). The GNSS/UWB inputs come from the
``gnss_uwb`` scenario stream (half-simulated: real ARL1 broadcast ephemeris, static receiver,
three UWB anchors at the paper's ranges; rfi_experiments/streams/gnss_uwb.py).
"""

from __future__ import annotations

import copy
import math
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import rclpy
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import NavSatFix

from gnss_common.coordinates import ecef_to_geodetic
from gnss_common.observations import UwbRangeMeasurement
from rfi_experiments.evaluation import ecef_errors_enu, horizontal_error_m
from rfi_experiments.scenario import Scenario
from rfi_experiments.streams import gnss_uwb
from rfi_msgs.msg import FusionStatus, GnssMeasurementArray, JammerState, UwbRange
from rfi_node_common.qos import DATA_QOS
from rfi_node_common.stamps import ns_to_stamp, stamp_to_ns
from uwb_gnss_fusion.conversions import uwb_to_msg
from uwb_gnss_fusion.fusion_node import ORIENTATION_UNKNOWN_VARIANCE_RAD2, FusionNode, FusionNodeParams

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'fusion.yaml'
SPIN_DEADLINE_S = 10.0
GOAL_HORIZONTAL_RMS_M = 0.2
"""Issue goal (Cao et al. scenario, 3 anchors): horizontal RMS below 0.2 m."""
CONVERGED_S = 10.0
TOPICS = {GnssMeasurementArray: '/gnss/measurements', UwbRange: '/uwb/ranges', JammerState: '/rfi/jammer_state'}
KIND = {GnssMeasurementArray: 'gnss', UwbRange: 'uwb', JammerState: 'jammer'}


@pytest.fixture(scope='module')
def clean_stream():
    """20 s, no jamming, UWB 10 Hz per anchor: (truth ECEF (3,), [(stamp_ns, topic, msg), ...])."""
    scenario = Scenario(name='node_test', description='', seed=3, duration_s=20.0, streams={})
    items = list(gnss_uwb.build(scenario, {'uwb_rate_hz': 10.0, 'truth_jammer_state': False}, seed=17))
    truth = next(m for _, t, m in items if t == '/truth/position').point
    inputs = [(s, t, m) for s, t, m in items if t in ('/gnss/measurements', '/uwb/ranges')]
    return np.array([truth.x, truth.y, truth.z]), inputs


class Rig:
    """The node under test plus a test node that publishes inputs and collects every output."""

    def __init__(self, params: dict | None = None, args: list[str] | None = None) -> None:
        self.context = Context()
        rclpy.init(args=args, context=self.context)
        overrides = [Parameter(k, value=v) for k, v in (params or {}).items()]
        try:
            self.node = FusionNode(context=self.context, parameter_overrides=overrides)
        except Exception:
            rclpy.shutdown(context=self.context)
            raise
        self.io = Node('fusion_test_io', context=self.context)
        self.pubs = {cls: self.io.create_publisher(cls, topic, DATA_QOS) for cls, topic in TOPICS.items()}
        self.out: dict[str, list] = {'/fusion/odometry': [], '/fusion/fix': [], '/fusion/status': [],
                                     '/diagnostics': []}
        for cls, topic in ((Odometry, '/fusion/odometry'), (NavSatFix, '/fusion/fix'),
                           (FusionStatus, '/fusion/status'), (DiagnosticArray, '/diagnostics')):
            self.io.create_subscription(cls, topic, self.out[topic].append, DATA_QOS)
        self.published: Counter[str] = Counter()
        for pub in (self.node.odom_pub, self.node.fix_pub, self.node.status_pub, self.node.diag_pub):
            pub.publish = self._counting(pub.publish, pub.topic_name)
        self.sent: Counter[str] = Counter()
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.io)
        self._spin_until(lambda: all(p.get_subscription_count() >= 1 for p in self.pubs.values())
                         and all(p.get_subscription_count() >= 1 for p in (
                             self.node.odom_pub, self.node.fix_pub, self.node.status_pub, self.node.diag_pub)))

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

    def send(self, msg) -> None:
        """Publish one input and spin until the node has taken it and all its outputs have arrived."""
        kind = KIND[type(msg)]
        self.pubs[type(msg)].publish(msg)
        self.sent[kind] += 1
        self._spin_until(lambda: self.node.counts[f'{kind}_received'] == self.sent[kind]
                         and all(len(v) == self.published[k] for k, v in self.out.items()))

    def last_status(self) -> FusionStatus:
        return self.out['/fusion/status'][-1]

    def reasons(self) -> dict[str, int]:
        s = self.last_status()
        return dict(zip(s.rejection_reasons, s.rejection_counts, strict=True))

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


def stamp_of(msg) -> int:
    return stamp_to_ns(msg.header.stamp)


def restamped(msg, stamp_ns: int):
    out = copy.deepcopy(msg)
    out.header.stamp = ns_to_stamp(stamp_ns)
    return out


def assert_no_nan_published(rig: Rig) -> None:
    for odom in rig.out['/fusion/odometry']:
        p, v = odom.pose.pose.position, odom.twist.twist.linear
        assert all(math.isfinite(x) for x in (p.x, p.y, p.z, v.x, v.y, v.z))
        assert all(math.isfinite(x) for x in odom.pose.covariance)
        assert all(math.isfinite(x) for x in odom.twist.covariance)
    for fix in rig.out['/fusion/fix']:
        assert all(math.isfinite(x) for x in (fix.latitude, fix.longitude, fix.altitude))
        assert all(math.isfinite(x) for x in fix.position_covariance)
        assert fix.status.status == fix.status.STATUS_FIX


def diag_values(rig: Rig) -> dict[str, str]:
    return {kv.key: kv.value for kv in rig.out['/diagnostics'][-1].status[0].values}


def positions(odoms) -> tuple[np.ndarray, np.ndarray]:
    t = np.array([stamp_of(o) for o in odoms])
    p = np.array([[o.pose.pose.position.x, o.pose.pose.position.y, o.pose.pose.position.z] for o in odoms])
    return t, p


# ----------------------------------------------------------------------------------------------
def test_converges_on_simulated_gnss_uwb(rig_factory, clean_stream):
    truth, inputs = clean_stream
    rig = rig_factory({'reorder_window_s': 0.0, 'accel_psd_m2ps3': 0.01})
    for _, _, msg in inputs:
        rig.send(msg)
    n_gnss = sum(1 for _, t, _ in inputs if t == '/gnss/measurements')
    n_uwb = len(inputs) - n_gnss
    # One status per measurement; the filter initialises on the first GNSS epoch (9 satellites).
    assert len(rig.out['/fusion/status']) == len(inputs)
    assert rig.out['/fusion/status'][0].initialized
    assert [stamp_of(s) for s in rig.out['/fusion/status']] == [s for s, _, _ in inputs]
    odoms = rig.out['/fusion/odometry']
    assert len(odoms) == len(inputs)
    t, p = positions(odoms)
    err_h = horizontal_error_m(ecef_errors_enu(p, truth))
    converged = t >= inputs[0][0] + CONVERGED_S * 1e9
    assert np.sqrt(np.mean(err_h[converged] ** 2)) < GOAL_HORIZONTAL_RMS_M
    last = odoms[-1]
    assert last.header.frame_id == 'earth' and last.child_frame_id == 'gnss_antenna'
    assert (last.pose.pose.orientation.x, last.pose.pose.orientation.w) == (0.0, 1.0)
    cov = np.array(last.pose.covariance).reshape(6, 6)
    assert np.allclose(cov[3:, 3:], ORIENTATION_UNKNOWN_VARIANCE_RAD2 * np.eye(3))
    assert np.allclose(cov[:3, :3], cov[:3, :3].T) and np.all(np.linalg.eigvalsh(cov[:3, :3]) > 0)
    assert np.linalg.norm([last.twist.twist.linear.x, last.twist.twist.linear.y, last.twist.twist.linear.z]) < 0.1
    # NavSatFix: the same point in WGS 84 with the ENU covariance (trace is rotation invariant).
    fix = rig.out['/fusion/fix'][-1]
    assert fix.header.frame_id == 'gnss_antenna'
    assert fix.position_covariance_type == NavSatFix.COVARIANCE_TYPE_KNOWN
    lat, lon, h = ecef_to_geodetic(np.array([last.pose.pose.position.x, last.pose.pose.position.y,
                                             last.pose.pose.position.z]))
    assert math.degrees(lat) == pytest.approx(fix.latitude, abs=1e-12)
    assert math.degrees(lon) == pytest.approx(fix.longitude, abs=1e-12)
    assert h == pytest.approx(fix.altitude, abs=1e-6)
    assert np.trace(np.array(fix.position_covariance).reshape(3, 3)) == pytest.approx(np.trace(cov[:3, :3]))
    status = rig.last_status()
    assert status.mode == FusionStatus.MODE_GNSS_UWB and status.uwb_used == 1
    assert math.isfinite(status.clock_bias_m) and math.isnan(status.jammer_to_signal_db)
    values = diag_values(rig)
    assert values['accounting_ok'] == 'True'
    assert int(values['gnss_processed']) <= n_gnss and int(values['uwb_processed']) <= n_uwb
    assert rig.out['/diagnostics'][-1].status[0].level == DiagnosticStatus.OK
    assert_no_nan_published(rig)


def test_bad_input_is_counted_and_never_published(rig_factory, clean_stream):
    truth, inputs = clean_stream
    rig = rig_factory({'reorder_window_s': 0.0, 'diagnostics_period_s': 0.01})
    first_half = [(s, t, m) for s, t, m in inputs if s < inputs[0][0] + 10 * 10**9]
    for _, _, msg in first_half:
        rig.send(msg)
    t_ns = first_half[-1][0]
    good_epoch = next(m for s, t, m in reversed(first_half) if t == '/gnss/measurements')
    good_uwb = next(m for s, t, m in reversed(first_half) if t == '/uwb/ranges')
    bad = []

    def epoch(measurements, dt_ms):
        msg = restamped(good_epoch, t_ns + dt_ms * 10**6)
        msg.measurements = measurements
        return msg

    sats = list(good_epoch.measurements)
    nan_pr = copy.deepcopy(sats)
    nan_pr[1].pseudorange_m = math.nan
    nan_pos = copy.deepcopy(sats)
    nan_pos[2].satellite_position_ecef_m[0] = math.nan
    bad.append(epoch(nan_pr, 10))                          # nonfinite_pseudorange
    bad.append(epoch(nan_pos, 20))                         # nonfinite_pseudorange
    bad.append(epoch([], 30))                              # no_satellites
    bad.append(epoch(sats + [copy.deepcopy(sats[0])], 40))  # duplicate_svid (2)
    bad.append(epoch(sats[:3], 50))                        # fewer_than_4_satellites
    wrong_frame = epoch(sats, 60)
    wrong_frame.header.frame_id = 'map'
    bad.append(wrong_frame)                                # gnss_frame_id
    negative = restamped(good_uwb, t_ns + 70 * 10**6)
    negative.range_m = -3.0
    bad.append(negative)                                   # negative_range
    nan_range = restamped(good_uwb, t_ns + 80 * 10**6)
    nan_range.range_m = math.nan
    bad.append(nan_range)                                  # nonfinite_range
    nan_anchor = restamped(good_uwb, t_ns + 90 * 10**6)
    nan_anchor.anchor_position.x = math.nan
    bad.append(nan_anchor)                                 # nonfinite_anchor_position
    bad.append(restamped(good_uwb, t_ns + 3600 * 10**9))   # stamp_far_future
    bad.append(restamped(good_epoch, t_ns - 3600 * 10**9))  # stamp_far_past
    bad.append(restamped(good_uwb, 0))                     # stamp_not_positive
    jam = JammerState(type=JammerState.CHIRP, jammer_to_signal_db=math.nan)
    jam.header.stamp = ns_to_stamp(t_ns + 95 * 10**6)
    bad.append(jam)                                        # jammer_state_nan
    for msg in bad:
        rig.send(msg)
    expected = {'nonfinite_pseudorange': 2, 'no_satellites': 1, 'duplicate_svid': 2,
                'fewer_than_4_satellites': 1, 'gnss_frame_id': 1, 'negative_range': 1, 'nonfinite_range': 1,
                'nonfinite_anchor_position': 1, 'stamp_far_future': 1, 'stamp_far_past': 1,
                'stamp_not_positive': 1, 'jammer_state_nan': 1}
    # The good data after the faults: the filter carries on.
    for s, _, msg in inputs[len(first_half):]:
        if s > t_ns + 100 * 10**6:
            rig.send(msg)
    reasons = rig.reasons()
    values = diag_values(rig)
    for reason, count in expected.items():
        assert reasons.get(reason) == count, reason
        key = f'filter.{reason}' if f'filter.{reason}' in values else f'rejected.{reason}'
        assert int(values[key]) == count, reason
    assert values['accounting_ok'] == 'True'
    assert int(values['gnss_received']) == rig.sent['gnss'] and int(values['uwb_received']) == rig.sent['uwb']
    assert int(values['gnss_rejected']) == 2 and int(values['uwb_rejected']) == 2  # frame, far past / future, 0
    assert int(values['jammer_rejected']) == 1
    assert rig.last_status().initialized and rig.last_status().reinitializations == 0
    assert_no_nan_published(rig)
    t, p = positions(rig.out['/fusion/odometry'])
    tail = t > t_ns + 5 * 10**9
    assert np.sqrt(np.mean(horizontal_error_m(ecef_errors_enu(p[tail], truth)) ** 2)) < GOAL_HORIZONTAL_RMS_M


def test_nothing_published_before_initialisation(rig_factory, clean_stream):
    _, inputs = clean_stream
    rig = rig_factory({'reorder_window_s': 0.0, 'use_uwb': False})
    first = next(m for _, t, m in inputs if t == '/gnss/measurements')
    few = copy.deepcopy(first)
    few.measurements = few.measurements[:3]   # too few to initialise from GNSS alone
    rig.send(few)
    status = rig.last_status()
    assert not status.initialized and status.mode == FusionStatus.MODE_NONE
    assert rig.out['/fusion/odometry'] == [] and rig.out['/fusion/fix'] == []
    assert rig.reasons()['gnss_init_failed'] == 1
    assert rig.out['/diagnostics'][-1].status[0].level == DiagnosticStatus.WARN
    uwb = next(m for _, t, m in inputs if t == '/uwb/ranges')
    rig.send(uwb)   # UWB disabled: counted, still nothing published
    assert rig.reasons()['uwb_disabled'] == 1 and rig.out['/fusion/fix'] == []
    good = restamped(first, stamp_of(uwb) + 10**6)
    rig.send(good)
    assert rig.last_status().initialized and rig.last_status().mode == FusionStatus.MODE_GNSS
    assert len(rig.out['/fusion/fix']) == 1 and len(rig.out['/fusion/odometry']) == 1


def test_reorder_window_and_late_messages(rig_factory, clean_stream):
    _, inputs = clean_stream
    rig = rig_factory({'reorder_window_s': 0.1})
    head = inputs[:40]
    # Swap neighbours: every message arrives up to one slot (<= 34 ms) out of order.
    shuffled = [m for pair in zip(head[1::2], head[0::2], strict=True) for m in pair]
    for _, _, msg in shuffled:
        rig.send(msg)
    stamps = [stamp_of(s) for s in rig.out['/fusion/status']]
    assert stamps == sorted(stamps)
    # Released = every message at least 0.1 s older than the newest.
    newest = max(s for s, _, _ in head)
    assert stamps == [s for s, _, _ in head if s <= newest - 10**8]
    late = restamped(head[5][2], head[5][0])   # older than what has been released
    rig.send(late)
    assert rig.node.reasons['late_beyond_reorder_window'] == 1
    rig.node.flush()
    values = rig.node.accounting()
    assert values['accounting_ok'] and values['uwb_buffered'] == values['gnss_buffered'] == 0
    assert values['uwb_processed'] + values['gnss_processed'] == len(head)


def test_stamp_jump_restarts_after_confirmations(rig_factory, clean_stream):
    _, inputs = clean_stream
    rig = rig_factory({'reorder_window_s': 0.0, 'stamp_jump_confirmations': 3})
    head = inputs[:30]
    for _, _, msg in head:
        rig.send(msg)
    shift = 7 * 86400 * 10**9   # the source's clock jumps a week ahead
    for s, _, msg in inputs[30:60]:
        rig.send(restamped(msg, s + shift))
    assert rig.node.reasons['stamp_far_future'] == 2
    assert rig.node.counts['time_jump_restarts'] == 1
    values = rig.node.accounting()
    assert values['accounting_ok']
    assert stamp_of(rig.last_status()) == inputs[59][0] + shift


def test_jammer_state_drives_the_weighting_j_s(rig_factory, clean_stream):
    _, inputs = clean_stream
    rig = rig_factory({'reorder_window_s': 0.0})
    for _, _, msg in inputs[:20]:
        rig.send(msg)
    t = inputs[19][0]
    jam = JammerState(type=JammerState.CHIRP, jammer_to_signal_db=22.0)
    jam.header.stamp = ns_to_stamp(t + 1)
    rig.send(jam)
    rig.send(restamped(inputs[20][2], t + 2))
    assert rig.last_status().jammer_to_signal_db == 22.0
    none = JammerState(type=JammerState.NONE, jammer_to_signal_db=5.0)
    none.header.stamp = ns_to_stamp(t + 3)
    rig.send(none)
    rig.send(restamped(inputs[21][2], t + 4))
    assert math.isnan(rig.last_status().jammer_to_signal_db)
    inf = JammerState(type=JammerState.WIDEBAND, jammer_to_signal_db=math.inf)
    inf.header.stamp = ns_to_stamp(t + 5)
    rig.send(inf)
    assert rig.node.reasons['jammer_state_nonphysical'] == 1 and rig.node.counts['jammer_processed'] == 2


def test_uwb_only_in_map_frame(rig_factory):
    rng = np.random.default_rng(5)
    anchors = {'A1': np.array([0.0, 0.0, 2.0]), 'A2': np.array([12.0, 0.0, 1.5]),
               'A3': np.array([0.0, 10.0, 2.5]), 'A4': np.array([11.0, 9.0, 0.5])}
    tag = np.array([4.0, 3.0, 1.0])
    rig = rig_factory({'use_gnss': False, 'reorder_window_s': 0.0, 'accel_psd_m2ps3': 0.01})
    t0 = 1_700_000_000 * 10**9
    for k in range(200):   # 10 s at 20 Hz, anchors in turn
        aid = f'A{k % 4 + 1}'
        r = float(np.linalg.norm(tag - anchors[aid]) + 0.05 * rng.standard_normal())
        rig.send(uwb_to_msg(UwbRangeMeasurement(stamp_ns=t0 + k * 50_000_000, anchor_id=aid,
                                                anchor_position_m=anchors[aid], frame_id='map', range_m=r,
                                                range_std_m=0.05)))
    odoms = rig.out['/fusion/odometry']
    assert odoms and all(o.header.frame_id == 'map' for o in odoms)
    assert rig.out['/fusion/fix'] == []   # no NavSatFix from a local frame
    status = rig.last_status()
    assert status.header.frame_id == 'map' and status.mode == FusionStatus.MODE_UWB
    assert math.isnan(status.clock_bias_m)
    _, p = positions(odoms[-40:])
    # Horizontal: within twice the 5 cm range noise (four anchors around the tag). Vertical is weakly
    # observed (anchor heights span 2 m, all near the tag's): bounded at six times the noise.
    assert np.sqrt(np.mean(np.sum((p[:, :2] - tag[:2]) ** 2, axis=1))) < 0.1
    assert np.sqrt(np.mean((p[:, 2] - tag[2]) ** 2)) < 0.3
    assert_no_nan_published(rig)
    # An ECEF-framed range cannot join a filter running in 'map'.
    rig.send(uwb_to_msg(UwbRangeMeasurement(stamp_ns=t0 + 200 * 50_000_000, anchor_id='A1',
                                            anchor_position_m=anchors['A1'], frame_id='earth', range_m=3.0,
                                            range_std_m=0.05)))
    assert rig.reasons()['uwb_frame_mismatch'] == 1


def test_config_file_values_equal_the_dataclass_defaults(rig_factory):
    fields = FusionNodeParams.__dataclass_fields__
    data = yaml.safe_load(CONFIG.read_text())['uwb_gnss_fusion']['ros__parameters']
    assert set(data) == set(fields)
    rig = rig_factory(args=['fusion_node', '--ros-args', '--params-file', str(CONFIG)])
    assert rig.node.params == FusionNodeParams()
    for name in fields:
        value = rig.node.get_parameter(name).value
        default = getattr(FusionNodeParams(), name)
        assert (tuple(value) if isinstance(default, tuple) else value) == default, name
    assert rig.node.filter.params == FusionNodeParams().fusion_params()


def test_every_filter_parameter_is_a_node_parameter():
    import dataclasses

    from uwb_gnss_fusion.fusion_filter import FusionParams
    from uwb_gnss_fusion.jamming_weights import TrackingLoopParams

    node_fields = set(FusionNodeParams.__dataclass_fields__)
    core = {f.name for f in dataclasses.fields(FusionParams)} - {'loop', 'anchors'}
    loop = {f'loop_{f.name}' for f in dataclasses.fields(TrackingLoopParams)}
    assert core | loop <= node_fields
    assert FusionNodeParams().fusion_params() == FusionParams()


@pytest.mark.parametrize('params, words', [
    ({'use_gnss': False, 'use_uwb': False}, 'use_uwb'),
    ({'reorder_window_s': -1.0}, 'reorder_window_s'),
    ({'gate_probability': 0.1}, 'gate_probability'),
    ({'uwb_lever_arm_m': [0.0, 1.0]}, 'uwb_lever_arm_m'),
    ({'earth_frame_id': 'map'}, 'map_frame_id'),
])
def test_invalid_parameters_are_refused(params, words):
    context = Context()
    rclpy.init(context=context)
    try:
        with pytest.raises(ValueError, match=words):
            FusionNode(context=context, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
    finally:
        rclpy.shutdown(context=context)
