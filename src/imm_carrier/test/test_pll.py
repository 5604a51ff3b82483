"""Tests of the Costas PLL baseline (Zhao et al., Section VII; Kaplan & Hegarty loop formulas)."""

import math

import numpy as np
import pytest

from imm_carrier.measurement_model import iq_amplitude_and_noise_std
from imm_carrier.pll import CostasPll, PllParams, bandwidth_schedule_hz


def test_bandwidth_schedule_runs_from_15_to_1_hz_monotonically():
    t = np.linspace(0, 100, 2001)
    b = bandwidth_schedule_hz(t)
    assert b[0] == pytest.approx(15.0)
    assert bandwidth_schedule_hz(70.0) == pytest.approx(1.0)
    assert np.all(b[t >= 70] == pytest.approx(1.0))
    assert np.all(np.diff(b[t <= 70]) < 0)


def _const_bw(bn):
    return PllParams(start_bandwidth_hz=bn, end_bandwidth_hz=bn)


def test_third_order_loop_tracks_a_frequency_ramp_without_steady_error():
    t_int, n = 0.001, 20000
    tk = t_int * np.arange(1, n + 1)
    truth = 2 * math.pi * (2.0 * tk + 0.5 * 0.5 * tk**2)  # 2 Hz offset, 0.5 Hz/s ramp
    bits = np.where(np.random.default_rng(0).random(n) < 0.5, 1.0, -1.0)
    pll = CostasPll(_const_bw(10.0))
    pll.initialize(0.0, 0.0)
    r = pll.process_batch(bits * np.cos(truth), bits * np.sin(truth), 60.0, t_int, np.zeros(n))
    assert np.max(np.abs(r.phase_rad[-1000:] - truth[-1000:])) < 1e-3
    assert r.frequency_hz[-1] == pytest.approx(2.0 + 0.5 * tk[-1], abs=1e-3)
    assert np.all(r.locked[-1000:])


def test_costas_discriminator_ignores_data_bits():
    t_int, n = 0.02, 500
    rng = np.random.default_rng(1)
    theta = 0.3 + 0.01 * np.arange(n)
    bits = np.where(rng.random(n) < 0.5, 1.0, -1.0)
    out = []
    for b in (np.ones(n), bits):
        pll = CostasPll(_const_bw(5.0))
        pll.initialize(0.2, 0.0)
        out.append(
            pll.process_batch(b * np.cos(theta), b * np.sin(theta), 45.0, t_int, np.zeros(n)).phase_rad
        )
    np.testing.assert_allclose(out[0], out[1], atol=1e-12)


def test_phase_jitter_matches_the_costas_thermal_noise_formula():
    # sigma^2 = B_n / (C/N0) (1 + 1 / (2 T C/N0)) (Kaplan & Hegarty, PLL thermal noise jitter).
    t_int, n, bn, cn0 = 0.001, 60000, 5.0, 45.0
    amp, sig = iq_amplitude_and_noise_std(cn0, t_int)
    rng = np.random.default_rng(3)
    pll = CostasPll(_const_bw(bn))
    pll.initialize(0.0, 0.0)
    r = pll.process_batch(
        amp + sig * rng.standard_normal(n), sig * rng.standard_normal(n), cn0, t_int, np.zeros(n)
    )
    c = 10 ** (cn0 / 10)
    expected = math.sqrt(bn / c * (1 + 1 / (2 * t_int * c)))
    nco = r.phase_rad - r.discriminator_rad  # the NCO phase (the loop's estimate before the update)
    assert np.std(nco[5000:]) == pytest.approx(expected, rel=0.2)


def test_pll_rejects_bad_inputs():
    pll = CostasPll(PllParams())
    with pytest.raises(ValueError):
        pll.process_batch(np.zeros(2), np.zeros(2), 40.0, 0.02, np.zeros(2))
    pll.initialize(0.0, 0.0)
    r = pll.process_batch(
        np.array([1.0, math.nan, 1.0]), np.zeros(3), np.array([40.0, 40.0, -5.0]), 0.02, np.zeros(3)
    )
    assert r.counters["rejected_cn0"] == 1 and r.counters["coasted_nonfinite_iq"] == 1
    assert not r.locked[2] and math.isnan(r.phase_rad[2])
    with pytest.raises(ValueError):
        pll.update(1.0, 0.0, 40.0, 0.0, 0.0)
    with pytest.raises(ValueError):
        PllParams(start_bandwidth_hz=1.0, end_bandwidth_hz=2.0)


def test_scalar_update_equals_process_batch():
    # update() is a compiled scalar step; it must give the batch loop's numbers (same arithmetic), through
    # the bandwidth tightening, with coasting (NaN) samples and a unit-noise lock indicator.
    rng = np.random.default_rng(7)
    n, t_int = 400, 0.02
    params = PllParams(tightening_duration_s=5.0, iq_scaling="unit_noise")
    cn0 = rng.uniform(25.0, 45.0, n)
    dphi = rng.uniform(-3, 3, n)
    theta = 0.3 + np.cumsum(dphi) + 0.01 * np.arange(n)
    amp = np.sqrt(2 * t_int * 10 ** (cn0 / 10))
    zi = amp * np.cos(theta) + rng.standard_normal(n)
    zq = amp * np.sin(theta) + rng.standard_normal(n)
    zi[[50, 51, 300]] = math.nan
    a, b = CostasPll(params), CostasPll(params)
    for p in (a, b):
        p.initialize(0.25, 0.1, satellite_phase_rad=0.05)
    batch = a.process_batch(zi, zq, cn0, t_int, dphi)
    steps = [b.update(zi[k], zq[k], cn0[k], t_int, dphi[k]) for k in range(n)]
    np.testing.assert_allclose([s.phase_rad for s in steps], batch.phase_rad, rtol=0, atol=1e-12)
    np.testing.assert_allclose([s.frequency_hz for s in steps], batch.frequency_hz, rtol=0, atol=1e-12)
    np.testing.assert_allclose([s.bandwidth_hz for s in steps], batch.bandwidth_hz, rtol=1e-12)
    np.testing.assert_allclose([s.lock_metric for s in steps], batch.lock_metric, rtol=0, atol=1e-12)
    assert [s.locked for s in steps] == list(batch.locked)
    assert steps[-1].bandwidth_hz == pytest.approx(1.0) and steps[0].bandwidth_hz == pytest.approx(15.0)
