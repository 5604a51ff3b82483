"""RINEX 2.x and 3.x/4.x observation files (rinex module docstring: scope): :func:`read_rinex_obs`."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gnss_common.rinex_format import (
    OBS_TIME_SYSTEMS,
    RinexFormatError,
    float_field,
    header_label,
    header_records,
    int_field,
    obs_epoch_to_gps,
    read_lines,
    sat_id,
    two_digit_year,
)

_RINEX2_OBS_PER_LINE = 5
_RINEX2_SATS_PER_LINE = 12
_OBS_FIELD_WIDTH = 16


@dataclass(frozen=True)
class RinexObsHeader:
    """Observation-file header fields used downstream.

    Attributes:
        version: RINEX format version, e.g. 2.11 or 3.04.
        file_system: satellite system letter of the file ("G", "M", ...).
        marker_name: MARKER NAME, stripped.
        approx_position_ecef_m: APPROX POSITION XYZ, m, shape (3,), or None when absent or zero.
        obs_types: system letter -> observable codes in file order (RINEX 2 codes such as
            "C1", "D1", "S1" are listed under every system letter "G", "R", "E", "S", "J", "C").
        interval_s: INTERVAL, s (NaN when absent).
        time_system: TIME OF FIRST OBS time system (default by file system as RINEX says: "GPS",
            "GLO" for a pure GLONASS file, ...); epochs are converted from it to GPS time.
        glonass_channels: GLONASS slot -> FDMA frequency channel k from ``GLONASS SLOT / FRQ #``
            (empty when absent).
    """

    version: float
    file_system: str
    marker_name: str
    approx_position_ecef_m: np.ndarray | None
    obs_types: dict[str, tuple[str, ...]]
    interval_s: float
    time_system: str
    glonass_channels: dict[int, int] = field(default_factory=dict)


@dataclass(frozen=True)
class RinexObsEpoch:
    """One observation epoch.

    Attributes:
        gps_week: continuous GPS week of the receiver time tag.
        tow_s: time of week of the receiver time tag, s.
        epoch_flag: 0 OK, 1 power failure before this epoch.
        receiver_clock_offset_s: optional receiver clock offset from the file, s (NaN if absent).
        observations: satellite id ("G05") -> {observable code: value}; missing values are NaN.
            Units as RINEX: pseudorange m, phase cycles, Doppler Hz, SNR dB-Hz (S fields).
        line_no: 1-based line number of the epoch record (for error messages).
    """

    gps_week: int
    tow_s: float
    epoch_flag: int
    receiver_clock_offset_s: float
    observations: dict[str, dict[str, float]]
    line_no: int


@dataclass(frozen=True)
class RinexObs:
    """A whole observation file: header and epochs in file order."""

    path: str
    header: RinexObsHeader
    epochs: tuple[RinexObsEpoch, ...]




def read_rinex_obs(path: str | Path) -> RinexObs:
    """Read a RINEX 2.10/2.11, 3.0x or 4.0x observation file.

    Args:
        path: file path.

    Returns:
        :class:`RinexObs` with all epochs of flag 0 or 1 in file order.

    Raises:
        RinexFormatError: unreadable file, missing ``END OF HEADER``, unsupported version or file
            type, malformed epoch or observation records (message names file and line).
    """
    lines = read_lines(path)
    header, data_start = _parse_obs_header(lines, path)
    if header.version < 3.0:
        epochs = tuple(_iter_obs2(lines, data_start, header, path))
    else:
        epochs = tuple(_iter_obs3(lines, data_start, header, path))
    return RinexObs(path=str(path), header=header, epochs=epochs)


def _parse_obs_header(lines: list[str], path: str | Path) -> tuple[RinexObsHeader, int]:
    if not lines:
        raise RinexFormatError(path, 1, "empty file")
    first = lines[0]
    if header_label(first) != "RINEX VERSION / TYPE":
        raise RinexFormatError(path, 1, "first line is not 'RINEX VERSION / TYPE'")
    version = float_field(first[0:9], path, 1, "RINEX version")
    if not (2.0 <= version < 5.0):
        raise RinexFormatError(path, 1, f"unsupported RINEX version {version}")
    if first[20:21].upper() != "O":
        raise RinexFormatError(path, 1, f"not an observation file (type {first[20:21]!r})")
    file_system = first[40:41].strip().upper() or "G"
    marker = ""
    approx: np.ndarray | None = None
    interval = math.nan
    time_system = "GPS"
    obs_types: dict[str, list[str]] = {}
    v2_types: list[str] = []
    v2_count = -1
    v3_current: str | None = None
    v3_count = 0
    glo_channels: dict[int, int] = {}
    end, records = header_records(lines)
    for line_no, label, line in records:
        if label == "MARKER NAME":
            marker = line[0:60].strip()
        elif label == "APPROX POSITION XYZ":
            xyz = np.array(
                [float_field(line[i : i + 14], path, line_no, "APPROX POSITION") for i in (0, 14, 28)]
            )
            approx = xyz if np.all(np.isfinite(xyz)) and np.linalg.norm(xyz) > 1.0e6 else None
        elif label == "INTERVAL":
            interval = float_field(line[0:10], path, line_no, "INTERVAL")
        elif label == "TIME OF FIRST OBS":
            time_system = line[48:51].strip() or "GPS"
        elif label == "# / TYPES OF OBSERV":
            if line[0:6].strip():
                v2_count = int_field(line[0:6], path, line_no, "number of observation types")
            for k in range(9):
                code = line[10 + 6 * k : 12 + 6 * k].strip()
                if code:
                    v2_types.append(code)
        elif label == "GLONASS SLOT / FRQ #":
            for k in range(8):
                tok = line[4 + 7 * k : 11 + 7 * k]
                if not tok.strip():
                    continue
                try:
                    glo_channels[int(tok[1:3])] = int(tok[3:7])
                except ValueError:
                    raise RinexFormatError(path, line_no, f"malformed GLONASS SLOT / FRQ # entry {tok!r}") from None
        elif label == "SYS / # / OBS TYPES":
            if line[0:1].strip():
                v3_current = line[0:1].upper()
                v3_count = int_field(line[3:6], path, line_no, "number of observation types")
                obs_types[v3_current] = []
            if v3_current is None:
                raise RinexFormatError(path, line_no, "continuation of SYS / # / OBS TYPES without a system")
            for k in range(13):
                code = line[7 + 4 * k : 10 + 4 * k].strip()
                if code:
                    obs_types[v3_current].append(code)
    if end is None:
        raise RinexFormatError(path, len(lines), "no END OF HEADER")
    if version < 3.0:
        if v2_count < 0:
            raise RinexFormatError(path, end, "no '# / TYPES OF OBSERV' in header")
        if len(v2_types) != v2_count:
            raise RinexFormatError(
                path, end, f"header announces {v2_count} observation types, lists {len(v2_types)}"
            )
        types = {s: tuple(v2_types) for s in ("G", "R", "E", "S", "J", "C", "I")}
    else:
        for sys_char, codes in obs_types.items():
            if not codes:
                raise RinexFormatError(path, end, f"system {sys_char} has no observation types")
        if not obs_types:
            raise RinexFormatError(path, end, "no 'SYS / # / OBS TYPES' in header")
        types = {k: tuple(v) for k, v in obs_types.items()}
        del v3_count
    if not time_system:
        # RINEX 2.11, 5.6 / RINEX 3.05, 5.6: a pure GLONASS file defaults to GLO, others to GPS,
        # a pure Galileo file to GAL, a pure BeiDou file to BDT, a pure QZSS file to QZS.
        time_system = {"R": "GLO", "E": "GAL", "C": "BDT", "J": "QZS"}.get(file_system, "GPS")
    if time_system not in OBS_TIME_SYSTEMS:
        raise RinexFormatError(
            path, end, f"time system {time_system!r} not supported (one of {', '.join(OBS_TIME_SYSTEMS)})"
        )
    header = RinexObsHeader(
        version=version,
        file_system=file_system,
        marker_name=marker,
        approx_position_ecef_m=approx,
        obs_types=types,
        interval_s=interval,
        time_system=time_system or "GPS",
        glonass_channels=glo_channels,
    )
    return header, end


def _parse_obs_values(chunks: list[str], codes: tuple[str, ...]) -> dict[str, float]:
    out: dict[str, float] = {}
    for k, code in enumerate(codes):
        text = chunks[k] if k < len(chunks) else ""
        s = text[0:14].strip()
        val = math.nan
        if s:
            val = float(s)
            if val == 0.0:
                val = math.nan
        out[code] = val
    return out


def _split_fields(line: str, start: int, count: int) -> list[str]:
    padded = line.ljust(start + count * _OBS_FIELD_WIDTH)
    return [padded[start + k * _OBS_FIELD_WIDTH : start + (k + 1) * _OBS_FIELD_WIDTH] for k in range(count)]


@dataclass(frozen=True)
class _EpochRecordLayout:
    """Columns of an observation epoch record: RINEX 2.11 Table A2, RINEX 3.04 Table A3 (0-based slices)."""

    marker: str  # the record's first characters ("" in RINEX 2, ">" in RINEX 3 and 4)
    min_columns: int
    flag: slice
    nsat: slice
    seconds: slice
    clock: slice
    date: Callable[[str], tuple[int, int, int, int, int]]  # year, month, day, hour, minute; ValueError if malformed


def _epoch_date2(line: str) -> tuple[int, int, int, int, int]:
    yy, mo, dd, hh, mi = (int(line[k : k + 3]) for k in (0, 3, 6, 9, 12))
    return two_digit_year(yy), mo, dd, hh, mi


def _epoch_date3(line: str) -> tuple[int, int, int, int, int]:
    mo, dd, hh, mi = (int(line[k : k + 3]) for k in (6, 9, 12, 15))
    return int(line[2:6]), mo, dd, hh, mi


_RINEX2_EPOCH = _EpochRecordLayout("", 32, slice(26, 29), slice(29, 32), slice(15, 26), slice(68, 80), _epoch_date2)
_RINEX3_EPOCH = _EpochRecordLayout(">", 35, slice(31, 32), slice(32, 35), slice(18, 29), slice(41, 56), _epoch_date3)

_ObsBlockReader = Callable[[int, int, int], tuple[int, dict[str, dict[str, float]]]]
"""Reads one epoch's satellites and observations: (index of the epoch record, nsat, its line number) ->
(index of the next record, observations by satellite)."""


def _iter_epochs(
    lines: list[str],
    idx: int,
    header: RinexObsHeader,
    path: str | Path,
    layout: _EpochRecordLayout,
    read_block: _ObsBlockReader,
) -> Iterator[RinexObsEpoch]:
    """The epochs of flag 0 or 1 from ``lines[idx:]``; event records (flag > 1) and what they carry skipped."""
    n = len(lines)
    while idx < n:
        line = lines[idx]
        line_no = idx + 1
        if not line.strip():
            idx += 1
            continue
        if not line.startswith(layout.marker):
            raise RinexFormatError(path, line_no, f"expected an epoch record starting with {layout.marker!r}")
        if len(line) < layout.min_columns:
            raise RinexFormatError(path, line_no, f"epoch record shorter than {layout.min_columns} columns")
        flag = int_field(line[layout.flag], path, line_no, "epoch flag")
        nsat = int_field(line[layout.nsat], path, line_no, "number of satellites")
        if flag > 1:
            # Event: nsat is the number of special records that follow (header lines or slips).
            idx += 1 + nsat
            continue
        try:
            year, mo, dd, hh, mi = layout.date(line)
        except ValueError:
            date_text = line[0 : layout.seconds.stop]
            raise RinexFormatError(path, line_no, f"malformed epoch date in {date_text!r}") from None
        sec = float_field(line[layout.seconds], path, line_no, "epoch seconds")
        week, tow = obs_epoch_to_gps(header.time_system, year, mo, dd, hh, mi, sec, path, line_no)
        clock = (
            float_field(line[layout.clock], path, line_no, "receiver clock offset")
            if len(line) > layout.clock.start
            else math.nan
        )
        idx, observations = read_block(idx, nsat, line_no)
        yield RinexObsEpoch(
            gps_week=week,
            tow_s=tow,
            epoch_flag=flag,
            receiver_clock_offset_s=clock,
            observations=observations,
            line_no=line_no,
        )


def _iter_obs2(
    lines: list[str], idx: int, header: RinexObsHeader, path: str | Path
) -> Iterator[RinexObsEpoch]:
    n = len(lines)
    codes = header.obs_types["G"]
    lines_per_sat = (len(codes) + _RINEX2_OBS_PER_LINE - 1) // _RINEX2_OBS_PER_LINE
    default_sys = header.file_system if header.file_system in "GRESJ" and header.file_system != "M" else "G"

    def read_block(idx: int, nsat: int, line_no: int) -> tuple[int, dict[str, dict[str, float]]]:
        # The satellite list fills columns 33-68 of the epoch record and of its continuation lines.
        sat_lines = (nsat + _RINEX2_SATS_PER_LINE - 1) // _RINEX2_SATS_PER_LINE
        sat_text = ""
        for k in range(max(sat_lines, 1)):
            if idx + k >= n:
                raise RinexFormatError(path, line_no, "file ends inside the satellite list")
            sat_text += lines[idx + k][32:68].ljust(36)
        sats = []
        for k in range(nsat):
            tok = sat_text[3 * k : 3 * k + 3]
            if not tok.strip():
                raise RinexFormatError(path, line_no, f"satellite {k + 1} of {nsat} missing in epoch record")
            try:
                sats.append(sat_id(tok, default_sys))
            except ValueError:
                raise RinexFormatError(path, line_no, f"malformed satellite id {tok!r}") from None
        idx += max(sat_lines, 1)
        observations: dict[str, dict[str, float]] = {}
        for sat in sats:
            chunks: list[str] = []
            for _ in range(lines_per_sat):
                if idx >= n:
                    raise RinexFormatError(path, idx, f"file ends inside the observations of {sat}")
                chunks.extend(_split_fields(lines[idx], 0, _RINEX2_OBS_PER_LINE))
                idx += 1
            try:
                observations[sat] = _parse_obs_values(chunks, codes)
            except ValueError:
                raise RinexFormatError(path, idx, f"malformed observation value for {sat}") from None
        return idx, observations

    return _iter_epochs(lines, idx, header, path, _RINEX2_EPOCH, read_block)


def _iter_obs3(
    lines: list[str], idx: int, header: RinexObsHeader, path: str | Path
) -> Iterator[RinexObsEpoch]:
    n = len(lines)

    def read_block(idx: int, nsat: int, line_no: int) -> tuple[int, dict[str, dict[str, float]]]:
        # One record per satellite after the epoch record: system and number, then the header's codes of its system.
        idx += 1
        observations: dict[str, dict[str, float]] = {}
        for _ in range(nsat):
            if idx >= n:
                raise RinexFormatError(path, idx, "file ends inside an epoch's observations")
            rec = lines[idx]
            rec_no = idx + 1
            idx += 1
            sys_char = rec[0:1].upper()
            try:
                sat = sat_id(rec[0:3], "G")
            except ValueError:
                raise RinexFormatError(path, rec_no, f"malformed satellite id {rec[0:3]!r}") from None
            codes = header.obs_types.get(sys_char)
            if codes is None:
                raise RinexFormatError(path, rec_no, f"satellite system {sys_char!r} not declared in header")
            try:
                observations[sat] = _parse_obs_values(_split_fields(rec, 3, len(codes)), codes)
            except ValueError:
                raise RinexFormatError(path, rec_no, f"malformed observation value for {sat}") from None
        return idx, observations

    return _iter_epochs(lines, idx, header, path, _RINEX3_EPOCH, read_block)
