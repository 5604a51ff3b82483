"""In-process tests of FusionNode: one Context per test, a SingleThreadedExecutor, bounded spins.

Each test publishes inputs from a test node and spins until the node has taken every one and every
message it published has arrived (counted, never slept for). The GNSS/UWB inputs come from the
GNSS/UWB simulator of rfi_sim (half-simulated: real ARL1 broadcast ephemeris, static receiver,
three UWB anchors at the paper's ranges; rfi_sim/gnss_uwb.py), run for one jammer-free phase as
the ``gnss_uwb`` scenario stream of rfi_experiments runs it.
"""

from __future__ import annotations

import copy
import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import rclpy
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.parameter import Parameter
from sensor_msgs.msg import NavSatFix

from gnss_common.coordinates import ecef_to_enu, ecef_to_enu_rotation, ecef_to_geodetic, geodetic_to_ecef
from gnss_common.observations import UwbRangeMeasurement
from rfi_msgs.msg import FusionStatus, GnssIntegrity, GnssMeasurementArray, JammerState, UwbRange
from rfi_node_common import testing
from rfi_node_common.conversions import epoch_to_msg, msg_to_uwb, uwb_to_msg
from rfi_node_common.qos import DATA_QOS
from rfi_node_common.stamps import ns_to_stamp, stamp_to_ns
from rfi_node_common.testing import NodeRig
from rfi_sim.evaluation import ecef_errors_enu, horizontal_error_m
from rfi_sim.gnss_uwb import BroadcastGeometry, GnssUwbScenario, simulate
from uwb_gnss_fusion.fusion_node import ORIENTATION_UNKNOWN_VARIANCE_RAD2, FusionNode, FusionNodeParams

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'fusion.yaml'
NAV_FILE = Path(__file__).resolve().parents[2] / 'gnss_common' / 'test' / 'data' / 'arlm2000.15n'
"""ARL1 broadcast ephemeris, 2015-07-19 (the copy of the gnss_common tests)."""
GOAL_HORIZONTAL_RMS_M = 0.2
"""Issue goal (Cao et al. scenario, 3 anchors): horizontal RMS below 0.2 m."""
CONVERGED_S = 10.0
TOPICS = {GnssMeasurementArray: '/gnss/measurements', UwbRange: '/uwb/ranges', JammerState: '/rfi/jammer_state',
          GnssIntegrity: '/gnss/integrity'}
KIND = {GnssMeasurementArray: 'gnss', UwbRange: 'uwb', JammerState: 'jammer', GnssIntegrity: 'integrity'}


@pytest.fixture(scope='module')
def clean_stream():
    """20 s, no jamming, UWB 10 Hz per anchor: (truth ECEF (3,), [(stamp_ns, topic, msg), ...])."""
    geometry = BroadcastGeometry(NAV_FILE)
    # The seed the scenario stream gives its only phase (stream seed 17): the same run as before.
    phase_seed = int(np.random.default_rng(17).integers(0, 2**31 - 1, size=1)[0])
    run = simulate(GnssUwbScenario(duration_s=20.0, seed=phase_seed, uwb_rate_hz=10.0), geometry,
                   geometry.iono_alpha, geometry.iono_beta)
    items = [(e.stamp_ns, 0, '/gnss/measurements', epoch_to_msg(e)) for e in run.gnss_epochs]
    items += [(u.stamp_ns, 1, '/uwb/ranges', uwb_to_msg(u)) for u in run.uwb_ranges]
    items.sort(key=lambda item: (item[0], item[1]))
    return np.array(GnssUwbScenario().receiver_ecef_m), [(s, t, m) for s, _, t, m in items]


WALL_CLOCK_OFF = {'idle_flush_s': 0.0, 'input_timeout_s': 0.0}
"""The rig's defaults: no wall-clock behaviour (idle flush, stale report) unless a test asks for it,
so that what the node publishes depends on the inputs only."""


class Rig(NodeRig):
    """The node under test plus a test node that publishes inputs and collects every output."""

    def __init__(self, params: dict | None = None, args: list[str] | None = None) -> None:
        if args is None:
            params = {**WALL_CLOCK_OFF, **(params or {})}
        super().__init__(lambda context, overrides: FusionNode(context=context, parameter_overrides=overrides),
                         inputs={topic: (cls, DATA_QOS) for cls, topic in TOPICS.items()},
                         outputs={'/fusion/odometry': Odometry, '/fusion/fix': NavSatFix,
                                  '/fusion/status': FusionStatus, '/diagnostics': DiagnosticArray,
                                  '/fusion/local_odometry': Odometry, '/fusion/datum': NavSatFix},
                         params=params, args=args, name='fusion_test_io')
        self.sent: Counter[str] = Counter()

    def send(self, msg, cls=None) -> None:
        """Publish one input (a message, or serialised bytes of type ``cls``) and spin until the node
        has taken it and all its outputs have arrived."""
        cls = type(msg) if cls is None else cls
        kind = KIND[cls]
        self.pubs[TOPICS[cls]].publish(msg)
        self.sent[kind] += 1
        self.settle(kind)

    def settle(self, kind: str) -> None:
        """Spin until the node has received every ``kind`` input sent and its outputs have arrived."""
        self.settle_until(lambda: self.node.counts[f'{kind}_received'] == self.sent[kind])

    def last_status(self) -> FusionStatus:
        return self.out['/fusion/status'][-1]

    def reasons(self) -> dict[str, int]:
        s = self.last_status()
        return dict(zip(s.rejection_reasons, s.rejection_counts, strict=True))



@pytest.fixture
def rig_factory():
    with testing.rig_factory(Rig) as make:
        yield make


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
    # One status per measurement. divergence_fix_confirm_s (1 s by default): the first GNSS epoch's fix
    # (9 satellites) is held, and the filter starts on the first epoch at least 1 s later, whose fix agrees.
    statuses = rig.out['/fusion/status']
    assert len(statuses) == len(inputs)
    gnss_stamps = [s for s, t, _ in inputs if t == '/gnss/measurements']
    first = next(i for i, st in enumerate(statuses) if st.initialized)
    assert stamp_of(statuses[first]) == next(s for s in gnss_stamps if s - gnss_stamps[0] >= 10**9)
    assert all(st.initialized for st in statuses[first:])
    assert [stamp_of(s) for s in statuses] == [s for s, _, _ in inputs]
    odoms = rig.out['/fusion/odometry']
    assert len(odoms) == len(inputs) - first
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
    assert values['motion_static'] == 'False'  # UWB ranges keep the moving model (motion_model)
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
    assert int(values['gnss_rejected']) == 2  # frame, far past
    # far future, 0; negative, NaN range, NaN anchor (rfi_node_common.message_checks, before the core)
    assert int(values['uwb_rejected']) == 5
    assert int(values['jammer_rejected']) == 1
    assert rig.last_status().initialized and rig.last_status().reinitializations == 0
    assert_no_nan_published(rig)
    t, p = positions(rig.out['/fusion/odometry'])
    tail = t > t_ns + 5 * 10**9
    assert np.sqrt(np.mean(horizontal_error_m(ecef_errors_enu(p[tail], truth)) ** 2)) < GOAL_HORIZONTAL_RMS_M


