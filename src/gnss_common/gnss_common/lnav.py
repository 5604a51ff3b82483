"""GPS L1 C/A LNAV navigation message: word parity, subframes 1-3 (ephemeris and clock) and
subframe 4 page 18 (Klobuchar parameters), decoded into :class:`gnss_common.ephemeris.GpsEphemeris`.

Input words are the ten 32-bit words of one subframe as a u-blox receiver reports them in
UBX-RXM-SFRBX (GPS L1 C/A): bits 31-30 hold D29*, D30* (the last two transmitted bits of the
previous word), bits 29-0 the 30 transmitted bits of the word (24 data bits, as transmitted,
i.e. complemented when D30* = 1, then 6 parity bits). Each word is parity-checked on its own
with the D29*, D30* it carries; the data bits are then restored upright. (Checked on a real
u-blox capture: every word of the RXM-SFRBX of pyubx2's sample log passes this check, see
``test/test_lnav.py``.)

The encoder (:func:`encode_ephemeris_subframes`, :func:`encode_iono_subframe`) does the
inverse; it builds UBX-RXM-SFRBX words for simulated receivers and for tests.

Notes
-----
IS-GPS-200 (rev. N): 20.3.2 and Figure 20-1 (subframe and word layout), 20.3.3.1 (TLM), 20.3.3.2
(HOW), Table 20-I / 20-II (subframe 1: WN, URA, health, T_GD, IODC, t_oc, a_f2, a_f1, a_f0),
Table 20-III (subframes 2-3: ephemeris scale factors), 20.3.3.5.1.7 and Table 20-X (page 18:
Klobuchar alpha/beta), 20.3.5.2 and Table 20-XIV (parity algorithm), 20.3.3.4.1 (fit interval
flag), 20.3.3.3.1.3 and 20.3.3.3.1.5 (URA index, T_GD), 20.3.3.4.1 (IODE = 8 LSBs of IODC for a
consistent set). Angles are broadcast in semicircles; they are converted with the GPS value of
pi (IS-GPS-200 20.3.3.4.3: 3.1415926535898) into the radians of :class:`GpsEphemeris`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gnss_common.constants import SECONDS_PER_WEEK
from gnss_common.ephemeris import DEFAULT_FIT_INTERVAL_H, GpsEphemeris
from gnss_common.gps_time import resolve_week_rollover

GPS_PI = 3.1415926535898
"""pi as IS-GPS-200 (20.3.3.4.3) defines it for semicircle conversion."""

PREAMBLE = 0x8B
"""TLM preamble 10001011 (IS-GPS-200 20.3.3.1)."""

WORDS_PER_SUBFRAME = 10
"""Words of one LNAV subframe (300 bits, 6 s)."""

URA_TABLE_M = (2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0, 48.0, 96.0, 192.0, 384.0, 768.0, 1536.0,
               3072.0, 6144.0, math.nan)
"""Upper bound of the user range accuracy per URA index 0..15, m; 15: no accuracy prediction
(IS-GPS-200 20.3.3.3.1.3)."""

EXTENDED_FIT_INTERVAL_H = 6.0
"""Fit interval used when the LNAV fit-interval flag is 1 (> 4 h): 6 h, the value for the IODCs
of a normal upload (IS-GPS-200 Table 20-XII, IODC 240-247); the store then accepts |t - t_oe| up
to 3 h."""

# Parity: for each of D25..D30, the data bits d1..d24 summed and which of D29*/D30* starts it.
_PARITY_BITS = (
    (29, (1, 2, 3, 5, 6, 10, 11, 12, 13, 14, 17, 18, 20, 23)),
    (30, (2, 3, 4, 6, 7, 11, 12, 13, 14, 15, 18, 19, 21, 24)),
    (29, (1, 3, 4, 5, 7, 8, 12, 13, 14, 15, 16, 19, 20, 22)),
    (30, (2, 4, 5, 6, 8, 9, 13, 14, 15, 16, 17, 20, 21, 23)),
    (30, (1, 3, 5, 6, 7, 9, 10, 14, 15, 16, 17, 18, 21, 22, 24)),
    (29, (3, 5, 6, 8, 9, 10, 11, 13, 15, 19, 22, 23, 24)),
)
_PARITY_MASKS = tuple((star, sum(1 << (24 - i) for i in bits)) for star, bits in _PARITY_BITS)


class LnavError(ValueError):
    """A subframe that cannot be decoded (parity, preamble, subframe id, inconsistent set)."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


