"""GPS time: week / time of week, calendar epochs and integer-nanosecond stamps.

Time-base convention used throughout the suite
----------------------------------------------
A *stamp* is GPS time (no leap seconds) expressed on a Unix-like axis, in integer nanoseconds::

    stamp_ns = (GPS_EPOCH_UNIX_S + week * 604800) * 10**9 + round(tow_s * 10**9)

i.e. the number of SI nanoseconds since 1970-01-01 00:00:00 *counted in the GPS time scale*.
It is therefore ahead of a true UTC Unix stamp by the GPS - UTC leap seconds (18 s since 2017).
No leap-second table is applied anywhere; calendar ``datetime`` objects handled here are labels
on the GPS time scale (as in RINEX files, whose epochs are GPS time), not UTC.

Notes
-----
IS-GPS-200, 3.3.4 (GPS epoch 1980-01-06 00:00:00, week number) and 20.3.3.3.3.1 (week-crossover
rule for t - t_oe: +-302400 s). The 10-bit broadcast week rolls over every 1024 weeks
(1999-08-22, 2019-04-07); :func:`resolve_week_rollover` restores the continuous week.
"""

from __future__ import annotations

import datetime as _dt
import math

import numpy as np

from gnss_common.constants import GPS_EPOCH_UNIX_S, SECONDS_PER_WEEK

NS_PER_S = 1_000_000_000
"""Nanoseconds per second."""

_WEEK_NS = int(SECONDS_PER_WEEK) * NS_PER_S
_GPS_EPOCH_NS = GPS_EPOCH_UNIX_S * NS_PER_S
GPS_EPOCH_DATETIME = _dt.datetime(1980, 1, 6, 0, 0, 0)
"""GPS epoch as a naive datetime on the GPS time scale."""

HALF_WEEK_S = SECONDS_PER_WEEK / 2.0
"""Half a GPS week, s (IS-GPS-200, 20.3.3.3.3.1 crossover threshold 302400 s)."""


def _check_week_tow(week: int, tow_s: float) -> None:
    if not isinstance(week, (int, np.integer)) or isinstance(week, bool):
        raise ValueError(f"GPS week must be an integer, got {week!r}")
    if week < 0:
        raise ValueError(f"GPS week must be >= 0, got {week}")
    if not math.isfinite(tow_s) or tow_s < 0.0 or tow_s >= SECONDS_PER_WEEK:
        raise ValueError(f"GPS time of week must be finite and in [0, 604800) s, got {tow_s!r}")


def gps_to_stamp_ns(week: int, tow_s: float) -> int:
    """Convert GPS week and time of week to an integer-nanosecond stamp (GPS scale, no leap s).

    Args:
        week: continuous GPS week number (not modulo 1024), >= 0.
        tow_s: GPS time of week, s, in [0, 604800).

    Returns:
        Stamp, ns: ``(GPS_EPOCH_UNIX_S + week*604800) * 1e9 + round(tow_s * 1e9)``.

    Raises:
        ValueError: non-integer or negative week, non-finite or out-of-range tow.

    Notes
    -----
    IS-GPS-200, 3.3.4. See the module docstring for the time-base convention.
    """
    _check_week_tow(week, tow_s)
    return _GPS_EPOCH_NS + int(week) * _WEEK_NS + int(round(tow_s * NS_PER_S))


def stamp_ns_to_gps(stamp_ns: int) -> tuple[int, float]:
    """Convert an integer-nanosecond stamp (GPS scale) to (GPS week, time of week in s).

    Args:
        stamp_ns: stamp, ns, at or after the GPS epoch (>= 315964800e9).

    Returns:
        ``(week, tow_s)`` with week continuous and tow_s in [0, 604800).

    Raises:
        ValueError: stamp before the GPS epoch or not an integer.
    """
    if not isinstance(stamp_ns, (int, np.integer)) or isinstance(stamp_ns, bool):
        raise ValueError(f"stamp_ns must be an integer number of ns, got {stamp_ns!r}")
    since = int(stamp_ns) - _GPS_EPOCH_NS
    if since < 0:
        raise ValueError(f"stamp_ns {stamp_ns} is before the GPS epoch 1980-01-06")
    week, rem_ns = divmod(since, _WEEK_NS)
    return int(week), rem_ns / NS_PER_S


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


def stamp_ns_to_datetime(stamp_ns: int) -> _dt.datetime:
    """Convert a stamp, ns (GPS scale), to a naive datetime on the GPS scale (us resolution)."""
    week, tow_s = stamp_ns_to_gps(stamp_ns)
    return gps_to_datetime(week, tow_s)


def datetime_to_stamp_ns(epoch: _dt.datetime) -> int:
    """Convert a GPS-scale calendar epoch to a stamp, ns (see :func:`datetime_to_gps`)."""
    week, tow_s = datetime_to_gps(epoch)
    return gps_to_stamp_ns(week, tow_s)


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