def test_nothing_published_before_initialisation(rig_factory, clean_stream):
    _, inputs = clean_stream
    rig = rig_factory({'divergence_fix_confirm_s': 0.0, 'reorder_window_s': 0.0, 'use_uwb': False})
    first = next(m for _, t, m in inputs if t == '/gnss/measurements')
    few = copy.deepcopy(first)
    few.measurements = few.measurements[:3]   # too few to initialise from GNSS alone
    rig.send(few)
    status = rig.last_status()
    assert not status.initialized and status.mode == FusionStatus.MODE_NONE
    assert rig.out['/fusion/odometry'] == [] and rig.out['/fusion/fix'] == []
    assert rig.reasons()['gnss_init_failed'] == 1
    # input processed but no solution: the output is not valid, ERROR
    assert rig.out['/diagnostics'][-1].status[0].level == DiagnosticStatus.ERROR
    assert 'no valid solution' in rig.out['/diagnostics'][-1].status[0].message
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
    late = restamped(head[5][2], head[5][0] + 1)   # older than what has been released (not a duplicate)
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
    rig = rig_factory({'divergence_fix_confirm_s': 0.0, 'reorder_window_s': 0.0})
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


def test_a_verdict_applies_to_the_epoch_it_was_computed_from(rig_factory, clean_stream):
    """gnss_integrity's verdict of epoch k has epoch k's stamp and arrives after it: within the
    re-ordering window it is applied before the epoch, so a DETECTED epoch is never fused."""
    _, inputs = clean_stream
    rig = rig_factory()  # the shipped re-ordering window (0.1 s)
    gnss = [i for i, (_, topic, _) in enumerate(inputs) if topic == '/gnss/measurements']
    k = gnss[30]
    for _, _, msg in inputs[:k + 1]:  # up to and including epoch k
        rig.send(msg)
    assert rig.node.counts['satellites_excluded_spoofing'] == 0
    verdict = GnssIntegrity(spoofing_state=GnssIntegrity.STATE_DETECTED, spoofing_scope=GnssIntegrity.SCOPE_ALL,
                            jamming_state=GnssIntegrity.STATE_NONE, jammer_to_signal_db=math.nan)
    verdict.header.stamp = ns_to_stamp(inputs[k][0])
    verdict.header.frame_id = 'earth'
    rig.send(verdict)
    for _, _, msg in inputs[k + 1:gnss[32] + 1]:
        rig.send(msg)
    assert rig.node.counts['integrity_processed'] == 1
    # epoch k and the two after it: every satellite excluded, none fused
    n_sats = sum(len(inputs[i][2].measurements) for i in gnss[30:32])
    assert rig.node.counts['satellites_excluded_spoofing'] >= n_sats
    assert rig.last_status().gnss_excluded == GnssIntegrity.SCOPE_ALL


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
    # An ECEF-framed range (anchor on the Earth's surface) cannot join a filter running in 'map'.
    rig.send(uwb_to_msg(UwbRangeMeasurement(stamp_ns=t0 + 200 * 50_000_000, anchor_id='A1',
                                            anchor_position_m=np.array([-740e3, -5457e3, 3207e3]), frame_id='earth',
                                            range_m=3.0, range_std_m=0.05)))
    assert rig.reasons()['uwb_frame_mismatch'] == 1


def test_config_file_values_equal_the_dataclass_defaults(rig_factory):
    from rfi_node_common.params import parameter_fields

    names = [f.name for f in parameter_fields(FusionNodeParams)]
    data = yaml.safe_load(CONFIG.read_text())['uwb_gnss_fusion']['ros__parameters']
    assert list(data) == names
    rig = rig_factory(args=['fusion_node', '--ros-args', '--params-file', str(CONFIG)])
    assert rig.node.params == FusionNodeParams()
    for name in names:
        value = rig.node.get_parameter(name).value
        default = getattr(FusionNodeParams(), name)
        assert (tuple(value) if isinstance(default, tuple) else value) == default, name
    assert rig.node.filter.params == FusionNodeParams().fusion_params()


def test_config_file_is_the_one_generated_from_the_parameter_definitions():
    """config/fusion.yaml is written by tools/generate_config.py from FusionParams / FusionNodeParams."""
    from uwb_gnss_fusion.fusion_node_params import CONFIG_FILE

    assert CONFIG.read_text() == CONFIG_FILE.text(), 'run python tools/generate_config.py'


def test_every_filter_parameter_is_a_node_parameter_defined_once():
    import dataclasses

    from gnss_common.jamming_weights import TrackingLoopParams
    from rfi_node_common.params import parameter_fields
    from uwb_gnss_fusion.fusion_filter import FusionParams

    node = {f.name: f for f in parameter_fields(FusionNodeParams)}
    core = {f.name: f for f in parameter_fields(FusionParams)}
    assert set(core) == {f.name for f in dataclasses.fields(FusionParams)} - {'loop', 'anchors'}
    loop = {f'loop_{f.name}' for f in dataclasses.fields(TrackingLoopParams)}
    assert set(core) | loop <= set(node)
    # the node inherits the core's definitions (default, description, range): one place to change them
    assert all(node[name] is core[name] for name in core)
    assert FusionNodeParams().fusion_params() == FusionParams()
    changed = FusionNodeParams(loop_dll_bandwidth_hz=4.0, min_cn0_dbhz=30.0)
    assert changed.loop == dataclasses.replace(TrackingLoopParams(), dll_bandwidth_hz=4.0)
    assert changed.fusion_params() == FusionParams(loop=changed.loop, min_cn0_dbhz=30.0)


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


# ---------------------------------------------------------------------------------- hostile input
def test_malformed_uwb_bytes_are_counted_and_the_node_keeps_running(rig_factory, clean_stream):
    from rclpy.serialization import serialize_message

    _, inputs = clean_stream
    rig = rig_factory({'divergence_fix_confirm_s': 0.0, 'reorder_window_s': 0.0, 'diagnostics_period_s': 0.01})
    for _, _, msg in inputs[:30]:
        rig.send(msg)
    raw = serialize_message(next(m for _, t, m in reversed(inputs[:30]) if t == '/uwb/ranges'))
    # rclpy's deserialize_message raises RMWError on each (the node's own decoder declines them first)
    bad = [b'\x00\x01\x00\x00', raw[:40], raw[:-1], b'\x00\x00\x00\x00' + raw[4:60], b'\x00\x01\x00\x00' + b'\xff' * 12]
    for payload in bad:
        rig.send(payload, UwbRange)
    assert rig.node.reasons['malformed_message'] == len(bad)
    assert rig.node.health.callback_errors_total() == 0   # handled by the node, not by the last net
    reports = len(rig.out['/diagnostics'])
    following = iter(inputs[30:60])
    while len(rig.out['/diagnostics']) == reports:   # the next report, timed by the next accepted stamp
        rig.send(next(following)[2])
    status = rig.out['/diagnostics'][reports].status[0]
    assert status.level == DiagnosticStatus.WARN and 'UWB ranges rejected 5/' in status.message
    for _, _, msg in following:
        rig.send(msg)
    values = diag_values(rig)
    assert values['rejected.malformed_message'] == str(len(bad)) and int(values['uwb_rejected']) == len(bad)
    assert values['accounting_ok'] == 'True' and values['input./uwb/ranges.callback_errors'] == '0'
    assert int(values['input./uwb/ranges.received']) == rig.sent['uwb']
    assert rig.last_status().initialized and stamp_of(rig.last_status()) == inputs[59][0]


