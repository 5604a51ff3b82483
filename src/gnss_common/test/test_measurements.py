"""Tests for gnss_common.measurements on real ARL1/GEONET data and the RINEX 3 pair."""

import math
from pathlib import Path

import numpy as np
import pytest

from gnss_common.constants import GPS_L1_WAVELENGTH_M
from gnss_common.coordinates import azimuth_elevation
from gnss_common.ephemeris import earth_rotation_correction
from gnss_common.gps_time import gps_to_ros_stamp_ns
from gnss_common.measurements import (
    SKIP_REASONS,
    GnssEpochBuilder,
    MeasurementBuilderParams,
    build_epochs,
    coarse_position_fix,
)
from gnss_common.observations import GPS
from gnss_common.rinex import read_rinex_nav, read_rinex_obs

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def arl1():
    obs = read_rinex_obs(DATA / "arlm200a.15o")
    nav = read_rinex_nav(DATA / "arlm2000.15n")
    return obs, nav, build_epochs(obs, nav)


def test_counts_and_fields(arl1):
    obs, nav, res = arl1
    assert len(res) == 120
    for r, e in zip(res, obs.epochs, strict=True):
        assert set(r.skipped) == set(SKIP_REASONS)
        # PRN 10 is flagged unhealthy all day, PRN 6 has no record before 20:00 (stale)
        assert ("G10", "unhealthy") in r.skipped_satellites
        g06_seen = "G06" in e.observations
        assert (("G06", "stale_ephemeris") in r.skipped_satellites) == g06_seen
        assert r.skipped["unhealthy"] == 1 and r.skipped["stale_ephemeris"] == int(g06_seen)
        assert len(r.epoch.observations) + sum(r.skipped.values()) == len(e.observations)
        assert r.epoch.stamp_ns == gps_to_ros_stamp_ns(e.gps_week, e.tow_s)  # ROS (UTC) stamp
        assert (r.epoch.gps_week, r.epoch.gps_time_of_week_s) == (e.gps_week, e.tow_s)
        assert r.reference_source == "given"
    assert sum(r.skipped["stale_ephemeris"] for r in res) > 0
    first = res[0].epoch
    g02 = next(o for o in first.observations if o.svid == 2)
    assert g02.constellation == GPS
    assert g02.pseudorange_m == 21276226.827
    assert g02.pseudorange_rate_mps == pytest.approx(-GPS_L1_WAVELENGTH_M * -1011.373)
    assert g02.cn0_dbhz == 45.770
    assert [o.svid for o in first.observations] == sorted(o.svid for o in first.observations)
    for o in first.observations:
        assert o.ionosphere_delay_m > 0 and o.troposphere_delay_m > 0
        assert math.isnan(o.pseudorange_std_m)


def test_residuals_at_the_surveyed_position_are_small(arl1):
    """The real oracle of orbits, clocks, TGD, Sagnac and delays: ARL1 C1 residuals at the truth."""
    obs, _, res = arl1
    truth = obs.header.approx_position_ecef_m
    all_res = []
    for r in res:
        ob = r.epoch.observations
        pos = np.array([o.satellite_position_ecef_m for o in ob])
        rot, _, _ = earth_rotation_correction(pos, truth)
        _, el = azimuth_elevation(truth, rot)
        modelled = np.array(
            [
                o.pseudorange_m + o.satellite_clock_bias_m - o.ionosphere_delay_m - o.troposphere_delay_m
                for o in ob
            ]
        )
        x = modelled - np.linalg.norm(rot - truth, axis=1)
        keep = el > math.radians(15.0)
        all_res.append(x[keep] - np.median(x[keep]))  # the median absorbs the receiver clock
    a = np.concatenate(all_res)
    assert np.sqrt(np.mean(a**2)) < 1.0  # measured 0.81 m
    assert np.max(np.abs(a)) < 5.0


def test_doppler_sign_matches_pseudorange_differences(arl1):
    _, _, res = arl1
    diffs = []
    for k in range(1, len(res) - 1):
        before = {o.svid: o.pseudorange_m for o in res[k - 1].epoch.observations}
        after = {o.svid: o.pseudorange_m for o in res[k + 1].epoch.observations}
        for o in res[k].epoch.observations:
            if o.svid in before and o.svid in after:
                diffs.append((after[o.svid] - before[o.svid]) / 60.0 - o.pseudorange_rate_mps)
    diffs = np.array(diffs)
    assert np.median(np.abs(diffs)) < 0.05  # measured 0.009 m/s; a sign error would give ~100s of m/s


