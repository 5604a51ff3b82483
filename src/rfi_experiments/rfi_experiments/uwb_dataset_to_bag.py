"""``uwb_dataset_to_bag CASE_DIR OUT``: one dynamic case of the Hanyang outdoor UWB dataset -> a bag.

The dataset (cucudasluv/UWB-dataset, commit c1259981, Apache-2.0; "Comprehensive outdoor UWB
dataset", ADIP laboratory, Hanyang University) gives, per dynamic case, CSV exports of a ROS 1 bag:

* ``A<id>.csv`` (one per anchor): ``%time`` (rosbag record time, ns), ``field.stamp`` (header
  stamp, ns), ``field.id`` (anchor id), ``field.x/y/z`` (anchor position, m, local frame),
  ``field.distanceFromTag`` (two-way range, m), ``field.rssi``, ``field.rssi_fp`` (dBm).
* ``trajectory.csv``: RTK-derived truth in the anchors' frame (timestamp, x, y, z [m], heading [deg]).
* ``LS.csv``, ``ESKF.csv``: the authors' own UWB-only least-squares and error-state KF solutions
  (timestamp [ns], x, y, z [m]).
* ``gnss.csv``: the RTK receiver's NavSatFix stream (used here only to restore exact truth stamps).

Output topics (bag log time = header stamp, all in integer ns):

* ``/uwb/ranges``: ``rfi_msgs/UwbRange``, frame "map", ``anchor_id`` = the csv ``field.id`` as a
  string ("3", "12"), ``rssi_dbm`` = ``field.rssi`` (``rssi_fp`` has no message field and is
  dropped), ``range_std_m`` NaN (the filter's default) unless ``--range-std-m`` is given.
* ``/truth/position``: ``geometry_msgs/PointStamped``, frame "map", from trajectory.csv (heading
  dropped).
* ``/reference/ls_position``, ``/reference/eskf_position``: the authors' solutions, frame "map",
  every row as published (see the ESKF tail below).

The "map" frame here is the dataset's anchor frame: z up, right-handed, but its x/y axes are not
east/north (a 2D Procrustes fit of the RTK fixes of LOS/Trajectory_A/Case_1 against
trajectory.csv gives a 19.5 deg rotation, 0.28 m rms residual). UWB-only processing does not care.

Time bases (checked on LOS/Trajectory_A/Case_1 by :func:`check_time_bases`; the converter prints
the same figures for any case):

* UWB: ``%time - field.stamp`` is 0.06 to 3.1 ms (median 0.25-0.29 ms per anchor): both stamps are
  the recording PC's ROS clock; the header stamp is used. Each anchor ranges at 10 Hz with
  gaps of up to 1.5 s; 1917-2194 rows per anchor.
* gnss.csv header stamps lie on an exact 125 ms (8 Hz) grid offset by 0.33 ms and are recorded
  26-77 ms (median 41 ms) later on the ROS clock, so they are the receiver's UTC epochs and the
  PC clock agreed with UTC within tens of ms (GPS time would put them 18 s ahead). The stamps are
  therefore kept as they are: they are already the suite's time base, ROS (UTC) time
  (:mod:`gnss_common.gps_time`), so these ranges line up with GNSS converted by ``rinex_to_bag``.
* trajectory.csv timestamps are those gnss.csv header stamps printed as float64 (``1.73e+18``),
  i.e. rounded to a multiple of 256 ns; 1881 of the 1882 fixes appear (seq 2733 is missing). When
  gnss.csv is present, each truth stamp is restored to the exact integer stamp whose float it is;
  otherwise it is rounded (error < 128 ns).
* LS.csv / ESKF.csv stamps are the authors' solver output times on the same ROS clock, 43-50 ms
  (5-95 %) after the latest UWB header stamp; 1790 stamps are common to both. ESKF.csv continues
  41 rows (2.1 s) after the last UWB range, and its last 20 rows repeat one stamp with z = 0 and
  a position about 16 m from the truth: an evaluation should clip the references to the UWB span.
  The other two cases look alike with other delays (LOS/B/3: LS 50-53 ms, ESKF 11-18 ms; NLOS/A/1:
  LS 87-94 ms, ESKF 59-63 ms median, and ESKF runs 588 rows, about a minute, past the last range).
* Ranges against truth: ``distanceFromTag - |truth(t) - anchor|`` is most consistent (median
  absolute deviation 0.13 m -> 0.08 m) when the truth is taken 0.15-0.20 s *before* the UWB
  header stamp, in all three dynamic cases: the ranges are about 0.2 s older than their stamps
  relative to the RTK time base (the distances end in ...333 / ...667, which suggests the module
  averages three ranges; that would explain part of the lag). The converter keeps the stamps as
  recorded; a filter may model this latency.

Notes
-----
No equations: a file-format conversion. Range model of the message: Cao et al., eq. 7.
"""

