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
