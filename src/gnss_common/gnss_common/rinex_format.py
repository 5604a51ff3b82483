"""What the RINEX observation and navigation readers share (rinex module): reading a file as stations publish it
(plain, gzip, Unix compress, Hatanaka), header records, fixed-width fields, epochs to GPS time, satellite ids, and the
error every reader raises (:class:`RinexFormatError`, naming file and line)."""

from __future__ import annotations

import calendar
import datetime as _dt
import math
from collections.abc import Iterator, Mapping
from pathlib import Path

import hatanaka

from gnss_common.constants import BEIDOU_MINUS_GPS_TIME_S
from gnss_common.gps_time import datetime_to_gps, leap_seconds_at_ros_stamp

SYSTEM_NAMES = {"G": "gps", "R": "glonass", "E": "galileo", "C": "beidou", "J": "qzss", "S": "sbas", "I": "navic"}
"""RINEX system letter -> lower-case constellation name (used as counter keys)."""


def add_counts(total: dict[str, int], counts: Mapping[str, int]) -> None:
    """Add ``counts`` into ``total``, key by key (a key new to ``total`` starts at 0)."""
    for key, n in counts.items():
        total[key] = total.get(key, 0) + n


def add_counts_by_group(total: dict[str, dict[str, int]], counts: Mapping[str, Mapping[str, int]]) -> None:
    """:func:`add_counts` per group (e.g. skipped records by constellation, then by reason)."""
    for group, by_key in counts.items():
        add_counts(total.setdefault(group, {}), by_key)



class RinexFormatError(ValueError):
    """Malformed RINEX input; the message names file and line."""

    def __init__(self, path: str | Path, line_no: int, message: str) -> None:
        super().__init__(f"{path}:{line_no}: {message}")
        self.path = str(path)
        self.line_no = line_no



def read_lines(path: str | Path) -> list[str]:
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise RinexFormatError(p, 0, f"cannot read file: {exc}") from exc
    if is_compressed(raw):
        try:
            raw = hatanaka.decompress(raw)
        except Exception as exc:  # gzip/zlib/CRX errors of any type: the file is unusable
            raise RinexFormatError(
                p, 0, f"cannot decompress ({type(exc).__name__}: {exc}); truncated or corrupted file?"
            ) from None
    return raw.decode("ascii", errors="replace").splitlines()


def is_compressed(raw: bytes) -> bool:
    """gzip, Unix compress, bzip2, zip magic numbers, or a Hatanaka (CRINEX) first line."""
    if raw[:2] in (b"\x1f\x8b", b"\x1f\x9d") or raw[:3] == b"BZh" or raw[:4] == b"PK\x03\x04":
        return True
    first = raw[:100].split(b"\n", 1)[0]
    return b"CRINEX VERS" in first[60:]


def header_label(line: str) -> str:
    return line[60:80].strip()


def header_records(lines: list[str]) -> tuple[int | None, Iterator[tuple[int, str, str]]]:
    """The header of a RINEX file, after its first line: ``(end, records)``.

    ``end`` is the index of the first line after ``END OF HEADER`` (None if the file has none, which
    the caller reports after reading the records); ``records`` yields ``(line number, label, line)``
    for each header line before it (every line after the first if there is no ``END OF HEADER``).
    """
    end = next((idx + 1 for idx in range(1, len(lines)) if header_label(lines[idx]) == "END OF HEADER"), None)
    stop = len(lines) if end is None else end - 1
    return end, ((idx + 1, header_label(lines[idx]), lines[idx]) for idx in range(1, stop))


def float_field(text: str, path: str | Path, line_no: int, what: str, blank: float = math.nan) -> float:
    s = text.strip()
    if not s:
        return blank
    try:
        return float(s.replace("D", "E").replace("d", "e"))
    except ValueError:
        raise RinexFormatError(path, line_no, f"cannot parse {what} from {text!r}") from None


def int_field(text: str, path: str | Path, line_no: int, what: str) -> int:
    s = text.strip()
    try:
        return int(s)
    except ValueError:
        raise RinexFormatError(path, line_no, f"cannot parse integer {what} from {text!r}") from None


def two_digit_year(yy: int) -> int:
    # RINEX 2: 80-99 -> 1980-1999, 00-79 -> 2000-2079.
    return yy + 1900 if yy >= 80 else yy + 2000


def epoch_to_gps(
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


OBS_TIME_SYSTEMS = ("GPS", "GAL", "QZS", "BDT", "GLO")
"""Observation-file time systems read (epochs are converted to GPS time): GST and QZSST are
aligned to GPST (offsets of a few ns neglected), BDT = GPST - 14 s, GLO = UTC(SU) + 3 h (RINEX
files give GLO epochs as UTC, RINEX 2.11 5.6 / 3.05 5.6)."""


def obs_epoch_to_gps(
    time_system: str, year: int, month: int, day: int, hour: int, minute: int, sec: float,
    path: str | Path, line_no: int,
) -> tuple[int, float]:
    """A calendar epoch on an observation file's time system -> (GPS week, GPS time of week)."""
    week, tow = epoch_to_gps(year, month, day, hour, minute, sec, path, line_no)
    if time_system == "BDT":
        tow -= BEIDOU_MINUS_GPS_TIME_S
    elif time_system == "GLO":  # given as UTC in RINEX
        tow += leap_seconds_at_ros_stamp(calendar.timegm((year, month, day, hour, minute, 0, 0, 0, 0)) * 1_000_000_000)
    if tow >= 604800.0:
        week, tow = week + 1, tow - 604800.0
    return week, tow


def sat_id(token: str, default_system: str) -> str:
    token = token.rstrip()
    sys_char = token[0] if token and token[0].isalpha() else " "
    num = token[1:] if sys_char != " " else token
    num = num.strip()
    if sys_char == " ":
        sys_char = default_system
    return f"{sys_char}{int(num):02d}"


# ----------------------------------------------------------------------------------------------
# observation files


