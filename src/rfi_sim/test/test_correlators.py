"""Tests of the correlator simulator (Zhao et al., eq. 2-5, Section VI-A)."""

import math

import numpy as np
import pytest

from gnss_common.clock_model import ClockHCoefficients, allan_variance, allan_variance_from_phase
from rfi_sim.correlators import CorrelatorScenario, simulate_correlators

TWO_PI = 2 * math.pi


def test_default_scenario_is_the_papers():
    sc = CorrelatorScenario()
    sim = simulate_correlators(sc, seed=0)
    assert [s.svid for s in sim.satellites] == [1, 30, 7, 11, 28]
    assert sc.n_steps == 12000
    for s, drop in zip(sim.satellites, sc.cn0_drops_db, strict=True):
        assert s.in_phase.shape == (12000,)
        assert np.all(s.cn0_dbhz[s.stamps_ns < 120e9] == 51.0)
        assert np.all(s.cn0_dbhz[s.stamps_ns >= 120e9] == 51.0 - drop)
    # One clock for all satellites: phases differ only by a constant.
    d = sim.satellites[0].truth_phase_rad - sim.satellites[3].truth_phase_rad
    assert np.ptp(d) < 1e-9


def test_simulated_clock_allan_variance_matches_the_h_formula():
    clock = ClockHCoefficients(h0=1e-20, h_minus2=1e-20)
    sc = CorrelatorScenario(
        svids=(1,), cn0_drops_db=(0.0,), duration_s=400.0, integration_time_s=0.01, clock=clock
    )
    sim = simulate_correlators(sc, seed=2)
    x = sim.clock_phase_rad / (TWO_PI * sc.carrier_hz)
    for m in (1, 10, 100):
        est = allan_variance_from_phase(x, sc.integration_time_s, m)
        assert est == pytest.approx(float(allan_variance(clock, m * sc.integration_time_s)), rel=0.1)
    # frequency truth is the derivative of the phase truth on average
    y = sim.clock_frequency_hz / sc.carrier_hz
    dx = np.diff(x)
    assert np.corrcoef(dx, y[:-1])[0, 1] > 0.9


def test_noise_amplitude_bits_and_predicted_phase():
    sc = CorrelatorScenario(
        svids=(4, 9), cn0_drops_db=(0.0, 20.0), duration_s=60.0, onset_s=30.0, integration_time_s=0.001
    )
    sim = simulate_correlators(sc, seed=5)
    sat = sim.by_svid(9)
    theta = np.cumsum(sat.predicted_phase_change_rad) + sat.truth_phase_rad
    # Remove the signal: the residual is N(0, sigma_v^2) with sigma_v = 1 / sqrt(2 T C/N0) (eq. 5).
    ri = sat.in_phase - sat.truth_bits * np.cos(theta)
    late = sat.stamps_ns > 31e9
    expected = 1 / math.sqrt(2 * 0.001 * 10 ** (31.0 / 10))
    assert np.std(ri[late]) == pytest.approx(expected, rel=0.03)
    assert np.allclose(sat.noise_std[late], expected)
    # 50 bit/s data: constant over each 20 ms, +-1.
    bits = sat.truth_bits.reshape(-1, 20)
    assert np.all(bits == bits[:, :1]) and set(np.unique(bits)) == {-1, 1}
    # The receiver's predicted phase change is that of a linear Doppler profile.
    second = np.diff(sat.predicted_phase_change_rad)
    assert np.ptp(second) < 1e-6
    assert abs(sat.predicted_phase_change_rad[0] / (TWO_PI * 0.001)) <= sc.doppler_range_hz + 1


def test_seeded_and_unit_noise_scaling():
    sc = CorrelatorScenario(duration_s=2.0)
    a = simulate_correlators(sc, seed=9)
    b = simulate_correlators(sc, seed=9)
    np.testing.assert_array_equal(a.satellites[2].in_phase, b.satellites[2].in_phase)
    c = simulate_correlators(CorrelatorScenario(duration_s=2.0, iq_scaling="unit_noise"), seed=9)
    ratio = c.satellites[2].amplitude / a.satellites[2].amplitude
    np.testing.assert_allclose(c.satellites[2].in_phase, a.satellites[2].in_phase * ratio, rtol=1e-12)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"integration_time_s": 0.003},
        {"integration_time_s": 0.04},
        {"svids": (1, 2), "cn0_drops_db": (0.0,)},
        {"nominal_cn0_dbhz": 80.0},
        {"duration_s": -1.0},
        {"svids": (0,), "cn0_drops_db": (0.0,)},
    ],
)
def test_invalid_scenarios_raise(kwargs):
    with pytest.raises(ValueError):
        CorrelatorScenario(**kwargs)
