"""Tests for gnss_common.gps_time: known dates, round trips, week rollover, crossover, ROS stamps
and the leap-second table (boundaries, a stamp inside a leap second, expiry)."""

import calendar
import datetime as dt
import pathlib
import warnings

import numpy as np
import pytest

from gnss_common.constants import GPS_EPOCH_UNIX_S
from gnss_common.gps_time import (
    LEAP_SECONDS,
    LEAP_TABLE_SOURCE,
    LEAP_TABLE_VALID_UNTIL_UNIX_S,
    LeapTableExpiredWarning,
    datetime_to_gps,
    datetime_to_gps_ns,
    gps_ns_to_datetime,
    gps_ns_to_gps,
    gps_ns_to_ros_stamp_ns,
    gps_seconds_difference,
    gps_to_datetime,
    gps_to_gps_ns,
    gps_to_ros_stamp_ns,
    leap_seconds_at_gps,
    leap_seconds_at_ros_stamp,
    resolve_week_rollover,
    ros_stamp_ns_to_gps,
    ros_stamp_ns_to_gps_ns,
    wrap_week_crossover_s,
)


def test_gps_epoch_maps_to_documented_stamp():
    assert gps_to_gps_ns(0, 0.0) == GPS_EPOCH_UNIX_S * 1_000_000_000
    assert gps_ns_to_gps(GPS_EPOCH_UNIX_S * 1_000_000_000) == (0, 0.0)


def test_known_dates():
    # 2015-07-19 was a Sunday of GPS week 1854 (ARL1 file); 2005-04-02 a Saturday of week 1316.
    assert datetime_to_gps(dt.datetime(2015, 7, 19)) == (1854, 0.0)
    assert datetime_to_gps(dt.datetime(2005, 4, 2)) == (1316, 518400.0)
    assert datetime_to_gps(dt.datetime(2019, 4, 7)) == (2048, 0.0)  # second 10-bit rollover
    # GPS-scale ns: the UTC-labelled Unix time of the same calendar label (no leap seconds)
    label = dt.datetime(2015, 7, 19, 0, 0, 30, tzinfo=dt.timezone.utc)
    assert datetime_to_gps_ns(label) == int(label.timestamp()) * 1_000_000_000


