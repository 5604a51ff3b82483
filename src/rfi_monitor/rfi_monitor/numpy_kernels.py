"""Compiled (numba) versions of the numpy reductions the ridge analysis (``rfi_monitor.ridge``) uses inside its
compiled stages, in numpy's own arithmetic order, so that a compiled stage gives to the bit what the numpy expression
it replaced gave (issue 14 item 6, issue 26 item 2): the pairwise sum, the first argmax, the linearly interpolated
quantile and the median of a sorted vector, np.polyfit and np.polyval.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit


@njit(cache=True)
def pairwise_sum(a: np.ndarray, zero: Any) -> Any:
    """Sum of a contiguous float32 or float64 vector in its own precision and in numpy's pairwise order (numpy's
    ``add.reduce`` over a contiguous axis: 8 partial sums, combined in pairs, the rest in order; halves above 128), so
    that a compiled sum equals the numpy expression it replaced to the bit. zero: 0 of a's type (``np.float32(0.0)``
    or ``0.0``), the start of the short sums (one kernel for both precisions, compiled once for each); the sum has
    a's type."""
    n = a.size
    if n < 8:
        res = zero
        for i in range(n):
            res += a[i]
        return res
    if n > 128:
        n2 = n // 2
        n2 -= n2 % 8
        return pairwise_sum(a[:n2], zero) + pairwise_sum(a[n2:], zero)
    r0, r1, r2, r3, r4, r5, r6, r7 = a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]
    i = 8
    while i < n - (n % 8):
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[i]
        i += 1
    return res


@njit(cache=True)
def first_argmax(r: np.ndarray, lo: int, hi: int) -> int:
    """Index of the first largest of r[lo .. hi] (np.argmax)."""
    j = lo
    for i in range(lo + 1, hi + 1):
        if r[i] > r[j]:
            j = i
    return j


@njit(cache=True)
def lerp(a: float, b: float, t: float) -> float:
    """numpy's quantile interpolation between neighbours (numpy.lib._function_base_impl._lerp)."""
    d = b - a
    if t >= 0.5:
        return b - d * (1.0 - t)
    return a + d * t


@njit(cache=True)
def quantile_sorted(v: np.ndarray, q: float) -> float:
    """np.percentile(v, 100 q) (method "linear") of a sorted, non-empty, NaN-free vector."""
    n = v.size
    vi = (n - 1) * q
    if vi >= n - 1:
        return float(v[n - 1])
    i = int(math.floor(vi))
    return lerp(float(v[i]), float(v[i + 1]), vi - i)


@njit(cache=True)
def median_sorted(v: np.ndarray) -> float:
    """np.median of a non-empty, NaN-free vector (sorted here: the middle value, or the mean of the two)."""
    s = np.sort(v)
    h = s.size // 2
    return float(s[h]) if s.size % 2 else (s[h - 1] + s[h]) / 2.0


@njit(cache=True)
def polyval(coef: np.ndarray, x: float) -> float:
    """np.polyval of one point (Horner, highest power first)."""
    y = 0.0
    for c in coef:
        y = y * x + c
    return y


@njit(cache=True)
def polyfit(x: np.ndarray, y: np.ndarray, deg: int) -> np.ndarray:
    """np.polyfit(x, y, deg): the Vandermonde columns scaled to unit norm, least squares (LAPACK gelsd, rcond
    n eps), the scale taken back out. Highest power first."""
    n = x.size
    order = deg + 1
    A = np.empty((n, order))
    for i in range(n):
        v = 1.0
        A[i, order - 1] = 1.0
        for j in range(order - 2, -1, -1):
            v = v * x[i]
            A[i, j] = v
    scale = np.zeros(order)
    for i in range(n):
        for j in range(order):
            scale[j] += A[i, j] * A[i, j]
    for j in range(order):
        scale[j] = math.sqrt(scale[j])
    for i in range(n):
        for j in range(order):
            A[i, j] /= scale[j]
    c = np.linalg.lstsq(A, y.copy(), n * 2.220446049250313e-16)[0]
    return c / scale
