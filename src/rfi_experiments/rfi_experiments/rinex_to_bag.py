"""``rinex_to_bag OBS NAV [NAV ...] OUT``: real RINEX observations -> a bag the fusion node can replay.

Each observation epoch of the RINEX 2/3/4 file (plain or compressed: ``.gz``, ``.Z``, Hatanaka
``.crx`` / ``.crx.gz`` as stations publish them) becomes one ``rfi_msgs/GnssMeasurementArray`` on
``/gnss/measurements``, built by :class:`gnss_common.measurements.GnssEpochBuilder` for every
constellation whose satellite state can be computed from the navigation file(s) given (one mixed
file or one per system): GPS and QZSS L1, Galileo E1, BeiDou B1I, GLONASS G1 (integrated
orbits): pseudorange, Doppler rate (with the signal's wavelength), C/N0, carrier frequency,
satellite state at transmission, broadcast clock, Klobuchar (scaled to the carrier) and
Saastamoinen delays. Every tracking attribute of the signal's band is read (RINEX 3.05 / 4.00
tables: e.g. B1I as ``C2I``, ``C2X`` or ``C2Q``; Galileo E1 as ``C1C``, ``C1X``, ``C1B``, ...); one
is picked per satellite and epoch by the priority of
:data:`gnss_common.observation_codes.DEFAULT_SIGNALS`, and pseudorange, Doppler and C/N0 all
come from it. The codes used are counted per constellation, printed in the summary and stored in
the bag's metadata (``custom_data``: :data:`CODES_METADATA_KEY`, :data:`PRIORITY_METADATA_KEY`,
JSON). ``--constellations`` restricts the set. SBAS and NavIC satellites are skipped
(no orbit model here) and counted, as every skipped satellite is, per constellation and reason.
When the observation header has an APPROX POSITION XYZ, the same point is
written on ``/truth/position`` (``geometry_msgs/PointStamped``, frame "earth") at every epoch: it
is the station's published coordinate, used as truth for a static receiver.

``--ionosphere-free``: the GPS pseudoranges are the ionosphere-free combination of the L1 and L2
P(Y) codes (RINEX 2 ``P1``/``P2``, RINEX 3/4 ``C1W``/``C2W``) with ``ionosphere_delay_m`` 0 and
the broadcast clock without T_GD (IS-GPS-200, 20.3.3.3.3.2-3); Doppler, C/N0 and the carrier stay
L1's. A GPS satellite without both codes is skipped (``missing_dual_frequency``); C/A with P2 is
not combined (each satellite's P1-C1 code bias, times 2.55, is in no broadcast message). The bag's
metadata says which (:data:`IONOSPHERE_FREE_METADATA_KEY`). The filter weighs these ranges as L1
ranges (their code noise is about 3x larger; on a static station the averaging absorbs it).

``--ionosphere carrier-levelled``: each GPS satellite's ``ionosphere_delay_m`` follows the
geometry-free combination of its L1 and L2 carrier phases (RINEX 2 ``L1``/``L2``, RINEX 3/4 the
first of :data:`gnss_common.rinex_ionosphere.GPS_PHASE_CODES` in the header), levelled per arc to
the mean of the broadcast Klobuchar delay over the arc (:func:`gnss_common.corrections.carrier_levelled_ionosphere_m`;
cycle slips and gaps start a new arc). A satellite or epoch without both carriers keeps Klobuchar;
both are counted (``levelled`` / ``model``), printed in the summary and the choice is stored in the
bag's metadata (:data:`IONOSPHERE_METADATA_KEY`). It uses each whole arc, i.e. future epochs: a
file converter's post-processing. Default ``klobuchar``: the broadcast model alone.

Time base: header stamps and bag log times are ROS time (UTC-based Unix time, integer ns), converted
from each epoch's GPS time by :func:`gnss_common.gps_time.gps_to_ros_stamp_ns` (leap seconds from
its one table); the exact GPS week and time of week are in the message's ``gps_week`` and
``gps_time_of_week_s``.

Satellites are skipped, and counted by reason, when they cannot be modelled (reasons of
:data:`gnss_common.measurements.SKIP_REASONS`) or when they are below the elevation mask seen
from the builder's reference position (``below_elevation_mask``; the mask cannot be applied
in an epoch without a reference position, counted as ``epochs_without_reference``).

Notes
-----
No new equations: measurement modelling is Cao et al., eq. 5-6 as implemented in
:mod:`gnss_common.measurements`; the elevation is computed as there (Earth-rotation-corrected
satellite position, Hofmann-Wellenhof et al. 2008, eq. 10.41-10.43).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from gnss_common.coordinates import azimuth_elevation
from gnss_common.ephemeris import earth_rotation_correction
from gnss_common.measurements import (
    CONSTELLATION_CODES,
    SKIP_REASONS,
    SUPPORTED_SYSTEMS,
    EpochBuildResult,
    GnssEpochBuilder,
    MeasurementBuilderParams,
)
from gnss_common.observations import GnssEpoch
from gnss_common.rinex import SYSTEM_NAMES, RinexFormatError, read_rinex_navs, read_rinex_obs
from gnss_common.rinex_format import add_counts, add_counts_by_group
from gnss_common.rinex_ionosphere import level_gps_ionosphere
from rfi_experiments import cli
from rfi_experiments.bag_io import BagError, BagWriter
from rfi_experiments.cli import error_reporter
from rfi_experiments.progress import ProgressLine
from rfi_node_common.conversions import epoch_to_msg, point_to_msg

PROG = "rinex_to_bag"
_fail = error_reporter(PROG)
MEASUREMENTS_TOPIC = "/gnss/measurements"
TRUTH_TOPIC = "/truth/position"
EARTH_FRAME_ID = "earth"
BELOW_MASK = "below_elevation_mask"
CODES_METADATA_KEY = "gnss_observation_codes"
"""Bag ``custom_data`` key: JSON ``{constellation: {pseudorange observable: measurements}}``, e.g.
``{"beidou": {"C2X": 20099}}`` (Doppler and C/N0 of each measurement are of the same attribute)."""
PRIORITY_METADATA_KEY = "gnss_observation_code_priority"
"""Bag ``custom_data`` key: JSON ``{constellation: [pseudorange observables in the order tried]}``
for the file's RINEX version (:data:`gnss_common.observation_codes.DEFAULT_SIGNALS`)."""
IONOSPHERE_METADATA_KEY = "gnss_ionosphere"
"""Bag ``custom_data`` key: where ``ionosphere_delay_m`` comes from, one of :data:`IONOSPHERE_SOURCES`,
plus the counts, as JSON (``{"source": ..., "levelled": n, "model": n}``)."""
IONOSPHERE_SOURCES = ("klobuchar", "carrier-levelled")
"""``--ionosphere`` choices: the broadcast Klobuchar model alone (default); or GPS delays from the
L1/L2 carrier, levelled per arc to Klobuchar's mean (module docstring)."""
IONOSPHERE_FREE_METADATA_KEY = "gnss_ionosphere_free"
"""Bag ``custom_data`` key: ``"true"`` when the GPS pseudoranges are the ionosphere-free L1/L2 P(Y)
combination (``--ionosphere-free``; ``ionosphere_delay_m`` 0, clock without T_GD), else ``"false"``."""