def test_fuzzed_uwb_bytes_never_stop_the_node(rig_factory, clean_stream):
    """Seeded random, truncated and bit-flipped /uwb/ranges payloads: every one is received and
    accounted for under a named reason (or processed), no handler raises, nothing invalid is published."""
    from rclpy.serialization import serialize_message

    _, inputs = clean_stream
    rig = rig_factory({'reorder_window_s': 0.1})
    for _, _, msg in inputs[:40]:
        rig.send(msg)
    raw = serialize_message(next(m for _, t, m in reversed(inputs[:40]) if t == '/uwb/ranges'))
    rng = np.random.default_rng(99)
    for k in range(300):
        if k % 3 == 0:
            payload = rng.integers(0, 256, int(rng.integers(1, 120)), dtype=np.uint8).tobytes()
        elif k % 3 == 1:
            payload = raw[:int(rng.integers(1, len(raw)))]
        else:
            flipped = bytearray(raw)
            for _ in range(int(rng.integers(1, 4))):
                flipped[int(rng.integers(4, len(raw)))] ^= 1 << int(rng.integers(0, 8))
            payload = bytes(flipped)
        rig.send(payload, UwbRange)
    rig.node.end_of_input()
    values = rig.node.accounting()
    assert values['accounting_ok'] and values['input./uwb/ranges.callback_errors'] == 0
    assert values['uwb_received'] == rig.sent['uwb'] == values['input./uwb/ranges.received']
    assert values['uwb_rejected'] >= 200 and rig.node.reasons['malformed_message'] >= 100
    assert rig.node.counts.get('core_exceptions', 0) == 0
    assert_no_nan_published(rig)


def _epoch_with(msg: GnssMeasurementArray, stamp_ns: int, index: int, **fields) -> GnssMeasurementArray:
    out = restamped(msg, stamp_ns)
    for name, value in fields.items():
        if name in ('satellite_position_ecef_m', 'satellite_velocity_ecef_mps'):
            getattr(out.measurements[index], name)[:] = value
        else:
            setattr(out.measurements[index], name, value)
    return out


def test_ranges_outside_the_shared_limits_are_rejected_by_name(rig_factory, clean_stream):
    """Issue 27: the limits gnss_integrity_node applied inline (1 mm - 10 km, a finite anchor) are the shared check's,
    so the fusion node applies them too: a range of 1e300 m was counted by the core against uwb_max_range_m, one of
    5e-324 m was applied as valid; now each is a named node rejection and none reaches the filter."""
    _, inputs = clean_stream
    rig = rig_factory({'reorder_window_s': 0.0})
    first_half = [(s, t, m) for s, t, m in inputs if s < inputs[0][0] + 10 * 10**9]
    for _, _, msg in first_half:
        rig.send(msg)
    t_ns = first_half[-1][0]
    good_uwb = next(m for s, t, m in reversed(first_half) if t == '/uwb/ranges')
    before = dict(rig.node.counts)
    core_before = dict(rig.node.filter.rejection_counts)
    cases = [('range_too_long', 'range_m', 1e300), ('range_too_short', 'range_m', 5e-324),
             ('nonphysical_anchor_position', 'x', 1e300), ('nonphysical_anchor_position', 'z', -1e300)]
    for k, (_, field, value) in enumerate(cases, start=1):
        msg = restamped(good_uwb, t_ns + k * 10**6)
        if field == 'range_m':
            msg.range_m = value
        else:
            setattr(msg.anchor_position, field, value)
        rig.send(msg)
    assert rig.node.counts['uwb_processed'] == before['uwb_processed']   # none reached the filter
    assert rig.node.counts['uwb_rejected'] == before['uwb_rejected'] + len(cases)
    assert dict(rig.node.filter.rejection_counts) == core_before           # nor the core's own counts
    values = rig.node.accounting()
    expected = Counter(reason for reason, _, _ in cases)
    for reason, count in expected.items():
        assert rig.node.rejection_reasons()[reason] == count and values[f'rejected.{reason}'] == count, reason
    assert values['accounting_ok']
    ok = restamped(good_uwb, t_ns + (len(cases) + 1) * 10**6)
    rig.send(ok)                                                            # a valid range after them: applied
    assert rig.node.counts['uwb_processed'] == before['uwb_processed'] + 1 and rig.last_status().uwb_used == 1


