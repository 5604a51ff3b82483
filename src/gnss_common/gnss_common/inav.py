"""Galileo I/NAV navigation message (E1-B / E5b-I): page CRC, word types 1-5, decoded into a
:class:`gnss_common.ephemeris.GpsEphemeris` with ``system="E"``.

Input pages are the eight 32-bit words of one UBX-RXM-SFRBX of a Galileo I/NAV signal, as a
u-blox receiver reports them: words 1-4 hold the even page part (120 bits, MSB first: even/odd
flag, page type, 112 data bits, 6 tail bits; 8 bits of padding), words 5-8 the odd part (even/odd
flag, page type, 16 data bits, 40 reserved/OSNMA bits, 22 SAR bits, 2 spare, CRC-24Q, 8 reserved,
6 tail). A page pair carries one 128-bit word (112 + 16 data bits) whose first 6 bits are its
type; word types 1-4 carry the ephemeris and clock (each with the issue of data IODnav), type 5
the ionosphere, BGDs, health and GST. The CRC-24Q covers 4 zero bits and the 114 + 82 first
bits of the even and odd parts.

Conventions of :class:`GpsEphemeris` for Galileo (as :mod:`gnss_common.rinex` reads RINEX 3):
``week`` is GST week + 1024 (GPS numbering), ``toe_s`` / ``toc_s`` are GST seconds of week,
``tgd_s`` is BGD(E1,E5b) (the I/NAV clock is the E1,E5b combination's), ``health`` is E1-B DVS
(bit 0) and E1-B HS (bits 1-2), ``iode`` / ``iodc`` are IODnav.

Notes
-----
Galileo OS SIS ICD 2.1 (2023): 4.3.2.1 and Table 36 (I/NAV nominal page layout), 4.3.5 and
Tables 40-44 (word types 1-5: fields, bits and scale factors), 4.3.2.1.3 (CRC-24Q over the page
pair), 5.1.9.3 (GST: week number with epoch 1999-08-22 = GPS week 1024), 5.1.5 (BGD and the
clock combination of I/NAV), 5.1.11 and 5.1.12 (SISA index, health and data validity status).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from gnss_common.constants import SECONDS_PER_WEEK
from gnss_common.ephemeris import DEFAULT_FIT_INTERVAL_H, GpsEphemeris
from gnss_common.lnav import GPS_PI

GST_WEEK_OFFSET = 1024
"""GPS week of the GST epoch (1999-08-22): GPS week = GST week + 1024."""

CRC24Q_POLY = 0x1864CFB
"""CRC-24Q generator polynomial (Galileo OS SIS ICD 4.3.2.1.3; as RTCM 3 and SBAS)."""

INAV_WORDS = 8
"""u-blox SFRBX words of one Galileo I/NAV page pair."""

INAV_REJECT_REASONS = ("word_count", "page_order", "crc", "iod_mismatch", "invalid_ephemeris")
"""Keys of :attr:`InavAssembler.rejected` (always all present)."""


class InavError(ValueError):
    """A page or word set that cannot be decoded; ``reason`` is one of INAV_REJECT_REASONS."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


def crc24q(data: bytes) -> int:
    """CRC-24Q of ``data`` (initial value 0, no reflection, no final XOR)."""
    crc = 0
    for byte in data:
        crc ^= byte << 16
        for _ in range(8):
            crc <<= 1
            if crc & 0x1000000:
                crc ^= CRC24Q_POLY
    return crc & 0xFFFFFF


def _field(value: int, nbits: int, start: int, length: int) -> int:
    return (value >> (nbits - start - length)) & ((1 << length) - 1)


def _crc_input(even: int, odd: int) -> bytes:
    """4 zero bits + even bits 0..113 + odd bits 0..81 (200 bits) as 25 bytes."""
    bits = (_field(even, 128, 0, 114) << 82) | _field(odd, 128, 0, 82)
    return bits.to_bytes(25, "big")