@dataclass(frozen=True)
class RinexConversion:
    """Epochs ready to be written, and what was dropped on the way.

    Attributes:
        epochs: one GnssEpoch per RINEX epoch (flags 0 and 1), in file order.
        truth_position_ecef_m: header APPROX POSITION XYZ, m, (3,), or None when absent.
        skipped: reason -> satellites skipped over the whole file (``SKIP_REASONS`` plus
            ``below_elevation_mask``).
        epochs_without_reference: epochs where no reference position existed, so the elevation
            mask was not applied.
        skipped_by_constellation: constellation name ("gps", "galileo", ...) -> reason -> satellite
            measurements skipped over the file (nonzero entries only).
        nav_records: system letter -> navigation records used; ``nav_skipped``: system letter ->
            reason -> navigation records not used (e.g. SBAS, Galileo F/NAV).
        codes_by_constellation: constellation name -> pseudorange observable (``"C2X"``,
            ``"C1C"``, RINEX 2 ``"C1"``) -> measurements written from it (pseudorange, Doppler and
            C/N0 of one tracking attribute).
        code_priority: constellation name -> pseudorange observables in the order they were tried
            (for the file's RINEX version), for the constellations converted.
        ionosphere_free: the GPS pseudoranges are the ionosphere-free P1/P2 combination
            (:attr:`gnss_common.measurements.MeasurementBuilderParams.ionosphere_free`).
        ionosphere: source of ``ionosphere_delay_m``, one of :data:`IONOSPHERE_SOURCES`;
            ``ionosphere_counts``: GPS measurements with a ``levelled`` delay and with the ``model``'s
            (``carrier-levelled`` only).
    """

    epochs: tuple[GnssEpoch, ...]
    truth_position_ecef_m: np.ndarray | None
    skipped: dict[str, int] = field(default_factory=dict)
    epochs_without_reference: int = 0
    skipped_by_constellation: dict[str, dict[str, int]] = field(default_factory=dict)
    nav_records: dict[str, int] = field(default_factory=dict)
    nav_skipped: dict[str, dict[str, int]] = field(default_factory=dict)
    codes_by_constellation: dict[str, dict[str, int]] = field(default_factory=dict)
    code_priority: dict[str, tuple[str, ...]] = field(default_factory=dict)
    ionosphere_free: bool = False
    ionosphere: str = "klobuchar"
    ionosphere_counts: dict[str, int] = field(default_factory=dict)

    @property
    def measurement_count(self) -> int:
        """Satellite measurements over all epochs."""
        return sum(len(e.observations) for e in self.epochs)

    def measurements_by_constellation(self) -> dict[str, int]:
        """Constellation name -> satellite measurements written over all epochs."""
        names = {code: SYSTEM_NAMES[letter] for letter, code in CONSTELLATION_CODES.items()}
        out: dict[str, int] = {}
        for e in self.epochs:
            for o in e.observations:
                name = names.get(o.constellation, str(o.constellation))
                out[name] = out.get(name, 0) + 1
        return out


