"""Compiled (numba) versions of the numpy reductions the ridge analysis (``rfi_monitor.ridge``) uses inside its
compiled stages, in numpy's own arithmetic order, so that a compiled stage gives to the bit what the numpy expression
it replaced gave (issue 14 item 6, issue 26 item 2): the pairwise sum, the first argmax, the linearly interpolated
quantile and the median of a sorted vector, a low and a high quantile of an unsorted one, np.polyfit and np.polyval,
and the k-th smallest value of each column of a float32 matrix (np.partition).
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
    if n > 128:
        n2 = n // 2
        n2 -= n2 % 8
        return pairwise_sum(a[:n2], zero) + pairwise_sum(a[n2:], zero)
    return pairwise_sum_short(a, zero)


@njit(cache=True, inline="always")
def pairwise_sum_short(a: np.ndarray, zero: Any) -> Any:
    """``pairwise_sum`` of a vector of at most 128 values (no halving: numpy's 8 partial sums, then the rest in
    order), inlined where it is called: the same sum to the bit, without a call per short row."""
    n = a.size
    if n < 8:
        res = zero
        for i in range(n):
            res += a[i]
        return res
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
def _smallest_sorted(v: np.ndarray, n: int, m: int, sign: float) -> np.ndarray:
    """The m smallest of sign * v[:n] (NaN-free, 1 <= m <= n), in ascending order: a sorted buffer that a value
    enters only when it is below the buffer's largest (after the first m values, rarely: a well predicted branch)."""
    buf = np.empty(m)
    for i in range(m):
        x = sign * v[i]
        j = i
        while j > 0 and buf[j - 1] > x:
            buf[j] = buf[j - 1]
            j -= 1
        buf[j] = x
    for i in range(m, n):
        x = sign * v[i]
        if x < buf[m - 1]:
            j = m - 1
            while j > 0 and buf[j - 1] > x:
                buf[j] = buf[j - 1]
                j -= 1
            buf[j] = x
    return buf


@njit(cache=True)
def quantile_pair(v: np.ndarray, n: int, q_lo: float, q_hi: float) -> tuple[float, float]:
    """(np.percentile(v[:n], 100 q_lo), np.percentile(v[:n], 100 q_hi)) (method "linear") of a NaN-free vector,
    n >= 1, q_lo <= 0.5 <= q_hi: ``quantile_sorted`` of the sorted vector, each from the two order statistics it
    interpolates, found among the few smallest (largest) values (``_smallest_sorted``) instead of by a sort of all
    n (whose branches on the values mispredict). The same values, so the same result to the bit."""
    lo_i = min(int(math.floor((n - 1) * q_lo)), n - 1)
    lo_m = min(lo_i + 2, n)
    s = _smallest_sorted(v, n, lo_m, 1.0)
    vi = (n - 1) * q_lo
    lo = float(s[n - 1]) if vi >= n - 1 else lerp(float(s[lo_i]), float(s[lo_i + 1]), vi - lo_i)
    vi = (n - 1) * q_hi
    hi_i = min(int(math.floor(vi)), n - 1)
    # ascending place p is the (n - 1 - p)-th largest: the largest values, negated, in ascending order
    g = _smallest_sorted(v, n, n - hi_i, -1.0)
    hi = -float(g[0]) if vi >= n - 1 else lerp(-float(g[n - 1 - hi_i]), -float(g[n - 2 - hi_i]), vi - hi_i)
    return lo, hi


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
def _order_key(x: Any) -> Any:
    """The bits of a float32 (given as its uint32 view) mapped to an integer of the same order as the values
    (negative values' bits inverted, positive values' sign bit set): the radix-sort key of a float."""
    return np.int64(x ^ (np.uint32(0xFFFFFFFF) if (x >> np.uint32(31)) else np.uint32(0x80000000)))


@njit(cache=True)
def _kth_of_few(a: np.ndarray, m: int, r: int) -> Any:
    """The r-th smallest (0-based) of a[:m], NaN-free, by counting each value's rank (ties ranked by place): no
    branch that depends on the data, for the few values of a histogram bucket."""
    res = a[0]
    for i in range(m):
        ai = a[i]
        c = 0
        for j in range(i):
            c += a[j] <= ai
        for j in range(i + 1, m):
            c += a[j] < ai
        res = ai if c == r else res
    return res


_SELECT_BUCKETS = 512
"""column_order_statistic: at most this many histogram buckets over the matrix's range of keys."""