def page_word(dwords: Sequence[int]) -> tuple[int, int]:
    """Check one u-blox Galileo I/NAV page pair; return ``(word_type, 128-bit data word)``.

    Word type 63 (dummy) and alert pages (page type 1) return type -1.

    Raises:
        InavError: reasons ``"word_count"``, ``"page_order"`` (not an even part followed by an odd
            part), ``"crc"``.
    """
    if len(dwords) != INAV_WORDS:
        raise InavError("word_count", f"Galileo I/NAV page needs 8 words, got {len(dwords)}")
    even = 0
    odd = 0
    for w in dwords[:4]:
        even = (even << 32) | (int(w) & 0xFFFFFFFF)
    for w in dwords[4:]:
        odd = (odd << 32) | (int(w) & 0xFFFFFFFF)
    if _field(even, 128, 0, 1) != 0 or _field(odd, 128, 0, 1) != 1:
        raise InavError("page_order", "Galileo I/NAV page parts not in even-odd order")
    if crc24q(_crc_input(even, odd)) != _field(odd, 128, 82, 24):
        raise InavError("crc", "Galileo I/NAV page fails its CRC-24Q")
    if _field(even, 128, 1, 1) or _field(odd, 128, 1, 1):
        return -1, 0  # alert page
    word = (_field(even, 128, 2, 112) << 16) | _field(odd, 128, 2, 16)
    wtype = word >> 122
    return (-1 if wtype == 63 else wtype), word


def _u(word: int, start: int, length: int) -> int:
    return _field(word, 128, start, length)


def _s(word: int, start: int, length: int) -> int:
    v = _u(word, start, length)
    return v - (1 << length) if v >> (length - 1) else v


def sisa_m(index: int) -> float:
    """Signal-in-space accuracy of a SISA index, m (NaN: 255, no accuracy prediction; OS SIS ICD 5.1.12)."""
    if index < 50:
        return 0.01 * index
    if index < 75:
        return 0.5 + 0.02 * (index - 50)
    if index < 100:
        return 1.0 + 0.04 * (index - 75)
    if index < 126:
        return 2.0 + 0.16 * (index - 100)
    return math.nan


