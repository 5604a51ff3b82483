"""The suite's one CDR codec: byte layouts derived from the generated message classes themselves.

A raw subscription delivers a message as its serialised bytes, and a publisher takes bytes too. Where
rclpy's conversion of a message to Python objects costs more than the work done with it (32
correlators at 1 kHz, UWB ranges at 20 Hz per anchor), the nodes read and write the bytes with this
module instead of hand-counting offsets. Nothing here is written per message type:

* :func:`layout` walks ``MsgClass.SLOT_TYPES`` / ``get_fields_and_field_types()`` of a generated
  rosidl class (nested messages, strings, fixed arrays, bounded and unbounded sequences) once, and
  compiles the walk into a small program (:class:`CdrLayout`). Changing a ``.msg`` file and
  rebuilding ``rfi_msgs`` changes the program; no offset is written anywhere.
* One compiled walk runs any program in either direction (:func:`_walk`: alignment, runs, nesting and
  every bounds check written once): :func:`decode_program` turns CDR bytes into two flat value
  streams in wire order (``ints``: every integer, bool, sequence count and string position;
  ``floats``: every float32/float64), and :func:`encode_program` writes the bytes back from such streams.
  Adapters in the node packages give those streams names (:meth:`CdrLayout.position`,
  :meth:`CdrLayout.element`).
* :mod:`rfi_node_common.message_builder` makes fast constructors of message objects from the same
  description (for outputs that must stay Python objects).

Call the two interpreters from Python, not from a ``cache=True`` numba function of another package:
numba's cache checks only the caller's own source file, so such a caller would keep running a stale
copy of this module's code after it changes.

Format (OMG CDR version 1 as the ROS 2 middlewares write it, little endian): a 4-byte encapsulation
header ``00 01 00 00`` (CDR_LE), then the fields in declaration order, each primitive aligned to its
own size counted from the end of the encapsulation header; a string is a uint32 length (with the
terminating NUL) and the bytes; a sequence a uint32 count and the elements (an empty sequence adds
no alignment for its element type); a fixed array just its elements; a nested message its fields.
The encoder writes zeros where the middleware leaves padding uninitialised and ends at the last
field (rmw_fastrtps's buffers may carry up to 4 unused trailing bytes per empty float64 sequence,
which deserialisers ignore). Only little-endian input is decoded; anything else, and any byte string
that is cut short or malformed, is declined (None), and every read is bounds-checked first.

No rclpy import: the message classes come from the rosidl-generated packages (rosidl_parser types).
The tests check decoding and encoding byte for byte against ``rclpy.serialization`` for random
messages of every type on the nodes' hot paths, and fuzz the decoder.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from functools import cache
from typing import Any, NamedTuple

import numpy as np
from numba import njit

CDR_LE = b"\x00\x01"
"""First two bytes of a little-endian CDR payload (encapsulation kind)."""
ENCAPSULATION = b"\x00\x01\x00\x00"
"""The 4-byte encapsulation header written by :meth:`CdrLayout.encode`."""

# Opcodes of a layout program: one row [opcode, a, b, c] per operation.
OP_PRIM = 0  # a = size in bytes (1, 2, 4, 8), b = kind (KIND_*), c = count of consecutive ones (a run)
OP_STRING = 1  # a = bound in bytes (0: unbounded); streams: ints += [start in buffer, length without NUL]
OP_SEQUENCE = 2  # a = row of its OP_END, b = bound (0: unbounded); streams: ints += [count]; body once per element
OP_ARRAY = 3  # a = row of its OP_END, b = fixed count (>= 1); body once per element
OP_END = 4  # a = row of its OP_SEQUENCE / OP_ARRAY
OP_MARK = 5  # a = top-level field index: the decoder records the payload offset where that field ends

KIND_UNSIGNED = 0
KIND_SIGNED = 1
KIND_FLOAT = 2
KIND_BOOL = 3

PRIMITIVES = {
    "boolean": (1, KIND_BOOL), "octet": (1, KIND_UNSIGNED), "char": (1, KIND_UNSIGNED),
    "uint8": (1, KIND_UNSIGNED), "int8": (1, KIND_SIGNED), "uint16": (2, KIND_UNSIGNED), "int16": (2, KIND_SIGNED),
    "uint32": (4, KIND_UNSIGNED), "int32": (4, KIND_SIGNED), "uint64": (8, KIND_UNSIGNED), "int64": (8, KIND_SIGNED),
    "float": (4, KIND_FLOAT), "double": (8, KIND_FLOAT),
}
"""rosidl basic type name -> (CDR size and alignment in bytes, kind)."""

_MAX_DEPTH = 16
_ERR = -1
ENCODE_BUFFER_FULL = -2
"""Return value of :func:`encode_program` when ``out`` is too small (retry with a larger one)."""
_FULL = ENCODE_BUFFER_FULL


# ---------------------------------------------------------------- layout from the message class
@dataclass(frozen=True)
class FieldLayout:
    """One field of a message as the codec sees it.

    Attributes:
        name: field name.
        kind: 'int' (integer types, bool included), 'float', 'string', 'message', 'sequence' or 'array'.
        primitive: rosidl basic type name for 'int' / 'float' (and of the elements of a primitive
            sequence or array), else ''.
        element: layout of the element message of a 'message', or of a sequence / array of messages.
        element_kind: for 'sequence' / 'array': 'int', 'float', 'string' or 'message'.
        size: fixed count of an 'array'; bound of a bounded 'sequence' or 'string' (0: unbounded).
    """

    name: str
    kind: str
    primitive: str = ""
    element: CdrLayout | None = None
    element_kind: str = ""
    size: int = 0


@dataclass(frozen=True, eq=False)
class CdrLayout:
    """CDR layout of one message class, computed from its generated description (see :func:`layout`).

    Attributes:
        msg_class: the generated message class.
        fields: one :class:`FieldLayout` per field, in declaration (= wire) order.
        program: int64 array (n_ops, 4) run by the compiled codec.
        field_ops: row of ``program`` where each top-level field starts (``len(fields)`` entries).
    """

    msg_class: Any
    fields: tuple[FieldLayout, ...]
    program: np.ndarray
    field_ops: tuple[int, ...]

    @property
    def name(self) -> str:
        return f"{self.msg_class.__module__.split('.')[0]}/{self.msg_class.__name__}"

    def field(self, name: str) -> FieldLayout:
        """The field called ``name`` (KeyError if the message has none)."""
        for f in self.fields:
            if f.name == name:
                return f
        raise KeyError(f"{self.name} has no field {name!r}")

    def element(self, name: str) -> CdrLayout:
        """Layout of the messages inside the message, sequence or array field ``name``."""
        f = self.field(name)
        if f.element is None:
            raise KeyError(f"{self.name}.{name} holds no messages")
        return f.element

    def entries(self) -> tuple[int, int] | None:
        """(ints, floats) stream entries of one message, or None if a sequence makes it vary."""
        n_int = n_float = 0
        for f in self.fields:
            e = _field_entries(f)
            if e is None:
                return None
            n_int, n_float = n_int + e[0], n_float + e[1]
        return n_int, n_float

    def position(self, path: str) -> tuple[int, int]:
        """(ints, floats) stream positions where the field ``path`` ('header.stamp.sec') starts.

        Raises:
            KeyError: no such field.
            ValueError: a sequence before the field makes its position vary.
        """
        head, _, rest = path.partition(".")
        n_int = n_float = 0
        for f in self.fields:
            if f.name == head:
                if not rest:
                    return n_int, n_float
                if f.kind != "message" or f.element is None:
                    raise KeyError(f"{self.name}.{head} is not a message")
                i, j = f.element.position(rest)
                return n_int + i, n_float + j
            e = _field_entries(f)
            if e is None:
                raise ValueError(f"{self.name}.{f.name} (a sequence) comes before {path!r}: its position varies")
            n_int, n_float = n_int + e[0], n_float + e[1]
        raise KeyError(f"{self.name} has no field {head!r}")

    def decode(self, raw: bytes, *, strict_strings: bool = True) -> DecodedCdr | None:
        """CDR bytes -> value streams, or None if not little-endian CDR of this message or malformed.

        Args:
            raw: the serialised message (encapsulation header included).
            strict_strings: also decline a string with a NUL before its terminating one (rclpy reads
                such a string only up to its first NUL, so a decoder that turns it into text would differ).

        Returns:
            :class:`DecodedCdr`; never raises and never reads outside ``raw``, whatever it holds.
        """
        if len(raw) < 4 or raw[:2] != CDR_LE:
            return None
        buf = np.frombuffer(raw, dtype=np.uint8)
        ints = np.empty(len(raw) + 8, dtype=np.int64)  # every int entry consumes >= 1 byte (a string 2 per 5)
        floats = np.empty(len(raw) // 4 + 1)
        marks = np.zeros(len(self.fields), dtype=np.int64)
        counts = np.zeros(2, dtype=np.int64)
        if decode_program(self.program, buf, ints, floats, marks, counts, strict_strings) < 0:
            return None
        return DecodedCdr(ints[:counts[0]], floats[:counts[1]], marks)

    def encode(self, ints: np.ndarray, floats: np.ndarray, text: bytes = b"", *, prefix: bytes = b"",
               after: str | None = None) -> bytes:
        """Value streams -> CDR bytes (the inverse of :meth:`decode`).

        Args:
            ints: int64 stream (integers, bools as 0/1, sequence counts, strings as [start, length]
                into ``text``), in wire order.
            floats: float64 stream, in wire order (float32 fields are rounded).
            text: the bytes the strings point into (UTF-8, without NULs).
            prefix: encapsulation header and the serialised top-level fields up to and including
                ``after``, copied verbatim (e.g. the header of an input message); the streams then
                start at the field after it.
            after: name of the last top-level field in ``prefix``.

        Returns:
            The serialised message.

        Raises:
            ValueError: streams shorter than the layout needs, a negative count, a string outside
                ``text``, a count above a bound.
        """
        start = 0
        if after is not None:
            start = self.field_ops[[f.name for f in self.fields].index(after) + 1] \
                if after != self.fields[-1].name else self.program.shape[0]
            if len(prefix) < 4:
                raise ValueError("prefix must hold the encapsulation header")
        elif prefix:
            raise ValueError("prefix needs the name of its last field (after=...)")
        head = np.frombuffer(prefix or ENCAPSULATION, dtype=np.uint8)
        ints = np.ascontiguousarray(ints, dtype=np.int64)
        floats = np.ascontiguousarray(floats, dtype=np.float64)
        if not (ints.flags.writeable and floats.flags.writeable):  # the one walk types its streams writable
            ints, floats = ints.copy(), floats.copy()
        chars = np.frombuffer(text, dtype=np.uint8)
        raw = encode_bytes(self.program, start, head, ints, floats, chars,
                           head.size + 16 * (ints.size + floats.size) + chars.size + 64)
        if raw is None:
            raise ValueError(f"value streams do not fit the layout of {self.name}")
        return raw


def encode_bytes(program: np.ndarray, start: int, head: np.ndarray, ints: np.ndarray, floats: np.ndarray,
                 text: np.ndarray, size: int) -> bytes | None:
    """:func:`encode_program` into a zeroed buffer of ``size`` bytes, doubled until the message fits.

    Returns:
        The serialised bytes, or None if the streams do not fit the program (too short, a negative
        count, a string outside ``text``, a bound exceeded).
    """
    while True:
        out = np.zeros(size, dtype=np.uint8)
        end = encode_program(program, start, head, ints, floats, text, out)
        if end != _FULL:
            break
        size *= 2
    return None if end < 0 else out[:end].tobytes()


class DecodedCdr(NamedTuple):
    """Value streams of one decoded message (see :meth:`CdrLayout.decode`).

    Attributes:
        ints: int64, every integer / bool / sequence count / string [start, length] in wire order
            (a string's start is its offset in the raw bytes, encapsulation included; a uint64 above
            2**63 - 1 appears as its int64 bit pattern).
        floats: float64, every float in wire order.
        marks: payload offset (after the encapsulation header) where each top-level field ends;
            ``raw[:4 + marks[k]]`` is the encapsulation and the fields up to k.
    """

    ints: np.ndarray
    floats: np.ndarray
    marks: np.ndarray


def _field_entries(f: FieldLayout) -> tuple[int, int] | None:
    if f.kind == "int":
        return 1, 0
    if f.kind == "float":
        return 0, 1
    if f.kind == "string":
        return 2, 0
    if f.kind == "message":
        assert f.element is not None
        return f.element.entries()
    if f.kind == "array":
        one = _element_entries(f)
        return None if one is None else (one[0] * f.size, one[1] * f.size)
    return None


def _element_entries(f: FieldLayout) -> tuple[int, int] | None:
    if f.element_kind == "message":
        assert f.element is not None
        return f.element.entries()
    return {"int": (1, 0), "float": (0, 1), "string": (2, 0)}[f.element_kind]


def message_class(t: Any) -> Any:
    """The generated class of a rosidl_parser NamespacedType (e.g. std_msgs/msg/Header)."""
    module = importlib.import_module(".".join(t.namespaces))
    return getattr(module, t.name)


def _nestable(t: Any) -> tuple[str, str, CdrLayout | None, int]:
    """(kind, primitive, element layout, string bound) of a rosidl nestable type."""
    cls = type(t).__name__
    if cls == "BasicType":
        if t.typename not in PRIMITIVES:
            raise NotImplementedError(f"CDR codec: basic type {t.typename!r} is not supported")
        return ("float" if PRIMITIVES[t.typename][1] == KIND_FLOAT else "int"), t.typename, None, 0
    if cls in ("UnboundedString", "BoundedString"):
        return "string", "", None, int(getattr(t, "maximum_size", 0))
    if cls == "NamespacedType":
        return "message", "", layout(message_class(t)), 0
    raise NotImplementedError(f"CDR codec: type {cls} is not supported (wide strings)")


def _emit(rows: list[list[int]], kind: str, primitive: str, element: CdrLayout | None, bound: int) -> None:
    if kind in ("int", "float"):
        size, k = PRIMITIVES[primitive]
        rows.append([OP_PRIM, size, k, 1])
    elif kind == "string":
        rows.append([OP_STRING, bound, 0, 0])
    else:
        assert element is not None
        base = len(rows)
        for r in element.program:
            a = int(r[1])
            if r[0] in (OP_SEQUENCE, OP_ARRAY, OP_END):
                a += base  # jump targets are rows of the program: shift them with the inlined body
            rows.append([int(r[0]), a, int(r[2]), int(r[3])])
        # inner marks would overwrite the outer ones: nested messages keep none
        rows[base:] = [r for r in rows[base:] if r[0] != OP_MARK]
        _retarget(rows, base)


def _retarget(rows: list[list[int]], base: int) -> None:
    """Recompute the jump targets of rows[base:] after rows were removed (pairs matched by nesting)."""
    stack: list[int] = []
    for i in range(base, len(rows)):
        if rows[i][0] in (OP_SEQUENCE, OP_ARRAY):
            stack.append(i)
        elif rows[i][0] == OP_END:
            begin = stack.pop()
            rows[begin][1] = i
            rows[i][1] = begin


@cache
def layout(msg_class: Any) -> CdrLayout:
    """The CDR layout of a generated rosidl message class (computed once per class).

    Args:
        msg_class: e.g. ``rfi_msgs.msg.CorrelatorArray``.

    Returns:
        Its :class:`CdrLayout`, from ``get_fields_and_field_types()`` (names) and ``SLOT_TYPES``
        (rosidl_parser types) of the class and, recursively, of every nested message class.

    Raises:
        NotImplementedError: a wide string or a ``long double`` (not used by the suite).
    """
    names = list(msg_class.get_fields_and_field_types())
    slot_types = msg_class.SLOT_TYPES
    if len(names) != len(slot_types):
        raise ValueError(f"{msg_class.__name__}: field names and SLOT_TYPES disagree")
    rows: list[list[int]] = []
    fields: list[FieldLayout] = []
    field_ops: list[int] = []
    for index, (name, t) in enumerate(zip(names, slot_types, strict=True)):
        field_ops.append(len(rows))
        cls = type(t).__name__
        if cls in ("Array", "BoundedSequence", "UnboundedSequence"):
            kind, primitive, element, bound = _nestable(t.value_type)
            if cls == "Array":
                n = int(t.size)
                rows.append([OP_ARRAY, 0, n, 0])
                fields.append(FieldLayout(name, "array", primitive, element, kind, n))
            else:
                n = int(getattr(t, "maximum_size", 0))
                rows.append([OP_SEQUENCE, 0, n, 0])
                fields.append(FieldLayout(name, "sequence", primitive, element, kind, n))
            begin = len(rows) - 1
            _emit(rows, kind, primitive, element, bound)
            rows.append([OP_END, begin, 0, 0])
            rows[begin][1] = len(rows) - 1
        else:
            kind, primitive, element, bound = _nestable(t)
            _emit(rows, kind, primitive, element, bound)
            fields.append(FieldLayout(name, kind, primitive, element, size=bound))
        _retarget(rows, 0)
        rows.append([OP_MARK, index, 0, 0])
    rows = _compact(rows)
    field_ops = [0] + [i + 1 for i, r in enumerate(rows) if r[0] == OP_MARK][:-1]
    program = np.array(rows, dtype=np.int64).reshape(-1, 4)
    return CdrLayout(msg_class, tuple(fields), program, tuple(field_ops))


def _compact(rows: list[list[int]]) -> list[list[int]]:
    """Merge consecutive primitives of one size and kind into one run (a fixed array of primitives
    included): the first one aligned makes the others aligned, so a run is aligned and bounds-checked
    once. Marks (top-level field ends) are kept, so runs never cross them."""
    out: list[list[int]] = []
    for r in rows:
        r = list(r)
        if r[0] == OP_END and len(out) >= 2 and out[-2][0] == OP_ARRAY and out[-1][0] == OP_PRIM:
            prim, array = out.pop(), out.pop()
            r = [OP_PRIM, prim[1], prim[2], prim[3] * array[2]]
        if r[0] == OP_PRIM and out and out[-1][0] == OP_PRIM and out[-1][1:3] == r[1:3]:
            out[-1][3] += r[3]
        else:
            out.append(r)
    _retarget(out, 0)
    return out


# ---------------------------------------------------------------- compiled interpreters
@njit(cache=True)
def _align(o, size):
    """Absolute offset ``o`` aligned to ``size`` counted from the end of the 4-byte encapsulation."""
    return 4 + ((o - 4 + size - 1) & ~(size - 1))  # sizes are powers of two


@njit(cache=True)
def _read_uint(buf, o, size):
    v = np.int64(0)
    for m in range(size):
        v |= np.int64(buf[o + m]) << (8 * m)
    return v


@njit(cache=True)
def _write_uint(out, o, size, v):
    for m in range(size):
        out[o + m] = (v >> (8 * m)) & 0xFF


@njit(cache=True, inline="always")
def _move_primitives(write, size, kind, count, src, dst, o, n, ints, floats, ni, nf, b8, tmp8, b4, tmp4):
    """_walk's leaf for a run of ``count`` primitives of ``size`` bytes and ``kind``: reads them from ``src`` into the
    streams or writes them from the streams into ``dst``, from offset ``o`` (aligned here). Returns (status, offset,
    ints used, floats used); status 0, or _walk's failure code."""
    o = _align(o, size)
    if o + size * count > n:
        return (_FULL if write else _ERR), o, ni, nf
    if kind == KIND_FLOAT:
        if nf + count > floats.shape[0]:
            return _ERR, o, ni, nf
        if write:
            for _ in range(count):
                if size == 8:
                    tmp8[0] = floats[nf]
                    for m in range(8):
                        dst[o + m] = b8[m]
                else:
                    tmp4[0] = floats[nf]
                    for m in range(4):
                        dst[o + m] = b4[m]
                nf += 1
                o += size
        else:
            for _ in range(count):
                if size == 8:
                    for m in range(8):
                        b8[m] = src[o + m]
                    floats[nf] = tmp8[0]
                else:
                    for m in range(4):
                        b4[m] = src[o + m]
                    floats[nf] = tmp4[0]
                nf += 1
                o += size
        return 0, o, ni, nf
    if ni + count > ints.shape[0]:
        return _ERR, o, ni, nf
    if write:
        for _ in range(count):
            v = ints[ni]
            _write_uint(dst, o, size, (1 if v != 0 else 0) if kind == KIND_BOOL else v)
            ni += 1
            o += size
    else:
        for _ in range(count):
            v = _read_uint(src, o, size)
            if kind == KIND_SIGNED and size < 8 and v >= np.int64(1) << (8 * size - 1):
                v -= np.int64(1) << (8 * size)
            elif kind == KIND_BOOL and v > 1:
                return _ERR, o, ni, nf
            ints[ni] = v
            ni += 1
            o += size
    return 0, o, ni, nf


