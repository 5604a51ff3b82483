"""Byte-exact oracle tests of the node's compiled CDR codec against rclpy's serialisation of the real messages."""

from __future__ import annotations

import math

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message

from imm_carrier.cdr import decode_correlator_array, encode_carrier_phase_array
from imm_carrier.measurement_model import METHOD_IMM, METHOD_PLL
from imm_carrier.tracker import N_BATCH_COLUMNS
from rfi_msgs.msg import CarrierPhase, CarrierPhaseArray, Correlator, CorrelatorArray


def _correlator_array(rng, n, frame_id, sec=1_400_000_000, nanosec=123_456_789):
    msg = CorrelatorArray()
    msg.header.stamp.sec = sec
    msg.header.stamp.nanosec = nanosec
    msg.header.frame_id = frame_id
    for _ in range(n):
        msg.correlators.append(Correlator(
            constellation=int(rng.integers(0, 256)), svid=int(rng.integers(0, 65536)),
            integration_time_s=float(rng.uniform(1e-3, 2e-2)), in_phase=float(rng.normal()),
            quadrature=float(rng.normal()), cn0_dbhz=float(rng.choice([rng.uniform(0, 70), math.nan])),
            predicted_phase_change_rad=float(rng.uniform(-1e3, 1e3)), carrier_lock=int(rng.integers(0, 256))))
    return msg


# frame_id lengths 0..8 move the first element through every alignment residue.
@pytest.mark.parametrize('frame_id', ['', 'a', 'ab', 'abc', 'abcd', 'gnss_receiver', 'abcdefg', 'abcdefgh'])
@pytest.mark.parametrize('n', [0, 1, 5, 32])
def test_decode_equals_rclpy_deserialisation(frame_id, n):
    rng = np.random.default_rng(len(frame_id) * 100 + n)
    msg = _correlator_array(rng, n, frame_id, sec=-5 if n == 1 else 1_400_000_000)
    raw = serialize_message(msg)
    d = decode_correlator_array(raw)
    assert d is not None
    assert d.stamp_ns == msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
    back = deserialize_message(raw[:4 + d.header_end] + b'\x00' * 8, CorrelatorArray)  # header + empty sequence
    assert back.header == msg.header
    for name, values in (('constellation', d.constellation), ('svid', d.svid),
                         ('integration_time_s', d.integration_time_s), ('in_phase', d.in_phase),
                         ('quadrature', d.quadrature), ('cn0_dbhz', d.cn0_dbhz),
                         ('predicted_phase_change_rad', d.predicted_phase_change_rad),
                         ('carrier_lock', d.carrier_lock)):
        np.testing.assert_array_equal(values, [getattr(c, name) for c in msg.correlators], err_msg=name)


def test_decode_rejects_big_endian_and_truncated_input():
    msg = _correlator_array(np.random.default_rng(1), 3, 'rx')
    raw = serialize_message(msg)
    assert decode_correlator_array(b'\x00\x00' + raw[2:]) is None
    for cut in (5, 20, len(raw) - 1):
        assert decode_correlator_array(raw[:cut]) is None


def _table(rng, n, method):
    v = np.empty((n, N_BATCH_COLUMNS))
    v[:, 0] = rng.integers(0, 256, n)
    v[:, 1] = rng.integers(0, 65536, n)
    v[:, 2:6] = rng.normal(size=(n, 4)) * 10
    v[:, 6] = rng.choice([-1, 0, 1], n)
    v[:, 7] = rng.random(n)
    v[:, 8] = rng.random(n)
    v[:, 9] = 1 - v[:, 8]
    v[:, 10] = rng.integers(0, 2, n)
    v[:, 11] = rng.integers(0, 2**32 + 10, n)
    if method == METHOD_PLL:
        v[:, [3, 5, 8, 9]] = math.nan
    if n > 2:
        v[1, 2] = math.nan  # a non-finite phase is never published as locked
        v[1, 10] = 1.0
        v[2, 11] = -3
    if n > 4:
        v[3, 3] = 0.0  # nor, for the IMM, a zero or infinite std
        v[4, 5] = math.inf
        v[3:5, 10] = 1.0
    return v


