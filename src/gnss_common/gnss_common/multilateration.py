"""Tag position from ranges to three or more known anchors (UWB multilateration).

Pure core (no rclpy). One implementation for the two users: the fusion's initialisation and
re-anchoring (``uwb_gnss_fusion.initialisation``, the range model of Cao et al. eq. 7 solved for the
position alone) and the integrity monitor's kinematic test (``gnss_integrity.kinematics_test``).

* :func:`gauss_newton`: Gauss-Newton from one start, compiled (numba; LAPACK least squares as
  ``np.linalg.lstsq``, rcond 1e-9), with the fit's RMS residual;
* :func:`multilaterate`: from a guess, or multi-start without one (three anchors leave two mirror
  solutions and local minima; the start with the smallest residual wins), refused above a residual.

Positions in any Cartesian frame (ECEF or a local map), m.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

MAX_FIT_RMS_M = 1.0
"""Default refusal bound of :func:`multilaterate`: a solution that fits the ranges worse than this
(m, RMS) is no solution (an NLOS range, a moved anchor, a local minimum)."""


@njit(cache=True)
def gauss_newton(anchors: np.ndarray, ranges: np.ndarray, start: np.ndarray, max_iterations: int,
                 step_tol_m: float) -> tuple[np.ndarray, bool, float]:
    """Gauss-Newton on ``|x - a_j| = r_j`` from ``start``.

    Args:
        anchors: anchor positions, m, (k, 3). ranges: measured ranges, m, (k,).
        start: first iterate, m, (3,). max_iterations: at most this many steps; stop when the step's
        norm is below ``step_tol_m`` (m).

    Returns:
        ``(x (3,), ok, fit RMS m)``: ok False when an iterate meets an anchor, or a range, a row or
        the solution is not finite (then the RMS is NaN).
    """
    k = anchors.shape[0]
    x = start.copy()
    h = np.empty((k, 3))
    r = np.empty(k)
    for _ in range(max_iterations):
        for j in range(k):
            d2 = 0.0
            for i in range(3):
                h[j, i] = x[i] - anchors[j, i]
                d2 += h[j, i] * h[j, i]
            dist = math.sqrt(d2)
            if not dist > 1e-9:
                return x, False, math.nan
            for i in range(3):
                h[j, i] = h[j, i] / dist
            r[j] = ranges[j] - dist
        for j in range(k):
            if not (math.isfinite(r[j]) and math.isfinite(h[j, 0]) and math.isfinite(h[j, 1])
                    and math.isfinite(h[j, 2])):
                return x, False, math.nan  # LAPACK's SVD does not converge on these: no solution
        step = np.linalg.lstsq(h, r, 1e-9)[0]
        x = x + step
        if math.sqrt(np.dot(step, step)) < step_tol_m:
            break
    if not (math.isfinite(x[0]) and math.isfinite(x[1]) and math.isfinite(x[2])):
        return x, False, math.nan
    sq = 0.0
    for j in range(k):
        d2 = 0.0
        for i in range(3):
            d2 += (x[i] - anchors[j, i]) ** 2
        fit = ranges[j] - math.sqrt(d2)
        sq += fit * fit
    return x, True, math.sqrt(sq / k)


def multilaterate(anchors: np.ndarray, ranges: np.ndarray, guess: np.ndarray | None = None, *,
                  max_iterations: int = 20, step_tol_m: float = 1e-6,
                  max_rms_m: float = MAX_FIT_RMS_M) -> np.ndarray | None:
    """The tag position, m, (3,), or None (fewer than three anchors, or no start that fits the
    ranges within ``max_rms_m`` RMS).

    With ``guess`` (e.g. the state, which keeps the solution on its side of a flat anchor cluster)
    one start; without, multi-start: the anchors' centroid and the centroid moved by the mean range
    along +-x and +-y of the frame (the tag is usually around the anchors, not at their centroid),
    keeping the smallest residual. A single start from the centroid converged to a local minimum
    12 m from the tag on the Hanyang NLOS case.
    """
    a = np.ascontiguousarray(anchors, dtype=float)
    r = np.ascontiguousarray(ranges, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] < 3 or r.shape != (a.shape[0],):
        return None
    if guess is not None:
        starts = [np.asarray(guess, dtype=float).reshape(3).copy()]
    else:
        c = a.mean(axis=0)
        rm = float(np.mean(r))
        starts = [c + np.array([0.1, 0.1, 0.0])] + [
            c + rm * np.array(u) for u in ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0))]
    best: tuple[float, np.ndarray] | None = None
    for x0 in starts:
        x, ok, rms = gauss_newton(a, r, x0, max_iterations, step_tol_m)
        if ok and (best is None or rms < best[0] - 1e-9):
            best = (rms, x)
    if best is None or not best[0] <= max_rms_m:
        return None
    return best[1]


def warm_up() -> None:
    """Compile (or load from numba's cache) :func:`gauss_newton` (a node calls it before subscribing)."""
    anchors = np.array([[10.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 10.0]])
    gauss_newton(anchors, np.full(3, 10.0), np.ones(3), 8, 1e-4)
