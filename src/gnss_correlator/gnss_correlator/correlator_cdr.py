"""rfi_msgs/CorrelatorArray from a :class:`gnss_correlator.receiver.CorrelatorInterval`: built field by field
(:func:`correlator_array`, the reference) and written as bytes through the suite's CDR codec
(:mod:`rfi_node_common.cdr`; :func:`correlator_array_bytes`), the node's publish path (no rclpy).

Building one ``Correlator`` message object per channel per millisecond (each field set through the generated
class's checked setters) and having rclpy convert them back cost the node ~0.3 s of CPU per second of a 12-channel
stream under the profiler (docs/gnss_correlator/live_stream.md); rclpy's ``Publisher.publish`` also takes the
serialised message as bytes. This module only names the codec's value streams (which entry is which field, found
by field name in the layout derived from the generated class, as :mod:`imm_carrier.cdr` does for the same message
on its input side); no byte offset is written here. The codec writes zeros where Fast CDR leaves its buffer's old
bytes in the padding, so the bytes equal rclpy's serialisation of the message built field by field
(:func:`correlator_array`, below) in every field and in length (tested).
"""

from __future__ import annotations

import numpy as np

from gnss_correlator.receiver import CorrelatorInterval
from rfi_msgs.msg import Correlator, CorrelatorArray, GnssMeasurement
from rfi_node_common.cdr import layout
from rfi_node_common.stamps import ns_to_stamp

_LAYOUT = layout(CorrelatorArray)
_SEC, _ = _LAYOUT.position('header.stamp.sec')
_NANOSEC, _ = _LAYOUT.position('header.stamp.nanosec')
_FRAME_ID, _ = _LAYOUT.position('header.frame_id')  # a string: [start in the text, length]
_COUNT, _ = _LAYOUT.position('correlators')
_ELEMENT = _LAYOUT.element('correlators')
_entries = _ELEMENT.entries()
if _entries is None or _LAYOUT.fields[-1].name != 'correlators':
    raise ImportError('gnss_correlator.correlator_cdr expects CorrelatorArray = header, ..., Correlator[] '
                      'correlators with Correlator of fixed-size fields: update CorrelatorArrayWriter')
_INTS_PER_ELEMENT, _FLOATS_PER_ELEMENT = _entries
FLOAT_FIELDS = ('integration_time_s', 'in_phase', 'quadrature', 'cn0_dbhz', 'predicted_phase_change_rad')
"""The float fields of a Correlator in the column order :meth:`CorrelatorArrayWriter.serialize` takes."""
_CONSTELLATION = _ELEMENT.position('constellation')[0]
_SVID = _ELEMENT.position('svid')[0]
_CARRIER_LOCK = _ELEMENT.position('carrier_lock')[0]
_FLOAT_AT = [_ELEMENT.position(name)[1] for name in FLOAT_FIELDS]
if _FLOATS_PER_ELEMENT != len(FLOAT_FIELDS) or _INTS_PER_ELEMENT != 3:
    raise ImportError('rfi_msgs/Correlator has fields gnss_correlator.correlator_cdr does not write: name them')


