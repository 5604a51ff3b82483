"""Seeded generators of hostile input messages for the fuzz tests (test_fuzz_nodes.py).

Each generator starts from real messages of a stored bag (valid templates) and makes one hostile
message per call, as the serialised bytes a publisher would send:

* ``garbage``: random bytes of random length (including empty and the 4-byte encapsulation alone);
* ``truncated``: a valid message cut short;
* ``flipped``: a valid message with random bytes overwritten after its header (the stamp is not
  touched, so that a flip cannot move a node's time line by a plausible amount);

  (these two and ``field`` start from the latest valid message, stamped 1 us after it);
* ``field``: a valid message with one field set to a hostile value (NaN, +-inf, 1e300, 5e-324,
  0, negative, integer extremes, empty or duplicated arrays, garbage strings);
* ``stamp``: a valid message with a hostile header stamp (0, negative, far future, far past,
  the latest valid stamp again);
* ``duplicate``: the latest valid message again, byte for byte;
* plus the explicit faults of issue 12 for each topic (:func:`issue_faults`).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
from rclpy.serialization import serialize_message

FLOATS = (math.nan, math.inf, -math.inf, 1e300, -1e300, 5e-324, -5e-324, 0.0, -1.0, 1e150, -1e9, 1e9)
STRINGS = ('', 'x' * 300, '\u00e9\u00e8\u2603', 'earth\x00junk')
HOSTILE_STAMPS_S = (0, -1, -2**31, 2**31 - 1, 1, 10**9 * 2)
"""Header seconds: unset, negative, int32 extremes, 1 s after the epoch (far past), 2033 (far future)."""

INT_RANGES = {
    'uint8': (0, 255), 'int8': (-128, 127), 'uint16': (0, 65535), 'int16': (-32768, 32767),
    'uint32': (0, 2**32 - 1), 'int32': (-2**31, 2**31 - 1), 'uint64': (0, 2**64 - 1), 'int64': (-2**63, 2**63 - 1),
}


def leaf_fields(msg: Any, prefix: tuple = ()) -> list[tuple[tuple, str]]:
    """(path, type) of every scalar or sequence field of ``msg`` except the header, recursively.

    A path is a tuple of attribute names and list indices.
    """
    out = []
    for name, ftype in msg.get_fields_and_field_types().items():
        if name == 'header':
            continue
        value = getattr(msg, name)
        if hasattr(value, 'get_fields_and_field_types'):
            out.extend(leaf_fields(value, prefix + (name,)))
        elif ftype.startswith('sequence<') and ftype[9:-1] not in INT_RANGES and ftype[9:-1] not in (
                'double', 'float', 'boolean', 'octet', 'string'):
            out.append((prefix + (name,), 'elements'))
            for i, element in enumerate(value):
                out.extend(leaf_fields(element, prefix + (name, i)))
        else:
            out.append((prefix + (name,), ftype))
    return out


def _get(msg: Any, path: tuple) -> Any:
    for step in path:
        msg = msg[step] if isinstance(step, int) else getattr(msg, step)
    return msg


def _set(msg: Any, path: tuple, value: Any) -> None:
    parent = _get(msg, path[:-1])
    if isinstance(path[-1], int):
        parent[path[-1]] = value
    else:
        setattr(parent, path[-1], value)


def hostile_value(ftype: str, current: Any, rng: np.random.Generator) -> list[Any]:
    """Candidate hostile values for a field of ROS type ``ftype`` (first that the setter takes wins)."""
    if ftype in ('double', 'float'):
        return [FLOATS[rng.integers(len(FLOATS))], math.inf]
    if ftype in INT_RANGES:
        lo, hi = INT_RANGES[ftype]
        values = (lo, hi, 0, 1, hi // 2)
        return [values[int(rng.integers(len(values)))]]
    if ftype == 'boolean':
        return [not current]
    if ftype == 'string':
        return [STRINGS[rng.integers(len(STRINGS))]]
    if ftype == 'elements':
        n = len(current)
        choice = rng.integers(3)
        if choice == 0 or n == 0:
            return [[]]
        if choice == 1:
            return [list(current) + [copy.deepcopy(current[rng.integers(n)])]]
        return [list(current)[: rng.integers(n)]]
    if ftype.startswith('sequence<'):
        n = len(current)
        choice = rng.integers(4)
        if choice == 0:
            return [[] if ftype != 'sequence<uint8>' else b'']
        if choice == 1 and ftype == 'sequence<uint8>':
            return [bytes(n)]  # all zero
        if choice == 2 and ftype == 'sequence<uint8>':
            return [bytes(current)[: max(1, n // 3) | 1]]  # short and odd
        if ftype == 'sequence<double>':
            return [[math.nan] * max(n, 1)]
        return [bytes(rng.integers(0, 256, size=n, dtype=np.uint8).tobytes())]
    return []


def mutate_field(template: Any, rng: np.random.Generator) -> Any:
    """A deep copy of ``template`` with one non-header field set to a hostile value."""
    msg = copy.deepcopy(template)
    fields = leaf_fields(msg)
    for _ in range(10):
        path, ftype = fields[rng.integers(len(fields))]
        for value in hostile_value(ftype, _get(msg, path), rng):
            try:
                _set(msg, path, value)
                return msg
            except (AssertionError, TypeError, ValueError, OverflowError):
                continue
    return msg


def with_stamp(template: Any, sec: int, nanosec: int = 0) -> Any:
    msg = copy.deepcopy(template)
    msg.header.stamp.sec = int(sec)
    msg.header.stamp.nanosec = int(nanosec)
    return msg


def header_end(raw: bytes) -> int:
    """Byte offset of the end of the header (encapsulation, stamp, frame_id) in a serialised message."""
    n = int.from_bytes(raw[12:16], 'little')
    return 16 + n


class HostileStream:
    """Yields ``(kind, raw_bytes)`` hostile messages for one topic, from valid templates.

    Args:
        templates: valid messages of the topic (message objects), in stamp order.
        rng: the seeded generator.
        faults: explicit faults for this topic, ``(message, keep_stamp)`` (:func:`issue_faults`), sent first;
            those without ``keep_stamp`` are stamped just after the latest valid message.
    """

    KINDS = ('garbage', 'truncated', 'flipped', 'field', 'field', 'field', 'stamp', 'duplicate')

    def __init__(self, templates: list[Any], rng: np.random.Generator, faults: list[Any] = ()) -> None:
        self.templates = templates
        self.rng = rng
        self.faults = list(faults)
        self._raw = [serialize_message(t) for t in templates]
        self._latest: Any = None
        self._step = 0

    def _base(self, template: Any, latest_valid: Any | None) -> Any:
        if latest_valid is not self._latest:
            self._latest, self._step = latest_valid, 0
        return latest_valid if latest_valid is not None else template

    def newer(self, msg: Any) -> Any:
        """``msg`` stamped 1 us after the previous hostile message since the latest valid one, so that a
        hostile field is judged on its value, not refused for its stamp (valid messages are >= 1 ms apart)."""
        self._step += 1
        ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec + 1000 * self._step
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 1_000_000_000)
        return msg

    def _template(self) -> tuple[Any, bytes]:
        i = int(self.rng.integers(len(self.templates)))
        return self.templates[i], self._raw[i]

    def make(self, kind: str, latest_valid: Any | None) -> bytes:
        rng = self.rng
        template, raw = self._template()
        if kind == 'garbage':
            n = int(rng.choice([1, 3, 4, 8, 16, 40, 200, 1000]))  # never empty: the middleware drops 0 bytes
            head = b'\x00\x01\x00\x00' if rng.random() < 0.5 else b''
            return head + rng.integers(0, 256, size=n, dtype=np.uint8).tobytes()
        if kind in ('truncated', 'flipped'):  # built on the latest valid message, stamped just after it
            raw = serialize_message(self.newer(copy.deepcopy(self._base(template, latest_valid))))
        if kind == 'truncated':
            return raw[: int(rng.integers(1, len(raw)))]
        if kind == 'flipped':
            start = header_end(raw)
            if start >= len(raw):
                return raw[:-1]
            buf = bytearray(raw)
            for _ in range(int(rng.integers(1, 6))):
                buf[int(rng.integers(start, len(buf)))] = int(rng.integers(256))
            return bytes(buf)
        if kind == 'field':
            return serialize_message(self.newer(mutate_field(self._base(template, latest_valid), rng)))
        if kind == 'stamp':
            base = self._base(template, latest_valid)
            choice = int(rng.integers(len(HOSTILE_STAMPS_S) + 1))
            if choice == len(HOSTILE_STAMPS_S):
                return serialize_message(base)  # the latest valid stamp again
            return serialize_message(with_stamp(base, HOSTILE_STAMPS_S[choice], int(rng.integers(10**9))))
        if kind == 'duplicate':
            return serialize_message(latest_valid if latest_valid is not None else template)
        raise ValueError(kind)

    def messages(self, count: int, latest_valid: Callable[[], Any | None]) -> Iterator[tuple[str, bytes]]:
        """``count`` hostile messages (the explicit faults first)."""
        for fault, keep_stamp in self.faults[:count]:
            if not keep_stamp:
                self._base(fault, latest_valid())
                fault = self.newer(copy.deepcopy(fault))
            yield 'issue_fault', serialize_message(fault)
        for _ in range(count - min(count, len(self.faults))):
            kind = self.KINDS[int(self.rng.integers(len(self.KINDS)))]
            yield kind, self.make(kind, latest_valid())


def issue_faults(topic: str, template: Any) -> list[tuple[Any, bool]]:
    """The faults that issue 12 lists for ``topic``, built on ``template`` (the latest valid message sent):
    ``(message, keep_stamp)``, keep_stamp False for a fault in a value (stamped newer when sent)."""
    t = copy.deepcopy
    out = []
    if topic == '/rfi/if_samples':
        out.append((with_stamp(template, -5), True))
        out.append((with_stamp(template, 2**31 - 1), True))  # far future: must not stall the node
        zero = t(template)
        zero.samples = bytes(len(template.samples))
        out.append((zero, False))
        for scale in (5e-324, 1e150, 1e308):
            m = t(template)
            m.scale = scale
            out.append((m, False))
        m = t(template)
        m.first_sample_index = 2**63
        out.append((m, False))
        m = t(template)
        m.first_sample_index = 2**64 - 1
        out.append((m, False))
    elif topic == '/gnss/correlators':
        out.append((with_stamp(template, -5), True))
        out.append((with_stamp(template, 2**31 - 1), True))
        for field, value in (('integration_time_s', 1e6), ('in_phase', 1e300), ('quadrature', -1e300),
                             ('integration_time_s', 0.0), ('integration_time_s', -0.001), ('in_phase', math.nan),
                             ('cn0_dbhz', 1e300), ('predicted_phase_change_rad', math.inf),
                             ('carrier_lock', 255)):  # a lock code this version does not know: counted as unknown
            m = t(template)
            for c in m.correlators:
                setattr(c, field, value)
            out.append((m, False))
    elif topic == '/uwb/ranges':
        for std in (-math.inf, math.inf, -1.0, 0.0):
            m = t(template)
            m.range_std_m = std
            out.append((m, False))
        out.append((t(template), True))  # an exact duplicate (the template was sent as valid before)
    elif topic == '/gnss/measurements':
        out.append((t(template), True))  # an exact duplicate epoch
        out.append((with_stamp(template, -5), True))
    elif topic == '/rfi/jammer_state':
        m = t(template)
        m.type = 200
        out.append((m, False))
        m = t(template)
        m.type = 2
        m.jammer_to_signal_db = math.inf
        out.append((m, False))
    return out
