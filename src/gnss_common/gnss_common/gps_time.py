"""GPS time: week / time of week, leap seconds, calendar epochs and ROS header stamps.

Time-base convention used throughout the suite
----------------------------------------------
Every header stamp is **ROS time**: UTC-based Unix time in integer nanoseconds, as the system
clock of a robot gives it (``rclpy`` ``Time``, ``builtin_interfaces/Time``), so GNSS messages line
up with an IMU, wheel odometry or tf. GPS time is kept exact in the messages' own fields
(``gps_week``, ``gps_time_of_week_s``). The one conversion between the two is here::

    gps_ns   = (GPS_EPOCH_UNIX_S + week * 604800) * 10**9 + round(tow_s * 10**9)
    stamp_ns = gps_ns - (GPS - UTC)(gps_ns) * 10**9          # gps_to_ros_stamp_ns

``gps_ns`` (the *GPS-scale* axis, what :func:`gps_to_gps_ns` returns) counts SI seconds since
1970-01-01 on the GPS time scale; it is continuous and is what simulators step on, but it is not a
header stamp: it runs ahead of ROS time by the leap seconds (17 s from 2015-07-01, 18 s since
2017-01-01).

Leap seconds come from one table, :data:`LEAP_SECONDS`, as of IERS Bulletin C 72 (see
:data:`LEAP_TABLE_SOURCE`). It is valid to :data:`LEAP_TABLE_VALID_UNTIL_UNIX_S`
(2027-06-28 00:00 UTC, the expiry the IERS gives its ``leap-seconds.list`` of that bulletin).
Beyond that date the conversions keep the last offset (18 s) and emit a
:class:`LeapTableExpiredWarning` (once per call site, Python's default warning filter): a
receiver on a robot must keep running, and the error is at most the leap seconds announced after
the table (none since 2017); update the table from the next Bulletin C
(https://hpiers.obspm.fr/iers/bul/bulc/bulletinc.dat) and its expiry together.

Inside an inserted leap second (UTC 23:59:60) the stamp repeats the last second of the day, as
the POSIX / Linux system clock does: the stamp steps back by 1 s once, and
:func:`ros_stamp_ns_to_gps` of such a stamp returns the first occurrence (the real 23:59:59).
The GPS fields of the message stay exact and unambiguous.

Calendar ``datetime`` objects handled here are labels on the GPS time scale (as in RINEX files,
whose epochs are GPS time), not UTC.

Notes
-----
IS-GPS-200, 3.3.4 (GPS epoch 1980-01-06 00:00:00 UTC, when GPS - UTC = 0; week number),
20.3.3.5.2.4 (GPS - UTC is an integer number of leap seconds, broadcast as Delta t_LS) and
20.3.3.3.3.1 (week-crossover rule for t - t_oe: +-302400 s). The 10-bit broadcast week rolls
over every 1024 weeks (1999-08-22, 2019-04-07); :func:`resolve_week_rollover` restores the
continuous week.
"""

from __future__ import annotations

import bisect
import calendar
import datetime as _dt
import math
import warnings

import numpy as np

from gnss_common.constants import GPS_EPOCH_UNIX_S, NS_PER_S, SECONDS_PER_WEEK

_WEEK_NS = int(SECONDS_PER_WEEK) * NS_PER_S
_GPS_EPOCH_NS = GPS_EPOCH_UNIX_S * NS_PER_S
GPS_EPOCH_DATETIME = _dt.datetime(1980, 1, 6, 0, 0, 0)
"""GPS epoch as a naive datetime on the GPS time scale."""

HALF_WEEK_S = SECONDS_PER_WEEK / 2.0
"""Half a GPS week, s (IS-GPS-200, 20.3.3.3.3.1 crossover threshold 302400 s)."""


class LeapTableExpiredWarning(UserWarning):
    """A time was converted beyond the date the leap-second table is known valid to."""


def _utc_unix_s(year: int, month: int, day: int) -> int:
    return calendar.timegm((year, month, day, 0, 0, 0, 0, 0, 0))


