"""The motion model's stationarity detector (uwb_gnss_fusion.motion_model, issue 27 item 4)."""

from pathlib import Path

import numpy as np
import pytest

from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic
from gnss_common.measurements import build_epochs
from gnss_common.rinex import read_rinex_nav, read_rinex_obs
from gnss_common.rinex_ionosphere import level_gps_ionosphere
from gnss_common.spp import SinglePointPositioner
from uwb_gnss_fusion.ckf import CubatureKalmanFilter
from uwb_gnss_fusion.fusion_filter import FusionFilter, FusionParams
from uwb_gnss_fusion.motion_model import StationarityDetector, displacement_test, zero_velocity_update

DATA = Path(__file__).resolve().parents[2] / "gnss_common" / "test" / "data"


def _horizontal_rms(positions: np.ndarray, truth: np.ndarray) -> float:
    lat, lon, _ = ecef_to_geodetic(truth)
    enu = (positions - truth) @ ecef_to_enu_rotation(lat, lon).T
    return float(np.sqrt(np.mean(enu[:, 0] ** 2 + enu[:, 1] ** 2)))


def _station(obs: str, nav: str, params: FusionParams,
             carrier_levelled: bool = False) -> tuple[float, float, dict[str, int]]:
    """(filter, SPP) horizontal RMS against the header position, and the filter's counts; every output
    after the detector's entry says the static model runs. ``carrier_levelled``: GPS ionospheric
    delays from the L1/L2 carriers (``rinex_to_bag --ionosphere carrier-levelled``), for both."""
    o = read_rinex_obs(DATA / obs)
    truth = np.asarray(o.header.approx_position_ecef_m, dtype=float)
    epochs = [r.epoch for r in build_epochs(o, read_rinex_nav(DATA / nav))]
    if carrier_levelled:
        epochs, counts = level_gps_ionosphere(o, epochs)
        assert counts["levelled"] > 0.9 * (counts["levelled"] + counts["model"])
    f = FusionFilter(params)
    spp = SinglePointPositioner()
    fused, snap = [], []
    for e in epochs:
        out = f.process_gnss(e)
        assert out.motion_static == f.motion_static
        if out.initialized:
            fused.append(out.position_m)
        s = spp.process(e)
        if s.valid:
            snap.append(s.position_ecef_m)
    return _horizontal_rms(np.array(fused), truth), _horizontal_rms(np.array(snap), truth), f.rejection_counts


def test_default_filter_beats_spp_by_20_percent_on_arl1():
    """ARL1 (static, 30 s, with Doppler): the shipped defaults find the antenna static on their own.
    Before the detector: 1.25 vs 1.27 m (2 %); told static (accel_psd 1e-6): 0.99 m."""
    fused, spp, counts = _station("arlm200a.15o", "arlm2000.15n", FusionParams(use_uwb=False))
    assert fused <= 0.8 * spp, (fused, spp)
    assert counts.get("motion_static_entered") == 1 and "motion_static_left" not in counts


@pytest.mark.parametrize("obs, nav", [("07590920.05o", "07590920.05n"), ("30400920.05o", "30400920.05n")])
def test_default_filter_beats_spp_without_doppler(obs, nav):
    """GEONET (static, 30 s, no Doppler): found static from the positions alone. The goal of 20 % is
    not met here (15 % and 18 %, docs/uwb_gnss_fusion/fusion_real_gnss.md); before: 3 % and 6 %."""
    fused, spp, counts = _station(obs, nav, FusionParams(use_uwb=False))
    assert fused <= 0.9 * spp, (fused, spp)
    assert counts.get("motion_static_entered") == 1 and "motion_static_left" not in counts


@pytest.mark.parametrize("obs, nav", [("arlm200a.15o", "arlm2000.15n"), ("07590920.05o", "07590920.05n"),
                                      ("30400920.05o", "30400920.05n")])
def test_broadcast_error_in_the_weights_beats_spp_by_20_percent(obs, nav):
    """The opt-in ``pseudorange_broadcast_std_m`` at the SPP's own SISRE (1 m): 21 %, 22 %, 21 %
    better than SPP (shipped, 0: 25 %, 15 %, 18 %); off by default because it worsens ESBC00DNK's
    multi-GNSS day (docs/uwb_gnss_fusion/fusion_esbc_diagnosis.md)."""
    fused, spp, counts = _station(obs, nav, FusionParams(use_uwb=False, pseudorange_broadcast_std_m=1.0))
    assert fused <= 0.8 * spp, (fused, spp)
    assert counts.get("motion_static_entered") == 1 and "motion_static_left" not in counts


@pytest.mark.parametrize("obs, nav", [("arlm200a.15o", "arlm2000.15n"), ("07590920.05o", "07590920.05n"),
                                      ("30400920.05o", "30400920.05n")])
