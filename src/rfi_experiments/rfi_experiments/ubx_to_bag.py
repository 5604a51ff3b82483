"""``ubx_to_bag UBX OUT [--nav NAV]``: a u-blox receiver's UBX log -> a bag the fusion node can replay.

Every UBX-RXM-RAWX epoch with at least ``--min-satellites`` modelled satellites becomes one
``rfi_msgs/GnssMeasurementArray`` on ``/gnss/measurements``, built by the same code as
``rinex_to_bag`` (:class:`gnss_common.measurements.GnssEpochBuilder`, via
:class:`rfi_experiments.ubx_decode.UbxDecoder`); the receiver's interference indicators
(UBX-MON-HW, UBX-MON-RF per RF block, UBX-SEC-SIG) go to ``/gnss/receiver_interference``
(``rfi_msgs/ReceiverInterference``), its spectrum (UBX-MON-SPAN, one message per RF block) to
``/gnss/receiver_spectrum`` (``rfi_msgs/ReceiverSpectrum``). Ephemerides come from the log's
UBX-RXM-SFRBX (GPS LNAV, Galileo I/NAV) and/or ``--nav`` (RINEX); a satellite without one is
written with NaN satellite states (real pseudorange, rate and C/N0; counted as
``satellites_without_ephemeris``) unless ``--skip-without-ephemeris``, so that a log without
SFRBX still feeds the C/N0 jamming tests.

Header stamps and bag log times are ROS time (UTC-based, ns) of the receive epoch; GPS week and
time of week are in the message fields. Corrupted frames, unknown messages and everything
skipped are counted in the summary printed at the end.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gnss_common.rinex import RinexFormatError, read_rinex_nav
from rfi_experiments import cli
from rfi_experiments.bag_io import BagError, BagWriter
from rfi_experiments.cli import error_reporter
from rfi_experiments.progress import ProgressLine
from rfi_experiments.ubx_decode import EpochOutput, InterferenceReport, SpectrumReport, UbxDecoder, UbxDecoderParams

PROG = "ubx_to_bag"
_fail = error_reporter(PROG)
MEASUREMENTS_TOPIC = "/gnss/measurements"
INTERFERENCE_TOPIC = "/gnss/receiver_interference"
SPECTRUM_TOPIC = "/gnss/receiver_spectrum"
EARTH_FRAME_ID = "earth"
CHUNK_BYTES = 1 << 16


@dataclass(frozen=True)
class UbxConversion:
    """Everything decoded from one UBX log, in stream order, and the decoder (its counters)."""

    epochs: tuple[EpochOutput, ...]
    interference: tuple[InterferenceReport, ...]
    decoder: UbxDecoder
    spectra: tuple[SpectrumReport, ...] = ()


def read_chunks(path: str | Path, size: int = CHUNK_BYTES) -> Iterator[bytes]:
    """The bytes of a file in chunks (OSError for an unreadable file)."""
    with open(path, "rb") as f:
        while chunk := f.read(size):
            yield chunk


def make_decoder(
    nav_path: str | Path | None = None,
    reference_position_ecef_m: Sequence[float] | None = None,
    params: UbxDecoderParams | None = None,
) -> UbxDecoder:
    """A :class:`UbxDecoder` with the ephemerides and Klobuchar parameters of a RINEX nav file.

    Raises:
        RinexFormatError: unreadable nav file. ValueError: bad reference position.
    """
    ephs: tuple = ()
    alpha = beta = None
    if nav_path is not None:
        nav = read_rinex_nav(nav_path)
        ephs = nav.ephemerides
        if np.all(np.isfinite(nav.header.iono_alpha)) and np.all(np.isfinite(nav.header.iono_beta)):
            alpha, beta = nav.header.iono_alpha, nav.header.iono_beta
    ref = None if reference_position_ecef_m is None else np.asarray(reference_position_ecef_m, dtype=float)
    return UbxDecoder(params, ephs, alpha, beta, ref)


def convert_ubx(ubx_path: str | Path, decoder: UbxDecoder, progress: ProgressLine | None = None) -> UbxConversion:
    """Decode a whole UBX log with ``decoder``. ``progress``, if given, counts the log's kB read (its size the
    total) and is closed at the end."""
    epochs: list[EpochOutput] = []
    reports: list[InterferenceReport] = []
    spectra: list[SpectrumReport] = []
    if progress is not None:
        progress.total = os.stat(ubx_path).st_size // 1024
    read_bytes = 0
    for chunk in read_chunks(ubx_path):
        read_bytes += len(chunk)
        if progress is not None:
            progress.set_done(read_bytes // 1024)
        for item in decoder.feed(chunk):
            if isinstance(item, EpochOutput):
                epochs.append(item)
            elif isinstance(item, SpectrumReport):
                spectra.append(item)
            else:
                reports.append(item)
    decoder.finish()
    if progress is not None:
        progress.close()
    return UbxConversion(tuple(epochs), tuple(reports), decoder, tuple(spectra))


def write_bag(conversion: UbxConversion, out: str | Path, *, overwrite: bool = False,
              receiver_frame_id: str = "gnss") -> dict[str, int]:
    """Write epochs, interference reports and spectra in the order of their stamps (log time = stamp;
    at one stamp the epoch first, as in the stream, then the reports that carry its time)."""
    from rfi_experiments.ubx_messages import report_to_msg, spectrum_to_msg
    from rfi_node_common.conversions import epoch_to_msg

    items: list[tuple[int, int, int, str, object]] = []
    for i, e in enumerate(conversion.epochs):
        items.append((e.epoch.stamp_ns, 0, i, MEASUREMENTS_TOPIC, epoch_to_msg(e.epoch, EARTH_FRAME_ID)))
    for i, r in enumerate(conversion.interference):
        items.append((r.stamp_ns, 1, i, INTERFERENCE_TOPIC, report_to_msg(r, receiver_frame_id)))
    for i, sp in enumerate(conversion.spectra):
        items.append((sp.stamp_ns, 2, i, SPECTRUM_TOPIC, spectrum_to_msg(sp, receiver_frame_id)))
    items.sort(key=lambda t: (t[0], t[1], t[2]))
    with BagWriter(out, overwrite=overwrite) as bag:
        for stamp, _, _, topic, msg in items:
            bag.write(topic, msg, stamp)
        return dict(bag.counts)


def summary_lines(decoder: UbxDecoder) -> list[str]:
    """Human-readable counters of a decoder (used by the tool and the node's final log)."""
    c = decoder.counts
    lines = [f"  {k:<30} {c[k]}" for k in c]
    lines.append("  satellites skipped by reason:")
    lines += [f"    {k:<28} {n}" for k, n in decoder.skipped.items()]
    rejected = {k: n for k, n in decoder.lnav_rejected.items() if n}
    if rejected:
        lines.append("  SFRBX GPS subframes rejected: " + ", ".join(f"{k} {n}" for k, n in rejected.items()))
    rejected = {k: n for k, n in decoder.inav_rejected.items() if n}
    if rejected:
        lines.append("  SFRBX Galileo pages rejected: " + ", ".join(f"{k} {n}" for k, n in rejected.items()))
    if decoder.ignored:
        lines.append("  messages not used: " + ", ".join(f"{k} {n}" for k, n in sorted(decoder.ignored.items())))
    return lines


def _position(text: str) -> tuple[float, float, float]:
    parts = [p for p in text.replace(",", " ").split() if p]
    try:
        xyz = tuple(float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not three numbers: {text!r}") from None
    if len(xyz) != 3 or not all(math.isfinite(v) for v in xyz):
        raise argparse.ArgumentTypeError(f"need X,Y,Z in metres (ECEF), got {text!r}")
    return xyz  # type: ignore[return-value]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description=(
            "Convert a u-blox UBX log (UBX-RXM-RAWX measurements, UBX-RXM-SFRBX navigation data, "
            "UBX-MON-HW / MON-RF / SEC-SIG interference indicators, UBX-MON-SPAN spectra) into a bag: "
            f"{MEASUREMENTS_TOPIC} (rfi_msgs/GnssMeasurementArray), {INTERFERENCE_TOPIC} "
            f"(rfi_msgs/ReceiverInterference) and {SPECTRUM_TOPIC} (rfi_msgs/ReceiverSpectrum). "
            "Stamps are ROS time (UTC-based)."
        ),
    )
    parser.add_argument("ubx", help="UBX log file (binary, as the receiver sent it; NMEA mixed in is skipped)")
    parser.add_argument("out", help="bag directory to write")
    parser.add_argument("--nav", metavar="RINEX_NAV", help="RINEX navigation file with the GPS ephemerides "
                        "(used with those decoded from RXM-SFRBX)")
    parser.add_argument("--no-sfrbx", action="store_true", help="ignore RXM-SFRBX (ephemerides only from --nav)")
    parser.add_argument("--reference-position", type=_position, metavar="X,Y,Z",
                        help="receiver ECEF position, m, for the iono/tropo models (default: a coarse fix per epoch); "
                             "write --reference-position=X,Y,Z when X is negative")
    parser.add_argument("--min-satellites", type=int, default=4, metavar="N",
                        help="write an epoch only with at least N satellites (default 4)")
    parser.add_argument("--skip-without-ephemeris", action="store_true",
                        help="skip satellites without a usable ephemeris (default: written with NaN satellite states "
                             "and their real pseudorange, rate and C/N0, for the C/N0 jamming tests)")
    parser.add_argument("--no-receiver-std", action="store_true",
                        help="leave the std fields NaN (the filter weights by C/N0) instead of the receiver's "
                             "prStdev / doStdev")
    parser.add_argument("--frame-id", default="gnss", help="header.frame_id of the interference reports (default gnss)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing bag")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Console entry point (``argv`` as ``sys.argv``). Returns 0, or 2 on any input error."""
    return cli.run_converter(build_parser(), argv, _fail, (RinexFormatError, BagError, ValueError, OSError),
                             _convert, _summary)


def _convert(args: argparse.Namespace, out: Path) -> tuple[UbxDecoder, dict[str, int]] | int:
    params = UbxDecoderParams(min_satellites=args.min_satellites, use_sfrbx=not args.no_sfrbx,
                              use_receiver_std=not args.no_receiver_std,
                              publish_without_ephemeris=not args.skip_without_ephemeris)
    decoder = make_decoder(args.nav, args.reference_position, params)
    conversion = convert_ubx(args.ubx, decoder, ProgressLine(f"ubx_to_bag {Path(args.ubx).name}", unit="kB",
                                                             enabled=not args.quiet))
    if not conversion.epochs and not conversion.interference and not conversion.spectra:
        return _fail(f"{args.ubx}: nothing to write (no RXM-RAWX epoch to write, no interference report or "
                     f"spectrum; {decoder.counts['frames']} valid UBX frames, "
                     f"{decoder.counts['epochs_waiting_for_ephemeris']} epochs waiting for ephemeris)")
    return decoder, write_bag(conversion, out, overwrite=args.overwrite, receiver_frame_id=args.frame_id)


def _summary(args: argparse.Namespace, result: tuple[UbxDecoder, dict[str, int]]) -> list[str]:
    decoder, counts = result
    return [f"  {topic}  {n}" for topic, n in sorted(counts.items())] + ["\n".join(summary_lines(decoder))]

if __name__ == "__main__":
    sys.exit(main())
