"""RINEX 2.x, 3.x and 4.x navigation files (rinex module docstring: scope): :func:`read_rinex_nav`,
:func:`read_rinex_navs`."""

from __future__ import annotations

import calendar
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gnss_common.constants import BEIDOU_WEEK_OFFSET
from gnss_common.ephemeris import DEFAULT_FIT_INTERVAL_H, GpsEphemeris
from gnss_common.glonass import GlonassEphemeris
from gnss_common.gps_time import leap_seconds_at_ros_stamp
from gnss_common.rinex_format import (
    RinexFormatError,
    add_counts,
    add_counts_by_group,
    epoch_to_gps,
    float_field,
    header_label,
    header_records,
    int_field,
    read_lines,
    two_digit_year,
)

_NAV3_LINES = {"G": 8, "E": 8, "C": 8, "J": 8, "I": 8, "R": 4, "S": 4}
NAV_SKIP_REASONS = (
    "unsupported_system", "non_physical_orbit", "galileo_fnav", "unsupported_message", "sto_record", "eop_record",
    "ion_record", "unknown_record",
)
"""Reasons a navigation record is not used (keys of :attr:`RinexNav.skipped_reasons` entries)."""

_GALILEO_INAV_SOURCES = 0b101  # data source bits 0 (I/NAV E1-B) and 2 (I/NAV E5b-I)
_GALILEO_E1_HEALTH_BITS = 0b111  # E1-B DVS (bit 0) and HS (bits 1-2), RINEX 3.05 Table A8
_QZSS_HEALTH_MASK = 0xFE  # the LSB flags the L6 (LEX) signal only (as RTKLIB does for L1 users)



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
    """A navigation file (or several merged): header, ephemerides, records not used.

    Attributes:
        path: the file (merged: the files joined by ``";"``).
        header: Klobuchar parameters and leap seconds.
        ephemerides: GPS LNAV records only (as before multi-GNSS support; the simulators use them).
        skipped_records: system letter -> number of records not used.
        other_ephemerides: Galileo, BeiDou and QZSS records (``GpsEphemeris.system`` "E", "C", "J").
        glonass_ephemerides: GLONASS records.
        skipped_reasons: system letter -> {reason (:data:`NAV_SKIP_REASONS`): records}.
    """

    path: str
    header: RinexNavHeader
    ephemerides: tuple[GpsEphemeris, ...]
    skipped_records: dict[str, int] = field(default_factory=dict)
    other_ephemerides: tuple[GpsEphemeris, ...] = ()
    glonass_ephemerides: tuple[GlonassEphemeris, ...] = ()
    skipped_reasons: dict[str, dict[str, int]] = field(default_factory=dict)

    @property
    def keplerian_ephemerides(self) -> tuple[GpsEphemeris, ...]:
        """GPS, Galileo, BeiDou and QZSS records together."""
        return self.ephemerides + self.other_ephemerides

    def record_counts(self) -> dict[str, int]:
        """System letter -> records read and kept."""
        out: dict[str, int] = {}
        for e in self.keplerian_ephemerides:
            out[e.system] = out.get(e.system, 0) + 1
        if self.glonass_ephemerides:
            out["R"] = len(self.glonass_ephemerides)
        return out


# ----------------------------------------------------------------------------------------------
# helpers




