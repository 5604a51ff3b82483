"""Tests of the KF / AKF / adaptive fading KF (Kang et al., eq. 11-22)."""

import numpy as np
import pytest

from rfi_monitor.tracking_filters import (
    MODE_AFKF,
    MODE_AKF,
    MODE_KF,
    TrackingFilterParams,
    kf_sweep_reset,
    run_tracking_filter,
)


def _reference_kf(z, p: TrackingFilterParams):
    """Textbook KF (numpy matrices, eq. 15-20, standard eq. 17 covariance update)."""
    F = np.array([[1.0, 1.0], [0.0, 1.0]])
    H = np.array([[1.0, 0.0]])
    Q = np.diag([p.process_std ** 2, p.process_rate_std ** 2])
    R = p.measurement_std ** 2
    x = np.array([p.initial_frequency, 0.0])
    P = np.diag([p.initial_frequency_std ** 2, p.initial_rate_std ** 2])
    out = []
    for k, zk in enumerate(z):
        if k > 0:
            x = F @ x
            P = F @ P @ F.T + Q
        if np.isfinite(zk):
            S = (H @ P @ H.T).item() + R
            K = (P @ H.T) / S
            x = x + (K * (zk - x[0])).ravel()
            P = (np.eye(2) - K @ H) @ P
        out.append(x[0])
    return np.array(out)


def test_kf_equals_reference_on_a_linear_ramp():
    rng = np.random.default_rng(0)
    p = TrackingFilterParams(mode=MODE_KF, measurement_std=0.05, process_std=1e-4, process_rate_std=1e-6)
    truth = 0.2 + 3e-4 * np.arange(400)
    z = truth + 0.05 * rng.standard_normal(400)
    z[[10, 50, 51]] = np.nan
    f, df, p11 = run_tracking_filter(z, p)
    np.testing.assert_allclose(f, _reference_kf(z, p), rtol=0, atol=1e-10)
    assert abs(df[-1] - 3e-4) < 3e-5


def _reference_afkf(z, p: TrackingFilterParams):
    """Textbook adaptive fading KF (eq. 11-14: alpha = max(1, C^/C), K = P H^T / (alpha C)), Joseph form."""
    F = np.array([[1.0, 1.0], [0.0, 1.0]])
    H = np.array([[1.0, 0.0]])
    Q = np.diag([p.process_std ** 2, p.process_rate_std ** 2])
    R = p.measurement_std ** 2
    x = np.array([p.initial_frequency, 0.0])
    P = np.diag([p.initial_frequency_std ** 2, p.initial_rate_std ** 2])
    window: list[float] = []
    out = []
    for k, zk in enumerate(z):
        if k > 0:
            x = F @ x
            P = F @ P @ F.T + Q
        if np.isfinite(zk):
            nu = zk - x[0]
            window = (window + [nu * nu])[-p.window:]
            C = (H @ P @ H.T).item() + R
            alpha = max(1.0, sum(window) / (p.window - 1) / C) if len(window) == p.window else 1.0
            K = (P @ H.T) / (alpha * C)
            x = x + (K * nu).ravel()
            A = np.eye(2) - K @ H
            P = A @ P @ A.T + R * (K @ K.T)
        out.append(x[0])
    return np.array(out)


def test_afkf_equals_reference():
    rng = np.random.default_rng(5)
    p = TrackingFilterParams(mode=MODE_AFKF, measurement_std=0.02, window=8)
    z = 0.25 + 2e-4 * np.arange(600) + 0.02 * rng.standard_normal(600)
    z[rng.random(600) < 0.1] += 0.2                 # outliers: alpha > 1 on many samples
    z[[5, 77, 78]] = np.nan
    f = run_tracking_filter(z, p)[0]
    np.testing.assert_allclose(f, _reference_afkf(z, p), rtol=0, atol=1e-10)


def test_afkf_equals_kf_when_innovations_are_consistent():
    # with the true noise much smaller than the assumed R, C^ < C so alpha = 1 (eq. 13)
    rng = np.random.default_rng(1)
    z = 0.3 + 1e-4 * rng.standard_normal(300)
    a = run_tracking_filter(z, TrackingFilterParams(mode=MODE_KF, measurement_std=0.05))[0]
    b = run_tracking_filter(z, TrackingFilterParams(mode=MODE_AFKF, measurement_std=0.05))[0]
    c = run_tracking_filter(z, TrackingFilterParams(mode=MODE_AKF, measurement_std=0.05))[0]
    np.testing.assert_allclose(a, b, atol=1e-12)
    np.testing.assert_allclose(a, c, atol=1e-12)


