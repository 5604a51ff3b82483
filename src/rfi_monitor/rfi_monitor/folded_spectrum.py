"""The shape of a sweep too weak for the per-frame ridge, from the short-time spectrum folded on its period (ours;
called by ``rfi_monitor.ridge.analyse`` when the ridge's profile shows no shape, and by the monitor for a chirp found
by the evidence over blocks, whose comb gives the period).

``folded_shape``: the short-time spectrum averaged per phase of the period (synchronous averaging), the strongest bin
per phase bin where it stands out of noise (``_fold_kernel``), the same shape rule as the ridge's profile
(``rfi_monitor.sweep_shape._shape``); when too few phase bins stand out for it, the sweep law (saw-tooth up or down,
triangle) whose line through the whole folded map has the largest sum (``_line_shape``: K phase bins of z each sum to
sqrt(K) z; Bonferroni over the laws, and a margin over the other classes). The demo's chirp at J/S +6 dB (J/N -13 dB)
gets its shape so (real_jammers.md).
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
from numba import njit
from scipy.special import ndtri

from rfi_monitor.stft import stft_power
from rfi_monitor.sweep_shape import (
    SAWTOOTH_DOWN,
    SAWTOOTH_UP,
    SHAPE_BINS,
    SHAPE_UNKNOWN,
    TRIANGLE,
    TRIANGLE_SIDE,
    _shape,
)


class FoldParams(Protocol):
    """What ``folded_shape`` needs of ``rfi_monitor.ridge.RidgeParams`` (its attributes' meaning there)."""

    @property
    def frame_lengths(self) -> tuple[int, ...]: ...
    @property
    def hook_rate_ratio(self) -> float: ...


FOLD_HOPS = 8
"""folded_shape: the frame's hop is at most the period over this (the profile then has >= FOLD_HOPS phases)."""
FOLD_FALSE = 1e-3
"""folded_shape: chance that noise alone makes any of the folded profile's phase bins present."""


@njit(cache=True)
def _fold_sums(S: np.ndarray, kb: np.ndarray, K: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The sums the folded map is made of: per phase bin (of K; kb: each frame's) and frequency bin the sum of S over
    the phase bin's frames, shape (K, bins); the frames per phase bin, (K,); per frequency bin the sum of S and of
    S^2 over all frames, (bins,) each (float64, in frame order)."""
    nfr, B = S.shape
    M = np.zeros((K, B))
    cnt = np.zeros(K)
    m1 = np.zeros(B)
    m2 = np.zeros(B)
    for t in range(nfr):
        k = kb[t]
        cnt[k] += 1.0
        for b in range(B):
            v = float(S[t, b])
            M[k, b] += v
            m1[b] += v
            m2[b] += v * v
    return M, cnt, m1, m2


@njit(cache=True)
def _fold_kernel(S: np.ndarray, kb: np.ndarray, K: int, freqs: np.ndarray, thr: float, cplx: bool
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """_fold_shape's folded profile, compiled: per phase bin (of K) the frequency bin whose mean of S over the phase
    bin's frames exceeds its mean over all frames the most (the strongest component at that phase, as the ridge
    takes the strongest bin), present when that excess stands z > thr standard errors (the bin's standard
    deviation over all frames / sqrt(n)); its frequency (parabola on the excesses) and standard error (one bin / z).
    Returns (profile, standard errors, present, fewest frames in a phase bin)."""
    nfr, B = S.shape
    M, cnt, m1, m2 = _fold_sums(S, kb, K)
    var = np.empty(B)
    for b in range(B):
        m1[b] /= nfr
        var[b] = max(m2[b] / nfr - m1[b] * m1[b], 1e-30)
    prof = np.full(K, np.nan)
    se = np.full(K, np.inf)
    present = np.zeros(K, np.bool_)
    binw = freqs[1] - freqs[0]
    nmin = nfr
    b_lo, b_hi = (1, B - 1) if cplx else (0, B)   # complex: the +-0.5 edge bins may be either side
    for k in range(K):
        n = cnt[k]
        nmin = min(nmin, int(n))
        if n < 1:
            continue
        for b in range(B):
            M[k, b] /= n
        best, kb_ = -np.inf, -1
        for b in range(b_lo, b_hi):
            if M[k, b] - m1[b] > best:
                best, kb_ = M[k, b] - m1[b], b
        if kb_ < 0:
            continue
        z = best / math.sqrt(var[kb_] / n)
        if not z > thr:
            continue
        present[k] = True
        d = 0.0
        if 0 < kb_ < B - 1:
            a = M[k, kb_ - 1] - m1[kb_ - 1]
            c = M[k, kb_ + 1] - m1[kb_ + 1]
            den = a - 2.0 * best + c
            if den < 0:
                d = min(max(0.5 * (a - c) / den, -0.5), 0.5)
        prof[k] = freqs[kb_] + d * binw
        se[k] = binw / max(z, 1.0)
    return prof, se, present, nmin


def folded_shape(x: np.ndarray, cplx: bool, period_samples: float, par: FoldParams
                 ) -> tuple[int, float, float, float]:
    """Sweep shape of a periodic jammer of known period too weak for the per-frame ridge (for a chirp found by the
    evidence over blocks, whose comb gives the period): (shape, in-band fraction, low, high), frequencies in
    cycles/sample; SHAPE_UNKNOWN and NaN when the block does not show it.

    The short-time spectrum (frames of the longest L with hop <= period / ``FOLD_HOPS``) is averaged per phase of
    the period (``SHAPE_BINS`` phase bins, or one per hop when the period is nearly a whole number of hops):
    synchronous averaging over the block's periods, n frames per phase bin, raises a sweep that is below the
    per-frame presence threshold by sqrt(n). Per phase bin the strongest frequency bin (the largest phase mean
    minus the bin's mean over all frames) must stand z standard errors high (the bin's standard deviation over
    frames / sqrt(n); no noise level is needed) with z above the Gaussian quantile of
    1 - ``FOLD_FALSE`` / (phase bins x bins) to be present; its frequency is interpolated (parabola on those
    excesses), its standard error taken as one bin / z (the position error of a peak
    about a bin wide that stands z standard errors high). The shape rule is ``_shape``'s (``rfi_monitor.sweep_shape``
    module docstring). Cost: one STFT of the block and one compiled pass over it (0.25-0.4 ms for 1 ms at 38.192 MS/s
    here)."""
    nan = math.nan
    x = np.asarray(x)
    T = float(period_samples)
    L = 0
    for cand in par.frame_lengths:
        if cand // 2 <= T / FOLD_HOPS:
            L = cand
    if L == 0 or not math.isfinite(T) or x.size < 8 * L or x.size < 4 * T:
        return SHAPE_UNKNOWN, nan, nan, nan
    S, freqs = stft_power(x, L, cplx)
    return _fold_shape(S, freqs, T / (L // 2), L, cplx, par.hook_rate_ratio)


def _fold_shape(S: np.ndarray, freqs: np.ndarray, per_fr: float, L: int, cplx: bool, hook_ratio: float
                ) -> tuple[int, float, float, float]:
    """folded_shape on a computed |STFT|^2 S (frames, bins) of frame length L and a period of per_fr frames."""
    nan = math.nan
    nfr, B = S.shape
    K = SHAPE_BINS
    if abs(per_fr - round(per_fr)) * (nfr / per_fr) < 1.0:      # whole number of hops: only round(per_fr) phases
        K = max(4, min(K, int(round(per_fr))))
    kb = np.minimum((np.mod(np.arange(nfr) / per_fr, 1.0) * K).astype(np.int64), K - 1)
    thr = float(-ndtri(FOLD_FALSE / (K * B)))
    prof, se, present, nmin = _fold_kernel(np.ascontiguousarray(S), kb, K, np.asarray(freqs, dtype=np.float64), thr,
                                           bool(cplx))
    if nmin < 4:
        return SHAPE_UNKNOWN, nan, nan, nan
    shape, low, high, _start, _step, _p = _shape(prof, present, hook_ratio, se)
    if shape != SHAPE_UNKNOWN or per_fr < FOLD_HOPS:
        return shape, float(np.mean(present)), low, high
    # too few phase bins stand out on their own: the whole sweep law, integrated along it (_line_shape); only with
    # frames short against the period (>= FOLD_HOPS hops per period, as folded_shape chooses them): a frame that spans
    # much of the period smears a saw-tooth into a shape a triangle's line fits as well (measured: a saw-tooth down
    # at 4 MS/s in 64-sample frames, 3 hops per period, read as a triangle)
    Z = _fold_zmap(np.ascontiguousarray(S), kb, K)
    b_lo, b_hi = (1, B - 1) if cplx else (0, B)
    code, lo_b, hi_b = _line_shape(Z[:, b_lo:b_hi])
    if code == SHAPE_UNKNOWN:
        return shape, float(np.mean(present)), low, high
    binw = float(freqs[1] - freqs[0])
    return code, nan, float(freqs[b_lo]) + lo_b * binw, float(freqs[b_lo]) + hi_b * binw


LINE_MIN_BINS = 2
"""_line_shape: a sweep law spans at least this many frequency bins of the folded map."""
LINE_MAX_BINS = 17
"""_line_shape: a folded map wider than this is searched with pairs of frequency bins merged (until it is not): the
search costs O(bins^2 phase bins^2): 16 phase bins take about 0.2 ms at 9 bins, 1 ms at 17, 16 ms at 65; merged to 9,
the demo's J/S +6 dB chirp (a 4-bin sweep at 17 bins) was found in 1 of 10 blocks instead of 10 of 10)."""
LINE_MARGIN_Z = 2.0
"""_line_shape: the best law's class (saw-tooth up, down, triangle) must beat the best law of every other class by
this many standard deviations of the line sum (a saw-tooth and a triangle with a short side share most of their
line; below this the data do not choose between them: unknown)."""
LINE_FALSE = 1e-3
"""_line_shape: chance that noise alone gives any candidate law a line sum over the threshold (Bonferroni over the
candidates)."""


@njit(cache=True)
def _fold_zmap(S: np.ndarray, kb: np.ndarray, K: int) -> np.ndarray:
    """Per phase bin (of K) and frequency bin, the excess of the phase bin's mean of S over the bin's mean over all
    frames, in standard errors (the bin's standard deviation over frames / sqrt(frames in the phase bin)): the map
    _fold_kernel takes its per-phase maxima from, whole. Shape (K, bins)."""
    nfr, B = S.shape
    M, cnt, m1, m2 = _fold_sums(S, kb, K)
    Z = np.zeros((K, B))
    for b in range(B):
        mean = m1[b] / nfr
        var = max(m2[b] / nfr - mean * mean, 1e-30)
        for k in range(K):
            if cnt[k] > 0:
                Z[k, b] = (M[k, b] / cnt[k] - mean) / math.sqrt(var / cnt[k])
    return Z


@njit(cache=True, inline="always")
def _z_at(Z: np.ndarray, k: int, f: float) -> float:
    """Z[k] linearly interpolated at the fractional bin f (inside the map)."""
    b = int(math.floor(f))
    a = f - b
    if b >= Z.shape[1] - 1:
        return Z[k, Z.shape[1] - 1]
    return (1.0 - a) * Z[k, b] + a * Z[k, b + 1]


def _line_shape(Z: np.ndarray) -> tuple[int, float, float]:
    """(shape, lowest, highest frequency bin) of the sweep law whose line through the folded map Z (phase bins x
    frequency bins, in standard errors) has the largest sum, or SHAPE_UNKNOWN (ours).

    Candidate laws, each a line through every phase bin k at the frequency it gives at the bin's centre: a saw-tooth
    up (down) from bin lo to bin hi (hi to lo) starting at phase bin k0 with an instantaneous flyback, and a triangle
    rising from lo to hi over u phase bins and falling back over K - u (both sides at least ``TRIANGLE_SIDE`` of the
    period), for every lo < hi at least ``LINE_MIN_BINS`` apart and every k0 (``_line_scores``). The score is the
    sum of Z along the line / sqrt(K) (standard normal under noise: the phase bins hold disjoint frames; a value
    interpolated between two bins has at most unit variance); the best must exceed the Gaussian quantile of
    1 - ``LINE_FALSE`` / candidates (Bonferroni) and beat the best law of every other class by ``LINE_MARGIN_Z``. A
    sweep too weak for any phase bin alone (``_fold_kernel``'s threshold) is found from all of them: the line sum of
    K phase bins standing z each is sqrt(K) z. A hook is not a candidate (a hooked saw-tooth reads as its saw-tooth).
    Maps wider than ``LINE_MAX_BINS`` frequency bins are searched with neighbouring bins merged."""
    Z = np.asarray(Z, dtype=np.float64)
    merge = 1
    while Z.shape[1] > LINE_MAX_BINS:
        # pairs of frequency bins summed (/ sqrt 2: still unit variance under noise): the search is O(B^2 K^2)
        m = Z.shape[1] // 2
        Z = (Z[:, 0:2 * m:2] + Z[:, 1:2 * m:2]) / math.sqrt(2.0)
        merge *= 2
    best, arg, n_cand = _line_scores(np.ascontiguousarray(Z))
    if n_cand == 0:
        return SHAPE_UNKNOWN, math.nan, math.nan
    thr = float(-ndtri(LINE_FALSE / n_cand))
    c = int(np.argmax(best))
    other = max(float(best[i]) for i in range(3) if i != c)
    if not (best[c] > thr and best[c] - other >= LINE_MARGIN_Z):
        return SHAPE_UNKNOWN, math.nan, math.nan
    code = SAWTOOTH_UP if c == 0 else (SAWTOOTH_DOWN if c == 1 else TRIANGLE)
    centre = 0.5 * (merge - 1)       # a merged bin's centre in the original bins
    return code, float(arg[c, 0]) * merge + centre, float(arg[c, 1]) * merge + centre


@njit(cache=True)
def _line_scores(Z: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """_line_shape's search, compiled: the best score of each class (saw-tooth up, down, triangle), its (lo, hi), and
    the number of candidates."""
    K, B = Z.shape
    best = np.full(3, -np.inf)
    arg = np.zeros((3, 2))
    n_cand = 0
    rk = 1.0 / math.sqrt(K)
    u_min = max(2, int(math.ceil(TRIANGLE_SIDE * K)))
    u_max = K - u_min
    for lo in range(B):
        for hi in range(lo + LINE_MIN_BINS, B):
            span = float(hi - lo)
            for k0 in range(K):
                up = 0.0
                dn = 0.0
                for j in range(K):
                    k = (k0 + j) % K
                    x = (j + 0.5) / K
                    up += _z_at(Z, k, lo + span * x)
                    dn += _z_at(Z, k, hi - span * x)
                n_cand += 2
                if up * rk > best[0]:
                    best[0] = up * rk
                    arg[0, 0], arg[0, 1] = lo, hi
                if dn * rk > best[1]:
                    best[1] = dn * rk
                    arg[1, 0], arg[1, 1] = lo, hi
                for u in range(u_min, u_max + 1):
                    tri = 0.0
                    for j in range(K):
                        k = (k0 + j) % K
                        if j < u:
                            f = lo + span * (j + 0.5) / u
                        else:
                            f = hi - span * (j - u + 0.5) / (K - u)
                        tri += _z_at(Z, k, f)
                    n_cand += 1
                    if tri * rk > best[2]:
                        best[2] = tri * rk
                        arg[2, 0], arg[2, 1] = lo, hi
    return best, arg, n_cand
