"""The ionosphere-free GPS pseudoranges of gnss_common.measurements (issue 27 item 4), on real ARL1/GEONET data."""

import math
from pathlib import Path

import numpy as np
import pytest

from gnss_common.constants import GPS_L1_FREQUENCY_HZ, GPS_L2_FREQUENCY_HZ, SPEED_OF_LIGHT_MPS
from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic
from gnss_common.corrections import ionosphere_free_pseudorange_m
from gnss_common.measurements import GnssEpochBuilder, MeasurementBuilderParams
from gnss_common.rinex import read_rinex_nav, read_rinex_obs
from gnss_common.spp import SinglePointPositioner

DATA = Path(__file__).parent / "data"


def test_combination_removes_a_first_order_delay_exactly() -> None:
    """Oracle: a delay 40.3 TEC / f^2 on both codes leaves the geometric range."""
    rho = np.array([2.0e7, 2.3e7, 2.55e7])
    iono_l1 = np.array([3.0, 12.5, 0.0])
    pr1 = rho + iono_l1
    pr2 = rho + iono_l1 * (GPS_L1_FREQUENCY_HZ / GPS_L2_FREQUENCY_HZ) ** 2
    out = ionosphere_free_pseudorange_m(pr1, pr2, GPS_L1_FREQUENCY_HZ, GPS_L2_FREQUENCY_HZ)
    assert np.allclose(out, rho, rtol=0.0, atol=1e-6)
    # the IS-GPS-200 form (PR_L2 - gamma PR_L1) / (1 - gamma)
    gamma = (GPS_L1_FREQUENCY_HZ / GPS_L2_FREQUENCY_HZ) ** 2
    assert np.allclose(out, (pr2 - gamma * pr1) / (1.0 - gamma), rtol=0.0, atol=1e-6)


@pytest.mark.parametrize("f1, f2", [(GPS_L1_FREQUENCY_HZ, GPS_L1_FREQUENCY_HZ), (0.0, GPS_L2_FREQUENCY_HZ),
                                    (math.nan, GPS_L2_FREQUENCY_HZ)])
def test_combination_rejects_bad_carriers(f1: float, f2: float) -> None:
    with pytest.raises(ValueError, match="carriers"):
        ionosphere_free_pseudorange_m(2.0e7, 2.0e7, f1, f2)


def _build(obs_name: str, nav_name: str, ionosphere_free: bool):
    obs = read_rinex_obs(DATA / obs_name)
    nav = read_rinex_nav(DATA / nav_name)
    builder = GnssEpochBuilder.from_rinex(obs, nav, MeasurementBuilderParams(ionosphere_free=ionosphere_free))
    return obs, nav, [builder.build(e) for e in obs.epochs]


def test_arl1_p1_p2_combination_no_iono_clock_without_tgd() -> None:
    obs, nav, dual = _build("arlm200a.15o", "arlm2000.15n", True)
    _, _, single = _build("arlm200a.15o", "arlm2000.15n", False)
    tgd = {e.prn: e.tgd_s for e in nav.keplerian_ephemerides if e.system == "G"}
    n = 0
    for d, s, e in zip(dual, single, obs.epochs, strict=True):
        assert d.skipped["missing_dual_frequency"] == 0
        by_svid = {o.svid: o for o in s.epoch.observations}
        assert {o.svid for o in d.epoch.observations} == set(by_svid)
        for o in d.epoch.observations:
            values = e.observations[f"G{o.svid:02d}"]
            expected = ionosphere_free_pseudorange_m(values["P1"], values["P2"], GPS_L1_FREQUENCY_HZ,
                                                     GPS_L2_FREQUENCY_HZ)
            assert o.pseudorange_m == pytest.approx(float(expected), abs=1e-6)
            assert o.ionosphere_delay_m == 0.0
            ref = by_svid[o.svid]
            assert ref.ionosphere_delay_m > 0.0
            # the same transmit time to within the IF-L1 range difference: the clock moves by < 1 mm
            assert o.satellite_clock_bias_m - ref.satellite_clock_bias_m == pytest.approx(
                SPEED_OF_LIGHT_MPS * tgd[o.svid], abs=1e-3)
            assert o.pseudorange_rate_mps == ref.pseudorange_rate_mps and o.cn0_dbhz == ref.cn0_dbhz
            assert d.signal_codes[f"G{o.svid:02d}"] == "P1+P2"
            n += 1
    assert n > 1000


def _spp_rms_3d(results, truth: np.ndarray) -> float:
    lat, lon, _ = ecef_to_geodetic(truth)
    rot = ecef_to_enu_rotation(lat, lon)
    spp = SinglePointPositioner()
    err = [rot @ (r.position_ecef_m - truth) for r in (spp.process(b.epoch) for b in results) if r.valid]
    return float(np.sqrt(np.mean(np.sum(np.square(err), axis=1))))


def test_arl1_ionosphere_free_spp_lowers_the_3d_error() -> None:
    """The Klobuchar residual is ARL1's largest SPP error (+2.5 m mean up): gone with P1/P2
    (docs/uwb_gnss_fusion/fusion_real_gnss.md, section 4: 3.18 -> 2.73 m 3D RMS)."""
    obs, _, dual = _build("arlm200a.15o", "arlm2000.15n", True)
    _, _, single = _build("arlm200a.15o", "arlm2000.15n", False)
    truth = obs.header.approx_position_ecef_m
    assert _spp_rms_3d(dual, truth) < 0.9 * _spp_rms_3d(single, truth)


def test_geonet_c1_only_is_not_combined() -> None:
    """GEONET records C1 and P2, no P1: C/A with P2 is not combined (P1-C1 bias): every GPS satellite
    skipped and counted, none built."""
    _, _, dual = _build("07590920.05o", "07590920.05n", True)
    _, _, single = _build("07590920.05o", "07590920.05n", False)
    assert sum(len(r.epoch.observations) for r in dual) == 0
    # each satellite with a C1 range is counted once, before the ephemeris checks
    later = ("pseudorange_out_of_range", "no_ephemeris", "unhealthy", "stale_ephemeris")
    expected = sum(len(r.epoch.observations) + sum(r.skipped[k] for k in later) for r in single)
    assert expected > 900
    assert sum(r.skipped["missing_dual_frequency"] for r in dual) == expected