def test_impossible_field_values_are_rejected_and_counted_never_applied(rig_factory, clean_stream):
    truth, inputs = clean_stream
    rig = rig_factory({'reorder_window_s': 0.0, 'diagnostics_period_s': 0.01})
    first_half = [(s, t, m) for s, t, m in inputs if s < inputs[0][0] + 10 * 10**9]
    for _, _, msg in first_half:
        rig.send(msg)
    t_ns = first_half[-1][0]
    good_epoch = next(m for s, t, m in reversed(first_half) if t == '/gnss/measurements')
    good_uwb = next(m for s, t, m in reversed(first_half) if t == '/uwb/ranges')
    n_sats = len(good_epoch.measurements)
    before = dict(rig.node.counts)
    # UWB: only NaN means "use the default 1-sigma"; impossible anchors are rejected
    uwb_cases = [('range_std_m', -math.inf), ('range_std_m', math.inf), ('range_std_m', 0.0),
                 ('range_std_m', -0.5), ('range_std_m', 1e6)]
    uwb_anchor_cases = [(1e300, 0.0, 0.0), (0.0, 0.0, 0.0), (6.4e6, 1e7, 0.0)]
    k = 0
    for name, value in uwb_cases:
        k += 1
        msg = restamped(good_uwb, t_ns + k * 10**6)
        setattr(msg, name, value)
        rig.send(msg)
    for x, y, z in uwb_anchor_cases:
        k += 1
        msg = restamped(good_uwb, t_ns + k * 10**6)
        msg.anchor_position.x, msg.anchor_position.y, msg.anchor_position.z = x, y, z
        rig.send(msg)
    assert rig.node.counts['uwb_processed'] == before['uwb_processed']   # none reached the filter
    assert rig.node.counts['uwb_rejected'] == before['uwb_rejected'] + len(uwb_cases) + len(uwb_anchor_cases)
    k += 1
    nan_std = restamped(good_uwb, t_ns + k * 10**6)
    nan_std.range_std_m = math.nan
    rig.send(nan_std)                                                      # NaN: the default, applied
    assert rig.node.counts['uwb_processed'] == before['uwb_processed'] + 1 and rig.last_status().uwb_used == 1
    # GNSS: the satellite is dropped, the rest of the epoch is used
    gnss_cases = [
        ('nonphysical_cn0', {'cn0_dbhz': -math.inf}), ('nonphysical_cn0', {'cn0_dbhz': math.inf}),
        ('nonphysical_cn0', {'cn0_dbhz': 1e3}),
        ('invalid_measurement_std', {'pseudorange_std_m': -math.inf}),
        ('invalid_measurement_std', {'pseudorange_std_m': 0.0}),
        ('invalid_measurement_std', {'pseudorange_std_m': -1.0}),
        ('invalid_measurement_std', {'pseudorange_std_m': 1e9}),
        ('invalid_measurement_std', {'pseudorange_rate_std_mps': math.inf}),
        ('nonphysical_satellite_state', {'satellite_velocity_ecef_mps': [1e300, 0.0, 0.0]}),
        ('nonphysical_satellite_state', {'satellite_clock_bias_m': 1e300}),
        ('nonphysical_satellite_state', {'satellite_clock_drift_mps': -1e9}),
        ('nonphysical_atmospheric_delay', {'ionosphere_delay_m': 1e6}),
        ('nonphysical_atmospheric_delay', {'troposphere_delay_m': 1e6}),
    ]
    for reason, fields in gnss_cases:
        k += 1
        rig.send(_epoch_with(good_epoch, t_ns + k * 10**6, 1, **fields))
        status = rig.last_status()
        assert stamp_of(status) == t_ns + k * 10**6, reason
        assert status.satellites_rejected >= 1 and status.satellites_used + status.satellites_rejected == n_sats
    expected = Counter({'invalid_range_std': 5, 'nonphysical_anchor_position': 3})
    expected.update(reason for reason, _ in gnss_cases)
    values = rig.node.accounting()
    for reason, count in expected.items():
        assert rig.node.rejection_reasons()[reason] == count and values[f'rejected.{reason}'] == count, reason
    assert rig.node.counts['gnss_processed'] == before['gnss_processed'] + len(gnss_cases)
    assert values['accounting_ok']
    # the filter carries on as if the impossible values had never been sent
    for s, _, msg in inputs[len(first_half):]:
        if s > t_ns + (k + 1) * 10**6:
            rig.send(msg)
    assert rig.last_status().initialized and rig.last_status().reinitializations == 0
    assert_no_nan_published(rig)
    t, p = positions(rig.out['/fusion/odometry'])
    tail = t > t_ns + 5 * 10**9
    assert np.sqrt(np.mean(horizontal_error_m(ecef_errors_enu(p[tail], truth)) ** 2)) < GOAL_HORIZONTAL_RMS_M


@pytest.mark.parametrize('window_s', [0.0, 0.1])
def test_exact_duplicates_are_rejected_and_counted(rig_factory, clean_stream, window_s):
    _, inputs = clean_stream
    rig = rig_factory({'reorder_window_s': window_s})
    head = inputs[:60]
    for _, _, msg in head:
        rig.send(msg)
        rig.send(copy.deepcopy(msg))   # the same message again, right behind it
    n_gnss = sum(1 for _, t, _ in head if t == '/gnss/measurements')
    n_uwb = len(head) - n_gnss
    assert rig.node.reasons['duplicate_gnss_epoch'] == n_gnss
    assert rig.node.reasons['duplicate_uwb_range'] == n_uwb
    # the same stamp with another content is a duplicate epoch too; another anchor is another range
    last_epoch = next(m for _, t, m in reversed(head) if t == '/gnss/measurements')
    other = copy.deepcopy(last_epoch)
    other.measurements = other.measurements[:5]
    rig.send(other)
    assert rig.node.reasons['duplicate_gnss_epoch'] == n_gnss + 1
    last_uwb = next(m for _, t, m in reversed(head) if t == '/uwb/ranges')
    other_anchor = copy.deepcopy(last_uwb)
    other_anchor.anchor_id = 'another'
    rig.send(other_anchor)
    assert rig.node.reasons['duplicate_uwb_range'] == n_uwb
    rig.node.end_of_input()
    rig.settle('uwb')
    values = rig.node.accounting()
    assert values['accounting_ok'] and values['gnss_processed'] == n_gnss and values['uwb_processed'] == n_uwb + 1
    statuses = rig.out['/fusion/status']
    assert len(statuses) == len(head) + 1
    assert [stamp_of(s) for s in statuses[:len(head)]] == [s for s, _, _ in head]


def test_jammer_state_of_unknown_type_is_rejected(rig_factory, clean_stream):
    _, inputs = clean_stream
    rig = rig_factory({'divergence_fix_confirm_s': 0.0, 'reorder_window_s': 0.0})
    for _, _, msg in inputs[:20]:
        rig.send(msg)
    t = inputs[19][0]
    odd = JammerState(type=200, jammer_to_signal_db=22.0)
    odd.header.stamp = ns_to_stamp(t + 1)
    rig.send(odd)
    rig.send(restamped(inputs[20][2], t + 2))
    assert rig.node.reasons['jammer_state_unknown_type'] == 1 and rig.node.counts['jammer_processed'] == 0
    assert math.isnan(rig.last_status().jammer_to_signal_db)   # not used
    for jammer_type in (JammerState.CW, JammerState.CHIRP, JammerState.WIDEBAND, JammerState.UNKNOWN):
        known = JammerState(type=jammer_type, jammer_to_signal_db=10.0 + jammer_type)
        t += 10
        known.header.stamp = ns_to_stamp(t)
        rig.send(known)
        rig.send(restamped(inputs[20][2], t + 1))
        assert rig.last_status().jammer_to_signal_db == 10.0 + jammer_type
    values = rig.node.accounting()
    assert values['jammer_rejected'] == 1 and values['jammer_processed'] == 4 and values['accounting_ok']


# ---------------------------------------------------------------------------------- end of input
def fields(msg):
    """A message as nested tuples, NaN-safe, for comparing outputs field for field."""
    if hasattr(msg, 'get_fields_and_field_types'):
        return tuple((name, fields(getattr(msg, name))) for name in msg.get_fields_and_field_types())
    if isinstance(msg, (list, tuple)) or type(msg).__name__ == 'array' or hasattr(msg, 'tolist'):
        return tuple(fields(v) for v in (msg.tolist() if hasattr(msg, 'tolist') else msg))
    if isinstance(msg, float) and math.isnan(msg):
        return 'nan'
    return msg


