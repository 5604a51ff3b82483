"""Output messages of fusion_node built from a :class:`FusionOutput` (no rclpy import).

``status_msg``, ``odometry_msg`` and ``fix_msg`` turn one core output into rfi_msgs/FusionStatus,
nav_msgs/Odometry and sensor_msgs/NavSatFix;
``local_odometry_msg`` turns a :class:`uwb_gnss_fusion.local_frame.LocalSolution` into the local-frame
nav_msgs/Odometry and ``datum_msg`` the local frame's origin into a NavSatFix.
They run for every input (up to 20 Hz UWB + 5 Hz GNSS), so their cost matters in a replay.

The messages stay Python objects (the node checks a fix before publishing it, and the in-process
replay hands the published object to the subscribers). A generated rosidl ``__init__`` builds a
default for every field, nested messages included, and imports its sub-message classes on every
call: an Odometry (12 messages) through the constructors took about 40 us. So each message is built
with :func:`rfi_node_common.message_builder.message_builder`, the suite's codec layer's constructor
generated from the class's own field description (``get_fields_and_field_types`` / ``SLOT_TYPES``),
which builds the whole tree in one call and fills each field once. It is used only where it agrees
with the public constructors (checked once per class, see
:func:`rfi_node_common.message_builder.builders_agree`); otherwise the public constructors are used
(:data:`FAST_CONSTRUCTION` says which). This module only says which value goes into which field.

The node's outputs:

* /fusion/status (rfi_msgs/FusionStatus): one per processed GNSS epoch or UWB range, every
  field filled; ``header.stamp`` is the stamp of the measurement processed; ``rejection_reasons``
  / ``rejection_counts`` are the cumulative counts of the node (:mod:`.fusion_node`,
  :mod:`.input_admission`, :mod:`rfi_node_common.message_checks`) and of the core
  (``fusion_filter`` reasons such as ``innovation_gate_pseudorange``, ``duplicate_svid``,
  ``negative_range``), sorted by reason.
* /fusion/odometry (nav_msgs/Odometry), only while the filter is initialised and its state is
  finite: ``header.frame_id`` ``earth_frame_id`` (ECEF) or ``map_frame_id`` (the anchors' local
  frame, UWB-only mode), ``child_frame_id`` the parameter; the estimated point is the GNSS antenna
  (the UWB tag is offset by ``uwb_lever_arm_m``). Orientation is not estimated: the quaternion is
  the identity and its covariance diagonal is :data:`ORIENTATION_UNKNOWN_VARIANCE_RAD2` (the
  ``robot_localization`` convention for an unobserved quantity: a large variance, no
  correlations). The twist holds the velocity with the axes of ``header.frame_id`` (with the
  identity orientation those are also the child frame's), angular velocity 0 with variance
  :data:`ORIENTATION_UNKNOWN_VARIANCE_RAD2`. Pose and twist covariances hold the filter's
  position and velocity blocks (the position-velocity correlation has no place in Odometry).
* /fusion/fix (sensor_msgs/NavSatFix), only in the earth frame and only while initialised with
  a finite state: WGS 84 latitude/longitude/ellipsoidal altitude of the antenna, ENU position
  covariance (row-major E, N, U), ``COVARIANCE_TYPE_KNOWN``, ``STATUS_FIX``, service GPS,
  ``header.frame_id`` = ``child_frame_id``. Nothing is published before the first
  initialisation or after a reset to uninitialised: a consumer must not read a NaN position as
  a fix, and ``STATUS_NO_FIX`` with NaN fields would be exactly that for a careless one. The loss
  is visible on /fusion/status (``initialized`` false) and /diagnostics (WARN).
* /diagnostics: every ``diagnostics_period_s`` of stamp time (timed by accepted stamps only), the
  counters and a level (:mod:`.fusion_diagnostics`); ``hardware_id`` is the parameter (the receiver and
  UWB tag). When no input has arrived for ``input_timeout_s`` of wall time, a STALE status ("no input for
  N s", with the counters) is published instead, stamped with the node clock's now: the only use of the
  wall clock besides ``idle_flush_s``.
* /fusion/local_odometry (nav_msgs/Odometry): every published solution again, in the local ENU
  frame ``map_frame_id`` at ``base_frame_id`` (robot_localization's EKF input; origin, lever arm
  and the attitude assumption: :mod:`uwb_gnss_fusion.local_frame`, :meth:`.fusion_node.FusionNode._publish_local`).
* /fusion/datum (sensor_msgs/NavSatFix, latched): the WGS 84 origin of ``map_frame_id``, once.
"""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import numpy as np
from nav_msgs.msg import Odometry
from sensor_msgs.msg import NavSatFix, NavSatStatus