@njit(cache=True)
def column_order_statistic(S: np.ndarray, k: int) -> np.ndarray:
    """``np.partition(S.T, k, axis=1)[:, k]`` of a 2-D float32 array (the k-th smallest value of each column, 0-based;
    NaN where fewer than k + 1 values of the column are not NaN, as numpy's NaN-last order gives). The value is unique
    whatever the algorithm, so the result is numpy's to the bit (a zero's sign aside).

    A histogram select, whose passes run along the rows with no branch that depends on the data (a selection by
    partitioning, Floyd and Rivest's, cost 3-4 times its time on data it had not seen, its branches mispredicted;
    issue 26 item 2): each value's order key (``_order_key``); the matrix's range of keys cut into at most
    ``_SELECT_BUCKETS`` buckets; a histogram per column, whose cumulative count gives the bucket that holds the k-th
    value and how many lie below it; the values of that bucket (a few: the bucket spans ~1/30 of the range) gathered
    and the right one picked among them."""
    nfr, B = S.shape
    q = np.empty(B, dtype=S.dtype)
    u = S.view(np.uint32)
    kmin = np.int64(0xFFFFFFFF)
    kmax = np.int64(0)
    for t in range(nfr):
        for b in range(B):
            v = S[t, b]
            key = _order_key(u[t, b])
            kmin = min(kmin, key if v == v else np.int64(0xFFFFFFFF))
            kmax = max(kmax, key if v == v else np.int64(0))
    if kmin > kmax or k >= nfr:
        q[:] = np.nan
        return q
    sh = 0
    while ((kmax - kmin) >> sh) >= _SELECT_BUCKETS:
        sh += 1
    nb = ((kmax - kmin) >> sh) + 1                       # NaN: bucket nb, after all others
    hist = np.zeros((nb + 1, B), dtype=np.int32)
    for t in range(nfr):
        for b in range(B):
            v = S[t, b]
            hist[((_order_key(u[t, b]) - kmin) >> sh) if v == v else nb, b] += 1
    cum = np.zeros(B, dtype=np.int64)
    bucket = np.zeros(B, dtype=np.int64)
    below = np.zeros(B, dtype=np.int64)
    for j in range(nb + 1):
        for b in range(B):
            c = cum[b] + hist[j, b]
            bucket[b] += 1 if c <= k else 0
            below[b] = c if c <= k else below[b]
            cum[b] = c
    buf = np.empty(nfr, dtype=S.dtype)
    for b in range(B):
        if bucket[b] >= nb:
            q[b] = np.nan
            continue
        m = 0
        for t in range(nfr):
            v = S[t, b]
            buf[m] = v
            m += 1 if (v == v and ((_order_key(u[t, b]) - kmin) >> sh) == bucket[b]) else 0
        r = k - below[b]
        q[b] = _kth_of_few(buf, m, r) if m <= 40 else np.sort(buf[:m])[r]
    return q


MEDIAN_NEAREST, MEDIAN_WRAP, MEDIAN_REFLECT = 0, 1, 2
"""running_median's modes: scipy.ndimage's "nearest", "wrap" and "reflect"."""


@njit(cache=True, nogil=True)
def running_median(x: np.ndarray, width: int, mode: int) -> np.ndarray:
    """``scipy.ndimage.median_filter(x, size=width, mode=...)`` of a finite vector: the element of rank width // 2 of
    the width values from width // 2 before each bin to width - 1 - width // 2 after it, the ends extended by mode:
    ``MEDIAN_NEAREST`` (the end bins repeated), ``MEDIAN_WRAP`` (periodically) or ``MEDIAN_REFLECT`` (mirrored about
    the end bins' outer edges: d c b a | a b c d | d c b a). A sorted window slid over the vector (one removal and one
    insertion per bin, O(width) a bin): an exact selection, the same values as scipy's."""
    n = x.size
    h = width // 2
    out = np.empty(n)
    buf = np.empty(width)

    def at(i: int) -> float:
        if mode == MEDIAN_NEAREST:
            return x[min(max(i, 0), n - 1)]
        if mode == MEDIAN_WRAP:
            return x[i % n]
        while i < 0 or i >= n:                       # mirror about the outer edges (repeatedly for short x)
            i = -i - 1 if i < 0 else 2 * n - i - 1
        return x[i]

    for k in range(width):                           # the first window, sorted by insertion
        v = at(k - h)
        j = k
        while j > 0 and buf[j - 1] > v:
            buf[j] = buf[j - 1]
            j -= 1
        buf[j] = v
    out[0] = buf[h]
    for i in range(1, n):
        old = at(i - 1 - h)                          # leaves the window
        new = at(i - 1 - h + width)                  # enters it
        j = 0
        while buf[j] != old:                         # the outgoing value (present: it entered before)
            j += 1
        while j < width - 1 and buf[j + 1] < new:    # shift the larger ones down over it
            buf[j] = buf[j + 1]
            j += 1
        while j > 0 and buf[j - 1] > new:            # or the smaller ones up
            buf[j] = buf[j - 1]
            j -= 1
        buf[j] = new
        out[i] = buf[h]
    return out
