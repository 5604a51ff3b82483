"""Tests of the block-level periodicity detector and the sweep-start step fit (ours)."""

import math

import numpy as np
import pytest

from rfi_monitor.if_measurement import acos_fast
from rfi_monitor.sweep_analysis import SweepAnalysisParams, analyse
from rfi_monitor.sweep_period import SweepPeriodParams, estimate_sweep_period
from rfi_monitor.tracker_state import Z_RING
from rfi_monitor.tracker_steps import STEP_FALSE_ALARM, step_fit, step_threshold


def _decimated_saw(T, s, n_dec, dec, sign=1.0, noise=0.0, seed=0):
    """Decimated saw-tooth track: start at sample s, period T samples, mean of each D samples."""
    k = np.arange(n_dec * dec)
    z = 0.2 + sign * 0.13 * np.mod((k - s) / T, 1.0)
    z = z + noise * np.random.default_rng(seed).standard_normal(z.size)
    return z.reshape(n_dec, dec).mean(axis=1)


@pytest.mark.parametrize("T,sign", [(19.5, 1.0), (195.3, 1.0), (195.3, -1.0), (1949.0, 1.0)])
def test_period_phase_and_direction_of_a_saw_tooth(T, sign):
    dec = 4
    s_true = 37.25
    w = _decimated_saw(T, s_true, 4096, dec, sign, noise=0.05)
    a = analyse(w, dec, 0.5 * (dec - 1), 0, SweepAnalysisParams())
    assert a.periodic and a.strength > 0.5
    assert a.period_samples == pytest.approx(T, rel=2e-3)
    assert math.copysign(1.0, a.jump) == sign
    # the start lattice passes within 2 % of a period of the true start (a down-chirp's start is
    # its upper edge: the same lattice)
    u = (a.start_index - s_true) / T
    assert abs(u - round(u)) * T <= 0.02 * T + 1.0
    assert a.harmonic_ratio == pytest.approx(0.5, abs=0.1)


@pytest.mark.parametrize("seed", range(3))
def test_white_and_correlated_noise_are_not_periodic(seed):
    rng = np.random.default_rng(seed)
    white = rng.uniform(0.0, 0.5, 4096)
    low_pass = np.convolve(rng.standard_normal(4200), np.ones(16) / 16, mode="valid")[:4096]
    for w in (white, low_pass, np.full(4096, 0.3) + 1e-3 * rng.standard_normal(4096)):
        assert not analyse(w, 4, 0.0, 0, SweepAnalysisParams()).periodic


def test_triangle_sweep_is_periodic_without_second_harmonic():
    k = np.arange(4096 * 4)
    T = 400.0
    u = np.mod(k / T, 1.0)
    z = 0.2 + 0.1 * np.minimum(u, 1 - u)
    a = analyse(z.reshape(-1, 4).mean(axis=1), 4, 1.5, 0, SweepAnalysisParams())
    assert a.periodic and a.period_samples == pytest.approx(T, rel=2e-3)
    assert a.harmonic_ratio < 0.05


def test_short_or_bad_window_gives_no_result():
    assert not analyse(np.zeros(100), 4, 0.0, 0, SweepAnalysisParams()).periodic
    w = np.full(4096, 0.2)
    w[5] = np.nan
    assert not analyse(w, 4, 0.0, 0, SweepAnalysisParams()).periodic
    with pytest.raises(ValueError):
        SweepAnalysisParams(min_strength=0.0)


@pytest.mark.parametrize("start", [100, 117])
def test_step_fit_finds_the_start_of_a_noise_free_sweep(start):
    T, df = 195.0, 6.9e-4
    ring = np.zeros(Z_RING)
    m = np.arange(start - 30, start + 30)
    z = np.where(m >= start, 0.18 + df * (m - start), 0.18 + df * (m - start + T))
    ring[m & (Z_RING - 1)] = z
    s_hat, _, sig = step_fit(ring, start + 2, 20, df, T, False)
    assert s_hat == start and sig > step_threshold(40)
    # down-chirp: negative df, the track jumps up at the start
    z = np.where(m >= start, 0.32 - df * (m - start), 0.32 - df * (m - start + T))
    ring[m & (Z_RING - 1)] = z
    s_hat, _, sig = step_fit(ring, start - 3, 20, -df, T, False)
    assert s_hat == start and sig > step_threshold(40)
    # the same track read as an up-chirp: a step of the wrong sign is no sweep start
    assert step_fit(ring, start - 3, 20, df, T, False)[2] == 0.0