def _expected_msg(header, tables):
    out = CarrierPhaseArray()
    out.header = header
    for values, method in tables:
        for r in values:
            out.estimates.append(CarrierPhase(
                constellation=int(r[0]), svid=int(r[1]), method=method, phase_rad=r[2], phase_std_rad=r[3],
                frequency_hz=r[4], frequency_std_hz=r[5], data_bit=int(r[6]), data_bit_probability=r[7],
                mode_probabilities=[r[8], r[9]] if method == METHOD_IMM else [],
                locked=bool(r[10] > 0.5 and math.isfinite(r[2]) and math.isfinite(r[4]) and (
                    method != METHOD_IMM or (0 < r[3] < math.inf and 0 < r[5] < math.inf))),
                cycle_slips=min(max(int(r[11]), 0), 2**32 - 1)))
    return out


@pytest.mark.parametrize('frame_id', ['', 'a', 'ab', 'abc', 'abcd', 'gnss_receiver', 'abcdefg'])
@pytest.mark.parametrize('sizes', [((0, METHOD_IMM),), ((1, METHOD_PLL),), ((32, METHOD_IMM),),
                                   ((3, METHOD_IMM), (3, METHOD_PLL)), ((5, METHOD_PLL), (2, METHOD_IMM))])
def test_encode_equals_rclpy_serialisation(frame_id, sizes):
    rng = np.random.default_rng(len(frame_id) + 7 * sum(n for n, _ in sizes))
    inp = _correlator_array(rng, 2, frame_id)
    raw_in = serialize_message(inp)
    d = decode_correlator_array(raw_in)
    tables = [(_table(rng, n, m), m) for n, m in sizes]
    raw_out = encode_carrier_phase_array(raw_in[:4 + d.header_end], tables)
    expected = _expected_msg(inp.header, tables)
    reference = serialize_message(expected)
    # The middleware leaves alignment padding uninitialised and its buffer length is its size estimate,
    # which pads even an empty float64 sequence (the data written does not): so our bytes must be a prefix
    # of the reference except at padding (bytes where two serialisations of the same message differ, or
    # that we zeroed), at most 4 bytes shorter per PLL row.
    n_pll = sum(n for n, m in sizes if m == METHOD_PLL)
    assert len(reference) - 4 * n_pll <= len(raw_out) <= len(reference)
    got = deserialize_message(raw_out, CarrierPhaseArray)
    assert got.header == expected.header and len(got.estimates) == len(expected.estimates)
    for a, b in zip(got.estimates, expected.estimates, strict=True):
        for name in CarrierPhase.get_fields_and_field_types():
            np.testing.assert_array_equal(np.asarray(getattr(a, name), dtype=float),
                                          np.asarray(getattr(b, name), dtype=float), err_msg=name)
    ours = np.frombuffer(raw_out, np.uint8)
    theirs = np.frombuffer(reference, np.uint8)[:ours.size]
    again = np.frombuffer(serialize_message(got), np.uint8)[:ours.size]
    fixed = theirs == again  # bytes the middleware wrote the same twice: fields (padding may repeat too)
    differ = np.flatnonzero(fixed & (ours != theirs))
    assert all(ours[i] == 0 for i in differ), differ  # where we differ, it is padding we zeroed


