"""Output messages of fusion_node built from a :class:`FusionOutput` (no rclpy import).

``status_msg``, ``odometry_msg`` and ``fix_msg`` turn one core output into rfi_msgs/FusionStatus,
nav_msgs/Odometry and sensor_msgs/NavSatFix (contents: see :mod:`uwb_gnss_fusion.fusion_node`).
They run for every input (up to 20 Hz UWB + 5 Hz GNSS), so their cost matters in a replay.

Construction. A generated rosidl message ``__init__`` builds a default for every field, nested
messages included (``kwargs.get('pose', Pose())`` evaluates ``Pose()`` even when a pose is
given), imports its sub-message classes on every call, and copies each array. An Odometry is 12
messages (9 of them nested), so building it through the constructors took about 40 us here and
the three outputs together about half of the node's time per input. Messages cannot be reused
between publications: the in-process replay (``ReplayHarness(transport='direct')``) hands the
published object itself to subscribers and collectors. So the builders here allocate each message
with ``cls.__new__`` and write the generated slots (``_x``, ``_header`` ...) directly, each exactly
once, with values of the slot's storage type (float, int, bool, str, float64 ``ndarray`` of the
right size, ``array('I')``, list of str), which is what the generated setters store when field
checks are off.

This depends on the layout rosidl_generator_py generates (one ``_<field>`` slot per field plus
``_check_fields``). :data:`FAST_CONSTRUCTION` is decided once at import: it is True only if every
message class used has exactly the expected slots, field checks are off
(``ROS_PYTHON_CHECK_FIELDS`` not ``1``), and a message built each way compares equal with
``==`` for every type. Otherwise the builders use the public constructors and setters (the
reference path, also used by the tests to check the fast one field by field).
"""

from __future__ import annotations

import math
import os
from array import array
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, PoseWithCovariance, Quaternion, Twist, TwistWithCovariance, Vector3
from nav_msgs.msg import Odometry
from sensor_msgs.msg import NavSatFix, NavSatStatus
from std_msgs.msg import Header

from rfi_msgs.msg import FusionStatus
from uwb_gnss_fusion.fusion_filter import FusionOutput

ORIENTATION_UNKNOWN_VARIANCE_RAD2 = 1.0e6
"""Variance written for the unestimated orientation and angular velocity, rad^2 (rad^2/s^2)."""

UINT16_MAX = 2**16 - 1
UINT32_MAX = 2**32 - 1
_NS = 1_000_000_000

_EXPECTED_SLOTS: dict[type, tuple[str, ...]] = {
    Time: ('sec', 'nanosec'),
    Header: ('stamp', 'frame_id'),
    Point: ('x', 'y', 'z'),
    Quaternion: ('x', 'y', 'z', 'w'),
    Vector3: ('x', 'y', 'z'),
    Pose: ('position', 'orientation'),
    Twist: ('linear', 'angular'),
    PoseWithCovariance: ('pose', 'covariance'),
    TwistWithCovariance: ('twist', 'covariance'),
    Odometry: ('header', 'child_frame_id', 'pose', 'twist'),
    NavSatStatus: ('status', 'service'),
    NavSatFix: ('header', 'status', 'latitude', 'longitude', 'altitude', 'position_covariance',
                'position_covariance_type'),
    FusionStatus: ('header', 'mode', 'initialized', 'diverged', 'reinitializations', 'satellites_used',
                   'satellites_rejected', 'uwb_used', 'uwb_rejected', 'normalized_innovation_squared',
                   'clock_bias_m', 'clock_drift_mps', 'jammer_to_signal_db', 'rejection_reasons',
                   'rejection_counts'),
}
"""Fields of each message class written by the fast builders (their slots are ``_<field>``)."""


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


def _status_values(out: FusionOutput) -> tuple:
    """FusionStatus scalar fields (counts clamped to their integer types), in slot order."""
    return (int(out.mode), bool(out.initialized), bool(out.diverged),
            min(int(out.reinitializations), UINT32_MAX), min(int(out.satellites_used), UINT16_MAX),
            min(int(out.satellites_rejected), UINT16_MAX), min(int(out.uwb_used), UINT16_MAX),
            min(int(out.uwb_rejected), UINT16_MAX), float(out.normalized_innovation_squared),
            float(out.clock_bias_m), float(out.clock_drift_mps), float(out.jammer_to_signal_db))


# ---------------------------------------------------------------- reference path (public API)
def _status_public(out: FusionOutput, stamp_ns: int, frame_id: str, names: list[str], counts: list[int]) -> Any:
    m = FusionStatus()
    m.header.stamp.sec, m.header.stamp.nanosec = _split_stamp(stamp_ns)
    m.header.frame_id = frame_id
    (m.mode, m.initialized, m.diverged, m.reinitializations, m.satellites_used, m.satellites_rejected,
     m.uwb_used, m.uwb_rejected, m.normalized_innovation_squared, m.clock_bias_m, m.clock_drift_mps,
     m.jammer_to_signal_db) = _status_values(out)
    m.rejection_reasons = list(names)
    m.rejection_counts = counts  # the setter copies into its own array('I')
    return m