LEAP_TABLE_SOURCE = (
    "IERS Bulletin C 70 (Paris, 7 July 2025): UTC - TAI = -37 s from 2017-01-01 until further "
    "notice, no leap second at the end of December 2025; GPS - UTC = (TAI - UTC) - 19 s. "
    "Bulletins C 71 and 72 added none (no leap second at the end of June 2026 nor of December 2026): "
    "checked against the tz database's leapseconds of tzdata 2026.6 (updated from the IERS "
    "leap-seconds.list of 2026-07-06, expires 2027-06-28)."
)
"""Where :data:`LEAP_SECONDS` comes from."""

LEAP_TABLE_VALID_UNTIL_UNIX_S = _utc_unix_s(2027, 6, 28)
"""UTC instant (Unix s) up to which :data:`LEAP_SECONDS` is known complete: 2027-06-28 00:00 UTC."""

LEAP_SECONDS: tuple[tuple[int, int], ...] = tuple(
    (_utc_unix_s(y, m, d), gps_minus_utc_s)
    for (y, m, d), gps_minus_utc_s in (
        ((1981, 7, 1), 1),
        ((1982, 7, 1), 2),
        ((1983, 7, 1), 3),
        ((1985, 7, 1), 4),
        ((1988, 1, 1), 5),
        ((1990, 1, 1), 6),
        ((1991, 1, 1), 7),
        ((1992, 7, 1), 8),
        ((1993, 7, 1), 9),
        ((1994, 7, 1), 10),
        ((1996, 1, 1), 11),
        ((1997, 7, 1), 12),
        ((1999, 1, 1), 13),
        ((2006, 1, 1), 14),
        ((2009, 1, 1), 15),
        ((2012, 7, 1), 16),
        ((2015, 7, 1), 17),
        ((2017, 1, 1), 18),
    )
)
"""(UTC Unix s at 00:00:00 of the day from which it holds, GPS - UTC in s), one row per leap
second since the GPS epoch (GPS - UTC = 0 s from 1980-01-06 to 1981-06-30). Source:
:data:`LEAP_TABLE_SOURCE`; valid to :data:`LEAP_TABLE_VALID_UNTIL_UNIX_S`."""

# The same table on the GPS-scale axis: the new offset applies from the start of the inserted
# second 23:59:60, which is GPS-scale Unix second (T + L - 1) for a row (T, L).
_LEAP_START_UTC_NS = [t * NS_PER_S for t, _ in LEAP_SECONDS]
_LEAP_START_GPS_NS = [(t + leap - 1) * NS_PER_S for t, leap in LEAP_SECONDS]
_LEAP_VALUES_S = [0] + [leap for _, leap in LEAP_SECONDS]
_VALID_UNTIL_NS = LEAP_TABLE_VALID_UNTIL_UNIX_S * NS_PER_S


def _warn_if_beyond_table(utc_ns: int) -> None:
    if utc_ns >= _VALID_UNTIL_NS:
        warnings.warn(
            "time converted beyond the leap-second table's validity (2027-06-28 UTC, "
            "IERS Bulletin C 72): GPS - UTC = 18 s assumed; update gnss_common.gps_time.LEAP_SECONDS "
            "from the current IERS Bulletin C",
            LeapTableExpiredWarning,
            stacklevel=3,
        )


def _check_stamp(stamp_ns: int, what: str) -> int:
    if not isinstance(stamp_ns, (int, np.integer)) or isinstance(stamp_ns, bool):
        raise ValueError(f"{what} must be an integer number of ns, got {stamp_ns!r}")
    if int(stamp_ns) < _GPS_EPOCH_NS:
        raise ValueError(f"{what} {stamp_ns} is before the GPS epoch 1980-01-06")
    return int(stamp_ns)


def _check_week_tow(week: int, tow_s: float) -> None:
    if not isinstance(week, (int, np.integer)) or isinstance(week, bool):
        raise ValueError(f"GPS week must be an integer, got {week!r}")
    if week < 0:
        raise ValueError(f"GPS week must be >= 0, got {week}")
    if not math.isfinite(tow_s) or tow_s < 0.0 or tow_s >= SECONDS_PER_WEEK:
        raise ValueError(f"GPS time of week must be finite and in [0, 604800) s, got {tow_s!r}")


