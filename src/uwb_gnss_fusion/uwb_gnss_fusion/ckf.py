"""Cubature Kalman filter (third-degree spherical-radial rule) with per-measurement gating.

Generic and pure: the state, the models and the noise are passed in. The fusion filter uses it
on the 8-state error vector of Cao et al. (the models add the error to the nominal state).

Beyond the paper, :meth:`CubatureKalmanFilter.update` offers (all off by default, so that the
default update is exactly Cao et al. eq. 17-24):

* ``active_dims``: an exact shortcut for models that depend on the leading state components only
  (a UWB range depends on the position): the cubature points that do not move those components all
  map to the same measurement, so only ``2 m + 1`` model evaluations and an ``m x m`` Cholesky
  factor are needed. The result equals the full 2n-point update to rounding.
* gating (``gate_nis``): each measurement's innovation is tested under the prior (its marginal is
  independent of the other measurements); the update then uses the accepted subset.
* ``huber_k`` / ``huber_k_positive``: Huber M-estimation in innovation form (Karlgaard & Schaub 2007,
  Huber-based divided difference filtering; one reweighting step: ``R_ii <- R_ii |e_i| / k`` for
  measurements whose normalised innovation ``e_i`` exceeds the threshold), optionally skewed (a smaller
  threshold for positive innovations, e.g. for non-line-of-sight UWB ranges, which are only ever
  too long).
* ``max_iterations``: iterated update, a Gauss-Newton minimisation of the MAP cost
  ``|x - x_prior|^2_P^-1 + |z - h(x)|^2_R^-1`` started at the cubature posterior mean (the iterated EKF
  of Bell & Cathey 1993, with the Jacobian taken by central differences along the prior's Cholesky
  columns, i.e. cubature points with a small spread); the covariance is that of the last
  linearisation. It is used only when the statistical-linearisation error ``Omega`` is significant:
  then the cubature mean of a range exceeds the range of the mean (convexity), and repeated range-only
  updates drag the state towards the anchor; the MAP point stays on the range sphere. For nearly
  linear measurements (pseudoranges) nothing changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .ckf_kernels import predict_inplace, range_update_inplace
from .measurement_models import MeasurementModel


class CholeskyError(ArithmeticError):
    """The covariance is not positive definite even after symmetrisation and jitter."""


def cubature_unit_points(n: int) -> np.ndarray:
    """Unit cubature points xi_i = sqrt(n) [1]_i, i = 1..2n.

    Args:
        n: state dimension.

    Returns:
        Points, shape (2n, n); each has weight 1/(2n).

    Notes:
        Cao et al., eq. 14 (``xi_i = sqrt(m/2) [1]_i``, ``m = 2n``); Arasaratnam & Haykin (2009),
        eq. 25-27.
    """
    eye = np.eye(n)
    return np.sqrt(n) * np.vstack([eye, -eye])


def robust_cholesky(p: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor of a covariance, symmetrising and adding jitter if needed.

    Args:
        p: covariance, shape (n, n).

    Returns:
        L with ``L @ L.T == p`` (to rounding), shape (n, n).

    Raises:
        CholeskyError: if ``p`` is not finite or stays indefinite after jitter.
    """
    try:
        low = np.linalg.cholesky(p)
        if math.isfinite(float(low.sum())):
            return low
    except np.linalg.LinAlgError:
        pass
    if not np.all(np.isfinite(p)):
        raise CholeskyError("covariance contains NaN or inf")
    sym = 0.5 * (p + p.T)
    scale = max(float(np.max(np.abs(np.diag(sym)))), 1e-30)
    for k in (1e-12, 1e-9, 1e-6):
        try:
            return np.linalg.cholesky(sym + k * scale * np.eye(p.shape[0]))
        except np.linalg.LinAlgError:
            continue
    raise CholeskyError("covariance is not positive definite")