def read_rinex_nav(path: str | Path) -> RinexNav:
    """Read broadcast ephemerides and Klobuchar parameters from a RINEX 2.x, 3.x or 4.x nav file.

    Args:
        path: file path (plain or compressed, see the module docstring).

    Returns:
        :class:`RinexNav`: GPS records in ``ephemerides``, Galileo/BeiDou/QZSS records in
        ``other_ephemerides``, GLONASS records in ``glonass_ephemerides``; records not used are
        counted in ``skipped_records`` by system letter, with the reasons in ``skipped_reasons``.

    Raises:
        RinexFormatError: unreadable file, wrong type, truncated or malformed records.
    """
    lines = read_lines(path)
    version, glonass_v2, alpha, beta, leap, end = _parse_nav_header(lines, path)
    header = RinexNavHeader(version=version, iono_alpha=alpha, iono_beta=beta, leap_seconds=leap)
    ephs: list[GpsEphemeris] = []
    others: list[GpsEphemeris] = []
    fnav: list[GpsEphemeris] = []
    glonass: list[GlonassEphemeris] = []
    skipped: dict[str, int] = {}
    reasons: dict[str, dict[str, int]] = {}

    def skip(sys_char: str, reason: str) -> None:
        skipped[sys_char] = skipped.get(sys_char, 0) + 1
        by = reasons.setdefault(sys_char, {})
        by[reason] = by.get(reason, 0) + 1

    def take(sys_char: str, rec: list[str], rec_no: int, first_vals_start: int, lead: int) -> None:
        """One ephemeris record (its lines in the RINEX 2 / 3 layout) into the lists above."""
        if sys_char == "G":
            ephs.append(_parse_gps_record(rec, rec_no, version, first_vals_start, lead, path))
        elif sys_char in ("E", "C", "J"):
            eph, reason = _parse_kepler_record(rec, rec_no, sys_char, path)
            if eph is None:
                skip(sys_char, reason)
            elif reason == "galileo_fnav":
                fnav.append(eph)
            else:
                others.append(eph)
        elif sys_char == "R":
            glo, reason = _parse_glonass_record(rec, rec_no, leap, path, rinex2=version < 3.0)
            if glo is None:
                skip(sys_char, reason)
            else:
                glonass.append(glo)
        else:
            skip(sys_char, "unsupported_system")

    idx = end
    n = len(lines)
    if version >= 4.0:
        ion = _read_nav4_records(lines, end, path, take, skip)
        if ion is not None and not (np.all(np.isfinite(alpha)) and np.all(np.isfinite(beta))):
            alpha, beta = ion
            header = RinexNavHeader(version=version, iono_alpha=alpha, iono_beta=beta, leap_seconds=leap)
        idx = n
    _read_nav23_records(lines, idx, version, glonass_v2, path, take)
    # Galileo F/NAV records only for satellites the file gives no I/NAV record of (the E1 user's
    # own message); the others are counted as not used.
    inav = {e.prn for e in others if e.system == "E"}
    for eph in fnav:
        if eph.prn in inav:
            skip("E", "galileo_fnav")
        else:
            others.append(eph)
    return RinexNav(
        path=str(path),
        header=header,
        ephemerides=tuple(ephs),
        skipped_records=skipped,
        other_ephemerides=tuple(others),
        glonass_ephemerides=tuple(glonass),
        skipped_reasons=reasons,
    )


def _parse_nav_header(lines: list[str], path: str | Path
                      ) -> tuple[float, bool, np.ndarray, np.ndarray, int | None, int]:
    """The header of a nav file: (version, RINEX 2 GLONASS file, Klobuchar alpha and beta (NaN when absent), leap
    seconds (None when absent), index of the first record line)."""
    if not lines or header_label(lines[0]) != "RINEX VERSION / TYPE":
        raise RinexFormatError(path, 1, "first line is not 'RINEX VERSION / TYPE'")
    version = float_field(lines[0][0:9], path, 1, "RINEX version")
    ftype = lines[0][20:21].upper()
    if not (2.0 <= version < 5.0):
        raise RinexFormatError(path, 1, f"unsupported RINEX version {version}")
    glonass_v2 = version < 3.0 and ftype == "G"  # RINEX 2 GLONASS nav file (".g")
    if ftype != "N" and not glonass_v2:
        raise RinexFormatError(
            path, 1, f"not a RINEX 2 GPS / GLONASS or RINEX 3 navigation file (type {ftype!r})"
        )
    if version >= 3.0 and lines[0][40:41].strip().upper() not in ("", "M", *_NAV3_LINES):
        raise RinexFormatError(path, 1, f"navigation file for unknown system {lines[0][40:41]!r}")
    alpha = np.full(4, math.nan)
    beta = np.full(4, math.nan)
    leap: int | None = None
    end, records = header_records(lines)
    for line_no, label, line in records:
        if label == "ION ALPHA":
            alpha = np.array(
                [float_field(line[2 + 12 * k : 14 + 12 * k], path, line_no, "ION ALPHA") for k in range(4)]
            )
        elif label == "ION BETA":
            beta = np.array(
                [float_field(line[2 + 12 * k : 14 + 12 * k], path, line_no, "ION BETA") for k in range(4)]
            )
        elif label == "IONOSPHERIC CORR":
            vals = np.array(
                [
                    float_field(line[5 + 12 * k : 17 + 12 * k], path, line_no, "IONOSPHERIC CORR")
                    for k in range(4)
                ]
            )
            if line[0:4] == "GPSA":
                alpha = vals
            elif line[0:4] == "GPSB":
                beta = vals
        elif label == "LEAP SECONDS":
            leap = int_field(line[0:6], path, line_no, "LEAP SECONDS")
    if end is None:
        raise RinexFormatError(path, len(lines), "no END OF HEADER")
    return version, glonass_v2, alpha, beta, leap, end