def test_step_fit_significance_on_noise_and_on_a_noisy_start():
    # Without a sweep start the significance exceeds step_threshold in about STEP_FALSE_ALARM of
    # the windows; a start at J/N ~ 11 dB (measurement std 0.055 cycles/sample) is found.
    rng = np.random.default_rng(5)
    T, df, w = 195.0, 6.9e-4, 24
    ring = np.zeros(Z_RING)
    m = np.arange(100 - w, 100 + w)
    false_alarms = 0
    for _ in range(2000):
        ring[m & (Z_RING - 1)] = 0.25 + df * (m - 100) + rng.normal(0.0, 0.055, m.size)
        false_alarms += step_fit(ring, 100, w, df, T, False)[2] >= step_threshold(2 * w)
    assert false_alarms / 2000 <= 2 * STEP_FALSE_ALARM
    found = 0
    for _ in range(200):
        z = np.where(m >= 100, 0.18 + df * (m - 100), 0.18 + df * (m - 100 + T))
        ring[m & (Z_RING - 1)] = z + rng.normal(0.0, 0.055, m.size)
        s_hat, _, sig = step_fit(ring, 100, w, df, T, False)
        found += abs(s_hat - 100) <= 1 and sig >= step_threshold(2 * w)
    assert found >= 180


def test_acos_fast_matches_libm():
    x = np.linspace(-1.0, 1.0, 20001)
    err = np.array([acos_fast(v) for v in x]) - np.arccos(x)
    assert np.max(np.abs(err)) < 3e-8


def test_lattice_voting_survives_false_peaks_between_true_ones():
    # a saw-tooth with false steps at random times: the lattice voting still finds the period
    rng = np.random.default_rng(4)
    T = 300.7
    k = np.arange(60_000)
    z = 0.2 + 0.1 * np.mod(k / T, 1.0) + 0.005 * rng.standard_normal(k.size)
    for i in rng.integers(0, k.size - 40, int(k.size / T / 3)):   # false steps, one per ~3 sweeps
        z[i:i + 40] -= 0.1
    *_, per, locked = estimate_sweep_period(z, SweepPeriodParams(lattice_voting=True))
    assert locked and per == pytest.approx(T, rel=0.01)


def test_fourier_coefficients_equal_the_direct_sum():
    from rfi_monitor.sweep_analysis import _fourier_12
    x = np.random.default_rng(2).standard_normal(4096)
    for t_dec in (3.3, 48.8, 1000.0):
        e1 = np.exp((-2j * np.pi / t_dec) * np.arange(x.size))
        c1, c2 = _fourier_12(x, t_dec)
        assert abs(c1 - np.sum(x * e1)) <= 1e-11 * np.sum(np.abs(x))
        assert abs(c2 - np.sum(x * e1 * e1)) <= 1e-11 * np.sum(np.abs(x))


def _best_lag_reference(r, lo, lmax):
    """Step 3 written with numpy (the vectorised form the compiled _best_lag replaced)."""
    seg = r[lo:lmax + 1]
    ismax = np.zeros(seg.size, dtype=bool)
    ismax[1:-1] = (seg[1:-1] >= seg[:-2]) & (seg[1:-1] >= seg[2:])
    if not ismax.any():
        return -1
    cand = np.flatnonzero(ismax) + lo
    trough = np.minimum.accumulate(r[1:])
    st_c = r[cand] - trough[cand - 1]
    kbest = int(cand[np.argmax(st_c)])
    best = float(np.max(st_c))
    for q in range(kbest // lo, 1, -1):
        cen = kbest / q
        k_lo, k_hi = max(1, math.floor(cen - 1.0)), min(r.size - 2, math.ceil(cen + 1.0))
        if k_hi < k_lo:
            continue
        ks = k_lo + int(np.argmax(r[k_lo:min(k_lo + 4, k_hi + 1)]))
        if ks >= lo and r[ks] >= r[ks - 1] and r[ks] >= r[ks + 1] and r[ks] - trough[ks - 1] >= 0.5 * best:
            return ks
    return kbest


@pytest.mark.parametrize("seed", range(6))
def test_best_lag_equals_the_numpy_reference(seed):
    from rfi_monitor.sweep_analysis import _best_lag
    rng = np.random.default_rng(seed)
    n = 2048
    T = rng.uniform(5.0, 300.0)
    t = np.arange(n)
    z = (t / T) % 1.0 + rng.uniform(0.0, 2.0) * rng.standard_normal(n)
    x = z - z.mean()
    r = np.correlate(x, x, mode="full")[n - 1:]
    r = r / r[0]
    k, trough = _best_lag(r, 3, n // 4)
    assert k == _best_lag_reference(r, 3, n // 4)
    np.testing.assert_array_equal(trough, np.minimum.accumulate(r[1:]))
