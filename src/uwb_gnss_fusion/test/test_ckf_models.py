"""Oracle tests of the CKF, the measurement models and the jamming weights (no ROS)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm

from gnss_common.constants import EARTH_ROTATION_RATE_RADPS, GPS_CA_CHIP_RATE_HZ, SPEED_OF_LIGHT_MPS
from gnss_common.jamming_weights import (
    CA_CHIP_LENGTH_M,
    TrackingLoopParams,
    dll_jitter_m,
    effective_cn0_dbhz,
    fll_jitter_mps,
    measurement_sigmas,
)
from uwb_gnss_fusion.ckf import CholeskyError, CubatureKalmanFilter, cubature_unit_points, robust_cholesky
from uwb_gnss_fusion.measurement_models import (
    constant_velocity_transition,
    pseudorange_model,
    pseudorange_rate_model,
    stack_models,
    uwb_range_model,
    white_acceleration_noise,
)


def _random_spd(rng, n):
    a = rng.standard_normal((n, n))
    return a @ a.T + n * np.eye(n)


# ----------------------------------------------------------------------------- CKF
def test_cubature_points_reproduce_mean_and_covariance():
    xi = cubature_unit_points(5)
    assert xi.shape == (10, 5)
    np.testing.assert_allclose(xi.mean(axis=0), 0.0, atol=1e-15)
    np.testing.assert_allclose(xi.T @ xi / 10, np.eye(5), atol=1e-14)


def test_ckf_equals_linear_kalman_filter_on_linear_model():
    rng = np.random.default_rng(1)
    n, k = 8, 5
    x0 = rng.standard_normal(n)
    p0 = _random_spd(rng, n)
    h = rng.standard_normal((k, n))
    r = _random_spd(rng, k)
    z = rng.standard_normal(k)
    phi = constant_velocity_transition(0.2)
    q = _random_spd(rng, n) * 0.01
    f = CubatureKalmanFilter(x0, p0)
    f.predict_linear(phi, q)
    f.update(z, r, lambda pts: pts @ h.T)
    # reference linear KF
    xp = phi @ x0
    pp = phi @ p0 @ phi.T + q
    s = h @ pp @ h.T + r
    gain = pp @ h.T @ np.linalg.inv(s)
    xr = xp + gain @ (z - h @ xp)
    pr = (np.eye(n) - gain @ h) @ pp
    np.testing.assert_allclose(f.x, xr, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(f.p, 0.5 * (pr + pr.T), rtol=1e-9, atol=1e-10)


def test_ckf_cubature_time_update_equals_linear_one_for_linear_fx():
    rng = np.random.default_rng(2)
    p0 = _random_spd(rng, 8)
    x0 = rng.standard_normal(8)
    phi = constant_velocity_transition(0.37)
    q = np.eye(8) * 1e-3
    a = CubatureKalmanFilter(x0, p0)
    b = CubatureKalmanFilter(x0, p0)
    a.predict_linear(phi, q)
    b.predict(lambda pts: pts @ phi.T, q)
    np.testing.assert_allclose(a.x, b.x, atol=1e-12)
    np.testing.assert_allclose(a.p, b.p, rtol=1e-10, atol=1e-10)


def test_ckf_third_degree_rule_is_exact_for_quadratic_measurement():
    # E[x^2] = mu^2 + sigma^2 exactly under the third-degree rule.
    f = CubatureKalmanFilter(np.array([2.0, 0.0]), np.diag([0.25, 1.0]))
    res = f.update(np.array([0.0]), np.array([1.0]), lambda pts: pts[:, :1] ** 2)
    z_hat = 0.0 - res.innovation[0]
    assert z_hat == pytest.approx(2.0**2 + 0.25, rel=1e-12)


def test_gating_excludes_outlier_and_equals_update_without_it():
    rng = np.random.default_rng(3)
    n = 4
    p0 = _random_spd(rng, n)
    h = rng.standard_normal((3, n))
    r = np.diag([1.0, 1.0, 1.0])
    z = h @ np.zeros(n) + np.array([0.1, -0.2, 1.0e4])
    gated = CubatureKalmanFilter(np.zeros(n), p0)
    res = gated.update(z, r, lambda pts: pts @ h.T, gate_nis=15.13)
    assert res.accepted.tolist() == [True, True, False]
    ref = CubatureKalmanFilter(np.zeros(n), p0)
    ref.update(z[:2], r[:2, :2], lambda pts: pts @ h[:2].T)
    np.testing.assert_allclose(gated.x, ref.x, atol=1e-12)
    np.testing.assert_allclose(gated.p, ref.p, atol=1e-12)
    assert math.isfinite(res.nis)


def test_all_gated_leaves_state_unchanged():
    f = CubatureKalmanFilter(np.zeros(2), np.eye(2))
    res = f.update(np.array([1e6]), np.array([1.0]), lambda pts: pts[:, :1], gate_nis=10.0)
    assert not res.accepted.any()
    np.testing.assert_array_equal(f.x, 0.0)
    np.testing.assert_array_equal(f.p, np.eye(2))
    assert math.isnan(res.nis)


def test_robust_cholesky_rejects_nan_and_indefinite():
    with pytest.raises(CholeskyError):
        robust_cholesky(np.array([[np.nan, 0.0], [0.0, 1.0]]))
    with pytest.raises(CholeskyError):
        robust_cholesky(np.array([[1.0, 0.0], [0.0, -1.0]]))
    low = robust_cholesky(np.array([[1.0, 1.0], [1.0, 1.0]]))  # PSD, singular: jitter makes it work
    np.testing.assert_allclose(low @ low.T, [[1.0, 1.0], [1.0, 1.0]], atol=1e-5)


def test_ckf_constructor_validates_shapes():
    with pytest.raises(ValueError):
        CubatureKalmanFilter(np.zeros(3), np.eye(2))


# ----------------------------------------------------------------------------- models
def _rot_z(v, ang):
    c, s = math.cos(ang), math.sin(ang)
    return np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]])


def test_pseudorange_sagnac_first_order_matches_exact_rotation():
    rx = np.array([-740289.918, -5457071.734, 3207245.542])
    sats = np.array([[-1.2e7, -2.0e7, 1.1e7], [1.5e7, -2.1e7, 0.5e7], [-2.0e7, -1.0e7, 1.6e7]])
    state = np.zeros((1, 8))
    state[0, 0:3] = rx
    pred = pseudorange_model(sats, np.zeros(3), np.zeros(3), np.zeros(3))(state)[0]
    for i, s in enumerate(sats):
        tau = np.linalg.norm(s - rx) / SPEED_OF_LIGHT_MPS
        for _ in range(3):
            tau = np.linalg.norm(_rot_z(s, EARTH_ROTATION_RATE_RADPS * tau) - rx) / SPEED_OF_LIGHT_MPS
        exact = np.linalg.norm(_rot_z(s, EARTH_ROTATION_RATE_RADPS * tau) - rx)
        assert abs(pred[i] - exact) < 1e-3
        assert abs(pred[i] - np.linalg.norm(s - rx)) > 1.0  # the correction is not negligible


def test_pseudorange_clock_and_corrections_enter_additively():
    sats = np.array([[1.5e7, -2.1e7, 0.5e7]])
    st = np.zeros((2, 8))
    st[:, 0:3] = [-740289.9, -5457071.7, 3207245.5]
    st[1, 6] = 100.0
    h = pseudorange_model(sats, np.array([5.0]), np.array([3.0]), np.array([2.0]))(st)
    h0 = pseudorange_model(sats, np.zeros(1), np.zeros(1), np.zeros(1))(st[:1])
    assert h[0, 0] - h0[0, 0] == pytest.approx(-5.0 + 3.0 + 2.0, abs=1e-6)
    assert h[1, 0] - h[0, 0] == pytest.approx(100.0, abs=1e-6)


def test_pseudorange_rate_is_time_derivative_of_pseudorange():
    rx = np.array([-740289.9, -5457071.7, 3207245.5])
    ps = np.array([[-1.2e7, -2.0e7, 1.1e7], [1.5e7, -2.1e7, 0.5e7]])
    vs = np.array([[1500.0, -2200.0, 900.0], [-800.0, 300.0, 3000.0]])
    clk = np.array([1.0e4, -3.0e3])
    drift = np.array([0.4, -0.2])
    x = np.zeros(8)
    x[0:3] = rx
    x[3:6] = [3.0, -4.0, 1.0]
    x[6:8] = [250.0, 12.0]
    rate = pseudorange_rate_model(ps, vs, drift)(x[None, :])[0]
    h = 1e-3

    def pr(t):
        xt = x.copy()
        xt[0:3] += x[3:6] * t
        xt[6] += x[7] * t
        return pseudorange_model(ps + vs * t, clk + drift * t, np.zeros(2), np.zeros(2))(xt[None, :])[0]

    numeric = (pr(h) - pr(-h)) / (2 * h)
    np.testing.assert_allclose(rate, numeric, atol=1e-4)


def test_uwb_model_with_lever_arm_and_stacking():
    anchors = np.array([[10.0, 0.0, 0.0], [0.0, 5.0, 0.0]])
    st = np.zeros((1, 8))
    hx = uwb_range_model(anchors, np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(hx(st)[0], [math.sqrt(101.0), math.sqrt(26.0)])
    both = stack_models([hx, uwb_range_model(anchors)])
    np.testing.assert_allclose(both(st)[0], [math.sqrt(101.0), math.sqrt(26.0), 10.0, 5.0])


def test_transition_is_matrix_exponential_of_paper_F():
    f = np.zeros((8, 8))
    f[0:3, 3:6] = np.eye(3)
    f[6, 7] = 1.0
    np.testing.assert_allclose(constant_velocity_transition(0.7), expm(f * 0.7), atol=1e-14)


def test_white_acceleration_noise_equals_van_loan_discretisation():
    q, dt = 0.3, 0.45
    f = np.zeros((6, 6))
    f[0:3, 3:6] = np.eye(3)
    g = np.zeros((6, 6))
    g[3:6, 3:6] = q * np.eye(3)
    big = np.block([[-f, g], [np.zeros((6, 6)), f.T]]) * dt
    e = expm(big)
    phi = e[6:, 6:].T
    qd = phi @ e[:6, 6:]
    np.testing.assert_allclose(white_acceleration_noise(q, dt), qd, atol=1e-13)


# ----------------------------------------------------------------------------- jamming weights
def test_effective_cn0_limits_and_monotonicity():
    assert effective_cn0_dbhz(45.0, -np.inf) == pytest.approx(45.0)
    # strong jammer: C/N0_eff -> 10 log10(Q f_c) - J/S
    assert effective_cn0_dbhz(45.0, 80.0, 2.0) == pytest.approx(
        10 * math.log10(2.0 * GPS_CA_CHIP_RATE_HZ) - 80.0, abs=1e-3
    )
    js = np.linspace(-20, 40, 13)
    ce = effective_cn0_dbhz(45.0, js)
    assert np.all(np.diff(ce) < 0)
    # equal contributions: 3.01 dB loss
    js_equal = -45.0 + 10 * math.log10(GPS_CA_CHIP_RATE_HZ)
    assert effective_cn0_dbhz(45.0, js_equal) == pytest.approx(45.0 - 10 * math.log10(2.0), abs=1e-9)
    with pytest.raises(ValueError):
        effective_cn0_dbhz(45.0, 0.0, quality_factor=0.0)


def test_dll_jitter_closed_form_and_scaling():
    loop = TrackingLoopParams(dll_bandwidth_hz=2.0, correlator_spacing_chips=1.0, integration_time_s=0.02)
    cn0 = 10**4.5
    expected = CA_CHIP_LENGTH_M * math.sqrt(2.0 * 1.0 / (2 * cn0) * (1 + 2 / (0.02 * cn0 * 1.0)))
    assert dll_jitter_m(45.0, loop) == pytest.approx(expected, rel=1e-12)
    # at high C/N0 the jitter scales as (C/N0)^-1/2: +20 dB -> / 10
    assert dll_jitter_m(70.0, loop) / dll_jitter_m(50.0, loop) == pytest.approx(0.1, rel=1e-2)


def test_fll_jitter_and_sigmas_grow_with_jamming():
    loop = TrackingLoopParams()
    assert fll_jitter_mps(34.9, loop) > fll_jitter_mps(35.0, loop) * math.sqrt(2) * 0.99
    s_pr0, s_r0, c0 = measurement_sigmas(np.array([45.0]), np.nan, loop)
    s_pr1, s_r1, c1 = measurement_sigmas(np.array([45.0]), 25.0, loop)
    assert c0[0] == pytest.approx(45.0)
    assert c1[0] < c0[0] and s_pr1[0] > s_pr0[0] and s_r1[0] > s_r0[0]
    assert s_pr0[0] >= loop.code_floor_m


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(dll_bandwidth_hz=0.0),
        dict(correlator_spacing_chips=1.5),
        dict(integration_time_s=-1.0),
        dict(code_floor_m=-0.1),
    ],
)
def test_loop_params_validation(kwargs):
    with pytest.raises(ValueError):
        TrackingLoopParams(**kwargs)


# ----------------------------------------------------------------------------- beyond the paper
def _range_hx(anchor):
    return lambda pts: np.linalg.norm(pts[:, :3] - anchor, axis=1)[:, None]


def _two_range_hx(a1, a2):
    return lambda pts: np.stack(
        [np.linalg.norm(pts[:, :3] - a1, axis=1), np.linalg.norm(pts[:, :3] - a2, axis=1)], axis=1
    )


@pytest.mark.parametrize("two", [False, True])
def test_active_dims_shortcut_equals_full_cubature_update(two):
    rng = np.random.default_rng(11)
    p0 = _random_spd(rng, 8)
    x0 = rng.standard_normal(8)
    a1, a2 = np.array([4.0, 1.0, 0.5]), np.array([-3.0, 2.0, 1.0])
    hx = _two_range_hx(a1, a2) if two else _range_hx(a1)
    z = hx(x0[None, :])[0] + 0.3
    r = np.full(z.size, 0.04)
    full = CubatureKalmanFilter(x0, p0)
    short = CubatureKalmanFilter(x0, p0)
    res_f = full.update(z, r, hx)
    res_s = short.update(z, r, hx, active_dims=3)
    np.testing.assert_allclose(short.x, full.x, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(short.p, full.p, rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(res_s.innovation, res_f.innovation, atol=1e-10)
    np.testing.assert_allclose(res_s.innovation_var, res_f.innovation_var, rtol=1e-10)


def test_iterated_update_reaches_the_map_point_and_is_not_pulled_to_the_anchor():
    from scipy.optimize import minimize

    rng = np.random.default_rng(12)
    anchor = np.array([3.0, 1.0, 0.5])
    hx = _range_hx(anchor)
    z = np.array([2.5])
    r = np.array([0.01])
    for _ in range(3):
        a = rng.standard_normal((8, 8))
        p0 = 0.3 * a @ a.T + 0.5 * np.eye(8)
        f = CubatureKalmanFilter(np.zeros(8), p0)
        res = f.update(z, r, hx, active_dims=3, max_iterations=30)
        assert res.iterations > 0 and res.nonlinearity > 1.0
        p_inv = np.linalg.inv(p0)

        def cost(x, p_inv=p_inv):
            return x @ p_inv @ x + (z[0] - np.linalg.norm(x[:3] - anchor)) ** 2 / r[0]

        best = minimize(cost, f.x, method="BFGS", options={"gtol": 1e-10})
        assert cost(f.x) == pytest.approx(best.fun, rel=1e-6)
        np.testing.assert_allclose(f.x, best.x, atol=1e-3)
        plain = CubatureKalmanFilter(np.zeros(8), p0)
        plain.update(z, r, hx, active_dims=3)
        # the cubature mean lies inside the range sphere (convexity); the MAP point on it
        assert np.linalg.norm(plain.x[:3] - anchor) < 2.4
        assert np.linalg.norm(f.x[:3] - anchor) == pytest.approx(2.5, abs=0.01)


def test_repeated_range_updates_keep_the_iterated_filter_on_the_sphere():
    # Tag 5 m from an anchor, wide prior across the line of sight, the same noise-free range
    # applied 50 times (no process noise): the plain CKF walks towards the anchor, the iterated
    # update stays at 5 m.
    anchor = np.array([5.0, 0.0, 0.0])
    hx = _range_hx(anchor)
    p0 = np.diag([4.0, 4.0, 4.0, 1.0, 1.0, 1.0, 1.0, 1.0])
    plain = CubatureKalmanFilter(np.zeros(8), p0)
    iterated = CubatureKalmanFilter(np.zeros(8), p0)
    for _ in range(50):
        plain.update(np.array([5.0]), np.array([0.01]), hx, active_dims=3)
        iterated.update(np.array([5.0]), np.array([0.01]), hx, active_dims=3, max_iterations=10)
    assert np.linalg.norm(plain.x[:3] - anchor) < 4.8
    assert np.linalg.norm(iterated.x[:3] - anchor) == pytest.approx(5.0, abs=0.01)
    np.testing.assert_allclose(iterated.x[:3], 0.0, atol=0.02)


def test_iterations_are_not_used_for_a_linear_model():
    rng = np.random.default_rng(13)
    p0 = _random_spd(rng, 8)
    h = rng.standard_normal((3, 8))
    f = CubatureKalmanFilter(np.zeros(8), p0)
    res = f.update(np.ones(3), np.ones(3), lambda pts: pts @ h.T, max_iterations=10)
    assert res.iterations == 0 and abs(res.nonlinearity) < 1e-9


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_huber_weighting_equals_kalman_update_with_inflated_noise(sign):
    # Scalar linear model: |e| = |nu| / sqrt(P_zz) > k inflates R by |e| / k (closed form).
    p0 = np.diag([4.0, 1.0])
    r = 1.0
    nu = sign * 9.0
    e = abs(nu) / math.sqrt(4.0 + r)
    k = 2.0
    f = CubatureKalmanFilter(np.zeros(2), p0)
    res = f.update(np.array([nu]), np.array([r]), lambda pts: pts[:, :1], huber_k=k)
    r_eff = r * e / k
    assert res.noise_scale[0] == pytest.approx(e / k)
    assert f.x[0] == pytest.approx(4.0 / (4.0 + r_eff) * nu, rel=1e-12)
    assert f.p[0, 0] == pytest.approx(4.0 - 16.0 / (4.0 + r_eff), rel=1e-12)
    # skewed: only positive innovations (too-long NLOS ranges) are down-weighted
    g = CubatureKalmanFilter(np.zeros(2), p0)
    res = g.update(np.array([nu]), np.array([r]), lambda pts: pts[:, :1], huber_k_positive=k)
    if sign > 0:
        assert res.noise_scale[0] == pytest.approx(e / k)
    else:
        assert res.noise_scale[0] == 1.0
        assert g.x[0] == pytest.approx(4.0 / 5.0 * nu, rel=1e-12)


def test_uwb_latency_back_propagates_with_velocity():
    anchor = np.array([[10.0, 0.0, 0.0]])
    states = np.zeros((2, 8))
    states[0, 3] = 2.0  # moving towards the anchor at 2 m/s: 0.25 s earlier it was 0.5 m further
    states[1, 0:3] = [1.0, 2.0, 0.5]
    hx = uwb_range_model(anchor, latency_s=0.25)
    np.testing.assert_allclose(hx(states)[:, 0], [10.5, np.linalg.norm(anchor[0] - states[1, 0:3])])
    with pytest.raises(ValueError):
        uwb_range_model(anchor, latency_s=-0.1)


@pytest.mark.parametrize(
    ("latency_s", "offset_m", "prior_std_m", "huber_k", "huber_k_positive"),
    [
        (0.0, 0.05, 0.05, math.inf, math.inf),  # plain update (no refinement: nearly linear)
        (0.0, 0.3, 1.0, math.inf, math.inf),  # wide prior: Gauss-Newton refinement
        (0.1, 0.3, 1.0, math.inf, math.inf),  # latency: 6 active components
        (0.0, 0.8, 0.05, 1.5, 0.5),  # skewed Huber weighting of a long range
        (0.0, -0.6, 0.05, 1.5, math.inf),  # Huber on a negative innovation
        (0.0, 50.0, 0.05, math.inf, math.inf),  # gated out
    ],
)
def test_compiled_uwb_step_equals_generic_ckf_update(latency_s, offset_m, prior_std_m, huber_k, huber_k_positive):
    from uwb_gnss_fusion.ckf_kernels import STATUS_APPLIED, STATUS_GATED, predict_inplace, range_update_inplace

    rng = np.random.default_rng(5)
    p0 = _random_spd(rng, 8) * 0.01 + np.diag([prior_std_m**2] * 3 + [0.01] * 5)
    nominal = np.array([3.0, -2.0, 1.0, 0.2, -0.1, 0.05, 100.0, 0.3])
    anchor, lever = np.array([10.0, 4.0, 2.0]), np.array([0.1, 0.0, 0.2])
    phi, q = constant_velocity_transition(0.05), np.diag(rng.uniform(1e-4, 1e-3, 8))
    m = 6 if latency_s > 0.0 else 3
    # generic path: numpy predict, then CubatureKalmanFilter.update on the error state (as before)
    nom_g = phi @ nominal
    ckf = CubatureKalmanFilter(np.zeros(8), p0)
    ckf.predict_linear(phi, q)
    rel = anchor - nom_g[0:3] + latency_s * nom_g[3:6]
    hx = uwb_range_model(rel[None, :], lever, latency_s)
    z = float(hx(np.zeros((1, 8)))[0, 0]) + offset_m
    gate = 15.1
    res = ckf.update(np.array([z]), np.array([0.01]), hx, gate, active_dims=m, huber_k=huber_k,
                     huber_k_positive=huber_k_positive, max_iterations=5, nonlinearity_threshold=0.05)
    nom_g = nom_g + ckf.x
    # compiled path, in place
    nom_c, p_c, out = nominal.copy(), p0.copy(), np.zeros(6)
    predict_inplace(nom_c, p_c, phi, q)
    status = range_update_inplace(nom_c, p_c, anchor, lever, latency_s, m, z, 0.01, gate, huber_k,
                                  huber_k_positive, 5, 0.05, out)
    assert status == (STATUS_APPLIED if res.accepted[0] else STATUS_GATED)
    np.testing.assert_allclose(nom_c, nom_g, rtol=0, atol=1e-10)
    np.testing.assert_allclose(p_c, ckf.p, rtol=1e-9, atol=1e-14)
    assert out[0] == pytest.approx(res.innovation[0], abs=1e-12)
    assert out[1] == pytest.approx(res.innovation_var[0], rel=1e-12)
    assert out[3] == pytest.approx(res.noise_scale[0], rel=1e-12)
    assert int(out[4]) == res.iterations
    if res.accepted[0]:
        assert out[2] == pytest.approx(res.nis, rel=1e-9)
    if prior_std_m > 0.5 and res.accepted[0]:
        assert res.iterations > 0  # the refinement branch is exercised


def test_compiled_uwb_update_reports_a_covariance_without_cholesky_factor():
    from uwb_gnss_fusion.ckf_kernels import STATUS_CHOLESKY_FAILED, range_update_inplace

    p = np.eye(8)
    p[0, 0] = -1.0
    nominal = np.zeros(8)
    before = (nominal.copy(), p.copy())
    status = range_update_inplace(nominal, p, np.array([10.0, 0.0, 0.0]), np.zeros(3), 0.0, 3, 10.0, 0.01,
                                  15.1, math.inf, math.inf, 5, 0.05, np.zeros(6))
    assert status == STATUS_CHOLESKY_FAILED
    np.testing.assert_array_equal(nominal, before[0])
    np.testing.assert_array_equal(p, before[1])