def parity_bits(data24: int, d29_star: int, d30_star: int) -> int:
    """Six parity bits D25..D30 of one word (IS-GPS-200 Table 20-XIV).

    Args:
        data24: the 24 source data bits d1..d24, upright (d1 in bit 23), int.
        d29_star, d30_star: last two transmitted bits of the previous word, 0 or 1.

    Returns:
        D25..D30 packed, D25 in bit 5.
    """
    out = 0
    for star, mask in _PARITY_MASKS:
        bit = (d29_star if star == 29 else d30_star) ^ (bin(data24 & mask).count("1") & 1)
        out = (out << 1) | bit
    return out


def word_data(dword: int) -> int:
    """Check one u-blox SFRBX word's parity and return its 24 data bits, upright.

    Raises:
        LnavError: reason ``"parity"``.
    """
    d29s = (dword >> 31) & 1
    d30s = (dword >> 30) & 1
    sent = (dword >> 6) & 0xFFFFFF
    data = sent ^ 0xFFFFFF if d30s else sent
    if parity_bits(data, d29s, d30s) != dword & 0x3F:
        raise LnavError("parity", f"word 0x{dword:08x} fails the LNAV parity check")
    return data


def encode_word(data24: int, d29_star: int, d30_star: int) -> int:
    """u-blox SFRBX word of 24 upright data bits after a word ending in (D29*, D30*)."""
    sent = data24 ^ 0xFFFFFF if d30_star else data24
    return (d29_star << 31) | (d30_star << 30) | (sent << 6) | parity_bits(data24, d29_star, d30_star)


@dataclass(frozen=True)
class LnavSubframe:
    """One parity-checked LNAV subframe.

    Attributes:
        prn: GPS PRN of the transmitting satellite.
        subframe_id: 1..5 (HOW bits 20-22).
        tow_count: HOW truncated TOW count: time of week of the *next* subframe start / 6 s.
        bits: the 240 data bits (ten 24-bit words, parity removed), bit 0 = d1 of word 1.
    """

    prn: int
    subframe_id: int
    tow_count: int
    bits: int

    def unsigned(self, start: int, length: int) -> int:
        """Unsigned field of ``length`` bits starting at data bit ``start`` (0-based, 240-bit stream)."""
        return (self.bits >> (240 - start - length)) & ((1 << length) - 1)

    def signed(self, start: int, length: int) -> int:
        """Two's-complement field (see :meth:`unsigned`)."""
        v = self.unsigned(start, length)
        return v - (1 << length) if v >> (length - 1) else v

    @property
    def transmit_tow_s(self) -> float:
        """GPS time of week of the start of this subframe, s."""
        return (self.tow_count * 6.0 - 6.0) % SECONDS_PER_WEEK


def parse_subframe(prn: int, dwords: Sequence[int]) -> LnavSubframe:
    """Parity-check the ten words of one subframe and read TLM/HOW.

    Args:
        prn: GPS PRN (UBX svId).
        dwords: ten u-blox SFRBX words (see module docstring).

    Raises:
        LnavError: reasons ``"word_count"``, ``"parity"``, ``"preamble"``, ``"subframe_id"``.
    """
    if len(dwords) != WORDS_PER_SUBFRAME:
        raise LnavError("word_count", f"PRN {prn}: LNAV subframe needs 10 words, got {len(dwords)}")
    bits = 0
    for w in dwords:
        bits = (bits << 24) | word_data(int(w) & 0xFFFFFFFF)
    sf = LnavSubframe(prn=int(prn), subframe_id=0, tow_count=0, bits=bits)
    if sf.unsigned(0, 8) != PREAMBLE:
        raise LnavError("preamble", f"PRN {prn}: TLM preamble 0x{sf.unsigned(0, 8):02x}, expected 0x8b")
    sid = sf.unsigned(43, 3)
    if not 1 <= sid <= 5:
        raise LnavError("subframe_id", f"PRN {prn}: subframe id {sid} outside 1..5")
    return LnavSubframe(prn=int(prn), subframe_id=sid, tow_count=sf.unsigned(24, 17), bits=bits)