def test_coarse_fix_when_no_reference_position(arl1):
    obs, nav, res = arl1
    builder = GnssEpochBuilder(nav.ephemerides, nav.header.iono_alpha, nav.header.iono_beta, None)
    r = builder.build(obs.epochs[0])
    assert r.reference_source == "coarse_fix"
    assert np.linalg.norm(r.reference_position_ecef_m - obs.header.approx_position_ecef_m) < 100.0
    for a, b in zip(r.epoch.observations, res[0].epoch.observations, strict=True):
        assert a.ionosphere_delay_m == pytest.approx(b.ionosphere_delay_m, abs=0.01)
        assert a.troposphere_delay_m == pytest.approx(b.troposphere_delay_m, abs=0.05)
    assert coarse_position_fix(np.zeros((3, 3)), np.zeros(3)) is None


def test_geonet_has_nan_rate_and_cn0():
    obs = read_rinex_obs(DATA / "07590920.05o")
    nav = read_rinex_nav(DATA / "07590920.05n")
    r = GnssEpochBuilder.from_rinex(obs, nav).build(obs.epochs[0])
    assert len(r.epoch.observations) == 8
    assert all(math.isnan(o.pseudorange_rate_mps) and math.isnan(o.cn0_dbhz) for o in r.epoch.observations)
    assert all(math.isfinite(o.pseudorange_m) for o in r.epoch.observations)


def test_missing_ephemeris_and_other_systems_are_counted(arl1):
    obs, nav, _ = arl1
    no_prn2 = [e for e in nav.ephemerides if e.prn != 2]
    r = GnssEpochBuilder(no_prn2, None, None, obs.header.approx_position_ecef_m).build(obs.epochs[0])
    assert r.skipped["no_ephemeris"] == 1 and ("G02", "no_ephemeris") in r.skipped_satellites
    assert r.extra["ionosphere_unavailable"] == len(r.epoch.observations)
    assert all(o.ionosphere_delay_m == 0.0 for o in r.epoch.observations)
    obs3 = read_rinex_obs(DATA / "hand_rnx3.rnx")
    nav3 = read_rinex_nav(DATA / "hand_rnx3.nav")
    r3 = GnssEpochBuilder.from_rinex(obs3, nav3).build(obs3.epochs[0])
    # The hand-made R07 / E11 nav records are non-physical, so those satellites have no ephemeris.
    assert r3.skipped["unsupported_constellation"] == 0
    assert r3.skipped_by_constellation["glonass"] == {"no_ephemeris": 1}
    assert r3.skipped_by_constellation["galileo"] == {"no_ephemeris": 1}
    gps_only = GnssEpochBuilder.from_rinex(obs3, nav3, MeasurementBuilderParams(constellations=("G",)))
    r3g = gps_only.build(obs3.epochs[0])
    assert r3g.skipped["unsupported_constellation"] == 2
    assert r3g.skipped_by_constellation["glonass"] == {"unsupported_constellation": 1}
    assert r3g.skipped_by_constellation["galileo"] == {"unsupported_constellation": 1}
    assert r3g.skipped["no_ephemeris"] == r3.skipped["no_ephemeris"] - 2
    ref = GnssEpochBuilder.from_rinex(obs, nav).build(obs.epochs[0])
    assert [o.svid for o in r3.epoch.observations] == [o.svid for o in ref.epoch.observations]
    for a, b in zip(r3.epoch.observations, ref.epoch.observations, strict=True):
        np.testing.assert_allclose(a.satellite_position_ecef_m, b.satellite_position_ecef_m, atol=1e-6)
        assert a.ionosphere_delay_m == pytest.approx(b.ionosphere_delay_m, rel=1e-3)


def test_missing_and_absurd_pseudoranges_are_counted(arl1):
    obs, nav, _ = arl1
    e = obs.epochs[0]
    obs_mod = dict(e.observations)
    obs_mod["G02"] = dict(obs_mod["G02"], C1=float("nan"))
    obs_mod["G05"] = dict(obs_mod["G05"], C1=12345.0)
    from dataclasses import replace

    r = GnssEpochBuilder.from_rinex(obs, nav).build(replace(e, observations=obs_mod))
    assert r.skipped["missing_pseudorange"] == 1
    assert r.skipped["pseudorange_out_of_range"] == 1
    with pytest.raises(ValueError):
        MeasurementBuilderParams(min_pseudorange_m=5e7)
    with pytest.raises(ValueError):
        GnssEpochBuilder(nav.ephemerides, None, None, np.array([1.0, 2.0, 3.0]))
