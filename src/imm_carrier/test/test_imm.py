"""Unit and oracle tests of the compiled two-mode IMM (Zhao et al., Section II)."""

import math

import numpy as np
import pytest

from gnss_common.clock_model import ClockHCoefficients, clock_process_noise_phase
from imm_carrier.covariance_analysis import covariance_analysis, phase_measurement_variance_rad2
from imm_carrier.imm import ImmCarrierFilter, ImmParams
from imm_carrier.imm_reference import imm_step_reference
from imm_carrier.measurement_model import iq_amplitude_and_noise_std

CLOCK = ClockHCoefficients(h0=1e-22, h_minus2=1e-22)  # lively enough that W matters in a short test
T = 0.02


def _bit_model(d, amp, sat):
    def h(x):
        th = sat + x[0]
        z = d * amp * np.array([math.cos(th), math.sin(th)])
        jac = d * amp * np.array([[-math.sin(th), 0.0], [math.cos(th), 0.0]])
        return z, jac

    return h


def test_compiled_imm_equals_reference_implementation():
    rng = np.random.default_rng(11)
    p_change = 0.3
    params = ImmParams(clock=CLOCK, bit_transition_probability=p_change)
    filt = ImmCarrierFilter(params)
    filt.initialize(0.4, 0.2, 0.3, 0.5, mode_probability_plus=0.7, satellite_phase_rad=0.1)
    w = clock_process_noise_phase(CLOCK, T)
    f = np.array([[1.0, T], [0.0, 1.0]])
    pi = np.array([[1 - p_change, p_change], [p_change, 1 - p_change]])
    p0 = np.diag([0.3**2, (2 * math.pi * 0.5) ** 2])
    means = [np.array([0.4, 2 * math.pi * 0.2])] * 2
    covs = [p0, p0]
    mu = np.array([0.7, 0.3])
    sat = 0.1
    for k in range(40):
        cn0 = 30.0 + 10 * rng.random()
        amp, sig = iq_amplitude_and_noise_std(cn0, T)
        dphi = rng.uniform(-3, 3)
        zi, zq = rng.normal(0.5, 0.5, size=2)
        if k == 17:
            zi = math.nan  # prediction-only step
        r = filt.update(zi, zq, cn0, T, dphi)
        sat = (sat + dphi + math.pi) % (2 * math.pi) - math.pi
        models = [_bit_model(1.0, amp, sat), _bit_model(-1.0, amp, sat)]
        z = None if k == 17 else np.array([zi, zq])
        means, covs, mu, xc, pc = imm_step_reference(means, covs, mu, pi, f, w, models, sig**2 * np.eye(2), z)
        assert r.phase_rad == pytest.approx(xc[0], abs=1e-9)
        assert r.frequency_hz == pytest.approx(xc[1] / (2 * math.pi), abs=1e-9)
        assert r.phase_std_rad == pytest.approx(math.sqrt(pc[0, 0]), rel=1e-9)
        assert r.frequency_std_hz == pytest.approx(math.sqrt(pc[1, 1]) / (2 * math.pi), rel=1e-9)
        assert r.mode_probabilities[0] == pytest.approx(mu[0], abs=1e-9)
        assert r.measurement_used == (k != 17)


def test_known_bits_reduce_to_the_covariance_analysis_riccati():
    # With the bit known every step the IMM is one EKF whose covariance is data independent and equals
    # the linear Kalman filter with H = [1, 0], R = sigma^2 / A^2 (covariance_analysis).
    rng = np.random.default_rng(2)
    filt = ImmCarrierFilter(ImmParams(clock=CLOCK))
    filt.initialize(0.0, 0.0, 0.2, 0.3)
    n = 200
    bits = np.where(rng.random(n) < 0.5, 1.0, -1.0)
    zi = bits * np.cos(0.05) + 0.05 * rng.standard_normal(n)
    zq = bits * np.sin(0.05) + 0.05 * rng.standard_normal(n)
    res = filt.process_batch(zi, zq, 35.0, T, np.zeros(n), bit_prior_plus=(bits > 0).astype(float))
    hist = covariance_analysis(CLOCK, 35.0, T, n, np.diag([0.2**2, (2 * math.pi * 0.3) ** 2]))
    np.testing.assert_allclose(res.phase_std_rad, hist.posterior_phase_std_rad, rtol=1e-6)
    np.testing.assert_allclose(res.frequency_std_hz, hist.posterior_frequency_std_hz, rtol=1e-6)
    np.testing.assert_allclose(res.prior_phase_std_rad, np.sqrt(hist.prior[:, 0, 0]), rtol=1e-6)