def _read_nav23_records(lines: list[str], idx: int, version: float, glonass_v2: bool, path: str | Path,
                        take: Callable[[str, list[str], int, int, int], None]) -> None:
    """The ephemeris records of a RINEX 2 or 3 nav file from line index idx, each handed to take(system letter,
    lines, line number, column of the first value, width of the lead field)."""
    n = len(lines)
    while idx < n:
        line = lines[idx]
        if not line.strip():
            idx += 1
            continue
        if version < 3.0:
            nrec = 4 if glonass_v2 else 8
            sys_char = "R" if glonass_v2 else "G"
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
        for j in range(1, nrec):
            if lines[idx + j][0:1].strip():
                raise RinexFormatError(
                    path, idx + j + 1, f"navigation record of {lines[idx][0:3]!r} truncated (needs {nrec} lines)"
                )
        rec = lines[idx : idx + nrec]
        rec_no = idx + 1
        idx += nrec
        if version >= 3.0:
            # Optional further lines (RINEX 3.05 adds a fifth GLONASS line): blank first column.
            while idx < n and lines[idx].strip() and not lines[idx][0:1].strip():
                idx += 1
        take(sys_char, rec, rec_no, first_vals_start, lead)


def read_rinex_navs(paths: Sequence[str | Path]) -> RinexNav:
    """Read several navigation files (e.g. one per system) and merge them.

    Args:
        paths: one or more nav files, any systems.

    Returns:
        One :class:`RinexNav`: the records of all files; the header of the first file that has
        Klobuchar parameters (alpha and beta) and of the first that has leap seconds; skipped
        records summed.

    Raises:
        RinexFormatError: as :func:`read_rinex_nav`, for any file.
        ValueError: no path given.
    """
    if not paths:
        raise ValueError("read_rinex_navs: no navigation file given")
    navs = [read_rinex_nav(p) for p in paths]
    if len(navs) == 1:
        return navs[0]
    iono = next((v.header for v in navs if np.all(np.isfinite(v.header.iono_alpha))
                 and np.all(np.isfinite(v.header.iono_beta))), navs[0].header)
    leap = next((v.header.leap_seconds for v in navs if v.header.leap_seconds is not None), None)
    skipped: dict[str, int] = {}
    reasons: dict[str, dict[str, int]] = {}
    for v in navs:
        add_counts(skipped, v.skipped_records)
        add_counts_by_group(reasons, v.skipped_reasons)
    header = RinexNavHeader(
        version=navs[0].header.version, iono_alpha=iono.iono_alpha, iono_beta=iono.iono_beta, leap_seconds=leap
    )
    return RinexNav(
        path=";".join(v.path for v in navs),
        header=header,
        ephemerides=tuple(e for v in navs for e in v.ephemerides),
        skipped_records=skipped,
        other_ephemerides=tuple(e for v in navs for e in v.other_ephemerides),
        glonass_ephemerides=tuple(e for v in navs for e in v.glonass_ephemerides),
        skipped_reasons=reasons,
    )


_NAV4_MESSAGES = {"G": ("LNAV",), "J": ("LNAV",), "E": ("INAV", "FNAV"), "C": ("D1", "D2"), "R": ("FDMA",)}
"""RINEX 4 ephemeris message types read, by system: those whose records have the RINEX 3 layout
(RINEX 4.01); CNAV, CNV1-3 and the SBAS and NavIC records are counted, not used."""