from rfi_msgs.msg import FusionStatus
from rfi_node_common.message_builder import builders_agree, message_builder
from uwb_gnss_fusion.fusion_filter import FusionOutput
from uwb_gnss_fusion.local_frame import LocalSolution

ORIENTATION_UNKNOWN_VARIANCE_RAD2 = 1.0e6
"""Variance written for the unestimated orientation and angular velocity, rad^2 (rad^2/s^2)."""

UINT16_MAX = 2**16 - 1
UINT32_MAX = 2**32 - 1
_NS = 1_000_000_000

def _odometry_covariance_index() -> tuple[np.ndarray, np.ndarray]:
    """Flat indices into ``[covariance_pv.ravel() (36), 0.0, ORIENTATION_UNKNOWN_VARIANCE_RAD2]``
    that give the row-major 6x6 pose and twist covariances (position / velocity block of the
    filter, unestimated rotation block diagonal :data:`ORIENTATION_UNKNOWN_VARIANCE_RAD2`)."""
    zero, unknown = 36, 37
    pose = np.full((6, 6), zero, dtype=np.intp)
    twist = np.full((6, 6), zero, dtype=np.intp)
    for i in range(3):
        for j in range(3):
            pose[i, j] = 6 * i + j
            twist[i, j] = 6 * (i + 3) + (j + 3)
    for k in range(3, 6):
        pose[k, k] = twist[k, k] = unknown
    return pose.ravel(), twist.ravel()


_POSE_COV_INDEX, _TWIST_COV_INDEX = _odometry_covariance_index()


def reason_lists(reasons: dict[str, int]) -> tuple[list[str], list[int]]:
    """Sorted reasons and their counts (clamped to uint32) for FusionStatus."""
    items = sorted(reasons.items())
    return [k for k, _ in items], [min(int(v), UINT32_MAX) for _, v in items]


def _split_stamp(stamp_ns: int) -> tuple[int, int]:
    """Integer ns (>= 0) -> (sec, nanosec) of a ROS time."""
    stamp_ns = int(stamp_ns)
    if stamp_ns < 0:
        raise ValueError(f'negative stamp {stamp_ns} ns cannot be a ROS time')
    return divmod(stamp_ns, _NS)


def _source_covariances(out: FusionOutput) -> tuple[np.ndarray, np.ndarray]:
    """Both 36-element Odometry covariances (fresh float64 arrays) by one gather each from the
    filter's 6x6 [position, velocity] covariance."""
    source = np.empty(38)
    source[:36] = out.covariance_pv.reshape(36)
    source[36] = 0.0
    source[37] = ORIENTATION_UNKNOWN_VARIANCE_RAD2
    return source.take(_POSE_COV_INDEX), source.take(_TWIST_COV_INDEX)


_CLASSES = (Odometry, NavSatFix, FusionStatus)


def _builders(fast: bool) -> Any:
    """One constructor per output message class, by class name (generated if ``fast``, else the public
    constructors); keywords are the leaf fields' paths (``header__stamp__sec``)."""
    return SimpleNamespace(**{cls.__name__: message_builder(cls, fast) for cls in _CLASSES})


_PUBLIC = _builders(False)
_FAST = _builders(True)
FAST_CONSTRUCTION = all(builders_agree(cls) for cls in _CLASSES)
"""True if every output message is built by its generated constructor (see the module docstring)."""

_STATUS_FIX, _SERVICE_GPS = int(NavSatStatus.STATUS_FIX), int(NavSatStatus.SERVICE_GPS)
_COVARIANCE_TYPE_KNOWN = int(NavSatFix.COVARIANCE_TYPE_KNOWN)