def _odometry_public(out: FusionOutput, frame_id: str, child_frame_id: str) -> Any:
    m = Odometry()
    m.header.stamp.sec, m.header.stamp.nanosec = _split_stamp(out.stamp_ns)
    m.header.frame_id = frame_id
    m.child_frame_id = child_frame_id
    position = m.pose.pose.position
    position.x, position.y, position.z = out.position_m.tolist()
    m.pose.pose.orientation.w = 1.0
    m.pose.covariance, m.twist.covariance = _source_covariances(out)
    linear = m.twist.twist.linear
    linear.x, linear.y, linear.z = out.velocity_mps.tolist()
    return m


def _fix_public(out: FusionOutput, frame_id: str) -> Any:
    m = NavSatFix()
    m.header.stamp.sec, m.header.stamp.nanosec = _split_stamp(out.stamp_ns)
    m.header.frame_id = frame_id
    m.status.status = NavSatStatus.STATUS_FIX
    m.status.service = NavSatStatus.SERVICE_GPS
    m.latitude, m.longitude, m.altitude = out.geodetic
    m.position_covariance = out.position_covariance_enu_m2.reshape(9).copy()
    m.position_covariance_type = NavSatFix.COVARIANCE_TYPE_KNOWN
    return m


# ---------------------------------------------------------------- fast path (generated slots)
_new = object.__new__


def _header_fast(stamp_ns: int, frame_id: str) -> Any:
    t = _new(Time)
    t._check_fields = False
    t._sec, t._nanosec = _split_stamp(stamp_ns)
    h = _new(Header)
    h._check_fields = False
    h._stamp = t
    h._frame_id = frame_id
    return h


def _xyz_fast(cls: type, x: float, y: float, z: float) -> Any:
    v: Any = _new(cls)
    v._check_fields = False
    v._x = x
    v._y = y
    v._z = z
    return v


def _status_fast(out: FusionOutput, stamp_ns: int, frame_id: str, names: list[str], counts: list[int]) -> Any:
    m = _new(FusionStatus)
    m._check_fields = False
    m._header = _header_fast(stamp_ns, frame_id)
    (m._mode, m._initialized, m._diverged, m._reinitializations, m._satellites_used, m._satellites_rejected,
     m._uwb_used, m._uwb_rejected, m._normalized_innovation_squared, m._clock_bias_m, m._clock_drift_mps,
     m._jammer_to_signal_db) = _status_values(out)
    m._rejection_reasons = list(names)
    m._rejection_counts = array('I', counts)
    return m


def _odometry_fast(out: FusionOutput, frame_id: str, child_frame_id: str) -> Any:
    pose_cov, twist_cov = _source_covariances(out)
    q = _new(Quaternion)
    q._check_fields = False
    q._x = q._y = q._z = 0.0
    q._w = 1.0
    pose = _new(Pose)
    pose._check_fields = False
    pose._position = _xyz_fast(Point, *out.position_m.tolist())
    pose._orientation = q
    pwc = _new(PoseWithCovariance)
    pwc._check_fields = False
    pwc._pose = pose
    pwc._covariance = pose_cov
    twist = _new(Twist)
    twist._check_fields = False
    twist._linear = _xyz_fast(Vector3, *out.velocity_mps.tolist())
    twist._angular = _xyz_fast(Vector3, 0.0, 0.0, 0.0)
    twc = _new(TwistWithCovariance)
    twc._check_fields = False
    twc._twist = twist
    twc._covariance = twist_cov
    m = _new(Odometry)
    m._check_fields = False
    m._header = _header_fast(out.stamp_ns, frame_id)
    m._child_frame_id = child_frame_id
    m._pose = pwc
    m._twist = twc
    return m


_STATUS_FIX, _SERVICE_GPS = int(NavSatStatus.STATUS_FIX), int(NavSatStatus.SERVICE_GPS)
_COVARIANCE_TYPE_KNOWN = int(NavSatFix.COVARIANCE_TYPE_KNOWN)


def _fix_fast(out: FusionOutput, frame_id: str) -> Any:
    status = _new(NavSatStatus)
    status._check_fields = False
    status._status = _STATUS_FIX
    status._service = _SERVICE_GPS
    m = _new(NavSatFix)
    m._check_fields = False
    m._header = _header_fast(out.stamp_ns, frame_id)
    m._status = status
    m._latitude, m._longitude, m._altitude = (float(v) for v in out.geodetic)
    m._position_covariance = np.array(out.position_covariance_enu_m2, dtype=np.float64).reshape(9)
    m._position_covariance_type = _COVARIANCE_TYPE_KNOWN
    return m