def test_afkf_resists_outliers_and_akf_follows_them():
    rng = np.random.default_rng(2)
    n = 3000
    z = 0.3 + 0.01 * rng.standard_normal(n)
    bursts = rng.random(n) < 0.05
    z[bursts] += rng.uniform(-0.25, 0.2, bursts.sum())   # heavy-tailed errors like Fig. 2
    errs = {}
    for mode in (MODE_KF, MODE_AKF, MODE_AFKF):
        f = run_tracking_filter(z, TrackingFilterParams(mode, measurement_std=0.01, process_std=1e-4))[0]
        errs[mode] = np.sqrt(np.mean((f[500:] - 0.3) ** 2))
    assert errs[MODE_AFKF] < errs[MODE_KF] < errs[MODE_AKF]


def test_akf_stays_finite_with_small_r():
    rng = np.random.default_rng(3)
    z = rng.uniform(0, 0.5, 5000)
    f, df, p11 = run_tracking_filter(z, TrackingFilterParams(mode=MODE_AKF, measurement_std=0.01))
    assert np.all(np.isfinite(f)) and np.all(p11 >= 0)


def test_sweep_reset_restores_the_saw_tooth():
    # noise-free saw-tooth, known period: with resets the filter follows every sweep (eq. 21-22)
    T = 200
    n = 20 * T
    k = np.arange(n)
    truth = 0.18 + 6e-4 * (k % T)
    reset = (k % T == 0) & (k > 0)
    p = TrackingFilterParams(mode=MODE_AFKF, measurement_std=0.02)
    with_reset = run_tracking_filter(truth, p, reset)[0]
    without = run_tracking_filter(truth, p)[0]
    e_r = np.sqrt(np.mean((with_reset[10 * T:] - truth[10 * T:]) ** 2))
    e_n = np.sqrt(np.mean((without[10 * T:] - truth[10 * T:]) ** 2))
    assert e_r < 1e-3 < e_n


def test_reset_formula_eq21():
    # after converging on a ramp, f0 = f_{T-1} - (T-1) df equals the ramp start
    T = 300
    z = 0.2 + 5e-4 * np.arange(T)
    z = np.concatenate([z, z[:2]])
    reset = np.zeros(z.size, bool)
    reset[T] = True
    f, df, p11 = run_tracking_filter(z, TrackingFilterParams(mode=MODE_KF, measurement_std=0.01), reset)
    assert f[T] == pytest.approx(0.2, abs=2e-3)


@pytest.mark.parametrize("kw", [dict(mode=7), dict(measurement_std=0.0), dict(window=1),
                                dict(process_std=-1.0), dict(initial_rate_std=0.0)])
def test_invalid_params(kw):
    with pytest.raises(ValueError):
        TrackingFilterParams(**kw)


def test_complex_wrap():
    # a signed frequency crossing +0.5 -> -0.5 is followed without a jump
    k = np.arange(2000)
    truth = (0.45 + 1e-4 * k + 0.5) % 1.0 - 0.5
    f = run_tracking_filter(truth, TrackingFilterParams(mode=MODE_KF, measurement_std=0.01,
                                                        initial_frequency=0.45), signed=True)[0]
    err = (f - truth + 0.5) % 1.0 - 0.5
    assert np.max(np.abs(err[200:])) < 1e-3


def test_sweep_reset_eq21_22_and_its_exact_covariance():
    f, df, m = 0.31, 6.9e-4, 194.0
    p = np.array([[4e-6, 2e-8], [2e-8, 3e-10]])
    f0, p11, p12 = kf_sweep_reset(f, df, p[0, 0], p[0, 1], p[1, 1], m, False)
    assert f0 == pytest.approx(f - m * df)
    assert (p11, p12) == (pytest.approx(p[0, 0] + m * m * p[1, 1]), 0.0)          # eq. 22
    # exact: A P A^T with A = [[1, -m], [0, 1]]
    a = np.array([[1.0, -m], [0.0, 1.0]])
    pe = a @ p @ a.T
    f0x, p11x, p12x = kf_sweep_reset(f, df, p[0, 0], p[0, 1], p[1, 1], m, True)
    assert f0x == f0
    assert p11x == pytest.approx(pe[0, 0]) and p12x == pytest.approx(pe[0, 1])
    # positive f~, df~ correlation (a ramp tracker's) makes f0~ less uncertain than eq. 22 says
    assert p11x < p11