@njit(cache=True, inline="always")
def _move_string(write, bound, src, dst, o, n, ints, text, ni, strict_strings):
    """_walk's leaf for a string: [start, length without NUL] in ints <-> uint32 length with NUL, bytes, NUL.
    Returns (status, offset after it, ints used); status 0, or _walk's failure code."""
    if write:
        if ni + 2 > ints.shape[0]:
            return _ERR, o, ni
        first = ints[ni]
        length = ints[ni + 1]
        if first < 0 or length < 0 or first + length > text.shape[0] or (bound > 0 and length > bound):
            return _ERR, o, ni
        o = _align(o, 4)
        if o + 5 + length > n:
            return _FULL, o, ni
        _write_uint(dst, o, 4, length + 1)
        for m in range(length):
            dst[o + 4 + m] = text[first + m]
        dst[o + 4 + length] = 0
    else:
        o = _align(o, 4)
        if o + 4 > n:
            return _ERR, o, ni
        length = _read_uint(src, o, 4) - 1
        if length < 0 or length + 1 > n - o - 4 or src[o + 4 + length] != 0 or (bound > 0 and length > bound):
            return _ERR, o, ni
        if strict_strings:
            for m in range(length):
                if src[o + 4 + m] == 0:
                    return _ERR, o, ni
        if ni + 2 > ints.shape[0]:
            return _ERR, o, ni
        ints[ni] = o + 4
        ints[ni + 1] = length
    return 0, o + 5 + length, ni + 2