def decode_words(prn: int, words: dict[int, int], reference_week: int) -> GpsEphemeris:
    """Decode word types 1-5 of one satellite into a Galileo :class:`GpsEphemeris`.

    Args:
        prn: Galileo SVID (1..36).
        words: word type -> 128-bit data word, types 1..5 present.
        reference_week: continuous GPS week near the broadcast one (resolves GST's 12-bit week).

    Raises:
        InavError: ``"iod_mismatch"`` (word types 1-4 of different IODnav), ``"invalid_ephemeris"``.
    """
    w1, w2, w3, w4, w5 = (words[k] for k in (1, 2, 3, 4, 5))
    iods = {_u(w, 6, 10) for w in (w1, w2, w3, w4)}
    if len(iods) != 1:
        raise InavError("iod_mismatch", f"E{prn:02d}: IODnav of word types 1-4 differ: {sorted(iods)}")
    iod = iods.pop()
    sc = GPS_PI
    toe_s = _u(w1, 16, 14) * 60.0
    toc_s = _u(w4, 54, 14) * 60.0
    gst_week = _u(w5, 73, 12)
    tow_s = float(_u(w5, 85, 20))
    week = gst_week + GST_WEEK_OFFSET
    week += 4096 * round((reference_week - week) / 4096)

    def near(t: float) -> int:
        dt = t - tow_s
        return week + (1 if dt < -SECONDS_PER_WEEK / 2 else -1 if dt > SECONDS_PER_WEEK / 2 else 0)

    e1b_hs = _u(w5, 69, 2)
    e1b_dvs = _u(w5, 72, 1)
    try:
        return GpsEphemeris(
            prn=int(prn), system="E",
            toc_week=near(toc_s), toc_s=toc_s,
            af0_s=_s(w4, 68, 31) * 2.0**-34, af1_s_per_s=_s(w4, 99, 21) * 2.0**-46,
            af2_s_per_s2=_s(w4, 120, 6) * 2.0**-59,
            iode=iod, iodc=iod,
            m0_rad=_s(w1, 30, 32) * 2.0**-31 * sc, e=_u(w1, 62, 32) * 2.0**-33,
            sqrt_a_sqrt_m=_u(w1, 94, 32) * 2.0**-19, toe_s=toe_s,
            omega0_rad=_s(w2, 16, 32) * 2.0**-31 * sc, i0_rad=_s(w2, 48, 32) * 2.0**-31 * sc,
            omega_rad=_s(w2, 80, 32) * 2.0**-31 * sc, idot_radps=_s(w2, 112, 14) * 2.0**-43 * sc,
            omega_dot_radps=_s(w3, 16, 24) * 2.0**-43 * sc, delta_n_radps=_s(w3, 40, 16) * 2.0**-43 * sc,
            cuc_rad=_s(w3, 56, 16) * 2.0**-29, cus_rad=_s(w3, 72, 16) * 2.0**-29,
            crc_m=_s(w3, 88, 16) * 2.0**-5, crs_m=_s(w3, 104, 16) * 2.0**-5,
            sv_accuracy_m=sisa_m(_u(w3, 120, 8)) if _u(w3, 120, 8) < 126 else 0.0,
            cic_rad=_s(w4, 22, 16) * 2.0**-29, cis_rad=_s(w4, 38, 16) * 2.0**-29,
            week=near(toe_s),
            tgd_s=_s(w5, 57, 10) * 2.0**-32,  # BGD(E1,E5b); BGD(E1,E5a) at bit 47
            health=e1b_dvs | (e1b_hs << 1),
            transmission_time_s=tow_s,
            fit_interval_h=DEFAULT_FIT_INTERVAL_H,
        )
    except ValueError as err:
        raise InavError("invalid_ephemeris", str(err)) from None


class InavAssembler:
    """Collects I/NAV word types 1-5 per satellite; emits each new ephemeris once.

    A satellite's ephemeris is decoded when its latest word types 1-4 carry the same IODnav and a
    word type 5 (GST, BGD, health) has arrived; a rejected page is counted in :attr:`rejected`.
    """

    def __init__(self) -> None:
        self._words: dict[int, dict[int, int]] = {}
        self._emitted: dict[int, tuple[int, float, int]] = {}
        self.rejected: dict[str, int] = dict.fromkeys(INAV_REJECT_REASONS, 0)
        self.pages = 0

    def add(self, prn: int, dwords: Sequence[int], reference_week: int) -> GpsEphemeris | None:
        try:
            wtype, word = page_word(dwords)
        except InavError as err:
            self.rejected[err.reason] += 1
            return None
        self.pages += 1
        if not 1 <= wtype <= 5:
            return None
        words = self._words.setdefault(int(prn), {})
        words[wtype] = word
        if len(words.keys() & {1, 2, 3, 4, 5}) < 5:
            return None
        if len({_u(words[k], 6, 10) for k in (1, 2, 3, 4)}) != 1:
            return None  # between two issues of data: wait for the matching words
        try:
            eph = decode_words(int(prn), words, reference_week)
        except InavError as err:
            self.rejected[err.reason] += 1
            return None
        key = (eph.iode, eph.toe_s, eph.week)
        if self._emitted.get(int(prn)) == key:
            return None
        self._emitted[int(prn)] = key
        return eph


# ------------------------------------------------------------------------------------------------
# encoder (simulated receivers, tests)


