"""u-blox UBX stream -> GNSS measurement epochs and the receiver's interference indicators (pure).

Never imports rclpy: :mod:`rfi_experiments.ubx_to_bag` (a tool) and
:mod:`rfi_experiments.ubx_source` (a node) are thin layers around :class:`UbxDecoder`.

Pipeline
--------
1. :class:`UbxFramer` cuts a byte stream (file chunks or whatever a serial port returned) into
   UBX frames: sync ``B5 62``, class, id, length, payload, Fletcher checksum. A frame with a bad
   checksum or an impossible length is counted and the search resumes one byte after its sync
   (so one corrupted length field does not swallow the good frames after it); bytes outside UBX
   frames (NMEA, RTCM, noise) are counted; a frame cut by the end of the stream is counted as
   truncated.
2. The frame's fields are decoded by pyubx2 (``UBXReader.parse``, the parser the field uses);
   a frame pyubx2 cannot parse is counted as ``unparsable``, one of a class / id pyubx2 does not
   know as ``unknown_messages``, a known message this module does not use by its identity
   (``ignored``).
3. UBX-RXM-RAWX -> :class:`RawxEpoch` (every measurement, every constellation and signal, with
   pseudorange / carrier-phase / Doppler, C/N0, lock time, the std fields and the tracking status
   flags). ``prValid`` = 0 makes the pseudorange NaN; ``cpValid`` = 0 the carrier phase NaN;
   the carrier phase is kept with ``half_cycle_resolved`` (``halfCyc``) and
   ``half_cycle_subtracted`` (``subHalfCyc``) so that a user of the phase can refuse an
   unresolved half cycle (the measurement message of the suite carries no phase).
4. The RAWX epoch is converted to RINEX 3 observables (``C1C``, ``D1C``, ``S1C``, ``L1C``, ... per
   constellation and signal, :data:`RINEX_CODES`) and built into a
   :class:`gnss_common.observations.GnssEpoch` by :class:`gnss_common.measurements.GnssEpochBuilder`,
   the same code ``rinex_to_bag`` uses (satellite state at transmission, broadcast clock,
   Klobuchar, Saastamoinen): one implementation. Whatever that builder cannot model is skipped
   and counted by its reason.
5. Broadcast ephemerides come from UBX-RXM-SFRBX (GPS LNAV subframes 1-3 and the Klobuchar page,
   :class:`gnss_common.lnav.LnavAssembler`; Galileo I/NAV word types 1-5,
   :class:`gnss_common.inav.InavAssembler`) and/or a RINEX navigation file given by the user.
   An epoch with fewer than ``min_satellites`` modelled satellites (at start-up: no ephemeris
   yet) is withheld and counted (``epochs_waiting_for_ephemeris``), never published half-empty.
6. UBX-MON-HW, UBX-MON-RF (one record per RF block) and UBX-SEC-SIG ->
   :class:`InterferenceReport`, stamped with the receive time of the latest RAWX epoch (these
   messages carry no time of their own; a report before the first RAWX is counted and dropped).

Time: header stamps are ROS time (UTC-based) from :func:`header_stamp_ns`; GPS week and time of
week stay in the message fields.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from gnss_common.ephemeris import GpsEphemeris
from gnss_common.gps_time import gps_to_ros_stamp_ns, leap_seconds_at_gps
from gnss_common.inav import InavAssembler
from gnss_common.lnav import KlobucharParams, LnavAssembler
from gnss_common.measurements import SKIP_REASONS, GnssEpochBuilder, MeasurementBuilderParams
from gnss_common.observations import GnssEpoch
from gnss_common.rinex import RinexObsEpoch

UBX_SYNC = b"\xb5\x62"
MAX_PAYLOAD_BYTES = 8192
"""Largest UBX payload accepted, bytes (the largest u-blox output, RXM-RAWX with 255
measurements, is 4096 + 16 bytes); a longer length field is taken as a corrupted header."""

GNSS_LETTERS = {0: "G", 1: "S", 2: "E", 3: "C", 5: "J", 6: "R", 7: "I"}
"""UBX gnssId -> RINEX satellite system letter (u-blox interface description, GNSS identifiers)."""

RINEX_CODES: dict[tuple[int, int], str] = {
    (0, 0): "1C", (0, 3): "2L", (0, 4): "2S", (0, 6): "5I", (0, 7): "5Q",
    (1, 0): "1C",
    (2, 0): "1C", (2, 1): "1B", (2, 3): "5I", (2, 4): "5Q", (2, 5): "7I", (2, 6): "7Q",
    (3, 0): "2I", (3, 1): "2I", (3, 2): "7I", (3, 3): "7I", (3, 5): "1P", (3, 7): "5P",
    (5, 0): "1C", (5, 1): "1Z", (5, 4): "2S", (5, 5): "2L", (5, 8): "5I", (5, 9): "5Q",
    (6, 0): "1C", (6, 2): "2C",
    (7, 0): "5A",
}
"""(gnssId, sigId) of UBX-RXM-RAWX -> RINEX 3 signal code (band + attribute; RINEX 3.04 Table 4,
u-blox F9 interface description, signal identifiers)."""

GALILEO_INAV_SIGNALS = (0, 1, 5)
"""UBX sigId of the Galileo signals whose RXM-SFRBX carries I/NAV: E1 (0 on u-blox M8, 1 = E1 B on
F9) and E5 bI (5)."""

REJECT_REASONS = ("bad_checksum", "bad_length", "truncated", "unparsable")
"""Frame-level rejections of :class:`UbxFramer` / :class:`UbxDecoder` (always all present)."""


def header_stamp_ns(week: int, tow_s: float) -> int:
    """Header stamp of a receive time given as GPS week / time of week: ROS time (UTC-based), ns.

    The suite's one conversion, :func:`gnss_common.gps_time.gps_to_ros_stamp_ns` (leap seconds
    from its table; the receiver's own leapS is kept in :class:`RawxEpoch`, and an epoch whose
    valid leapS differs from the table is counted as ``leap_seconds_disagree``).
    """
    return gps_to_ros_stamp_ns(week, tow_s)


# ------------------------------------------------------------------------------------------------
# framing


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


# ------------------------------------------------------------------------------------------------
# decoded records


@dataclass(frozen=True)
class RawxMeasurement:
    """One measurement of UBX-RXM-RAWX (one satellite, one signal).

    Attributes:
        gnss_id, sv_id, sig_id, freq_id: UBX identifiers (freq_id: GLONASS channel + 7).
        pseudorange_m: m; NaN when ``prValid`` is 0.
        carrier_phase_cycles: cycles; NaN when ``cpValid`` is 0.
        doppler_hz: Hz, positive for an approaching satellite (as RINEX).
        cn0_dbhz: dB-Hz (integer as reported).
        lock_time_s: carrier-phase lock time, s (capped at 64.5 s by the receiver).
        pseudorange_std_m: 0.01 * 2**prStdev, m.
        carrier_phase_std_cycles: 0.004 * cpStdev, cycles (NaN when cpStdev = 15: invalid).
        doppler_std_hz: 0.002 * 2**doStdev, Hz.
        pr_valid, cp_valid, half_cycle_resolved, half_cycle_subtracted: trkStat bits 0-3.
    """

    gnss_id: int
    sv_id: int
    sig_id: int
    freq_id: int
    pseudorange_m: float
    carrier_phase_cycles: float
    doppler_hz: float
    cn0_dbhz: float
    lock_time_s: float
    pseudorange_std_m: float
    carrier_phase_std_cycles: float
    doppler_std_hz: float
    pr_valid: bool
    cp_valid: bool
    half_cycle_resolved: bool
    half_cycle_subtracted: bool

    @property
    def satellite_id(self) -> str | None:
        """RINEX 3 satellite id ("G05", "E11", "S23" for SBAS PRN 123), None if not representable."""
        letter = GNSS_LETTERS.get(self.gnss_id)
        if letter is None:
            return None
        number = self.sv_id - 100 if letter == "S" else self.sv_id
        if letter == "J" and number > 10:
            number -= 192  # QZSS PRN 193.. reported as svId 193..
        if not 1 <= number <= 99:
            return None
        return f"{letter}{number:02d}"


@dataclass(frozen=True)
class RawxEpoch:
    """One UBX-RXM-RAWX message.

    Attributes:
        week: continuous GPS week of the receive time.
        tow_s: receive time of week (receiver local time), s.
        leap_seconds: GPS - UTC, s, as the receiver reports it; ``leap_seconds_valid`` its flag.
        clock_reset: recStat clkReset (receiver clock reset: phase and lock times restart).
        measurements: every measurement of the message, in message order.
    """

    week: int
    tow_s: float
    leap_seconds: int
    leap_seconds_valid: bool
    clock_reset: bool
    measurements: tuple[RawxMeasurement, ...]


def _num(msg: Any, name: str, default: float = math.nan) -> Any:
    return getattr(msg, name, default)


def rawx_from_message(msg: Any) -> RawxEpoch:
    """Decode a pyubx2 UBX-RXM-RAWX message (fields with the ``_NN`` suffix per measurement)."""
    meas = []
    for i in range(1, int(msg.numMeas) + 1):
        s = f"_{i:02d}"
        pr_valid = bool(_num(msg, "prValid" + s, 0))
        cp_valid = bool(_num(msg, "cpValid" + s, 0))
        cp_std = int(_num(msg, "cpStd" + s, 15))
        meas.append(RawxMeasurement(
            gnss_id=int(_num(msg, "gnssId" + s)),
            sv_id=int(_num(msg, "svId" + s)),
            sig_id=int(_num(msg, "sigId" + s, 0)),
            freq_id=int(_num(msg, "freqId" + s, 0)),
            pseudorange_m=float(_num(msg, "prMes" + s)) if pr_valid else math.nan,
            carrier_phase_cycles=float(_num(msg, "cpMes" + s)) if cp_valid else math.nan,
            doppler_hz=float(_num(msg, "doMes" + s)),
            cn0_dbhz=float(_num(msg, "cno" + s)),
            lock_time_s=float(_num(msg, "locktime" + s)) / 1000.0,
            pseudorange_std_m=0.01 * 2.0 ** int(_num(msg, "prStd" + s, 15)),
            carrier_phase_std_cycles=0.004 * cp_std if cp_std != 15 else math.nan,
            doppler_std_hz=0.002 * 2.0 ** int(_num(msg, "doStd" + s, 15)),
            pr_valid=pr_valid,
            cp_valid=cp_valid,
            half_cycle_resolved=bool(_num(msg, "halfCyc" + s, 0)),
            half_cycle_subtracted=bool(_num(msg, "subHalfCyc" + s, 0)),
        ))
    return RawxEpoch(
        week=int(msg.week),
        tow_s=float(msg.rcvTow),
        leap_seconds=int(_num(msg, "leapS", 0)),
        leap_seconds_valid=bool(_num(msg, "leapSec", 0)),
        clock_reset=bool(_num(msg, "clkReset", 0)),
        measurements=tuple(meas),
    )


def rawx_to_observations(rawx: RawxEpoch) -> tuple[RinexObsEpoch, int]:
    """RINEX 3 observables of one RAWX epoch, for :class:`GnssEpochBuilder`.

    Returns:
        ``(epoch, n_unmapped)``: satellite id -> {``C``/``L``/``D``/``S`` + signal code: value}
        (pseudorange m, phase cycles, Doppler Hz, C/N0 dB-Hz; invalid values NaN), and the
        number of measurements whose constellation or signal has no RINEX code here.
    """
    obs: dict[str, dict[str, float]] = {}
    unmapped = 0
    for m in rawx.measurements:
        code = RINEX_CODES.get((m.gnss_id, m.sig_id))
        sat = m.satellite_id
        if code is None or sat is None:
            unmapped += 1
            continue
        values = obs.setdefault(sat, {})
        values["C" + code] = m.pseudorange_m
        values["L" + code] = m.carrier_phase_cycles
        values["D" + code] = m.doppler_hz
        values["S" + code] = m.cn0_dbhz
    epoch = RinexObsEpoch(gps_week=rawx.week, tow_s=rawx.tow_s, epoch_flag=0,
                          receiver_clock_offset_s=math.nan, observations=obs, line_no=0)
    return epoch, unmapped


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


# ------------------------------------------------------------------------------------------------
# the decoder


@dataclass(frozen=True)
class UbxDecoderParams:
    """Parameters of :class:`UbxDecoder`.

    Attributes:
        min_satellites: an epoch is published only with at least this many modelled satellites
            (4: enough for a position); fewer are withheld and counted.
        use_receiver_std: put the receiver's prStdev / doStdev into the measurement's std fields
            (else NaN: the filter decides from C/N0).
        use_sfrbx: decode ephemerides (GPS LNAV, Galileo I/NAV) and the GPS Klobuchar parameters
            from RXM-SFRBX.
        max_ephemerides_per_satellite: records kept per PRN (the store picks the nearest t_oe).
        builder: parameters of :class:`GnssEpochBuilder` (observable codes, plausibility limits).
    """

    min_satellites: int = 4
    use_receiver_std: bool = True
    use_sfrbx: bool = True
    max_ephemerides_per_satellite: int = 4
    builder: MeasurementBuilderParams = field(default_factory=MeasurementBuilderParams)

    def __post_init__(self) -> None:
        if self.min_satellites < 1:
            raise ValueError(f"min_satellites must be >= 1, got {self.min_satellites}")
        if self.max_ephemerides_per_satellite < 1:
            raise ValueError("max_ephemerides_per_satellite must be >= 1")


@dataclass(frozen=True)
class EpochOutput:
    """A built epoch ready to publish, with what was skipped in it."""

    epoch: GnssEpoch
    rawx: RawxEpoch
    skipped: dict[str, int]


Output = EpochOutput | InterferenceReport

COUNTER_KEYS = (
    "frames", "skipped_bytes", *REJECT_REASONS, "unknown_messages", "rawx_epochs", "epochs_published",
    "epochs_waiting_for_ephemeris", "interference_reports", "interference_before_time",
    "leap_seconds_disagree", "sfrbx_subframes", "sfrbx_without_week", "ephemerides_decoded",
    "klobuchar_decoded", "unmapped_measurements", "ionosphere_unavailable",
)


class UbxDecoder:
    """UBX bytes in, :class:`EpochOutput` and :class:`InterferenceReport` out (see module docstring).

    Args:
        params: :class:`UbxDecoderParams`.
        ephemerides: broadcast records from a RINEX nav file (optional; SFRBX adds to them).
        iono_alpha, iono_beta: Klobuchar coefficients from that file (optional; SFRBX page 18
            replaces them when it arrives).
        reference_position_ecef_m: receiver position for the atmosphere models, m, (3,); None
            for the builder's per-epoch coarse fix.

    Attributes:
        counts: every counter of :data:`COUNTER_KEYS`.
        skipped: satellites skipped in published and withheld epochs, by reason
            (:data:`gnss_common.measurements.SKIP_REASONS`).
        ignored: messages decoded but not used, by pyubx2 identity (e.g. ``NAV-PVT``).
        lnav_rejected, inav_rejected: SFRBX GPS subframes / Galileo pages rejected, by reason.
    """

    def __init__(
        self,
        params: UbxDecoderParams | None = None,
        ephemerides: Sequence[GpsEphemeris] = (),
        iono_alpha: np.ndarray | None = None,
        iono_beta: np.ndarray | None = None,
        reference_position_ecef_m: np.ndarray | None = None,
    ) -> None:
        self.params = params if params is not None else UbxDecoderParams()
        self._framer = UbxFramer()
        self._lnav = LnavAssembler()
        self._inav = InavAssembler()
        self._ephs: dict[tuple[str, int], list[Any]] = {}
        for e in ephemerides:
            self._ephs.setdefault((getattr(e, "system", "G"), e.prn), []).append(e)
        self._alpha = iono_alpha
        self._beta = iono_beta
        self._ref = reference_position_ecef_m
        self._builder: GnssEpochBuilder | None = None
        self._pending_sfrbx: list[Any] = []
        self._last_time: tuple[int, int, float] | None = None
        self.counts: Counter[str] = Counter(dict.fromkeys(COUNTER_KEYS, 0))
        self.skipped: Counter[str] = Counter(dict.fromkeys(SKIP_REASONS, 0))
        self.ignored: Counter[str] = Counter()

    @property
    def lnav_rejected(self) -> dict[str, int]:
        """GPS LNAV subframes rejected, by reason (:data:`gnss_common.lnav.LNAV_REJECT_REASONS`)."""
        return dict(self._lnav.rejected)

    @property
    def inav_rejected(self) -> dict[str, int]:
        """Galileo I/NAV pages rejected, by reason (:data:`gnss_common.inav.INAV_REJECT_REASONS`)."""
        return dict(self._inav.rejected)

    @property
    def satellites_with_ephemeris(self) -> tuple[str, ...]:
        """RINEX ids ("G05", "E11") of the satellites with at least one ephemeris."""
        return tuple(f"{s}{p:02d}" for s, p in sorted(self._ephs))

    def _sync_counts(self) -> None:
        self.counts["frames"] = self._framer.frames
        self.counts["skipped_bytes"] = self._framer.skipped_bytes
        for k, v in self._framer.rejected.items():
            self.counts[k] = v

    def feed(self, chunk: bytes) -> list[Output]:
        """Decode a chunk of the byte stream; returns the outputs completed by it, in order."""
        out: list[Output] = []
        for frame in self._framer.feed(chunk):
            out.extend(self.process_frame(frame))
        self._sync_counts()
        return out

    def discard_partial_frame(self) -> None:
        """The byte stream broke (a serial port lost and reopened): a frame cut by the break is counted
        as truncated and dropped, so that it is not glued to the bytes of the new connection."""
        self._framer.finish()
        self._sync_counts()

    def finish(self) -> None:
        """End of stream: counts a truncated last frame, and SFRBX that never got a week (no RAWX)."""
        self.counts["sfrbx_without_week"] += len(self._pending_sfrbx)
        self._pending_sfrbx = []
        self._framer.finish()
        self._sync_counts()

    def process_frame(self, frame: bytes) -> list[Output]:
        """Decode one checksum-valid UBX frame."""
        from pyubx2 import UBXReader

        try:
            msg = UBXReader.parse(frame)
            ident = msg.identity
        except Exception:  # noqa: BLE001 (pyubx2 raises several types for unknown or malformed payloads)
            self.counts["unparsable"] += 1
            return []
        try:
            if ident == "RXM-RAWX":
                return self._on_rawx(rawx_from_message(msg))
            if ident == "RXM-SFRBX":
                self._on_sfrbx(msg)
                return []
            if ident in ("MON-HW", "MON-RF", "SEC-SIG"):
                if self._last_time is None:
                    self.counts["interference_before_time"] += 1
                    return []
                stamp, week, tow = self._last_time
                reports = interference_from_message(msg, stamp, week, tow)
                self.counts["interference_reports"] += len(reports)
                return list(reports)
        except (AttributeError, TypeError, ValueError):
            self.counts["unparsable"] += 1
            return []
        if ident.startswith("UNKNOWN"):  # pyubx2 names a class/id it has no definition for UNKNOWN-ccii-...
            self.counts["unknown_messages"] += 1
        else:
            self.ignored[ident] += 1
        return []

    # -- ephemerides ------------------------------------------------------------------------

    def _add_ephemeris(self, eph: GpsEphemeris) -> None:
        records = self._ephs.setdefault((eph.system, eph.prn), [])
        records[:] = [e for e in records if not (e.iodc == eph.iodc and e.toe_s == eph.toe_s and e.week == eph.week)]
        records.append(eph)
        del records[: max(0, len(records) - self.params.max_ephemerides_per_satellite)]
        self._builder = None

    def _on_sfrbx(self, msg: Any) -> None:
        if not self.params.use_sfrbx:
            self.ignored["RXM-SFRBX"] += 1
            return
        gnss, sig = int(msg.gnssId), int(getattr(msg, "sigId", 0))
        if not (gnss == 0 and sig == 0) and not (gnss == 2 and sig in GALILEO_INAV_SIGNALS):
            self.ignored["RXM-SFRBX (not GPS L1 C/A, not Galileo I/NAV)"] += 1
            return
        if self._last_time is None:  # the broadcast week needs a reference: wait for the first RAWX
            if len(self._pending_sfrbx) < 1000:
                self._pending_sfrbx.append(msg)
            return
        self.counts["sfrbx_subframes"] += 1
        words = [int(getattr(msg, f"dwrd_{i:02d}")) for i in range(1, int(msg.numWords) + 1)]
        if gnss == 2:
            eph = self._inav.add(int(msg.svId), words, self._last_time[1])
            if eph is not None:
                self.counts["ephemerides_decoded"] += 1
                self._add_ephemeris(eph)
            return
        result = self._lnav.add(int(msg.svId), words, self._last_time[1])
        if isinstance(result, GpsEphemeris):
            self.counts["ephemerides_decoded"] += 1
            self._add_ephemeris(result)
        elif isinstance(result, KlobucharParams):
            self.counts["klobuchar_decoded"] += 1
            self._alpha, self._beta = result.alpha, result.beta
            self._builder = None

    # -- epochs -----------------------------------------------------------------------------

    def _get_builder(self) -> GnssEpochBuilder:
        if self._builder is None:
            ephs = [e for records in self._ephs.values() for e in records]
            self._builder = GnssEpochBuilder(ephs, self._alpha, self._beta, self._ref, self.params.builder)
        return self._builder

    def _on_rawx(self, rawx: RawxEpoch) -> list[Output]:
        self.counts["rawx_epochs"] += 1
        stamp = header_stamp_ns(rawx.week, rawx.tow_s)
        if rawx.leap_seconds_valid and rawx.leap_seconds != leap_seconds_at_gps(rawx.week, rawx.tow_s):
            self.counts["leap_seconds_disagree"] += 1  # the stamp keeps the suite's table; counted
        self._last_time = (stamp, rawx.week, rawx.tow_s)
        if self._pending_sfrbx:
            pending, self._pending_sfrbx = self._pending_sfrbx, []
            for msg in pending:
                self._on_sfrbx(msg)
        obs_epoch, unmapped = rawx_to_observations(rawx)
        self.counts["unmapped_measurements"] += unmapped
        result = self._get_builder().build(obs_epoch)
        for reason, n in result.skipped.items():
            self.skipped[reason] += n
        epoch = result.epoch
        if len(epoch.observations) < self.params.min_satellites:
            self.counts["epochs_waiting_for_ephemeris"] += 1
            return []
        self.counts["ionosphere_unavailable"] += int(result.extra.get("ionosphere_unavailable", 0.0))
        if self.params.use_receiver_std:
            epoch = replace(epoch, observations=tuple(self._with_std(o, rawx) for o in epoch.observations))
        epoch = replace(epoch, stamp_ns=stamp)
        self.counts["epochs_published"] += 1
        return [EpochOutput(epoch=epoch, rawx=rawx, skipped=dict(result.skipped))]

    @staticmethod
    def _with_std(obs: Any, rawx: RawxEpoch) -> Any:
        """The receiver's std of the RAWX measurement the builder took (the one whose pseudorange
        it copied); rate std = |wavelength| * doStdev with the wavelength of that signal."""
        for m in rawx.measurements:
            if m.pr_valid and m.pseudorange_m == obs.pseudorange_m:
                rate_std = math.nan
                if m.doppler_hz != 0.0 and math.isfinite(obs.pseudorange_rate_mps):
                    rate_std = abs(obs.pseudorange_rate_mps / m.doppler_hz) * m.doppler_std_hz
                return replace(obs, pseudorange_std_m=m.pseudorange_std_m, pseudorange_rate_std_mps=rate_std)
        return obs


def decode_stream(chunks: Iterable[bytes], decoder: UbxDecoder) -> list[Output]:
    """Run a whole stream (e.g. a file read in chunks) through ``decoder``; returns every output."""
    out: list[Output] = []
    for chunk in chunks:
        out.extend(decoder.feed(chunk))
    decoder.finish()
    return out