def _near_week(week_tx: int, tow_tx_s: float, t_s: float) -> int:
    """Week of a time of week t_s broadcast in week ``week_tx`` at ``tow_tx_s`` (crossover rule)."""
    dt = t_s - tow_tx_s
    if dt < -SECONDS_PER_WEEK / 2:
        return week_tx + 1
    if dt > SECONDS_PER_WEEK / 2:
        return week_tx - 1
    return week_tx


def decode_ephemeris(
    sf1: LnavSubframe, sf2: LnavSubframe, sf3: LnavSubframe, reference_week: int
) -> GpsEphemeris:
    """Decode one consistent set of subframes 1, 2, 3 into a :class:`GpsEphemeris`.

    Args:
        sf1, sf2, sf3: parsed subframes of one PRN (ids 1, 2, 3).
        reference_week: a continuous GPS week within +-512 weeks of the broadcast one (e.g. the
            receiver's week from UBX-RXM-RAWX), for the 10-bit week rollover.

    Returns:
        The ephemeris; ``transmission_time_s`` is the time of week of subframe 1.

    Raises:
        LnavError: reason ``"iode_mismatch"`` (IODE of 2, 3 and the 8 LSBs of IODC differ: the
            subframes belong to different uploads), ``"subframe_id"`` for wrong ids or PRNs,
            ``"invalid_ephemeris"`` when the values are not an orbit.
    """
    if (sf1.subframe_id, sf2.subframe_id, sf3.subframe_id) != (1, 2, 3) or not sf1.prn == sf2.prn == sf3.prn:
        raise LnavError("subframe_id", "decode_ephemeris needs subframes 1, 2, 3 of one PRN")
    iodc = (sf1.unsigned(70, 2) << 8) | sf1.unsigned(168, 8)
    iode2 = sf2.unsigned(48, 8)
    iode3 = sf3.unsigned(216, 8)
    if not iode2 == iode3 == (iodc & 0xFF):
        raise LnavError("iode_mismatch", f"PRN {sf1.prn}: IODC {iodc}, IODE {iode2} / {iode3} differ")
    week_tx = resolve_week_rollover(sf1.unsigned(48, 10), reference_week)
    tow_tx = sf1.transmit_tow_s
    ura = sf1.unsigned(60, 4)
    health = sf1.unsigned(64, 6)
    tgd_raw = sf1.signed(160, 8)
    toc_s = sf1.unsigned(176, 16) * 16.0
    toe_s = sf2.unsigned(216, 16) * 16.0
    fit_flag = _fit_flag(sf2)
    sc = GPS_PI
    try:
        return GpsEphemeris(
            prn=sf1.prn,
            toc_week=_near_week(week_tx, tow_tx, toc_s),
            toc_s=toc_s,
            af0_s=sf1.signed(216, 22) * 2.0**-31,
            af1_s_per_s=sf1.signed(200, 16) * 2.0**-43,
            af2_s_per_s2=sf1.signed(192, 8) * 2.0**-55,
            iode=iode2,
            crs_m=sf2.signed(56, 16) * 2.0**-5,
            delta_n_radps=sf2.signed(72, 16) * 2.0**-43 * sc,
            m0_rad=sf2.signed(88, 32) * 2.0**-31 * sc,
            cuc_rad=sf2.signed(120, 16) * 2.0**-29,
            e=sf2.unsigned(136, 32) * 2.0**-33,
            cus_rad=sf2.signed(168, 16) * 2.0**-29,
            sqrt_a_sqrt_m=sf2.unsigned(184, 32) * 2.0**-19,
            toe_s=toe_s,
            cic_rad=sf3.signed(48, 16) * 2.0**-29,
            omega0_rad=sf3.signed(64, 32) * 2.0**-31 * sc,
            cis_rad=sf3.signed(96, 16) * 2.0**-29,
            i0_rad=sf3.signed(112, 32) * 2.0**-31 * sc,
            crc_m=sf3.signed(144, 16) * 2.0**-5,
            omega_rad=sf3.signed(160, 32) * 2.0**-31 * sc,
            omega_dot_radps=sf3.signed(192, 24) * 2.0**-43 * sc,
            idot_radps=sf3.signed(224, 14) * 2.0**-43 * sc,
            week=_near_week(week_tx, tow_tx, toe_s),
            sv_accuracy_m=URA_TABLE_M[ura] if ura < 15 else 0.0,
            health=health,
            tgd_s=0.0 if tgd_raw == -128 else tgd_raw * 2.0**-31,
            iodc=iodc,
            transmission_time_s=tow_tx,
            fit_interval_h=EXTENDED_FIT_INTERVAL_H if fit_flag else DEFAULT_FIT_INTERVAL_H,
        )
    except ValueError as err:
        raise LnavError("invalid_ephemeris", str(err)) from None


