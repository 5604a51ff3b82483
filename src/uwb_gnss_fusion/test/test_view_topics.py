"""The fusion's topics made to be drawn (issue 30): geometry (pure) and the node's /fusion/path, /fusion/markers and
/fusion/satellites, published valid and only while subscribed (in-process: one Context per test, a
SingleThreadedExecutor, bounded spins). Inputs: the half-simulated GNSS/UWB stream of test_fusion_node.py (real ARL1
broadcast ephemeris, static receiver, three anchors)."""

from __future__ import annotations

import copy
import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from visualization_msgs.msg import Marker, MarkerArray

from gnss_common.coordinates import ecef_to_enu, geodetic_to_ecef
from rfi_msgs.msg import FusionStatus, GnssMeasurementArray, UwbRange
from rfi_node_common import testing
from rfi_node_common.conversions import epoch_to_msg, uwb_to_msg
from rfi_node_common.qos import DATA_QOS
from rfi_node_common.stamps import stamp_to_ns
from rfi_node_common.testing import NodeRig
from rfi_sim.gnss_uwb import BroadcastGeometry, GnssUwbScenario, simulate
from uwb_gnss_fusion.fusion_node import TOPICS as NODE_TOPICS
from uwb_gnss_fusion.fusion_node import FusionNode
from uwb_gnss_fusion.fusion_view import covariance_ellipse, satellite_label, sky_directions
from uwb_gnss_fusion.view_topics import MARKERS_TOPIC, PATH_TOPIC, SATELLITES_TOPIC, TOPICS

NAV_FILE = Path(__file__).resolve().parents[2] / 'gnss_common' / 'test' / 'data' / 'arlm2000.15n'
KIND = {GnssMeasurementArray: 'gnss', UwbRange: 'uwb'}


# ---------------------------------------------------------------------------------------------- pure
@pytest.mark.parametrize('angle_deg', [0.0, 30.0, -60.0, 89.0])
def test_covariance_ellipse_recovers_the_axes_it_was_built_from(angle_deg):
    a, b, yaw = 3.0, 0.5, math.radians(angle_deg)
    r = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    cov = r @ np.diag([a * a, b * b]) @ r.T
    k95 = math.sqrt(5.991464547107979)                    # chi-square quantile, 2 dof, 0.95
    got_a, got_b, got_yaw = covariance_ellipse(cov, 0.95)
    assert got_a == pytest.approx(k95 * a) and got_b == pytest.approx(k95 * b)
    assert got_yaw == pytest.approx(yaw)
    assert math.isnan(covariance_ellipse(np.full((2, 2), np.nan), 0.95)[0])


def test_sky_directions_and_labels():
    rx = np.asarray(geodetic_to_ecef(0.0, 0.0, 0.0), dtype=float)       # equator, Greenwich: up is +x ECEF
    sats = np.array([rx + [2.0e7, 0.0, 0.0], rx + [0.0, 2.0e7, 0.0], [np.nan, 0.0, 0.0]])
    d = sky_directions(rx, sats)
    assert d[0] == pytest.approx([0.0, 0.0, 1.0]) and d[1] == pytest.approx([1.0, 0.0, 0.0])   # zenith, east
    assert np.isnan(d[2]).all()
    assert [satellite_label(k) for k in (1005, 2012, 3011, 4030, 9001)] == ['G05', 'R12', 'E11', 'C30', '?01']


def test_the_node_help_names_every_topic_it_draws():
    for topic, type_name in TOPICS:
        assert f'/{topic} ({type_name.replace("/msg/", "/")}' in NODE_TOPICS


# ---------------------------------------------------------------------------------------------- node
@pytest.fixture(scope='module')
def stream():
    """8 s, no jamming, UWB 5 Hz per anchor: (truth ECEF (3,), [msg, ...] in stamp order)."""
    geometry = BroadcastGeometry(NAV_FILE)
    run = simulate(GnssUwbScenario(duration_s=8.0, seed=11, uwb_rate_hz=5.0), geometry, geometry.iono_alpha,
                   geometry.iono_beta)
    items = [(e.stamp_ns, 0, epoch_to_msg(e)) for e in run.gnss_epochs]
    items += [(u.stamp_ns, 1, uwb_to_msg(u)) for u in run.uwb_ranges]
    items.sort(key=lambda item: (item[0], item[1]))
    return np.array(GnssUwbScenario().receiver_ecef_m), [m for _, _, m in items], run