def test_end_of_input_processes_the_buffer_in_order_with_the_same_results(rig_factory, clean_stream):
    _, inputs = clean_stream
    head = inputs[:80]
    reference = rig_factory({'reorder_window_s': 0.0})   # in-order input: processed at once
    for _, _, msg in head:
        reference.send(msg)
    rig = rig_factory({'reorder_window_s': 0.1})
    for _, _, msg in head:
        rig.send(msg)
    newest = head[-1][0]
    held = sum(1 for s, _, _ in head if s > newest - 10**8)
    assert sum(rig.node.buffered.values()) == held > 0
    assert rig.node.end_of_input() == held
    rig.settle('gnss')
    assert sum(rig.node.buffered.values()) == 0 and rig.node.counts['end_of_input_flushes'] == 1
    for topic in ('/fusion/status', '/fusion/odometry', '/fusion/fix'):
        assert [fields(m) for m in rig.out[topic]] == [fields(m) for m in reference.out[topic]], topic
    assert rig.node.end_of_input() == 0
    # a message older than the last one processed is late afterwards, as any late message
    rig.send(restamped(head[-3][2], head[-3][0] - 1))
    assert rig.node.reasons['late_beyond_reorder_window'] == 1
    assert rig.node.accounting()['accounting_ok']


def test_idle_input_flushes_the_buffer(rig_factory, clean_stream):
    _, inputs = clean_stream
    # 60 s: no pause between two sends, however loaded the machine, lets the timer flush by itself (then
    # idle_flushes would be 2 and fewer messages held); the timer's own flush is the quick rig's below
    rig = rig_factory({'reorder_window_s': 0.1, 'idle_flush_s': 60.0})
    assert rig.node.idle_flush_timer is not None
    for _, _, msg in inputs[:30]:
        rig.send(msg)
    held = sum(rig.node.buffered.values())
    assert held > 0
    assert rig.node.flush_if_idle() == 0            # input arrived just now: not idle
    rig.node.health.last_activity_s -= 120.0        # as if 2 minutes of wall time had passed without input
    assert rig.node.flush_if_idle() == held
    rig.settle('uwb')
    assert sum(rig.node.buffered.values()) == 0 and rig.node.counts['idle_flushes'] == 1
    assert len(rig.out['/fusion/status']) == 30 and rig.node.accounting()['accounting_ok']
    # the timer does it by itself: spin (bounded) until a short idle time has drained the buffer
    quick = rig_factory({'reorder_window_s': 0.1, 'idle_flush_s': 0.05})
    for _, _, msg in inputs[:30]:
        quick.send(msg)
    quick.spin_until(lambda: sum(quick.node.buffered.values()) == 0
                     and len(quick.out['/fusion/status']) == quick.published['/fusion/status'] == 30)
    # off: nothing is processed without newer input
    off = rig_factory({'reorder_window_s': 0.1, 'idle_flush_s': 0.0})
    assert off.node.idle_flush_timer is None


def test_buffer_is_processed_when_the_node_is_destroyed(clean_stream):
    _, inputs = clean_stream
    rig = Rig({'reorder_window_s': 0.1})
    try:
        for _, _, msg in inputs[:30]:
            rig.send(msg)
        held = sum(rig.node.buffered.values())
        processed = rig.node.counts['uwb_processed'] + rig.node.counts['gnss_processed']
    finally:
        rig.close()
    assert held > 0 and sum(rig.node.buffered.values()) == 0
    assert rig.node.counts['uwb_processed'] + rig.node.counts['gnss_processed'] == processed + held


# ---------------------------------------------------------------------------------- late input
def test_reorder_window_grows_after_late_arrivals_up_to_its_maximum(rig_factory, clean_stream):
    _, inputs = clean_stream
    rig = rig_factory({'reorder_window_s': 0.1, 'reorder_window_max_s': 1.0})
    uwb = [(s, m) for s, t, m in inputs if t == '/uwb/ranges']
    t0 = uwb[0][0]
    sent = [(s, m) for s, m in uwb if s < t0 + 2 * 10**9]
    for _, msg in sent:
        rig.send(msg)
    newest = sent[-1][0]
    # 0.3 s late: older than what was released, rejected; the window grows to 0.45 s
    rig.send(restamped(sent[0][1], newest - 3 * 10**8))
    assert rig.node.reasons['late_beyond_reorder_window'] == 1
    assert rig.node.reorder_window_s == pytest.approx(0.45)
    assert rig.node.counts['reorder_window_growths'] == 1
    # from now on ranges 0.3 s late are taken and applied in stamp order
    later = [(s, m) for s, m in uwb if newest < s < newest + 2 * 10**9]
    statuses_before = len(rig.out['/fusion/status'])
    for i, (s, msg) in enumerate(later):
        rig.send(msg)
        if i % 10 == 9:
            rig.send(restamped(msg, s - 3 * 10**8 + 1))
    assert rig.node.reasons['late_beyond_reorder_window'] == 1
    stamps = [stamp_of(st) for st in rig.out['/fusion/status'][statuses_before:]]
    assert stamps == sorted(stamps) and len(stamps) > 0
    assert rig.node.accounting()['reorder_window_s'] == pytest.approx(0.45)
    # 0.9 s late: the window stops at the maximum; far later than the maximum: rejected, no change
    rig.send(restamped(sent[0][1], later[-1][0] - 9 * 10**8))
    assert rig.node.reasons['late_beyond_reorder_window'] == 2 and rig.node.reorder_window_s == 1.0
    small = rig_factory({'reorder_window_s': 0.1, 'reorder_window_max_s': 0.5})
    for _, msg in sent:
        small.send(msg)
    small.send(restamped(sent[0][1], newest - 6 * 10**8))
    assert small.node.reasons['late_beyond_reorder_window'] == 1 and small.node.reorder_window_s == 0.1
    assert rig.node.accounting()['accounting_ok'] and small.node.accounting()['accounting_ok']


def test_reorder_window_stays_fixed_when_its_maximum_is_not_above_it(rig_factory, clean_stream):
    _, inputs = clean_stream
    rig = rig_factory({'reorder_window_s': 0.1, 'reorder_window_max_s': 0.0})
    for _, _, msg in inputs[:40]:
        rig.send(msg)
    rig.send(restamped(inputs[5][2], inputs[5][0]))
    assert rig.node.reasons['late_beyond_reorder_window'] == 1 and rig.node.reorder_window_s == 0.1


# ---------------------------------------------------------------------------------- drivers, STALE
def test_best_effort_publisher_reaches_the_node(rig_factory, clean_stream):
    """A sensor driver publishes with qos_profile_sensor_data (best effort): accepted and processed."""
    from rclpy.qos import qos_profile_sensor_data

    _, inputs = clean_stream
    rig = rig_factory({'divergence_fix_confirm_s': 0.0, 'reorder_window_s': 0.0})
    for cls in (GnssMeasurementArray, UwbRange):
        rig.pubs[TOPICS[cls]] = rig.io.create_publisher(cls, TOPICS[cls], qos_profile_sensor_data)
    rig.spin_until(lambda: all(rig.pubs[TOPICS[c]].get_subscription_count() >= 1
                               for c in (GnssMeasurementArray, UwbRange)))
    for _, _, msg in inputs[:20]:
        rig.send(msg)
    assert len(rig.out['/fusion/status']) == 20 and rig.last_status().initialized
    values = rig.node.accounting()
    assert values['input./uwb/ranges.received'] == values['uwb_received'] == rig.sent['uwb']
    assert values['input./gnss/measurements.received'] == values['gnss_received'] == rig.sent['gnss']


