"""Unit and oracle tests of gnss_common.clock_model (Zhao et al., eq. 6-9, Fig. 4)."""

import math

import numpy as np
import pytest

from gnss_common.clock_model import (
    OCXO,
    RUBIDIUM_LPFRS,
    RUBIDIUM_LPFRS_VIBRATION,
    TCXO,
    ClockHCoefficients,
    allan_deviation,
    allan_variance,
    allan_variance_from_phase,
    clock_process_noise_m,
    clock_process_noise_phase,
    clock_process_noise_s,
    fit_h_bound,
    phase_noise_psd_rad2_per_hz,
    simulate_clock,
    transition_matrix,
    vibration_h0_bound,
    vibration_phase_psd_rad2_per_hz,
)
from gnss_common.constants import GPS_L1_FREQUENCY_HZ, SPEED_OF_LIGHT_MPS

BALANCED = ClockHCoefficients(h0=1e-20, h_minus2=1e-20)  # white FM and RW FM cross near tau = 0.28 s


def test_presets_match_paper_values():
    assert RUBIDIUM_LPFRS.h0 == 5e-25 and RUBIDIUM_LPFRS.h_minus2 == 1e-30
    assert RUBIDIUM_LPFRS_VIBRATION.h0 == 2e-21 and RUBIDIUM_LPFRS_VIBRATION.h_minus2 == 1e-30
    assert RUBIDIUM_LPFRS.s_f == pytest.approx(2.5e-25)
    assert RUBIDIUM_LPFRS.s_g == pytest.approx(2 * math.pi**2 * 1e-30)
    # Section IX: the TCXO's S_f is "about 1e3" times the LPFRS's.
    assert 1e2 < TCXO.s_f / RUBIDIUM_LPFRS.s_f < 1e4
    assert OCXO.h0 > 0


@pytest.mark.parametrize("bad", [-1e-20, math.nan, math.inf])
def test_invalid_coefficients_raise(bad):
    with pytest.raises(ValueError):
        ClockHCoefficients(h0=bad, h_minus2=1e-30)


def test_allan_variance_closed_form_terms():
    tau = np.array([0.1, 1.0, 10.0])
    h = ClockHCoefficients(h0=2e-22, h_minus1=3e-23, h_minus2=4e-24)
    expected = 2e-22 / (2 * tau) + 2 * math.log(2) * 3e-23 + 2 * math.pi**2 / 3 * 4e-24 * tau
    np.testing.assert_allclose(allan_variance(h, tau), expected, rtol=1e-14)
    # White PM: E h2 / tau^2 with E = 3 f_h / (4 pi^2).
    hp = ClockHCoefficients(h0=0.0, h_minus2=0.0, h2=1e-24)
    np.testing.assert_allclose(
        allan_variance(hp, tau, f_high_hz=100.0), 3 * 100.0 / (4 * math.pi**2) * 1e-24 / tau**2, rtol=1e-14
    )
    np.testing.assert_allclose(allan_deviation(h, tau), np.sqrt(expected), rtol=1e-14)


def test_discrete_model_allan_variance_equals_h_formula_exactly():
    # Second difference of x over tau from the exact discrete model: var = 2 W11 + tau^2 W22 - 2 tau W12.
    for tau in (0.01, 0.3, 7.0):
        w = clock_process_noise_s(BALANCED, tau)
        var_d2 = 2 * w[0, 0] + tau**2 * w[1, 1] - 2 * tau * w[0, 1]
        assert var_d2 / (2 * tau**2) == pytest.approx(float(allan_variance(BALANCED, tau)), rel=1e-12)


def test_process_noise_composes_only_in_brown_hwang_form():
    t = 0.02
    f = transition_matrix(t)
    w = clock_process_noise_s(BALANCED, t)
    np.testing.assert_allclose(f @ w @ f.T + w, clock_process_noise_s(BALANCED, 2 * t), rtol=1e-12, atol=0.0)
    wz = clock_process_noise_s(BALANCED, t, form="zhao_eq8")
    assert not np.allclose(
        f @ wz @ f.T + wz, clock_process_noise_s(BALANCED, 2 * t, form="zhao_eq8"), rtol=1e-3, atol=0.0
    )
    assert wz[1, 1] == pytest.approx(BALANCED.s_f / t + 4 * BALANCED.s_g * t / 3)