class Rig(NodeRig):
    """The fusion node with publishers of its inputs; the drawn topics collected only if ``drawn``."""

    def __init__(self, drawn: bool, **params) -> None:
        outputs: dict = {'/fusion/status': FusionStatus, '/fusion/local_odometry': Odometry}
        if drawn:
            outputs.update({'/' + PATH_TOPIC: PathMsg, '/' + MARKERS_TOPIC: MarkerArray,
                            '/' + SATELLITES_TOPIC: MarkerArray})
        base = {'idle_flush_s': 0.0, 'input_timeout_s': 0.0, 'reorder_window_s': 0.0, **params}
        super().__init__(lambda context, ov: FusionNode(context=context, parameter_overrides=ov),
                         inputs={'/gnss/measurements': (GnssMeasurementArray, DATA_QOS),
                                 '/uwb/ranges': (UwbRange, DATA_QOS)},
                         outputs=outputs, params=base, name='fusion_view_test_io')
        self.sent: Counter[str] = Counter()

    def send(self, msg) -> None:
        kind = KIND[type(msg)]
        self.pubs['/gnss/measurements' if kind == 'gnss' else '/uwb/ranges'].publish(msg)
        self.sent[kind] += 1
        self.settle_until(lambda: self.node.counts[f'{kind}_received'] == self.sent[kind])


@pytest.fixture
def rig_factory():
    with testing.rig_factory(Rig) as make:
        yield make


def test_nothing_is_drawn_while_nobody_subscribes(rig_factory, stream, monkeypatch):
    _, msgs, _ = stream
    rig = rig_factory(drawn=False, view_rate_hz=100.0)
    made = []
    monkeypatch.setattr(rig.node.view, 'markers', lambda *a: made.append(a))
    monkeypatch.setattr(rig.node.view, 'satellites', lambda *a: made.append(a))
    for m in msgs:
        rig.send(m)
    assert rig.out['/fusion/local_odometry']                      # the filter ran and published ...
    assert made == [] and rig.node.view.published == 0            # ... and nothing was drawn or kept
    assert not rig.node.view.active and not rig.node.view._path and not rig.node.view._anchors
    assert rig.node.counts['view_errors'] == 0