from __future__ import annotations

import argparse
import csv
import math
import re
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gnss_common.observations import UwbRangeMeasurement
from rfi_experiments import cli
from rfi_experiments.bag_io import BagError, BagWriter
from rfi_experiments.cli import error_reporter
from rfi_experiments.progress import ProgressLine
from rfi_node_common.conversions import point_to_msg, uwb_to_msg

PROG = "uwb_dataset_to_bag"
_fail = error_reporter(PROG)
MAP_FRAME_ID = "map"
UWB_TOPIC = "/uwb/ranges"
TRUTH_TOPIC = "/truth/position"
LS_TOPIC = "/reference/ls_position"
ESKF_TOPIC = "/reference/eskf_position"

UWB_COLUMNS = (
    "%time", "field.stamp", "field.id", "field.x", "field.y", "field.z",
    "field.distanceFromTag", "field.rssi", "field.rssi_fp",
)
"""Header of an anchor csv (rostopic echo -p export of the DW1000 range topic)."""

_ANCHOR_FILE = re.compile(r"^A(\d+)\.csv$")
NS_PER_MS = 1.0e6


class DatasetFormatError(ValueError):
    """A dataset file is missing or malformed; the message names the file and 1-based line."""


@dataclass(frozen=True)
class UwbTable:
    """Rows of one anchor csv that passed the checks, as arrays (N rows).

    Attributes:
        record_ns: rosbag record time, ns, int64 (N,).
        stamp_ns: header stamp, ns, int64 (N,).
        anchor_id: anchor ids, int64 (N,).
        anchor_position_m: anchor positions in the dataset frame, m, (N, 3).
        range_m: tag-anchor distances, m, (N,).
        rssi_dbm: received power, dBm, (N,).
        rejected: reason -> rows dropped (``non_finite``, ``range_not_positive``).
    """

    record_ns: np.ndarray
    stamp_ns: np.ndarray
    anchor_id: np.ndarray
    anchor_position_m: np.ndarray
    range_m: np.ndarray
    rssi_dbm: np.ndarray
    rejected: dict[str, int]


@dataclass(frozen=True)
class PositionTable:
    """A ``timestamp,x,y,z[,...]`` csv (truth or reference solution).

    Attributes:
        stamp_ns: stamps, ns, int64 (N,).
        position_m: positions in the dataset frame, m, (N, 3).
        inexact_stamps: rows whose stamp was written as a float and could not be restored
            exactly (rounded to the nearest ns instead).
    """

    stamp_ns: np.ndarray
    position_m: np.ndarray
    inexact_stamps: int = 0


@dataclass(frozen=True)
class HanyangCase:
    """One dynamic case, read and checked.

    Attributes:
        path: the case directory.
        uwb: anchor file name -> its table, in file-name order.
        truth: trajectory.csv.
        references: topic -> table of the authors' solutions present (LS, ESKF).
        gnss_stamps_ns: header stamps of gnss.csv, ns (empty when the file is absent).
    """

    path: Path
    uwb: dict[str, UwbTable]
    truth: PositionTable
    references: dict[str, PositionTable]
    gnss_stamps_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


def _read_rows(
    path: Path, expected_header: Sequence[str] | None, min_columns: int
) -> list[tuple[int, list[str]]]:
    try:
        with open(path, newline="") as fh:
            rows = list(csv.reader(fh))
    except OSError as err:
        raise DatasetFormatError(f"{path}: cannot read ({err.strerror})") from None
    except (csv.Error, UnicodeDecodeError) as err:
        raise DatasetFormatError(f"{path}: not a csv file ({err})") from None
    if not rows:
        raise DatasetFormatError(f"{path}:1: empty file")
    header = [h.strip() for h in rows[0]]
    if expected_header is not None and tuple(header) != tuple(expected_header):
        raise DatasetFormatError(f"{path}:1: unexpected header {','.join(header)!r}, expected "
                                 f"{','.join(expected_header)!r}")
    if expected_header is None and (len(header) < min_columns or header[0] != "timestamp"):
        raise DatasetFormatError(f"{path}:1: expected a header 'timestamp,x,y,z', got {','.join(header)!r}")
    body = [(i + 2, r) for i, r in enumerate(rows[1:]) if r]
    for line_no, r in body:
        if len(r) < min_columns:
            raise DatasetFormatError(f"{path}:{line_no}: {len(r)} columns, expected at least {min_columns}")
    if not body:
        raise DatasetFormatError(f"{path}: no data rows")
    return body