@njit(cache=True, inline="always")
def _move_count(write, bound, src, dst, o, n, ints, ni):
    """_walk's leaf for a sequence's uint32 element count <-> ints. Returns (status, count, offset after it, ints
    used); status 0, or _walk's failure code."""
    o = _align(o, 4)
    if write:
        if ni >= ints.shape[0]:
            return _ERR, 0, o, ni
        count = ints[ni]
        if count < 0 or count >= 2**32 or (bound > 0 and count > bound):
            return _ERR, count, o, ni
        if o + 4 > n:
            return _FULL, count, o, ni
        _write_uint(dst, o, 4, count)
    else:
        if o + 4 > n:
            return _ERR, 0, o, ni
        count = _read_uint(src, o, 4)
        if (bound > 0 and count > bound) or ni >= ints.shape[0]:
            return _ERR, count, o, ni
        ints[ni] = count
    return 0, count, o + 4, ni + 1


@njit(cache=True, inline="always")
def _walk(write, program, pc, src, dst, o, ints, floats, text, marks, strict_strings):
    """The one walk of a layout program, for both directions: from row ``pc`` and byte offset ``o``, read
    the bytes ``src`` into the streams (``write`` False), or write the streams into the bytes ``dst``
    (``write`` True). Alignment, runs, nesting and every bounds and stream check are written once here and in
    its three leaves (``_move_primitives``, ``_move_string``, ``_move_count``), each for both directions. The
    other byte array is not touched (two arrays, not one: the bytes read are often read-only).

    Returns (end offset, ints used, floats used), the offset negative on failure: -1 for bytes that are
    malformed (reading) or streams that do not fit the program (writing), -2 for a ``dst`` too small
    (writing; reading, bytes too short are malformed). Every access to the bytes is bounds-checked first.
    """
    n = dst.shape[0] if write else src.shape[0]
    ni = 0
    nf = 0
    left = np.zeros(_MAX_DEPTH, dtype=np.int64)
    depth = 0
    tmp8 = np.empty(1, dtype=np.float64)
    b8 = tmp8.view(np.uint8)
    tmp4 = np.empty(1, dtype=np.float32)
    b4 = tmp4.view(np.uint8)
    n_ops = program.shape[0]
    while pc < n_ops:
        op = program[pc, 0]
        if op == OP_PRIM:
            status, o, ni, nf = _move_primitives(write, program[pc, 1], program[pc, 2], program[pc, 3], src, dst, o,
                                                 n, ints, floats, ni, nf, b8, tmp8, b4, tmp4)
            if status != 0:
                return status, ni, nf
        elif op == OP_STRING:
            status, o, ni = _move_string(write, program[pc, 1], src, dst, o, n, ints, text, ni, strict_strings)
            if status != 0:
                return status, ni, nf
        elif op == OP_SEQUENCE or op == OP_ARRAY:
            if op == OP_SEQUENCE:
                status, count, o, ni = _move_count(write, program[pc, 2], src, dst, o, n, ints, ni)
                if status != 0:
                    return status, ni, nf
                if count == 0:
                    pc = program[pc, 1] + 1
                    continue
                if count > n - o and not write:  # reading: every element takes at least one byte
                    return _ERR, ni, nf
            else:
                count = program[pc, 2]
            if depth >= _MAX_DEPTH:
                return _ERR, ni, nf
            left[depth] = count
            depth += 1
        elif op == OP_END:
            left[depth - 1] -= 1
            if left[depth - 1] > 0:
                pc = program[pc, 1] + 1
                continue
            depth -= 1
        elif op == OP_MARK and not write:
            marks[program[pc, 1]] = o - 4
        pc += 1
    return o, ni, nf