def test_path_markers_and_satellites_are_valid_and_in_map(rig_factory, stream):
    truth, msgs, run = stream
    # the last epoch's first satellite 300 m off: the filter rejects it (common-mode screen or gate)
    last_gnss = max(i for i, m in enumerate(msgs) if isinstance(m, GnssMeasurementArray))
    bad = copy.deepcopy(msgs[last_gnss])
    bad.measurements[0].pseudorange_m += 300.0
    bad_label = satellite_label(bad.measurements[0].constellation * 1000 + bad.measurements[0].svid)
    msgs = msgs[:last_gnss] + [bad] + msgs[last_gnss + 1:]
    rate_hz = 5.0      # the GNSS epoch rate: every epoch is drawn (it comes first among the inputs of its stamp)
    rig = rig_factory(drawn=True, view_rate_hz=rate_hz)
    for m in msgs:
        rig.send(m)
    assert rig.node.counts['view_errors'] == 0
    paths = rig.out['/' + PATH_TOPIC]
    span_s = (stamp_to_ns(msgs[-1].header.stamp) - stamp_to_ns(msgs[0].header.stamp)) / 1e9
    # one publication per period of stamp time (the first input opens the first period)
    assert len(paths) == len(rig.out['/' + MARKERS_TOPIC]) == len(rig.out['/' + SATELLITES_TOPIC])
    assert int(span_s * rate_hz) <= len(paths) <= int(span_s * rate_hz) + 1
    path = paths[-1]
    assert path.header.frame_id == 'map' and len(path.poses) >= 2
    stamps = [stamp_to_ns(p.header.stamp) for p in path.poses]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
    # the track is the local odometry: each pose equals an odometry of its stamp (ranges of several anchors
    # share a stamp: one odometry each)
    odom: dict[int, list] = {}
    for o in rig.out['/fusion/local_odometry']:
        q = o.pose.pose.position
        odom.setdefault(stamp_to_ns(o.header.stamp), []).append((q.x, q.y, q.z))
    for p in path.poses:
        q = p.pose.position
        assert p.header.frame_id == 'map' and (q.x, q.y, q.z) in odom[stamp_to_ns(p.header.stamp)]
    # anchors: one cube each at its surveyed position in map (the datum is the first ECEF solution)
    markers = rig.out['/' + MARKERS_TOPIC][-1].markers
    cubes = [m for m in markers if m.ns == 'uwb_anchors']
    labels = sorted(m.text for m in markers if m.ns == 'uwb_anchor_labels')
    anchors = {u.anchor_id: u.anchor_position_m for u in run.uwb_ranges}
    assert labels == sorted(anchors) and len(cubes) == len(anchors)
    origin = rig.node.local_frame.origin_ecef_m
    expected = sorted(ecef_to_enu(np.array(list(anchors.values())), origin).round(6).tolist())
    got = sorted([[round(c.pose.position.x, 6), round(c.pose.position.y, 6), round(c.pose.position.z, 6)]
                  for c in cubes])
    assert np.allclose(got, expected, atol=1e-6)
    assert all(c.type == Marker.CUBE and c.header.frame_id == 'map' for c in cubes)
    # the covariance ellipse: at the latest pose, its axes those of the odometry's horizontal covariance
    (ell,) = [m for m in markers if m.ns == 'position_covariance']
    last = rig.out['/fusion/local_odometry'][-1]
    assert ell.type == Marker.CYLINDER and stamp_to_ns(ell.header.stamp) <= stamp_to_ns(last.header.stamp)
    cov = np.array(rig.out['/fusion/local_odometry'][-1].pose.covariance).reshape(6, 6)[:2, :2]
    a, b, _ = covariance_ellipse(cov, 0.95)
    if stamp_to_ns(ell.header.stamp) == stamp_to_ns(last.header.stamp):
        assert (ell.scale.x, ell.scale.y) == pytest.approx((2 * a, 2 * b))
    assert 0 < ell.scale.y <= ell.scale.x and ell.color.a > 0
    # satellites: a DELETEALL, then every satellite of the latest epoch, used ones green, around the antenna
    sats = rig.out['/' + SATELLITES_TOPIC][-1].markers
    assert sats[0].action == Marker.DELETEALL
    spheres = [m for m in sats if m.type == Marker.SPHERE]
    n_epoch = len(run.gnss_epochs[-1].observations)
    assert len(spheres) == n_epoch
    used = [m for m in spheres if m.ns == 'satellites_used']
    status = [s for s in rig.out['/fusion/status'] if stamp_to_ns(s.header.stamp) == stamp_to_ns(
        sats[1].header.stamp) and s.satellites_used + s.satellites_rejected > 0]      # the epoch's, not a range's
    assert status and len(used) == status[-1].satellites_used and len(used) >= 4
    rejected = [m for m in spheres if m.ns == 'satellites_rejected']
    assert len(rejected) == status[-1].satellites_rejected == 1
    assert all(m.color.g > m.color.r for m in used) and rejected[0].color.r > rejected[0].color.g
    label_of = {m.id: m.text for m in sats if m.ns == 'satellite_labels'}
    assert label_of[rejected[0].id] == bad_label
    centre = np.array([path.poses[-1].pose.position.x, path.poses[-1].pose.position.y,
                       path.poses[-1].pose.position.z])
    for m in spheres:
        d = np.linalg.norm(np.array([m.pose.position.x, m.pose.position.y, m.pose.position.z]) - centre)
        assert d == pytest.approx(20.0, abs=1.0)                 # the antenna is base_link (no lever arm) +- motion
    assert sorted(m.text for m in sats if m.ns == 'satellite_labels') == sorted(
        satellite_label(o.constellation * 1000 + o.svid) for o in run.gnss_epochs[-1].observations)
