"""Time-correlated pseudorange errors (issue 15 item 2): one Gauss-Markov state per satellite.

An oracle (a hand-written Kalman filter with the same augmented model on a linear-enough
scenario), the allocation and removal of the per-satellite states, and the consistency of the
filter on the simulator whose pseudoranges carry 60 s correlated errors.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gnss_common.clock_model import clock_process_noise_m
from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic, enu_to_ecef
from gnss_common.earth_rotation import sagnac_range_correction_m
from gnss_common.observations import GLONASS, GPS, GnssEpoch, SatelliteObservation
from uwb_gnss_fusion.fusion_filter import CORRELATED_ERROR_MAX_GAP_TAU, FusionFilter, FusionParams
from uwb_gnss_fusion.fusion_params import GLONASS_BIAS_MAX_GAP_S
from uwb_gnss_fusion.measurement_models import STATE_DIM, white_acceleration_noise

RX = np.array([3582105.2910, 532589.7313, 5232754.8054])
NS = 1_000_000_000
T0 = 2_000 * NS
CLOCK_M = 120.0
SKY = [(0, 75), (60, 35), (130, 50), (200, 25), (250, 60), (310, 30), (100, 15), (170, 80)]
SAT_POS = np.array([
    enu_to_ecef(2.2e7 * np.array([math.cos(math.radians(e)) * math.sin(math.radians(a)),
                                  math.cos(math.radians(e)) * math.cos(math.radians(a)),
                                  math.sin(math.radians(e))]), RX)
    for a, e in SKY
])
SIGMA_PR = 0.5  # white part, given in the messages, m
STD_M, TAU_S = 0.8, 5.0


def _epoch(k: int, errors: np.ndarray, rng: np.random.Generator, present) -> GnssEpoch:
    obs = []
    for i in present:
        sp = SAT_POS[i]
        rho = float(np.linalg.norm(sp - RX) + sagnac_range_correction_m(sp, RX))
        pr = rho + CLOCK_M + errors[i] + SIGMA_PR * rng.standard_normal()
        obs.append(SatelliteObservation(
            constellation=GPS, svid=i + 1, pseudorange_m=pr, pseudorange_rate_mps=math.nan, cn0_dbhz=45.0,
            satellite_position_ecef_m=sp.copy(), satellite_velocity_ecef_mps=np.zeros(3),
            satellite_clock_bias_m=0.0, satellite_clock_drift_mps=0.0, pseudorange_std_m=SIGMA_PR,
        ))
    return GnssEpoch(stamp_ns=T0 + k * NS, gps_week=2111, gps_time_of_week_s=float(k), observations=tuple(obs))


def _params(**kw) -> FusionParams:
    base = dict(use_uwb=False, use_doppler=False, accel_psd_m2ps3=0.01, gate_probability=1.0,
                common_mode_screen=False, max_update_iterations=0,
                pseudorange_correlated_std_m=STD_M, pseudorange_correlated_tau_s=TAU_S,
                divergence_fix_confirm_s=0.0,   # the state layout from the first epoch on
                motion_detection=False)   # the oracle is the constant-velocity model (no static model)
    base.update(kw)
    return FusionParams(**base)


def _gm_errors(rng: np.random.Generator, n_epochs: int) -> np.ndarray:
    phi = math.exp(-1.0 / TAU_S)
    e = np.empty((n_epochs, len(SKY)))
    e[0] = STD_M * rng.standard_normal(len(SKY))
    for k in range(1, n_epochs):
        e[k] = phi * e[k - 1] + STD_M * math.sqrt(1 - phi**2) * rng.standard_normal(len(SKY))
    return e


def test_oracle_equals_kalman_filter_with_the_augmented_model():
    """The filter against a Kalman filter written out here with the same augmented model: states
    [p, v, c dt, c ddt, e_1..e_8], Phi with exp(-dt/tau) on the error states, Q with
    sigma^2 (1 - exp(-2 dt/tau)), H = [-los^T, 0, 1, 0, unit row]. The satellites are 22,000 km
    away and the position error is metres, so the range is linear to 1e-7 relative and the cubature
    update equals the Kalman one to well below a millimetre. Satellite 8 stops at epoch 20; its
    state is removed after CORRELATED_ERROR_MAX_GAP_TAU tau (an exact marginalisation: the other
    states keep matching the reference, which keeps the unobserved state)."""
    rng = np.random.default_rng(11)
    n_ep = 45
    err = _gm_errors(rng, n_ep)
    p = _params()
    f = FusionFilter(p)
    x0 = RX + np.array([3.0, -2.0, 4.0])
    f.initialize(T0, x0, velocity_mps=np.zeros(3), clock_bias_m=CLOCK_M + 5.0, clock_drift_mps=0.0)
    n = STATE_DIM + len(SKY)
    x = np.zeros(n)
    x[0:3] = x0
    x[6] = CLOCK_M + 5.0
    cov = np.zeros((n, n))
    cov[:STATE_DIM, :STATE_DIM] = f.state.ckf.p  # the same prior (init_*_std of the parameters)
    cov[STATE_DIM:, STATE_DIM:] = np.eye(len(SKY)) * STD_M**2
    phi = np.eye(n)
    phi[0, 3] = phi[1, 4] = phi[2, 5] = phi[6, 7] = 1.0
    g = math.exp(-1.0 / TAU_S)
    phi[STATE_DIM:, STATE_DIM:] *= g
    q = np.zeros((n, n))
    q[0:6, 0:6] = white_acceleration_noise(p.accel_psd_m2ps3, 1.0)
    q[6:8, 6:8] = clock_process_noise_m(p.clock, 1.0)
    q[STATE_DIM:, STATE_DIM:] = np.eye(len(SKY)) * STD_M**2 * (1.0 - g**2)
    removed_at = None
    for k in range(1, n_ep):
        present = range(len(SKY)) if k < 20 else range(len(SKY) - 1)
        ep = _epoch(k, err[k], rng, present)
        out = f.process_gnss(ep)
        x = phi @ x
        cov = phi @ cov @ phi.T + q
        idx = list(present)
        d = SAT_POS[idx] - x[None, 0:3]
        rng_m = np.linalg.norm(d, axis=1)
        h = np.zeros((len(idx), n))
        h[:, 0:3] = -d / rng_m[:, None]
        h[:, 6] = 1.0
        h[np.arange(len(idx)), STATE_DIM + np.array(idx)] = 1.0
        z = np.array([o.pseudorange_m for o in ep.observations])
        z_hat = rng_m + sagnac_range_correction_m(SAT_POS[idx], x[None, 0:3]) + x[6] + x[STATE_DIM + np.array(idx)]
        s = h @ cov @ h.T + SIGMA_PR**2 * np.eye(len(idx))
        gain = cov @ h.T @ np.linalg.inv(s)
        x = x + gain @ (z - z_hat)
        cov = cov - gain @ s @ gain.T
        np.testing.assert_allclose(out.position_m, x[0:3], rtol=0, atol=2e-4)
        np.testing.assert_allclose(out.clock_bias_m, x[6], rtol=0, atol=2e-4)
        np.testing.assert_allclose(out.covariance_pv[0:3, 0:3], cov[0:3, 0:3], rtol=1e-4, atol=1e-8)
        est = f.correlated_errors_m
        for i in idx:
            assert est[GPS * 1000 + i + 1][0] == pytest.approx(x[STATE_DIM + i], abs=2e-4)
            assert est[GPS * 1000 + i + 1][1] == pytest.approx(math.sqrt(cov[STATE_DIM + i, STATE_DIM + i]), rel=1e-4)
        if removed_at is None and f.state_dimension == STATE_DIM + len(SKY) - 1:
            removed_at = k
    # the state of satellite 8 (last seen at epoch 19) is removed at the first epoch more than
    # CORRELATED_ERROR_MAX_GAP_TAU * tau later
    assert removed_at == 19 + math.floor(CORRELATED_ERROR_MAX_GAP_TAU * TAU_S) + 1
    assert f.rejection_counts["correlated_error_removed"] == 1


def test_slots_follow_the_satellites_and_inter_system_biases_stay_in_front():
    """Satellites appearing get a state (zero, stationary variance), those gone for long lose it,
    a returning one gets a fresh state; an inter-system bias added later goes in front of the
    error states, which keep their estimates."""
    from gnss_common.observations import GALILEO

    rng = np.random.default_rng(3)
    f = FusionFilter(_params())
    errs = np.zeros(len(SKY))
    f.process_gnss(_epoch(0, errs, rng, range(6)))  # snapshot fix: no error states yet
    assert f.state_dimension == STATE_DIM
    f.process_gnss(_epoch(1, errs, rng, range(6)))
    assert f.state_dimension == STATE_DIM + 6
    assert sorted(f.correlated_errors_m) == [GPS * 1000 + i + 1 for i in range(6)]
    f.process_gnss(_epoch(2, errs, rng, range(7)))
    assert f.state_dimension == STATE_DIM + 7
    new = f.correlated_errors_m[GPS * 1000 + 7]
    # fresh (prior: the stationary 1-sigma, uncorrelated), then one update: the new satellite's
    # pseudorange mostly informs its own error, so its 1-sigma drops only a little
    assert 0.6 * STD_M < new[1] < STD_M
    before = f.correlated_errors_m
    # a Galileo satellite appears: its system's bias goes to column 8, the error states follow
    ep = _epoch(3, errs, rng, range(7))
    gal = SatelliteObservation(
        constellation=GALILEO, svid=5, pseudorange_m=ep.observations[0].pseudorange_m + 30.0,
        pseudorange_rate_mps=math.nan, cn0_dbhz=45.0, satellite_position_ecef_m=SAT_POS[0] * 1.02,
        satellite_velocity_ecef_mps=np.zeros(3), satellite_clock_bias_m=0.0, satellite_clock_drift_mps=0.0,
        pseudorange_std_m=SIGMA_PR)
    sp = gal.satellite_position_ecef_m
    gal = SatelliteObservation(**{**gal.__dict__, "pseudorange_m": float(
        np.linalg.norm(sp - RX) + sagnac_range_correction_m(sp, RX) + CLOCK_M + 30.0)})
    f.process_gnss(GnssEpoch(ep.stamp_ns, ep.gps_week, ep.gps_time_of_week_s, ep.observations + (gal,)))
    assert f.state_dimension == STATE_DIM + 1 + 8
    assert "galileo" in f.inter_system_biases_m
    after = f.correlated_errors_m
    assert set(after) == set(before) | {GALILEO * 1000 + 5}
    # GPS satellites 1-6 only from now on: 7 and the Galileo one are removed after the gap
    gap = int(CORRELATED_ERROR_MAX_GAP_TAU * TAU_S) + 2
    for k in range(4, 4 + gap):
        f.process_gnss(_epoch(k, errs, rng, range(6)))
    assert sorted(f.correlated_errors_m) == [GPS * 1000 + i + 1 for i in range(6)]
    assert f.rejection_counts["correlated_error_removed"] == 2
    # satellite 7 returns: a fresh state
    f.process_gnss(_epoch(4 + gap, errs, rng, range(7)))
    assert GPS * 1000 + 7 in f.correlated_errors_m
    assert f.rejection_counts["correlated_error_added"] == 6 + 1 + 1 + 1


def test_off_by_default_keeps_eight_states():
    rng = np.random.default_rng(1)
    f = FusionFilter(_params(pseudorange_correlated_std_m=0.0))
    for k in range(4):
        f.process_gnss(_epoch(k, np.zeros(len(SKY)), rng, range(8)))
    assert f.state_dimension == STATE_DIM and f.correlated_errors_m == {}
    assert FusionParams().pseudorange_correlated_std_m == 0.0
    with pytest.raises(ValueError):
        FusionParams(pseudorange_correlated_std_m=-1.0)
    with pytest.raises(ValueError):
        FusionParams(pseudorange_correlated_tau_s=0.0)


NAV = Path(__file__).resolve().parents[2] / "gnss_common" / "test" / "data" / "arlm2000.15n"


def _consistency(std_m: float) -> np.ndarray:
    from rfi_sim.gnss_uwb import BroadcastGeometry, GnssUwbScenario, simulate

    geo = BroadcastGeometry(NAV)
    run = simulate(GnssUwbScenario(jsr_db=None, duration_s=360.0, seed=100), geo, geo.iono_alpha, geo.iono_beta)
    truth = np.asarray(run.truth.receiver_ecef_m, dtype=float)
    lat, lon, _ = ecef_to_geodetic(truth)
    rot = ecef_to_enu_rotation(lat, lon)
    f = FusionFilter(FusionParams(use_uwb=False, accel_psd_m2ps3=0.01, pseudorange_correlated_std_m=std_m))
    ratios = []
    t0 = run.gnss_epochs[0].stamp_ns
    for ep in run.gnss_epochs:
        out = f.process_gnss(ep)
        if (ep.stamp_ns - t0) / NS >= 10.0:
            e = rot @ (out.position_m - truth)
            s = np.sqrt(np.diag(rot @ out.covariance_pv[0:3, 0:3] @ rot.T))
            ratios.append(e / s)
    return np.sqrt(np.mean(np.array(ratios) ** 2, axis=0))


def test_consistent_on_the_simulator_with_60s_correlated_errors():
    """The simulator adds a 0.7 m, 60 s Gauss-Markov error to every pseudorange. Treated as white,
    the GNSS-only filter's errors are 6-7 times its reported 1-sigma (measured: 6.7 / 7.1 / 5.9
    east / north / up); with the matching model they are about its 1-sigma (measured 1.0 / 1.0 /
    0.5). Six minutes hold only six correlation times, so the band is wide."""
    white = _consistency(0.0)
    modelled = _consistency(0.7)
    assert np.all(white > 3.0)
    assert np.all(modelled < 2.0) and np.all(modelled > 0.25)


def _with_glonass(ep: GnssEpoch, svids, bias_m: float) -> GnssEpoch:
    """The epoch with GLONASS satellites ``svids`` at the positions of GPS satellites 1.. scaled by 1.03
    (distinct satellites), each with ``bias_m`` of code bias on top of a 40 m inter-system bias."""
    extra = []
    for j, svid in enumerate(svids):
        sp = SAT_POS[j] * 1.03
        pr = float(np.linalg.norm(sp - RX) + sagnac_range_correction_m(sp, RX)) + CLOCK_M + 40.0 + bias_m
        extra.append(SatelliteObservation(
            constellation=GLONASS, svid=svid, pseudorange_m=pr, pseudorange_rate_mps=math.nan, cn0_dbhz=45.0,
            satellite_position_ecef_m=sp, satellite_velocity_ecef_mps=np.zeros(3), satellite_clock_bias_m=0.0,
            satellite_clock_drift_mps=0.0, pseudorange_std_m=SIGMA_PR, carrier_frequency_hz=1_602.0e6))
    return GnssEpoch(ep.stamp_ns, ep.gps_week, ep.gps_time_of_week_s, ep.observations + tuple(extra))


def test_glonass_code_bias_states_only_for_glonass_and_constant():
    """With the correlated errors off, ``glonass_satellite_bias_std_m`` gives each GLONASS satellite (and
    no other) a state with that prior sigma and no process noise (a random constant: its variance never
    grows); a GLONASS satellite unseen for GLONASS_BIAS_MAX_GAP_S loses it."""
    rng = np.random.default_rng(4)
    f = FusionFilter(_params(pseudorange_correlated_std_m=0.0, glonass_satellite_bias_std_m=1.0))
    zero = np.zeros(len(SKY))
    for k in range(2):  # the first epoch initialises the filter, the second allocates the states
        f.process_gnss(_with_glonass(_epoch(k, zero, rng, range(8)), (3, 9), 0.0))
    # 8 + the GLONASS inter-system bias + two code-bias states
    assert f.state_dimension == STATE_DIM + 1 + 2
    errs = f.correlated_errors_m
    assert sorted(errs) == [GLONASS * 1000 + 3, GLONASS * 1000 + 9]
    assert all(0.0 < s <= 1.0 for _, s in errs.values())  # from the prior 1-sigma, one update applied
    sigmas = []
    for k in range(2, 40):
        f.process_gnss(_with_glonass(_epoch(k, zero, rng, range(8)), (3, 9), 0.0))
        sigmas.append([s for _, s in f.correlated_errors_m.values()])
    sig = np.array(sigmas)
    assert (np.diff(sig, axis=0) <= 1e-12).all()  # no process noise: never grows
    # GLONASS 9 leaves; after the gap its state is removed, GLONASS 3's kept
    k = 40
    for t in range(k, k + int(GLONASS_BIAS_MAX_GAP_S) + 200, 100):  # 100 s steps: no time-gap reset
        f.process_gnss(_with_glonass(_epoch(t, zero, rng, range(8)), (3,), 0.0))
    assert sorted(f.correlated_errors_m) == [GLONASS * 1000 + 3]
    assert f.rejection_counts["correlated_error_removed"] == 1
    with pytest.raises(ValueError):
        FusionParams(glonass_satellite_bias_std_m=-1.0)
    with pytest.raises(ValueError):
        FusionParams(glonass_pseudorange_error_factor=0.5)