def _random_gps_times(seed: int, count: int, weeks: int):
    """``count`` seeded (week, tow_s): week in [0, weeks), tow_s on a 1 us grid within the week."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        week = int(rng.integers(0, weeks))
        yield week, float(np.round(rng.uniform(0.0, 604800.0 - 1e-3), 6))


def test_round_trips():
    for week, tow in _random_gps_times(11, 200, 3000):
        stamp = gps_to_gps_ns(week, tow)
        w2, t2 = gps_ns_to_gps(stamp)
        assert w2 == week
        assert t2 == pytest.approx(tow, abs=1e-9)
        assert datetime_to_gps(gps_to_datetime(week, tow)) == (week, pytest.approx(tow, abs=1e-6))
        assert gps_ns_to_datetime(stamp) == gps_to_datetime(week, tow)


def test_stamps_are_continuous_across_the_week_boundary():
    a = gps_to_gps_ns(1854, 604799.5)
    b = gps_to_gps_ns(1855, 0.0)
    assert b - a == 500_000_000


def test_week_rollover():
    assert resolve_week_rollover(1854 % 1024, 1800) == 1854
    assert resolve_week_rollover(0, 2047) == 2048
    assert resolve_week_rollover(1023, 2050) == 2047
    assert resolve_week_rollover(830, 830) == 830
    assert resolve_week_rollover(5, 1000) == 1029
    with pytest.raises(ValueError):
        resolve_week_rollover(1024, 2000)


def test_crossover_rule():
    np.testing.assert_allclose(
        wrap_week_crossover_s(np.array([302401.0, -302401.0, 100.0])), [-302399.0, 302399.0, 100.0]
    )
    assert wrap_week_crossover_s(-604000.0) == pytest.approx(800.0)
    assert gps_seconds_difference(1855, 10.0, 1854, 604790.0) == pytest.approx(20.0)


def test_invalid_inputs_raise():
    with pytest.raises(ValueError):
        gps_to_gps_ns(-1, 0.0)
    with pytest.raises(ValueError):
        gps_to_gps_ns(100, 604800.0)
    with pytest.raises(ValueError):
        gps_to_gps_ns(100, float("nan"))
    with pytest.raises(ValueError):
        gps_to_gps_ns(1.5, 0.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        gps_ns_to_gps(0)
    with pytest.raises(ValueError):
        datetime_to_gps(dt.datetime(1979, 1, 1))
    with pytest.raises(ValueError):
        datetime_to_gps(dt.datetime(2015, 1, 1, tzinfo=dt.timezone(dt.timedelta(hours=2))))


# ---- ROS stamps (UTC) and the leap-second table -------------------------------------------

# IERS leap-seconds.list (updated 2025-07-07, expires 2026-06-28): NTP second (since 1900) from
# which TAI - UTC holds, and TAI - UTC; GPS - UTC = TAI - UTC - 19 s (the GPS epoch's offset).
_IERS_NTP_TAI_MINUS_UTC = (
    (2571782400, 20), (2603318400, 21), (2634854400, 22), (2698012800, 23), (2776982400, 24),
    (2840140800, 25), (2871676800, 26), (2918937600, 27), (2950473600, 28), (2982009600, 29),
    (3029443200, 30), (3076704000, 31), (3124137600, 32), (3345062400, 33), (3439756800, 34),
    (3550089600, 35), (3644697600, 36), (3692217600, 37),
)
_NTP_TO_UNIX_S = 2_208_988_800
_NS = 1_000_000_000


def test_leap_table_equals_the_iers_list():
    expected = tuple((ntp - _NTP_TO_UNIX_S, dtai - 19) for ntp, dtai in _IERS_NTP_TAI_MINUS_UTC)
    assert LEAP_SECONDS == expected
    # No leap second since (Bulletins C 71 and 72); the list of Bulletin C 72 expires 2027-06-28 00:00 UTC.
    assert LEAP_TABLE_VALID_UNTIL_UNIX_S == 1814140800
    assert "Bulletin C 70" in LEAP_TABLE_SOURCE and "72" in LEAP_TABLE_SOURCE


def test_leap_table_equals_the_tz_database():
    """The tz database's leapseconds file (PyPI tzdata, in the venv): every leap second since the GPS epoch and the
    expiry. A newer tzdata that announces a leap second, or a later expiry, fails here: update the table."""
    tzdata = pytest.importorskip("tzdata")
    text = (pathlib.Path(tzdata.__file__).parent / "zoneinfo" / "leapseconds").read_text()
    months = {m: i for i, m in enumerate(calendar.month_abbr) if m}
    starts = []
    for line in text.splitlines():
        f = line.split()
        if f[:1] == ["Leap"]:
            assert f[5] == "+", line  # a negative leap second has never happened; the table has no sign for it
            day = dt.datetime(int(f[1]), months[f[2]], int(f[3]), tzinfo=dt.timezone.utc) + dt.timedelta(days=1)
            starts.append(int(day.timestamp()))
    expires = [int(line.split()[1]) for line in text.splitlines() if line.startswith("#expires")]
    gps_era = [t for t in starts if t > 315964800]  # after 1980-01-06
    assert tuple((t, i + 1) for i, t in enumerate(gps_era)) == LEAP_SECONDS
    assert expires == [LEAP_TABLE_VALID_UNTIL_UNIX_S]


def test_leap_table_equals_the_system_list_where_it_has_one():
    path = pathlib.Path("/usr/share/zoneinfo/leap-seconds.list")
    if not path.is_file():
        pytest.skip("no system leap-seconds.list to cross-check")
    rows = []
    for line in path.read_text().splitlines():
        if line and not line.startswith("#"):
            ntp, dtai = line.split()[:2]
            if int(dtai) > 19:  # after the GPS epoch
                rows.append((int(ntp) - _NTP_TO_UNIX_S, int(dtai) - 19))
    # The system list may be newer than ours (more rows), never different on the common part.
    assert tuple(rows[: len(LEAP_SECONDS)]) == LEAP_SECONDS


def test_ros_stamps_of_known_gps_times():
    # GPS epoch: GPS - UTC = 0, the stamp is the Unix time of 1980-01-06 00:00:00 UTC.
    assert gps_to_ros_stamp_ns(0, 0.0) == GPS_EPOCH_UNIX_S * _NS
    assert ros_stamp_ns_to_gps(GPS_EPOCH_UNIX_S * _NS) == (0, 0.0)
    # 2015-07-19 00:00:00 GPST (ARL1): 17 s ahead of UTC, 2015-07-18 23:59:43 UTC.
    utc = dt.datetime(2015, 7, 18, 23, 59, 43, tzinfo=dt.timezone.utc)
    assert gps_to_ros_stamp_ns(1854, 0.0) == int(utc.timestamp()) * _NS
    assert leap_seconds_at_gps(1854, 0.0) == 17
    # 2024-02-08 00:00:00 GPST: 18 s.
    assert gps_to_ros_stamp_ns(2300, 345600.0) == gps_to_gps_ns(2300, 345600.0) - 18 * _NS
    assert leap_seconds_at_gps(2300, 345600.0) == 18
    assert ros_stamp_ns_to_gps(gps_to_ros_stamp_ns(2300, 345600.0)) == (2300, 345600.0)


@pytest.mark.parametrize("row", range(len(LEAP_SECONDS)))
def test_table_boundaries(row):
    t_unix, leap = LEAP_SECONDS[row]
    old = leap - 1
    ms = 1_000_000
    # UTC side: the new offset holds from 00:00:00 UTC of its day.
    assert leap_seconds_at_ros_stamp(t_unix * _NS - 1) == old
    assert leap_seconds_at_ros_stamp(t_unix * _NS) == leap
    # GPS side: 23:59:59.999 UTC, the inserted 23:59:60 and 00:00:00 UTC on the GPS-scale axis.
    last_ordinary = (t_unix - 1 + old) * _NS + 999 * ms
    leap_start = (t_unix + leap - 1) * _NS
    midnight = (t_unix + leap) * _NS
    assert gps_ns_to_ros_stamp_ns(last_ordinary) == t_unix * _NS - ms
    assert gps_ns_to_ros_stamp_ns(midnight) == t_unix * _NS
    assert gps_ns_to_ros_stamp_ns(midnight - 1) == t_unix * _NS - 1
    # Round trips on both sides of the leap second are exact.
    for g in (last_ordinary, midnight, midnight + 7 * ms):
        assert ros_stamp_ns_to_gps_ns(gps_ns_to_ros_stamp_ns(g)) == g
    assert leap_seconds_at_gps(*gps_ns_to_gps(last_ordinary)) == old
    assert leap_seconds_at_gps(*gps_ns_to_gps(leap_start)) == leap


def test_a_stamp_inside_a_leap_second():
    # 2016-12-31 23:59:60.5 UTC = GPS-scale 1483228800 + 17 + 0.5 s: the stamp repeats 23:59:59.5
    # (POSIX system clock), and the way back gives the first 23:59:59.5 (GPS 1483228816.5).
    t = 1483228800
    inside = (t + 17) * _NS + _NS // 2
    assert gps_ns_to_ros_stamp_ns(inside) == (t - 1) * _NS + _NS // 2
    assert ros_stamp_ns_to_gps_ns(gps_ns_to_ros_stamp_ns(inside)) == inside - _NS
    week, tow = gps_ns_to_gps(inside)
    assert (week, tow) == (1930, 17.5)  # 2017-01-01 is GPS week 1930, day 0
    assert gps_to_ros_stamp_ns(week, tow) == (t - 1) * _NS + _NS // 2
    assert ros_stamp_ns_to_gps(gps_to_ros_stamp_ns(week, tow)) == (1930, 16.5)
    # Stepping through it at 10 Hz on the GPS axis, the stamp goes back by 1 s exactly once.
    g = np.arange((t + 15) * _NS, (t + 20) * _NS, _NS // 10, dtype=np.int64)
    stamps = np.array([gps_ns_to_ros_stamp_ns(int(x)) for x in g])
    steps = np.diff(stamps)
    assert sorted(set(steps.tolist())) == [_NS // 10 - _NS, _NS // 10]
    assert int(np.sum(steps < 0)) == 1


def test_ros_round_trips_over_the_whole_table():
    for week, tow in _random_gps_times(12, 300, 2300):
        stamp = gps_to_ros_stamp_ns(week, tow)
        leap = leap_seconds_at_gps(week, tow)
        assert stamp == gps_to_gps_ns(week, tow) - leap * _NS
        in_leap_second = leap_seconds_at_ros_stamp(stamp) != leap
        if not in_leap_second:
            w2, t2 = ros_stamp_ns_to_gps(stamp)
            assert w2 == week
            assert t2 == pytest.approx(tow, abs=1e-9)


def test_beyond_the_table_warns_and_keeps_the_last_offset():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gps_to_ros_stamp_ns(2450, 0.0)  # 2026-12-20: inside the table, no warning
    week_2027 = 2480  # 2027-07-18
    with pytest.warns(LeapTableExpiredWarning):
        stamp = gps_to_ros_stamp_ns(week_2027, 0.0)
    assert stamp == gps_to_gps_ns(week_2027, 0.0) - 18 * _NS
    with pytest.warns(LeapTableExpiredWarning):
        assert ros_stamp_ns_to_gps(stamp) == (week_2027, 0.0)
    with pytest.warns(LeapTableExpiredWarning):
        assert leap_seconds_at_ros_stamp(stamp) == 18


def test_invalid_ros_stamps_raise():
    with pytest.raises(ValueError):
        ros_stamp_ns_to_gps(GPS_EPOCH_UNIX_S * _NS - 1)
    with pytest.raises(ValueError):
        ros_stamp_ns_to_gps(1.5e18)  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        gps_to_ros_stamp_ns(100, 604800.0)
    with pytest.raises(ValueError):
        gps_ns_to_ros_stamp_ns(0)
