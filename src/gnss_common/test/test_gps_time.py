"""Tests for gnss_common.gps_time: known dates, round trips, week rollover, crossover."""

import datetime as dt

import numpy as np
import pytest

from gnss_common.constants import GPS_EPOCH_UNIX_S
from gnss_common.gps_time import (
    datetime_to_gps,
    datetime_to_stamp_ns,
    gps_seconds_difference,
    gps_to_datetime,
    gps_to_stamp_ns,
    resolve_week_rollover,
    stamp_ns_to_datetime,
    stamp_ns_to_gps,
    wrap_week_crossover_s,
)


def test_gps_epoch_maps_to_documented_stamp():
    assert gps_to_stamp_ns(0, 0.0) == GPS_EPOCH_UNIX_S * 1_000_000_000
    assert stamp_ns_to_gps(GPS_EPOCH_UNIX_S * 1_000_000_000) == (0, 0.0)


def test_known_dates():
    # 2015-07-19 was a Sunday of GPS week 1854 (ARL1 file); 2005-04-02 a Saturday of week 1316.
    assert datetime_to_gps(dt.datetime(2015, 7, 19)) == (1854, 0.0)
    assert datetime_to_gps(dt.datetime(2005, 4, 2)) == (1316, 518400.0)
    assert datetime_to_gps(dt.datetime(2019, 4, 7)) == (2048, 0.0)  # second 10-bit rollover
    # no leap seconds: the stamp is the UTC-labelled Unix time of the same calendar label
    label = dt.datetime(2015, 7, 19, 0, 0, 30, tzinfo=dt.timezone.utc)
    assert datetime_to_stamp_ns(label) == int(label.timestamp()) * 1_000_000_000


def test_round_trips():
    rng = np.random.default_rng(11)
    for _ in range(200):
        week = int(rng.integers(0, 3000))
        tow = float(np.round(rng.uniform(0.0, 604800.0 - 1e-3), 6))
        stamp = gps_to_stamp_ns(week, tow)
        w2, t2 = stamp_ns_to_gps(stamp)
        assert w2 == week
        assert t2 == pytest.approx(tow, abs=1e-9)
        assert datetime_to_gps(gps_to_datetime(week, tow)) == (week, pytest.approx(tow, abs=1e-6))
        assert stamp_ns_to_datetime(stamp) == gps_to_datetime(week, tow)


def test_stamps_are_continuous_across_the_week_boundary():
    a = gps_to_stamp_ns(1854, 604799.5)
    b = gps_to_stamp_ns(1855, 0.0)
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
        gps_to_stamp_ns(-1, 0.0)
    with pytest.raises(ValueError):
        gps_to_stamp_ns(100, 604800.0)
    with pytest.raises(ValueError):
        gps_to_stamp_ns(100, float("nan"))
    with pytest.raises(ValueError):
        gps_to_stamp_ns(1.5, 0.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        stamp_ns_to_gps(0)
    with pytest.raises(ValueError):
        datetime_to_gps(dt.datetime(1979, 1, 1))
    with pytest.raises(ValueError):
        datetime_to_gps(dt.datetime(2015, 1, 1, tzinfo=dt.timezone(dt.timedelta(hours=2))))