def _hostile_payloads(rng, count):
    """Seeded hostile byte strings: random bytes, truncations, overwritten bytes and overwritten lengths of
    valid CorrelatorArrays (as a fuzzer on the wire sends them)."""
    valid = [serialize_message(_correlator_array(rng, n, f)) for n, f in ((0, ''), (1, 'a'), (3, 'rx'), (7, 'abcdefg'))]
    out = [b'', b'\x00', b'\x00\x01\x00\x00', b'\x00\x01\x00\x00' + bytes(8), b'\x00\x01\x00\x00' + b'\xff' * 40]
    for raw in valid:
        out += [raw[:cut] for cut in range(len(raw))]
        count_at = 4 + (12 + int.from_bytes(raw[12:16], 'little') + 3) // 4 * 4
        for offset in (12, count_at):  # the string length, the sequence count
            for value in (0, 1, 2**31 - 1, 2**32 - 1, 10**6):
                buf = bytearray(raw)
                if offset + 4 <= len(buf):
                    buf[offset:offset + 4] = value.to_bytes(4, 'little')
                    out.append(bytes(buf))
    while len(out) < count:
        kind = rng.integers(3)
        if kind == 0:
            head = b'\x00\x01\x00\x00' if rng.random() < 0.7 else b''
            out.append(head + rng.integers(0, 256, int(rng.integers(0, 400)), dtype=np.uint8).tobytes())
        else:
            buf = bytearray(valid[int(rng.integers(len(valid)))])
            for _ in range(int(rng.integers(1, 8))):
                buf[int(rng.integers(4, len(buf)))] = int(rng.integers(256))
            out.append(bytes(buf) if kind == 1 else bytes(buf[:int(rng.integers(4, len(buf) + 1))]))
    return out


def test_decoder_never_fails_or_reads_out_of_bounds_on_hostile_bytes(monkeypatch):
    """Fuzz (seeded, 3000 payloads): the compiled decoder returns None or the fields the bytes encode, never
    raises; its uncompiled twin, whose numpy indexing raises IndexError on any read past the buffer, agrees on
    every payload (so the compiled one reads nothing out of bounds). Whatever it accepts, rclpy deserialises to
    the same fields."""
    from rfi_node_common import cdr as codec

    twin = {name: getattr(codec, name).py_func for name in codec.CODEC_KERNELS}
    rng = np.random.default_rng(12)
    accepted = 0
    for raw in _hostile_payloads(rng, 3000):
        d = decode_correlator_array(raw)
        with monkeypatch.context() as m:
            for name, func in twin.items():
                m.setattr(codec, name, func)
            t = decode_correlator_array(raw)  # IndexError here = an out-of-bounds read
        assert (t is None) == (d is None)
        if d is not None:
            np.testing.assert_array_equal(t.in_phase, d.in_phase)
            np.testing.assert_array_equal(t.svid, d.svid)
        if d is None:
            continue
        accepted += 1
        assert 0 < d.header_end <= len(raw) - 4
        msg = deserialize_message(raw, CorrelatorArray)
        assert d.stamp_ns == msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        assert d.stamp_nanosec == msg.header.stamp.nanosec
        assert len(msg.correlators) == d.constellation.shape[0]
        for name, values in (('svid', d.svid), ('integration_time_s', d.integration_time_s),
                             ('in_phase', d.in_phase), ('cn0_dbhz', d.cn0_dbhz)):
            np.testing.assert_array_equal(values, [getattr(c, name) for c in msg.correlators], err_msg=name)
    assert accepted > 100  # the overwritten payloads that stay well-formed


def test_decoder_requires_a_terminated_frame_id():
    raw = serialize_message(_correlator_array(np.random.default_rng(2), 2, 'rx'))
    assert decode_correlator_array(raw) is not None
    no_nul = raw[:18] + b'x' + raw[19:]  # frame_id 'rx' + NUL -> 'rxx' without its terminating NUL
    assert decode_correlator_array(no_nul) is None
    empty = raw[:12] + bytes(4) + raw[16:]  # string length 0: not a CDR string (the NUL counts)
    assert decode_correlator_array(empty) is None


def test_every_carrier_phase_field_has_a_source():
    """The encoder says where each CarrierPhase field comes from, by name (a field added to the .msg without a
    source fails at import); the decoder finds the Correlator fields by name in the layout."""
    from imm_carrier.cdr import ESTIMATE_SOURCES

    assert list(ESTIMATE_SOURCES) == list(CarrierPhase.get_fields_and_field_types())
    assert {'constellation', 'svid', 'in_phase', 'quadrature'} <= set(Correlator.get_fields_and_field_types())