def test_default_filter_beats_spp_by_20_percent_with_carrier_levelled_ionosphere(obs, nav):
    """Issue 27 item 4 with the ionosphere's changes measured by the L1/L2 carrier (both solutions on
    the same epochs): 27 %, 25 %, 24 % (docs/uwb_gnss_fusion/fusion_real_gnss.md); with Klobuchar
    alone 25 %, 15 %, 18 % (the test above)."""
    fused, spp, counts = _station(obs, nav, FusionParams(use_uwb=False), carrier_levelled=True)
    assert fused <= 0.8 * spp, (fused, spp)
    assert counts.get("motion_static_entered") == 1 and "motion_static_left" not in counts


def test_zero_velocity_update_equals_the_linear_kalman_update():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(8, 8))
    p = a @ a.T + np.eye(8)
    v = np.array([0.3, -0.2, 0.1])
    dx, p_new = zero_velocity_update(p, v, 0.01)
    kf = CubatureKalmanFilter(np.zeros(8), p)
    h = np.zeros((3, 8))
    h[:, 3:6] = np.eye(3)
    kf.update(-v, np.eye(3) * 1e-4, lambda s: s @ h.T)
    np.testing.assert_allclose(dx, kf.x, atol=1e-9)
    np.testing.assert_allclose(p_new, kf.p, atol=1e-9)


def test_displacement_test_sees_a_displacement_not_a_common_mode_nor_one_outlier():
    rng = np.random.default_rng(4)
    los = rng.normal(size=(10, 3))
    los /= np.linalg.norm(los, axis=1)[:, None]
    groups = np.array([0, 0, 0, 0, 0, 0, 1, 1, 1, 1])
    noise = rng.normal(size=10)
    cov = np.eye(3) * 1e-6
    base = displacement_test(noise, los, cov, np.ones(10), groups)
    # common modes (clock, inter-system bias) change nothing
    shifted = displacement_test(noise + np.where(groups == 1, 50.0, -7.0), los, cov, np.ones(10), groups)
    assert shifted[:3] == pytest.approx(base[:3])
    assert base[2] == 10 - 2 - 3
    # a 5 m displacement: significant (chi2_3(0.999) = 16.3), and it explains the innovations
    # (chi2_5(0.999) = 20.5)
    moved = displacement_test(noise - los @ np.array([5.0, 0.0, 0.0]), los, cov, np.ones(10), groups)
    assert moved[0] > 16.3 and moved[1] < 20.5
    assert abs(moved[3][0] - 5.0) < 1.5  # the receiver's displacement
    # one 50-sigma outlier is left out
    one = noise.copy()
    one[3] += 50.0
    assert displacement_test(one, los, cov, np.ones(10), groups)[0] < 20.0


Z = np.zeros(3)


def test_detector_hysteresis_entry_and_exit():
    d = StationarityDetector(enter_s=10.0)
    rng = np.random.default_rng(5)
    cov = np.eye(3)
    # moving at 1 m/s with 30 s epochs: never static
    for k in range(20):
        assert not d.observe_moving(k * 30_000_000_000, np.array([30.0 * k, 0, 0]) + rng.normal(size=3), cov,
                                    np.array([1.0, 0, 0]), np.eye(3) * 0.01)
    d.reset()
    # static: three epochs and 10 s, then static
    entered = [d.observe_moving(k * 5_000_000_000, rng.normal(size=3), cov, rng.normal(size=3) * 0.05,
                                np.eye(3) * 0.0025) for k in range(4)]
    assert entered == [False, False, True, False] or entered[:3] == [False, False, True]
    assert d.static
    # one failing epoch opens the covariance, a passing one clears it, two in a row leave; a displacement
    # that leaves inconsistent residuals is a measurement fault, not motion
    assert d.observe_static([(1000.0, 3.0, 6, Z)]).open_covariance and d.static
    assert not d.observe_static([(3.0, 3.0, 6, Z)]).open_covariance
    assert not d.observe_static([(1000.0, 1000.0, 6, Z)]).open_covariance  # noise, whatever its scale
    d.observe_static([(1000.0, 3.0, 6, Z)])
    decision = d.observe_static([(2.0, 3.0, 6, Z), (1000.0, 3.0, 6, Z)])  # the rates saw it
    assert decision.left_static and not d.static


def test_moving_receiver_is_never_static_and_static_one_is():
    """The filter on simulated receivers (benchmarks/fusion_motion_model.py): a receiver at 1 m/s is not
    declared static; a static one is, and its error is no worse than the moving model's."""
    from rfi_sim.gnss_uwb import BroadcastGeometry, GnssUwbScenario, simulate

    geo = BroadcastGeometry(DATA / "arlm2000.15n")
    for v, expect in (((1.0, 0.0, 0.0), 0), ((0.0, 0.0, 0.0), 1)):
        run = simulate(GnssUwbScenario(jsr_db=None, seed=27, duration_s=120.0, receiver_velocity_enu_mps=v),
                       geo, geo.iono_alpha, geo.iono_beta)
        f = FusionFilter(FusionParams(use_uwb=False))
        for e in run.gnss_epochs:
            f.process_gnss(e)
        assert f.rejection_counts.get("motion_static_entered", 0) == expect
