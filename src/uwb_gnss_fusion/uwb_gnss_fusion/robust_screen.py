"""Common-mode innovation screen: find gross GNSS outliers before the CKF update sees them.

Beyond Cao et al.: the paper's filter applies every pseudorange and pseudorange rate, and its
Sec. 4 observes that after jamming outliers the filter "struggles to return to a normal level of
positioning accuracy". Per-measurement chi-square gating on the CKF innovation (``ckf.update``)
catches large outliers, but its innovation variance ``P_zz[i, i]`` contains the receiver clock
bias (drift) variance, which a crystal clock makes metres (m/s) after a fraction of a second.
An outlier of a few tens of metres on one pseudorange (a few m/s on one rate) then passes the gate,
moves the clock, and through the clock-height correlation the height and the vertical velocity;
with a static receiver and nearly coplanar UWB anchors the vertical velocity error integrates for
seconds (measured in docs/uwb_gnss_fusion/fusion_jamming.md).

The clock term is common to all satellites of an epoch, so it cancels in the difference between
an innovation and the epoch's median innovation (a robust estimate of the common clock innovation
that one outlier, or a minority of them, cannot move). What remains is tested against the
clock-free variance:

    nu_i = z_i - h_i(x^-)                        innovation at the predicted state (eq. 5 or 6)
    c    = median_i(nu_i)                          common-mode (clock) innovation
    keep_i  <=>  (nu_i - c)^2 <= g * (R_i + e_i^T P e_i + pi/2 * median(R) / n)

with ``e_i`` the unit line of sight (receiver to satellite), ``P`` the predicted position (for
rates: velocity) covariance, ``g`` the 1-dof chi-square gate and the last term the variance of the
median of ``n`` residuals (asymptotic, ``pi sigma^2 / (2 n)``). Fewer than ``min_count``
measurements leave nothing to compare with: all are kept (the CKF gate still applies). This is
the residual test of receiver autonomous integrity monitoring (RAIM, Parkinson & Axelrad 1988)
with the clock removed by the median instead of by a least-squares fit, so that the outlier does
not pull its own reference.
"""

from __future__ import annotations

import math

import numpy as np

#: variance of the median of n iid N(0, s^2) residuals is about (pi / 2) s^2 / n
_MEDIAN_VARIANCE_FACTOR = math.pi / 2.0


def _median(a: np.ndarray) -> float:
    """Median of a short 1-D array (np.median's overhead is ~10 us; a sort of a dozen values ~1 us)."""
    s = np.sort(a)
    k = s.size // 2
    return float(s[k]) if s.size % 2 else 0.5 * (float(s[k - 1]) + float(s[k]))


def projected_variance(line_of_sight: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """``e_i^T P e_i`` for each row of ``line_of_sight``.

    Args:
        line_of_sight: unit vectors receiver -> satellite, shape (n, 3).
        covariance: 3x3 position (m^2) or velocity ((m/s)^2) covariance.

    Returns:
        shape (n,), same unit as ``covariance``.
    """
    e = np.asarray(line_of_sight, dtype=float)
    p = np.asarray(covariance, dtype=float)
    return np.einsum("ij,jk,ik->i", e, p, e)


def common_mode_screen(innovation: np.ndarray, variance: np.ndarray, gate_nis: float,
                       min_count: int = 3) -> np.ndarray:
    """Keep mask of the common-mode innovation screen (module docstring).

    Args:
        innovation: ``z_i - h_i(x^-)`` of one epoch's pseudoranges (m) or rates (m/s), shape (n,).
        variance: clock-free innovation variance ``R_i + e_i^T P e_i`` of each, same unit squared,
            shape (n,), > 0.
        gate_nis: 1-dof chi-square threshold (``FusionParams.gate_nis``); ``inf`` keeps all.
        min_count: fewest finite innovations for the test, >= 3.

    Returns:
        bool shape (n,): True where the measurement is consistent with the others. Non-finite
        innovations are never kept.

    Raises:
        ValueError: shapes differ, a variance is not positive, or min_count < 3.
    """
    nu = np.asarray(innovation, dtype=float)
    var = np.asarray(variance, dtype=float)
    if nu.shape != var.shape or nu.ndim != 1:
        raise ValueError(f"innovation and variance must be 1-D of one shape, got {nu.shape} and {var.shape}")
    if min_count < 3:
        raise ValueError(f"min_count must be >= 3, got {min_count}")
    finite = np.isfinite(nu)
    if np.any(~(var[finite] > 0.0)):
        raise ValueError("variances must be > 0")
    n = int(finite.sum())
    if n < min_count or math.isinf(gate_nis):
        return finite
    med = _median(nu[finite])
    var_med = _MEDIAN_VARIANCE_FACTOR * _median(var[finite]) / n
    d = np.where(finite, nu - med, math.inf)
    return d * d <= gate_nis * (var + var_med)
