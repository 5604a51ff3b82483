"""UBX framing (pure): a byte stream (file chunks, serial reads) -> checksum-valid UBX frames.

Sync ``B5 62``, class, id, little-endian length, payload, 8-bit Fletcher checksum (u-blox
interface description, "UBX frame structure"). Used by :class:`rfi_experiments.ubx_decode.UbxDecoder`;
never imports rclpy.
"""

from __future__ import annotations

UBX_SYNC = b"\xb5\x62"
MAX_PAYLOAD_BYTES = 8192
"""Largest UBX payload accepted, bytes (the largest u-blox output, RXM-RAWX with 255
measurements, is 4096 + 16 bytes); a longer length field is taken as a corrupted header."""


def ubx_checksum(body: bytes) -> bytes:
    """8-bit Fletcher checksum (CK_A, CK_B) over class, id, length and payload."""
    a = b = 0
    for byte in body:
        a = (a + byte) & 0xFF
        b = (b + a) & 0xFF
    return bytes((a, b))


class UbxFramer:
    """Incremental UBX framer with resynchronisation and counted rejections.

    ``feed(chunk)`` returns the complete, checksum-valid frames (sync to checksum) found so far;
    ``finish()`` counts a partial frame left at the end of the stream as ``truncated``.

    Attributes:
        rejected: ``bad_checksum``, ``bad_length``, ``truncated`` counts.
        skipped_bytes: bytes outside UBX frames (NMEA, RTCM 3, noise, the sync of a rejected frame).
        frames: valid frames returned.
    """

    def __init__(self, max_payload_bytes: int = MAX_PAYLOAD_BYTES) -> None:
        self._buf = bytearray()
        self._max = int(max_payload_bytes)
        self.rejected: dict[str, int] = {"bad_checksum": 0, "bad_length": 0, "truncated": 0}
        self.skipped_bytes = 0
        self.frames = 0

    def feed(self, chunk: bytes) -> list[bytes]:
        buf = self._buf
        buf.extend(chunk)
        out: list[bytes] = []
        pos = 0
        n = len(buf)
        while True:
            start = buf.find(UBX_SYNC, pos)
            if start < 0:
                keep = 1 if n > pos and buf[n - 1] == 0xB5 else 0
                self.skipped_bytes += n - pos - keep
                pos = n - keep
                break
            self.skipped_bytes += start - pos
            if n - start < 6:
                pos = start
                break
            length = buf[start + 4] | (buf[start + 5] << 8)
            if length > self._max:
                self.rejected["bad_length"] += 1
                self.skipped_bytes += 2
                pos = start + 2
                continue
            end = start + 8 + length
            if end > n:
                pos = start
                break
            frame = bytes(buf[start:end])
            if ubx_checksum(frame[2:-2]) != frame[-2:]:
                self.rejected["bad_checksum"] += 1
                self.skipped_bytes += 2
                pos = start + 2
                continue
            out.append(frame)
            self.frames += 1
            pos = end
        del buf[:pos]
        return out

    def finish(self) -> None:
        """End of stream: a partial frame still buffered is counted as truncated."""
        if self._buf.startswith(UBX_SYNC):
            self.rejected["truncated"] += 1
        else:
            self.skipped_bytes += len(self._buf)
        self._buf.clear()
