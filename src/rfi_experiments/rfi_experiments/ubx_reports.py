"""The receiver's own monitor messages (pure): UBX-MON-HW, MON-RF, SEC-SIG -> :class:`InterferenceReport`,
UBX-MON-SPAN -> :class:`SpectrumReport`.

These messages carry no time of their own: :class:`rfi_experiments.ubx_decode.UbxDecoder` stamps
them with the receive time of the latest RXM-RAWX epoch. Fields are read from pyubx2's parse
(``UBXReader.parse``); never imports rclpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

JAMMING_UNKNOWN, JAMMING_OK, JAMMING_WARNING, JAMMING_CRITICAL = 0, 1, 2, 3
SOURCE_MON_HW, SOURCE_MON_RF, SOURCE_SEC_SIG = 1, 2, 3


@dataclass(frozen=True)
class InterferenceReport:
    """The receiver's interference indicators from one message (one RF block for MON-RF).

    Mirrors rfi_msgs/ReceiverInterference.msg field by field. Quantities a source does not
    report are NaN (floats) or 0 / unknown (states).
    """

    stamp_ns: int
    gps_week: int
    gps_time_of_week_s: float
    source: int
    rf_block_id: int
    jamming_state: int
    jam_indicator: float
    agc_count: float
    noise_per_ms: float
    antenna_status: int
    antenna_power: int
    jamming_detection_enabled: bool
    spoofing_state: int
    spoofing_detection_enabled: bool


def interference_from_message(msg: Any, stamp_ns: int, week: int, tow_s: float) -> list[InterferenceReport]:
    """InterferenceReports of a pyubx2 MON-HW, MON-RF or SEC-SIG message ([] for others)."""
    ident = msg.identity
    base: dict[str, Any] = dict(stamp_ns=stamp_ns, gps_week=week, gps_time_of_week_s=tow_s)
    if ident == "MON-HW":
        return [InterferenceReport(
            **base, source=SOURCE_MON_HW, rf_block_id=0, jamming_state=int(msg.jammingState),
            jam_indicator=float(msg.jamInd), agc_count=float(msg.agcCnt), noise_per_ms=float(msg.noisePerMS),
            antenna_status=int(msg.aStatus), antenna_power=int(msg.aPower),
            jamming_detection_enabled=int(msg.jammingState) != JAMMING_UNKNOWN,
            spoofing_state=0, spoofing_detection_enabled=False)]
    if ident == "MON-RF":
        out = []
        for i in range(1, int(msg.nBlocks) + 1):
            s = f"_{i:02d}"
            state = int(getattr(msg, "jammingState" + s))
            out.append(InterferenceReport(
                **base, source=SOURCE_MON_RF, rf_block_id=int(getattr(msg, "blockId" + s)),
                jamming_state=state, jam_indicator=float(getattr(msg, "jamInd" + s)),
                agc_count=float(getattr(msg, "agcCnt" + s)), noise_per_ms=float(getattr(msg, "noisePerMS" + s)),
                antenna_status=int(getattr(msg, "antStatus" + s)), antenna_power=int(getattr(msg, "antPower" + s)),
                jamming_detection_enabled=state != JAMMING_UNKNOWN, spoofing_state=0,
                spoofing_detection_enabled=False))
        return out
    if ident == "SEC-SIG":
        jam_state = int(msg.jammingState)  # same names in SEC-SIG versions 1 and 2; missing: unparsable
        return [InterferenceReport(
            **base, source=SOURCE_SEC_SIG, rf_block_id=0, jamming_state=jam_state, jam_indicator=math.nan,
            agc_count=math.nan, noise_per_ms=math.nan, antenna_status=0, antenna_power=0,
            jamming_detection_enabled=bool(msg.jamDetEnabled), spoofing_state=int(msg.spoofingState),
            spoofing_detection_enabled=bool(msg.spfDetEnabled))]
    return []


SPECTRUM_BINS = 256
"""Bins per RF block of UBX-MON-SPAN."""
SPECTRUM_UNIT_DB = 0.25
"""UBX-MON-SPAN spectrum unit, dB per count (u-blox integration manuals: "0.25 dB units")."""


@dataclass(frozen=True)
class SpectrumReport:
    """One RF block of UBX-MON-SPAN: the receiver's spectrum before correlation.

    Mirrors rfi_msgs/ReceiverSpectrum.msg field by field.

    Attributes:
        stamp_ns, gps_week, gps_time_of_week_s: the latest RXM-RAWX epoch before the report
            (ROS time, ns; GPS week; s), as :class:`InterferenceReport`.
        rf_block_id: index of the block in the message (0: usually the L1 band).
        center_frequency_hz: ``center``, Hz.
        span_hz: ``span``, Hz.
        resolution_hz: ``res``, Hz (span / 256).
        pga_gain_db: ``pga``, dB (the PGA gain is not included in the spectrum).
        power_db: the 256 bins of ``spectrum`` times :data:`SPECTRUM_UNIT_DB`, dB, ascending
            frequency; bin i at ``center + span (i - 127) / 256`` by the u-blox interface description.
    """

    stamp_ns: int
    gps_week: int
    gps_time_of_week_s: float
    rf_block_id: int
    center_frequency_hz: float
    span_hz: float
    resolution_hz: float
    pga_gain_db: float
    power_db: tuple[float, ...]


def spectrum_from_message(msg: Any, stamp_ns: int, week: int, tow_s: float) -> list[SpectrumReport]:
    """SpectrumReports of a pyubx2 UBX-MON-SPAN message, one per RF block.

    pyubx2 names the repeated group's fields ``spectrum_NN`` (a list of 256 raw counts), ``span_NN``,
    ``res_NN``, ``center_NN``, ``pga_NN`` (NN = 01 .. numRfBlocks).

    Raises:
        ValueError: a block whose spectrum is not 256 counts, or whose span, resolution or centre is 0.
    """
    out = []
    for i in range(1, int(msg.numRfBlocks) + 1):
        s = f"_{i:02d}"
        counts = list(getattr(msg, "spectrum" + s))
        span, res, center = (float(getattr(msg, name + s)) for name in ("span", "res", "center"))
        if len(counts) != SPECTRUM_BINS:
            raise ValueError(f"MON-SPAN block {i - 1}: {len(counts)} bins, expected {SPECTRUM_BINS}")
        if min(span, res, center) <= 0.0:
            raise ValueError(f"MON-SPAN block {i - 1}: span {span}, res {res}, center {center} Hz")
        out.append(SpectrumReport(
            stamp_ns=stamp_ns, gps_week=week, gps_time_of_week_s=tow_s, rf_block_id=i - 1,
            center_frequency_hz=center, span_hz=span, resolution_hz=res, pga_gain_db=float(getattr(msg, "pga" + s)),
            power_db=tuple(SPECTRUM_UNIT_DB * float(c) for c in counts)))
    return out
