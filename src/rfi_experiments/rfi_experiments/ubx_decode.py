"""u-blox UBX stream -> GNSS measurement epochs and the receiver's interference indicators (pure).

Never imports rclpy: :mod:`rfi_experiments.ubx_to_bag` (a tool) and
:mod:`rfi_experiments.ubx_source` (a node) are thin layers around :class:`UbxDecoder`.

Pipeline
--------
1. :class:`~rfi_experiments.ubx_framing.UbxFramer` cuts a byte stream (file chunks or whatever a
   serial port returned) into UBX frames: sync ``B5 62``, class, id, length, payload, Fletcher
   checksum. A frame with a bad checksum or an impossible length is counted and the search
   resumes one byte after its sync (so one corrupted length field does not swallow the good
   frames after it); bytes outside UBX frames (NMEA, RTCM, noise) are counted; a frame cut by the
   end of the stream is counted as truncated.
2. The frame's fields are decoded by pyubx2 (``UBXReader.parse``, the parser the field uses);
   a frame pyubx2 cannot parse is counted as ``unparsable``, one of a class / id pyubx2 does not
   know as ``unknown_messages``, a known message this module does not use by its identity
   (``ignored``).
3. UBX-RXM-RAWX -> :class:`~rfi_experiments.ubx_rawx.RawxEpoch` (every measurement, every
   constellation and signal, with pseudorange / carrier-phase / Doppler, C/N0, lock time, the
   std fields and the tracking status flags). ``prValid`` = 0 makes the pseudorange NaN;
   ``cpValid`` = 0 the carrier phase NaN; the carrier phase is kept with ``half_cycle_resolved``
   (``halfCyc``) and ``half_cycle_subtracted`` (``subHalfCyc``) so that a user of the phase can
   refuse an unresolved half cycle (the measurement message of the suite carries no phase).
4. The RAWX epoch is converted to RINEX 3 observables (``C1C``, ``D1C``, ``S1C``, ``L1C``, ... per
   constellation and signal, :data:`RINEX_CODES`) and built into a
   :class:`gnss_common.observations.GnssEpoch` by :class:`gnss_common.measurements.GnssEpochBuilder`,
   the same code ``rinex_to_bag`` uses (satellite state at transmission, broadcast clock,
   Klobuchar, Saastamoinen): one implementation. Whatever that builder cannot model is skipped
   and counted by its reason.
5. Broadcast ephemerides come from UBX-RXM-SFRBX (GPS LNAV subframes 1-3 and the Klobuchar page,
   :class:`gnss_common.lnav.LnavAssembler`; Galileo I/NAV word types 1-5,
   :class:`gnss_common.inav.InavAssembler`) and/or a RINEX navigation file given by the user.
   A satellite without a usable ephemeris (none yet, e.g. a log or stream without SFRBX; or only
   stale ones) is published, with ``publish_without_ephemeris``, with NaN satellite states
   (position, velocity, clock, ionosphere, troposphere) and its real pseudorange, Doppler rate
   and C/N0, and counted (``satellites_without_ephemeris``): the C/N0 jamming tests need no
   ephemeris, and a position filter rejects and counts such a satellite (the fusion as
   ``nonfinite_pseudorange``). Never a valid-looking state. An epoch with fewer than
   ``min_satellites`` satellites to publish is withheld and counted
   (``epochs_waiting_for_ephemeris``).
6. UBX-MON-HW, UBX-MON-RF (one record per RF block) and UBX-SEC-SIG ->
   :class:`~rfi_experiments.ubx_reports.InterferenceReport`; UBX-MON-SPAN -> one
   :class:`~rfi_experiments.ubx_reports.SpectrumReport` per RF block (256 bins, 0.25 dB units ->
   dB). Both are stamped with the receive time of the latest RAWX epoch (these messages carry no
   time of their own; a report before the first RAWX is counted and dropped).

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
from gnss_common.measurements import (
    CONSTELLATION_CODES,
    SKIP_REASONS,
    GnssEpochBuilder,
    MeasurementBuilderParams,
)
from gnss_common.observations import GnssEpoch
from rfi_experiments.ubx_framing import MAX_PAYLOAD_BYTES, UBX_SYNC, UbxFramer, ubx_checksum
from rfi_experiments.ubx_rawx import (
    GNSS_LETTERS,
    RINEX_CODES,
    RawxEpoch,
    RawxMeasurement,
    observation_without_ephemeris,
    rawx_from_message,
    rawx_to_observations,
)
from rfi_experiments.ubx_reports import (
    JAMMING_CRITICAL,
    JAMMING_OK,
    JAMMING_UNKNOWN,
    JAMMING_WARNING,
    SOURCE_MON_HW,
    SOURCE_MON_RF,
    SOURCE_SEC_SIG,
    InterferenceReport,
    SpectrumReport,
    interference_from_message,
    spectrum_from_message,
)
from rfi_node_common.params import parameter

__all__ = [  # the framing and report names are re-exported: callers import them from here
    "JAMMING_CRITICAL", "JAMMING_OK", "JAMMING_UNKNOWN", "JAMMING_WARNING", "MAX_PAYLOAD_BYTES",
    "SOURCE_MON_HW", "SOURCE_MON_RF", "SOURCE_SEC_SIG", "UBX_SYNC", "EpochOutput", "InterferenceReport",
    "RawxEpoch", "RawxMeasurement", "SpectrumReport", "UbxDecoder", "UbxDecoderParams", "UbxFramer",
    "GNSS_LETTERS", "RINEX_CODES", "decode_stream", "header_stamp_ns", "interference_from_message",
    "observation_without_ephemeris", "rawx_from_message",
    "rawx_to_observations", "spectrum_from_message", "ubx_checksum",
]

GALILEO_INAV_SIGNALS = (0, 1, 5)
"""UBX sigId of the Galileo signals whose RXM-SFRBX carries I/NAV: E1 (0 on u-blox M8, 1 = E1 B on
F9) and E5 bI (5)."""

REJECT_REASONS = ("bad_checksum", "bad_length", "truncated", "unparsable")
"""Frame-level rejections of :class:`UbxFramer` / :class:`UbxDecoder` (always all present)."""

WITHOUT_EPHEMERIS = ("no_ephemeris", "stale_ephemeris")
"""Builder skip reasons of a satellite that is published with NaN states under
``publish_without_ephemeris`` (an unhealthy satellite stays skipped)."""


def header_stamp_ns(week: int, tow_s: float) -> int:
    """Header stamp of a receive time given as GPS week / time of week: ROS time (UTC-based), ns.

    The suite's one conversion, :func:`gnss_common.gps_time.gps_to_ros_stamp_ns` (leap seconds
    from its table; the receiver's own leapS is kept in :class:`RawxEpoch`, and an epoch whose
    valid leapS differs from the table is counted as ``leap_seconds_disagree``).
    """
    return gps_to_ros_stamp_ns(week, tow_s)


# ------------------------------------------------------------------------------------------------
# the decoder


@dataclass(frozen=True)
class UbxDecoderParams:
    """Parameters of :class:`UbxDecoder`.

    Fields written with :func:`rfi_node_common.params.parameter` are also parameters of ubx_source: their
    default, description and range are there, once.

    Attributes:
        max_ephemerides_per_satellite: records kept per PRN (the store picks the nearest t_oe).
        builder: parameters of :class:`GnssEpochBuilder` (observable codes, plausibility limits).
    """

    min_satellites: int = parameter(
        4, 'An epoch is published only with at least this many satellites (modelled: ephemeris present, healthy, '
        'plausible pseudorange; with publish_without_ephemeris also those without ephemeris); fewer: counted as '
        'epochs_waiting_for_ephemeris. 4 = enough for a position; 1 publishes whatever there is.',
        minimum=1, maximum=64)
    use_receiver_std: bool = parameter(
        True, "Fill pseudorange_std_m / pseudorange_rate_std_mps from the receiver's prStdev / doStdev. false: NaN, "
        'and the fusion weights by C/N0 (and J/S) instead.')
    use_sfrbx: bool = parameter(
        True, 'Decode GPS LNAV subframes 1-3 (ephemeris) and subframe 4 page 18 (Klobuchar), and Galileo I/NAV word '
        'types 1-5 (ephemeris, clock, BGD, health), from RXM-SFRBX. false: ephemerides only from nav_file.')
    publish_without_ephemeris: bool = parameter(
        True, 'Satellites without a usable ephemeris (none decoded yet, RXM-SFRBX off and no nav_file, or only '
        'stale records) are published with NaN satellite states (position, velocity, clock, ionosphere, '
        'troposphere) and their real pseudorange, Doppler rate and C/N0, counted as satellites_without_ephemeris: '
        'the C/N0 jamming test of gnss_integrity works without ephemeris; the fusion rejects such satellites and '
        'counts them (nonfinite_pseudorange). false: skip them (counted as skipped_no_ephemeris / '
        'skipped_stale_ephemeris).')
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


Output = EpochOutput | InterferenceReport | SpectrumReport

COUNTER_KEYS = (
    "frames", "skipped_bytes", *REJECT_REASONS, "unknown_messages", "rawx_epochs", "epochs_published",
    "epochs_waiting_for_ephemeris", "satellites_without_ephemeris", "interference_reports",
    "interference_before_time", "spectrum_reports", "spectrum_before_time",
    "leap_seconds_disagree", "sfrbx_subframes", "sfrbx_without_week", "ephemerides_decoded",
    "klobuchar_decoded", "unmapped_measurements", "ionosphere_unavailable",
)


class UbxDecoder:
    """UBX bytes in, :class:`EpochOutput`, :class:`InterferenceReport` and :class:`SpectrumReport`
    out (see the module docstring).

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
            (:data:`gnss_common.measurements.SKIP_REASONS`; those published with NaN states under
            ``publish_without_ephemeris`` are counted in ``satellites_without_ephemeris`` instead).
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
            if ident == "MON-SPAN":
                if self._last_time is None:
                    self.counts["spectrum_before_time"] += 1
                    return []
                spectra = spectrum_from_message(msg, *self._last_time)
                self.counts["spectrum_reports"] += len(spectra)
                return list(spectra)
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
        unmodelled = [(sat, reason) for sat, reason in result.skipped_satellites
                      if self.params.publish_without_ephemeris and reason in WITHOUT_EPHEMERIS]
        skipped = dict(result.skipped)
        if len(result.epoch.observations) + len(unmodelled) < self.params.min_satellites:
            self.skipped.update(skipped)
            self.counts["epochs_waiting_for_ephemeris"] += 1
            return []
        for _, reason in unmodelled:
            skipped[reason] -= 1
        self.skipped.update(skipped)
        self.counts["satellites_without_ephemeris"] += len(unmodelled)
        self.counts["ionosphere_unavailable"] += int(result.extra.get("ionosphere_unavailable", 0.0))
        letters = {code: letter for letter, code in CONSTELLATION_CODES.items()}
        by_sat = {f"{letters[o.constellation]}{o.svid:02d}": o for o in result.epoch.observations}
        for sat, _ in unmodelled:
            by_sat[sat] = observation_without_ephemeris(sat, obs_epoch.observations[sat], rawx, self.params.builder)
        observations = tuple(by_sat[sat] for sat in sorted(by_sat))
        if self.params.use_receiver_std:
            observations = tuple(self._with_std(o, rawx) for o in observations)
        epoch = replace(result.epoch, stamp_ns=stamp, observations=observations)
        self.counts["epochs_published"] += 1
        return [EpochOutput(epoch=epoch, rawx=rawx, skipped=skipped)]

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