def test_silent_node_reports_stale(rig_factory, clean_stream):
    _, inputs = clean_stream
    rig = rig_factory({'reorder_window_s': 0.0, 'input_timeout_s': 5.0})
    assert rig.node.stale_watch.timer is not None
    assert not rig.node.stale_watch.check()         # just started: not silent yet
    rig.node.health.started_s -= 60.0               # as if a minute had passed with no input
    before_ns = rig.node.get_clock().now().nanoseconds
    assert rig.node.stale_watch.check()
    rig.spin_until(lambda: len(rig.out['/diagnostics']) == rig.published['/diagnostics'] == 1)
    stale = rig.out['/diagnostics'][-1]
    status = stale.status[0]
    assert status.level == DiagnosticStatus.STALE and status.message.startswith('no input for 6')
    assert stamp_of(stale) >= before_ns                   # the node clock's now, not a message stamp
    values = {kv.key: kv.value for kv in status.values}
    assert values['input./uwb/ranges.received'] == '0' and values['accounting_ok'] == 'True'
    # input arrives: the stamp-timed reports resume, and the node is not stale
    for _, _, msg in inputs[:5]:
        rig.send(msg)
    assert rig.out['/diagnostics'][-1].status[0].level != DiagnosticStatus.STALE
    assert not rig.node.stale_watch.check()
    # the timer does it by itself (bounded spin)
    quick = rig_factory({'reorder_window_s': 0.0, 'input_timeout_s': 0.05})
    quick.spin_until(lambda: any(a.status[0].level == DiagnosticStatus.STALE for a in quick.out['/diagnostics']))


def test_handler_errors_and_lost_messages_set_the_diagnostics_level(rig_factory, clean_stream):
    _, inputs = clean_stream
    rig = rig_factory({'divergence_fix_confirm_s': 0.0, 'reorder_window_s': 0.0, 'diagnostics_period_s': 0.01})
    for _, _, msg in inputs[:20]:
        rig.send(msg)
    # lost before the node (a sequence gap or the middleware's event): WARN
    rig.node.health.middleware_lost('/uwb/ranges', 3)
    rig.send(inputs[20][2])
    status = rig.out['/diagnostics'][-1].status[0]
    assert status.level == DiagnosticStatus.WARN and 'messages lost 3/' in status.message
    # a handler that raises (a bug): counted by the subscription's guard, ERROR, and the node goes on
    accept = rig.node._accept_uwb
    rig.node._accept_uwb = lambda *args: (_ for _ in ()).throw(RuntimeError('bug'))
    rig.pubs[TOPICS[UwbRange]].publish(next(m for s, t, m in inputs[21:] if t == '/uwb/ranges'))
    rig.spin_until(lambda: rig.node.health.callback_errors_total() == 1)
    rig.node._accept_uwb = accept
    for _, _, msg in inputs[22:30]:
        rig.send(msg)
    levels = [a.status[0].level for a in rig.out['/diagnostics'][-8:]]
    assert levels.count(DiagnosticStatus.ERROR) == 1 and levels[-1] != DiagnosticStatus.ERROR
    error = next(a.status[0] for a in rig.out['/diagnostics'] if a.status[0].level == DiagnosticStatus.ERROR)
    assert 'handler' in error.message
    assert diag_values(rig)['input./uwb/ranges.callback_errors'] == '1'


# ---------------------------------------------------------------------------------- local frame (issue 11 item 2)
# What robot_localization reads (cra-ros-pkg/robot_localization, ros2 branch):
# * ekf_node, odomN input (RosFilter::odometryCallback): the pose part as a PoseWithCovarianceStamped with
#   header = the message's header (frame_id: the world frame, map_frame / odom_frame of the EKF, or a frame
#   tf can transform) and pose.covariance (6x6 row-major x, y, z, roll, pitch, yaw); the twist part with
#   header.frame_id = child_frame_id (base_link_frame, or a frame tf can transform into it) and
#   twist.covariance. A message older than the previous one of the topic is ignored (RosFilter::poseCallback:
#   processed when last_message_time <= stamp).
# * navsat_transform_node, gps/fix input (NavSatTransform::gpsFixCallback): header.frame_id (the GPS
#   frame, looked up in tf against base_link; empty: "assume mounted at the robot's origin"),
#   header.stamp, status.status != STATUS_NO_FIX, latitude / longitude / altitude not NaN, and the
#   3x3 position_covariance (ENU).
EKF_MAP_FRAME, EKF_BASE_LINK_FRAME = 'map', 'base_link'
"""robot_localization's default map_frame and base_link_frame."""


def vec(p) -> np.ndarray:
    return np.array([p.x, p.y, p.z])


def assert_ekf_readable(odom: Odometry) -> None:
    """The fields an EKF odometry input reads: finite, symmetric covariances with positive diagonals, a
    unit quaternion, unestimated quantities marked by ORIENTATION_UNKNOWN_VARIANCE_RAD2."""
    q = odom.pose.pose.orientation
    assert math.isclose(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2, 1.0, rel_tol=1e-12)
    for cov in (np.array(odom.pose.covariance).reshape(6, 6), np.array(odom.twist.covariance).reshape(6, 6)):
        assert np.all(np.isfinite(cov)) and np.allclose(cov, cov.T)
        assert np.all(np.linalg.eigvalsh(cov[:3, :3]) > 0)
        assert np.all(np.diag(cov) > 0)
    assert odom.pose.covariance[21] == odom.pose.covariance[28] == ORIENTATION_UNKNOWN_VARIANCE_RAD2  # roll, pitch
    assert all(odom.twist.covariance[k] == ORIENTATION_UNKNOWN_VARIANCE_RAD2 for k in (21, 28, 35))
    assert all(math.isfinite(x) for x in (*vec(odom.pose.pose.position), *vec(odom.twist.twist.linear)))