def test_static_phase_with_known_bits_reaches_the_cramer_rao_bound():
    # No clock dynamics, known bits: the phase error after N looks is sqrt(1 / (N 2 T C/N0)).
    cn0, n, runs = 25.0, 100, 300
    params = ImmParams(clock=ClockHCoefficients(h0=0.0, h_minus2=0.0))
    rng = np.random.default_rng(5)
    amp, sig = iq_amplitude_and_noise_std(cn0, T)
    truth = math.radians(135.0)
    errs = []
    for _ in range(runs):
        f = ImmCarrierFilter(params)
        f.initialize(truth + 0.2 * rng.standard_normal(), 0.0, 0.5, 1e-9)
        zi = amp * math.cos(truth) + sig * rng.standard_normal(n)
        zq = amp * math.sin(truth) + sig * rng.standard_normal(n)
        r = f.process_batch(zi, zq, cn0, T, np.zeros(n), bit_prior_plus=1.0)
        errs.append(r.phase_rad[-1] - truth)
    crlb = math.sqrt(phase_measurement_variance_rad2(cn0, T) / n)
    assert np.std(errs) == pytest.approx(crlb, rel=0.15)
    assert abs(np.mean(errs)) < 3 * crlb / math.sqrt(runs) + 0.01


def test_unknown_bits_are_recovered_and_tracking_is_consistent():
    rng = np.random.default_rng(8)
    n = 3000
    cn0 = 40.0
    amp, sig = iq_amplitude_and_noise_std(cn0, T)
    bits = np.where(rng.random(n) < 0.5, 1.0, -1.0)
    truth = 0.7 + 2 * math.pi * 0.05 * T * np.arange(1, n + 1)  # 0.05 Hz residual frequency
    zi = bits * amp * np.cos(truth) + sig * rng.standard_normal(n)
    zq = bits * amp * np.sin(truth) + sig * rng.standard_normal(n)
    f = ImmCarrierFilter(ImmParams(clock=CLOCK))
    f.initialize(0.7, 0.0, 0.1, 0.1, mode_probability_plus=1.0)
    r = f.process_batch(zi, zq, cn0, T, np.zeros(n))
    est_bits = np.where(r.mode_probability_plus > 0.5, 1.0, -1.0)
    assert np.mean(est_bits == bits) > 0.999
    err = r.phase_rad - truth
    assert np.max(np.abs(err)) < 0.5  # no half-cycle slip
    nees = np.mean((err[500:] / r.phase_std_rad[500:]) ** 2)
    assert 0.6 < nees < 1.6
    assert abs(np.mean(r.frequency_hz[-500:]) - 0.05) < 0.02
    assert np.all(r.locked[500:])


def test_unit_noise_scaling_gives_the_same_estimates():
    rng = np.random.default_rng(4)
    n = 50
    cn0 = 30.0
    amp_u, sig_u = iq_amplitude_and_noise_std(cn0, T, "unit_noise")
    zi = rng.standard_normal(n) * sig_u + amp_u
    zq = rng.standard_normal(n) * sig_u
    a = ImmCarrierFilter(ImmParams(clock=CLOCK))
    b = ImmCarrierFilter(ImmParams(clock=CLOCK, iq_scaling="unit_noise"))
    for f in (a, b):
        f.initialize(0.0, 0.0, 0.3, 0.3)
    ra = a.process_batch(zi / amp_u, zq / amp_u, cn0, T, np.zeros(n))
    rb = b.process_batch(zi, zq, cn0, T, np.zeros(n))
    np.testing.assert_allclose(ra.phase_rad, rb.phase_rad, rtol=1e-10, atol=1e-12)


def test_bad_inputs_are_rejected_or_coasted():
    f = ImmCarrierFilter(ImmParams(clock=CLOCK))
    with pytest.raises(ValueError):
        f.update(1.0, 0.0, 40.0, T, 0.0)  # not initialised
    f.initialize(0.0, 0.0, 0.1, 0.1)
    for kwargs in (
        {"integration_time_s": 0.0},
        {"integration_time_s": -T},
        {"cn0_dbhz": 80.0},
        {"cn0_dbhz": math.nan},
        {"predicted_phase_change_rad": math.inf},
    ):
        args = {
            "in_phase": 1.0,
            "quadrature": 0.0,
            "cn0_dbhz": 40.0,
            "integration_time_s": T,
            "predicted_phase_change_rad": 0.0,
        } | kwargs
        with pytest.raises(ValueError):
            f.update(**args)
    before = f.update(1.0, 0.0, 40.0, T, 0.0)
    coast = f.update(math.nan, math.inf, 40.0, T, 0.0)
    assert not coast.measurement_used
    assert coast.phase_std_rad > before.phase_std_rad
    assert math.isfinite(coast.phase_rad)
    res = f.process_batch(
        np.array([1.0, math.nan, 1.0, 1.0]),
        np.zeros(4),
        np.array([40.0, 40.0, 90.0, 40.0]),
        np.array([T, T, T, 0.0]),
        np.zeros(4),
    )
    assert res.counters == {
        "rejected_integration_time": 1,
        "rejected_cn0": 1,
        "rejected_predicted_phase": 0,
        "coasted_nonfinite_iq": 1,
    }
    assert list(res.accepted) == [True, True, False, False]
    assert not np.any(res.locked & ~np.isfinite(res.phase_rad))
    with pytest.raises(ValueError):
        f.process_batch(np.zeros(3), np.zeros(2), 40.0, T, np.zeros(3))


