"""rfi_node_common.stamps: the header stamp read from serialised bytes equals the message's own stamp."""

from __future__ import annotations

from rclpy.serialization import serialize_message

from rfi_msgs.msg import FusionStatus, UwbRange
from rfi_node_common.stamps import ns_to_stamp, peek_header_stamp_ns, stamp_to_ns


def test_the_stamp_peeked_from_the_bytes_is_the_messages_header_stamp():
    for cls, stamp_ns in ((UwbRange, 1_700_000_000_123_456_789), (FusionStatus, 1_437_267_613_000_000_000),
                          (UwbRange, 1)):
        msg = cls()
        msg.header.stamp = ns_to_stamp(stamp_ns)
        msg.header.frame_id = 'earth'
        raw = serialize_message(msg)
        expected = stamp_to_ns(msg.header.stamp) if msg.header.stamp.sec > 0 else None  # at the epoch: not a stamp
        assert peek_header_stamp_ns(raw) == expected


def test_bytes_that_are_not_little_endian_cdr_with_a_header_give_none():
    msg = UwbRange()
    msg.header.stamp = ns_to_stamp(1_700_000_000_000_000_000)
    raw = serialize_message(msg)
    assert peek_header_stamp_ns(raw[:11]) is None                      # too short
    assert peek_header_stamp_ns(b'\x00\x00' + raw[2:]) is None         # big-endian CDR
    bad_nsec = raw[:8] + (2_000_000_000).to_bytes(4, 'little') + raw[12:]
    assert peek_header_stamp_ns(bad_nsec) is None                      # nanoseconds out of range