def _int(text: str, path: Path, line_no: int, what: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise DatasetFormatError(f"{path}:{line_no}: cannot read integer {what} from {text!r}") from None


def _float(text: str, path: Path, line_no: int, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise DatasetFormatError(f"{path}:{line_no}: cannot read {what} from {text!r}") from None


def read_uwb_csv(path: str | Path) -> UwbTable:
    """Read one anchor csv (columns :data:`UWB_COLUMNS`), stamps parsed as exact integers.

    Args:
        path: ``A<id>.csv``.

    Returns:
        :class:`UwbTable`; rows with a non-finite value or a range <= 0 are dropped and counted.

    Raises:
        DatasetFormatError: unreadable file, wrong header, short row, unparseable field, or stamps
            that decrease.
    """
    p = Path(path)
    body = _read_rows(p, UWB_COLUMNS, len(UWB_COLUMNS))
    rejected = {"non_finite": 0, "range_not_positive": 0}
    rec: list[int] = []
    stamp: list[int] = []
    ids: list[int] = []
    pos: list[list[float]] = []
    rng: list[float] = []
    rssi: list[float] = []
    for line_no, r in body:
        rec_i = _int(r[0], p, line_no, "record time")
        stamp_i = _int(r[1], p, line_no, "header stamp")
        id_i = _int(r[2], p, line_no, "anchor id")
        values = [_float(r[k], p, line_no, UWB_COLUMNS[k]) for k in (3, 4, 5, 6, 7)]
        if not all(math.isfinite(v) for v in values[:4]):
            rejected["non_finite"] += 1
            continue
        if values[3] <= 0.0:
            rejected["range_not_positive"] += 1
            continue
        if stamp and stamp_i < stamp[-1]:
            raise DatasetFormatError(f"{p}:{line_no}: header stamp {stamp_i} ns goes back in time")
        rec.append(rec_i)
        stamp.append(stamp_i)
        ids.append(id_i)
        pos.append(values[:3])
        rng.append(values[3])
        rssi.append(values[4])
    return UwbTable(
        record_ns=np.array(rec, dtype=np.int64),
        stamp_ns=np.array(stamp, dtype=np.int64),
        anchor_id=np.array(ids, dtype=np.int64),
        anchor_position_m=np.array(pos, dtype=float).reshape(-1, 3),
        range_m=np.array(rng, dtype=float),
        rssi_dbm=np.array(rssi, dtype=float),
        rejected=rejected,
    )


def read_position_csv(path: str | Path, exact_stamps_ns: np.ndarray | None = None) -> PositionTable:
    """Read a ``timestamp,x,y,z[,...]`` csv; extra columns are ignored.

    Args:
        path: trajectory.csv, LS.csv or ESKF.csv.
        exact_stamps_ns: integer stamps, ns, that float-printed timestamps were made from (the
            gnss.csv header stamps for trajectory.csv); a float timestamp equal to float(s) for one
            of them becomes s exactly. None: float timestamps are rounded.

    Returns:
        :class:`PositionTable`.

    Raises:
        DatasetFormatError: unreadable file, bad header, short row, unparseable or non-finite field.
    """
    p = Path(path)
    body = _read_rows(p, None, 4)
    lookup: dict[float, int] = {}
    if exact_stamps_ns is not None:
        lookup = {float(s): int(s) for s in np.asarray(exact_stamps_ns, dtype=np.int64)}
    stamps, xyz = [], []
    inexact = 0
    for line_no, r in body:
        text = r[0].strip()
        try:
            stamp = int(text)
        except ValueError:
            value = _float(text, p, line_no, "timestamp")
            if not math.isfinite(value):
                raise DatasetFormatError(f"{p}:{line_no}: non-finite timestamp {text!r}") from None
            stamp = lookup.get(value, -1)
            if stamp < 0:
                stamp = int(round(value))
                inexact += 1
        xyz_row = [_float(r[k], p, line_no, "position") for k in (1, 2, 3)]
        if not all(math.isfinite(v) for v in xyz_row):
            raise DatasetFormatError(f"{p}:{line_no}: non-finite position")
        stamps.append(stamp)
        xyz.append(xyz_row)
    return PositionTable(np.array(stamps, dtype=np.int64), np.array(xyz, dtype=float), inexact)


def _read_gnss_stamps(path: Path) -> np.ndarray:
    """Header stamps (``field.header.stamp``), ns, of the NavSatFix export gnss.csv."""
    try:
        with open(path, newline="") as fh:
            rows = list(csv.reader(fh))
    except (OSError, csv.Error, UnicodeDecodeError) as err:
        raise DatasetFormatError(f"{path}: cannot read ({err})") from None
    if not rows or "field.header.stamp" not in rows[0]:
        raise DatasetFormatError(f"{path}:1: no 'field.header.stamp' column")
    col = rows[0].index("field.header.stamp")
    return np.array([_int(r[col], path, i + 2, "header stamp") for i, r in enumerate(rows[1:]) if r],
                    dtype=np.int64)


def read_case(case_dir: str | Path) -> HanyangCase:
    """Read a dynamic case directory (``A*.csv``, ``trajectory.csv``, optional LS/ESKF/gnss csv).

    Args:
        case_dir: e.g. ``Dynamic_measurements/LOS/Trajectory_A/Case_1``.

    Returns:
        :class:`HanyangCase`.

    Raises:
        DatasetFormatError: directory missing, no anchor file, no trajectory.csv, or a malformed
            file.
    """
    d = Path(case_dir)
    if not d.is_dir():
        raise DatasetFormatError(f"{d}: no such case directory")
    anchor_files = sorted((f for f in d.iterdir() if _ANCHOR_FILE.match(f.name)),
                          key=lambda f: int(_ANCHOR_FILE.match(f.name).group(1)))  # type: ignore[union-attr]
    if not anchor_files:
        raise DatasetFormatError(f"{d}: no anchor files A<id>.csv")
    if not (d / "trajectory.csv").is_file():
        raise DatasetFormatError(f"{d}: no trajectory.csv (the truth)")
    gnss = _read_gnss_stamps(d / "gnss.csv") if (d / "gnss.csv").is_file() else np.zeros(0, dtype=np.int64)
    refs = {}
    for topic, name in ((LS_TOPIC, "LS.csv"), (ESKF_TOPIC, "ESKF.csv")):
        if (d / name).is_file():
            refs[topic] = read_position_csv(d / name)
    return HanyangCase(
        path=d,
        uwb={f.name: read_uwb_csv(f) for f in anchor_files},
        truth=read_position_csv(d / "trajectory.csv", gnss if gnss.size else None),
        references=refs,
        gnss_stamps_ns=gnss,
    )


@dataclass(frozen=True)
class TimeBaseReport:
    """Cross-checks of the time bases of one case (all times in ms unless named otherwise).

    Attributes:
        uwb_record_minus_stamp_ms: (min, median, max) of ``%time - field.stamp`` over all anchors.
        uwb_span_ns: (first, last) UWB header stamp, ns.
        truth_span_ns: (first, last) truth stamp, ns.
        truth_stamps_restored: truth rows whose stamp was restored exactly from gnss.csv.
        truth_stamps_rounded: truth rows whose float stamp could only be rounded.
        reference_delay_ms: topic -> (5th, 50th, 95th percentile) of the delay of each reference
            stamp after the latest UWB header stamp before it.
        reference_rows_after_uwb: topic -> rows stamped after the last UWB range.
        reference_repeated_stamps: topic -> rows whose stamp equals the previous row's.
    """

    uwb_record_minus_stamp_ms: tuple[float, float, float]
    uwb_span_ns: tuple[int, int]
    truth_span_ns: tuple[int, int]
    truth_stamps_restored: int
    truth_stamps_rounded: int
    reference_delay_ms: dict[str, tuple[float, float, float]]
    reference_rows_after_uwb: dict[str, int]
    reference_repeated_stamps: dict[str, int]

    def lines(self) -> list[str]:
        """Human-readable summary, one fact per line."""
        r = self.uwb_record_minus_stamp_ms
        out = [
            f"UWB record time - header stamp: min {r[0]:.3f} ms, median {r[1]:.3f} ms, max {r[2]:.3f} ms",
            f"UWB span {(self.uwb_span_ns[1] - self.uwb_span_ns[0]) * 1e-9:.1f} s; truth starts "
            f"{(self.truth_span_ns[0] - self.uwb_span_ns[0]) * 1e-9:+.3f} s and ends "
            f"{(self.truth_span_ns[1] - self.uwb_span_ns[1]) * 1e-9:+.3f} s relative to it",
            f"truth stamps restored exactly from gnss.csv: {self.truth_stamps_restored}, "
            f"rounded from float: {self.truth_stamps_rounded}",
        ]
        for topic, (p5, p50, p95) in self.reference_delay_ms.items():
            out.append(
                f"{topic}: {p5:.1f}/{p50:.1f}/{p95:.1f} ms (5/50/95 %) after the latest UWB stamp; "
                f"{self.reference_rows_after_uwb[topic]} rows after the last range, "
                f"{self.reference_repeated_stamps[topic]} repeated stamps"
            )
        return out


def check_time_bases(case: HanyangCase) -> TimeBaseReport:
    """Compare the stamps of the files of one case (see the module docstring for the findings).

    Args:
        case: output of :func:`read_case`.

    Returns:
        :class:`TimeBaseReport`.
    """
    rec = np.concatenate([t.record_ns for t in case.uwb.values()])
    stamp = np.concatenate([t.stamp_ns for t in case.uwb.values()])
    if stamp.size == 0:
        raise DatasetFormatError(f"{case.path}: no valid UWB rows")
    diff_ms = (rec - stamp) / NS_PER_MS
    uwb_sorted = np.sort(stamp)
    delays: dict[str, tuple[float, float, float]] = {}
    after: dict[str, int] = {}
    repeated: dict[str, int] = {}
    for topic, table in case.references.items():
        k = np.searchsorted(uwb_sorted, table.stamp_ns, side="right") - 1
        ok = k >= 0
        d_ms = (table.stamp_ns[ok] - uwb_sorted[k[ok]]) / NS_PER_MS
        p5, p50, p95 = np.percentile(d_ms, [5, 50, 95]) if d_ms.size else (math.nan, math.nan, math.nan)
        delays[topic] = (float(p5), float(p50), float(p95))
        after[topic] = int(np.sum(table.stamp_ns > uwb_sorted[-1]))
        repeated[topic] = int(np.sum(np.diff(table.stamp_ns) == 0))
    n_truth = case.truth.stamp_ns.size
    return TimeBaseReport(
        uwb_record_minus_stamp_ms=(float(diff_ms.min()), float(np.median(diff_ms)), float(diff_ms.max())),
        uwb_span_ns=(int(uwb_sorted[0]), int(uwb_sorted[-1])),
        truth_span_ns=(int(case.truth.stamp_ns.min()), int(case.truth.stamp_ns.max())),
        truth_stamps_restored=n_truth - case.truth.inexact_stamps if case.gnss_stamps_ns.size else 0,
        truth_stamps_rounded=case.truth.inexact_stamps,
        reference_delay_ms=delays,
        reference_rows_after_uwb=after,
        reference_repeated_stamps=repeated,
    )


def uwb_measurements(
    table: UwbTable, range_std_m: float = math.nan
) -> list[tuple[UwbRangeMeasurement, float]]:
    """Turn an anchor table into (measurement, rssi_dbm) pairs in the "map" frame.

    Args:
        table: one anchor's rows.
        range_std_m: 1-sigma written into every range, m (NaN: the filter's default).

    Returns:
        One pair per row, stamp = header stamp (ns), anchor id = the csv id as a string.
    """
    return [
        (
            UwbRangeMeasurement(
                stamp_ns=int(table.stamp_ns[i]),
                anchor_id=str(int(table.anchor_id[i])),
                anchor_position_m=table.anchor_position_m[i].copy(),
                frame_id=MAP_FRAME_ID,
                range_m=float(table.range_m[i]),
                range_std_m=float(range_std_m),
            ),
            float(table.rssi_dbm[i]),
        )
        for i in range(table.stamp_ns.size)
    ]


def write_case_bag(case: HanyangCase, out: str | Path, *, overwrite: bool = False,
                   range_std_m: float = math.nan, progress: ProgressLine | None = None) -> dict[str, int]:
    """Write one case to a bag, all topics merged in stamp order (log time = header stamp).

    Args:
        case: output of :func:`read_case`.
        out: bag directory to create.
        overwrite: replace an existing bag.
        range_std_m: 1-sigma of every UWB range, m, > 0 or NaN.
        progress: if given, gets the number of messages as its total and one count per message written,
            and is closed at the end.

    Returns:
        Topic -> messages written.

    Raises:
        ValueError: invalid ``range_std_m``.
        BagError: output exists (without overwrite) or cannot be written.
    """
    if not (math.isnan(range_std_m) or (math.isfinite(range_std_m) and range_std_m > 0.0)):
        raise ValueError(f"--range-std-m must be > 0 (or omitted), got {range_std_m}")
    items: list[tuple[int, int, int, str, object]] = []
    order = {UWB_TOPIC: 0, TRUTH_TOPIC: 1, LS_TOPIC: 2, ESKF_TOPIC: 3}
    seq = 0
    for uwb_table in case.uwb.values():
        for meas, rssi in uwb_measurements(uwb_table, range_std_m):
            items.append((meas.stamp_ns, order[UWB_TOPIC], seq, UWB_TOPIC, uwb_to_msg(meas, rssi)))
            seq += 1
    for topic, table in ((TRUTH_TOPIC, case.truth), *case.references.items()):
        for stamp, xyz in zip(table.stamp_ns, table.position_m, strict=True):
            items.append((int(stamp), order[topic], seq, topic, point_to_msg(int(stamp), xyz, MAP_FRAME_ID)))
            seq += 1
    items.sort(key=lambda it: it[:3])
    if progress is not None:
        progress.total = len(items)
    with BagWriter(out, overwrite=overwrite) as bag:
        for stamp, _, _, topic, msg in (items if progress is None else progress.iterate(items)):
            bag.write(topic, msg, stamp)
        return dict(bag.counts)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description=(
            "Convert one dynamic case of the Hanyang outdoor UWB dataset (cucudasluv/UWB-dataset) into a "
            f"bag: {UWB_TOPIC} (rfi_msgs/UwbRange), {TRUTH_TOPIC} (RTK truth from trajectory.csv) and the "
            f"authors' solutions {LS_TOPIC}, {ESKF_TOPIC} (geometry_msgs/PointStamped), all in frame 'map' "
            "(the dataset's anchor frame). Stamps are the csv header stamps (ROS time, ns)."
        ),
    )
    parser.add_argument("case_dir", help="case directory holding A<id>.csv, trajectory.csv, LS.csv, ESKF.csv")
    parser.add_argument("out", help="bag directory to write")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing bag")
    parser.add_argument("--range-std-m", type=float, default=math.nan, metavar="S",
                        help="1-sigma written into every range, m (default: NaN, the filter decides)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Console entry point. ``argv`` is a full argument vector (``argv[0]`` is the program name),
    as ``sys.argv``, like the suite's other tools. Returns 0, or 2 on any input error."""
    return cli.run_converter(build_parser(), argv, _fail, (DatasetFormatError, BagError, ValueError, OSError),
                             _convert, _summary)


def _convert(args: argparse.Namespace, out: Path) -> tuple[HanyangCase, TimeBaseReport, dict[str, int]]:
    case = read_case(args.case_dir)
    report = check_time_bases(case)
    progress = ProgressLine(f"{PROG} {Path(args.case_dir).name}", unit="msg", enabled=not args.quiet)
    return case, report, write_case_bag(case, out, overwrite=args.overwrite, range_std_m=args.range_std_m,
                                        progress=progress)


def _summary(args: argparse.Namespace, result: tuple[HanyangCase, TimeBaseReport, dict[str, int]]) -> list[str]:
    case, report, counts = result
    lines = [f"  {topic}  {n}" for topic, n in sorted(counts.items())]
    for name, table in case.uwb.items():
        rejected = ", ".join(f"{k} {v}" for k, v in table.rejected.items())
        lines.append(f"  {name}: {table.stamp_ns.size} ranges (rejected: {rejected})")
    missing = [t for t in (LS_TOPIC, ESKF_TOPIC) if t not in case.references]
    if missing:
        lines.append(f"  reference solutions not found: {', '.join(missing)}")
    lines.append("  time bases:")
    lines += [f"    {line}" for line in report.lines()]
    return lines

if __name__ == "__main__":
    sys.exit(main())