def gps_to_gps_ns(week: int, tow_s: float) -> int:
    """Convert GPS week and time of week to GPS-scale ns since 1970 (no leap s; NOT a header stamp).

    A header stamp is :func:`gps_to_ros_stamp_ns`; this continuous GPS-scale axis is what
    simulators step on before converting with :func:`gps_ns_to_ros_stamp_ns`.

    Args:
        week: continuous GPS week number (not modulo 1024), >= 0.
        tow_s: GPS time of week, s, in [0, 604800).

    Returns:
        GPS-scale time, ns: ``(GPS_EPOCH_UNIX_S + week*604800) * 1e9 + round(tow_s * 1e9)``.

    Raises:
        ValueError: non-integer or negative week, non-finite or out-of-range tow.

    Notes
    -----
    IS-GPS-200, 3.3.4. See the module docstring for the time-base convention.
    """
    _check_week_tow(week, tow_s)
    return _GPS_EPOCH_NS + int(week) * _WEEK_NS + int(round(tow_s * NS_PER_S))


def gps_ns_to_gps(gps_ns: int) -> tuple[int, float]:
    """Convert GPS-scale ns since 1970 (NOT a header stamp) to (GPS week, time of week in s).

    A header stamp is converted with :func:`ros_stamp_ns_to_gps`.

    Args:
        gps_ns: GPS-scale time, ns, at or after the GPS epoch (>= 315964800e9).

    Returns:
        ``(week, tow_s)`` with week continuous and tow_s in [0, 604800).

    Raises:
        ValueError: time before the GPS epoch or not an integer.
    """
    since = _check_stamp(gps_ns, "gps_ns") - _GPS_EPOCH_NS
    week, rem_ns = divmod(since, _WEEK_NS)
    return int(week), rem_ns / NS_PER_S


def _leap_at_gps_ns(gps_ns: int) -> int:
    return _LEAP_VALUES_S[bisect.bisect_right(_LEAP_START_GPS_NS, gps_ns)]


def _leap_at_utc_ns(utc_ns: int) -> int:
    return _LEAP_VALUES_S[bisect.bisect_right(_LEAP_START_UTC_NS, utc_ns)]


def gps_ns_to_ros_stamp_ns(gps_ns: int) -> int:
    """Convert GPS-scale ns since 1970 (:func:`gps_to_gps_ns`) to a ROS header stamp, ns (UTC).

    Args:
        gps_ns: GPS-scale time, ns, at or after the GPS epoch.

    Returns:
        ``gps_ns - (GPS - UTC) * 1e9`` with GPS - UTC from :data:`LEAP_SECONDS` at that GPS time;
        inside an inserted leap second the stamp repeats 23:59:59 (module docstring).

    Raises:
        ValueError: not an integer or before the GPS epoch.

    Warns:
        LeapTableExpiredWarning: the time is beyond :data:`LEAP_TABLE_VALID_UNTIL_UNIX_S`.
    """
    gps_ns = _check_stamp(gps_ns, "gps_ns")
    stamp_ns = gps_ns - _leap_at_gps_ns(gps_ns) * NS_PER_S
    _warn_if_beyond_table(stamp_ns)
    return stamp_ns


def ros_stamp_ns_to_gps_ns(stamp_ns: int) -> int:
    """Convert a ROS header stamp, ns (UTC), to GPS-scale ns since 1970.

    Args:
        stamp_ns: ROS time, ns, at or after the GPS epoch (1980-01-06, 315964800e9 ns).

    Returns:
        ``stamp_ns + (GPS - UTC) * 1e9`` with GPS - UTC from :data:`LEAP_SECONDS` at that UTC
        time; a stamp in the repeated second 23:59:59 of a leap-second day maps to its first
        occurrence.

    Raises:
        ValueError: not an integer or before the GPS epoch.

    Warns:
        LeapTableExpiredWarning: the time is beyond :data:`LEAP_TABLE_VALID_UNTIL_UNIX_S`.
    """
    stamp_ns = _check_stamp(stamp_ns, "stamp_ns")
    _warn_if_beyond_table(stamp_ns)
    return stamp_ns + _leap_at_utc_ns(stamp_ns) * NS_PER_S