def _status(b: Any, out: FusionOutput, stamp_ns: int, frame_id: str, names: list[str], counts: list[int],
            gnss_excluded: int = 0, satellites_excluded: int = 0) -> Any:
    sec, nanosec = _split_stamp(stamp_ns)
    return b.FusionStatus(
        header__stamp__sec=sec, header__stamp__nanosec=nanosec, header__frame_id=frame_id, mode=int(out.mode),
        initialized=bool(out.initialized), diverged=bool(out.diverged),
        reinitializations=min(int(out.reinitializations), UINT32_MAX),
        satellites_used=min(int(out.satellites_used), UINT16_MAX),
        satellites_rejected=min(int(out.satellites_rejected), UINT16_MAX),
        uwb_used=min(int(out.uwb_used), UINT16_MAX), uwb_rejected=min(int(out.uwb_rejected), UINT16_MAX),
        normalized_innovation_squared=float(out.normalized_innovation_squared),
        clock_bias_m=float(out.clock_bias_m), clock_drift_mps=float(out.clock_drift_mps),
        jammer_to_signal_db=float(out.jammer_to_signal_db),
        rejection_reasons=list(names), rejection_counts=counts,  # the setter copies counts into array('I')
        gnss_excluded=int(gnss_excluded), satellites_excluded=min(int(satellites_excluded), UINT16_MAX))


def _odometry(b: Any, out: FusionOutput, frame_id: str, child_frame_id: str) -> Any:
    sec, nanosec = _split_stamp(out.stamp_ns)
    pose_cov, twist_cov = _source_covariances(out)
    x, y, z = out.position_m.tolist()
    vx, vy, vz = out.velocity_mps.tolist()
    return b.Odometry(  # orientation (0, 0, 0, 1) and angular velocity 0: unestimated
        header__stamp__sec=sec, header__stamp__nanosec=nanosec, header__frame_id=frame_id,
        child_frame_id=child_frame_id,
        pose__pose__position__x=x, pose__pose__position__y=y, pose__pose__position__z=z,
        pose__pose__orientation__x=0.0, pose__pose__orientation__y=0.0, pose__pose__orientation__z=0.0,
        pose__pose__orientation__w=1.0, pose__covariance=pose_cov,
        twist__twist__linear__x=vx, twist__twist__linear__y=vy, twist__twist__linear__z=vz,
        twist__twist__angular__x=0.0, twist__twist__angular__y=0.0, twist__twist__angular__z=0.0,
        twist__covariance=twist_cov)


def _fix(b: Any, out: FusionOutput, frame_id: str) -> Any:
    sec, nanosec = _split_stamp(out.stamp_ns)
    latitude, longitude, altitude = (float(v) for v in out.geodetic)
    return b.NavSatFix(
        header__stamp__sec=sec, header__stamp__nanosec=nanosec, header__frame_id=frame_id,
        status__status=_STATUS_FIX, status__service=_SERVICE_GPS, latitude=latitude, longitude=longitude,
        altitude=altitude, position_covariance=np.asarray(out.position_covariance_enu_m2, dtype=np.float64).reshape(9),
        position_covariance_type=_COVARIANCE_TYPE_KNOWN)


