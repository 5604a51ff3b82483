"""rfi_msgs/CorrelatorArray serialised with numpy (pure: no rclpy), for the node's publish path.

Building one ``Correlator`` message object per channel per millisecond (each field set through the generated
class's checked setters) and having rclpy convert them back cost the node ~0.3 s of CPU per second of a 12-channel
stream (docs/gnss_correlator/live_stream.md); rclpy's ``Publisher.publish`` also takes the serialised message as
bytes, which this module writes from the interval's arrays with a few numpy assignments. The bytes are those of
``rclpy.serialization.serialize_message`` on the message built field by field (tested byte for byte: the node's
``correlator_array`` stays the reference).

Layout (OMG CDR version 1, little endian, as the ROS 2 middlewares write it): a 4-byte encapsulation header
``00 01 00 00``, then the fields in order, each aligned to its size (at most 8) counted from the end of that
header; a string is a uint32 length (with the terminating NUL), its bytes and the NUL; a sequence a uint32 count
and its elements. CorrelatorArray: ``header.stamp.sec`` int32, ``header.stamp.nanosec`` uint32,
``header.frame_id`` string, ``correlators`` sequence of Correlator: ``constellation`` uint8, ``svid`` uint16,
the five float64 (``integration_time_s``, ``in_phase``, ``quadrature``, ``cn0_dbhz``,
``predicted_phase_change_rad``), ``carrier_lock`` uint8. Within the sequence, the float64 block of element k
starts at ``F_0 + 48 k``; no padding is written after the last byte (as rclpy's own serialisation). Padding bytes
are zero here; Fast CDR leaves whatever its buffer held in them (readers skip them), so the comparison with rclpy's
bytes is made on the fields' bytes (:meth:`CorrelatorArrayWriter.field_bytes`) and on the decoded message.
"""

from __future__ import annotations

import numpy as np

ENCAPSULATION = b'\x00\x01\x00\x00'
"""CDR_LE encapsulation header (representation identifier 0x0001, options 0)."""
_ELEMENT_STRIDE = 48
"""Bytes from one Correlator's float64 block to the next's (after the first element)."""
_FLOATS = 5
"""float64 fields of a Correlator, in their order."""


def _align(offset: int, size: int) -> int:
    return (offset + size - 1) // size * size


class CorrelatorArrayWriter:
    """Serialises CorrelatorArrays of one ``frame_id`` (its header bytes computed once).

    Args:
        frame_id: ``header.frame_id`` of every message.
    """

    def __init__(self, frame_id: str) -> None:
        name = frame_id.encode('utf-8') + b'\x00'
        self.frame_id = frame_id
        # offsets from the end of the encapsulation header
        self._name = np.frombuffer(np.uint32(len(name)).astype('<u4').tobytes() + name, dtype=np.uint8)
        self._count_at = _align(8 + self._name.size, 4)
        first = self._count_at + 4  # the first Correlator's constellation
        self._first_svid = first + 2
        self._first_floats = _align(first + 4, 8)

    def serialize(self, stamp_ns: int, constellation: int, svid: np.ndarray, floats: np.ndarray,
                  carrier_lock: np.ndarray) -> bytes:
        """The serialised CorrelatorArray (module docstring).

        Args:
            stamp_ns: ``header.stamp``, ns (>= 0).
            constellation: ``Correlator.constellation`` of every element (uint8).
            svid: ``svid`` per element, shape (n,) (uint16 values).
            floats: per element ``integration_time_s, in_phase, quadrature, cn0_dbhz,
                predicted_phase_change_rad``, shape (n, 5).
            carrier_lock: ``carrier_lock`` per element, shape (n,) (uint8 values).

        Raises:
            ValueError: shapes that do not agree, or a value outside its field's type.
        """
        svid = np.asarray(svid)
        floats = np.asarray(floats, dtype=np.float64)
        carrier_lock = np.asarray(carrier_lock)
        n = svid.size
        if svid.shape != (n,) or floats.shape != (n, _FLOATS) or carrier_lock.shape != (n,):
            raise ValueError(f'shapes do not agree: svid {svid.shape}, floats {floats.shape}, '
                             f'carrier_lock {carrier_lock.shape}')
        if n and (svid.min() < 0 or svid.max() > 0xFFFF or carrier_lock.min() < 0 or carrier_lock.max() > 0xFF):
            raise ValueError('svid must fit uint16 and carrier_lock uint8')
        if not 0 <= constellation <= 0xFF:
            raise ValueError(f'constellation must fit uint8, got {constellation}')
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        if not 0 <= sec < 2 ** 31:
            raise ValueError(f'stamp out of the int32 seconds range: {stamp_ns} ns')
        h = len(ENCAPSULATION)
        if n:
            last_floats = self._first_floats + (n - 1) * _ELEMENT_STRIDE
            size = last_floats + 8 * _FLOATS + 1
        else:
            size = self._count_at + 4
        buf = np.zeros(h + size, dtype=np.uint8)
        buf[:h] = np.frombuffer(ENCAPSULATION, dtype=np.uint8)
        buf[h:h + 8] = np.frombuffer(np.array([sec, nanosec], dtype='<u4').tobytes(), dtype=np.uint8)
        buf[h + 8:h + 8 + self._name.size] = self._name
        np.ndarray((1,), dtype='<u4', buffer=buf, offset=h + self._count_at)[0] = n
        if n:
            f0 = h + self._first_floats
            np.ndarray((n, _FLOATS), dtype='<f8', buffer=buf, offset=f0, strides=(_ELEMENT_STRIDE, 8))[:] = floats
            np.ndarray((n,), dtype=np.uint8, buffer=buf, offset=f0 + 8 * _FLOATS,
                       strides=(_ELEMENT_STRIDE,))[:] = carrier_lock
            # element 0's constellation and svid follow the sequence count, the others' the previous element
            buf[h + self._count_at + 4] = constellation
            np.ndarray((1,), dtype='<u2', buffer=buf, offset=h + self._first_svid)[0] = svid[0]
            if n > 1:
                np.ndarray((n - 1,), dtype=np.uint8, buffer=buf, offset=f0 + 8 * _FLOATS + 1,
                           strides=(_ELEMENT_STRIDE,))[:] = constellation
                np.ndarray((n - 1,), dtype='<u2', buffer=buf, offset=f0 + 8 * _FLOATS + 2,
                           strides=(_ELEMENT_STRIDE,))[:] = svid[1:]
        return buf.tobytes()

    def field_bytes(self, n: int) -> np.ndarray:
        """Which bytes of a message of ``n`` correlators belong to a field (the encapsulation header included),
        not to alignment padding, bool, shape (len,)."""
        size = len(self.serialize(0, 0, np.zeros(n, np.int64), np.zeros((n, _FLOATS)), np.zeros(n, np.int64)))
        mask = np.zeros(size, dtype=bool)
        h = len(ENCAPSULATION)
        mask[:h + 8 + self._name.size] = True
        mask[h + self._count_at:h + self._count_at + 5] = True  # the count, element 0's constellation
        if n:
            mask[h + self._first_svid:h + self._first_svid + 2] = True
            for k in range(n):
                f = h + self._first_floats + k * _ELEMENT_STRIDE
                mask[f:f + 8 * _FLOATS + 1] = True  # the floats and carrier_lock
                if k:
                    mask[f - 7:f - 4] = True  # constellation, svid
        else:
            mask[h + self._count_at + 4:] = False
        return mask
