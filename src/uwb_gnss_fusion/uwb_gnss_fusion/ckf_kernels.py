"""Compiled kernels of the cubature Kalman filter: time update, and one gated cubature range update.

Pure core (no rclpy). Only :class:`.ckf.CubatureKalmanFilter` calls these, on its own covariance
(:meth:`~.ckf.CubatureKalmanFilter.predict_with_nominal`,
:meth:`~.ckf.CubatureKalmanFilter.update_range_compiled`). The generic
:meth:`.ckf.CubatureKalmanFilter.update` costs about 100 us per UWB range, nearly all of it numpy
call overhead on 8 x 8 arrays (a 20 Hz x 3-anchor stream makes 60 of them per second). The
functions here do the same arithmetic on scalars in numba-compiled loops, in place on the
filter's nominal state and error covariance:

* :func:`predict_inplace`: ``x <- Phi x``, ``P <- Phi P Phi^T + Q`` (Cao et al., eq. 15-16).
* :func:`range_curvature_variance`: the second-order (curvature) variance of a range over the
  position uncertainty, added to the range noise (``FusionParams.uwb_range_curvature_noise``).
* :func:`range_update_inplace`: the cubature update of one range with the position-only
  (``active_dims``) shortcut, gating, the optional skewed Huber weighting and the optional
  Gauss-Newton refinement, exactly as ``CubatureKalmanFilter.update`` with ``k = 1`` (Cao et al.,
  eq. 7 and 17-24, then the status correction eq. 25). The error state is zero before the update
  (it is folded into the nominal after every update), which the filter guarantees.

The equations, the order of the tests and the iteration rule are those of :mod:`.ckf`; only the
summation order differs, so the results agree with the generic update (the reference, and the
test oracle) to rounding (test_ckf_models.py checks it). A leading covariance block that is not
positive definite is reported (:data:`STATUS_CHOLESKY_FAILED`) with the state untouched, and the
caller falls back to the generic update, which symmetrises, adds jitter or raises.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

STATUS_APPLIED = 0
"""The range passed the gate and was applied."""
STATUS_GATED = 1
"""The range failed the innovation gate (or its innovation is not finite); state unchanged."""
STATUS_CHOLESKY_FAILED = 2
"""The leading ``m x m`` block of P has no Cholesky factor; nothing was changed."""

_GN_EPS = 0.01
"""Central-difference step of the Gauss-Newton refinement, prior standard deviations (as .ckf)."""


@njit(cache=True)
def predict_inplace(nominal, p, phi, q):  # pragma: no cover - compiled
    """Linear time update in place.

    Args:
        nominal: nominal state, shape (n,), replaced by ``Phi nominal``.
        p: error covariance, shape (n, n), replaced by ``Phi P Phi^T + Q``.
        phi: state transition, shape (n, n).
        q: process noise covariance, shape (n, n).

    Notes:
        Cao et al., eq. 15-16 (the error mean is zero after every correction, so only the nominal
        and the covariance move).
    """
    n = nominal.shape[0]
    tmp = np.empty(n)
    for i in range(n):
        s = 0.0
        for k in range(n):
            s += phi[i, k] * nominal[k]
        tmp[i] = s
    nominal[:] = tmp
    a = np.empty((n, n))  # Phi P
    for i in range(n):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += phi[i, k] * p[k, j]
            a[i, j] = s
    for i in range(n):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += a[i, k] * phi[j, k]
            p[i, j] = s + q[i, j]


@njit(cache=True)
def _range(e, m, a0, lat):  # pragma: no cover - compiled
    """|e_p - lat e_v - a0| for the error state ``e`` (the model of .measurement_models.uwb_range_model)."""
    s = 0.0
    for i in range(3):
        d = e[i] - a0[i] if lat == 0.0 else e[i] - lat * e[i + 3] - a0[i]
        s += d * d
    return math.sqrt(s)


@njit(cache=True)
def _leading_columns(p, m, low):  # pragma: no cover - compiled
    """First m columns of the lower Cholesky factor of p into ``low`` (n, m); False if not PD."""
    n = p.shape[0]
    for j in range(m):
        s = p[j, j]
        for k in range(j):
            s -= low[j, k] * low[j, k]
        if not s > 0.0 or not s < math.inf:
            return False
        d = math.sqrt(s)
        low[j, j] = d
        for i in range(j):
            low[i, j] = 0.0
        for i in range(j + 1, n):
            t = p[i, j]
            for k in range(j):
                t -= low[i, k] * low[j, k]
            low[i, j] = t / d
            if not abs(low[i, j]) < math.inf:
                return False
    return True


@njit(cache=True)
def _gn_evaluate(bb, low, m, n, a0, lat, z, r_chol, xc, pt, hl):  # pragma: no cover - compiled
    """Central-difference ``H L`` into ``hl``, residual and MAP cost at ``x = L bb`` (as .ckf)."""
    for i in range(n):
        s = 0.0
        for j in range(m):
            s += low[i, j] * bb[j]
        xc[i] = s
    zc = _range(xc, m, a0, lat)
    for j in range(m):
        for i in range(n):
            pt[i] = xc[i] + _GN_EPS * low[i, j]
        zp = _range(pt, m, a0, lat)
        for i in range(n):
            pt[i] = xc[i] - _GN_EPS * low[i, j]
        zm = _range(pt, m, a0, lat)
        hl[j] = (zp - zm) * (0.5 / _GN_EPS)
    res = z - zc
    w = res / r_chol
    cost = w * w
    for j in range(m):
        cost += bb[j] * bb[j]
    return res, cost


@njit(cache=True)
def range_curvature_variance(p, nominal, anchor, lever, lat):  # pragma: no cover - compiled
    """Second-order variance of a range over the position uncertainty, m^2.

    ``0.5 tr(A P_t A P_t)`` with ``A = (I - u u^T) / rho`` the Hessian of ``|t - a|`` (``u`` the
    unit line of sight from the anchor to the tag, ``rho`` the range) and ``P_t`` the covariance
    of the tag position ``p + lever - lat v``; equal to ``|T P_t T|_F^2 / (2 rho^2)`` with
    ``T = I - u u^T``. This is the term a second-order filter adds to the innovation covariance
    (Bar-Shalom, Li & Kirubarajan, Estimation with Applications to Tracking and Navigation, 2001,
    sec. 10.3, the second-order EKF): the part of the range that the linearisation at the estimate misses when the tag
    is uncertain across the line of sight. Reference: ``uwb_update.range_curvature_variance_reference``.

    Args:
        p: error covariance, (n, n), the first 3 (6 with a latency) components position (velocity).
        nominal: nominal state, (n,).
        anchor: anchor position in the state frame, m, (3,).
        lever: UWB tag minus GNSS antenna, m, (3,).
        lat: range latency, s (>= 0).
    """
    u = np.empty(3)
    rho2 = 0.0
    for i in range(3):
        t = nominal[i] + lever[i] - anchor[i]
        if lat > 0.0:
            t -= lat * nominal[i + 3]
        u[i] = t
        rho2 += t * t
    if not rho2 > 0.0:
        return 0.0
    rho = math.sqrt(rho2)
    for i in range(3):
        u[i] /= rho
    pt = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            v = p[i, j]
            if lat > 0.0:
                v += -lat * (p[i, j + 3] + p[i + 3, j]) + lat * lat * p[i + 3, j + 3]
            pt[i, j] = v
    # T P_t T with T = I - u u^T
    pu = np.empty(3)
    for i in range(3):
        pu[i] = pt[i, 0] * u[0] + pt[i, 1] * u[1] + pt[i, 2] * u[2]
    upu = u[0] * pu[0] + u[1] * pu[1] + u[2] * pu[2]
    f2 = 0.0
    for i in range(3):
        for j in range(3):
            v = pt[i, j] - u[i] * pu[j] - pu[i] * u[j] + u[i] * u[j] * upu
            f2 += v * v
    return f2 / (2.0 * rho2)


@njit(cache=True)
def _range_moments(low, m, n, a0, lat, pt, g):  # pragma: no cover - compiled
    """The ranges of the cubature points ``+- sqrt(n) L_j`` about the zero error state and of the centre
    point (Cao et al., eq. 17-19; ``low`` the first ``m`` columns ``L`` of chol(P)): returns their mean and
    variance ``(z_hat, var(Z))`` (eq. 20-21 without R); ``g`` (m,) receives ``S^-1 P_xz`` on the active
    columns. ``pt`` (n,) is scratch, zero on return."""
    c = math.sqrt(n)
    inv2n = 1.0 / (2 * n)
    zp = np.empty(m)
    zm = np.empty(m)
    for j in range(m):
        for i in range(n):
            pt[i] = c * low[i, j]
        zp[j] = _range(pt, m, a0, lat)
        for i in range(n):
            pt[i] = -c * low[i, j]
        zm[j] = _range(pt, m, a0, lat)
    n_c = 2 * (n - m)
    for i in range(n):
        pt[i] = 0.0
    zc = _range(pt, m, a0, lat) if m < n else 0.0
    zh = (zp.sum() + zm.sum() + n_c * zc) * inv2n
    var_z = n_c * (zc - zh) ** 2
    dsum = 0.0
    for j in range(m):
        dsum += (zp[j] - zh) * (zp[j] - zh)
    for j in range(m):
        dsum += (zm[j] - zh) * (zm[j] - zh)
    var_z = (dsum + var_z) * inv2n
    for j in range(m):
        g[j] = (c * inv2n) * (zp[j] - zm[j])
    return zh, var_z


@njit(cache=True)
def _gauss_newton_range(b, low, m, n, a0, lat, z, r, max_iterations, pt, lvec):  # pragma: no cover - compiled
    """Iterated (Gauss-Newton) refinement of the MAP point of one range, as ``.ckf._gauss_newton``: ``b``
    (m,), the whitened correction, is refined in place; after at least one step ``lvec`` (n,) receives
    ``L h`` of the last linearisation. ``pt`` (n,) is scratch. Returns (steps taken, the innovation
    variance of the last linearisation; NaN when no step was taken)."""
    r_chol = math.sqrt(r)
    xc = np.empty(n)
    hl = np.empty(m)
    hl_n = np.empty(m)
    b_new = np.empty(m)
    res, cost = _gn_evaluate(b, low, m, n, a0, lat, z, r_chol, xc, pt, hl)
    iters = 0
    for _ in range(max_iterations):
        hh = 0.0
        hb = 0.0
        for j in range(m):
            hh += hl[j] * hl[j]
            hb += hl[j] * b[j]
        f = (res + hb) / (hh + r)
        for j in range(m):
            b_new[j] = hl[j] * f
        res_n, cost_n = _gn_evaluate(b_new, low, m, n, a0, lat, z, r_chol, xc, pt, hl_n)
        halvings = 0
        while not cost_n <= cost and halvings < 4:
            for j in range(m):
                b_new[j] = 0.5 * (b[j] + b_new[j])
            res_n, cost_n = _gn_evaluate(b_new, low, m, n, a0, lat, z, r_chol, xc, pt, hl_n)
            halvings += 1
        if not cost_n <= cost:
            break
        iters += 1
        moved = 0.0
        for j in range(m):
            moved = max(moved, abs(b_new[j] - b[j]))
            b[j] = b_new[j]
            hl[j] = hl_n[j]
        res = res_n
        cost = cost_n
        if moved < 1e-4:
            break
    if iters:
        hh = 0.0
        for j in range(m):
            hh += hl[j] * hl[j]
        for i in range(n):
            s = 0.0
            for j in range(m):
                s += low[i, j] * hl[j]
            lvec[i] = s
        return iters, hh + r
    return iters, math.nan


@njit(cache=True)
def range_update_inplace(
    nominal, p, anchor, lever, lat, m, z, r, gate_nis, huber_k, huber_k_positive, max_iterations, threshold, out
):  # pragma: no cover - compiled
    """Gated cubature update of one UWB range, in place on the nominal state and P.

    Args:
        nominal: nominal state [p, v, c dt, c ddt], shape (n,), m, m/s; corrected in place (eq. 25).
        p: error covariance, shape (n, n); replaced by the posterior.
        anchor: anchor position in the state frame, m, shape (3,).
        lever: UWB tag minus GNSS antenna in the state frame, m, shape (3,).
        lat: range latency, s (>= 0; 0: the paper's model).
        m: active state components (3: position; 6 with a latency).
        z: measured range, m.
        r: range noise variance, m^2.
        gate_nis: threshold on ``nu^2 / P_zz`` (inf: no gate).
        huber_k: Huber threshold on the normalised innovation (inf: off).
        huber_k_positive: threshold for positive innovations (the filter passes its parameter).
        max_iterations: Gauss-Newton steps allowed (0: plain CKF update).
        threshold: refine when ``(var(Z) - g^T g) / R`` exceeds this.
        out: float64[6] written with [innovation, prior innovation variance, NIS, noise scale,
            iterations, nonlinearity].

    Returns:
        :data:`STATUS_APPLIED`, :data:`STATUS_GATED` or :data:`STATUS_CHOLESKY_FAILED`.

    Notes:
        Cao et al., eq. 7 (range model ``|p + lever - anchor|``, latency beyond the paper) and
        eq. 17-24 (cubature points ``chi = S xi``, ``z_hat`` their mean range, ``P_zz``,
        ``P_xz = S g``, gain, posterior), eq. 25 (correction of the nominal state). With the
        first m columns L of chol(P), the 2n cubature points that do not move the first m
        components all map to the central range, so ``2m + 1`` evaluations suffice (exact).
        The gate, Huber weighting and Gauss-Newton refinement are those of
        :meth:`.ckf.CubatureKalmanFilter.update` (``_update_scalar`` and ``_gauss_newton``).
    """
    n = nominal.shape[0]
    low = np.empty((n, m))
    if not _leading_columns(p, m, low):
        return STATUS_CHOLESKY_FAILED
    a0 = np.empty(3)
    for i in range(3):
        rel = anchor[i] - nominal[i] + lat * nominal[i + 3] if lat > 0.0 else anchor[i] - nominal[i]
        a0[i] = rel - lever[i]
    # Cubature points about the zero error state (eq. 17-18), ranges (eq. 19-21).
    pt = np.zeros(n)
    g = np.empty(m)
    zh, var_z = _range_moments(low, m, n, a0, lat, pt, g)
    # Gate (beyond the paper) on the prior innovation.
    nu = z - zh
    s11 = var_z + r
    out[0] = nu
    out[1] = s11
    out[2] = math.nan
    out[3] = 1.0
    out[4] = 0.0
    out[5] = 0.0
    if not (abs(nu) < math.inf and nu * nu <= gate_nis * s11):
        return STATUS_GATED
    # Skewed Huber weighting (beyond the paper).
    thr = huber_k_positive if nu > 0.0 else huber_k
    if abs(thr) < math.inf:
        e = abs(nu) / math.sqrt(s11)
        if e > thr:
            scale = e / thr
            r *= scale
            s11 = var_z + r
            out[3] = scale
    out[2] = nu * nu / s11
    # Gain and posterior (eq. 22-24) in whitened active coordinates x = L b.
    b = np.empty(m)
    gg = 0.0
    for j in range(m):
        b[j] = g[j] * (nu / s11)
        gg += g[j] * g[j]
    lvec = np.empty(n)
    for i in range(n):
        s = 0.0
        for j in range(m):
            s += low[i, j] * g[j]
        lvec[i] = s
    denom = s11
    nonlin = (var_z - gg) / r
    out[5] = nonlin
    if max_iterations > 0 and nonlin > threshold:
        iters, denom_gn = _gauss_newton_range(b, low, m, n, a0, lat, z, r, max_iterations, pt, lvec)
        if iters:
            denom = denom_gn
        out[4] = iters
    inv = 1.0 / denom
    for i in range(n):
        for j in range(n):
            p[i, j] = p[i, j] - lvec[i] * lvec[j] * inv
    for i in range(n):
        for j in range(i + 1, n):
            v = 0.5 * (p[i, j] + p[j, i])
            p[i, j] = v
            p[j, i] = v
    for i in range(n):
        s = 0.0
        for j in range(m):
            s += low[i, j] * b[j]
        nominal[i] += s
    return STATUS_APPLIED


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernels on a throwaway state.

    The first call otherwise pays the compilation (10-20 s on a cold cache) inside the first
    measurement callback; a node calls this before it subscribes, so that it is ready, and looks
    ready to the graph, only when it can keep up.
    """
    n = 8
    nominal = np.zeros(n)
    nominal[0] = 6.4e6
    p = np.eye(n)
    predict_inplace(nominal, p, np.eye(n), np.eye(n) * 1e-3)
    range_curvature_variance(p, nominal, np.array([6.4e6 + 10.0, 0.0, 0.0]), np.zeros(3), 0.0)
    range_update_inplace(nominal, p, np.array([6.4e6 + 10.0, 0.0, 0.0]), np.zeros(3), 0.0, 3, 10.0, 0.01,
                         16.0, np.inf, np.inf, 5, 0.05, np.zeros(6))
    range_update_inplace(nominal, p, np.array([6.4e6 + 10.0, 0.0, 0.0]), np.zeros(3), 0.1, 6, 10.0, 0.01,
                         16.0, np.inf, np.inf, 5, 0.05, np.zeros(6))