def apply_elevation_mask(result: EpochBuildResult, mask_rad: float) -> tuple[GnssEpoch, int, bool]:
    """Drop the satellites of one built epoch whose elevation is below ``mask_rad``.

    Args:
        result: output of :meth:`GnssEpochBuilder.build`.
        mask_rad: elevation mask, rad, in [-pi/2, pi/2].

    Returns:
        ``(epoch, n_dropped, applied)``: the masked epoch, the number of satellites removed, and
        False when the epoch had no reference position (then nothing is removed). Use
        :func:`elevation_mask_drops` for the dropped satellites by constellation.

    Notes
    -----
    Elevation of the Earth-rotation-corrected satellite position seen from the builder's
    reference position (as :mod:`gnss_common.measurements` does for the atmosphere models).
    """
    epoch = result.epoch
    if not epoch.observations:
        return epoch, 0, True
    ref = np.asarray(result.reference_position_ecef_m, dtype=float)
    if result.reference_source == "none" or not np.all(np.isfinite(ref)):
        return epoch, 0, False
    sats = np.array([o.satellite_position_ecef_m for o in epoch.observations], dtype=float)
    rotated, _, _ = earth_rotation_correction(sats, ref)
    _, el = azimuth_elevation(ref, rotated)
    keep = tuple(o for o, e in zip(epoch.observations, np.atleast_1d(el), strict=True) if e >= mask_rad)
    return replace(epoch, observations=keep), len(epoch.observations) - len(keep), True


