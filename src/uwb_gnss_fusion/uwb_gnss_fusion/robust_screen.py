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
an innovation and a robust estimate ``c`` of the common clock innovation. What remains is tested
against the clock-free variance:

    nu_i = z_i - h_i(x^-)                        innovation at the predicted state (eq. 5 or 6)
    V_i  = R_i + e_i^T P e_i                      its clock-free variance
    keep_i  <=>  (nu_i - c)^2 <= g * (V_i + V_c)

with ``e_i`` the unit line of sight (receiver to satellite), ``P`` the predicted position (for
rates: velocity) covariance, ``g`` the 1-dof chi-square gate and ``V_c`` the variance of ``c``.
``c`` is the inverse-variance mean of the largest set of mutually consistent innovations (a
one-dimensional consensus, every innovation tried as the seed, then refined on the kept set; see
:func:`common_mode_screen`). Until issue 15 it was the epoch's median, which one outlier cannot
move but two can when only 4-6 satellites are tracked (30 dB J/S): with 2 outliers among 4, the
median rejected 41 % of the good pseudoranges in a Monte Carlo of the screen alone, the consensus
2.9 % (``test_robust_screen.py``). Fewer than ``min_count`` measurements leave nothing to compare
with: all are kept (the CKF gate still applies). This is the residual test of receiver autonomous
integrity monitoring (RAIM, Parkinson & Axelrad 1988) with the clock removed by a consensus instead
of by a least-squares fit, so that outliers do not pull their own reference.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: variance of the median of n iid N(0, s^2) residuals is about (pi / 2) s^2 / n
_MEDIAN_VARIANCE_FACTOR = math.pi / 2.0

#: re-estimations of the common mode from the kept set (a consensus may hold one marginal outlier)
_MAX_REFINEMENTS = 4


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
    """Keep mask of the common-mode innovation screen, by consensus (module docstring).

    Steps: (1) two innovations are *compatible* when ``(nu_i - nu_j)^2 <= g (V_i + V_j)``; (2) the
    largest set of innovations compatible with one of them is the consensus (ties between different
    sets: the one whose reference lies closest to the epoch's median innovation); (3) the common
    mode ``c`` is the inverse-variance mean of the consensus, variance ``V_c = 1 / sum(1/V_i)``;
    (4) keep ``i`` where ``(nu_i - c)^2 <= g (V_i + V_c)``, then re-estimate ``c`` and ``V_c`` from
    the kept set and repeat until the set is stable (at most four times), so that a marginal outlier
    inside the consensus does not pull the reference. Unlike the median, the consensus is not
    moved by two or more outliers as long as the consistent satellites outnumber each group of
    mutually consistent outliers (RANSAC-style consensus, Fischler & Bolles 1981, in one dimension:
    every innovation is a candidate, so no random sampling is needed). Where no two innovations
    agree, the epoch's median is the reference, with variance ``pi/2 median(V) / n``.

    Args:
        innovation: ``z_i - h_i(x^-)`` of one epoch's pseudoranges (m) or rates (m/s), shape (n,).
        variance: clock-free innovation variance ``V_i = R_i + e_i^T P e_i`` of each, same unit
            squared, shape (n,), > 0.
        gate_nis: 1-dof chi-square threshold ``g`` (``FusionParams.gate_nis``); ``inf`` keeps all.
        min_count: fewest finite innovations for the test, >= 3.

    Returns:
        bool shape (n,): True where the measurement is consistent with the consensus. Non-finite
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
    return _consensus_keep(nu, var, float(gate_nis))


@njit(cache=True)
def _median_sorted(a: np.ndarray) -> float:
    s = np.sort(a)
    k = s.size // 2
    return s[k] if s.size % 2 else 0.5 * (s[k - 1] + s[k])


@njit(cache=True)
def _consensus_keep(nu: np.ndarray, var: np.ndarray, gate: float) -> np.ndarray:
    """Steps (1)-(4) of :func:`common_mode_screen` (compiled: ~100 us in numpy, ~2 us here).
    Arguments are validated by the caller; non-finite innovations are never kept."""
    n_all = nu.size
    idx = np.empty(n_all, np.int64)
    n = 0
    for i in range(n_all):
        if np.isfinite(nu[i]):
            idx[n] = i
            n += 1
    x = np.empty(n)
    v = np.empty(n)
    for a in range(n):
        x[a] = nu[idx[a]]
        v[a] = var[idx[a]]
    med = _median_sorted(x)
    # (1)-(2): the largest compatible set; among equal sizes the reference closest to the median
    best = 0
    c = med
    var_c = 0.0
    for j in range(n):
        cnt = 0
        sw = 0.0
        swx = 0.0
        for i in range(n):
            d = x[i] - x[j]
            if d * d <= gate * (v[i] + v[j]):
                cnt += 1
                sw += 1.0 / v[i]
                swx += x[i] / v[i]
        ref = swx / sw
        if cnt > best or (cnt == best and abs(ref - med) < abs(c - med)):
            best = cnt
            c = ref
            var_c = 1.0 / sw
    keep = np.zeros(n_all, np.bool_)
    if best < 2:
        # no two innovations agree: the median is the only reference left (the former rule)
        var_c = _MEDIAN_VARIANCE_FACTOR * _median_sorted(v) / n
        for a in range(n):
            d = x[a] - med
            keep[idx[a]] = d * d <= gate * (v[a] + var_c)
        return keep
    # (3)-(4): gate against the consensus mean, re-estimate it from the kept set until stable
    for _ in range(_MAX_REFINEMENTS + 1):
        changed = False
        sw = 0.0
        swx = 0.0
        for a in range(n):
            d = x[a] - c
            k = d * d <= gate * (v[a] + var_c)
            if k != keep[idx[a]]:
                changed = True
            keep[idx[a]] = k
            if k:
                sw += 1.0 / v[a]
                swx += x[a] / v[a]
        if not changed or sw == 0.0:
            break
        c = swx / sw
        var_c = 1.0 / sw
    return keep
