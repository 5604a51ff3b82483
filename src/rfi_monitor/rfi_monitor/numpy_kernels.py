"""Compiled (numba) versions of the numpy reductions the ridge analysis (``rfi_monitor.ridge``) uses inside its
compiled stages, in numpy's own arithmetic order, so that a compiled stage gives to the bit what the numpy expression
it replaced gave (issue 14 item 6, issue 26 item 2): the pairwise sum, the first argmax, the linearly interpolated
quantile and the median of a sorted vector, np.polyfit and np.polyval, and the k-th smallest value of each column of a
matrix (np.partition).
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


@njit(cache=True, inline="always")
def _partition_at(a: np.ndarray, left: int, right: int, k: int) -> int:
    """Floyd and Rivest's partition step: a[left .. right] split about t = a[k] (Hoare's scheme); returns t's place j
    (a[left .. j - 1] <= t <= a[j + 1 .. right])."""
    t = a[k]
    a[left], a[k] = a[k], a[left]
    if a[right] > t:
        a[right], a[left] = a[left], a[right]
    i, j = left, right
    while i < j:
        a[i], a[j] = a[j], a[i]
        i += 1
        j -= 1
        while a[i] < t:
            i += 1
        while a[j] > t:
            j -= 1
    if a[left] == t:
        a[left], a[j] = a[j], a[left]
    else:
        j += 1
        a[j], a[right] = a[right], a[j]
    return j


@njit(cache=True)
def _select(a: np.ndarray, k: int) -> Any:
    """The k-th smallest value (0-based) of a NaN-free vector, which it reorders: Floyd and Rivest's SELECT (1975),
    its sample step (ranges over 200 values) done by a plain selection instead of a recursion."""
    left, right = 0, a.size - 1
    while right > left:
        if right - left > 200:
            n = right - left + 1
            i = k - left + 1
            z = math.log(n)
            s = 0.5 * math.exp(2.0 * z / 3.0)
            sd = 0.5 * math.sqrt(z * s * (n - s) / n) * (1.0 if i - n / 2 >= 0 else -1.0)
            lo2 = max(left, int(k - i * s / n + sd))
            hi2 = min(right, int(k + (n - i) * s / n + sd))
            while hi2 > lo2:
                j = _partition_at(a, lo2, hi2, k)
                if j <= k:
                    lo2 = j + 1
                if k <= j:
                    hi2 = j - 1
        j = _partition_at(a, left, right, k)
        if j <= k:
            left = j + 1
        if k <= j:
            right = j - 1
    return a[k]


@njit(cache=True)
def column_order_statistic(S: np.ndarray, k: int) -> np.ndarray:
    """``np.partition(S.T, k, axis=1)[:, k]`` of a 2-D float array (the k-th smallest value of each column, 0-based;
    NaN where fewer than k + 1 values of the column are not NaN, as numpy's NaN-last order gives). The value is unique
    whatever the algorithm (a selection by Floyd and Rivest's SELECT here), so the result is numpy's to the bit."""
    nfr, B = S.shape
    q = np.empty(B, dtype=S.dtype)
    col = np.empty(nfr, dtype=S.dtype)
    for b in range(B):
        m = 0
        for t in range(nfr):
            v = S[t, b]
            if v == v:
                col[m] = v
                m += 1
        q[b] = _select(col[:m], k) if k < m else np.nan
    return q
