"""RINEX 2.10/2.11 and 3.0x observation and GPS navigation readers.

Readers return plain frozen dataclasses; malformed input raises :class:`RinexFormatError`
(a ``ValueError``) whose message names the file and the 1-based line number.

Scope
-----
- Observation files, RINEX 2.x (``# / TYPES OF OBSERV``, 80-column epoch records with
  continuation lines for > 12 satellites and > 5 observables) and RINEX 3.x
  (``SYS / # / OBS TYPES``, ``>`` epoch records). Event flags 2-5 (header records inside the
  data) and 6 (cycle-slip records) are skipped. Blank or zero-filled fields become NaN.
  Satellite ids are normalised to ``"G05"`` style (RINEX 2 blank system letter means GPS).
- Navigation files: GPS LNAV records from RINEX 2.x GPS nav files (``N``) and RINEX 3.x
  (``N``, any constellation mix; non-GPS records are skipped and counted). Klobuchar parameters
  from ``ION ALPHA`` / ``ION BETA`` (2.x) or ``IONOSPHERIC CORR GPSA/GPSB`` (3.x).
- Epoch times are on the GPS time scale (RINEX "GPS" time system); other time systems are
  rejected with a clear error for GPS processing.

Notes
-----
Gurtner & Estey, RINEX 2.11 (2007), tables A1-A4; IGS RINEX 3.04/3.05 (2020), tables A1-A8.
"""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gnss_common.ephemeris import DEFAULT_FIT_INTERVAL_H, GpsEphemeris
from gnss_common.gps_time import datetime_to_gps

_RINEX2_OBS_PER_LINE = 5
_RINEX2_SATS_PER_LINE = 12
_OBS_FIELD_WIDTH = 16
_NAV3_LINES = {"G": 8, "E": 8, "C": 8, "J": 8, "I": 8, "R": 4, "S": 4}


