"""RINEX observation codes: every tracking attribute of every band, and the one a measurement uses.

A RINEX 3 / 4 observable is ``<type><band><attribute>``: type ``C`` (pseudorange, m), ``L`` (carrier
phase, cycles), ``D`` (Doppler, Hz), ``S`` (signal strength, dB-Hz); band a digit (``1`` = L1 / E1 /
G1 / B1C, ``2`` = L2 / G2 / B1I, ...); attribute a letter naming the tracking mode or channel
(``C`` = C/A, ``X`` = data + pilot, ``W`` = Z-tracking, ...). Receivers write the same signal with
different attributes: BeiDou B1I is ``C2I`` on a Septentrio PolaRx5 or a u-blox F9P but ``C2X``
(I+Q) on a Trimble NetR9; Galileo E1 is ``C1C`` (pilot) on a PolaRx5, a Leica GR50 or a u-blox F9P
and ``C1X`` on a NetR9.

:data:`OBSERVATION_ATTRIBUTES` lists, per system and band, every attribute of the RINEX 3.05 and
4.00 observation-code tables. :data:`DEFAULT_SIGNALS` is the one place where the suite says which
signal of each system makes its measurement and in which order the attributes are tried;
:func:`select_signal` applies it to one satellite's observables.

Priority (why this order)
-------------------------
1. The kind of signal the suite's correlator models (:mod:`rfi_sim.correlators`,
   :mod:`imm_carrier`: a BPSK code on L1 carrying 50 bit/s navigation data, i.e. GPS C/A): GPS and
   QZSS C/A (``C``), GLONASS C/A (``C``), BeiDou B1I open service (``I``). For Galileo E1 (CBOC,
   no C/A) the pilot ``C``, which is what most receivers track and write (PolaRx5, GR50, F9P;
   the suite's default before every attribute was read).
   Files that carry these codes are converted exactly as before.
2. The same signal tracked on data and pilot together (``X``), then pilot alone, then data alone
   (pilot tracking is a pure PLL without data-bit ambiguity, so it holds lock longer under
   jamming): GPS / QZSS L1C ``X``, ``L``, ``S``; Galileo E1 ``X``, ``B``; BeiDou B1I ``X``, ``Q``.
   QZSS then its other L1 signals on the same carrier: L1C/B ``E``, L1S ``Z``, L1Sb ``B``.
3. Precise and encrypted codes whose civil tracking is semi-codeless or codeless (GPS ``P``,
   ``W``, ``Y``, ``M``, ``N``; GLONASS ``P``; Galileo ``Z``, ``A``): noisier, and they lose lock
   first under jamming (squaring losses), but a pseudorange of the right band is still better
   than none.

Inter-signal code biases between these attributes are decimetres to about a metre (e.g. GPS
P1-C1), below the single-point noise the suite works with; the code used is reported (per
constellation in :mod:`rfi_experiments.rinex_to_bag`'s summary and bag metadata) so that a
change of code is visible.

The choice is made per satellite and epoch (a satellite whose ``C1C`` range is missing in one epoch
is measured on its next attribute in that epoch only); only the band of the measured signal is
chosen from, since the suite builds one measurement per satellite.

The pseudorange, carrier phase, Doppler and C/N0 of a satellite come from one tracking attribute:
:func:`select_signal` takes the first attribute (in priority order) whose pseudorange is finite
and reads ``L``, ``D`` and ``S`` of that same attribute only (NaN where the receiver did not write
them); it never takes ``S1W`` for a ``C1C`` range.

RINEX 2 files name observables without attribute (``C1``, ``L1``, ``D1``, ``S1``): ``C1`` is
tried after every RINEX 3 code, with ``L1``, ``D1``, ``S1`` of the band. ``P1`` is not used (as
before: a RINEX 2 satellite without ``C1`` is counted as missing its pseudorange), since RINEX 2
cannot say which attribute ``L1``, ``D1`` and ``S1`` belong to.

BeiDou band numbers changed in RINEX 3.02: 3.01 files write B1I as band 1 (``C1I``, ``C1Q``,
``C1X``), 3.02 and later as band 2 (``C2I``...), and from 3.04 band 1 is B1C (``C1D``, ``C1P``,
``C1X``). ``1I`` and ``1Q`` are B1I in any file (no other BeiDou signal has these attributes on
band 1; some receivers still write them, e.g. Unicore UB4B0); ``1X`` is B1I only in files older
than 3.02 (:attr:`SignalPreference.rinex301_codes`).

Notes
-----
IGS / RTCM-SC104, RINEX 3.05 (2020), section 5.1-5.2 and Table 4 (observation codes per system);
IGS / RTCM-SC104, RINEX 4.00 (2021), Table 4 (adds BeiDou B1A ``1S/1L/1Z`` and B3A ``6D/6P/6Z``
in place of 3.05's ``1A`` and ``6A``, and NavIC L1 ``1D/1P/1X``); RINEX 3.02 (2013), section 5.12
(BeiDou B1 moved from band 1 to band 2).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from gnss_common.constants import BEIDOU_B1I_FREQUENCY_HZ, GALILEO_E1_FREQUENCY_HZ, GPS_L1_FREQUENCY_HZ

OBSERVATION_ATTRIBUTES: dict[str, dict[str, str]] = {
    "G": {  # GPS
        "1": "CSLXPWYMN",  # L1: C/A, L1C-D, L1C-P, L1C-(D+P), P, Z-tracking, Y, M, codeless
        "2": "CDSLXPWYMN",  # L2: C/A, semi-codeless L1(C/A)+(P2-P1), L2C(M), L2C(L), L2C(M+L), P, Z, Y, M, codeless
        "5": "IQX",  # L5: I, Q, I+Q
    },
    "R": {  # GLONASS
        "1": "CP",  # G1 FDMA: C/A, P
        "4": "ABX",  # G1a CDMA (L1OC): L1OCd, L1OCp, d+p
        "2": "CP",  # G2 FDMA: C/A, P
        "6": "ABX",  # G2a CDMA (L2CSI / L2OCp)
        "3": "IQX",  # G3: I, Q, I+Q
    },
    "E": {  # Galileo
        "1": "ABCXZ",  # E1: PRS, B (I/NAV data), C (pilot), B+C, A+B+C
        "5": "IQX",  # E5a
        "7": "IQX",  # E5b
        "8": "IQX",  # E5 (E5a+E5b, AltBOC)
        "6": "ABCXZ",  # E6: PRS, B, C, B+C, A+B+C
    },
    "C": {  # BeiDou (band numbers of RINEX 3.02 and later)
        "2": "IQX",  # B1I (B1-2): I, Q, I+Q
        "1": "DPXASLZN",  # B1C: D, P, D+P; B1A: A (3.05), S, L, Z (4.00); codeless N (3.05)
        "5": "DPX",  # B2a
        "7": "IQXDPZ",  # B2I (BDS-2/3): I, Q, I+Q; B2b (BDS-3): D, P, D+P
        "8": "DPX",  # B2a+b
        "6": "IQXADPZ",  # B3I: I, Q, I+Q; B3A: A (3.05), D, P, Z (4.00)
    },
    "J": {  # QZSS
        "1": "CESLXZB",  # L1: C/A, L1C/B, L1C-D, L1C-P, L1C-(D+P), L1S (SAIF/SLAS), L1Sb (4.0x)
        "2": "SLX",  # L2C: M, L, M+L
        "5": "IQXDPZ",  # L5: I, Q, I+Q; L5S: D, P, D+P
        "6": "SLXEZ",  # L6: D (LEX/CLAS), P, D+P, E (MADOCA), D+E
    },
    "I": {  # NavIC / IRNSS
        "5": "ABCX",  # L5: SPS, RS-data, RS-pilot, B+C
        "9": "ABCX",  # S band
        "1": "DPX",  # L1: D, P, D+P (RINEX 4.00)
    },
    "S": {  # SBAS
        "1": "C",  # L1 C/A
        "5": "IQX",  # L5
    },
}
"""System letter -> band digit -> every tracking attribute of that band (RINEX 3.05 Table 4 and
RINEX 4.00 Table 4, union). Observable types C, L, D, S exist for each (codeless ``N`` has no
pseudorange in the tables; it is listed so that a file writing one is still read)."""


@dataclass(frozen=True)
class SignalPreference:
    """The signal that makes one system's measurement, and its attributes in priority order.

    Attributes:
        name: signal name for messages ("L1 C/A", "E1", "B1I", "G1", "L1").
        band: RINEX band digit of the signal.
        attributes: tracking attributes of ``band``, most preferred first (a subset of
            :data:`OBSERVATION_ATTRIBUTES`).
        carrier_frequency_hz: the signal's carrier, Hz; NaN for GLONASS FDMA (per channel k).
        extra_codes: further band + attribute codes of the same signal tried after ``attributes``
            (BeiDou: B1I written on band 1 as in RINEX 3.01).
        rinex301_codes: band + attribute codes tried after ``extra_codes`` only in files older
            than RINEX 3.02 (their meaning changed then).
        rinex2_codes: RINEX 2 pseudorange observables tried last (``C1``); phase, Doppler and
            strength are then ``L<band>``, ``D<band>``, ``S<band>``.
    """

    name: str
    band: str
    attributes: str
    carrier_frequency_hz: float
    extra_codes: tuple[str, ...] = ()
    rinex301_codes: tuple[str, ...] = ()
    rinex2_codes: tuple[str, ...] = ()

    def candidates(self, rinex_version: float | None = None) -> tuple[str, ...]:
        """Signal codes tried in order: ``"1C"`` style (band + attribute) then RINEX 2 ``"C1"`` style.

        Args:
            rinex_version: version of the file the observables come from; None for RINEX 3.02 or
                later (e.g. observables converted from a receiver's binary messages).
        """
        old = rinex_version is not None and rinex_version < 3.02
        return (
            tuple(self.band + a for a in self.attributes)
            + self.extra_codes
            + (self.rinex301_codes if old else ())
            + self.rinex2_codes
        )

    def pseudorange_observables(self, rinex_version: float | None = None) -> tuple[str, ...]:
        """:meth:`candidates` as pseudorange observables: ``"C1C"``, ..., RINEX 2 ``"C1"``."""
        return tuple(_pseudorange_observable(c) for c in self.candidates(rinex_version))


DEFAULT_SIGNALS: dict[str, SignalPreference] = {
    "G": SignalPreference("L1", "1", "CXLSPWYMN", GPS_L1_FREQUENCY_HZ, rinex2_codes=("C1",)),
    "E": SignalPreference("E1", "1", "CXBZA", GALILEO_E1_FREQUENCY_HZ, rinex2_codes=("C1",)),
    "C": SignalPreference("B1I", "2", "IXQ", BEIDOU_B1I_FREQUENCY_HZ, extra_codes=("1I", "1Q"),
                          rinex301_codes=("1X",)),
    "R": SignalPreference("G1", "1", "CP", math.nan, rinex2_codes=("C1",)),
    "J": SignalPreference("L1", "1", "CXLSEZB", GPS_L1_FREQUENCY_HZ, rinex2_codes=("C1",)),
}
"""The signal of each system whose satellite state is modelled here, attributes in priority order
(module docstring: why this order). GPS / QZSS L1 (LNAV clock, TGD), Galileo E1 (I/NAV, BGD
E1-E5b), BeiDou B1I (D1/D2, TGD1), GLONASS G1 FDMA."""


@dataclass(frozen=True)
class SelectedSignal:
    """The observables of one satellite on one tracking attribute.

    Attributes:
        code: signal code used: ``"2X"`` (band + attribute, RINEX 3 / 4) or ``"C1"`` (the
            RINEX 2 pseudorange observable).
        pseudorange_m: m (finite).
        carrier_phase_cycles: cycles, NaN when not written.
        doppler_hz: Hz (RINEX sign: positive for an approaching satellite), NaN when not written.
        cn0_dbhz: signal strength, dB-Hz, NaN when not written.
    """

    code: str
    pseudorange_m: float
    carrier_phase_cycles: float
    doppler_hz: float
    cn0_dbhz: float

    @property
    def pseudorange_observable(self) -> str:
        """The pseudorange observable as the file names it: ``"C2X"``, RINEX 2 ``"C1"``."""
        return _pseudorange_observable(self.code)


def _pseudorange_observable(code: str) -> str:
    """``"2X"`` -> ``"C2X"``; a RINEX 2 observable (``"C1"``) unchanged."""
    return "C" + code if code[0].isdigit() else code


def _finite(values: Mapping[str, float], key: str) -> float:
    v = values.get(key, math.nan)
    return float(v) if math.isfinite(v) else math.nan


def select_signal(
    values: Mapping[str, float], preference: SignalPreference, rinex_version: float | None = None
) -> SelectedSignal | None:
    """Pick one tracking attribute of a satellite's observables and read all four types from it.

    Args:
        values: observable code -> value of one satellite at one epoch (as
            :class:`gnss_common.rinex.RinexObsEpoch` holds them; missing values NaN or absent).
        preference: the system's signal (:data:`DEFAULT_SIGNALS`).
        rinex_version: the file's RINEX version (None: 3.02 or later).

    Returns:
        The first candidate of ``preference.candidates(rinex_version)`` whose pseudorange is
        finite, with phase, Doppler and strength of that same attribute; None when none has a
        pseudorange.
    """
    for code in preference.candidates(rinex_version):
        if code[0].isdigit():  # RINEX 3 / 4: band + attribute
            pr = _finite(values, "C" + code)
            if math.isfinite(pr):
                return SelectedSignal(code, pr, _finite(values, "L" + code), _finite(values, "D" + code),
                                      _finite(values, "S" + code))
        else:  # RINEX 2: C1, the band's L, D, S observables
            pr = _finite(values, code)
            if math.isfinite(pr):
                band = code[1:]
                return SelectedSignal(code, pr, _finite(values, "L" + band), _finite(values, "D" + band),
                                      _finite(values, "S" + band))
    return None