@njit(cache=True)
def decode_program(program, buf, ints, floats, marks, counts, strict_strings):
    """Run a layout program over CDR bytes ``buf`` (encapsulation included): fill the streams.

    Writes counts = [entries in ints, entries in floats] and marks (payload offsets where the top-level
    fields end). Returns 0, or -1 if the bytes are too short for what they announce, a string is not a
    CDR string (length >= 1 with its terminating NUL; with strict_strings no NUL inside), a bool byte
    is not 0 or 1, a count exceeds its bound or the bytes left, or the streams would overflow. Every
    read is bounds-checked first: any byte string gives 0 or -1, never a read outside buf.
    """
    end, ni, nf = _walk(False, program, 0, buf, marks.view(np.uint8)[:0], 4, ints, floats, buf[:0], marks,
                        strict_strings)
    if end < 0:
        return _ERR
    counts[0] = ni
    counts[1] = nf
    return 0


@njit(cache=True)
def encode_program(program, start, head, ints, floats, text, out):
    """Write ``head`` (encapsulation + any verbatim prefix) then run the program from row ``start`` over
    the streams into ``out`` (zeroed). Returns the end offset, -2 if ``out`` is too small, -1 if the
    streams do not fit the program (too short, negative count, string outside text, bound exceeded)."""
    if head.shape[0] > out.shape[0]:
        return _FULL
    for m in range(head.shape[0]):
        out[m] = head[m]
    out[0] = 0
    out[1] = 1
    out[2] = 0
    out[3] = 0
    end, _, _ = _walk(True, program, start, head, out, head.shape[0], ints, floats, text, ints[:0], False)
    return end


CODEC_KERNELS = ("_align", "_read_uint", "_write_uint", "_move_primitives", "_move_string", "_move_count", "_walk",
                 "decode_program", "encode_program")
"""The compiled functions of the codec, by name: a test swaps each for its ``py_func`` (numpy indexing
raises on any access out of bounds) to check that the compiled ones never read outside the bytes."""