def test_process_noise_units_and_validity():
    t = 1.0
    w = clock_process_noise_s(RUBIDIUM_LPFRS, t)
    np.testing.assert_allclose(clock_process_noise_m(RUBIDIUM_LPFRS, t), SPEED_OF_LIGHT_MPS**2 * w)
    np.testing.assert_allclose(
        clock_process_noise_phase(RUBIDIUM_LPFRS, t), (2 * math.pi * GPS_L1_FREQUENCY_HZ) ** 2 * w
    )
    assert np.all(np.linalg.eigvalsh(w) >= 0)
    for bad in (0.0, -1.0, math.nan):
        with pytest.raises(ValueError):
            clock_process_noise_s(RUBIDIUM_LPFRS, bad)
    with pytest.raises(ValueError):
        clock_process_noise_s(RUBIDIUM_LPFRS, 1.0, form="nope")


def test_simulated_clock_allan_variance_matches_formula():
    dt = 0.01
    x, _ = simulate_clock(BALANCED, dt, 2000, seed=3, n_realizations=200)
    for m in (1, 10, 30, 100):
        est = allan_variance_from_phase(x, dt, m)
        assert est == pytest.approx(float(allan_variance(BALANCED, m * dt)), rel=0.08)


def test_simulate_clock_is_seeded_and_starts_at_initial_state():
    a = simulate_clock(TCXO, 0.001, 100, seed=7, x0_s=1e-6, y0=2e-9)
    b = simulate_clock(TCXO, 0.001, 100, seed=7, x0_s=1e-6, y0=2e-9)
    np.testing.assert_array_equal(a[0], b[0])
    assert a[0][0] == 1e-6 and a[1][0] == 2e-9 and a[0].shape == (101,)


def test_phase_psd_power_laws():
    f = np.array([1.0, 10.0])
    s = phase_noise_psd_rad2_per_hz(RUBIDIUM_LPFRS, f)
    nu2 = GPS_L1_FREQUENCY_HZ**2
    np.testing.assert_allclose(s, nu2 * (5e-25 / f**2 + 1e-30 / f**4), rtol=1e-14)
    with pytest.raises(ValueError):
        phase_noise_psd_rad2_per_hz(RUBIDIUM_LPFRS, np.array([0.0]))


def test_fit_h_bound_recovers_generating_coefficients_and_bounds():
    tau = np.logspace(-2, 3, 12)
    spec = allan_deviation(RUBIDIUM_LPFRS, tau)
    fit = fit_h_bound(tau, spec)
    assert fit.h0 == pytest.approx(5e-25, rel=1e-6)
    assert fit.h_minus2 == pytest.approx(1e-30, rel=1e-6)
    rng = np.random.default_rng(0)
    bumpy = spec * np.exp(0.3 * rng.standard_normal(tau.size))
    fit2 = fit_h_bound(tau, bumpy)
    assert np.all(allan_deviation(fit2, tau) >= bumpy * (1 - 1e-7))
    with pytest.raises(ValueError):
        fit_h_bound(tau, -spec)


def test_vibration_term_and_paper_bound():
    f = np.array([10.0, 100.0])
    g = np.array([0.01, 0.05])
    s = vibration_phase_psd_rad2_per_hz(f, g, 2e-10)
    np.testing.assert_allclose(s, (2e-10 * GPS_L1_FREQUENCY_HZ) ** 2 * g / f**2)
    # With k_g = 2e-10 and a 0.05 g^2/Hz peak, the bound is the paper's h0 = 2e-21 (plus the static h0).
    hb = vibration_h0_bound(RUBIDIUM_LPFRS, g, 2e-10)
    assert hb.h0 == pytest.approx(2e-21 + 5e-25)
    assert hb.h_minus2 == RUBIDIUM_LPFRS.h_minus2
    # The white-FM phase PSD of the bound covers clock plus vibration at every frequency.
    assert np.all(phase_noise_psd_rad2_per_hz(hb, f) >= phase_noise_psd_rad2_per_hz(RUBIDIUM_LPFRS, f) + s)