def _fit_flag(sf2: LnavSubframe) -> int:
    return sf2.unsigned(232, 1)


@dataclass(frozen=True)
class KlobucharParams:
    """Broadcast Klobuchar coefficients (subframe 4 page 18).

    Attributes:
        alpha: alpha_0..3, s, s/sc, s/sc^2, s/sc^3, shape (4,).
        beta: beta_0..3, s, s/sc, s/sc^2, s/sc^3, shape (4,).
    """

    alpha: np.ndarray
    beta: np.ndarray


_ALPHA_SCALES = (2.0**-30, 2.0**-27, 2.0**-24, 2.0**-24)
_BETA_SCALES = (2.0**11, 2.0**14, 2.0**16, 2.0**16)
PAGE18_SV_ID = 56
"""Subframe 4 page 18 (ionospheric and UTC data) carries SV ID 56 (IS-GPS-200 Table 20-V)."""


def decode_klobuchar(sf4: LnavSubframe) -> KlobucharParams | None:
    """Klobuchar coefficients of a subframe 4 page 18, or None for any other subframe / page."""
    if sf4.subframe_id != 4 or sf4.unsigned(50, 6) != PAGE18_SV_ID:
        return None
    alpha = np.array([sf4.signed(56 + 8 * i, 8) * s for i, s in enumerate(_ALPHA_SCALES)])
    beta = np.array([sf4.signed(88 + 8 * i, 8) * s for i, s in enumerate(_BETA_SCALES)])
    return KlobucharParams(alpha=alpha, beta=beta)


LNAV_REJECT_REASONS = (
    "word_count", "parity", "preamble", "subframe_id", "iode_mismatch", "invalid_ephemeris",
)
"""Keys of :attr:`LnavAssembler.rejected` (always all present)."""


class LnavAssembler:
    """Collects subframes per PRN and emits each new ephemeris and Klobuchar set once complete.

    A PRN's ephemeris is decoded when its latest subframes 1, 2 and 3 carry the same issue of data
    (IODC 8 LSBs = IODE of 2 = IODE of 3, IS-GPS-200 20.3.3.4.1); a new upload (new IODE) starts
    a new set, so subframes of different uploads are never mixed. A rejected subframe is counted
    in :attr:`rejected` by reason and dropped.
    """

    def __init__(self) -> None:
        self._pending: dict[int, dict[int, LnavSubframe]] = {}
        self._emitted: dict[int, tuple[int, float, int]] = {}
        self.rejected: dict[str, int] = dict.fromkeys(LNAV_REJECT_REASONS, 0)
        self.subframes = 0
        self.klobuchar: KlobucharParams | None = None

    def add(
        self, prn: int, dwords: Sequence[int], reference_week: int
    ) -> GpsEphemeris | KlobucharParams | None:
        """Add one subframe (ten u-blox words) of ``prn``.

        Args:
            prn: GPS PRN.
            dwords: the subframe's words.
            reference_week: continuous GPS week near the broadcast one (see :func:`decode_ephemeris`).

        Returns:
            A newly completed :class:`GpsEphemeris` (not returned again for the same IODC and
            t_oe), new :class:`KlobucharParams` (when they differ from the last ones), or None.
        """
        try:
            sf = parse_subframe(prn, dwords)
        except LnavError as err:
            self.rejected[err.reason] += 1
            return None
        self.subframes += 1
        if sf.subframe_id == 4:
            kb = decode_klobuchar(sf)
            if kb is None:
                return None
            if self.klobuchar is not None and np.array_equal(kb.alpha, self.klobuchar.alpha) and \
                    np.array_equal(kb.beta, self.klobuchar.beta):
                return None
            self.klobuchar = kb
            return kb
        if sf.subframe_id > 3:
            return None
        pending = self._pending.setdefault(sf.prn, {})
        pending[sf.subframe_id] = sf
        if len(pending) < 3:
            return None
        iodc_lsb = pending[1].unsigned(168, 8)
        if not pending[2].unsigned(48, 8) == pending[3].unsigned(216, 8) == iodc_lsb:
            return None  # a set in transition between uploads: wait for the matching subframes
        try:
            eph = decode_ephemeris(pending[1], pending[2], pending[3], reference_week)
        except LnavError as err:
            self.rejected[err.reason] += 1
            self._pending.pop(sf.prn, None)
            return None
        key = (eph.iodc, eph.toe_s, eph.week)
        if self._emitted.get(sf.prn) == key:
            return None
        self._emitted[sf.prn] = key
        return eph