# ---------------------------------------------------------------- selection
def _layout_matches() -> bool:
    """Every class has exactly the slots ``_<field>`` of :data:`_EXPECTED_SLOTS` + ``_check_fields``."""
    for cls, fields in _EXPECTED_SLOTS.items():
        expected = {f'_{f}' for f in fields} | {'_check_fields'}
        declared = set(getattr(cls, 'get_fields_and_field_types', dict)())
        if set(getattr(cls, '__slots__', ())) != expected or declared != set(fields):
            return False
    return True


def _probe_output() -> _ProbeOutput:
    """A FusionOutput with distinct values in every field the builders read (for the self-check)."""
    cov = np.arange(1.0, 37.0).reshape(6, 6)
    return _ProbeOutput(stamp_ns=1_700_000_000_123_456_789, position_m=np.array([1.0e6, -5.0e6, 3.0e6]),
                        velocity_mps=np.array([0.25, -0.5, 0.125]), covariance_pv=cov + cov.T)


class _ProbeOutput:
    """Duck-typed stand-in for :class:`FusionOutput` in the import-time self-check."""

    def __init__(self, stamp_ns: int, position_m: np.ndarray, velocity_mps: np.ndarray,
                 covariance_pv: np.ndarray) -> None:
        self.stamp_ns = stamp_ns
        self.position_m = position_m
        self.velocity_mps = velocity_mps
        self.covariance_pv = covariance_pv
        self.mode, self.initialized, self.diverged, self.reinitializations = 3, True, False, 2
        self.satellites_used, self.satellites_rejected, self.uwb_used, self.uwb_rejected = 9, 1, 1, 0
        self.normalized_innovation_squared, self.clock_bias_m = 1.5, 12.25
        self.clock_drift_mps, self.jammer_to_signal_db = -0.5, math.nan
        self.geodetic = (38.5, -97.25, 312.5)
        self.position_covariance_enu_m2 = covariance_pv[:3, :3] + 0.5


def _messages_equal(a: Any, b: Any) -> bool:
    """Field-by-field equality, NaN equal to NaN (generated ``__eq__`` says NaN != NaN)."""
    if type(a) is not type(b):
        return False
    if hasattr(type(a), 'get_fields_and_field_types'):
        return all(_messages_equal(getattr(a, f), getattr(b, f)) for f in type(a).get_fields_and_field_types())
    if isinstance(a, (np.ndarray, array)):
        return (len(a) == len(b) and np.asarray(a).dtype == np.asarray(b).dtype
                and bool(np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)))
    if isinstance(a, float) and math.isnan(a):
        return math.isnan(b)
    return bool(a == b)


def _fast_path_agrees() -> bool:
    """The fast builders give messages equal, field by field and in storage type, to the public path."""
    out: Any = _probe_output()
    names, counts = ['a_reason', 'b_reason'], [3, UINT32_MAX]
    pairs = [(_status_fast(out, out.stamp_ns, 'earth', names, counts),
              _status_public(out, out.stamp_ns, 'earth', names, counts)),
             (_odometry_fast(out, 'earth', 'gnss_antenna'), _odometry_public(out, 'earth', 'gnss_antenna')),
             (_fix_fast(out, 'gnss_antenna'), _fix_public(out, 'gnss_antenna'))]
    return all(_messages_equal(f, p) for f, p in pairs)


def _choose_fast() -> bool:
    if os.environ.get('ROS_PYTHON_CHECK_FIELDS', '') == '1' or not _layout_matches():
        return False
    try:
        return _fast_path_agrees()
    except (AttributeError, TypeError, ValueError):
        return False


FAST_CONSTRUCTION = _choose_fast()
"""True if the builders write the generated slots directly (see the module docstring)."""


def status_msg(out: FusionOutput, stamp_ns: int, frame_id: str, reasons: dict[str, int],
               lists: tuple[list[str], list[int]] | None = None) -> Any:
    """FusionOutput -> rfi_msgs/FusionStatus (counts clamped to their integer types).

    ``lists``: ``reason_lists(reasons)`` if the caller has it already (copied into the message,
    never shared between messages).
    """
    names, counts = reason_lists(reasons) if lists is None else lists
    build = _status_fast if FAST_CONSTRUCTION else _status_public
    return build(out, stamp_ns, frame_id, names, counts)


def odometry_msg(out: FusionOutput, frame_id: str, child_frame_id: str) -> Any:
    """FusionOutput (initialised, finite) -> nav_msgs/Odometry (see the fusion_node docstring)."""
    return (_odometry_fast if FAST_CONSTRUCTION else _odometry_public)(out, frame_id, child_frame_id)


def fix_msg(out: FusionOutput, frame_id: str) -> Any:
    """FusionOutput (initialised, finite, earth frame) -> sensor_msgs/NavSatFix."""
    return (_fix_fast if FAST_CONSTRUCTION else _fix_public)(out, frame_id)