def test_local_odometry_and_fix_are_what_robot_localization_reads(rig_factory, clean_stream):
    _, inputs = clean_stream
    lever = [0.3, -0.4, 1.2]
    rig = rig_factory({'reorder_window_s': 0.0, 'antenna_position_m': lever})
    for _, _, msg in inputs[:120]:
        rig.send(msg)
    ecef, local, fixes = rig.out['/fusion/odometry'], rig.out['/fusion/local_odometry'], rig.out['/fusion/fix']
    assert len(local) == len(ecef) == len(fixes) > 50
    assert [stamp_of(m) for m in local] == [stamp_of(m) for m in ecef]
    # the origin: the first published ECEF solution, published once (latched) as a NavSatFix
    (datum,) = rig.out['/fusion/datum']
    origin = vec(ecef[0].pose.pose.position)
    lat, lon, alt = ecef_to_geodetic(origin)
    assert datum.header.frame_id == 'map' and stamp_of(datum) == stamp_of(ecef[0])
    assert (datum.latitude, datum.longitude) == pytest.approx((math.degrees(lat), math.degrees(lon)), abs=1e-9)
    assert datum.altitude == pytest.approx(alt, abs=1e-6)
    for e, m in zip(ecef, local, strict=True):
        # the EKF's frames: pose in map, twist in base_link
        assert (m.header.frame_id, m.child_frame_id) == (EKF_MAP_FRAME, EKF_BASE_LINK_FRAME)
        assert_ekf_readable(m)
        enu = ecef_to_enu(vec(e.pose.pose.position), origin)
        # no yaw (heading_source none): the vertical lever arm applies, the horizontal one widens the covariance
        np.testing.assert_allclose(vec(m.pose.pose.position), enu - [0.0, 0.0, 1.2], atol=1e-6)
        assert (m.pose.pose.orientation.w, m.pose.covariance[35]) == (1.0, ORIENTATION_UNKNOWN_VARIANCE_RAD2)
        assert m.pose.covariance[0] > 0.25 / 2 and m.pose.covariance[7] > 0.25 / 2
        # body velocity: horizontal direction unknown (mean 0), vertical the ENU vertical velocity
        assert (m.twist.twist.linear.x, m.twist.twist.linear.y) == (0.0, 0.0)
    # the static receiver: body velocity known to be small once converged
    assert max(local[-1].twist.covariance[0], local[-1].twist.covariance[7]) < 0.1
    # navsat_transform's input is /fusion/fix, unchanged
    for fix in fixes:
        assert fix.header.frame_id == 'gnss_antenna' and fix.status.status != fix.status.STATUS_NO_FIX
        assert not any(math.isnan(x) for x in (fix.latitude, fix.longitude, fix.altitude))
        assert np.all(np.isfinite(fix.position_covariance))
        assert fix.position_covariance_type == fix.COVARIANCE_TYPE_KNOWN
    # the EKF ignores a message older than the previous one of its topic (an equal stamp passes: a GNSS
    # epoch and a UWB range of one instant give two solutions with that stamp)
    for msgs in (fixes, local):
        stamps = [stamp_of(m) for m in msgs]
        assert stamps == sorted(stamps)
    # a subscriber that joins late still gets the datum (latched)
    from rfi_node_common.qos import LATCHED_QOS
    late: list = []
    rig.io.create_subscription(NavSatFix, '/fusion/datum', late.append, LATCHED_QOS)
    rig.spin_until(lambda: len(late) == 1, 'latched datum')
    assert late[0].latitude == datum.latitude


def test_datum_parameter_is_the_origin_and_velocity_heading_rotates_the_lever_arm(rig_factory, clean_stream):
    truth, inputs = clean_stream
    lat, lon, alt = ecef_to_geodetic(truth)
    datum = [math.degrees(lat), math.degrees(lon), alt - 2.0]
    min_speed_mps = 0.02   # below the default: the static stream's converging filter moves by centimetres per second
    rig = rig_factory({'divergence_fix_confirm_s': 0.0, 'reorder_window_s': 0.0, 'local_origin': 'datum',
                       'datum': datum, 'antenna_position_m': [0.5, 0.0, 0.0], 'heading_source': 'velocity',
                       'heading_min_speed_mps': min_speed_mps})
    for _, _, msg in inputs[:60]:
        rig.send(msg)
    origin = geodetic_to_ecef(lat, lon, alt - 2.0)
    ecef, local = rig.out['/fusion/odometry'], rig.out['/fusion/local_odometry']
    assert rig.out['/fusion/datum'][0].altitude == pytest.approx(alt - 2.0, abs=1e-9)
    lat0, lon0 = math.radians(datum[0]), math.radians(datum[1])
    rotation = ecef_to_enu_rotation(lat0, lon0)
    known = 0
    for e, m in zip(ecef, local, strict=True):
        enu = ecef_to_enu(vec(e.pose.pose.position), origin)
        v_enu = rotation @ vec(e.twist.twist.linear)
        q = m.pose.pose.orientation
        if m.pose.covariance[35] < ORIENTATION_UNKNOWN_VARIANCE_RAD2:
            # moving (here: the velocity of the converging filter) above heading_min_speed_mps: yaw = course
            known += 1
            yaw = 2.0 * math.atan2(q.z, q.w)
            assert math.hypot(v_enu[0], v_enu[1]) >= min_speed_mps
            assert yaw == pytest.approx(math.atan2(v_enu[1], v_enu[0]), abs=1e-9)
            lever = np.array([0.5 * math.cos(yaw), 0.5 * math.sin(yaw), 0.0])
            np.testing.assert_allclose(vec(m.pose.pose.position), enu - lever, atol=1e-6)
            assert m.twist.twist.linear.x == pytest.approx(math.hypot(v_enu[0], v_enu[1]), abs=1e-9)
            assert m.twist.twist.linear.y == pytest.approx(0.0, abs=1e-9)
        else:   # slower: yaw unknown, the horizontal lever arm only widens the covariance
            assert math.hypot(v_enu[0], v_enu[1]) < min_speed_mps and (q.z, q.w) == (0.0, 1.0)
            np.testing.assert_allclose(vec(m.pose.pose.position), enu, atol=1e-6)
    assert 0 < known < len(local)
    assert abs(vec(local[-1].pose.pose.position)[2] - 2.0) < 1.0   # the datum 2 m below the antenna


def test_parameters_set_while_running_are_validated_as_at_start_and_applied_between_messages(rig_factory,
                                                                                              clean_stream):
    from rfi_node_common.params import set_parameters_remotely

    _, inputs = clean_stream
    rig = rig_factory({'reorder_window_s': 0.0, 'diagnostics_period_s': 0.01})
    for _, _, msg in inputs[:30]:
        rig.send(msg)

    def param_set(**values):
        return set_parameters_remotely(rig.io, rig.executor, '/uwb_gnss_fusion', values)

    results = param_set(min_cn0_dbhz=30.0, hardware_id='ublox-f9p#7', antenna_position_m=[0.0, 0.0, 1.0],
                        warn_rejected_fraction=0.5)
    assert all(r.successful for r in results), [r.reason for r in results]
    assert rig.node.params.min_cn0_dbhz == 20.0 and rig.node.runtime.pending   # applied at the next message
    before = len(rig.out['/fusion/local_odometry'])
    for _, _, msg in inputs[30:40]:
        rig.send(msg)
    origin = vec(rig.out['/fusion/odometry'][0].pose.pose.position)
    for k, (e, m) in enumerate(zip(rig.out['/fusion/odometry'], rig.out['/fusion/local_odometry'], strict=True)):
        lever_up = 1.0 if k >= before else 0.0   # the new antenna position from the first message after the set
        enu = ecef_to_enu(vec(e.pose.pose.position), origin)
        assert m.pose.pose.position.z == pytest.approx(enu[2] - lever_up, abs=1e-6)
    assert rig.node.params.min_cn0_dbhz == 30.0 and rig.node.filter.params.min_cn0_dbhz == 30.0
    assert rig.node.params.warn_rejected_fraction == 0.5 and rig.node.counts['parameter_changes'] == 1
    assert rig.out['/diagnostics'][-1].status[0].hardware_id == 'ublox-f9p#7'
    # refused: read-only (the core derives its gate at construction; buffers size state)
    for name, value in (('gate_probability', 0.999), ('reorder_window_s', 0.5), ('datum', [1.0, 2.0, 3.0])):
        (result,) = param_set(**{name: value})
        assert not result.successful and 'read-only' in result.reason, name
    # refused by the descriptor's range (rclpy), as at start
    (result,) = param_set(min_cn0_dbhz=80.0)
    assert not result.successful and 'out of range' in result.reason
    # refused by the dataclass's validation: the same message as at start
    for name, value in (('heading_source', 'compass'), ('antenna_position_m', [0.0, 1.0])):
        (result,) = param_set(**{name: value})
        with pytest.raises(ValueError) as at_start:
            FusionNodeParams(**{name: tuple(value) if isinstance(value, list) else value})
        assert not result.successful and result.reason == str(at_start.value), name
    assert rig.node.runtime.changes_refused == 2 and not rig.node.runtime.pending
    assert rig.node.params.heading_source == 'none' and rig.node.get_parameter('heading_source').value == 'none'
    for _, _, msg in inputs[40:50]:
        rig.send(msg)
    assert diag_values(rig)['parameter_changes_refused'] == '2'


