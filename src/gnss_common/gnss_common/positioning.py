"""Least-squares receiver position (and velocity) from ranges: the one implementation.

Every snapshot solver of the suite (the measurement builder's coarse fix, SPP, the fusion filter's
initialisation) linearises the same model, Cao et al., eq. 5,

    y_i = |p_i - p_r| + c dt_r + e_i,      H_i = [-u_i^T, 1]

(u_i the unit vector from the receiver to satellite i; the callers choose how |p_i - p_r| treats
Earth rotation and the atmosphere, and the weights) and solves it by Gauss-Newton with the weighted
normal equations. The velocity and clock drift follow from eq. 6 with the same H, in one linear
step (:func:`weighted_least_squares`).

Notes
-----
Kaplan & Hegarty 3rd ed., sec. 11.2.1 (iterated least squares), eq. 11.40-11.45 (weighted
solution and its covariance (H^T W H)^-1).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

CONVERGED = "converged"
NOT_CONVERGED = "not_converged"
SINGULAR = "singular"

RangeModel = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]
"""model(x) for x = [x, y, z, c dt] (m) -> (predicted y (N,) m, unit vectors u (N, 3), weights (N,) 1/m^2)."""


@dataclass(frozen=True)
class PositionSolution:
    """Result of :func:`least_squares_position`.

    Attributes:
        status: ``converged``, ``not_converged`` (iteration cap) or ``singular``.
        x: ``[x, y, z, c dt]`` after the last step, m (the last finite iterate when singular).
        covariance: ``(H^T W H)^-1`` of the last linearisation, m^2, (4, 4) (NaN when singular).
        h: design matrix of the last linearisation, (N, 4).
        weights: weights of the last linearisation, 1/m^2, (N,).
        iterations: linearisations done.
    """

    status: str
    x: np.ndarray
    covariance: np.ndarray
    h: np.ndarray
    weights: np.ndarray
    iterations: int


def weighted_least_squares(
    h: np.ndarray, y: np.ndarray, w: np.ndarray, max_variance: float = np.inf
) -> tuple[np.ndarray, np.ndarray] | None:
    """One weighted least-squares solution ``(H^T W H)^-1 H^T W y`` and its covariance.

    Args:
        h: design matrix, (N, n).
        y: observations (or residuals), (N,).
        w: weights (inverse variances), (N,).
        max_variance: a covariance diagonal entry above this (or not finite and > 0) is singular.

    Returns:
        ``(solution (n,), covariance (n, n))``, or None when ``H^T W H`` cannot be inverted or the
        covariance fails the check.
    """
    nmat = h.T @ (h * w[:, None])
    try:
        cov = np.linalg.inv(nmat)
    except np.linalg.LinAlgError:
        return None
    dcov = np.diag(cov)
    if not (np.all(np.isfinite(dcov)) and np.all(dcov > 0.0)) or float(np.max(dcov)) > max_variance:
        return None
    return cov @ (h.T @ (w * y)), cov


def least_squares_position(
    model: RangeModel,
    y: np.ndarray,
    x0: np.ndarray,
    max_iterations: int,
    tolerance_m: float,
    max_variance_m2: float = 1.0e10,
) -> PositionSolution:
    """Gauss-Newton (iterated weighted least squares) for ``[x, y, z, c dt]``.

    Args:
        model: ``model(x) -> (predicted, u, w)`` evaluated at each iterate (see :data:`RangeModel`).
        y: observations, m, (N,), N >= 4.
        x0: starting point ``[x, y, z, c dt]``, m, (4,).
        max_iterations: linearisation cap, >= 1.
        tolerance_m: converged when the step's norm is below this, m.
        max_variance_m2: a larger covariance diagonal entry declares the geometry singular, m^2.

    Returns:
        :class:`PositionSolution`.

    Notes
    -----
    Linearised Cao et al., eq. 5: ``dx = (H^T W H)^-1 H^T W (y - h(x))``, ``H = [-u^T, 1]``.
    """
    x = np.asarray(x0, dtype=float).copy()
    n = y.shape[0]
    h = np.empty((n, 4))
    h[:, 3] = 1.0
    w = np.ones(n)
    nan_cov = np.full((4, 4), np.nan)
    for it in range(1, max_iterations + 1):
        pred, los, w = model(x)
        h[:, :3] = -los
        step = weighted_least_squares(h, y - pred, w, max_variance_m2)
        if step is None:
            return PositionSolution(SINGULAR, x, nan_cov, h, w, it)
        dx, cov = step
        x = x + dx
        if np.linalg.norm(dx) < tolerance_m:
            return PositionSolution(CONVERGED, x, cov, h, w, it)
    return PositionSolution(NOT_CONVERGED, x, cov, h, w, max_iterations)
