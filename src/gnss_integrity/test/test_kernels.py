"""Oracle tests of ``gnss_integrity.kernels``: the running median against ``np.median``, the compiled
chi-square forms and clock Kalman step against their numpy forms."""

import math

import numpy as np
import pytest

from gnss_integrity import kernels

RNG_SEED = 25


@pytest.fixture
def rng():
    return np.random.default_rng(RNG_SEED)


def test_running_median_equals_numpy_median_over_a_sliding_window(rng):
    median = kernels.RunningMedian(maxlen=17)
    values = rng.normal(0, 5, 400).round(1)  # rounding makes ties, which a sorted list must keep
    held: list[float] = []
    assert math.isnan(median.median())
    for v in values:
        median.append(v)
        held = (held + [float(v)])[-17:]
        assert len(median) == len(held)
        assert median.median() == float(np.median(held))


def test_running_median_is_nan_while_a_nan_is_held():
    median = kernels.RunningMedian(maxlen=3)
    for v in (1.0, math.nan, 2.0):
        median.append(v)
    assert math.isnan(median.median())
    median.append(3.0)
    median.append(4.0)  # the NaN has left the window
    assert median.median() == 3.0


def test_chi2_forms_equal_numpy(rng):
    k = 5
    u = rng.normal(0, 1, (k, 3))
    axes = rng.uniform(0.1, 2, 3)
    own = rng.uniform(0.01, 0.5, k)
    d = rng.normal(0, 1, k)
    c = u @ np.diag(axes) @ u.T + np.diag(own)
    want = float(d @ np.linalg.solve(c, d))
    assert kernels.chi2_form(u, axes, own, d) == pytest.approx(want, rel=1e-12)
    a = c + np.eye(k)
    assert kernels.quad_solve(a, d) == pytest.approx(float(d @ np.linalg.solve(a, d)), rel=1e-12)
    lags = 4
    dd = rng.normal(0, 1, (lags, k))
    oo = rng.uniform(0.01, 0.5, (lags, k))
    g, n_eff, lag_s = rng.uniform(0.5, 2, lags), rng.uniform(1, 50, lags), rng.uniform(5, 300, lags)
    cov_axes, white_axes, lag_var = rng.uniform(0.1, 1, 3), rng.uniform(0.1, 1, 3), 1e-3
    got = kernels.lagged_chi2(u, dd, oo, g, n_eff, lag_s, cov_axes, white_axes, lag_var)
    for m in range(lags):
        ax = g[m] * cov_axes + (white_axes / n_eff[m] + lag_var * lag_s[m])
        cm = u @ np.diag(ax) @ u.T + np.diag(oo[m])
        assert got[m] == pytest.approx(float(dd[m] @ np.linalg.solve(cm, dd[m])), rel=1e-12)


def test_clock_kalman_step_equals_the_textbook_update_and_realigns_millisecond_steps():
    dt = 1.0
    phi = np.array([[1.0, dt], [0.0, 1.0]])
    q = np.diag([0.5, 0.01])
    r = np.diag([4.0, 0.04])
    x = np.array([100.0, 2.0])
    p = np.diag([9.0, 0.25])
    z = np.array([103.0, 2.1])
    xn, pn, nis, steps = kernels.clock_kalman_step(x, p, phi, q, r, z, 299792.458, 1000.0)
    xp, pp = phi @ x, phi @ p @ phi.T + q
    s = pp + r
    nu = z - xp
    gain = pp @ np.linalg.inv(s)
    np.testing.assert_allclose(xn, xp + gain @ nu, rtol=1e-13)
    np.testing.assert_allclose(pn, (np.eye(2) - gain) @ pp, rtol=1e-12)
    assert nis == pytest.approx(float(nu @ np.linalg.solve(s, nu)), rel=1e-12)
    assert steps == 0
    # a receiver millisecond clock step is re-aligned, not an innovation
    stepped = z + np.array([2 * 299792.458, 0.0])
    xs, _, nis_s, steps_s = kernels.clock_kalman_step(x, p, phi, q, r, stepped, 299792.458, 1000.0)
    assert steps_s == 2
    assert nis_s == pytest.approx(nis, rel=1e-9)
    np.testing.assert_allclose(xs[1], xn[1], rtol=1e-9)
