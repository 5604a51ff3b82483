"""The CHIRP test of the evidence over blocks (orchestrated by ``rfi_monitor.integration.Integrator``; issue 14 item
5): the comb over the summed 2-D autocorrelation of the short-time spectrum (``rfi_monitor.spectral_autocorrelation``).

A periodic sweep puts the same spectrum at every multiple of its period, so the statistic is the comb
``Z(p) = sum_k r(k p) / sqrt(sum_k var r(k p))`` (``k = 1..K_p``, up to ``max_multiples``, lags rounded to frames;
candidate periods on a grid of ``0.5 / K_p`` frames: the folding of the spectrogram at the period, written with the
autocorrelation so that blocks add without knowing their sweep phase). Under noise ``Z`` is standard normal per
candidate (lags >= 2 frames: Hann frames at hop L/2 do not overlap); the threshold is ``Phi^-1(1 - alpha / M)`` for
``M`` candidates (Bonferroni), moved by the comb's skew (``_comb_skew``, Cornish-Fisher). A coarse comb
(``COARSE_MULTIPLES``) over all periods selects the candidates of the fine one (``ChirpComb.test``). A sweep periodic in
T is periodic in 2 T, 3 T, ... as well: before the best candidate's period is published, its sub-multiples are tested
on the same sums (``resolve_submultiple``), and a period that cannot be told from a multiple of a shorter one is
published NaN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy import special

from rfi_monitor.numpy_kernels import pairwise_sum

MIN_CHIRP_FRAMES = 512
"""The chirp statistic decides once the window holds this many frames: a sum of products of few frames has heavier
tails than the normal law its threshold assumes (measured on Gaussian noise: 1024-sample blocks of 12 MS/s real IF,
127 frames each, exceeded the alpha = 1e-4 threshold in 1 of 3,000 single blocks)."""
COARSE_MULTIPLES = 16
"""Multiples summed by the coarse comb that selects the candidates of the fine one."""
FINE_CANDIDATES = 12
"""Best coarse candidates refined with ``max_multiples`` multiples."""
FINE_HALF_WIDTH = 1.5
"""Half-width of the fine search around a coarse candidate, in units of 1 / K_p frames (K_p: the coarse multiples):
the coarse comb is flat over up to two of its steps (0.5 / K_p), and the true period may lie at either end."""
SUBMULTIPLES = (2, 3)
"""Sub-multiples P / m of a chirp decision's period P tested before it is published (:func:`resolve_submultiple`)."""
SUBMULTIPLE_Z = 4.0
"""A sub-multiple p / m is the period when the comb over its lags that are not lags of p reads at least this many
standard deviations (``resolve_submultiple``). Where p is the period those lags fall between its multiples, where a
sweep's amplitudes are anti-correlated (in a bin at one lag, elsewhere at the other): measured over 11,854 tests
(5,927 correct decisions: the demo's chirp, saw-tooths, triangles and hooked saw-tooths at 4 MS/s I/Q and 16.368 MS/s
real, J/N -12 to 0 dB, 1 ms blocks) median -2 to -90 and at most 2.9."""
SUBMULTIPLE_ABSENT_Z = 0.0
"""... and p is the period when that comb reads below this. Where p / m is the period those lags carry the sweep as
p's own multiples do: measured 1.6 to 11.6 in the 32 decisions (of the same runs) that had picked 2 p or 3 p."""
SUBMULTIPLE_MARGIN = 3.0
"""Where p / m, were it the period, would show on those lags at ``Z_pred`` (predicted from p's strength): it is the
period from ``Z_pred / 2`` (the midpoint between the two outcomes) on, and p is kept below ``Z_pred / 2`` minus this
many standard deviations (p's strength is that of the largest comb of the search, so ``Z_pred`` errs high by up to
about this: measured 1.6 against a predicted 6.8 in a decision that had picked 2 p)."""
SUBMULTIPLE_MIN_EXPECTED = 4.0
"""The test decides only when p / m, were it the period, would show on those lags at no less than this many standard
deviations as predicted from p's strength (else neither outcome could be told from noise): below, and between
``SUBMULTIPLE_ABSENT_Z`` and ``SUBMULTIPLE_Z``, the period is ambiguous and published NaN."""