def leading_sqrt_columns(p: np.ndarray, m: int) -> np.ndarray:
    """First ``m`` columns of the lower Cholesky factor of ``p``, from its leading m x m block.

    Args:
        p: covariance, shape (n, n).
        m: number of leading columns, 1 <= m <= n.

    Returns:
        ``L[:, :m]`` with ``L = chol(p)``, shape (n, m): ``L[:m, :m] = chol(p[:m, :m])`` and
        ``L[m:, :m] = p[m:, :m] chol(p[:m, :m])^-T`` (block Cholesky).

    Raises:
        CholeskyError: if the leading block is not positive definite.
    """
    n = p.shape[0]
    try:
        full = np.linalg.cholesky(p)  # one small LAPACK call is cheaper than block algebra
        if math.isfinite(float(full[:, :m].sum())):
            return full[:, :m]
    except np.linalg.LinAlgError:
        pass
    l_aa = robust_cholesky(p[:m, :m])
    if m == n:
        return l_aa
    out = np.empty((n, m))
    out[:m] = l_aa
    out[m:] = np.linalg.solve(l_aa, p[:m, m:]).T
    return out


@dataclass(frozen=True)
class UpdateResult:
    """Outcome of one gated CKF measurement update.

    Attributes:
        x: posterior state, shape (n,).
        p: posterior covariance, shape (n, n).
        accepted: mask of measurements applied, shape (k,), bool.
        innovation: z - z_hat under the prior, shape (k,).
        innovation_var: diagonal of P_zz under the prior, shape (k,).
        nis: normalised innovation squared of the applied set (nu^T P_zz^-1 nu), or NaN if none.
        noise_scale: factor applied to each measurement's noise variance by the robust (Huber)
            weighting, shape (k,) (1: full weight).
        iterations: Gauss-Newton refinement steps taken after the cubature update (0: the plain
            CKF update of Cao et al. eq. 17-24).
        nonlinearity: largest ratio of the linearisation-error variance to the (weighted)
            measurement noise variance over the applied measurements (see ``update``).
    """

    x: np.ndarray
    p: np.ndarray
    accepted: np.ndarray
    innovation: np.ndarray
    innovation_var: np.ndarray
    nis: float
    noise_scale: np.ndarray = field(default_factory=lambda: np.ones(0))
    iterations: int = 0
    nonlinearity: float = 0.0


