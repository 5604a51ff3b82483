"""The fusion's topics made to be drawn in rviz2 and Foxglove (issue 30), all in ``map_frame_id`` (local ENU):

* ``fusion/path`` (``nav_msgs/Path``): the track of base_link (the poses of /fusion/local_odometry), one pose added
  per update, at most ``path_max_poses``;
* ``fusion/markers`` (``visualization_msgs/MarkerArray``): namespace ``uwb_anchors`` (a cube per anchor that ranged,
  at its surveyed position, and ``uwb_anchor_labels``: its id), ``position_covariance`` (a flat cylinder: the
  horizontal confidence ellipse of the position at ``covariance_probability``, :func:`.fusion_view.covariance_ellipse`);
* ``fusion/satellites`` (``visualization_msgs/MarkerArray``): the satellites of the latest GNSS epoch as a sky plot
  around the antenna (``satellite_marker_distance_m`` along each line of sight): namespace ``satellites_used``
  (green spheres: pseudoranges the filter applied), ``satellites_rejected`` (red: the core's checks, elevation mask,
  common-mode screen or gate rejected them, or the epoch was not applied), ``satellite_labels`` (``G05``, ...); the
  array starts with a DELETEALL so that satellites that set are removed. Satellites the node's message checks drop
  (impossible values, no state) never reach the epoch and are not drawn: /fusion/status counts them.

Cost. Every ``1 / view_rate_hz`` of stamp time (never the wall clock) :meth:`FusionView.after_input` asks the three
publishers for their subscription count; between two such times an input costs one integer comparison. While nobody
subscribes nothing else is done and nothing is kept (the track, the anchors and the epoch are forgotten: a viewer
that subscribes later sees the track from then on). While someone does, the anchors of the ranges and the latest GNSS
epoch are remembered (references, no copies) and the topics published every period. Satellites need the ECEF
solution and the map origin (no satellites in UWB-only mode). A failure here is counted by the node, never raised into
the processing of the input.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from gnss_common.coordinates import ecef_to_enu
from gnss_common.observations import GnssEpoch, UwbRangeMeasurement
from rfi_node_common.qos import VIEW_QOS
from rfi_node_common.stamps import NS_PER_S
from uwb_gnss_fusion.fusion_filter import FRAME_EARTH
from uwb_gnss_fusion.fusion_view import covariance_ellipse, satellite_label, sky_directions, yaw_quaternion
from uwb_gnss_fusion.local_frame import LocalFrame, LocalSolution

PATH_TOPIC = 'fusion/path'
MARKERS_TOPIC = 'fusion/markers'
SATELLITES_TOPIC = 'fusion/satellites'
TOPICS = ((PATH_TOPIC, 'nav_msgs/msg/Path'), (MARKERS_TOPIC, 'visualization_msgs/msg/MarkerArray'),
          (SATELLITES_TOPIC, 'visualization_msgs/msg/MarkerArray'))
"""(topic, type) of every topic this module publishes (the viewer configurations are checked against it)."""
USED, REJECTED = (0.1, 0.8, 0.1, 0.9), (0.9, 0.1, 0.1, 0.9)
ANCHOR, ELLIPSE, LABEL = (1.0, 0.6, 0.0, 1.0), (0.2, 0.4, 1.0, 0.35), (1.0, 1.0, 1.0, 1.0)
"""RGBA of the markers."""


def _color(rgba: tuple[float, float, float, float]) -> ColorRGBA:
    return ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])


def _header(msg: Any, stamp_ns: int, frame_id: str) -> None:
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), NS_PER_S)
    msg.header.frame_id = frame_id


def _marker(stamp_ns: int, frame_id: str, ns: str, mid: int, mtype: int, xyz: Any, scale: tuple[float, float, float],
            rgba: tuple[float, float, float, float], text: str = '') -> Marker:
    m = Marker()
    _header(m, stamp_ns, frame_id)
    m.ns, m.id, m.type, m.action = ns, int(mid), int(mtype), Marker.ADD
    m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in xyz)
    m.pose.orientation.w = 1.0
    m.scale.x, m.scale.y, m.scale.z = scale
    m.color = _color(rgba)
    m.lifetime = Duration()
    m.text = text
    return m


class FusionView:
    """The drawn topics of one fusion node (module docstring).

    Args:
        node: the rclpy node that owns the publishers.
        params: anything with the fields of :class:`.fusion_view.FusionViewParams` and ``map_frame_id``.
        local_frame: the node's map frame (its origin is set by the node).
    """

    def __init__(self, node: Any, params: Any, local_frame: LocalFrame) -> None:
        self.params = params
        self.local_frame = local_frame
        self._period_ns = int(round(NS_PER_S / float(params.view_rate_hz)))
        self._due_ns: int | None = None
        self.path_pub = node.create_publisher(Path, PATH_TOPIC, VIEW_QOS)
        self.markers_pub = node.create_publisher(MarkerArray, MARKERS_TOPIC, VIEW_QOS)
        self.satellites_pub = node.create_publisher(MarkerArray, SATELLITES_TOPIC, VIEW_QOS)
        self._logger = node.get_logger()
        self.active = False
        self._path: deque[PoseStamped] = deque(maxlen=int(params.path_max_poses))
        self._anchors: dict[str, tuple[np.ndarray, str]] = {}
        self._epoch: GnssEpoch | None = None
        self._receiver_ecef: np.ndarray | None = None
        self.published = 0
        """Periods at which the topics were published."""

    def listened(self) -> bool:
        """Someone subscribes to one of the topics."""
        return (self.path_pub.get_subscription_count() > 0 or self.markers_pub.get_subscription_count() > 0
                or self.satellites_pub.get_subscription_count() > 0)

    def after_input_logged(self, counts: Any, throttle_s: float, stamp_ns: int, kind: str, payload: Any, out: Any,
                           solution: LocalSolution | None, used_satellites: tuple[int, np.ndarray] | None) -> None:
        """:meth:`after_input`, a failure counted (``counts['view_errors']``) and logged at most once per
        ``throttle_s``, never raised: a drawing must never cost an estimate."""
        try:
            self.after_input(stamp_ns, kind, payload, out, solution, used_satellites)
        except Exception as err:  # noqa: BLE001 - a drawing must never cost an estimate
            counts['view_errors'] += 1
            self._logger.error(f'fusion view topics not published: {type(err).__name__}: {err}',
                               throttle_duration_sec=throttle_s)

    def after_input(self, stamp_ns: int, kind: str, payload: Any, out: Any, solution: LocalSolution | None,
                    used_satellites: tuple[int, np.ndarray] | None) -> bool:
        """After the core processed an input (``kind`` 'gnss', 'uwb', ...; its ``payload``) and the node published
        ``out`` (a FusionOutput or None) and the local ``solution`` (the latest, or None): remember what the
        drawings need while someone listens, and publish them when a period of stamp time is due. Returns whether
        it published."""
        due = self._due_ns is None or stamp_ns >= self._due_ns or stamp_ns < self._due_ns - self._period_ns
        if not due and not self.active:
            return False
        if due:
            self._due_ns = stamp_ns + self._period_ns
            listened = self.listened()
            if not listened:
                if self.active:
                    self._forget()
                return False
            self.active = True
        self._remember(kind, payload, out)
        if not due:
            return False
        frame = self.params.map_frame_id
        if solution is not None:
            pose = PoseStamped()
            _header(pose, solution.stamp_ns, frame)
            pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (float(v) for v in solution.position_m)
            _, _, z, w = yaw_quaternion(0.0 if math.isnan(solution.yaw_rad) else solution.yaw_rad)
            pose.pose.orientation.z, pose.pose.orientation.w = z, w
            if not self._path or self._path[-1].header.stamp != pose.header.stamp:
                self._path.append(pose)
        path = Path()
        _header(path, stamp_ns, frame)
        path.poses = list(self._path)
        self.path_pub.publish(path)
        self.markers_pub.publish(self.markers(stamp_ns, solution))
        self.satellites_pub.publish(self.satellites(stamp_ns, used_satellites))
        self.published += 1
        return True

    def _forget(self) -> None:
        self.active = False
        self._path.clear()
        self._anchors.clear()
        self._epoch = None
        self._receiver_ecef = None

    def _remember(self, kind: str, payload: Any, out: Any) -> None:
        if kind == 'uwb' and isinstance(payload, UwbRangeMeasurement):
            self._anchors[payload.anchor_id] = (payload.anchor_position_m, payload.frame_id)
        elif kind == 'gnss' and isinstance(payload, GnssEpoch):
            self._epoch = payload
        if out is not None and out.initialized and out.frame_id == FRAME_EARTH and np.isfinite(out.position_m).all():
            self._receiver_ecef = out.position_m

    def _to_map(self, position_m: np.ndarray, frame: str) -> np.ndarray | None:
        """An anchor's position in map (the core's frame names: FRAME_EARTH anchors need the map origin)."""
        if frame != FRAME_EARTH:
            return np.asarray(position_m, dtype=np.float64)
        if self.local_frame.origin_ecef_m is None:
            return None
        return ecef_to_enu(np.asarray(position_m, dtype=np.float64).reshape(1, 3), self.local_frame.origin_ecef_m)[0]

    def markers(self, stamp_ns: int, solution: LocalSolution | None) -> MarkerArray:
        """UWB anchors (cubes and labels) and the horizontal position confidence ellipse, in map."""
        frame = self.params.map_frame_id
        arr = MarkerArray()
        for i, anchor_id in enumerate(sorted(self._anchors)):
            pos, anchor_frame = self._anchors[anchor_id]
            xyz = self._to_map(pos, anchor_frame)
            if xyz is None or not np.isfinite(xyz).all():
                continue
            arr.markers.append(_marker(stamp_ns, frame, 'uwb_anchors', i, Marker.CUBE, xyz, (0.3, 0.3, 0.3), ANCHOR))
            arr.markers.append(_marker(stamp_ns, frame, 'uwb_anchor_labels', i, Marker.TEXT_VIEW_FACING,
                                       xyz + np.array([0.0, 0.0, 0.5]), (0.0, 0.0, 0.3), LABEL, anchor_id))
        if solution is not None:
            a, b, yaw = covariance_ellipse(solution.position_covariance_m2, self.params.covariance_probability)
            if math.isfinite(a) and math.isfinite(b):
                m = _marker(solution.stamp_ns, frame, 'position_covariance', 0, Marker.CYLINDER, solution.position_m,
                            (max(2.0 * a, 1e-3), max(2.0 * b, 1e-3), 0.02), ELLIPSE)
                _, _, m.pose.orientation.z, m.pose.orientation.w = yaw_quaternion(yaw)
                arr.markers.append(m)
        return arr

    def satellites(self, stamp_ns: int, used: tuple[int, np.ndarray] | None) -> MarkerArray:
        """The latest epoch's satellites around the antenna, used green, rejected red (module docstring)."""
        frame = self.params.map_frame_id
        clear = Marker()
        _header(clear, stamp_ns, frame)
        clear.action = Marker.DELETEALL
        arr = MarkerArray(markers=[clear])
        epoch, rx = self._epoch, self._receiver_ecef
        if epoch is None or rx is None or self.local_frame.origin_ecef_m is None or not epoch.observations:
            return arr
        used_keys = set(used[1].tolist()) if used is not None and used[0] == epoch.stamp_ns else set()
        keys = [o.constellation * 1000 + o.svid for o in epoch.observations]
        dirs = sky_directions(rx, np.array([o.satellite_position_ecef_m for o in epoch.observations]))
        centre = ecef_to_enu(np.asarray(rx, dtype=np.float64).reshape(1, 3), self.local_frame.origin_ecef_m)[0]
        d = float(self.params.satellite_marker_distance_m)
        for i, (key, u) in enumerate(zip(keys, dirs, strict=True)):
            if not np.isfinite(u).all():
                continue
            ok = key in used_keys
            xyz = centre + d * u
            arr.markers.append(_marker(epoch.stamp_ns, frame, 'satellites_used' if ok else 'satellites_rejected', i,
                                       Marker.SPHERE, xyz, (1.0, 1.0, 1.0), USED if ok else REJECTED))
            arr.markers.append(_marker(epoch.stamp_ns, frame, 'satellite_labels', i, Marker.TEXT_VIEW_FACING,
                                       xyz + np.array([0.0, 0.0, 1.0]), (0.0, 0.0, 0.8), LABEL, satellite_label(key)))
        return arr