def convert_rinex(
    obs_path: str | Path,
    nav_path: str | Path | Sequence[str | Path],
    elevation_mask_deg: float = 0.0,
    constellations: Sequence[str] = SUPPORTED_SYSTEMS,
    progress: ProgressLine | None = None,
    ionosphere_free: bool = False,
    ionosphere: str = "klobuchar",
) -> RinexConversion:
    """Read a RINEX observation file and its navigation file(s) and build every epoch.

    Args:
        obs_path: RINEX 2.x / 3.x observation file (plain or compressed).
        nav_path: RINEX 2.x / 3.x navigation file, or several (e.g. one per system).
        elevation_mask_deg: satellites below this elevation, deg, in [-90, 90], are dropped.
        constellations: RINEX system letters to convert (of
            :data:`gnss_common.measurements.SUPPORTED_SYSTEMS`); the others are skipped and counted.
        progress: if given, gets the number of epochs as its total and one count per epoch built (the
            slow part: satellite positions), and is closed at the end.
        ionosphere_free: GPS pseudoranges as the ionosphere-free combination of the L1 and L2 P(Y)
            codes (RINEX 2 ``P1``/``P2``, RINEX 3/4 ``C1W``/``C2W``), without ionospheric model and
            T_GD; GPS satellites without both are skipped as ``missing_dual_frequency``
            (:attr:`gnss_common.measurements.MeasurementBuilderParams.ionosphere_free`).
        ionosphere: ``"klobuchar"`` (broadcast model) or ``"carrier-levelled"`` (GPS delays from the
            L1/L2 carriers levelled to Klobuchar per arc,
            :func:`gnss_common.rinex_ionosphere.level_gps_ionosphere`).

    Returns:
        :class:`RinexConversion`.

    Raises:
        RinexFormatError: unreadable or malformed file (the message names file and line).
        ValueError: invalid mask or constellation, no epochs in the file, or an unusable header
            position.
    """
    if not (math.isfinite(elevation_mask_deg) and -90.0 <= elevation_mask_deg <= 90.0):
        raise ValueError(f"--elevation-mask-deg must be in [-90, 90], got {elevation_mask_deg}")
    if ionosphere not in IONOSPHERE_SOURCES:
        raise ValueError(f"--ionosphere must be one of {', '.join(IONOSPHERE_SOURCES)}, got {ionosphere!r}")
    if ionosphere != "klobuchar" and ionosphere_free:
        raise ValueError("--ionosphere carrier-levelled and --ionosphere-free exclude each other")
    params = MeasurementBuilderParams(constellations=tuple(constellations), ionosphere_free=ionosphere_free)
    obs = read_rinex_obs(obs_path)
    navs = [nav_path] if isinstance(nav_path, (str, Path)) else list(nav_path)
    nav = read_rinex_navs(navs)
    if not obs.epochs:
        raise ValueError(f"{obs_path}: no observation epochs")
    builder = GnssEpochBuilder.from_rinex(obs, nav, params)
    mask_rad = math.radians(elevation_mask_deg)
    skipped = dict.fromkeys((*SKIP_REASONS, BELOW_MASK), 0)
    by_system: dict[str, dict[str, int]] = {}
    names = {code: SYSTEM_NAMES[letter] for letter, code in CONSTELLATION_CODES.items()}
    letters = {code: letter for letter, code in CONSTELLATION_CODES.items()}
    codes: dict[str, dict[str, int]] = {}
    epochs = []
    without_ref = 0
    if progress is not None:
        progress.total = len(obs.epochs)
    for rinex_epoch in (obs.epochs if progress is None else progress.iterate(obs.epochs)):
        result = builder.build(rinex_epoch)
        add_counts(skipped, result.skipped)
        add_counts_by_group(by_system, result.skipped_by_constellation)
        epoch, dropped, applied = apply_elevation_mask(result, mask_rad)
        skipped[BELOW_MASK] += dropped
        if dropped:
            kept = {id(o) for o in epoch.observations}
            for o in result.epoch.observations:
                if id(o) not in kept:
                    dst = by_system.setdefault(names.get(o.constellation, str(o.constellation)), {})
                    dst[BELOW_MASK] = dst.get(BELOW_MASK, 0) + 1
        without_ref += 0 if applied else 1
        for o in epoch.observations:
            used = result.signal_codes[f"{letters[o.constellation]}{o.svid:02d}"]
            dst = codes.setdefault(names[o.constellation], {})
            dst[used] = dst.get(used, 0) + 1
        epochs.append(epoch)
    iono_counts: dict[str, int] = {}
    if ionosphere == "carrier-levelled":
        epochs, iono_counts = level_gps_ionosphere(obs, epochs)
    truth = obs.header.approx_position_ecef_m
    return RinexConversion(
        epochs=tuple(epochs),
        truth_position_ecef_m=None if truth is None else np.asarray(truth, dtype=float).copy(),
        skipped=skipped,
        epochs_without_reference=without_ref,
        skipped_by_constellation=by_system,
        nav_records=nav.record_counts(),
        nav_skipped={k: dict(v) for k, v in nav.skipped_reasons.items()},
        codes_by_constellation=codes,
        code_priority={
            SYSTEM_NAMES[letter]: params.signals[letter].pseudorange_observables(obs.header.version)
            for letter in params.constellations
        },
        ionosphere_free=ionosphere_free,
        ionosphere=ionosphere,
        ionosphere_counts=iono_counts,
    )