# ------------------------------------------------------------------------------------------------
# encoder (simulated receivers, tests)


class _Bits:
    def __init__(self) -> None:
        self.value = 0

    def put(self, start: int, length: int, field: int, name: str) -> None:
        lo, hi = -(1 << (length - 1)), (1 << length) - 1
        if not lo <= field <= hi:
            raise ValueError(f"LNAV field {name} = {field} does not fit in {length} bits")
        self.value |= (field & ((1 << length) - 1)) << (240 - start - length)

    def scaled(self, start: int, length: int, value: float, scale: float, name: str, signed: bool) -> None:
        n = int(round(value / scale))
        if not signed and n < 0:
            raise ValueError(f"LNAV field {name} = {value} must be >= 0")
        if signed and not -(1 << (length - 1)) <= n < (1 << (length - 1)):
            raise ValueError(f"LNAV field {name} = {value} out of range for {length} signed bits")
        self.put(start, length, n, name)


def _frame_words(bits: _Bits, prev: tuple[int, int]) -> tuple[list[int], tuple[int, int]]:
    """Split 240 data bits into ten u-blox words, solving the t bits of words 2 and 10 so that
    their D29, D30 are zero (IS-GPS-200 20.3.5.2)."""
    words: list[int] = []
    d29s, d30s = prev
    for k in range(WORDS_PER_SUBFRAME):
        data = (bits.value >> (240 - 24 * (k + 1))) & 0xFFFFFF
        if k in (1, 9):
            for t in range(4):
                candidate = (data & ~0x3) | t
                if parity_bits(candidate, d29s, d30s) & 0x3 == 0:
                    data = candidate
                    break
        w = encode_word(data, d29s, d30s)
        words.append(w)
        d29s, d30s = (w >> 1) & 1, w & 1
    return words, (d29s, d30s)


def _tlm_how(bits: _Bits, start_tow_s: float, subframe_id: int) -> None:
    bits.put(0, 8, PREAMBLE, "preamble")
    count = int(round(start_tow_s / 6.0)) + 1
    bits.put(24, 17, count % 100800, "TOW count")
    bits.put(43, 3, subframe_id, "subframe id")