def gps_to_ros_stamp_ns(week: int, tow_s: float) -> int:
    """Convert GPS week and time of week to a ROS header stamp (UTC-based Unix time), ns.

    Args:
        week: continuous GPS week number (not modulo 1024), >= 0.
        tow_s: GPS time of week, s, in [0, 604800).

    Returns:
        Stamp, ns: the GPS-scale time minus GPS - UTC leap seconds at that time (from
        :data:`LEAP_SECONDS`), e.g. 18 s since 2017-01-01, 17 s from 2015-07-01.

    Raises:
        ValueError: non-integer or negative week, non-finite or out-of-range tow.

    Warns:
        LeapTableExpiredWarning: the time is beyond :data:`LEAP_TABLE_VALID_UNTIL_UNIX_S`.

    Notes
    -----
    IS-GPS-200, 3.3.4 and 20.3.3.5.2.4. See the module docstring for the time-base convention
    and the leap second itself.
    """
    return gps_ns_to_ros_stamp_ns(gps_to_gps_ns(week, tow_s))


def ros_stamp_ns_to_gps(stamp_ns: int) -> tuple[int, float]:
    """Convert a ROS header stamp (UTC-based Unix time), ns, to (GPS week, time of week in s).

    Args:
        stamp_ns: ROS time, ns, at or after the GPS epoch.

    Returns:
        ``(week, tow_s)`` with week continuous and tow_s in [0, 604800); the inverse of
        :func:`gps_to_ros_stamp_ns` except inside an inserted leap second (module docstring).

    Raises:
        ValueError: stamp before the GPS epoch or not an integer.

    Warns:
        LeapTableExpiredWarning: the time is beyond :data:`LEAP_TABLE_VALID_UNTIL_UNIX_S`.
    """
    return gps_ns_to_gps(ros_stamp_ns_to_gps_ns(stamp_ns))


def leap_seconds_at_gps(week: int, tow_s: float) -> int:
    """GPS - UTC in s at a GPS time (from :data:`LEAP_SECONDS`; 18 since 2017-01-01).

    The offset changes at the start of the inserted second 23:59:60 UTC.

    Warns:
        LeapTableExpiredWarning: the time is beyond :data:`LEAP_TABLE_VALID_UNTIL_UNIX_S`.
    """
    gps_ns = gps_to_gps_ns(week, tow_s)
    leap = _leap_at_gps_ns(gps_ns)
    _warn_if_beyond_table(gps_ns - leap * NS_PER_S)
    return leap


def leap_seconds_at_ros_stamp(stamp_ns: int) -> int:
    """GPS - UTC in s at a ROS (UTC) stamp, ns (from :data:`LEAP_SECONDS`).

    The offset changes at 00:00:00 UTC of the day after the leap second.

    Warns:
        LeapTableExpiredWarning: the time is beyond :data:`LEAP_TABLE_VALID_UNTIL_UNIX_S`.
    """
    stamp_ns = _check_stamp(stamp_ns, "stamp_ns")
    _warn_if_beyond_table(stamp_ns)
    return _leap_at_utc_ns(stamp_ns)


def datetime_to_gps(epoch: _dt.datetime) -> tuple[int, float]:
    """Convert a calendar epoch on the GPS time scale to (week, time of week in s).

    Args:
        epoch: naive datetime read as GPS time (e.g. a RINEX epoch); an aware datetime is
            converted to its naive wall-clock value in its own zone first, and must be UTC-labelled
            (the label is kept, no leap seconds are added).

    Returns:
        ``(week, tow_s)``; microsecond resolution of ``datetime`` is kept.

    Raises:
        ValueError: epoch before 1980-01-06 or with a non-UTC time zone.
    """
    if epoch.tzinfo is not None:
        offset = epoch.utcoffset()
        if offset is None or offset != _dt.timedelta(0):
            raise ValueError(f"datetime {epoch!r} must be naive (GPS scale) or UTC-labelled")
        epoch = epoch.replace(tzinfo=None)
    delta = epoch - GPS_EPOCH_DATETIME
    total_us = (delta.days * 86400 + delta.seconds) * 1_000_000 + delta.microseconds
    if total_us < 0:
        raise ValueError(f"datetime {epoch!r} is before the GPS epoch 1980-01-06")
    week_us = int(SECONDS_PER_WEEK) * 1_000_000
    week, rem_us = divmod(total_us, week_us)
    return int(week), rem_us / 1e6