class CubatureKalmanFilter:
    """Cubature Kalman filter with a linear (or cubature) time update and a gated update.

    Args:
        x: initial state, shape (n,).
        p: initial covariance, shape (n, n), positive definite.

    Notes:
        Arasaratnam & Haykin (2009); Cao et al., eq. 14-24. Eq. 21 of Cao et al. prints ``+ R_k``
        in the cross-covariance; that is a typo (the cross-covariance of state and measurement has
        no measurement-noise term, Arasaratnam & Haykin eq. 37), and it is not used here.

    Example:
        >>> import numpy as np
        >>> f = CubatureKalmanFilter(np.zeros(2), np.eye(2))
        >>> res = f.update(np.array([1.0]), np.array([[1.0]]), lambda X: X[:, :1])
        >>> round(float(f.x[0]), 6)
        0.5
    """

    def __init__(self, x: np.ndarray, p: np.ndarray) -> None:
        x = np.asarray(x, dtype=float).copy()
        p = np.asarray(p, dtype=float).copy()
        if x.ndim != 1 or p.shape != (x.size, x.size):
            raise ValueError(f"x must be (n,) and p (n, n); got {x.shape} and {p.shape}")
        self.x = x
        self.p = p
        self.n = x.size
        self._xi = cubature_unit_points(self.n)

    def predict_linear(self, phi: np.ndarray, q: np.ndarray) -> None:
        """Linear time update.

        Args:
            phi: state transition, shape (n, n).
            q: process noise covariance, shape (n, n).

        Notes:
            Cao et al., eq. 15-16 (the state model is linear, so the cubature time update reduces
            to the Kalman one exactly).
        """
        self.x = phi @ self.x
        self.p = phi @ self.p @ phi.T + q

    def predict_with_nominal(self, nominal: np.ndarray, phi: np.ndarray, q: np.ndarray) -> None:
        """Error-state time update, compiled and in place, moving the caller's nominal state too.

        Args:
            nominal: nominal state, shape (n,), replaced by ``Phi nominal`` in place.
            phi: state transition, shape (n, n).
            q: process noise covariance, shape (n, n).

        Notes:
            Cao et al., eq. 15-16 (:func:`.ckf_kernels.predict_inplace`). The error mean is zero
            after every correction (:meth:`reset_error_state`) and is set to zero here, so only the
            nominal and the covariance move; the same arithmetic as :meth:`predict_linear`.
        """
        self.x[:] = 0.0
        predict_inplace(nominal, self.p, phi, q)

    def reset_error_state(self) -> np.ndarray:
        """Return the error-state mean and set it to zero (the status correction of Cao et al.,
        eq. 25 adds it to the nominal)."""
        x = self.x
        self.x = np.zeros(self.n)
        return x

    def reset_block(self, indices: slice, variances: np.ndarray) -> None:
        """Decorrelate states ``indices`` from all others and give them new variances.

        Args:
            indices: the states, a slice (e.g. ``slice(6, 8)`` for the receiver clock).
            variances: their new variances, shape (len,), in the states' units squared.

        Used when a state block is (re)initialised from outside information, e.g. the receiver
        clock set from pseudorange residuals while the position is kept.
        """
        self.p[indices, :] = 0.0
        self.p[:, indices] = 0.0
        idx = np.arange(self.n)[indices]
        self.p[idx, idx] = variances

    def update_range_compiled(
        self,
        nominal: np.ndarray,
        anchor: np.ndarray,
        lever: np.ndarray,
        latency_s: float,
        active_dims: int,
        z: float,
        r: float,
        gate_nis: float,
        huber_k: float,
        huber_k_positive: float,
        max_iterations: int,
        nonlinearity_threshold: float,
        scratch: np.ndarray,
    ) -> int:
        """The compiled cubature update of one UWB range (:func:`.ckf_kernels.range_update_inplace`).

        Same equations and arguments as :meth:`update` with ``k = 1`` and ``active_dims``, with the
        range model of :func:`.measurement_models.uwb_range_model` (anchor ``anchor`` in the
        state frame, ``lever`` the tag lever arm, ``latency_s`` the range age) and the status
        correction folded into ``nominal`` in place. The error mean must be zero (it is after
        :meth:`reset_error_state`). ``scratch`` (6,) receives the diagnostics (``scratch[2]``:
        the NIS).

        Returns:
            ``ckf_kernels.STATUS_APPLIED``, ``STATUS_GATED`` or ``STATUS_CHOLESKY_FAILED`` (nothing
            changed: call :meth:`update`, which symmetrises, adds jitter or raises).

        Notes:
            Cao et al., eq. 7, 17-25.
        """
        return int(range_update_inplace(
            nominal, self.p, anchor, lever, latency_s, active_dims, z, r, gate_nis, huber_k,
            huber_k_positive, max_iterations, nonlinearity_threshold, scratch,
        ))

    def predict(self, fx, q: np.ndarray) -> None:
        """Cubature time update for a nonlinear transition.

        Args:
            fx: callable mapping points (2n, n) to propagated points (2n, n).
            q: process noise covariance, shape (n, n).

        Notes:
            Arasaratnam & Haykin (2009), eq. 28-32.
        """
        s = robust_cholesky(self.p)
        pts = self.x[None, :] + self._xi @ s.T
        prop = fx(pts)
        self.x = prop.mean(axis=0)
        d = prop - self.x
        self.p = d.T @ d / pts.shape[0] + q

    def update(
        self,
        z: np.ndarray,
        r: np.ndarray,
        hx: MeasurementModel,
        gate_nis: float = np.inf,
        *,
        active_dims: int | None = None,
        huber_k: float = np.inf,
        huber_k_positive: float | None = None,
        max_iterations: int = 0,
        nonlinearity_threshold: float = 0.05,
    ) -> UpdateResult:
        """Cubature measurement update with per-measurement gating (and optional robust extras).

        Args:
            z: measurements, shape (k,).
            r: measurement noise covariance, shape (k, k) (or (k,) variances).
            hx: measurement model, points (N, n) -> (N, k) (N = 2n, or 2m + 1 with active_dims).
            gate_nis: per-measurement threshold on ``nu_i^2 / P_zz[i, i]`` (a 1-dof chi-square
                quantile); measurements above it are excluded from this update. ``inf``: no gating.
            active_dims: the model depends on the first ``m`` state components only (None: all).
                Exact: the update equals the full 2n-point one to rounding.
            huber_k: Huber threshold on the normalised innovation ``e = nu / sqrt(P_zz[i, i])``
                (inf: off). A measurement with ``|e| > k`` gets its noise variance multiplied by
                ``|e| / k``.
            huber_k_positive: threshold for positive innovations (measurement larger than
                predicted); None: ``huber_k``.
            max_iterations: Gauss-Newton refinement steps allowed after the cubature update when
                the measurement is strongly nonlinear over the prior (0: off).
            nonlinearity_threshold: refine only if, for some applied measurement, the variance of
                the cubature linearisation error (``Omega_ii = var(Z_i) - P_xz^T P^-1 P_xz``, the
                residual of the statistical linear regression) exceeds this fraction of its noise
                variance.

        Returns:
            :class:`UpdateResult`; the filter's ``x`` and ``p`` are replaced by the posterior.

        Raises:
            CholeskyError: if the prior covariance is not positive definite.

        Notes:
            Cao et al., eq. 17-24 (Arasaratnam & Haykin 2009, eq. 33-42): points
            ``chi_i = x + S xi_i``, ``Z_i = h(chi_i)``, ``z_hat = mean Z_i``,
            ``P_zz = cov(Z) + R``, ``P_xz = cov(chi, Z)``, ``K = P_xz P_zz^-1``,
            ``x += K (z - z_hat)``, ``P -= K P_zz K^T``. With the lower Cholesky factor S,
            ``P_xz = S G`` with ``G = (1/2n) sum_i xi_i (Z_i - z_hat)^T`` (used below).

            Beyond the paper (module docstring): gating, Huber weighting, iterated update.
        """
        z = np.asarray(z, dtype=float)
        r = np.asarray(r, dtype=float)
        if r.ndim == 1:
            r = np.diag(r)
        k = z.size
        n = self.n
        m = n if active_dims is None else int(active_dims)
        if not 1 <= m <= n:
            raise ValueError(f"active_dims must be in [1, {n}], got {active_dims}")
        x0 = self.x
        p0 = self.p
        lcols = leading_sqrt_columns(p0, m)  # (n, m)
        c = math.sqrt(n)
        zs = hx(_active_cubature_points(x0, lcols, c))
        inv2n = 1.0 / (2 * n)
        if k == 1:
            zh, var_z, g1 = _scalar_moments(zs[:, 0], m, n, c)
            return self._update_scalar(float(z[0]), float(r[0, 0]), hx, gate_nis, lcols, g1, zh, var_z, huber_k,
                                       huber_k_positive, max_iterations, nonlinearity_threshold)
        z_hat, cov_z = _measurement_moments(zs, m, n)
        g = (c * inv2n) * (zs[:m] - zs[m : 2 * m])  # (m, k): S^-1 P_xz on the active columns
        nu = z - z_hat
        pzz = cov_z + r
        var = np.diag(pzz).copy()
        accepted = np.isfinite(nu) & (nu * nu <= gate_nis * var)
        n_acc = int(accepted.sum())
        scale = np.ones(k)
        if n_acc == 0:
            return UpdateResult(x0.copy(), p0.copy(), accepted, nu, var, math.nan, scale, 0, 0.0)
        idx = None if n_acc == k else np.flatnonzero(accepted)
        if idx is not None:
            sub = np.ix_(idx, idx)
            pzz, r_a, cov_a, g_a, nu_a, var_a = pzz[sub], r[sub], cov_z[sub], g[:, idx], nu[idx], var[idx]
        else:
            r_a, cov_a, g_a, nu_a, var_a = r, cov_z, g, nu, var
        robust = math.isfinite(huber_k) or (huber_k_positive is not None and math.isfinite(huber_k_positive))
        if robust:
            s_a = _huber_scales(nu_a, var_a, huber_k, huber_k_positive)
            if np.any(s_a > 1.0):
                d = np.sqrt(s_a)
                r_a = r_a * np.outer(d, d)
                pzz = cov_a + r_a
                if idx is None:
                    scale = s_a
                else:
                    scale[idx] = s_a
        # Cubature update (eq. 22-24) in the whitened active coordinates: x = x0 + L b.
        ch = np.linalg.cholesky(pzz)
        wn = np.linalg.solve(ch, nu_a)
        nis = float(wn @ wn)
        gain_w = np.linalg.solve(ch.T, np.linalg.solve(ch, g_a.T)).T  # G P_zz^-1, (m, k)
        b = gain_w @ nu_a
        lcg = lcols @ gain_w
        p_new = p0 - lcg @ pzz @ lcg.T
        omega = np.diag(cov_a) - np.einsum("ij,ij->j", g_a, g_a)
        nonlin = float(np.max(omega / np.diag(r_a)))
        iters = 0
        if max_iterations > 0 and nonlin > nonlinearity_threshold:
            b_map, iters, hl = self._gauss_newton(z if idx is None else z[idx], r_a, hx, lcols, b, max_iterations, idx)
            if iters:
                # covariance of the last linearisation (iterated EKF, Bell & Cathey 1993)
                s_l = hl @ hl.T + r_a
                lk = lcols @ np.linalg.solve(s_l, hl).T
                p_new = p0 - lk @ s_l @ lk.T
                b = b_map
        self.x = x0 + lcols @ b
        self.p = 0.5 * (p_new + p_new.T)
        return UpdateResult(self.x.copy(), self.p.copy(), accepted, nu, var, nis, scale, iters, nonlin)

    def _update_scalar(
        self, z, r, hx, gate_nis, lcols, g, z_hat, var_z, huber_k, huber_k_positive, max_iterations, threshold
    ) -> UpdateResult:
        """The update of :meth:`update` for one measurement, in floats (same equations)."""
        x0 = self.x
        p0 = self.p
        nu = z - z_hat
        s11 = var_z + r
        prior_var = s11
        if not (math.isfinite(nu) and nu * nu <= gate_nis * s11):
            return UpdateResult(
                x0.copy(),
                p0.copy(),
                np.array([False]),
                np.array([nu]),
                np.array([s11]),
                math.nan,
                np.ones(1),
                0,
                0.0,
            )
        scale = 1.0
        k_pos = huber_k if huber_k_positive is None else huber_k_positive
        thr = k_pos if nu > 0.0 else huber_k
        if math.isfinite(thr):
            e = abs(nu) / math.sqrt(s11)
            if e > thr:
                scale = e / thr
                r *= scale
                s11 = var_z + r
        nis = nu * nu / s11
        b = g * (nu / s11)
        lg = lcols @ g
        p_new = p0 - np.outer(lg, lg) * (1.0 / s11)
        nonlin = (var_z - float(g @ g)) / r
        iters = 0
        if max_iterations > 0 and nonlin > threshold:
            r_m = np.array([[r]])
            b_map, iters, hl = self._gauss_newton(np.array([z]), r_m, hx, lcols, b, max_iterations, None)
            if iters:
                h0 = hl[0]
                lh = lcols @ h0
                p_new = p0 - np.outer(lh, lh) * (1.0 / (float(h0 @ h0) + r))
                b = b_map
        self.x = x0 + lcols @ b
        self.p = 0.5 * (p_new + p_new.T)
        return UpdateResult(
            self.x.copy(),
            self.p.copy(),
            np.array([True]),
            np.array([nu]),
            np.array([prior_var]),
            nis,
            np.array([scale]),
            iters,
            nonlin,
        )

    def _gauss_newton(self, z, r, hx, lcols, b, max_iterations, idx):
        """Iterated (Gauss-Newton) refinement in whitened coordinates ``x = x_prior + L b``.

        Minimises ``b^T b + (z - h(x))^T R^-1 (z - h(x))`` from ``b``; returns the final ``b``,
        the number of steps that lowered the cost (each step is halved up to four times until it
        does) and ``H L`` at the final point, shape (k, m).
        """
        x0 = self.x
        m = lcols.shape[1]
        n = self.n
        r_chol = np.linalg.cholesky(r)
        eps = 0.01  # central-difference step, in prior standard deviations
        steps = eps * lcols.T
        pts = np.empty((2 * m + 1, n))

        def evaluate(bb):
            xc = x0 + lcols @ bb
            pts[:m] = xc + steps
            pts[m : 2 * m] = xc - steps
            pts[2 * m] = xc
            zz = hx(pts)
            if idx is not None:
                zz = zz[:, idx]
            hl = (zz[:m] - zz[m : 2 * m]).T * (0.5 / eps)  # (k, m): H L
            res = z - zz[2 * m]
            wres = np.linalg.solve(r_chol, res) if res.size > 1 else res / r_chol[0]
            return hl, res, float(bb @ bb + wres @ wres)

        hl, res, cost = evaluate(b)
        iters = 0
        for _ in range(max_iterations):
            if res.size == 1:
                h0 = hl[0]
                b_new = h0 * (float(res[0] + h0 @ b) / float(h0 @ h0 + r[0, 0]))
            else:
                b_new = hl.T @ np.linalg.solve(hl @ hl.T + r, res + hl @ b)
            hl_n, res_n, cost_n = evaluate(b_new)
            halvings = 0
            while not cost_n <= cost and halvings < 4:
                b_new = 0.5 * (b + b_new)
                hl_n, res_n, cost_n = evaluate(b_new)
                halvings += 1
            if not cost_n <= cost:
                break
            iters += 1
            moved = float(np.max(np.abs(b_new - b)))
            b, hl, res, cost = b_new, hl_n, res_n, cost_n
            if moved < 1e-4:
                break
        return b, iters, hl