def encode_ephemeris_subframes(eph: GpsEphemeris, week: int, start_tow_s: float) -> list[list[int]]:
    """Encode an ephemeris into subframes 1, 2, 3 as u-blox RXM-SFRBX words.

    Args:
        eph: the record (its values are rounded to the broadcast scale factors).
        week: continuous GPS week of the transmission (broadcast modulo 1024).
        start_tow_s: GPS time of week at which subframe 1 starts, s (multiple of 6).

    Returns:
        Three lists of ten 32-bit words (subframes 1, 2, 3, transmitted 6 s apart).

    Raises:
        ValueError: a field that the LNAV format cannot carry.
    """
    sc = GPS_PI
    ura = next((i for i, u in enumerate(URA_TABLE_M[:15]) if eph.sv_accuracy_m <= u), 15)
    fit = 0 if eph.fit_interval_h <= DEFAULT_FIT_INTERVAL_H else 1
    iodc = eph.iodc if eph.iodc & 0xFF == eph.iode & 0xFF else eph.iode & 0xFF
    sf1, sf2, sf3 = _Bits(), _Bits(), _Bits()
    _tlm_how(sf1, start_tow_s, 1)
    sf1.put(48, 10, int(week) % 1024, "WN")
    sf1.put(60, 4, ura, "URA")
    sf1.put(64, 6, eph.health, "health")
    sf1.put(70, 2, iodc >> 8, "IODC MSB")
    sf1.scaled(160, 8, eph.tgd_s, 2.0**-31, "TGD", True)
    sf1.put(168, 8, iodc & 0xFF, "IODC LSB")
    sf1.scaled(176, 16, eph.toc_s, 16.0, "toc", False)
    sf1.scaled(192, 8, eph.af2_s_per_s2, 2.0**-55, "af2", True)
    sf1.scaled(200, 16, eph.af1_s_per_s, 2.0**-43, "af1", True)
    sf1.scaled(216, 22, eph.af0_s, 2.0**-31, "af0", True)
    _tlm_how(sf2, start_tow_s + 6.0, 2)
    sf2.put(48, 8, iodc & 0xFF, "IODE")
    sf2.scaled(56, 16, eph.crs_m, 2.0**-5, "Crs", True)
    sf2.scaled(72, 16, eph.delta_n_radps / sc, 2.0**-43, "delta n", True)
    sf2.scaled(88, 32, eph.m0_rad / sc, 2.0**-31, "M0", True)
    sf2.scaled(120, 16, eph.cuc_rad, 2.0**-29, "Cuc", True)
    sf2.scaled(136, 32, eph.e, 2.0**-33, "e", False)
    sf2.scaled(168, 16, eph.cus_rad, 2.0**-29, "Cus", True)
    sf2.scaled(184, 32, eph.sqrt_a_sqrt_m, 2.0**-19, "sqrt A", False)
    sf2.scaled(216, 16, eph.toe_s, 16.0, "toe", False)
    sf2.put(232, 1, fit, "fit flag")
    _tlm_how(sf3, start_tow_s + 12.0, 3)
    sf3.scaled(48, 16, eph.cic_rad, 2.0**-29, "Cic", True)
    sf3.scaled(64, 32, _wrap_sc(eph.omega0_rad / sc), 2.0**-31, "Omega0", True)
    sf3.scaled(96, 16, eph.cis_rad, 2.0**-29, "Cis", True)
    sf3.scaled(112, 32, _wrap_sc(eph.i0_rad / sc), 2.0**-31, "i0", True)
    sf3.scaled(144, 16, eph.crc_m, 2.0**-5, "Crc", True)
    sf3.scaled(160, 32, _wrap_sc(eph.omega_rad / sc), 2.0**-31, "omega", True)
    sf3.scaled(192, 24, eph.omega_dot_radps / sc, 2.0**-43, "Omega dot", True)
    sf3.put(216, 8, iodc & 0xFF, "IODE")
    sf3.scaled(224, 14, eph.idot_radps / sc, 2.0**-43, "IDOT", True)
    out = []
    prev = (0, 0)
    for bits in (sf1, sf2, sf3):
        words, prev = _frame_words(bits, prev)
        out.append(words)
    return out


def _wrap_sc(x: float) -> float:
    """Wrap semicircles into [-1, 1) (a 32-bit signed field at 2^-31 sc)."""
    return (x + 1.0) % 2.0 - 1.0


def encode_iono_subframe(alpha: np.ndarray, beta: np.ndarray, start_tow_s: float) -> list[int]:
    """Encode Klobuchar coefficients into a subframe 4 page 18 (UTC fields zero) as u-blox words."""
    bits = _Bits()
    _tlm_how(bits, start_tow_s, 4)
    bits.put(48, 2, 1, "data id")
    bits.put(50, 6, PAGE18_SV_ID, "SV id")
    for i, s in enumerate(_ALPHA_SCALES):
        bits.scaled(56 + 8 * i, 8, float(alpha[i]), s, f"alpha{i}", True)
    for i, s in enumerate(_BETA_SCALES):
        bits.scaled(88 + 8 * i, 8, float(beta[i]), s, f"beta{i}", True)
    return _frame_words(bits, (0, 0))[0]