def _read_nav4_records(
    lines: list[str], start: int, path: str | Path, take, skip
) -> tuple[np.ndarray, np.ndarray] | None:
    """The data section of a RINEX 4 navigation file: records introduced by ``> TYPE SAT MESSAGE``.

    ``EPH`` records of the messages in :data:`_NAV4_MESSAGES` go to ``take(sys_char, lines,
    line_no, 23, 4)`` (their lines are those of RINEX 3); other ``EPH`` messages are counted with
    ``skip(sys_char, "unsupported_message")``, ``STO`` / ``EOP`` records with ``"sto_record"`` /
    ``"eop_record"``, ``ION`` records other than the first GPS ``LNAV`` one with ``"ion_record"``.

    Returns:
        The Klobuchar ``(alpha, beta)`` of the first ``ION G.. LNAV`` record (alpha0-2 on its
        epoch line, alpha3 and beta0-2 on the next, beta3 on the third), or None when the file
        has none.

    Raises:
        RinexFormatError: a record line before the first ``>``, a malformed ``>`` line, a record
            shorter than its message needs or whose first line names another satellite.
    """
    ion: tuple[np.ndarray, np.ndarray] | None = None
    n = len(lines)
    idx = start
    while idx < n and not lines[idx].strip():
        idx += 1
    while idx < n:
        head = lines[idx]
        head_no = idx + 1
        if not head.startswith(">"):
            raise RinexFormatError(path, head_no, "RINEX 4 navigation data: expected a '> TYPE SAT MESSAGE' line")
        parts = head[1:].split()
        if len(parts) < 2 or len(parts[1]) != 3 or not parts[1][1:].isdigit():
            raise RinexFormatError(path, head_no, f"malformed RINEX 4 record line {head.rstrip()!r}")
        kind, sat = parts[0].upper(), parts[1].upper()
        msg = parts[2].upper() if len(parts) > 2 else ""
        sys_char = sat[0]
        idx += 1
        body_start = idx
        while idx < n and not lines[idx].startswith(">"):
            idx += 1
        body = [ln for ln in lines[body_start:idx] if ln.strip()]
        rec_no = body_start + 1
        if kind == "EPH":
            if msg not in _NAV4_MESSAGES.get(sys_char, ()):
                skip(sys_char, "unsupported_system" if sys_char not in _NAV4_MESSAGES else "unsupported_message")
                continue
            need = _NAV3_LINES[sys_char]
            if len(body) < need:
                raise RinexFormatError(path, head_no, f"{sat} {msg} record truncated (needs {need} lines)")
            if body[0][0:3].upper() != sat:
                raise RinexFormatError(path, rec_no, f"record of {body[0][0:3]!r} under '> EPH {sat}'")
            take(sys_char, body[:need], rec_no, 23, 4)
        elif kind == "ION" and sys_char == "G" and msg == "LNAV" and ion is None:
            if len(body) < 3:
                raise RinexFormatError(path, head_no, f"ION {sat} LNAV record truncated (needs 3 lines)")
            vals = [float_field(body[0][23 + 19 * k: 42 + 19 * k], path, rec_no, "Klobuchar alpha") for k in range(3)]
            vals += [float_field(body[1][4 + 19 * k: 23 + 19 * k], path, rec_no + 1, "Klobuchar parameter")
                     for k in range(4)]
            vals.append(float_field(body[2][4:23], path, rec_no + 2, "Klobuchar beta3"))
            v = np.array(vals)
            if np.all(np.isfinite(v)):
                ion = (v[0:4], v[4:8])
        elif kind in ("STO", "EOP", "ION"):
            skip(sys_char, f"{kind.lower()}_record")
        else:
            skip(sys_char, "unknown_record")
    return ion


def _record_values(
    rec: list[str], line_no: int, path: str | Path, n_lines: int, rinex2: bool = False
) -> list[float]:
    """The 3 clock values of the first line and 4 values per following line (RINEX 3 layout, or
    RINEX 2: values from column 22 / 3)."""
    start, lead = (22, 3) if rinex2 else (23, 4)
    vals = [
        float_field(rec[0][start + 19 * k : start + 19 * (k + 1)], path, line_no, "clock parameter")
        for k in range(3)
    ]
    for j in range(1, n_lines):
        line = rec[j]
        for k in range(4):
            vals.append(
                float_field(line[lead + 19 * k : lead + 19 * (k + 1)], path, line_no + j,
                             f"orbit parameter {len(vals) + 1}", blank=0.0)
            )
    if any(not math.isfinite(v) for v in vals[:3]):
        raise RinexFormatError(path, line_no, "blank clock parameter")
    return vals