class RinexFormatError(ValueError):
    """Malformed RINEX input; the message names file and line."""

    def __init__(self, path: str | Path, line_no: int, message: str) -> None:
        super().__init__(f"{path}:{line_no}: {message}")
        self.path = str(path)
        self.line_no = line_no


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
        time_system: TIME OF FIRST OBS time system ("GPS" default).
    """

    version: float
    file_system: str
    marker_name: str
    approx_position_ecef_m: np.ndarray | None
    obs_types: dict[str, tuple[str, ...]]
    interval_s: float
    time_system: str


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


@dataclass(frozen=True)
class RinexNavHeader:
    """Navigation-file header fields.

    Attributes:
        version: RINEX version.
        iono_alpha: Klobuchar alpha_0..3 (s, s/sc, s/sc^2, s/sc^3), shape (4,), NaN if absent.
        iono_beta: Klobuchar beta_0..3 (s, s/sc, s/sc^2, s/sc^3), shape (4,), NaN if absent.
        leap_seconds: GPS - UTC leap seconds from the header, or None.
    """

    version: float
    iono_alpha: np.ndarray
    iono_beta: np.ndarray
    leap_seconds: int | None


@dataclass(frozen=True)
class RinexNav:
    """A navigation file: header, GPS ephemerides, and counts of skipped records by system."""

    path: str
    header: RinexNavHeader
    ephemerides: tuple[GpsEphemeris, ...]
    skipped_records: dict[str, int] = field(default_factory=dict)


# ----------------------------------------------------------------------------------------------
# helpers


def _read_lines(path: str | Path) -> list[str]:
    p = Path(path)
    try:
        text = p.read_text(encoding="ascii", errors="replace")
    except OSError as exc:
        raise RinexFormatError(p, 0, f"cannot read file: {exc}") from exc
    return text.splitlines()


def _label(line: str) -> str:
    return line[60:80].strip()


def _float_field(text: str, path: str | Path, line_no: int, what: str, blank: float = math.nan) -> float:
    s = text.strip()
    if not s:
        return blank
    try:
        return float(s.replace("D", "E").replace("d", "e"))
    except ValueError:
        raise RinexFormatError(path, line_no, f"cannot parse {what} from {text!r}") from None


def _int_field(text: str, path: str | Path, line_no: int, what: str) -> int:
    s = text.strip()
    try:
        return int(s)
    except ValueError:
        raise RinexFormatError(path, line_no, f"cannot parse integer {what} from {text!r}") from None


def _two_digit_year(yy: int) -> int:
    # RINEX 2: 80-99 -> 1980-1999, 00-79 -> 2000-2079.
    return yy + 1900 if yy >= 80 else yy + 2000


def _epoch_to_gps(
    year: int, month: int, day: int, hour: int, minute: int, sec: float, path: str | Path, line_no: int
) -> tuple[int, float]:
    if not (math.isfinite(sec) and 0.0 <= sec < 61.0):
        raise RinexFormatError(path, line_no, f"seconds field out of range: {sec}")
    try:
        base = _dt.datetime(year, month, day, hour, minute)
    except ValueError as exc:
        raise RinexFormatError(path, line_no, f"invalid epoch date/time: {exc}") from None
    week, tow = datetime_to_gps(base)
    tow = tow + sec
    if tow >= 604800.0:
        week, tow = week + 1, tow - 604800.0
    return week, tow


def _sat_id(token: str, default_system: str) -> str:
    token = token.rstrip()
    sys_char = token[0] if token and token[0].isalpha() else " "
    num = token[1:] if sys_char != " " else token
    num = num.strip()
    if sys_char == " ":
        sys_char = default_system
    return f"{sys_char}{int(num):02d}"


# ----------------------------------------------------------------------------------------------
# observation files


def read_rinex_obs(path: str | Path) -> RinexObs:
    """Read a RINEX 2.10/2.11 or 3.0x observation file.

    Args:
        path: file path.

    Returns:
        :class:`RinexObs` with all epochs of flag 0 or 1 in file order.

    Raises:
        RinexFormatError: unreadable file, missing ``END OF HEADER``, unsupported version or file
            type, malformed epoch or observation records (message names file and line).
    """
    lines = _read_lines(path)
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
    if _label(first) != "RINEX VERSION / TYPE":
        raise RinexFormatError(path, 1, "first line is not 'RINEX VERSION / TYPE'")
    version = _float_field(first[0:9], path, 1, "RINEX version")
    if not (2.0 <= version < 4.0):
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
    end = None
    for idx in range(1, len(lines)):
        line = lines[idx]
        line_no = idx + 1
        label = _label(line)
        if label == "END OF HEADER":
            end = idx + 1
            break
        if label == "MARKER NAME":
            marker = line[0:60].strip()
        elif label == "APPROX POSITION XYZ":
            xyz = np.array(
                [_float_field(line[i : i + 14], path, line_no, "APPROX POSITION") for i in (0, 14, 28)]
            )
            approx = xyz if np.all(np.isfinite(xyz)) and np.linalg.norm(xyz) > 1.0e6 else None
        elif label == "INTERVAL":
            interval = _float_field(line[0:10], path, line_no, "INTERVAL")
        elif label == "TIME OF FIRST OBS":
            time_system = line[48:51].strip() or "GPS"
        elif label == "# / TYPES OF OBSERV":
            if line[0:6].strip():
                v2_count = _int_field(line[0:6], path, line_no, "number of observation types")
            for k in range(9):
                code = line[10 + 6 * k : 12 + 6 * k].strip()
                if code:
                    v2_types.append(code)
        elif label == "SYS / # / OBS TYPES":
            if line[0:1].strip():
                v3_current = line[0:1].upper()
                v3_count = _int_field(line[3:6], path, line_no, "number of observation types")
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
    if time_system not in ("GPS", ""):
        raise RinexFormatError(path, end, f"time system {time_system!r} not supported (GPS time expected)")
    header = RinexObsHeader(
        version=version,
        file_system=file_system,
        marker_name=marker,
        approx_position_ecef_m=approx,
        obs_types=types,
        interval_s=interval,
        time_system=time_system or "GPS",
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


def _iter_obs2(
    lines: list[str], idx: int, header: RinexObsHeader, path: str | Path
) -> Iterator[RinexObsEpoch]:
    n = len(lines)
    n_types = len(header.obs_types["G"])
    lines_per_sat = (n_types + _RINEX2_OBS_PER_LINE - 1) // _RINEX2_OBS_PER_LINE
    default_sys = header.file_system if header.file_system in "GRESJ" and header.file_system != "M" else "G"
    while idx < n:
        line = lines[idx]
        line_no = idx + 1
        if not line.strip():
            idx += 1
            continue
        if len(line) < 32:
            raise RinexFormatError(path, line_no, "epoch record shorter than 32 columns")
        flag = _int_field(line[26:29], path, line_no, "epoch flag")
        nsat = _int_field(line[29:32], path, line_no, "number of satellites")
        if flag > 1:
            # Event: nsat is the number of special records that follow (header lines or slips).
            idx += 1 + nsat
            continue
        try:
            yy, mo, dd, hh, mi = (int(line[k : k + 3]) for k in (0, 3, 6, 9, 12))
        except ValueError:
            raise RinexFormatError(path, line_no, f"malformed epoch date in {line[0:26]!r}") from None
        sec = _float_field(line[15:26], path, line_no, "epoch seconds")
        week, tow = _epoch_to_gps(_two_digit_year(yy), mo, dd, hh, mi, sec, path, line_no)
        clock = (
            _float_field(line[68:80], path, line_no, "receiver clock offset") if len(line) > 68 else math.nan
        )
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
                sats.append(_sat_id(tok, default_sys))
            except ValueError:
                raise RinexFormatError(path, line_no, f"malformed satellite id {tok!r}") from None
        idx += max(sat_lines, 1)
        observations: dict[str, dict[str, float]] = {}
        codes = header.obs_types["G"]
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
        yield RinexObsEpoch(
            gps_week=week,
            tow_s=tow,
            epoch_flag=flag,
            receiver_clock_offset_s=clock,
            observations=observations,
            line_no=line_no,
        )


def _iter_obs3(
    lines: list[str], idx: int, header: RinexObsHeader, path: str | Path
) -> Iterator[RinexObsEpoch]:
    n = len(lines)
    while idx < n:
        line = lines[idx]
        line_no = idx + 1
        if not line.strip():
            idx += 1
            continue
        if not line.startswith(">"):
            raise RinexFormatError(path, line_no, "expected an epoch record starting with '>'")
        if len(line) < 35:
            raise RinexFormatError(path, line_no, "epoch record shorter than 35 columns")
        flag = _int_field(line[31:32], path, line_no, "epoch flag")
        nsat = _int_field(line[32:35], path, line_no, "number of satellites")
        if flag > 1:
            idx += 1 + nsat
            continue
        try:
            year = int(line[2:6])
            mo, dd, hh, mi = (int(line[k : k + 3]) for k in (6, 9, 12, 15))
        except ValueError:
            raise RinexFormatError(path, line_no, f"malformed epoch date in {line[0:29]!r}") from None
        sec = _float_field(line[18:29], path, line_no, "epoch seconds")
        week, tow = _epoch_to_gps(year, mo, dd, hh, mi, sec, path, line_no)
        clock = (
            _float_field(line[41:56], path, line_no, "receiver clock offset") if len(line) > 41 else math.nan
        )
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
                sat = _sat_id(rec[0:3], "G")
            except ValueError:
                raise RinexFormatError(path, rec_no, f"malformed satellite id {rec[0:3]!r}") from None
            codes = header.obs_types.get(sys_char)
            if codes is None:
                raise RinexFormatError(path, rec_no, f"satellite system {sys_char!r} not declared in header")
            try:
                observations[sat] = _parse_obs_values(_split_fields(rec, 3, len(codes)), codes)
            except ValueError:
                raise RinexFormatError(path, rec_no, f"malformed observation value for {sat}") from None
        yield RinexObsEpoch(
            gps_week=week,
            tow_s=tow,
            epoch_flag=flag,
            receiver_clock_offset_s=clock,
            observations=observations,
            line_no=line_no,
        )


# ----------------------------------------------------------------------------------------------
# navigation files


def read_rinex_nav(path: str | Path) -> RinexNav:
    """Read GPS LNAV ephemerides and Klobuchar parameters from a RINEX 2.x or 3.x nav file.

    Args:
        path: file path.

    Returns:
        :class:`RinexNav`; non-GPS records of RINEX 3 mixed files are skipped and counted in
        ``skipped_records`` by system letter.

    Raises:
        RinexFormatError: unreadable file, wrong type, truncated or malformed records.
    """
    lines = _read_lines(path)
    if not lines or _label(lines[0]) != "RINEX VERSION / TYPE":
        raise RinexFormatError(path, 1, "first line is not 'RINEX VERSION / TYPE'")
    version = _float_field(lines[0][0:9], path, 1, "RINEX version")
    ftype = lines[0][20:21].upper()
    if not (2.0 <= version < 4.0):
        raise RinexFormatError(path, 1, f"unsupported RINEX version {version}")
    if ftype != "N":
        raise RinexFormatError(path, 1, f"not a GPS/mixed navigation file (type {ftype!r})")
    if version >= 3.0 and lines[0][40:41].strip().upper() not in ("", "G", "M"):
        raise RinexFormatError(path, 1, f"navigation file for system {lines[0][40:41]!r}, GPS expected")
    alpha = np.full(4, math.nan)
    beta = np.full(4, math.nan)
    leap: int | None = None
    end = None
    for idx in range(1, len(lines)):
        line = lines[idx]
        line_no = idx + 1
        label = _label(line)
        if label == "END OF HEADER":
            end = idx + 1
            break
        if label == "ION ALPHA":
            alpha = np.array(
                [_float_field(line[2 + 12 * k : 14 + 12 * k], path, line_no, "ION ALPHA") for k in range(4)]
            )
        elif label == "ION BETA":
            beta = np.array(
                [_float_field(line[2 + 12 * k : 14 + 12 * k], path, line_no, "ION BETA") for k in range(4)]
            )
        elif label == "IONOSPHERIC CORR":
            vals = np.array(
                [
                    _float_field(line[5 + 12 * k : 17 + 12 * k], path, line_no, "IONOSPHERIC CORR")
                    for k in range(4)
                ]
            )
            if line[0:4] == "GPSA":
                alpha = vals
            elif line[0:4] == "GPSB":
                beta = vals
        elif label == "LEAP SECONDS":
            leap = _int_field(line[0:6], path, line_no, "LEAP SECONDS")
    if end is None:
        raise RinexFormatError(path, len(lines), "no END OF HEADER")
    header = RinexNavHeader(version=version, iono_alpha=alpha, iono_beta=beta, leap_seconds=leap)
    ephs: list[GpsEphemeris] = []
    skipped: dict[str, int] = {}
    idx = end
    n = len(lines)
    while idx < n:
        line = lines[idx]
        if not line.strip():
            idx += 1
            continue
        if version < 3.0:
            nrec = 8
            sys_char = "G"
            first_vals_start = 22
            lead = 3
        else:
            sys_char = line[0:1].upper()
            if sys_char not in _NAV3_LINES:
                raise RinexFormatError(path, idx + 1, f"unknown satellite system {sys_char!r} in nav record")
            nrec = _NAV3_LINES[sys_char]
            first_vals_start = 23
            lead = 4
        if idx + nrec > n:
            raise RinexFormatError(path, idx + 1, f"navigation record truncated (needs {nrec} lines)")
        if sys_char != "G":
            skipped[sys_char] = skipped.get(sys_char, 0) + 1
            idx += nrec
            continue
        ephs.append(
            _parse_gps_record(lines[idx : idx + nrec], idx + 1, version, first_vals_start, lead, path)
        )
        idx += nrec
    return RinexNav(path=str(path), header=header, ephemerides=tuple(ephs), skipped_records=skipped)


def _parse_gps_record(
    rec: list[str], line_no: int, version: float, start: int, lead: int, path: str | Path
) -> GpsEphemeris:
    first = rec[0]
    try:
        if version < 3.0:
            prn = int(first[0:2])
            yy, mo, dd, hh, mi = (int(first[k : k + 3]) for k in (2, 5, 8, 11, 14))
            year = _two_digit_year(yy)
            sec = float(first[17:22])
        else:
            prn = int(first[1:3])
            year = int(first[4:8])
            mo, dd, hh, mi, isec = (int(first[k : k + 3]) for k in (8, 11, 14, 17, 20))
            sec = float(isec)
    except ValueError:
        raise RinexFormatError(path, line_no, f"malformed navigation record epoch {first[0:23]!r}") from None
    toc_week, toc_s = _epoch_to_gps(year, mo, dd, hh, mi, sec, path, line_no)
    vals: list[float] = []
    for k in range(3):
        vals.append(
            _float_field(first[start + 19 * k : start + 19 * (k + 1)], path, line_no, "clock parameter")
        )
    for j in range(1, 8):
        line = rec[j]
        for k in range(4):
            vals.append(
                _float_field(
                    line[lead + 19 * k : lead + 19 * (k + 1)],
                    path,
                    line_no + j,
                    f"orbit parameter {len(vals) + 1}",
                    blank=0.0,
                )
            )
    if any(not math.isfinite(v) for v in vals[:3]):
        raise RinexFormatError(path, line_no, "blank satellite clock parameter")
    (
        af0,
        af1,
        af2,
        iode,
        crs,
        dn,
        m0,
        cuc,
        e,
        cus,
        sqa,
        toe,
        cic,
        om0,
        cis,
        i0,
        crc,
        om,
        omd,
        idot,
        _l2codes,
        week,
        _l2p,
        acc,
        health,
        tgd,
        iodc,
        ttm,
        fit,
    ) = vals[:29]
    if sqa < 1000.0 or not (0.0 <= e < 1.0):
        raise RinexFormatError(path, line_no, f"PRN {prn}: non-physical orbit (sqrt(A)={sqa}, e={e})")
    fit_h = fit if fit >= DEFAULT_FIT_INTERVAL_H else DEFAULT_FIT_INTERVAL_H
    try:
        return GpsEphemeris(
            prn=prn,
            toc_week=toc_week,
            toc_s=toc_s,
            af0_s=af0,
            af1_s_per_s=af1,
            af2_s_per_s2=af2,
            iode=int(iode),
            crs_m=crs,
            delta_n_radps=dn,
            m0_rad=m0,
            cuc_rad=cuc,
            e=e,
            cus_rad=cus,
            sqrt_a_sqrt_m=sqa,
            toe_s=toe,
            cic_rad=cic,
            omega0_rad=om0,
            cis_rad=cis,
            i0_rad=i0,
            crc_m=crc,
            omega_rad=om,
            omega_dot_radps=omd,
            idot_radps=idot,
            week=int(week),
            sv_accuracy_m=acc,
            health=int(health),
            tgd_s=tgd,
            iodc=int(iodc),
            transmission_time_s=ttm,
            fit_interval_h=fit_h,
        )
    except ValueError as exc:
        raise RinexFormatError(path, line_no, str(exc)) from None