# Settable filter parameters: the core must read each at every update, so that a change is applied
# (FusionNode._apply_parameters replaces FusionFilter.params). Checked per parameter: a filter built
# with the default and given the new value before the first input behaves exactly as one built with
# the new value (a value the core cached at construction would make them differ), and the new value
# changes the outputs on this data (so the check is not vacuous) unless listed in NO_EFFECT_HERE.
SETTABLE_FILTER_VALUES = {
    'uwb_range_std_m': 0.3, 'uwb_max_range_m': 12.0, 'elevation_mask_deg': 40.0, 'min_cn0_dbhz': 44.0,
    'nominal_cn0_dbhz': 35.0, 'jammer_quality_factor': 2.0, 'jammer_info_timeout_s': 0.05,
    'loop_dll_bandwidth_hz': 4.0, 'loop_correlator_spacing_chips': 1.0, 'loop_integration_time_s': 0.001,
    'loop_fll_bandwidth_hz': 10.0, 'loop_code_floor_m': 3.0, 'loop_rate_floor_mps': 0.5,
    'max_position_std_m': 0.02, 'divergence_gnss_epochs': 1, 'divergence_uwb_gated_fraction': 0.01,
    'uwb_huber_k': 0.3, 'uwb_huber_k_positive': 0.3, 'nonlinearity_threshold': 1e-6, 'max_update_iterations': 0,
    'common_mode_screen': False, 'receiver_clock_steps': False, 'uwb_mirror_covariance': False,
    'uwb_mirror_gnss_std_m': 0.5,
}
NO_EFFECT_HERE: dict[str, str] = {}
"""Settable filter parameters whose test value does not change the outputs of this short clean run, and why."""


def test_every_settable_filter_parameter_is_read_by_the_core_at_each_update(clean_stream):
    import dataclasses

    from rfi_node_common.conversions import msg_to_epoch
    from rfi_node_common.params import runtime_parameter_names
    from uwb_gnss_fusion.fusion_filter import FusionFilter, FusionParams

    core_names = {f.name for f in dataclasses.fields(FusionParams)} | {
        name for name in FusionNodeParams.__dataclass_fields__ if name.startswith('loop_')}
    assert set(runtime_parameter_names(FusionNodeParams)) & core_names == set(SETTABLE_FILTER_VALUES)
    _, inputs = clean_stream
    items = []
    t0 = inputs[0][0]
    for stamp, topic, msg in inputs[:400]:
        rel_s = (stamp - t0) * 1e-9
        if topic == '/gnss/measurements':
            epoch = msg_to_epoch(msg)
            if 3.0 <= rel_s < 4.0:   # a burst of pseudorange outliers on most satellites (a jammed receiver)
                observations = tuple(dataclasses.replace(o, pseudorange_m=o.pseudorange_m + 150.0 * (k + 1))
                                     if k < 5 else o for k, o in enumerate(epoch.observations))
                epoch = dataclasses.replace(epoch, observations=observations)
            if rel_s >= 8.0:   # the receiver steps its clock by 1 ms (every pseudorange + 299,792.458 m)
                epoch = dataclasses.replace(epoch, observations=tuple(
                    dataclasses.replace(o, pseudorange_m=o.pseudorange_m + 299_792.458) for o in epoch.observations))
            items.append((stamp, 'gnss', epoch))
        else:
            uwb = msg_to_uwb(msg, frame_id='earth')
            if 5.0 <= rel_s < 5.5 and uwb.anchor_id == 'A1':   # NLOS ranges of one anchor
                uwb = dataclasses.replace(uwb, range_m=uwb.range_m + 2.0)
            items.append((stamp, 'uwb', uwb))

    def run(f: FusionFilter) -> np.ndarray:
        out = []
        for k, (stamp, kind, payload) in enumerate(items):
            if k % 50 == 0:
                f.set_jammer_to_signal(stamp, 20.0)
            o = f.process_gnss(payload) if kind == 'gnss' else f.process_uwb(payload)
            out.append(np.concatenate([o.position_m, o.velocity_mps, np.diag(o.covariance_pv),
                                       [o.satellites_used, o.uwb_used, o.reinitializations]]))
        return np.array(out)

    reference = run(FusionFilter(FusionNodeParams().fusion_params()))
    no_effect = {}
    for name, value in SETTABLE_FILTER_VALUES.items():
        changed = FusionNodeParams(**{name: value}).fusion_params()
        built = run(FusionFilter(changed))
        swapped_filter = FusionFilter(FusionNodeParams().fusion_params())
        swapped_filter.params = changed
        swapped = run(swapped_filter)
        assert np.array_equal(built, swapped, equal_nan=True), name
        if np.array_equal(built, reference, equal_nan=True):
            no_effect[name] = 'no effect'
    assert set(no_effect) == set(NO_EFFECT_HERE), no_effect


def settable_in_config(text: str) -> set[str]:
    """Parameters a config file marks ``[settable while running]`` in the comment block above them (a key
    right below another key, without a comment of its own, belongs to that key's block)."""
    import re

    settable, block, previous = set(), [], False
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith('#'):
            block.append(stripped)
            continue
        key = re.match(r'^\s{4}([a-z0-9_]+):', line)
        if key:
            marked = any('[settable while running' in c for c in block) if block else previous
            if marked:
                settable.add(key.group(1))
            previous = marked
        block = []
    return settable


def test_config_marks_exactly_the_settable_parameters():
    from rfi_node_common.params import runtime_parameter_names

    assert settable_in_config(CONFIG.read_text()) == set(runtime_parameter_names(FusionNodeParams))