def gps_to_datetime(week: int, tow_s: float) -> _dt.datetime:
    """Convert GPS week and time of week to a naive datetime on the GPS time scale.

    Args:
        week: continuous GPS week, >= 0.
        tow_s: time of week, s, in [0, 604800). Rounded to the microsecond.

    Returns:
        Naive ``datetime`` (GPS scale, no leap seconds).
    """
    _check_week_tow(week, tow_s)
    return GPS_EPOCH_DATETIME + _dt.timedelta(weeks=int(week), microseconds=round(tow_s * 1e6))


def gps_ns_to_datetime(gps_ns: int) -> _dt.datetime:
    """Convert GPS-scale ns (not a header stamp) to a naive datetime on the GPS scale (us resolution)."""
    week, tow_s = gps_ns_to_gps(gps_ns)
    return gps_to_datetime(week, tow_s)


def datetime_to_gps_ns(epoch: _dt.datetime) -> int:
    """Convert a GPS-scale calendar epoch to GPS-scale ns (see :func:`datetime_to_gps`; not a stamp)."""
    week, tow_s = datetime_to_gps(epoch)
    return gps_to_gps_ns(week, tow_s)


def resolve_week_rollover(week_mod_1024: int, reference_week: int) -> int:
    """Restore a continuous GPS week from a 10-bit (modulo-1024) broadcast week.

    Args:
        week_mod_1024: broadcast week in [0, 1023].
        reference_week: any continuous week known to lie within +-512 weeks of the true one
            (e.g. from the receiver's calendar or a file's header).

    Returns:
        The continuous week congruent to ``week_mod_1024`` modulo 1024 that is nearest to
        ``reference_week``.

    Raises:
        ValueError: week_mod_1024 outside [0, 1023] or negative reference.

    Notes
    -----
    IS-GPS-200, 20.3.3.3.1.1 (10-bit WN, rollover every 1024 weeks).
    """
    if not 0 <= int(week_mod_1024) <= 1023:
        raise ValueError(f"week_mod_1024 must be in [0, 1023], got {week_mod_1024}")
    if int(reference_week) < 0:
        raise ValueError(f"reference_week must be >= 0, got {reference_week}")
    base = int(reference_week) - ((int(reference_week) - int(week_mod_1024)) % 1024)
    # base <= reference and congruent; pick the nearer of base and base + 1024.
    if int(reference_week) - base > 512:
        base += 1024
    return base


def wrap_week_crossover_s(dt_s: np.ndarray | float) -> np.ndarray | float:
    """Apply the IS-GPS-200 week-crossover rule to a time difference t - t_ref.

    Args:
        dt_s: time difference(s) computed from times of week, s, any shape.

    Returns:
        ``dt_s`` with 604800 subtracted where > 302400 and added where < -302400.

    Notes
    -----
    IS-GPS-200, 20.3.3.3.3.1 (t_k definition).
    """
    arr = np.asarray(dt_s, dtype=float)
    out = arr - SECONDS_PER_WEEK * (arr > HALF_WEEK_S) + SECONDS_PER_WEEK * (arr < -HALF_WEEK_S)
    if np.ndim(dt_s) == 0:
        return float(out)
    return out


def gps_seconds_difference(week_a: int, tow_a_s: float, week_b: int, tow_b_s: float) -> float:
    """Return (week_a, tow_a) - (week_b, tow_b) in s, exact in the week part (no float week*604800)."""
    return (int(week_a) - int(week_b)) * SECONDS_PER_WEEK + (float(tow_a_s) - float(tow_b_s))