def _record_epoch(
    first: str, line_no: int, path: str | Path, rinex2: bool = False
) -> tuple[int, int, int, int, int, int, float]:
    try:
        if rinex2:  # I2 satellite, 5 x I3 (2-digit year), F5.1 seconds
            num = int(first[0:2])
            yy, mo, dd, hh, mi = (int(first[k : k + 3]) for k in (2, 5, 8, 11, 14))
            return num, two_digit_year(yy), mo, dd, hh, mi, float(first[17:22])
        num = int(first[1:3])
        year = int(first[4:8])
        mo, dd, hh, mi, isec = (int(first[k : k + 3]) for k in (8, 11, 14, 17, 20))
    except ValueError:
        raise RinexFormatError(path, line_no, f"malformed navigation record epoch {first[0:23]!r}") from None
    return num, year, mo, dd, hh, mi, float(isec)


def _parse_kepler_record(
    rec: list[str], line_no: int, sys_char: str, path: str | Path
) -> tuple[GpsEphemeris | None, str]:
    """A RINEX 3 Galileo, BeiDou or QZSS record (RINEX 3.05 Tables A8, A14, A10).

    Returns ``(ephemeris, "ok")``, ``(ephemeris, "galileo_fnav")`` for a Galileo F/NAV record
    (its clock corrected with BGD E5a/E1, its health from the E5a bits), or ``(None, reason)`` for
    a record that is well formed but not usable (a non-physical orbit)."""
    num, year, mo, dd, hh, mi, sec = _record_epoch(rec[0], line_no, path)
    # Galileo: GST calendar; BeiDou: BDT calendar; QZSS: GPST. Numbered as GPS weeks either way.
    toc_week, toc_s = epoch_to_gps(year, mo, dd, hh, mi, sec, path, line_no)
    v = _record_values(rec, line_no, path, 8)
    af0, af1, af2, iod, crs, dn, m0, cuc, e, cus, sqa, toe, cic, om0, cis, i0, crc, om, omd, idot = v[:20]
    word21, week, _spare, acc, health, grp1, grp2, ttm, last = v[20:29]
    if sqa < 1000.0 or not (0.0 <= e < 1.0):
        return None, "non_physical_orbit"
    fit_h = DEFAULT_FIT_INTERVAL_H
    if sys_char == "E":
        fnav = not int(word21) & _GALILEO_INAV_SOURCES
        if fnav:  # F/NAV: clock of the E1,E5a combination, health bits of E5a only
            tgd = grp1  # BGD E5a/E1 (OS SIS ICD 5.1.5)
            health_used = (int(health) >> 3) & _GALILEO_E1_HEALTH_BITS
        else:
            tgd = grp2  # BGD E5b/E1: the I/NAV clock is the E1,E5b combination's (OS SIS ICD 5.1.5)
            health_used = int(health) & _GALILEO_E1_HEALTH_BITS
        iodc = int(iod)
    elif sys_char == "C":
        week = week + BEIDOU_WEEK_OFFSET
        tgd = grp1  # TGD1: B1I user (BDS-SIS-ICD-B1I-3.0, 5.2.4.10)
        health_used = int(health)
        iodc = int(last)  # AODC
    else:  # QZSS, GPS layout
        tgd = grp1
        health_used = int(health) & _QZSS_HEALTH_MASK
        iodc = int(grp2)
        fit_h = last if last >= DEFAULT_FIT_INTERVAL_H else DEFAULT_FIT_INTERVAL_H
    try:
        return GpsEphemeris(
            prn=num, toc_week=toc_week, toc_s=toc_s, af0_s=af0, af1_s_per_s=af1, af2_s_per_s2=af2,
            iode=int(iod), crs_m=crs, delta_n_radps=dn, m0_rad=m0, cuc_rad=cuc, e=e, cus_rad=cus,
            sqrt_a_sqrt_m=sqa, toe_s=toe, cic_rad=cic, omega0_rad=om0, cis_rad=cis, i0_rad=i0, crc_m=crc,
            omega_rad=om, omega_dot_radps=omd, idot_radps=idot, week=int(week), sv_accuracy_m=acc,
            health=health_used, tgd_s=tgd, iodc=iodc, transmission_time_s=ttm, fit_interval_h=fit_h,
            system=sys_char,
        ), ("galileo_fnav" if sys_char == "E" and fnav else "ok")
    except ValueError as exc:
        raise RinexFormatError(path, line_no, str(exc)) from None


