"""The node's hot-path messages (CorrelatorArray in, CarrierPhaseArray out) through the suite's CDR codec.

At 32 satellites and 1 kHz, letting rclpy turn each serialised CorrelatorArray into 32 Python
``Correlator`` objects, and each answer into 32 ``CarrierPhase`` objects that rclpy then converts
back to C structures, costs more than the filters themselves. The node therefore subscribes with
``raw=True`` and publishes ``bytes``. The bytes are read and written by :mod:`rfi_node_common.cdr`,
whose layouts come from the generated message classes: this module only names the streams (which
stream entry is which field, found by field name in the layout) and says where each CarrierPhase
field comes from (:data:`ESTIMATE_SOURCES`, one entry per field of rfi_msgs/CarrierPhase). A field
added to CarrierPhase.msg without an entry there fails at import; a field added to Correlator.msg is
decoded and ignored until it is named here (``carrier_lock`` is: the correlator's own carrier lock, handed to the
trackers); no byte offset is written here.

Little-endian CDR only: ``decode_correlator_array`` returns None otherwise (the node then lets rclpy
re-serialise the message), and for malformed bytes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from imm_carrier.measurement_model import METHOD_IMM
from imm_carrier.tracker import BATCH_COLUMNS
from rfi_msgs.msg import CarrierPhaseArray, CorrelatorArray
from rfi_node_common.cdr import CDR_LE, encode_bytes, layout

__all__ = ["CDR_LE", "DecodedCorrelatorArray", "ESTIMATE_SOURCES", "decode_correlator_array",
           "encode_carrier_phase_array"]

UINT32_MAX = 2**32 - 1

# ---------------------------------------------------------------- CorrelatorArray: stream positions by name
_IN = layout(CorrelatorArray)
_SEC, _ = _IN.position("header.stamp.sec")
_NANOSEC, _ = _IN.position("header.stamp.nanosec")
_HEADER_FIELD = [f.name for f in _IN.fields].index("header")
_COUNT, _FIRST_FLOAT = _IN.position("correlators")  # the count, then the elements
_CORRELATOR = _IN.element("correlators")
_entries = _CORRELATOR.entries()
if _entries is None or _IN.fields[-1].name != "correlators":
    raise ImportError("imm_carrier.cdr expects CorrelatorArray = header, ..., Correlator[] correlators "
                      "with Correlator of fixed-size fields: update decode_correlator_array")
_INTS_PER_ELEMENT, _FLOATS_PER_ELEMENT = _entries
_INT_FIELDS = ("constellation", "svid", "carrier_lock")
_FLOAT_FIELDS = ("integration_time_s", "in_phase", "quadrature", "cn0_dbhz", "predicted_phase_change_rad")
_INT_AT = [_CORRELATOR.position(name)[0] for name in _INT_FIELDS]
_FLOAT_AT = [_CORRELATOR.position(name)[1] for name in _FLOAT_FIELDS]


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
        carrier_lock: int64, rfi_msgs/Correlator CARRIER_LOCK_* (0 unknown, 1 lost, 2 held).
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
    carrier_lock: np.ndarray


def decode_correlator_array(raw: bytes) -> DecodedCorrelatorArray | None:
    """Serialised rfi_msgs/CorrelatorArray -> arrays, or None if not little-endian CDR or malformed.

    Safe on any byte string (fuzz-tested): a truncated, overwritten or random payload gives None or the
    fields that its bytes encode, never an error or a read out of bounds. A frame_id with a NUL inside
    is accepted (the header is copied verbatim into the answer).

    Args:
        raw: the serialised message, as a raw subscription delivers it.

    Returns:
        DecodedCorrelatorArray, or None (the caller then uses rclpy's deserialisation).
    """
    if len(raw) < 8:
        return None
    d = _IN.decode(raw, strict_strings=False)
    if d is None:
        return None
    ints, floats = d.ints, d.floats
    n = int(ints[_COUNT])
    elements = ints[_COUNT + 1:_COUNT + 1 + n * _INTS_PER_ELEMENT].reshape(n, _INTS_PER_ELEMENT)
    values = floats[_FIRST_FLOAT:_FIRST_FLOAT + n * _FLOATS_PER_ELEMENT].reshape(n, _FLOATS_PER_ELEMENT)
    nanosec = int(ints[_NANOSEC])
    return DecodedCorrelatorArray(
        stamp_ns=int(ints[_SEC]) * 1_000_000_000 + nanosec,
        stamp_nanosec=nanosec,
        header_end=int(d.marks[_HEADER_FIELD]),
        constellation=elements[:, _INT_AT[0]],
        svid=elements[:, _INT_AT[1]],
        integration_time_s=values[:, _FLOAT_AT[0]],
        in_phase=values[:, _FLOAT_AT[1]],
        quadrature=values[:, _FLOAT_AT[2]],
        cn0_dbhz=values[:, _FLOAT_AT[3]],
        predicted_phase_change_rad=values[:, _FLOAT_AT[4]],
        carrier_lock=elements[:, _INT_AT[2]],
    )


# ---------------------------------------------------------------- CarrierPhaseArray: where each field comes from
SOURCE_METHOD = -1
SOURCE_LOCKED = -2
SOURCE_CYCLE_SLIPS = -3
SOURCE_MODE_PROBABILITIES = -4
_COLUMN = {name: k for k, name in enumerate(BATCH_COLUMNS)}

ESTIMATE_SOURCES: dict[str, int] = {
    "constellation": _COLUMN["constellation"],
    "svid": _COLUMN["svid"],
    "method": SOURCE_METHOD,
    "phase_rad": _COLUMN["phase_rad"],
    "phase_std_rad": _COLUMN["phase_std_rad"],
    "frequency_hz": _COLUMN["frequency_hz"],
    "frequency_std_hz": _COLUMN["frequency_std_hz"],
    "data_bit": _COLUMN["data_bit"],
    "data_bit_probability": _COLUMN["data_bit_probability"],
    "mode_probabilities": SOURCE_MODE_PROBABILITIES,
    "locked": SOURCE_LOCKED,
    "cycle_slips": SOURCE_CYCLE_SLIPS,
}
"""Source of each rfi_msgs/CarrierPhase field: a column of the tracker's result table
(imm_carrier.tracker.BATCH_COLUMNS; an integer field takes the column's integer part), or a rule:
SOURCE_METHOD the table's method; SOURCE_MODE_PROBABILITIES the two mode probabilities for the IMM,
none for the PLL; SOURCE_LOCKED the lock flag, written true only with a finite phase and frequency
(and for the IMM finite standard deviations > 0: a last net behind the tracker's own check);
SOURCE_CYCLE_SLIPS the count clipped to uint32."""

_OUT = layout(CarrierPhaseArray)
if [f.name for f in _OUT.fields] != ["header", "estimates"]:
    raise ImportError("imm_carrier.cdr expects CarrierPhaseArray = header, CarrierPhase[] estimates: "
                      "say where its new fields come from in encode_carrier_phase_array")
_ESTIMATE = _OUT.element("estimates")
_missing = [f.name for f in _ESTIMATE.fields if f.name not in ESTIMATE_SOURCES]
if _missing:
    raise ImportError(f"rfi_msgs/CarrierPhase fields without a source in imm_carrier.cdr.ESTIMATE_SOURCES: {_missing}")
_SLOT_INT, _SLOT_FLOAT, _SLOT_FLOAT_SEQUENCE = 0, 1, 2


def _slot(f) -> list[int]:
    source = ESTIMATE_SOURCES[f.name]
    if f.kind == "int":
        return [_SLOT_INT, source]
    if f.kind == "float":
        return [_SLOT_FLOAT, source]
    if f.kind == "sequence" and f.element_kind == "float" and source == SOURCE_MODE_PROBABILITIES:
        return [_SLOT_FLOAT_SEQUENCE, source]
    raise ImportError(f"imm_carrier.cdr cannot write CarrierPhase.{f.name} ({f.kind})")


_SLOTS = np.array([_slot(f) for f in _ESTIMATE.fields], dtype=np.int64)
_ESTIMATES_START = _OUT.field_ops[1]
_V_PHASE, _V_PHASE_STD = _COLUMN["phase_rad"], _COLUMN["phase_std_rad"]
_V_FREQ, _V_FREQ_STD = _COLUMN["frequency_hz"], _COLUMN["frequency_std_hz"]
_V_MU1, _V_MU2 = _COLUMN["mode_probability_plus"], _COLUMN["mode_probability_minus"]
_V_LOCKED, _V_SLIPS = _COLUMN["locked"], _COLUMN["cycle_slips"]


@njit(cache=True)
def _rule(r, method, source):
    """Integer value of a rule source for one table row r."""
    if source == SOURCE_METHOD:
        return method
    if source == SOURCE_LOCKED:
        valid = abs(r[_V_PHASE]) < np.inf and abs(r[_V_FREQ]) < np.inf
        if method == METHOD_IMM:  # the IMM's standard deviations must be usable too
            valid = valid and 0.0 < r[_V_PHASE_STD] < np.inf and 0.0 < r[_V_FREQ_STD] < np.inf
        return 1 if (r[_V_LOCKED] > 0.5 and valid) else 0
    slips = int(r[_V_SLIPS])
    return min(max(slips, 0), UINT32_MAX)


@njit(cache=True)
def _put_rows(values, method, slots, ints, floats, ni, nf):
    for k in range(values.shape[0]):
        r = values[k]
        for s in range(slots.shape[0]):
            kind = slots[s, 0]
            source = slots[s, 1]
            if kind == _SLOT_INT:
                ints[ni] = int(r[source]) if source >= 0 else _rule(r, method, source)
                ni += 1
            elif kind == _SLOT_FLOAT:
                floats[nf] = r[source]
                nf += 1
            elif method == METHOD_IMM:  # mode probabilities
                ints[ni] = 2
                floats[nf] = r[_V_MU1]
                floats[nf + 1] = r[_V_MU2]
                ni += 1
                nf += 2
            else:
                ints[ni] = 0
                ni += 1
    return ni, nf


@njit(cache=True)
def _streams(values_a, method_a, values_b, method_b, slots):
    """The value streams of the estimates sequence (count, then each row's fields in wire order)."""
    n = values_a.shape[0] + values_b.shape[0]
    width = slots.shape[0] + 2
    ints = np.empty(1 + n * width, dtype=np.int64)
    floats = np.empty(n * width)
    ints[0] = n
    ni, nf = _put_rows(values_a, method_a, slots, ints, floats, 1, 0)
    ni, nf = _put_rows(values_b, method_b, slots, ints, floats, ni, nf)
    return ints[:ni], floats[:nf]


_EMPTY_TABLE = np.empty((0, len(BATCH_COLUMNS)))
_NO_TEXT = np.empty(0, dtype=np.uint8)


def encode_carrier_phase_array(header: bytes, tables: list[tuple[np.ndarray, int]]) -> bytes:
    """Serialise a CarrierPhaseArray whose header is ``header`` and whose estimates are the rows of tables.

    Args:
        header: the encapsulation and serialised std_msgs/Header (4 + header_end bytes of the input,
            see DecodedCorrelatorArray.header_end), copied verbatim.
        tables: up to two (values, method) pairs, values shaped (n, 12) with the columns of
            imm_carrier.tracker.BATCH_COLUMNS, method METHOD_IMM (two mode probabilities) or METHOD_PLL
            (none), in output order.

    Returns:
        The serialised message (little-endian CDR), ready for ``Publisher.publish``; each field as
        :data:`ESTIMATE_SOURCES` says.
    """
    if len(tables) > 2:
        raise ValueError("at most two tables (one per method)")
    pairs = list(tables) + [(_EMPTY_TABLE, 0)] * (2 - len(tables))
    n = sum(v.shape[0] for v, _ in pairs)
    head = np.frombuffer(header, dtype=np.uint8)
    # Two compiled calls, not one: a cached numba function that called the codec of another package would
    # keep a stale copy of it after that package changes (numba checks only the caller's own file).
    ints, floats = _streams(np.ascontiguousarray(pairs[0][0], dtype=np.float64), int(pairs[0][1]),
                            np.ascontiguousarray(pairs[1][0], dtype=np.float64), int(pairs[1][1]), _SLOTS)
    raw = encode_bytes(_OUT.program, _ESTIMATES_START, head, ints, floats, _NO_TEXT, head.size + 8 + 128 * n)
    if raw is None:
        raise ValueError("tables do not fit rfi_msgs/CarrierPhaseArray")
    return raw