class CorrelatorArrayWriter:
    """Serialises CorrelatorArrays of one ``frame_id``.

    Args:
        frame_id: ``header.frame_id`` of every message.
    """

    def __init__(self, frame_id: str) -> None:
        self.frame_id = frame_id
        self._text = frame_id.encode('utf-8')

    def serialize(self, stamp_ns: int, constellation: int, svid: np.ndarray, floats: np.ndarray,
                  carrier_lock: np.ndarray) -> bytes:
        """The serialised CorrelatorArray (little-endian CDR, encapsulation header included).

        Args:
            stamp_ns: ``header.stamp``, ns (>= 0).
            constellation: ``Correlator.constellation`` of every element (uint8).
            svid: ``svid`` per element, shape (n,) (uint16 values).
            floats: per element the fields of :data:`FLOAT_FIELDS` in that order, shape (n, 5).
            carrier_lock: ``carrier_lock`` per element, shape (n,) (uint8 values).

        Raises:
            ValueError: shapes that do not agree, or a value outside its field's type.
        """
        svid = np.asarray(svid)
        floats = np.asarray(floats, dtype=np.float64)
        carrier_lock = np.asarray(carrier_lock)
        n = svid.size
        if svid.shape != (n,) or floats.shape != (n, _FLOATS_PER_ELEMENT) or carrier_lock.shape != (n,):
            raise ValueError(f'shapes do not agree: svid {svid.shape}, floats {floats.shape}, '
                             f'carrier_lock {carrier_lock.shape}')
        if n and (svid.min() < 0 or svid.max() > 0xFFFF or carrier_lock.min() < 0 or carrier_lock.max() > 0xFF):
            raise ValueError('svid must fit uint16 and carrier_lock uint8')
        if not 0 <= constellation <= 0xFF:
            raise ValueError(f'constellation must fit uint8, got {constellation}')
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        if not 0 <= sec < 2 ** 31:
            raise ValueError(f'stamp out of the int32 seconds range: {stamp_ns} ns')
        ints = np.empty(_COUNT + 1 + n * _INTS_PER_ELEMENT, dtype=np.int64)
        ints[_SEC], ints[_NANOSEC] = sec, nanosec
        ints[_FRAME_ID], ints[_FRAME_ID + 1] = 0, len(self._text)
        ints[_COUNT] = n
        elements = ints[_COUNT + 1:].reshape(n, _INTS_PER_ELEMENT)
        elements[:, _CONSTELLATION] = constellation
        elements[:, _SVID] = svid
        elements[:, _CARRIER_LOCK] = carrier_lock
        stream = np.empty((n, _FLOATS_PER_ELEMENT), dtype=np.float64)
        stream[:, _FLOAT_AT] = floats
        return _LAYOUT.encode(ints, stream.ravel(), self._text)


def carrier_lock_codes(interval: CorrelatorInterval) -> np.ndarray:
    """Correlator.carrier_lock of each channel of an interval: CARRIER_LOCK_HELD / _LOST by the lock rule
    (``interval.locked``), CARRIER_LOCK_UNKNOWN while the rule's window is not full yet (its discriminator std
    NaN: the first ``lock_window_ms`` of a channel), shape (n,), int."""
    return np.where(~np.isfinite(interval.phase_error_std_rad), Correlator.CARRIER_LOCK_UNKNOWN,
                    np.where(interval.locked, Correlator.CARRIER_LOCK_HELD, Correlator.CARRIER_LOCK_LOST))


def correlator_array(interval: CorrelatorInterval, frame_id: str) -> CorrelatorArray:
    """CorrelatorInterval -> rfi_msgs/CorrelatorArray (GPS, one Correlator per channel, its carrier lock from
    :func:`carrier_lock_codes`)."""
    msg = CorrelatorArray()
    msg.header.stamp = ns_to_stamp(interval.stamp_ns)
    msg.header.frame_id = frame_id
    msg.correlators = [
        Correlator(constellation=GnssMeasurement.GPS, svid=int(s), integration_time_s=float(t), in_phase=float(i),
                   quadrature=float(q), cn0_dbhz=float(c), predicted_phase_change_rad=float(d), carrier_lock=int(k))
        for s, i, q, c, d, t, k in zip(interval.svid, interval.in_phase, interval.quadrature, interval.cn0_dbhz,
                                       interval.predicted_phase_change_rad, interval.integration_time_s,
                                       carrier_lock_codes(interval), strict=True)]
    return msg


def correlator_array_bytes(interval: CorrelatorInterval, writer: CorrelatorArrayWriter) -> bytes:
    """:func:`correlator_array` serialised (the bytes rclpy's ``serialize_message`` gives for it), written from the
    interval's arrays by :class:`gnss_correlator.correlator_cdr.CorrelatorArrayWriter` without building the message
    objects: what the node publishes."""
    floats = np.column_stack((interval.integration_time_s, interval.in_phase, interval.quadrature,
                              interval.cn0_dbhz, interval.predicted_phase_change_rad))
    return writer.serialize(interval.stamp_ns, GnssMeasurement.GPS, interval.svid, floats,
                            carrier_lock_codes(interval))
