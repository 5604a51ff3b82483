"""Tests of the LPD + AR sweep-period estimator (Kang et al., eq. 23-27)."""

import numpy as np
import pytest

from rfi_monitor.sweep_period import SweepPeriodParams, estimate_sweep_period


@pytest.mark.parametrize("T", [195.0, 382.3, 1000.0])
def test_period_of_a_clean_saw_tooth_within_one_percent(T):
    rng = np.random.default_rng(0)
    k = np.arange(40_000)
    bw = 0.134
    z = 0.1832 + bw * np.mod(k / T, 1.0) + 0.01 * rng.standard_normal(k.size)
    zg, zar, starts, per, locked = estimate_sweep_period(z)
    assert locked
    assert per == pytest.approx(T, rel=0.01)
    # detected starts (group delay removed) fall near true starts
    true = np.ceil(np.arange(1, k.size / T) * T)
    err = np.array([np.min(np.abs(true - s)) for s in starts])
    assert np.median(err) <= 3


def test_down_chirp_with_sign():
    k = np.arange(30_000)
    T = 250.0
    z = 0.3 - 0.1 * np.mod(k / T, 1.0)
    *_, per, locked = estimate_sweep_period(z, sign=-1.0)
    assert locked and per == pytest.approx(T, rel=0.01)


def test_no_lock_on_noise():
    rng = np.random.default_rng(1)
    z = rng.uniform(0.0, 0.5, 60_000)
    *_, locked = estimate_sweep_period(z)
    assert not locked


def test_no_lock_on_constant_tone():
    rng = np.random.default_rng(2)
    z = 0.27 + 0.02 * rng.standard_normal(60_000)
    zg, zar, starts, per, locked = estimate_sweep_period(z)
    assert not locked and np.isnan(per)


def test_decimation_keeps_accuracy():
    k = np.arange(40_000)
    T = 300.7
    z = 0.2 + 0.1 * np.mod(k / T, 1.0)
    for d in (1, 2, 4):
        *_, per, locked = estimate_sweep_period(z, SweepPeriodParams(decimation=d))
        assert locked and per == pytest.approx(T, rel=0.01)


@pytest.mark.parametrize("kw", [dict(forgetting=1.0), dict(beta=0.0), dict(decimation=0), dict(tolerance=0.6),
                                dict(ar_transition=1.0)])
def test_invalid(kw):
    with pytest.raises(ValueError):
        SweepPeriodParams(**kw)


def test_bad_input():
    with pytest.raises(ValueError):
        estimate_sweep_period(np.array([0.1, np.nan, 0.2]))


def test_low_rank_ar_step_equals_the_full_matrix_filter():
    # eq. 24-27 with A = 0.2 I: the low-rank covariance drops terms of relative weight a^(2(K+1))
    from rfi_monitor.sweep_period import (
        AR_ORDER,
        _ar_step_full,
        _ar_step_low_rank,
        ar_low_rank_terms,
        initial_ar_covariance,
    )
    k = ar_low_rank_terms(0.2)
    assert k == 4 and 0.04 ** (k + 1) <= 1e-6
    assert ar_low_rank_terms(0.9) == -1            # slow decay: full matrix
    rng = np.random.default_rng(3)
    v = np.convolve(rng.standard_normal(3000), [1.0, 0.6, -0.3], mode="same")
    state = [(np.zeros(AR_ORDER), initial_ar_covariance(), np.zeros(AR_ORDER)) for _ in range(2)]
    za = np.array([_ar_step_full(x, *state[0], 0.2, 1.0, 1.0) for x in v])
    zb = np.array([_ar_step_low_rank(x, *state[1], 0.2, 1.0, 1.0, k) for x in v])
    np.testing.assert_allclose(zb, za, rtol=0, atol=1e-6 * np.max(np.abs(za)))
    np.testing.assert_allclose(state[1][0], state[0][0], atol=1e-6)


def test_paper_decimation_one_locks():
    k = np.arange(20_000)
    T = 195.3
    z = 0.1832 + 0.134 * np.mod(k / T, 1.0)
    *_, per, locked = estimate_sweep_period(z, SweepPeriodParams(decimation=1))
    assert locked and per == pytest.approx(T, rel=0.005)


def test_specialised_k4_ar_step_equals_the_generic_low_rank_step():
    # the unrolled K = 4 step (zAR = pred + (s - R) innov) is the same arithmetic as the generic loop
    from rfi_monitor.sweep_period import (
        AR_K4,
        AR_LR_BASE,
        AR_LR_WROW,
        AR_ORDER,
        _ar_step_k4,
        _ar_step_low_rank,
        ar_step,
        initial_ar_covariance,
    )
    rng = np.random.default_rng(5)
    v = np.convolve(rng.standard_normal(2000), [1.0, -0.7, 0.2], mode="same") * 0.01
    state = [(np.zeros(AR_ORDER), initial_ar_covariance(), np.zeros(AR_ORDER)) for _ in range(3)]
    za = np.array([_ar_step_low_rank(x, *state[0], 0.2, 1.0, 1.0, AR_K4) for x in v])
    zb = np.array([_ar_step_k4(x, *state[1], 0.2, 1.0, 1.0) for x in v])
    zc = np.array([ar_step(x, *state[2], 0.2, 1.0, 1.0, AR_K4) for x in v])
    scale = np.max(np.abs(za))
    np.testing.assert_allclose(zb, za, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(zc, zb, rtol=0, atol=1e-12 * scale)  # ar_step dispatches to the K = 4 form
    # (not bit for bit: the two are compiled separately with fastmath contractions, which a CPU may order differently)
    np.testing.assert_allclose(state[1][0], state[0][0], rtol=0, atol=1e-12)
    lr = slice(AR_LR_BASE, AR_LR_WROW + 1)          # the low-rank terms, weights, d, ring position
    np.testing.assert_allclose(state[1][1][lr], state[0][1][lr], rtol=0, atol=1e-12)
