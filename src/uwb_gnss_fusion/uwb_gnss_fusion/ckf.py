"""Cubature Kalman filter (third-degree spherical-radial rule) with per-measurement gating.

Generic and pure: the state, the models and the noise are passed in. The fusion filter uses it
on the 8-state error vector of Cao et al. (the models add the error to the nominal state).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

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
    """

    x: np.ndarray
    p: np.ndarray
    accepted: np.ndarray
    innovation: np.ndarray
    innovation_var: np.ndarray
    nis: float


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
        self, z: np.ndarray, r: np.ndarray, hx: MeasurementModel, gate_nis: float = np.inf
    ) -> UpdateResult:
        """Cubature measurement update with per-measurement innovation gating.

        Args:
            z: measurements, shape (k,).
            r: measurement noise covariance, shape (k, k) (or (k,) variances).
            hx: measurement model, points (2n, n) -> (2n, k).
            gate_nis: per-measurement threshold on ``nu_i^2 / P_zz[i, i]`` (a 1-dof chi-square
                quantile); measurements above it are excluded from this update. ``inf``: no gating.

        Returns:
            :class:`UpdateResult`; the filter's ``x`` and ``p`` are replaced by the posterior.

        Raises:
            CholeskyError: if the prior covariance is not positive definite.

        Notes:
            Cao et al., eq. 17-24 (Arasaratnam & Haykin 2009, eq. 33-42): points
            ``chi_i = x + S xi_i``, ``Z_i = h(chi_i)``, ``z_hat = mean Z_i``,
            ``P_zz = cov(Z) + R``, ``P_xz = cov(chi, Z)``, ``K = P_xz P_zz^-1``,
            ``x += K (z - z_hat)``, ``P -= K P_zz K^T``. Gating is beyond the paper: each
            measurement's innovation is tested under the prior (its marginal is independent of the
            other measurements), and the update is then computed with the accepted subset only.
        """
        z = np.asarray(z, dtype=float)
        r = np.asarray(r, dtype=float)
        if r.ndim == 1:
            r = np.diag(r)
        k = z.size
        s = robust_cholesky(self.p)
        dx = self._xi @ s.T
        pts = self.x[None, :] + dx
        zs = hx(pts)
        m = pts.shape[0]
        z_hat = zs.mean(axis=0)
        dz = zs - z_hat
        pzz = dz.T @ dz / m + r
        pxz = dx.T @ dz / m
        nu = z - z_hat
        if k == 1:
            var = pzz[0]
            s11 = float(var[0])
            nu0 = float(nu[0])
            ok = math.isfinite(nu0) and nu0 * nu0 <= gate_nis * s11
            accepted = np.array([ok])
            if not ok:
                return UpdateResult(self.x.copy(), self.p.copy(), accepted, nu, var, float("nan"))
            gain = pxz / s11
            nu_a = nu
            nis = nu0 * nu0 / s11
        else:
            var = np.diag(pzz).copy()
            accepted = np.isfinite(nu) & (nu * nu <= gate_nis * var)
            n_acc = int(accepted.sum())
            if n_acc == 0:
                return UpdateResult(self.x.copy(), self.p.copy(), accepted, nu, var, float("nan"))
            if n_acc < k:
                idx = np.flatnonzero(accepted)
                pzz = pzz[np.ix_(idx, idx)]
                pxz = pxz[:, idx]
                nu_a = nu[idx]
            else:
                nu_a = nu
            c = np.linalg.cholesky(pzz)
            gain = np.linalg.solve(c.T, np.linalg.solve(c, pxz.T)).T
            w = np.linalg.solve(c, nu_a)
            nis = float(w @ w)
        self.x = self.x + gain @ nu_a
        p = self.p - gain @ pzz @ gain.T
        self.p = 0.5 * (p + p.T)
        return UpdateResult(self.x.copy(), self.p.copy(), accepted, nu, var, nis)