@pytest.mark.parametrize(
    "kwargs",
    [
        {"process_noise_scale": 0.0},
        {"bit_transition_probability": 1.5},
        {"process_noise_form": "x"},
        {"iq_scaling": "x"},
        {"initial_phase_std_rad": math.nan},
    ],
)
def test_params_validation(kwargs):
    with pytest.raises(ValueError):
        ImmParams(**kwargs)


def _one_bit_correlators(n, flip_at, cn0, t, seed):
    """Unit-amplitude correlators of a constant bit +1 at residual phase 0.4 + 0.01 k rad (10 rad/s); the sign of the
    correlators is flipped from index flip_at on (a glitch if only one sample, a bit change if all)."""
    rng = np.random.default_rng(seed)
    _, sig = iq_amplitude_and_noise_std(cn0, t)
    theta = 0.4 + 0.01 * np.arange(1, n + 1)
    sign = np.ones(n)
    sign[flip_at] = -1.0
    zi = sign * np.cos(theta) + sig * rng.standard_normal(n)
    zq = sign * np.sin(theta) + sig * rng.standard_normal(n)
    return theta, zi, zq


def test_sign_flipped_correlator_inside_a_bit_at_high_cn0_does_not_crash():
    # Regression: T = 1 ms, 60 dB-Hz, bit change forbidden inside the bit (p = 0). The
    # bit -1 mode's probability underflows to exactly 0; one sign-flipped correlator then favours that
    # mode by 2 (2 T C/N0) = 4000 in log-likelihood, and normalising 0 * 1 + 1 * exp(-4000) divided by zero.
    t, cn0, n = 0.001, 60.0, 60
    theta, zi, zq = _one_bit_correlators(n, [30], cn0, t, seed=5)
    f = ImmCarrierFilter(ImmParams())
    f.initialize(0.4, 10.0 / (2 * math.pi), 0.05, 0.1, mode_probability_plus=1.0)
    results = [f.update(zi[k], zq[k], cn0, t, 0.0, bit_transition_probability=0.0) for k in range(n)]
    for k, r in enumerate(results):
        assert all(math.isfinite(v) for v in (r.phase_rad, r.phase_std_rad, r.frequency_hz, r.frequency_std_hz))
        assert sum(r.mode_probabilities) == pytest.approx(1.0, abs=1e-12)
        assert 0.0 <= r.mode_probabilities[1] <= 1.0
        # The bit cannot change inside a bit: the flipped sample is an outlier of mode +1, whose EKF
        # residual along the phase direction is zero for an exact sign flip, so the phase stays on truth.
        assert r.data_bit == 1 and r.locked
        if k >= 10:  # after convergence; noise 1/sqrt(2 T C/N0) = 0.022 rad per look
            assert abs(r.phase_rad - theta[k]) < 0.02
    assert results[30].data_bit_probability > 1.0 - 1e-12


def test_bit_change_with_zero_transition_probability_stays_finite_and_consistent():
    # bit_transition_probability = 0 (a pilot-signal setting) on a signal whose bit does change: the model is
    # wrong, so the filter is not expected to track after the change (it loses the phase by several rad),
    # but it must neither crash nor return NaN or probabilities outside [0, 1] (nor divide by zero on the
    # first sample after the change).
    t, cn0, n = 0.001, 60.0, 400
    theta, zi, zq = _one_bit_correlators(n, slice(100, None), cn0, t, seed=6)
    f = ImmCarrierFilter(ImmParams(bit_transition_probability=0.0))
    f.initialize(0.4, 10.0 / (2 * math.pi), 0.05, 0.1, mode_probability_plus=0.5)
    r = f.process_batch(zi, zq, cn0, t, np.zeros(n))
    assert np.all(np.isfinite(r.phase_rad)) and np.all(np.isfinite(r.phase_std_rad))
    assert np.all((r.mode_probability_plus >= 0.0) & (r.mode_probability_plus <= 1.0))
    assert np.all(np.abs(r.phase_rad[10:100] - theta[10:100]) < 0.02)
    assert np.all(r.accepted) and r.mode_probability_plus[99] == 1.0