def _local_covariance_index() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flat indices into ``[position cov (9), velocity cov (9), yaw variance, 0.0, ORIENTATION_UNKNOWN_VARIANCE_RAD2]``
    that give the row-major 6x6 pose covariance with the yaw known, with it unknown, and the twist covariance."""
    pcov, vcov, yaw, zero, unknown = 0, 9, 18, 19, 20
    pose = np.full((6, 6), zero, dtype=np.intp)
    twist = np.full((6, 6), zero, dtype=np.intp)
    for i in range(3):
        for j in range(3):
            pose[i, j] = pcov + 3 * i + j
            twist[i, j] = vcov + 3 * i + j
    for k in range(3, 6):
        pose[k, k] = twist[k, k] = unknown
    pose_unknown_yaw = pose.copy()
    pose[5, 5] = yaw
    return pose.ravel(), pose_unknown_yaw.ravel(), twist.ravel()


_LOCAL_POSE_INDEX, _LOCAL_POSE_UNKNOWN_YAW_INDEX, _LOCAL_TWIST_INDEX = _local_covariance_index()


def _local_covariances(sol: LocalSolution) -> tuple[np.ndarray, np.ndarray]:
    """Row-major 6x6 pose and twist covariances of the local odometry: the position / velocity blocks,
    roll and pitch (and yaw when unknown) and the angular velocity :data:`ORIENTATION_UNKNOWN_VARIANCE_RAD2`
    (one gather each, as :func:`_source_covariances`)."""
    source = np.empty(21)
    source[0:9] = sol.position_covariance_m2.reshape(9)
    source[9:18] = sol.velocity_covariance_m2ps2.reshape(9)
    source[18] = sol.yaw_variance_rad2
    source[19] = 0.0
    source[20] = ORIENTATION_UNKNOWN_VARIANCE_RAD2
    pose = _LOCAL_POSE_INDEX if math.isfinite(sol.yaw_variance_rad2) else _LOCAL_POSE_UNKNOWN_YAW_INDEX
    return source.take(pose), source.take(_LOCAL_TWIST_INDEX)


def local_odometry_msg(sol: LocalSolution, frame_id: str, child_frame_id: str) -> Any:
    """LocalSolution -> nav_msgs/Odometry in the local frame (``frame_id``, e.g. map) of ``child_frame_id``
    (base_link): pose in frame_id, twist in child_frame_id axes (the Odometry convention); orientation
    the yaw when known (roll = pitch = 0 with variance ORIENTATION_UNKNOWN_VARIANCE_RAD2), else the
    identity with that variance on all three angles."""
    sec, nanosec = _split_stamp(sol.stamp_ns)
    pose_cov, twist_cov = _local_covariances(sol)
    x, y, z = sol.position_m.tolist()
    vx, vy, vz = sol.velocity_body_mps.tolist()
    half = 0.0 if math.isnan(sol.yaw_rad) else sol.yaw_rad / 2.0
    return _FAST.Odometry(
        header__stamp__sec=sec, header__stamp__nanosec=nanosec, header__frame_id=frame_id,
        child_frame_id=child_frame_id,
        pose__pose__position__x=x, pose__pose__position__y=y, pose__pose__position__z=z,
        pose__pose__orientation__x=0.0, pose__pose__orientation__y=0.0, pose__pose__orientation__z=math.sin(half),
        pose__pose__orientation__w=math.cos(half), pose__covariance=pose_cov,
        twist__twist__linear__x=vx, twist__twist__linear__y=vy, twist__twist__linear__z=vz,
        twist__twist__angular__x=0.0, twist__twist__angular__y=0.0, twist__twist__angular__z=0.0,
        twist__covariance=twist_cov)


def datum_msg(stamp_ns: int, frame_id: str, geodetic: tuple[float, float, float]) -> Any:
    """The local frame's origin as a NavSatFix: WGS 84 latitude, longitude (deg) and ellipsoidal altitude
    (m) of the point (0, 0, 0) of ``frame_id``; exact by definition (COVARIANCE_TYPE_UNKNOWN, zeros)."""
    sec, nanosec = _split_stamp(stamp_ns)
    latitude, longitude, altitude = (float(v) for v in geodetic)
    return _FAST.NavSatFix(
        header__stamp__sec=sec, header__stamp__nanosec=nanosec, header__frame_id=frame_id,
        status__status=_STATUS_FIX, status__service=_SERVICE_GPS, latitude=latitude, longitude=longitude,
        altitude=altitude, position_covariance=np.zeros(9),
        position_covariance_type=int(NavSatFix.COVARIANCE_TYPE_UNKNOWN))


def status_msg(out: FusionOutput, stamp_ns: int, frame_id: str, reasons: dict[str, int],
               lists: tuple[list[str], list[int]] | None = None, gnss_excluded: int = 0,
               satellites_excluded: int = 0) -> Any:
    """FusionOutput -> rfi_msgs/FusionStatus (counts clamped to their integer types).

    ``lists``: ``reason_lists(reasons)`` if the caller has it already (copied into the message,
    never shared between messages).
    """
    names, counts = reason_lists(reasons) if lists is None else lists
    return _status(_FAST, out, stamp_ns, frame_id, names, counts, gnss_excluded, satellites_excluded)


def odometry_msg(out: FusionOutput, frame_id: str, child_frame_id: str) -> Any:
    """FusionOutput (initialised, finite) -> nav_msgs/Odometry (see the fusion_node docstring)."""
    return _odometry(_FAST, out, frame_id, child_frame_id)


def fix_msg(out: FusionOutput, frame_id: str) -> Any:
    """FusionOutput (initialised, finite, earth frame) -> sensor_msgs/NavSatFix."""
    return _fix(_FAST, out, frame_id)
