"""The CDR codec against rclpy's serialisation, for random messages of every type the nodes decode or
build on their hot paths (and every rfi_msgs type): layouts derived from the generated classes, both
directions byte for byte, the .msg files (parsed by rosbags) agree with the layouts, fuzzed bytes,
and the generated message constructors against the public ones."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import NavSatFix
from std_msgs.msg import Header

import rfi_msgs.msg as rfi
from rfi_node_common import cdr
from rfi_node_common import message_builder as mb

RFI_TYPES = (rfi.CarrierPhase, rfi.CarrierPhaseArray, rfi.Correlator, rfi.CorrelatorArray, rfi.FusionStatus,
             rfi.GnssMeasurement, rfi.GnssMeasurementArray, rfi.IfSamples, rfi.JammerState, rfi.UwbRange)
TYPES = RFI_TYPES + (Odometry, NavSatFix, Header, Time, PointStamped, DiagnosticArray)
MSG_DIR = Path(__file__).resolve().parents[2] / "rfi_msgs" / "msg"


def _flatten(msg, ints: list, floats: list, strings: list) -> None:
    """Independent oracle of the stream order: walk the message object field by field."""
    for name, t in zip(type(msg).get_fields_and_field_types(), type(msg).SLOT_TYPES, strict=True):
        value = getattr(msg, name)
        kind = type(t).__name__
        if kind in ("Array", "BoundedSequence", "UnboundedSequence"):
            if kind != "Array":
                ints.append(len(value))
            for v in value:
                _flatten_one(t.value_type, v, ints, floats, strings)
        else:
            _flatten_one(t, value, ints, floats, strings)


def _flatten_one(t, v, ints, floats, strings) -> None:
    kind = type(t).__name__
    if kind == "NamespacedType":
        _flatten(v, ints, floats, strings)
    elif kind in ("UnboundedString", "BoundedString"):
        strings.append((len(ints), v))
        ints += [None, len(v.encode())]
    elif t.typename in ("float", "double"):
        floats.append(float(v))
    elif t.typename == "octet":
        ints.append(v[0] if isinstance(v, bytes) else int(v))
    else:
        ints.append(int(v) - 2**64 if int(v) >= 2**63 else int(v))  # a uint64 as its int64 bit pattern


def _same_streams(msg, raw: bytes, d: cdr.DecodedCdr) -> None:
    ints: list = []
    floats: list = []
    strings: list = []
    _flatten(msg, ints, floats, strings)
    got_ints = d.ints.tolist()
    assert len(got_ints) == len(ints) and len(d.floats) == len(floats)
    for at, text in strings:
        start, length = got_ints[at], got_ints[at + 1]
        assert raw[start:start + length].decode(errors="replace") == text  # rclpy replaces invalid UTF-8
        ints[at:at + 2] = [start, length]
    assert got_ints == ints
    np.testing.assert_array_equal(d.floats, np.array(floats, dtype=float))


def _padding(layout: cdr.CdrLayout, d: cdr.DecodedCdr, text: bytes) -> np.ndarray:
    """Byte positions the encoder leaves untouched (alignment padding): written with out pre-filled by
    0x00 and by 0xFF, they differ only there."""
    outs = []
    for fill in (0, 255):
        out = np.full(len(text) * 2 + 64, fill, dtype=np.uint8)
        end = cdr.encode_program(layout.program, 0, np.frombuffer(cdr.ENCAPSULATION, np.uint8), d.ints, d.floats,
                                 np.frombuffer(text, np.uint8), out)
        outs.append(out[:end])
    return outs[0] != outs[1]


@pytest.mark.parametrize("cls", TYPES, ids=lambda c: c.__name__)
def test_layout_equals_rclpy_serialisation_both_ways(cls):
    """Random messages (seeded): decoding rclpy's bytes gives the fields in wire order; encoding those
    streams gives rclpy's bytes, except alignment padding (left uninitialised by the middleware, zero
    here) and unused trailing bytes of its size estimate; rclpy reads our bytes back to the message."""
    layout = cdr.layout(cls)
    rng = np.random.default_rng(sum(map(ord, cls.__name__)))
    for _ in range(40):
        msg = cls(**mb.probe_values(cls, rng, max_sequence=4))
        raw = serialize_message(msg)
        d = layout.decode(raw)
        assert d is not None
        _same_streams(msg, raw, d)
        assert d.marks[-1] <= len(raw) - 4
        ours = layout.encode(d.ints, d.floats, raw)
        assert 0 <= len(raw) - len(ours) <= 8 * layout.program.shape[0]
        pad = _padding(layout, d, raw)
        theirs, mine = np.frombuffer(raw, np.uint8)[:len(ours)], np.frombuffer(ours, np.uint8)
        assert np.array_equal(theirs[~pad], mine[~pad]) and not mine[pad].any()
        assert mb.messages_equal(deserialize_message(ours, cls), msg)


def test_marks_and_positions_name_the_streams():
    layout = cdr.layout(rfi.UwbRange)
    msg = rfi.UwbRange(anchor_id="A7", range_m=12.5)
    msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = 17, 9, "earth"
    msg.anchor_position.y = -3.0
    raw = serialize_message(msg)
    d = layout.decode(raw)
    assert d.ints[layout.position("header.stamp.sec")[0]] == 17
    assert d.ints[layout.position("header.stamp.nanosec")[0]] == 9
    assert d.floats[layout.position("anchor_position.y")[1]] == -3.0
    assert d.floats[layout.position("range_m")[1]] == 12.5
    header = Header(stamp=msg.header.stamp, frame_id="earth")
    assert raw[:4 + d.marks[0]] == serialize_message(header)[:4 + d.marks[0]]
    assert layout.entries() == (6, 6)
    assert cdr.layout(rfi.CorrelatorArray).entries() is None  # a sequence: varies
    with pytest.raises(ValueError, match="position varies"):
        cdr.layout(rfi.FusionStatus).position("rejection_counts")
    with pytest.raises(KeyError):
        layout.position("header.nope")


def test_encode_after_a_verbatim_prefix():
    """The answer of a node can copy the serialised header of its input and encode the rest."""
    src = rfi.CorrelatorArray()
    src.header.stamp.sec, src.header.frame_id = 5, "rx"
    raw_in = serialize_message(src)
    head = raw_in[:4 + cdr.layout(rfi.CorrelatorArray).decode(raw_in).marks[0]]
    out = cdr.layout(rfi.CarrierPhaseArray).encode(np.array([1, 7, 9, 2, 0, 2, 1, 3]), np.arange(7.0), prefix=head,
                                                  after="header")
    msg = deserialize_message(out, rfi.CarrierPhaseArray)
    assert msg.header == src.header and len(msg.estimates) == 1
    e = msg.estimates[0]
    assert (e.constellation, e.svid, e.method, e.data_bit, e.locked, e.cycle_slips) == (7, 9, 2, 0, True, 3)
    assert (e.phase_rad, e.data_bit_probability, list(e.mode_probabilities)) == (0.0, 4.0, [5.0, 6.0])
    with pytest.raises(ValueError, match="do not fit"):
        cdr.layout(rfi.CarrierPhaseArray).encode(np.array([1, 7]), np.zeros(0), prefix=head, after="header")


@pytest.mark.parametrize("path", sorted(MSG_DIR.glob("*.msg")), ids=lambda p: p.stem)
def test_layouts_follow_the_msg_files(path):
    """The generated classes the layouts are computed from match src/rfi_msgs/msg (rosbags' parser):
    same field names and types in the same order. A .msg edited without rebuilding rfi_msgs fails here."""
    from rosbags.typesys import get_types_from_msg

    name = f"rfi_msgs/msg/{path.stem}"
    _, fields = get_types_from_msg(path.read_text(), name)[name]
    layout = cdr.layout(getattr(rfi, path.stem))
    assert [f.name for f in layout.fields] == [f[0] for f in fields]
    for f, (_, (node, spec)) in zip(layout.fields, fields, strict=True):
        kind = getattr(node, "name", str(node))
        if kind == "BASE":
            base = spec[0] if isinstance(spec, tuple) else spec
            if base == "string":
                assert f.kind == "string"
            else:
                assert f.primitive == {"float64": "double", "float32": "float", "bool": "boolean"}.get(base, base)
        elif kind == "NAME":
            assert f.kind == "message" and f.element.msg_class.__name__ == spec.split("/")[-1]
        else:  # ARRAY (fixed) or SEQUENCE
            assert f.kind == ("array" if kind == "ARRAY" else "sequence"), (f.name, kind)


def test_layout_change_is_picked_up():
    """A class whose description gains a field (as after editing a .msg and rebuilding) gets a new layout:
    the fields after it move, with no offset written anywhere."""
    from rosidl_parser.definition import BasicType

    class UwbRangeWithOffset:
        SLOT_TYPES = rfi.UwbRange.SLOT_TYPES[:2] + (BasicType("double"),) + rfi.UwbRange.SLOT_TYPES[2:]

        @staticmethod
        def get_fields_and_field_types():
            fields = list(rfi.UwbRange.get_fields_and_field_types().items())
            return dict(fields[:2] + [("antenna_offset_m", "double")] + fields[2:])

    old, new = cdr.layout(rfi.UwbRange), cdr.layout(UwbRangeWithOffset)
    assert new.position("range_m") == (old.position("range_m")[0], old.position("range_m")[1] + 1)
    raw = new.encode(np.array([1, 2, 0, 1, 0, 1]), np.arange(7.0), b"e")  # frame_id and anchor_id "e"
    d = new.decode(raw)
    assert d.ints.tolist() == [1, 2, 16, 1, 24, 1] and d.floats.tolist() == list(range(7))
    assert old.decode(raw).floats.tolist() == list(range(6))  # read with the old layout: every value moves


def _hostile(raw: bytes, rng: np.random.Generator, count: int):
    yield from (b"", b"\x00\x01", b"\x00\x01\x00\x00", b"\x00\x01\x00\x00" + b"\xff" * 40)
    yield from (raw[:cut] for cut in range(len(raw)))
    for k in range(count):
        buf = bytearray(raw)
        if k % 3 == 0:
            yield b"\x00\x01\x00\x00" + rng.integers(0, 256, int(rng.integers(0, 200)), dtype=np.uint8).tobytes()
            continue
        for _ in range(int(rng.integers(1, 6))):
            buf[int(rng.integers(4, len(buf)))] = int(rng.choice([0, 1, 2, 255, int(rng.integers(256))]))
        yield bytes(buf) if k % 3 == 1 else bytes(buf[:int(rng.integers(4, len(buf) + 1))])


@pytest.mark.parametrize("cls", (rfi.CorrelatorArray, rfi.UwbRange, rfi.GnssMeasurementArray, rfi.FusionStatus,
                                 NavSatFix), ids=lambda c: c.__name__)
def test_decoder_on_hostile_bytes(cls, monkeypatch):
    """Fuzz (seeded): random, truncated and overwritten bytes. The compiled decoder never raises and
    declines with None; its uncompiled twin, whose numpy indexing raises IndexError on any read past the
    buffer, agrees on every payload (so the compiled one reads nothing out of bounds); whatever it
    accepts, rclpy deserialises to the same fields."""
    layout = cdr.layout(cls)
    rng = np.random.default_rng(99)
    valid = serialize_message(cls(**mb.probe_values(cls, rng, max_sequence=3)))
    payloads = list(_hostile(valid, rng, 1500))
    decoded = [layout.decode(raw) for raw in payloads]  # compiled
    with monkeypatch.context() as m:
        for name in cdr.CODEC_KERNELS:  # the uncompiled twin: every compiled function of the codec
            m.setattr(cdr, name, getattr(cdr, name).py_func)
        for raw, d in zip(payloads, decoded, strict=True):
            twin = layout.decode(raw)  # IndexError here = an out-of-bounds read
            assert (twin is None) == (d is None)
            if d is not None:
                assert twin is not None and all(a.tobytes() == b.tobytes() for a, b in zip(twin, d, strict=True))
    accepted = 0
    for raw, d in zip(payloads, decoded, strict=True):
        if d is None:
            continue
        accepted += 1
        msg = deserialize_message(raw, cls)
        _same_streams(msg, raw, d)
    assert accepted > 20


def test_decoder_declines_malformed_strings_and_bools():
    raw = serialize_message(rfi.UwbRange(anchor_id="ab"))
    layout = cdr.layout(rfi.UwbRange)
    assert layout.decode(raw) is not None
    at = raw.index(b"ab\x00")
    assert layout.decode(raw[:at] + b"a\x00\x00" + raw[at + 3:]) is None  # NUL inside
    assert layout.decode(raw[:at] + b"a\x00\x00" + raw[at + 3:], strict_strings=False) is not None
    assert layout.decode(raw[:at] + b"abc" + raw[at + 3:]) is None  # no terminating NUL
    assert layout.decode(b"\x00\x00" + raw[2:]) is None  # big endian
    status = serialize_message(rfi.FusionStatus(initialized=True))
    at = cdr.layout(rfi.FusionStatus).decode(status).marks[1] + 4  # the byte of 'initialized'
    assert status[at] == 1
    assert cdr.layout(rfi.FusionStatus).decode(status[:at] + b"\x02" + status[at + 1:]) is None


@pytest.mark.parametrize("cls", TYPES, ids=lambda c: c.__name__)
def test_message_builder_equals_public_constructor(cls):
    assert mb.builders_agree(cls)
    build, public = mb.message_builder(cls), mb.message_builder(cls, fast=False)
    rng = np.random.default_rng(5)
    for _ in range(20):
        msg = cls(**mb.probe_values(cls, rng))
        fast = build(**mb.leaf_values(msg))
        assert mb.messages_equal(fast, msg) and mb.messages_equal(public(**mb.leaf_values(msg)), msg)
        assert mb.messages_equal(deserialize_message(serialize_message(fast), cls), msg)
    a, b = build(), build()
    assert mb.messages_equal(a, cls())
    for name in cls.get_fields_and_field_types():  # defaults are never shared between messages
        va = getattr(a, name)
        assert not isinstance(va, (list, np.ndarray)) or va is not getattr(b, name)
    if "header" in cls.get_fields_and_field_types():
        assert a.header is not b.header and build(header__frame_id="x").header.frame_id == "x"


def test_message_builder_refused_with_field_checks(monkeypatch):
    import std_msgs.msg._header as module

    assert mb.builders_agree.__wrapped__(Header)
    monkeypatch.setattr(module, "ros_python_check_fields", "1")
    assert not mb.builders_agree.__wrapped__(Header)


def test_messages_equal():
    a, b = Time(sec=1, nanosec=2), Time(sec=1, nanosec=2)
    assert mb.messages_equal(a, b)
    assert not mb.messages_equal(a, Time(sec=1, nanosec=3))
    f1, f2 = NavSatFix(latitude=math.nan), NavSatFix(latitude=math.nan)
    assert mb.messages_equal(f1, f2) and f1 != f2