@njit(cache=True, nogil=True)
def _comb_z(r: np.ndarray, v: np.ndarray, idx: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Comb statistic Z(p) per candidate row (module docstring): sum of r over the row's lags over the square root of
    the sum of their variances; -inf where the variance is zero. Compiled (one pass over the candidates' lags)."""
    M, K = idx.shape
    out = np.empty(M)
    for i in range(M):
        num = 0.0
        den = 0.0
        for k in range(K):
            if mask[i, k]:
                num += r[idx[i, k]]
                den += v[idx[i, k]]
        out[i] = num / math.sqrt(den) if den > 0 else -math.inf
    return out


@njit(cache=True, nogil=True)
def _comb_z_direct(r: np.ndarray, v: np.ndarray, P: np.ndarray, Kp: np.ndarray, lag_limit: int) -> np.ndarray:
    """:func:`_comb_z` of the candidates P (frames) without their lag and mask arrays (issue 26 item 2: the fine
    comb's 128 multiples of a few hundred candidates): lag rint(P k), k = 1..Kp (Kp from the caller, as
    ``comb_lags`` clips it), kept while <= lag_limit; the same sums in the same order."""
    M = P.size
    out = np.empty(M)
    for i in range(M):
        num = 0.0
        den = 0.0
        for k in range(1, Kp[i] + 1):
            lag = np.int64(np.rint(P[i] * float(k)))
            if lag <= lag_limit:
                num += r[lag]
                den += v[lag]
        out[i] = num / math.sqrt(den) if den > 0 else -math.inf
    return out


@njit(cache=True, nogil=True)
def _separated(order: np.ndarray, periods: np.ndarray, count: int) -> np.ndarray:
    """The first ``count`` indices of ``order`` whose periods lie more than 0.5 frames from every one taken before
    (the fine comb's candidates, best first)."""
    top = np.empty(count, dtype=np.int64)
    n = 0
    for i in order:
        ok = True
        for j in range(n):
            if not abs(periods[i] - periods[top[j]]) > 0.5:
                ok = False
                break
        if ok:
            top[n] = i
            n += 1
            if n == count:
                break
    return top[:n]


@njit(cache=True, nogil=True)
def _comb_z_prefix(r: np.ndarray, v: np.ndarray, lags: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """:func:`_comb_z` of the compact grid (:func:`compact_lags`): row i's lags are its first counts[i] (a comb's
    mask is a prefix of its multiples), stored in 16 or 32 bits; the same sums in the same order. The coarse grid
    at 38.192 MS/s (6,024 x 16) is 0.2 MB instead of the 0.9 MB of int64 lags and mask read per tested sum."""
    M = lags.shape[0]
    out = np.empty(M)
    for i in range(M):
        num = 0.0
        den = 0.0
        for k in range(counts[i]):
            lag = lags[i, k]
            num += r[lag]
            den += v[lag]
        out[i] = num / math.sqrt(den) if den > 0 else -math.inf
    return out


def compact_lags(idx: np.ndarray, mask: np.ndarray, lag_limit: int) -> tuple[np.ndarray, np.ndarray]:
    """(lags, counts) of ``comb_lags``' (idx, mask): the lags in int16 (int32 from lag_limit 32,768 on) and the number
    of each row's lags kept (its mask is a prefix: k p grows with k)."""
    dtype = np.int16 if lag_limit < 2 ** 15 else np.int32
    return np.ascontiguousarray(idx, dtype=dtype), mask.sum(axis=1).astype(np.int64)


@njit(cache=True, nogil=True)
def _coarse_top(r: np.ndarray, v: np.ndarray, lags: np.ndarray, counts: np.ndarray, periods: np.ndarray, n_top: int,
                count: int) -> np.ndarray:
    """The coarse comb's candidates for the fine one: :func:`_comb_z_prefix` of every row (the grid in the form of
    :func:`compact_lags`), its ``n_top`` largest in descending order, ties to the lower index (the shorter period:
    the coarse comb is flat over up to two of its steps, and equal values are common), and of those the first
    ``count`` more than 0.5 frames apart (:func:`_separated`). The ``n_top`` are those above the n_top-th largest
    value (numba's np.partition: the value is unique whatever the selection) and the lowest-indexed of those equal to
    it, sorted by a stable sort of the negated values: a strict order, so the same list as the bounded heap and
    insertion sort before (issue 26 item 2: 170-210 -> 110-140 us a tested sum at 38.192 MS/s, with the compact
    grid; a numpy argpartition and argsort before those, whose order among equal values was numpy's partition's)."""
    z = _comb_z_prefix(r, v, lags, counts)
    M = z.size
    n_top = min(n_top, M)
    if n_top <= 0:
        return _separated(np.empty(0, dtype=np.int64), periods, count)
    zt = np.partition(z, M - n_top)[M - n_top]     # the n_top-th largest value (z is NaN-free: finite sums or -inf)
    n_eq = n_top
    for i in range(M):
        if z[i] > zt:
            n_eq -= 1
    sel = np.empty(n_top, dtype=np.int64)
    n = 0
    for i in range(M):
        if z[i] > zt or (z[i] == zt and n_eq > 0):
            if not z[i] > zt:
                n_eq -= 1
            sel[n] = i
            n += 1
    keys = np.empty(n_top)
    for a in range(n_top):
        keys[a] = -z[sel[a]]
    order = sel[np.argsort(keys, kind="mergesort")]
    return _separated(order, periods, count)


@njit(cache=True, nogil=True)
def _fine_best(r: np.ndarray, v: np.ndarray, periods: np.ndarray, top: np.ndarray, lmin: float, lmax: float,
               lag_limit: int, kc: int, kf: int) -> tuple[float, float, int, float, float]:
    """The fine comb around the coarse candidates ``top`` (:func:`_fine_candidates`, :func:`_comb_z_direct` with
    K_p = clip(lag_limit // P, 2, kf) as ``comb_lags``) and its best candidate (the first largest, np.argmax):
    (its Z, its period in frames, the number of its lags (``_multiples``), the pairwise sum of r over them and the
    sum of the lags (``comb_strength``'s terms)). Compiled in one (issue 26 item 2: ten numpy calls per test before,
    the same values)."""
    Pf = _fine_grid(periods, top, lmin, lmax, lag_limit, kc, kf, FINE_HALF_WIDTH)
    Kp = np.empty(Pf.size, dtype=np.int64)
    for j in range(Pf.size):
        Kp[j] = min(max(int(lag_limit // Pf[j]), 2), kf)
    zf = _comb_z_direct(r, v, Pf, Kp, lag_limit)
    i = 0
    for j in range(1, zf.size):
        if zf[j] > zf[i]:
            i = j
    p = Pf[i]
    vals = np.empty(Kp[i])
    n = 0
    lag_sum = 0
    for k in range(1, Kp[i] + 1):
        lag = np.int64(np.rint(p * float(k)))
        if lag <= lag_limit:
            vals[n] = r[lag]
            lag_sum += int(lag)
            n += 1
    return zf[i], p, n, pairwise_sum(vals[:n].copy(), 0.0), float(lag_sum)


def _multiples(p: float, lag_limit: int, kmax: int) -> tuple[np.ndarray, np.ndarray]:
    """(k, lags) of the comb of a period of p frames (as ``comb_lags``): k = 1..K_p with
    K_p = clip(lag_limit // p, 2, kmax), lag = rint(k p), kept while lag <= lag_limit."""
    kp = int(min(max(lag_limit // p, 2), kmax))
    ks = np.arange(1, kp + 1)
    lags = np.rint(p * ks).astype(np.int64)
    keep = lags <= lag_limit
    return ks[keep], lags[keep]


def comb_strength(r: np.ndarray, lags: np.ndarray, spread: float, spread_frames: float) -> float:
    """Share of the amplitudes' variance that repeats at ``lags`` (``IntegratedDecision.chirp_strength``): the sum of r
    over them over the same sum for a perfectly periodic E, whose r(l) is ``spread_frames - spread l`` (the variance
    per frame summed over the frames that have a partner l frames later); NaN when that is not positive."""
    scale = lags.size * spread_frames - spread * float(lags.sum())
    return float(r[lags].sum()) / scale if scale > 0 else math.nan


def resolve_submultiple(r: np.ndarray, v: np.ndarray, spread: float, spread_frames: float, p: float, lmin: float,
                        lag_limit: int, kmax: int) -> tuple[float, int, float]:
    """The sweep period a comb that detected a periodic sweep at p frames stands for: p, a sub-multiple p / m, or NaN.

    A frequency law periodic in T (Kang et al., eq. 4-5: ``f_n = f_0 + Delta f (n - T)`` from n = T on) is periodic in
    every multiple m T as well, so the comb ``Z(p)`` (module docstring) is large at T, 2 T, 3 T, ...; the search takes
    the largest Z, which is T's in expectation, but a noisy coarse comb can leave T out of the fine search (measured:
    the demo's +6 dB chirp, J/N -14 dB in one 1 ms snapshot, 5.10 us published as 10.2 us in 3 of its 20 blocks; 15
    of 200 such snapshots simulated). So, for m in ``SUBMULTIPLES`` (repeatedly, so that 4 T and 6 T come down to T),
    the lags of p / m that are not lags of p (the multiples k p / m, k not divisible by m) are tested with the same
    evidence: r summed over them over the square root of the sum of its variances under noise, ``Z_x``, a comb of
    its own (none of its lags entered the detection, so it is not biased by the search). Were p / m the period, those
    lags repeat the sweep as p's do (``Z_x`` about the detection's own significance); were p the period, they fall
    between its multiples, where the amplitudes of a sweep are anti-correlated (``Z_x`` mostly negative). p's strength
    s (:func:`comb_strength`) predicts what p / m would give: ``Z_pred = s * sum_l (spread_frames - spread l) /
    sqrt(sum_l var r(l))``. Rule: p / m when ``Z_x >= max(SUBMULTIPLE_Z, Z_pred / 2)``; p when
    ``Z_x < max(SUBMULTIPLE_ABSENT_Z, Z_pred / 2 - SUBMULTIPLE_MARGIN)``; otherwise, or when ``Z_pred <
    SUBMULTIPLE_MIN_EXPECTED`` (p / m could not show), the period is ambiguous: NaN. A
    multiple of the true period is then never published as valid. Sub-multiples below ``lmin`` frames (shorter than
    any period searched) are not tested. Ours: the paper estimates the period from successive LPD peaks (Sec. 3.2,
    eq. 23-27), where a missed peak doubles an interval in the same way (``sweep_period``: q = 2 intervals).
    Measured on single 1 ms blocks, 200 per case (the demo's chirp at +6 dB J/S; saw-tooths up and down, triangles,
    a hooked saw-tooth at 4 MS/s I/Q and 16.368 MS/s real, J/N -14 to -8 dB): multiples of the period published in
    30 of 2,852 chirp decisions before, none after; NaN in 32 (at most 7 of the 95 decisions of a case, all at J/N
    -10 and -12 dB, where a decision barely reaches its threshold), none from J/N -8 dB (4 MS/s) and -10 dB (16 MS/s).

    Args:
        r, v: the window's summed autocorrelation over frames and its variance under noise, lags 0..lag_limit.
        spread, spread_frames: the window's sums of E's variance per frame (``_Sums``).
        p: the detected period, frames (fractional).
        lmin: shortest period searched, frames.
        lag_limit: longest lag summed, frames; kmax: most multiples of a comb.

    Returns:
        (period in frames or NaN, m: p over the returned period (1: p kept), its strength).
    """
    m_total = 1
    _, lags = _multiples(p, lag_limit, kmax)
    strength = comb_strength(r, lags, spread, spread_frames)
    changed = True
    while changed:
        changed = False
        for m in SUBMULTIPLES:
            q = p / m
            if q < lmin:
                continue
            ks, lags_q = _multiples(q, lag_limit, kmax)
            extra = lags_q[ks % m != 0]
            var = float(v[extra].sum()) if extra.size else 0.0
            if not (var > 0 and math.isfinite(strength) and strength > 0):
                continue
            scale = extra.size * spread_frames - spread * float(extra.sum())
            expected = strength * scale / math.sqrt(var)
            z_extra = float(r[extra].sum()) / math.sqrt(var)
            if z_extra >= max(SUBMULTIPLE_Z, 0.5 * expected):
                p, m_total, changed = q, m_total * m, True
                strength = comb_strength(r, lags_q, spread, spread_frames)
                break
            if expected < SUBMULTIPLE_MIN_EXPECTED or z_extra >= max(SUBMULTIPLE_ABSENT_Z,
                                                                     0.5 * expected - SUBMULTIPLE_MARGIN):
                return math.nan, m_total, strength
    return p, m_total, strength


def _comb_skew(p: float, K: int, copies: float, copy_frames: float) -> float:
    """Skewness of the comb statistic Z(p) under noise (K multiples of p frames), summed over ``copies`` independent bin
    sequences of ``copy_frames / copies`` frames on average (Gaussian amplitudes assumed).

    Z is a quadratic form, per bin sequence ``Q = sum_t sum_k E(t) E(t + l_k)`` (l_k = k p), not a sum of independent
    terms: its cumulants are ``kappa_2 = sum_k (T - l_k)`` and ``kappa_3 = 6 sum_(a, b) (T - l_a - l_b)`` over the
    ordered pairs of multiples whose lags add up to another one (a + b <= K: the comb's triangles), so the skewness
    ``kappa_3 / kappa_2^1.5`` grows as sqrt(K / T) and falls as 1 / sqrt(copies). A sum over few frames is markedly
    skewed: measured on Gaussian noise with the normal threshold alone, one-block sums exceeded the alpha = 1e-4
    threshold in 1.3-3.5 of 1,000 blocks at 4-38 MS/s (a 16.368 MS/s block: skewness about 0.2, the threshold 1 sigma
    higher). Closed forms of the sums for l_k = k p:
    ``kappa_2 = K A - C p K (K + 1) / 2``, ``kappa_3 = 6 (A K (K - 1) / 2 - C p (K - 1) K (K + 1) / 3)``,
    A = copy_frames, C = copies (copy_frames sums each copy's frames).
    """
    if K < 2 or copies <= 0:
        return 0.0
    k2 = K * copy_frames - copies * p * K * (K + 1) / 2.0
    k3 = 6.0 * (copy_frames * K * (K - 1) / 2.0 - copies * p * (K - 1) * K * (K + 1) / 3.0)
    if not k2 > 0 or not k3 > 0:
        return 0.0
    return k3 / k2 ** 1.5


def comb_lags(P: np.ndarray, lag_limit: int, kmax: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(P, lags (M, kmax), mask (M, kmax)) of the combs of the candidate periods P (M,) frames: lag rint(k P),
    k = 1..K_p, K_p = clip(lag_limit // P, 2, kmax), kept while <= lag_limit (masked lags set to 0)."""
    ks = np.arange(1, kmax + 1)
    Kp = np.clip((lag_limit // P).astype(np.int64), 2, kmax)
    idx = np.rint(P[:, None] * ks[None, :]).astype(np.int64)
    mask = (ks[None, :] <= Kp[:, None]) & (idx <= lag_limit)
    return P, np.where(mask, idx, 0), mask


@dataclass(frozen=True)
class CombResult:
    """The CHIRP test of one window's sums (``ChirpComb.test``).

    Attributes:
        z: the largest fine comb statistic, standard deviations; threshold: its threshold.
        strength: the share of the amplitudes' variance that repeats at the period (``comb_strength``; of the
            sub-multiple when one was taken).
        detected: z over the threshold and the strength at least the minimum.
        period_frames: the period (detected only): the best candidate's or its sub-multiple's, frames; NaN when
            ambiguous (``resolve_submultiple``).
        multiple: the best candidate's period over the one returned (1: kept).
    """

    z: float
    threshold: float
    strength: float
    detected: bool
    period_frames: float = math.nan
    multiple: int = 1


class ChirpComb:
    """The comb test (module docstring) with its candidate grids and thresholds cached."""

    def __init__(self) -> None:
        self._grids: dict[tuple[int, int, int, int], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._chirp_thr: dict[tuple[int, int, int, int, float], float] = {}

    def test(self, r: np.ndarray, v: np.ndarray, copies: float, copy_frames: float, spread: float,
             spread_frames: float, alpha: float, lmin: int, lmax: int, lag_limit: int, max_multiples: int,
             min_strength: float) -> CombResult:
        """The test of a summed autocorrelation r and its variance v (lags 0..lag_limit; ``copies``, ``copy_frames``,
        ``spread``, ``spread_frames``: the window's sums of ``spectral_autocorrelation``'s moments) over periods
        lmin..lmax frames at false-alarm probability alpha."""
        kf = int(max_multiples)
        kc = min(COARSE_MULTIPLES, kf)
        # coarse comb (kc multiples) over all periods, then the fine one (kf multiples, a finer grid) around
        # the best coarse candidates; the threshold counts every fine candidate over the whole range
        # (Bonferroni), so evaluating only some of them keeps the false-alarm rate below alpha
        periods, lags, counts = self._comb_grid(lmin, lmax, lag_limit, kc)
        top = _coarse_top(r, v, lags, counts, periods, 20 * FINE_CANDIDATES, FINE_CANDIDATES)
        chirp_z, p_best, n_lags, r_sum, lag_sum = _fine_best(r, v, periods, top, float(lmin), float(lmax),
                                                             int(lag_limit), kc, kf)
        ck = (lmin, lmax, lag_limit, kf, alpha)
        if ck not in self._chirp_thr:
            self._chirp_thr[ck] = -float(special.ndtri(alpha / _fine_count(lmin, lmax, lag_limit, kf)))
        # the normal quantile, moved by the comb's skew (Cornish-Fisher): Z is a quadratic form of the amplitudes
        z0 = self._chirp_thr[ck]
        gamma = _comb_skew(p_best, n_lags, copies, copy_frames)
        chirp_thr = z0 + gamma / 6.0 * (z0 * z0 - 1.0)
        scale = n_lags * spread_frames - spread * lag_sum               # comb_strength of the best candidate's lags
        strength = r_sum / scale if scale > 0 else math.nan
        if not (chirp_z > chirp_thr and strength >= min_strength):
            return CombResult(chirp_z, chirp_thr, strength, False)
        # the comb is large at every multiple of the period: the best candidate's sub-multiples are tested on
        # the same sums (resolve_submultiple); an ambiguous one leaves the period NaN
        p_res, m, s_res = resolve_submultiple(r, v, spread, spread_frames, p_best, lmin, lag_limit, kf)
        return CombResult(chirp_z, chirp_thr, s_res if m > 1 else strength, True, p_res, m)

    def _comb_grid(self, lmin: int, lmax: int, lag_limit: int, kmax: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(periods (M,), lags (M, kmax), counts (M,)): candidate periods from lmin to lmax frames on a grid of
        0.5 / K_p frames, K_p = min(kmax, lag_limit // p) multiples, their lags as :func:`compact_lags` (cached)."""
        key = (lmin, lmax, lag_limit, kmax)
        hit = self._grids.get(key)
        if hit is not None:
            return hit
        periods: list[float] = []
        p = float(lmin)
        while p <= lmax:
            periods.append(p)
            p += 0.5 / max(2, min(kmax, int(lag_limit // p)))
        P = np.asarray(periods)
        _, idx, mask = comb_lags(P, lag_limit, kmax)
        out = (P, *compact_lags(idx, mask, lag_limit))
        self._grids[key] = out
        return out


def _fine_candidates(periods: np.ndarray, top: list[int], lmin: int, lmax: int, lag_limit: int, kc: int, kf: int
                     ) -> np.ndarray:
    """The fine comb's candidate periods, frames: around each of the best coarse ones (``top``, indices into
    periods) +-``FINE_HALF_WIDTH`` coarse steps on the fine grid (0.5 / K_p frames, K_p up to kf multiples), within
    lmin..lmax (the best coarse one alone when none is)."""
    # around each: +-1.5 coarse steps. The coarse comb rounds k p to whole frames for k <= kc, so it is flat
    # over up to 1 / kc frames of p (two coarse steps) and the candidate taken from such a plateau may sit at
    # either end of it; a fine search of +-0.5 step missed the period when the true one lay at the plateau's
    # other end, and the comb then picked twice the period (measured: a 4 MS/s I/Q saw-tooth of 8.972 frames,
    # its period published doubled in 1 of 3 decisions)
    return _fine_grid(periods, np.asarray(top, dtype=np.int64), float(lmin), float(lmax), int(lag_limit), int(kc),
                      int(kf), FINE_HALF_WIDTH)


@njit(cache=True, nogil=True)
def _arange(start: float, stop: float, step: float) -> np.ndarray:
    """np.arange(start, stop, step) of floats, to the bit: ceil((stop - start) / step) values, the i-th
    start + i * d with d = (start + step) - start (numpy's fill of a float range)."""
    n = max(int(math.ceil((stop - start) / step)), 0)
    out = np.empty(n)
    if n > 0:
        out[0] = start
    if n > 1:
        out[1] = start + step
        d = out[1] - start
        for i in range(2, n):
            out[i] = start + i * d
    return out


@njit(cache=True, nogil=True)
def _fine_grid(periods: np.ndarray, top: np.ndarray, lmin: float, lmax: float, lag_limit: int, kc: int, kf: int,
               half_width: float) -> np.ndarray:
    """:func:`_fine_candidates` compiled (the same values in the same order)."""
    parts = []
    n = 0
    for i in top:
        p0 = periods[i]
        k0 = max(2, min(kc, int(lag_limit // p0)))
        k1 = max(2, min(kf, int(lag_limit // p0)))
        a = _arange(p0 - half_width / k0, p0 + half_width / k0 + 1e-12, 0.5 / k1)
        parts.append(a)
        n += a.size
    out = np.empty(n)
    m = 0
    for a in parts:
        for c in a:
            if lmin <= c <= lmax:
                out[m] = c
                m += 1
    if m == 0:
        out = np.empty(1)
        out[0] = periods[top[0]]
        return out
    return out[:m].copy()


def _fine_count(lmin: int, lmax: int, lag_limit: int, kmax: int) -> float:
    """Candidates of the fine grid (0.5 / K_p frames, K_p up to kmax) over lmin..lmax: the Bonferroni count."""
    p = np.linspace(lmin, lmax, 20001)
    K = np.clip(lag_limit // p, 2, kmax)
    return float(np.trapezoid(2.0 * K, p)) + 1.0