def _put(fields: list[tuple[int, int, int]]) -> int:
    """128-bit word from (start, length, value) fields (values two's complement)."""
    word = 0
    for start, length, value in fields:
        if not -(1 << (length - 1)) <= value < (1 << length):
            raise ValueError(f"I/NAV field at bit {start} = {value} does not fit in {length} bits")
        word |= (value & ((1 << length) - 1)) << (128 - start - length)
    return word


def _q(value: float, scale: float) -> int:
    return int(round(value / scale))


def _wrap_sc(x: float) -> float:
    return (x + 1.0) % 2.0 - 1.0


def encode_words(eph: GpsEphemeris, tow_s: float) -> dict[int, int]:
    """Word types 1-5 of a Galileo record (``system="E"``); type 5 carries GST ``tow_s`` (s)."""
    sc = GPS_PI
    iod = eph.iode & 0x3FF
    sisa = next((i for i in range(126) if sisa_m(i) >= eph.sv_accuracy_m), 255)
    hs, dvs = (eph.health >> 1) & 3, eph.health & 1
    w1 = [(0, 6, 1), (6, 10, iod), (16, 14, _q(eph.toe_s, 60.0)),
          (30, 32, _q(_wrap_sc(eph.m0_rad / sc), 2.0**-31)), (62, 32, _q(eph.e, 2.0**-33)),
          (94, 32, _q(eph.sqrt_a_sqrt_m, 2.0**-19))]
    w2 = [(0, 6, 2), (6, 10, iod), (16, 32, _q(_wrap_sc(eph.omega0_rad / sc), 2.0**-31)),
          (48, 32, _q(_wrap_sc(eph.i0_rad / sc), 2.0**-31)), (80, 32, _q(_wrap_sc(eph.omega_rad / sc), 2.0**-31)),
          (112, 14, _q(eph.idot_radps / sc, 2.0**-43))]
    w3 = [(0, 6, 3), (6, 10, iod), (16, 24, _q(eph.omega_dot_radps / sc, 2.0**-43)),
          (40, 16, _q(eph.delta_n_radps / sc, 2.0**-43)), (56, 16, _q(eph.cuc_rad, 2.0**-29)),
          (72, 16, _q(eph.cus_rad, 2.0**-29)), (88, 16, _q(eph.crc_m, 2.0**-5)), (104, 16, _q(eph.crs_m, 2.0**-5)),
          (120, 8, sisa)]
    w4 = [(0, 6, 4), (6, 10, iod), (16, 6, eph.prn), (22, 16, _q(eph.cic_rad, 2.0**-29)),
          (38, 16, _q(eph.cis_rad, 2.0**-29)), (54, 14, _q(eph.toc_s, 60.0)), (68, 31, _q(eph.af0_s, 2.0**-34)),
          (99, 21, _q(eph.af1_s_per_s, 2.0**-46)), (120, 6, _q(eph.af2_s_per_s2, 2.0**-59))]
    w5 = [(0, 6, 5), (47, 10, _q(eph.tgd_s, 2.0**-32)), (57, 10, _q(eph.tgd_s, 2.0**-32)), (69, 2, hs),
          (72, 1, dvs), (73, 12, (eph.week - GST_WEEK_OFFSET) % 4096), (85, 20, int(tow_s) % 604800)]
    return {k: _put(w) for k, w in enumerate((w1, w2, w3, w4, w5), start=1)}


def encode_page(word: int) -> list[int]:
    """The eight u-blox SFRBX words of the nominal page pair carrying one 128-bit I/NAV word."""
    even = (0 << 127) | (0 << 126) | ((word >> 16) << 14)  # even/odd 0, page type 0, 112 data bits, tail 0
    odd = (1 << 127) | (0 << 126) | ((word & 0xFFFF) << 110)
    odd |= crc24q(_crc_input(even, odd)) << (128 - 82 - 24)
    return [(even >> (96 - 32 * k)) & 0xFFFFFFFF for k in range(4)] + \
           [(odd >> (96 - 32 * k)) & 0xFFFFFFFF for k in range(4)]
