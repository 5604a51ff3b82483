"""Conversions between rfi_msgs / geometry_msgs messages and the plain dataclasses of the cores.

The pure cores (SPP, the fusion filter, the simulators) work on
:mod:`gnss_common.observations` dataclasses with integer-nanosecond stamps; the nodes and the bag
converters work on ROS messages. This module is the only place where one becomes the other, field
by field, with no arithmetic on the values:

* :func:`epoch_to_msg` / :func:`msg_to_epoch`: ``GnssEpoch`` <-> ``rfi_msgs/GnssMeasurementArray``.
* :func:`uwb_to_msg` / :func:`msg_to_uwb`: ``UwbRangeMeasurement`` <-> ``rfi_msgs/UwbRange``.
* :func:`point_to_msg` / :func:`msg_to_point`: (stamp_ns, xyz) <-> ``geometry_msgs/PointStamped``
  (truth and reference positions in bags).
* :func:`decode_uwb_range_cdr`: the serialised ``rfi_msgs/UwbRange`` (CDR bytes, as a ``raw=True``
  subscription or a bag delivers them) straight to a ``UwbRangeMeasurement`` through the suite's
  codec (:mod:`rfi_node_common.cdr`), without rclpy's deserialisation (which builds the message and
  its nested Header, Time and Point objects; about 30 us per range, at 20 Hz per anchor).

Round trips are exact: every float is a float64 on both sides (NaN stays NaN, -0.0 stays -0.0),
stamps are integer nanoseconds (``builtin_interfaces/Time`` holds them exactly for stamps >= 0).

Bad input raises :class:`ValueError` with a message naming the field (a wrong shape, a negative
stamp, a duplicate satellite, an integer out of its message range), never an rclpy
``AssertionError`` from deep inside a setter.

Notes
-----
No equations: the field meanings, units and sign conventions are those of
rfi_msgs/GnssMeasurement.msg (Cao et al., eq. 5 pseudorange model, eq. 6 Doppler-derived rate) and
rfi_msgs/UwbRange.msg (Cao et al., eq. 7 two-way range).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from geometry_msgs.msg import Point, PointStamped
from std_msgs.msg import Header

from gnss_common.observations import GnssEpoch, SatelliteObservation, UwbRangeMeasurement
from rfi_msgs.msg import GnssMeasurement, GnssMeasurementArray, UwbRange
from rfi_node_common.cdr import layout
from rfi_node_common.stamps import ns_to_stamp, stamp_to_ns

EARTH_FRAME_ID = "earth"
"""REP 105 frame id of ECEF, used for GNSS measurement arrays."""

_FLOAT_FIELDS = (
    "pseudorange_m",
    "pseudorange_rate_mps",
    "cn0_dbhz",
    "satellite_clock_bias_m",
    "satellite_clock_drift_mps",
    "ionosphere_delay_m",
    "troposphere_delay_m",
    "pseudorange_std_m",
    "pseudorange_rate_std_mps",
    "carrier_frequency_hz",
)
"""Scalar float64 fields shared by SatelliteObservation and GnssMeasurement (same names, units)."""


def _header(stamp_ns: int, frame_id: str) -> Header:
    if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, (int, np.integer)):
        raise ValueError(f"stamp_ns must be an integer number of ns, got {stamp_ns!r}")
    if not isinstance(frame_id, str):
        raise ValueError(f"frame_id must be a string, got {frame_id!r}")
    return Header(stamp=ns_to_stamp(int(stamp_ns)), frame_id=frame_id)


def _vector3(value: object, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,):
        raise ValueError(f"{name} must have shape (3,), got {arr.shape}")
    return arr.copy()


def _uint(value: object, name: str, bits: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if not 0 <= int(value) < 2**bits:
        raise ValueError(f"{name} must be in [0, {2**bits - 1}] (uint{bits} in the message), got {value}")
    return int(value)


def _float(value: object, name: str) -> float:
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a float, got {value!r}") from None


def observation_to_msg(obs: SatelliteObservation) -> GnssMeasurement:
    """Convert one :class:`SatelliteObservation` to ``rfi_msgs/GnssMeasurement``.

    Args:
        obs: the observation; ``satellite_position_ecef_m`` (m) and
            ``satellite_velocity_ecef_mps`` (m/s) of shape (3,), scalars in the units of their names.

    Returns:
        The message, every field copied unchanged.

    Raises:
        ValueError: constellation outside uint8, svid outside uint16, a vector not of shape (3,),
            a scalar that is not a float.
    """
    msg = GnssMeasurement()
    msg.constellation = _uint(obs.constellation, "constellation", 8)
    msg.svid = _uint(obs.svid, "svid", 16)
    for name in _FLOAT_FIELDS:
        setattr(msg, name, _float(getattr(obs, name), name))
    msg.satellite_position_ecef_m = _vector3(obs.satellite_position_ecef_m, "satellite_position_ecef_m")
    msg.satellite_velocity_ecef_mps = _vector3(obs.satellite_velocity_ecef_mps, "satellite_velocity_ecef_mps")
    return msg


def msg_to_observation(msg: GnssMeasurement) -> SatelliteObservation:
    """Convert ``rfi_msgs/GnssMeasurement`` to a :class:`SatelliteObservation` (fields unchanged).

    Args:
        msg: the message.

    Returns:
        The observation; the two vectors are fresh float64 arrays of shape (3,).
    """
    return SatelliteObservation(
        constellation=int(msg.constellation),
        svid=int(msg.svid),
        satellite_position_ecef_m=_vector3(msg.satellite_position_ecef_m, "satellite_position_ecef_m"),
        satellite_velocity_ecef_mps=_vector3(msg.satellite_velocity_ecef_mps, "satellite_velocity_ecef_mps"),
        **{name: float(getattr(msg, name)) for name in _FLOAT_FIELDS},
    )


def _check_unique(keys: Sequence[tuple[int, int]]) -> None:
    seen: set[tuple[int, int]] = set()
    for key in keys:
        if key in seen:
            raise ValueError(
                f"satellite (constellation {key[0]}, svid {key[1]}) appears twice in one epoch; "
                "GnssMeasurementArray allows at most one measurement per satellite"
            )
        seen.add(key)


def epoch_to_msg(epoch: GnssEpoch, frame_id: str = EARTH_FRAME_ID) -> GnssMeasurementArray:
    """Convert a :class:`GnssEpoch` to ``rfi_msgs/GnssMeasurementArray``.

    Args:
        epoch: the epoch; ``stamp_ns`` (integer ns, >= 0) becomes ``header.stamp``,
            ``gps_week`` (continuous week, 0..65535) and ``gps_time_of_week_s`` (s) are copied.
        frame_id: ``header.frame_id``; "earth" (ECEF, REP 105) as the message specifies.

    Returns:
        The message with one GnssMeasurement per observation, in the epoch's order.

    Raises:
        ValueError: negative or non-integer stamp, week outside uint16, duplicate
            (constellation, svid), or a bad observation field (see :func:`observation_to_msg`).
    """
    _check_unique([(int(o.constellation), int(o.svid)) for o in epoch.observations])
    msg = GnssMeasurementArray()
    msg.header = _header(epoch.stamp_ns, frame_id)
    msg.gps_week = _uint(epoch.gps_week, "gps_week", 16)
    msg.gps_time_of_week_s = _float(epoch.gps_time_of_week_s, "gps_time_of_week_s")
    msg.measurements = [observation_to_msg(o) for o in epoch.observations]
    return msg


def msg_to_epoch(msg: GnssMeasurementArray, expected_frame_id: str | None = EARTH_FRAME_ID) -> GnssEpoch:
    """Convert ``rfi_msgs/GnssMeasurementArray`` to a :class:`GnssEpoch`.

    Args:
        msg: the message.
        expected_frame_id: raise if ``header.frame_id`` differs (satellite states are ECEF, so
            anything but "earth" means a producer bug); None skips the check.

    Returns:
        The epoch: ``stamp_ns`` = ``header.stamp`` in integer ns; observations in message order.

    Raises:
        ValueError: unexpected frame id, or two measurements of the same (constellation, svid).
    """
    if expected_frame_id is not None and msg.header.frame_id != expected_frame_id:
        raise ValueError(
            f"GnssMeasurementArray frame_id is {msg.header.frame_id!r}, expected {expected_frame_id!r}"
        )
    observations = tuple(msg_to_observation(m) for m in msg.measurements)
    _check_unique([(o.constellation, o.svid) for o in observations])
    return GnssEpoch(
        stamp_ns=stamp_to_ns(msg.header.stamp),
        gps_week=int(msg.gps_week),
        gps_time_of_week_s=float(msg.gps_time_of_week_s),
        observations=observations,
    )


def uwb_to_msg(meas: UwbRangeMeasurement, rssi_dbm: float = math.nan) -> UwbRange:
    """Convert a :class:`UwbRangeMeasurement` to ``rfi_msgs/UwbRange``.

    Args:
        meas: the range; ``stamp_ns`` (integer ns >= 0) -> ``header.stamp``, ``frame_id`` ->
            ``header.frame_id`` ("earth" = ECEF, "map" = local ENU), ``anchor_position_m`` (m, (3,))
            -> ``anchor_position``, ``range_m`` and ``range_std_m`` (m) copied.
        rssi_dbm: received signal strength, dBm (NaN: unknown). The dataclass has no RSSI field,
            so it is passed here.

    Returns:
        The message.

    Raises:
        ValueError: bad stamp, anchor position not of shape (3,), non-string anchor id.
    """
    if not isinstance(meas.anchor_id, str):
        raise ValueError(f"anchor_id must be a string, got {meas.anchor_id!r}")
    pos = _vector3(meas.anchor_position_m, "anchor_position_m")
    msg = UwbRange()
    msg.header = _header(meas.stamp_ns, meas.frame_id)
    msg.anchor_id = meas.anchor_id
    msg.anchor_position = Point(x=float(pos[0]), y=float(pos[1]), z=float(pos[2]))
    msg.range_m = _float(meas.range_m, "range_m")
    msg.range_std_m = _float(meas.range_std_m, "range_std_m")
    msg.rssi_dbm = _float(rssi_dbm, "rssi_dbm")
    return msg


def msg_to_uwb(msg: UwbRange, frame_id: str | None = None) -> UwbRangeMeasurement:
    """Convert ``rfi_msgs/UwbRange`` to a :class:`UwbRangeMeasurement`.

    Args:
        msg: the message.
        frame_id: ``frame_id`` of the measurement; None: the message's ``header.frame_id`` (the
            node passes the core's name of the header's frame).

    Returns:
        The measurement (``stamp_ns`` in integer ns). ``rssi_dbm`` is not part of the dataclass;
        read it from the message if needed.
    """
    p = msg.anchor_position
    return UwbRangeMeasurement(
        stamp_ns=stamp_to_ns(msg.header.stamp),
        anchor_id=str(msg.anchor_id),
        anchor_position_m=np.array([p.x, p.y, p.z], dtype=float),
        frame_id=str(msg.header.frame_id) if frame_id is None else frame_id,
        range_m=float(msg.range_m),
        range_std_m=float(msg.range_std_m),
    )


def point_to_msg(stamp_ns: int, position_m: np.ndarray, frame_id: str) -> PointStamped:
    """Build a ``geometry_msgs/PointStamped`` (truth or reference position).

    Args:
        stamp_ns: time of the position, integer ns >= 0.
        position_m: position, m, shape (3,), in ``frame_id`` ("earth" ECEF or "map" local).
        frame_id: ``header.frame_id``.

    Returns:
        The message.

    Raises:
        ValueError: bad stamp or a position not of shape (3,).
    """
    pos = _vector3(position_m, "position_m")
    return PointStamped(
        header=_header(stamp_ns, frame_id), point=Point(x=float(pos[0]), y=float(pos[1]), z=float(pos[2]))
    )


def msg_to_point(msg: PointStamped) -> tuple[int, np.ndarray, str]:
    """Read a ``geometry_msgs/PointStamped``.

    Args:
        msg: the message.

    Returns:
        ``(stamp_ns, position_m, frame_id)``: integer ns, float64 array (3,) in m, the frame id.
    """
    p = msg.point
    return stamp_to_ns(msg.header.stamp), np.array([p.x, p.y, p.z], dtype=float), str(msg.header.frame_id)


_UWB = layout(UwbRange)
_UWB_SEC, _ = _UWB.position("header.stamp.sec")
_UWB_NANOSEC, _ = _UWB.position("header.stamp.nanosec")
_UWB_FRAME_ID, _ = _UWB.position("header.frame_id")
_UWB_ANCHOR_ID, _ = _UWB.position("anchor_id")
_, _UWB_POSITION = _UWB.position("anchor_position")
_, _UWB_RANGE = _UWB.position("range_m")
_, _UWB_RANGE_STD = _UWB.position("range_std_m")


def decode_uwb_range_cdr(raw: bytes, frame_map: dict[str, str] | None = None
                         ) -> tuple[int, str, UwbRangeMeasurement | None] | None:
    """Decode a serialised ``rfi_msgs/UwbRange`` (little-endian CDR) without rclpy.

    The bytes are read by the suite's codec (:mod:`rfi_node_common.cdr`, layout from the generated
    UwbRange class); the fields are found in its value streams by name.

    Args:
        raw: the serialised message, as a ``raw=True`` subscription or a bag delivers it.
        frame_map: optional header.frame_id -> measurement frame_id (the node's names of the core
            frames); a frame_id not in it gives no measurement. None: the measurement keeps
            header.frame_id (as :func:`msg_to_uwb`).

    Returns:
        ``(stamp_ns, header.frame_id, measurement or None)``; None if ``raw`` is not little-endian
        CDR or is cut short or malformed, or a string is not UTF-8 or has a NUL inside (the caller
        then deserialises it with rclpy, which reports the error). Equal field for field to
        ``msg_to_uwb(deserialize_message(raw, UwbRange))`` whenever both decode the bytes (tested,
        also on fuzzed bytes). Never raises and never reads outside ``raw``, whatever it holds.
    """
    d = _UWB.decode(raw)
    if d is None:
        return None
    ints = d.ints.tolist()
    f = d.floats.tolist()
    start, length = ints[_UWB_FRAME_ID], ints[_UWB_FRAME_ID + 1]
    anchor_start, anchor_length = ints[_UWB_ANCHOR_ID], ints[_UWB_ANCHOR_ID + 1]
    try:
        frame_id = raw[start:start + length].decode("utf-8")
        anchor_id = raw[anchor_start:anchor_start + anchor_length].decode("utf-8")
    except UnicodeDecodeError:
        return None
    stamp_ns = ints[_UWB_SEC] * 1_000_000_000 + ints[_UWB_NANOSEC]
    target = frame_id if frame_map is None else frame_map.get(frame_id)
    if target is None:
        return stamp_ns, frame_id, None
    meas = UwbRangeMeasurement(stamp_ns=stamp_ns, anchor_id=anchor_id,
                               anchor_position_m=np.array(f[_UWB_POSITION:_UWB_POSITION + 3]), frame_id=target,
                               range_m=f[_UWB_RANGE], range_std_m=f[_UWB_RANGE_STD])
    return stamp_ns, frame_id, meas