def _parse_glonass_record(
    rec: list[str], line_no: int, leap_seconds: int | None, path: str | Path, rinex2: bool = False
) -> tuple[GlonassEphemeris | None, str]:
    """A RINEX 3 GLONASS record (RINEX 3.05 Table A11; RINEX 2.11 Table A11 for ``rinex2``): epoch
    t_b in UTC, -tau_n, +gamma_n, frame time; then X, Vx, Ax, health / Y, Vy, Ay, channel / Z, Vz,
    Az, age (km, km/s, km/s^2)."""
    num, year, mo, dd, hh, mi, sec = _record_epoch(rec[0], line_no, path, rinex2)
    week, tow = epoch_to_gps(year, mo, dd, hh, mi, sec, path, line_no)
    if leap_seconds is None:  # no LEAP SECONDS in the header: the suite's one table (UTC Unix ns)
        leap = leap_seconds_at_ros_stamp(calendar.timegm((year, mo, dd, hh, mi, 0, 0, 0, 0)) * 1_000_000_000)
    else:
        leap = leap_seconds
    tow += leap  # UTC -> GPST
    if tow >= 604800.0:
        week, tow = week + 1, tow - 604800.0
    v = _record_values(rec, line_no, path, 4, rinex2)
    minus_tau, gamma, frame_t = v[0:3]
    x, vx, ax, health, y, vy, ay, chan, z, vz, az, age = v[3:15]
    pos = np.array([x, y, z]) * 1.0e3
    if not 2.0e7 < float(np.linalg.norm(pos)) < 3.0e7:
        return None, "non_physical_orbit"
    if chan != round(chan):
        raise RinexFormatError(path, line_no + 2, f"R{num:02d}: frequency channel {chan} is not an integer")
    try:
        return GlonassEphemeris(
            slot=num, tb_week=week, tb_s=tow, minus_tau_n_s=minus_tau, gamma_n=gamma, frame_time_s=frame_t,
            position_m=pos, velocity_mps=np.array([vx, vy, vz]) * 1.0e3,
            acceleration_mps2=np.array([ax, ay, az]) * 1.0e3, health=int(health),
            frequency_channel=int(round(chan)), age_days=age,
        ), "ok"
    except ValueError as exc:
        raise RinexFormatError(path, line_no, str(exc)) from None


def _parse_gps_record(
    rec: list[str], line_no: int, version: float, start: int, lead: int, path: str | Path
) -> GpsEphemeris:
    first = rec[0]
    try:
        if version < 3.0:
            prn = int(first[0:2])
            yy, mo, dd, hh, mi = (int(first[k : k + 3]) for k in (2, 5, 8, 11, 14))
            year = two_digit_year(yy)
            sec = float(first[17:22])
        else:
            prn = int(first[1:3])
            year = int(first[4:8])
            mo, dd, hh, mi, isec = (int(first[k : k + 3]) for k in (8, 11, 14, 17, 20))
            sec = float(isec)
    except ValueError:
        raise RinexFormatError(path, line_no, f"malformed navigation record epoch {first[0:23]!r}") from None
    toc_week, toc_s = epoch_to_gps(year, mo, dd, hh, mi, sec, path, line_no)
    vals: list[float] = []
    for k in range(3):
        vals.append(
            float_field(first[start + 19 * k : start + 19 * (k + 1)], path, line_no, "clock parameter")
        )
    for j in range(1, 8):
        line = rec[j]
        for k in range(4):
            vals.append(
                float_field(
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

