"""Conversions between ROS time messages and integer nanoseconds (the cores' time unit)."""

from builtin_interfaces.msg import Time

from gnss_common.constants import NS_PER_S


def stamp_to_ns(stamp: Time) -> int:
    """``builtin_interfaces/Time`` -> integer nanoseconds."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def ns_to_stamp(stamp_ns: int) -> Time:
    """Integer nanoseconds (>= 0) -> ``builtin_interfaces/Time``."""
    stamp_ns = int(stamp_ns)
    if stamp_ns < 0:
        raise ValueError(f'negative stamp {stamp_ns} ns cannot be a ROS time')
    return Time(sec=stamp_ns // NS_PER_S, nanosec=stamp_ns % NS_PER_S)


def peek_header_stamp_ns(raw: bytes) -> int | None:
    """``header.stamp`` in ns of a serialised message whose first field is ``std_msgs/Header``, read from its first
    bytes without deserialising it (little-endian CDR: a 4-byte encapsulation header, then ``stamp.sec`` int32 and
    ``stamp.nanosec`` uint32), or None if the bytes do not look like that (big-endian, too short, a stamp at or
    before the epoch, nanoseconds out of range)."""
    if len(raw) < 12 or raw[0] != 0 or raw[1] not in (1, 3):      # CDR_LE / PL_CDR_LE
        return None
    sec = int.from_bytes(raw[4:8], 'little', signed=True)
    nsec = int.from_bytes(raw[8:12], 'little')
    if sec <= 0 or nsec >= NS_PER_S:
        return None
    return sec * NS_PER_S + nsec