def write_bag(conversion: RinexConversion, out: str | Path, *, overwrite: bool = False) -> dict[str, int]:
    """Write the converted epochs (and truth) to a bag; log time = header stamp. The observation
    codes used and their priority go into the metadata's ``custom_data`` (JSON under
    :data:`CODES_METADATA_KEY` and :data:`PRIORITY_METADATA_KEY`).

    Args:
        conversion: output of :func:`convert_rinex`.
        out: bag directory to create.
        overwrite: replace an existing bag.

    Returns:
        Topic -> number of messages written.

    Raises:
        BagError: the output exists (without ``overwrite``) or cannot be written.
    """
    with BagWriter(out, overwrite=overwrite) as bag:
        bag.set_custom_data(CODES_METADATA_KEY, json.dumps(conversion.codes_by_constellation, sort_keys=True))
        bag.set_custom_data(PRIORITY_METADATA_KEY, json.dumps(
            {k: list(v) for k, v in conversion.code_priority.items()}, sort_keys=True))
        bag.set_custom_data(IONOSPHERE_FREE_METADATA_KEY, "true" if conversion.ionosphere_free else "false")
        bag.set_custom_data(IONOSPHERE_METADATA_KEY, json.dumps(
            {"source": conversion.ionosphere, **conversion.ionosphere_counts}, sort_keys=True))
        for epoch in conversion.epochs:
            bag.write(MEASUREMENTS_TOPIC, epoch_to_msg(epoch, EARTH_FRAME_ID), epoch.stamp_ns)
            if conversion.truth_position_ecef_m is not None:
                bag.write(TRUTH_TOPIC, point_to_msg(epoch.stamp_ns, conversion.truth_position_ecef_m,
                                                    EARTH_FRAME_ID), epoch.stamp_ns)
        return dict(bag.counts)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description=(
            "Convert a RINEX 2/3/4 observation file (plain, .gz, .Z, Hatanaka .crx / .crx.gz) and its broadcast "
            "navigation file(s) (one mixed file or one per system) into a bag: "
            f"{MEASUREMENTS_TOPIC} (rfi_msgs/GnssMeasurementArray, one per epoch: GPS and QZSS L1 C/A, Galileo "
            "E1, BeiDou B1I, GLONASS G1, each where the navigation files carry its ephemerides) and "
            f"{TRUTH_TOPIC} (geometry_msgs/PointStamped, frame 'earth'). The truth is the header's "
            "APPROX POSITION XYZ, i.e. the station's published position, repeated at every epoch and "
            "used as truth for a static receiver; it is omitted when the header has none. Stamps are "
            "ROS time (UTC, ns since 1970; GPS - UTC leap seconds removed); GPS week and time of week "
            "are in the message fields."
        ),
    )
    parser.add_argument("obs", help="RINEX observation file (2.x or 3.x; plain, .gz, .crx, .crx.gz)")
    parser.add_argument("nav", nargs="+",
                        help="RINEX navigation file(s) with the broadcast ephemerides (mixed, or one per system)")
    parser.add_argument("out", help="bag directory to write")
    parser.add_argument("--constellations", type=_constellations, default=SUPPORTED_SYSTEMS, metavar="LIST",
                        help="RINEX system letters to convert, comma-separated, of "
                             f"{','.join(SUPPORTED_SYSTEMS)} (default: all of them)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing bag")
    parser.add_argument("--elevation-mask-deg", type=float, default=0.0, metavar="X",
                        help="drop satellites below X degrees of elevation (default 0: below the horizon)")
    parser.add_argument("--ionosphere-free", action="store_true",
                        help="GPS pseudoranges as the ionosphere-free combination of the L1 and L2 P(Y) codes "
                             "(RINEX 2 P1/P2, RINEX 3/4 C1W/C2W), no ionospheric model, clock without T_GD; GPS "
                             "satellites without both codes are skipped (missing_dual_frequency). C/A with P2 "
                             "is not combined (it needs the P1-C1 code biases, which no broadcast message has)")
    parser.add_argument("--ionosphere", choices=IONOSPHERE_SOURCES, default="klobuchar",
                        help="source of ionosphere_delay_m: the broadcast Klobuchar model (default), or for GPS "
                             "the L1/L2 carrier phases' geometry-free combination levelled per arc to Klobuchar's "
                             "mean over the arc (uses the whole arc: post-processing; Klobuchar where a "
                             "satellite lacks a carrier)")
    return parser