def _measurement_moments(zs: np.ndarray, m: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance (without noise) of the measurements ``zs`` of the ``2 m`` cubature points of
    the leading ``m`` components and, when ``m < n``, the centre point standing for the other ``2 (n -
    m)`` (Cao et al., eq. 19-20; weights ``1 / 2n``)."""
    inv2n = 1.0 / (2 * n)
    zp = zs[:m]
    zm = zs[m : 2 * m]
    if m < n:
        zc = zs[2 * m]
        z_hat = (zp.sum(axis=0) + zm.sum(axis=0) + (2 * (n - m)) * zc) * inv2n
        dz = zs - z_hat
        dc = dz[2 * m]
        return z_hat, (dz[: 2 * m].T @ dz[: 2 * m] + (2 * (n - m)) * np.outer(dc, dc)) * inv2n
    z_hat = (zp.sum(axis=0) + zm.sum(axis=0)) * inv2n
    dz = zs - z_hat
    return z_hat, (dz.T @ dz) * inv2n


def _huber_scales(nu: np.ndarray, var: np.ndarray, huber_k: float, huber_k_positive: float | None) -> np.ndarray:
    """Huber noise factors ``|e| / k`` of the normalised innovations ``e = nu / sqrt(var)`` beyond the
    threshold (``huber_k_positive`` for positive ones, None: ``huber_k``), 1 elsewhere (module docstring)."""
    e = nu / np.sqrt(var)
    k_pos = huber_k if huber_k_positive is None else huber_k_positive
    thr = np.where(e > 0.0, k_pos, huber_k)
    return np.where(np.abs(e) > thr, np.abs(e) / thr, 1.0)


def _active_cubature_points(x0: np.ndarray, lcols: np.ndarray, c: float) -> np.ndarray:
    """The cubature points ``x0 +- c L_j`` along the ``m`` columns ``lcols`` (n, m) of the prior's square
    root, and ``x0`` itself standing for the other ``2 (n - m)`` when ``m < n`` (Cao et al., eq. 17-18)."""
    n, m = lcols.shape
    pts = np.empty((2 * m + (1 if m < n else 0), n))
    step = c * lcols.T
    pts[:m] = x0 + step
    pts[m : 2 * m] = x0 - step
    if m < n:
        pts[2 * m] = x0
    return pts


def _scalar_moments(z1: np.ndarray, m: int, n: int, c: float) -> tuple[float, float, np.ndarray]:
    """:func:`_measurement_moments` of one measurement in Python floats, and ``G`` (``S^-1 P_xz`` on the
    active columns, (m,)): ``(z_hat, var(Z), G)``."""
    inv2n = 1.0 / (2 * n)
    zp1 = z1[:m]
    zm1 = z1[m : 2 * m]
    n_c = 2 * (n - m)
    zc1 = float(z1[2 * m]) if m < n else 0.0
    zh = (float(zp1.sum()) + float(zm1.sum()) + n_c * zc1) * inv2n
    d1 = z1[: 2 * m] - zh
    var_z = (float(d1 @ d1) + n_c * (zc1 - zh) ** 2) * inv2n
    return zh, var_z, (c * inv2n) * (zp1 - zm1)
