"""Tests of the cycle-slip counter and of the covariance analysis (Zhao et al., Section IV, Fig. 9)."""

import math

import numpy as np
import pytest

from gnss_common.clock_model import RUBIDIUM_LPFRS, TCXO
from imm_carrier.covariance_analysis import covariance_analysis, steady_state_covariance
from imm_carrier.cycle_slips import count_cycle_slips


def test_injected_slips_are_counted_exactly():
    rng = np.random.default_rng(0)
    n = 2000
    truth = np.cumsum(0.01 * rng.standard_normal(n))
    est = truth + 1.3 + 0.1 * rng.standard_normal(n)  # constant offset, noise well below the hysteresis
    est[500:] += math.pi
    est[1200:] -= 2 * math.pi
    est[1500:] += 3 * math.pi
    r = count_cycle_slips(est, truth, slip_period_rad=math.pi)
    assert r.count == 1 + 2 + 3
    assert list(r.slip_indices) == [500, 1200, 1500]
    assert np.std(r.phase_error_rad) < 0.15
    # In full cycles, half-cycle jumps stay inside the hysteresis band; whole cycles count.
    est2 = truth + 1.3 + 0.1 * rng.standard_normal(n)
    est2[500:] += 2 * math.pi
    est2[1200:] -= 4 * math.pi
    full = count_cycle_slips(est2, truth, slip_period_rad=2 * math.pi)
    assert full.count == 3 and list(full.slip_indices) == [500, 1200]


def test_noise_near_half_period_is_not_counted_and_nan_is_skipped():
    n = 1000
    truth = np.zeros(n)
    est = np.where(np.arange(n) % 2 == 0, 0.6, -0.6) * math.pi  # 0.6 periods: inside the hysteresis band
    est[:50] = 0.0
    est[700] = math.nan
    assert count_cycle_slips(est, truth, reference_samples=50).count == 0
    with pytest.raises(ValueError):
        count_cycle_slips(np.zeros(3), np.zeros(4))


def test_riccati_converges_to_the_dare_solution():
    p0 = np.diag([0.5**2, (2 * math.pi * 5.0) ** 2])
    hist = covariance_analysis(TCXO, 40.0, 0.02, 3000, p0)
    p_bar, p_hat = steady_state_covariance(TCXO, 40.0, 0.02)
    np.testing.assert_allclose(hist.prior[-1], p_bar, rtol=1e-6)
    np.testing.assert_allclose(hist.posterior[-1], p_hat, rtol=1e-6)
    assert np.all(hist.prior[:, 1, 1] >= hist.posterior[:, 1, 1])


def test_rubidium_covariance_drops_fast_at_51_dbhz_and_1_ms():
    # Fig. 9: with the rubidium model, the propagation adds little (P-bar ~ P-hat of the previous step)
    # and the frequency uncertainty falls by two orders of magnitude within 1 s.
    p0 = np.diag([0.1**2, (2 * math.pi * 0.1) ** 2])
    hist = covariance_analysis(RUBIDIUM_LPFRS, 51.0, 0.001, 1000, p0)
    assert hist.posterior_frequency_std_hz[-1] < 0.02 * 0.1
    growth = hist.prior[1:, 1, 1] / hist.posterior[:-1, 1, 1]
    assert np.all(growth[100:] < 1.001)