def _constellations(text: str) -> tuple[str, ...]:
    """argparse type: ``G,E,C`` -> ("G", "E", "C"), each of :data:`SUPPORTED_SYSTEMS`."""
    letters = tuple(t.strip().upper() for t in text.split(",") if t.strip())
    bad = [t for t in letters if t not in SUPPORTED_SYSTEMS]
    if not letters or bad:
        raise argparse.ArgumentTypeError(
            f"expected system letters among {','.join(SUPPORTED_SYSTEMS)}, got {text!r}"
        )
    return letters


def main(argv: Sequence[str] | None = None) -> int:
    """Console entry point. ``argv`` is a full argument vector (``argv[0]`` is the program name),
    as ``sys.argv``, like the suite's other tools. Returns 0, or 2 on any input error."""
    return cli.run_converter(build_parser(), argv, _fail, (RinexFormatError, BagError, ValueError, OSError),
                             _convert, _summary)


def _convert(args: argparse.Namespace, out: Path) -> tuple[RinexConversion, dict[str, int]]:
    conversion = convert_rinex(args.obs, args.nav, args.elevation_mask_deg, args.constellations,
                               progress=ProgressLine(f'rinex_to_bag {Path(args.obs).name}', unit='epoch',
                                                     enabled=not args.quiet),
                               ionosphere_free=args.ionosphere_free, ionosphere=args.ionosphere)
    return conversion, write_bag(conversion, out, overwrite=args.overwrite)


def _summary(args: argparse.Namespace, result: tuple[RinexConversion, dict[str, int]]) -> list[str]:
    conversion, counts = result
    lines = [f"  epochs        {len(conversion.epochs)}", f"  measurements  {conversion.measurement_count}"]
    empty = sum(1 for e in conversion.epochs if not e.observations)
    if empty:
        lines.append(f"  epochs without measurements  {empty}")
    has_truth = conversion.truth_position_ecef_m is not None
    truth = "header APPROX POSITION" if has_truth else "none (no APPROX POSITION)"
    lines.append(f"  truth         {truth}")
    if conversion.ionosphere_free:
        lines.append("  GPS pseudoranges  ionosphere-free L1/L2 P(Y) combination (no ionospheric model)")
    if conversion.ionosphere != "klobuchar":
        c = conversion.ionosphere_counts
        lines.append(f"  ionosphere    {conversion.ionosphere}: GPS {c.get('levelled', 0)} levelled from L1/L2 "
                     f"carrier, {c.get('model', 0)} Klobuchar (no dual-frequency carrier); other systems Klobuchar")
    for topic, n in sorted(counts.items()):
        lines.append(f"  {topic}  {n}")
    lines.append("  measurements by constellation:")
    for name, n in sorted(conversion.measurements_by_constellation().items()):
        lines.append(f"    {name:<26} {n}")
    lines.append("  observation codes used (pseudorange, Doppler, C/N0 of one tracking attribute):")
    for name, used in sorted(conversion.codes_by_constellation.items()):
        text = ", ".join(f"{c} {n}" for c, n in sorted(used.items(), key=lambda kv: (-kv[1], kv[0])))
        lines.append(f"    {name:<10} {text}")
    lines.append("  navigation records used by system:  " + (
        ", ".join(f"{SYSTEM_NAMES.get(k, k)} {n}" for k, n in sorted(conversion.nav_records.items())) or "none"))
    for letter, reasons in sorted(conversion.nav_skipped.items()):
        text = ", ".join(f"{r} {n}" for r, n in sorted(reasons.items()))
        lines.append(f"  navigation records not used, {SYSTEM_NAMES.get(letter, letter)}: {text}")
    lines.append("  skipped satellites by reason:")
    for reason, n in conversion.skipped.items():
        lines.append(f"    {reason:<26} {n}")
    if conversion.skipped_by_constellation:
        lines.append("  skipped satellites by constellation and reason:")
        for name, reasons in sorted(conversion.skipped_by_constellation.items()):
            text = ", ".join(f"{r} {n}" for r, n in sorted(reasons.items()))
            lines.append(f"    {name:<10} {text}")
    if conversion.epochs_without_reference:
        n_unmasked = conversion.epochs_without_reference
        lines.append(f"  epochs without reference position (mask not applied): {n_unmasked}")
    return lines

if __name__ == "__main__":
    sys.exit(main())
