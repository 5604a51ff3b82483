"""Compiled CDR codec of the two messages on the node's hot path (CorrelatorArray in, CarrierPhaseArray out).

At 32 satellites and 1 kHz, letting rclpy turn each serialised CorrelatorArray into 32 Python
``Correlator`` objects, and each answer into 32 ``CarrierPhase`` objects that rclpy then converts
back to C structures, costs more than the filters themselves. The node therefore subscribes with
``raw=True`` and publishes ``bytes``: this module reads the correlator fields straight into numpy
arrays and writes the CarrierPhaseArray payload from the tracker's result table, in one compiled
call each. No rclpy or rfi_msgs import here; the tests check both directions byte for byte against
``rclpy.serialization`` on the real message types, so a change of the .msg files fails loudly.

Format (OMG CDR version 1 as written by ROS 2 middlewares, little endian): a 4-byte encapsulation
header ``00 01 00 00`` (CDR_LE), then the fields in declaration order, each primitive aligned to its
own size counted from the end of the encapsulation header; strings are a uint32 length (with the
terminating NUL) and the bytes; sequences a uint32 count and the elements (an empty float64
sequence adds no alignment padding). We write zeros where the middleware leaves padding
uninitialised, and end at the last field: rmw_fastrtps reports the length of its size estimate,
which aligns even an empty float64 sequence, so its buffers can end with up to 4 bytes per empty
sequence of unused trailing bytes; deserialisers ignore them. Only little-endian
input is decoded here (``decode_correlator_array`` returns None otherwise, and the caller falls back
to rclpy).

Messages (src/rfi_msgs/msg): CorrelatorArray = Header header, Correlator[] correlators; Correlator =
uint8 constellation, uint16 svid, float64 integration_time_s, in_phase, quadrature, cn0_dbhz,
predicted_phase_change_rad. CarrierPhaseArray = Header header, CarrierPhase[] estimates; CarrierPhase
= uint8 constellation, uint16 svid, uint8 method, float64 phase_rad, phase_std_rad, frequency_hz,
frequency_std_hz, int8 data_bit, float64 data_bit_probability, float64[] mode_probabilities, bool
locked, uint32 cycle_slips. Header = builtin_interfaces/Time stamp (int32 sec, uint32 nanosec),
string frame_id.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from imm_carrier.measurement_model import METHOD_IMM

CDR_LE = b"\x00\x01"
"""First two bytes of a little-endian CDR payload (encapsulation kind)."""
UINT32_MAX = 2**32 - 1
_ENCAPSULATION = 4
_N_CORRELATOR_FIELDS = 7
_MAX_ESTIMATE_BYTES = 104  # upper bound of one CarrierPhase with two mode probabilities, padding included
_ERR = -1


@dataclass(frozen=True)
class DecodedCorrelatorArray:
    """Fields of one CorrelatorArray as arrays, shape (n,) each.

    Attributes:
        stamp_ns: header.stamp, ns (sec * 1e9 + nanosec; negative for a negative sec).
        stamp_nanosec: header.stamp.nanosec as sent (a valid Time has it below 1e9).
        header_end: byte offset (from the payload start, after the 4-byte encapsulation) where the
            header ends; ``raw[:4 + header_end]`` is the encapsulation and the header, which an answer
            with the same header can copy.
        constellation, svid: int64.
        integration_time_s, in_phase, quadrature, cn0_dbhz, predicted_phase_change_rad: float64.
    """

    stamp_ns: int
    stamp_nanosec: int
    header_end: int
    constellation: np.ndarray
    svid: np.ndarray
    integration_time_s: np.ndarray
    in_phase: np.ndarray
    quadrature: np.ndarray
    cn0_dbhz: np.ndarray
    predicted_phase_change_rad: np.ndarray


@njit(cache=True)
def _align(offset, size):
    return (offset + size - 1) // size * size


@njit(cache=True)
def _u32(buf, p):
    return buf[p] | (buf[p + 1] << 8) | (buf[p + 2] << 16) | (np.int64(buf[p + 3]) << 24)


@njit(cache=True)
def _decode(buf, ints, floats, meta):
    """Decode a CDR_LE CorrelatorArray payload (buf includes the encapsulation header).

    Writes meta = [sec, nanosec, header_end, n]; ints (n, 2) constellation, svid; floats (n, 5).
    Returns n, or -1 if the buffer is too short for what it announces, the frame_id is not a CDR string
    (length >= 1 with its terminating NUL) or there are too many elements. Every read is bounds-checked
    first: any byte string gives n or -1, never a read outside buf.
    """
    size = buf.shape[0] - _ENCAPSULATION
    b = buf[_ENCAPSULATION:]
    if size < 12:
        return _ERR
    sec = _u32(b, 0)
    if sec >= 2**31:
        sec -= 2**32
    meta[0] = sec
    meta[1] = _u32(b, 4)
    slen = _u32(b, 8)
    o = 12 + slen
    if slen < 1 or o > size or b[o - 1] != 0:
        return _ERR
    meta[2] = o
    o = _align(o, 4)
    if o + 4 > size:
        return _ERR
    n = _u32(b, o)
    o += 4
    if n > ints.shape[0]:
        return _ERR
    tmp = np.empty(1, dtype=np.float64)
    tb = tmp.view(np.uint8)
    for k in range(n):
        if o + 1 > size:
            return _ERR
        ints[k, 0] = b[o]
        o = _align(o + 1, 2)
        if o + 2 > size:
            return _ERR
        ints[k, 1] = b[o] | (np.int64(b[o + 1]) << 8)
        o = _align(o + 2, 8)
        if o + 40 > size:
            return _ERR
        for f in range(5):
            for m in range(8):
                tb[m] = b[o + m]
            floats[k, f] = tmp[0]
            o += 8
    meta[3] = n
    return n


def decode_correlator_array(raw: bytes) -> DecodedCorrelatorArray | None:
    """Serialised rfi_msgs/CorrelatorArray -> arrays, or None if not little-endian CDR or malformed.

    Safe on any byte string (fuzz-tested): a truncated, overwritten or random payload gives None or the
    fields that its bytes encode, never an error or a read out of bounds.

    Args:
        raw: the serialised message, as a raw subscription delivers it.

    Returns:
        DecodedCorrelatorArray, or None (the caller then uses rclpy's deserialisation).
    """
    if len(raw) < 8 or raw[:2] != CDR_LE:
        return None
    buf = np.frombuffer(raw, dtype=np.uint8)
    n_max = max(0, (len(raw) - 20) // 44)  # an element takes at least 44 bytes
    ints = np.empty((n_max, 2), dtype=np.int64)
    floats = np.empty((n_max, 5))
    meta = np.zeros(4, dtype=np.int64)
    n = _decode(buf, ints, floats, meta)
    if n < 0:
        return None
    return DecodedCorrelatorArray(
        stamp_ns=int(meta[0]) * 1_000_000_000 + int(meta[1]),
        stamp_nanosec=int(meta[1]),
        header_end=int(meta[2]),
        constellation=ints[:n, 0],
        svid=ints[:n, 1],
        integration_time_s=floats[:n, 0],
        in_phase=floats[:n, 1],
        quadrature=floats[:n, 2],
        cn0_dbhz=floats[:n, 3],
        predicted_phase_change_rad=floats[:n, 4],
    )


@njit(cache=True)
def _put_f8(out, o, x, tmp, tb):
    o = _align(o, 8)
    tmp[0] = x
    for m in range(8):
        out[_ENCAPSULATION + o + m] = tb[m]
    return o + 8


@njit(cache=True)
def _put_u32(out, o, v):
    o = _align(o, 4)
    for m in range(4):
        out[_ENCAPSULATION + o + m] = (v >> (8 * m)) & 0xFF
    return o + 4


@njit(cache=True)
def _put_rows(out, o, values, method, tmp, tb):
    """Append the CarrierPhase elements of one tracker's result table (columns of tracker.BATCH_COLUMNS)."""
    for k in range(values.shape[0]):
        r = values[k]
        e = _ENCAPSULATION
        out[e + o] = np.uint8(int(r[0]) & 0xFF)
        o = _align(o + 1, 2)
        sv = int(r[1])
        out[e + o] = sv & 0xFF
        out[e + o + 1] = (sv >> 8) & 0xFF
        o += 2
        out[e + o] = method
        o += 1
        o = _put_f8(out, o, r[2], tmp, tb)
        o = _put_f8(out, o, r[3], tmp, tb)
        o = _put_f8(out, o, r[4], tmp, tb)
        o = _put_f8(out, o, r[5], tmp, tb)
        out[e + o] = np.uint8(int(r[6]) & 0xFF)  # int8 data_bit, two's complement
        o += 1
        o = _put_f8(out, o, r[7], tmp, tb)
        if method == METHOD_IMM:
            o = _put_u32(out, o, 2)
            o = _put_f8(out, o, r[8], tmp, tb)
            o = _put_f8(out, o, r[9], tmp, tb)
        else:
            o = _put_u32(out, o, 0)
        valid = abs(r[2]) < np.inf and abs(r[4]) < np.inf
        if method == METHOD_IMM:  # the IMM's standard deviations must be usable too
            valid = valid and 0.0 < r[3] < np.inf and 0.0 < r[5] < np.inf
        out[e + o] = 1 if (r[10] > 0.5 and valid) else 0
        o += 1
        slips = int(r[11])
        o = _put_u32(out, o, min(max(slips, 0), UINT32_MAX))
    return o


@njit(cache=True)
def _encode(header, values_a, method_a, values_b, method_b, out):
    """Write a CarrierPhaseArray payload: header bytes (encapsulation included) then the estimates."""
    for m in range(header.shape[0]):
        out[m] = header[m]
    out[0] = 0
    out[1] = 1
    out[2] = 0
    out[3] = 0
    o = header.shape[0] - _ENCAPSULATION
    o = _put_u32(out, o, values_a.shape[0] + values_b.shape[0])
    tmp = np.empty(1, dtype=np.float64)
    tb = tmp.view(np.uint8)
    o = _put_rows(out, o, values_a, method_a, tmp, tb)
    o = _put_rows(out, o, values_b, method_b, tmp, tb)
    return o + _ENCAPSULATION


_EMPTY_TABLE = np.empty((0, 12))


def encode_carrier_phase_array(header: bytes, tables: list[tuple[np.ndarray, int]]) -> bytes:
    """Serialise a CarrierPhaseArray whose header is ``header`` and whose estimates are the rows of tables.

    Args:
        header: the encapsulation and serialised std_msgs/Header (4 + header_end bytes of the input,
            see DecodedCorrelatorArray.header_end), copied verbatim.
        tables: up to two (values, method) pairs, values shaped (n, 12) with the columns of
            imm_carrier.tracker.BATCH_COLUMNS, method METHOD_IMM (two mode probabilities) or METHOD_PLL
            (none), in output order.

    Returns:
        The serialised message (little-endian CDR), ready for ``Publisher.publish``. ``locked`` is
        written true only with a finite phase and frequency (and, for the IMM, finite standard deviations
        > 0: a last net behind the tracker's own check); cycle_slips is clipped to uint32.
    """
    if len(tables) > 2:
        raise ValueError("at most two tables (one per method)")
    pairs = list(tables) + [(_EMPTY_TABLE, 0)] * (2 - len(tables))
    n = sum(v.shape[0] for v, _ in pairs)
    hdr = np.frombuffer(header, dtype=np.uint8)
    out = np.zeros(hdr.size + 8 + _MAX_ESTIMATE_BYTES * n, dtype=np.uint8)
    end = _encode(hdr, pairs[0][0], int(pairs[0][1]), pairs[1][0], int(pairs[1][1]), out)
    return out[:end].tobytes()
