"""Sweep-period estimation of a saw-tooth chirp: LPD, AR pattern enhancement, peak detection.

Kang et al., Sec. 3.2:

1. Low-pass differentiator (Laguna et al. 1990), G(z) = 1 - z^-6, with forgetting factor gamma
   and normalisation beta (eq. 23):
   ``zG_n = gamma zG_{n-1} - (1 - gamma) (z_n - z_{n-6}) / (beta (f_max - f_min) / fs)``.
   At a sweep start z drops by the sweep bandwidth, so zG shows a positive peak (a down-chirp
   gives a negative one; we detect |zG| peaks of the sign that the rate estimate predicts, see
   ``sign``). A rejected measurement is replaced by the tracker's prediction.
2. AR(p) pattern enhancement (Oikonomou et al. 2006): zG is an AR(p) process whose coefficients
   Gamma follow ``Gamma_n = A Gamma_{n-1} + w`` (A = 0.2 I, eq. 25) and are estimated by a
   Kalman filter from ``zG_n = C_n^T Gamma_n + v`` (C_n = past p values, eq. 26); the enhanced
   pattern is ``zAR_n = C_n^T Gamma^_n`` (eq. 27). p = 10.
3. Peak: the maximum of zAR over an excursion above the threshold
   ``max(beta_en (f_max - f_min) / fs, kappa * noise level of zAR)`` (the paper's fixed threshold,
   plus a noise-relative floor so that the same parameters work at any J/N).
4. Period from the peak times (the paper only says "from successive peaks"). Default: interval
   d_i between successive peaks is consistent when within ``tol`` of q_i = 1 or 2 times the median
   interval (a missed peak gives q = 2); ``T^ = sum d_i / sum q_i`` over the consistent intervals
   of the last 16 peaks; locked when at least ``min_consistent`` intervals, and at least 60 % of
   them, agree. Option ``lattice_voting`` (ours): every distance from the newest peak to one of
   its 4 predecessors, over q = 1, 2, is a candidate T_c, refined by least squares; a peak fits
   when within ``max(min_tolerance_samples, tol T_c)`` of the lattice; score ``fits - (expected -
   fits) / 2``; locked when the fits are significant against chance (in-span peaks times
   2 tol / T, plus four standard deviations plus two), fill a third of the lattice points and 60 %
   of the peaks in the span, and two successive votes agree (two failed votes unlock). It keeps
   lock where one false peak between two true ones breaks the interval rule.

Decimation (documented deviation, for speed): the LPD runs at the full rate; its output is
averaged over ``decimation`` samples (default 4; ``RfiMonitorParams.paper_method()`` uses 2; the
paper runs at the full rate, D = 1) and the AR Kalman filter (low-rank covariance, O(K p) per step, see
``ar_step``) and peak detector run at the decimated rate. A peak time is then known to +-D/2
samples, and the period, a least-squares fit over up to 16 peaks, to a small fraction of D (1 %
of the period at D = 4 in the tests).
The peak is late with respect to the sweep start by the LPD length (the 6-sample difference
reaches its full value 5 samples after the jump) plus the half decimation block; ``delay``
removes this deterministic group delay.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numba import njit

from rfi_node_common.params import parameter

LPD_LAG = 6
"""Lag of the low-pass differentiator G(z) = 1 - z^-6 (Kang et al., eq. 23)."""
AR_ORDER = 10
"""AR model order p (Kang et al., Sec. 3.2)."""
PEAK_RING = 16
"""Number of recent peak times kept for the period estimate."""


class SweepFloat(IntEnum):
    """Slots of the float state of the sweep-period estimator (``initial_state()[0]``)."""

    ZG = 0
    ACC = 1
    NOISE = 2
    PKMAX = 3
    PERIOD = 4
    ZAR = 5
    CAND = 6


class SweepInt(IntEnum):
    """Slots of its int state (``initial_state()[1]``)."""

    DEC = 0
    INPEAK = 1
    PKIDX = 2
    NPEAKS = 3
    RPOS = 4
    RCOUNT = 5
    LOCKED = 6
    ZPOS = 7
    ZCOUNT = 8
    NDEC = 9


class SweepParam(IntEnum):
    """Slots of the packed parameters (``SweepPeriodParams.as_array``)."""

    GAMMA = 0
    NORM = 1
    THR = 2
    KAPPA = 3
    LAMBDA = 4
    DEC = 5
    QAR = 6
    RAR = 7
    A = 8
    DELAY = 9
    MINSEP = 10
    TOL = 11
    MINCONS = 12
    TOLABS = 13
    MAXPER = 14
    VOTING = 15
    ARK = 16


N_SFSTATE = len(SweepFloat)
N_SISTATE = len(SweepInt)
N_SPAR = len(SweepParam)

AR_LR_MAX = 8
"""Most rank-one terms kept by the low-rank AR covariance (see ``ar_step``)."""
AR_LR_TOL = 1e-6
"""Relative weight below which a decayed rank-one term of the AR covariance is dropped."""
# rows of the AR covariance array ``pmat`` (shape (AR_PMAT_ROWS, p)): 0..p-1 the full matrix,
# p scratch, p+1..p+AR_LR_MAX the low-rank vectors, then: their weights, d and the ring pos; scratch
AR_LR_BASE = AR_ORDER + 1
AR_LR_WROW = AR_LR_BASE + AR_LR_MAX
AR_LR_CROW = AR_LR_WROW + 1
AR_PMAT_ROWS = AR_LR_CROW + 1
AR_LR_D = AR_LR_MAX
AR_LR_POS = AR_LR_MAX + 1
assert AR_LR_POS < AR_ORDER
AR_K4 = 4
"""Rank-one terms of the specialised AR step (``_ar_step_k4``): K at the paper's A = 0.2 I."""


def ar_low_rank_terms(a: float, tol: float = AR_LR_TOL) -> int:
    """Rank-one terms K the low-rank AR covariance keeps for a transition ``a`` (-1: full matrix).

    The term dropped after K steps carries the weight ``a^(2 (K + 1))`` relative to a fresh one;
    K is the smallest with ``a^(2 (K + 1)) <= tol`` (a = 0.2: K = 4, dropped weight 1.0e-7).
    """
    a2 = a * a
    if a2 == 0.0:
        return 0
    k = int(math.ceil(math.log(tol) / math.log(a2))) - 1
    return max(k, 0) if k <= AR_LR_MAX else -1

_AR_FASTMATH = {"nsz", "arcp", "contract", "reassoc"}
"""Fast-math flags that keep NaN/inf semantics (no 'nnan'/'ninf'), so finiteness guards still work."""


@dataclass(frozen=True)
class SweepPeriodParams:
    """Design parameters of the sweep-period estimator (Kang et al. give no values; these are ours). Each field
    is described once, with its equation, unit and range, on its definition below (the node's ``sweep_*``
    parameters are these)."""

    forgetting: float = parameter(
        0.92, 'Forgetting factor gamma of the linear prediction detector (eq. 23), [0, 1).',
        minimum=0.0, maximum=0.999999)
    beta: float = parameter(
        1.0, 'Normalisation beta of eq. 23, dimensionless (scaled by the band internally).',
        minimum=1e-12, maximum=1e6)
    beta_en: float = parameter(
        1e-4, 'Enhancement rate beta_en of the peak threshold, dimensionless.', minimum=0.0, maximum=1e6)
    kappa: float = parameter(
        8.0,
        'Peak threshold in multiples of the running mean |zAR|, dimensionless. Lower it if the period does not lock '
        'at low J/N (more false peaks), raise it if it locks on noise.', minimum=1e-6, maximum=1e6)
    noise_time_constant: float = parameter(
        256.0, 'Time constant of the running mean |zAR|, decimated steps.', minimum=1.0, maximum=1e9)
    decimation: int = parameter(
        4, 'Samples averaged per AR(10) step, samples (speed; 1 = full rate).', minimum=1, maximum=1000)
    ar_process_var: float = parameter(
        1.0, 'Diagonal of the AR process noise Q_AR (eq. 25), dimensionless.',
        minimum=1e-12, maximum=1e12)
    ar_measurement_var: float = parameter(
        1.0, 'AR measurement variance sigma_AR^2 (eq. 26), dimensionless.',
        minimum=1e-12, maximum=1e12)
    ar_transition: float = parameter(
        0.2, 'Diagonal of the AR transition matrix A (eq. 25; the paper: 0.2), (-1, 1).',
        minimum=-0.999999, maximum=0.999999)
    delay: float = parameter(
        12.0, 'Samples from a sweep start to its detected peak (detector group delay), samples.',
        minimum=0.0, maximum=1e6)
    min_separation: int = parameter(
        12,
        'Refractory time between two detected sweep starts, samples. Sweeps shorter than this cannot lock: lower it '
        'for very fast sweeps.', minimum=1, maximum=10**9)
    tolerance: float = parameter(
        0.05, 'Relative tolerance of a sweep interval to a multiple of the period, (0, 0.5).',
        minimum=1e-6, maximum=0.499999)
    min_consistent: int = parameter(
        3, 'Peaks fitting the period lattice needed to lock, minus one.', minimum=1, maximum=100000)
    min_tolerance_samples: float = parameter(
        3.0, 'Absolute floor of the lattice tolerance, samples (matters for short periods).',
        minimum=0.0, maximum=1e6)
    max_period: float = parameter(
        10000.0,
        'Longest sweep period considered by the lattice voting, samples (10000 = 262 us at 38.192 MHz). Raise it for '
        'slow sweeps; must exceed sweep_min_separation.', minimum=1.0, maximum=1e9)
    lattice_voting: bool = parameter(
        False,
        'Period by lattice voting over all recent peaks (ours; robust to missed and false peaks) instead of the '
        'successive intervals of the paper. Set false to reproduce the paper.')

    def __post_init__(self) -> None:
        if not 0.0 <= self.forgetting < 1.0:
            raise ValueError("forgetting must be in [0, 1)")
        for name in ("beta", "kappa", "ar_process_var", "ar_measurement_var"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be finite and > 0")
        if not (math.isfinite(self.beta_en) and self.beta_en >= 0):
            raise ValueError("beta_en must be >= 0")
        if not self.noise_time_constant >= 1:
            raise ValueError("noise_time_constant must be >= 1")
        if int(self.decimation) < 1:
            raise ValueError("decimation must be >= 1")
        if not -1.0 < self.ar_transition < 1.0:
            raise ValueError("ar_transition must be in (-1, 1)")
        if not self.delay >= 0:
            raise ValueError("delay must be >= 0")
        if int(self.min_separation) < 1:
            raise ValueError("min_separation must be >= 1")
        if not 0.0 < self.tolerance < 0.5:
            raise ValueError("tolerance must be in (0, 0.5)")
        if int(self.min_consistent) < 1:
            raise ValueError("min_consistent must be >= 1")
        if not (math.isfinite(self.min_tolerance_samples) and self.min_tolerance_samples >= 0):
            raise ValueError("min_tolerance_samples must be finite and >= 0")
        if not (math.isfinite(self.max_period) and self.max_period > self.min_separation):
            raise ValueError("max_period must be finite and > min_separation")

    def as_array(self, band: float) -> np.ndarray:
        """Packed parameters for the kernels; ``band`` = (f_max - f_min) / fs, cycles/sample."""
        return np.array([self.forgetting, self.beta * band, self.beta_en * band, self.kappa,
                         1.0 / self.noise_time_constant, self.decimation, self.ar_process_var,
                         self.ar_measurement_var, self.ar_transition, self.delay, self.min_separation,
                         self.tolerance, self.min_consistent, self.min_tolerance_samples,
                         self.max_period, 1.0 if self.lattice_voting else 0.0,
                         ar_low_rank_terms(self.ar_transition)], dtype=np.float64)


def initial_state() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                             np.ndarray]:
    """(float state, int state, z history, AR Gamma, AR P (``ar_step``), AR history, peaks)."""
    sf = np.zeros(N_SFSTATE)
    sf[SweepFloat.PERIOD] = math.nan
    sf[SweepFloat.CAND] = math.nan
    return (sf, np.zeros(N_SISTATE, dtype=np.int64), np.zeros(LPD_LAG), np.zeros(AR_ORDER),
            initial_ar_covariance(), np.zeros(AR_ORDER), np.zeros(PEAK_RING, dtype=np.int64))


def initial_ar_covariance() -> np.ndarray:
    """AR covariance array of ``ar_step`` for P_0 = I (full rows and low-rank form d = 1, no terms)."""
    pmat = np.zeros((AR_PMAT_ROWS, AR_ORDER))
    pmat[:AR_ORDER] = np.eye(AR_ORDER)
    pmat[AR_LR_WROW, AR_LR_D] = 1.0
    return pmat


@njit(cache=True)
def _update_period_intervals(sf: np.ndarray, si: np.ndarray, peaks: np.ndarray, par: np.ndarray) -> None:
    """Period from successive peak intervals (step 4, default): d_i consistent when within tol of
    q_i = 1 or 2 times the median interval; T = sum d_i / sum q_i; locked when at least
    min_consistent intervals, and 60 % of them, are consistent."""
    cnt = si[SweepInt.RCOUNT]
    if cnt < 2:
        return
    k = peaks.size
    start = (si[SweepInt.RPOS] - cnt) % k
    d = np.empty(cnt - 1)
    prev = peaks[start]
    for i in range(1, cnt):
        cur = peaks[(start + i) % k]
        d[i - 1] = cur - prev
        prev = cur
    med = np.median(d)
    if med <= 0:
        return
    tol = par[SweepParam.TOL]
    sd = 0.0
    sq = 0.0
    nc = 0
    for i in range(d.size):
        q = math.floor(d[i] / med + 0.5)
        if 1 <= q <= 2 and abs(d[i] - q * med) <= tol * med * q:
            sd += d[i]
            sq += q
            nc += 1
    if nc >= int(par[SweepParam.MINCONS]) and 5 * nc >= 3 * d.size:
        sf[SweepFloat.PERIOD] = sd / sq
        si[SweepInt.LOCKED] = 1
    else:
        si[SweepInt.LOCKED] = 0


@njit(cache=True)
def _lattice_fit(d: np.ndarray, tc: float, tol_abs: float, tol_rel: float, kmax: int) -> tuple[int, float, float]:
    """Peaks (distances d to the newest) on the lattice k * tc (1 <= k <= kmax): (fits, span, LS T)."""
    tol = max(tol_abs, tol_rel * tc)
    fit = 1
    span = 0.0
    skd = 0.0
    skk = 0.0
    for b in range(d.size):
        kk = math.floor(d[b] / tc + 0.5)
        if 1 <= kk <= kmax and abs(d[b] - kk * tc) <= tol:
            fit += 1
            span = max(span, d[b])
            skd += kk * d[b]
            skk += kk * kk
    return fit, span, skd / skk if skk > 0 else tc


@njit(cache=True)
def _update_period(sf: np.ndarray, si: np.ndarray, peaks: np.ndarray, par: np.ndarray) -> None:
    """Re-estimate the period from the stored peak times by lattice voting (step 4, module doc).

    Candidates: the distance from the newest peak to each of its 4 nearest predecessors, over
    q = 1, 2. Each candidate is refined twice by least squares (first on lattice numbers <= 4,
    where its error is small, then on all), then scored.
    """
    cnt = si[SweepInt.RCOUNT]
    if cnt < 3:
        return
    k = peaks.size
    newest = peaks[(si[SweepInt.RPOS] - 1) % k]
    d = np.empty(cnt - 1)
    for b in range(1, cnt):
        d[b - 1] = newest - peaks[(si[SweepInt.RPOS] - 1 - b) % k]
    tol_rel, tol_abs, min_sep = par[SweepParam.TOL], par[SweepParam.TOLABS], par[SweepParam.MINSEP]
    best_score = -1e300
    best_t = math.nan
    best_ok = False
    for a in range(min(4, d.size)):
        for q in range(1, 3):
            tc = d[a] / q
            if tc < min_sep:
                break
            if tc > par[SweepParam.MAXPER]:
                continue
            fit, span, tc = _lattice_fit(d, tc, tol_abs, tol_rel, 4)
            fit, span, tc = _lattice_fit(d, tc, tol_abs, tol_rel, 1 << 30)
            fit, span, t_ls = _lattice_fit(d, tc, tol_abs, tol_rel, 1 << 30)
            expected = span / t_ls + 1.0
            # peaks inside the span that do not fit are false peaks
            in_span = 1
            for b in range(d.size):
                if d[b] <= span + tol_abs:
                    in_span += 1
            score = fit - 0.5 * (expected - fit)
            if score > best_score + 1e-9 or (abs(score - best_score) <= 1e-9 and t_ls > best_t):
                best_score, best_t = score, t_ls
                # significance: peaks that fit by chance, in_span p0, with p0 = 2 tol / T
                chance = in_span * min(1.0, 2.0 * max(tol_abs, tol_rel * t_ls) / t_ls)
                best_ok = (fit >= int(par[SweepParam.MINCONS]) + 1 and 3 * fit >= expected
                           and 5 * fit >= 3 * in_span and t_ls <= par[SweepParam.MAXPER]
                           and fit >= chance + 4.0 * math.sqrt(chance) + 2.0)
    # a lattice that fits by chance does not repeat: the previous vote must agree
    prev = sf[SweepFloat.CAND]
    sf[SweepFloat.CAND] = best_t if best_ok else math.nan
    if best_ok and abs(best_t - prev) <= tol_rel * best_t:
        sf[SweepFloat.PERIOD] = best_t
        si[SweepInt.LOCKED] = 1
    elif not best_ok and not prev > 0:
        si[SweepInt.LOCKED] = 0                       # two failed votes in a row unlock


@njit(cache=True, inline="always", fastmath=_AR_FASTMATH)
def _ar_step_full(v: float, gam: np.ndarray, pmat: np.ndarray, hist: np.ndarray, a: float, q_ar: float,
                  r_ar: float) -> float:
    """Full-matrix AR coefficient Kalman step (any |a| < 1); see ``ar_step``."""
    p = AR_ORDER
    a2 = a * a
    pred = 0.0
    for i in range(p):
        gam[i] = a * gam[i]
        pred += hist[i] * gam[i]
    for i in range(p):                     # P- = A P A^T + Q (A = a I)
        for j in range(p):
            pmat[i, j] = a2 * pmat[i, j]
        pmat[i, i] += q_ar
    s = r_ar
    for i in range(p):                     # P- C (scratch row p) and C^T P- C + R
        acc = 0.0
        for j in range(p):
            acc += pmat[i, j] * hist[j]
        pmat[p, i] = acc
        s += hist[i] * acc
    inv_s = 1.0 / s
    innov = (v - pred) * inv_s
    zar = 0.0
    for i in range(p):
        gam[i] += pmat[p, i] * innov
        zar += hist[i] * gam[i]
    for i in range(p):                     # P+ = P- - P-C C^T P- / s
        ki = pmat[p, i] * inv_s
        for j in range(p):
            pmat[i, j] -= ki * pmat[p, j]
    for i in range(p - 1, 0, -1):
        hist[i] = hist[i - 1]
    hist[0] = v
    return zar


@njit(cache=True, inline="always", fastmath=_AR_FASTMATH)
def _dot_row(pmat: np.ndarray, row: int, x: np.ndarray) -> float:
    """pmat[row, :p] . x[:p] with four partial sums (a short dependency chain), p = AR_ORDER."""
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    s3 = 0.0
    for i in range(0, AR_ORDER - 3, 4):
        s0 += pmat[row, i] * x[i]
        s1 += pmat[row, i + 1] * x[i + 1]
        s2 += pmat[row, i + 2] * x[i + 2]
        s3 += pmat[row, i + 3] * x[i + 3]
    for i in range(AR_ORDER - AR_ORDER % 4, AR_ORDER):
        s0 += pmat[row, i] * x[i]
    return (s0 + s1) + (s2 + s3)


@njit(cache=True, inline="always", fastmath=_AR_FASTMATH)
def _dot(a: np.ndarray, x: np.ndarray) -> float:
    """a[:p] . x[:p] with four partial sums, p = AR_ORDER."""
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    s3 = 0.0
    for i in range(0, AR_ORDER - 3, 4):
        s0 += a[i] * x[i]
        s1 += a[i + 1] * x[i + 1]
        s2 += a[i + 2] * x[i + 2]
        s3 += a[i + 3] * x[i + 3]
    for i in range(AR_ORDER - AR_ORDER % 4, AR_ORDER):
        s0 += a[i] * x[i]
    return (s0 + s1) + (s2 + s3)


@njit(cache=True, inline="always", fastmath=_AR_FASTMATH)
def _ar_step_low_rank(v: float, gam: np.ndarray, pmat: np.ndarray, hist: np.ndarray, a: float, q_ar: float,
                      r_ar: float, k_terms: int) -> float:
    """Low-rank AR coefficient Kalman step (``ar_step``, Notes); k_terms >= 0 rank-one terms.

    2-D indexing only (no row views, which cost reference counting in the compiled loop) and dot
    products with partial sums (the step is a serial recursion: its latency counts)."""
    p = AR_ORDER
    u_row = AR_ORDER                        # scratch row: u = P- C
    a2 = a * a
    d = a2 * pmat[AR_LR_WROW, AR_LR_D] + q_ar      # P- = d I - sum_k w_k u_k u_k^T
    pmat[AR_LR_WROW, AR_LR_D] = d
    # c_k = w_k (u_k . C) into the scratch row; s = R + C^T P- C = R + d |C|^2 - sum_k w_k (u_k . C)^2
    s = r_ar + d * _dot(hist, hist)
    for k in range(k_terms):
        wk = a2 * pmat[AR_LR_WROW, k]
        pmat[AR_LR_WROW, k] = wk
        dk = _dot_row(pmat, AR_LR_BASE + k, hist)
        pmat[AR_LR_CROW, k] = wk * dk
        s -= wk * dk * dk
    for i in range(p):                      # u = P- C = d C - sum_k c_k u_k
        acc = d * hist[i]
        for k in range(k_terms):
            acc -= pmat[AR_LR_CROW, k] * pmat[AR_LR_BASE + k, i]
        pmat[u_row, i] = acc
    pred = a * _dot(gam, hist)
    inv_s = 1.0 / s
    innov = (v - pred) * inv_s
    for i in range(p):
        gam[i] = a * gam[i] + pmat[u_row, i] * innov
    zar = _dot(gam, hist)
    if k_terms > 0:                         # P+ = P- - u u^T / s: the new term replaces the oldest
        pos = int(pmat[AR_LR_WROW, AR_LR_POS])
        for i in range(p):
            pmat[AR_LR_BASE + pos, i] = pmat[u_row, i]
        pmat[AR_LR_WROW, pos] = inv_s
        pmat[AR_LR_WROW, AR_LR_POS] = pos + 1 if pos + 1 < k_terms else 0
    for i in range(p - 1, 0, -1):
        hist[i] = hist[i - 1]
    hist[0] = v
    return zar


@njit(cache=True, inline="always", fastmath=_AR_FASTMATH)
def _ar_step_k4(v: float, gam: np.ndarray, pmat: np.ndarray, hist: np.ndarray, a: float, q_ar: float,
                r_ar: float) -> float:
    """Low-rank AR step specialised to K = AR_K4 = 4 terms (the paper's A = 0.2 I); see ``ar_step``.

    Same arithmetic as ``_ar_step_low_rank`` with the K loop unrolled (the term weights and dot
    products live in registers), the K + 2 dot products with C in one pass over it, u written
    straight into the slot of the dropped term (each element is read before it is overwritten), and
    ``zAR = C^T Gamma^_n = pred + (s - sigma_AR^2) innov`` (since ``C^T u = s - sigma_AR^2``) instead
    of a second dot product. About 2x faster per step than the generic loop.
    """
    a2 = a * a
    d = a2 * pmat[AR_LR_WROW, AR_LR_D] + q_ar
    pmat[AR_LR_WROW, AR_LR_D] = d
    w0 = a2 * pmat[AR_LR_WROW, 0]
    w1 = a2 * pmat[AR_LR_WROW, 1]
    w2 = a2 * pmat[AR_LR_WROW, 2]
    w3 = a2 * pmat[AR_LR_WROW, 3]
    pmat[AR_LR_WROW, 0] = w0
    pmat[AR_LR_WROW, 1] = w1
    pmat[AR_LR_WROW, 2] = w2
    pmat[AR_LR_WROW, 3] = w3
    cc = 0.0
    d0 = 0.0
    d1 = 0.0
    d2 = 0.0
    d3 = 0.0
    pg = 0.0
    for i in range(AR_ORDER):
        h = hist[i]
        cc += h * h
        d0 += pmat[AR_LR_BASE, i] * h
        d1 += pmat[AR_LR_BASE + 1, i] * h
        d2 += pmat[AR_LR_BASE + 2, i] * h
        d3 += pmat[AR_LR_BASE + 3, i] * h
        pg += gam[i] * h
    c0 = w0 * d0
    c1 = w1 * d1
    c2 = w2 * d2
    c3 = w3 * d3
    s = r_ar + d * cc - ((c0 * d0 + c1 * d1) + (c2 * d2 + c3 * d3))
    pred = a * pg
    inv_s = 1.0 / s
    innov = (v - pred) * inv_s
    pos = int(pmat[AR_LR_WROW, AR_LR_POS])
    row = AR_LR_BASE + pos
    for i in range(AR_ORDER):
        u = d * hist[i] - ((c0 * pmat[AR_LR_BASE, i] + c1 * pmat[AR_LR_BASE + 1, i])
                           + (c2 * pmat[AR_LR_BASE + 2, i] + c3 * pmat[AR_LR_BASE + 3, i]))
        gam[i] = a * gam[i] + u * innov
        pmat[row, i] = u                       # P+ = P- - u u^T / s: the new term replaces the oldest
    pmat[AR_LR_WROW, pos] = inv_s
    pmat[AR_LR_WROW, AR_LR_POS] = pos + 1 if pos + 1 < AR_K4 else 0
    for i in range(AR_ORDER - 1, 0, -1):
        hist[i] = hist[i - 1]
    hist[0] = v
    return pred + (s - r_ar) * innov


@njit(cache=True, inline="always", fastmath=_AR_FASTMATH)
def ar_step(v: float, gam: np.ndarray, pmat: np.ndarray, hist: np.ndarray, a: float, q_ar: float,
            r_ar: float, k_terms: int) -> float:
    """One step of the AR(p) coefficient Kalman filter (eq. 24-27); returns zAR (eq. 27).

    Args:
        v: new (decimated) LPD value zG.
        gam: Gamma estimate, shape (p,), updated in place.
        pmat: covariance of Gamma, shape (AR_PMAT_ROWS, p) (``initial_ar_covariance``): rows
            0..p-1 the full matrix (used when k_terms < 0), row p scratch, then the low-rank form;
            updated in place.
        hist: C_n = the last p values of zG (newest first), shape (p,), shifted in place.
        a: diagonal of A; q_ar: diagonal of Q_AR; r_ar: sigma_AR^2.
        k_terms: rank-one terms of the low-rank form (``ar_low_rank_terms``); -1: full matrix.

    Notes:
        Kang et al., eq. 24-27 (after Oikonomou et al. 2006) with A = a I, Q = q I:
        ``P-_n = a^2 P+_{n-1} + q I``, ``u = P-_n C_n``, ``s = C_n^T u + sigma_AR^2``,
        ``Gamma^_n = a Gamma^_{n-1} + u (zG_n - a C_n^T Gamma^_{n-1}) / s``, ``P+_n = P-_n - u u^T / s``.
        Low-rank form (speed; exact up to the dropped terms): unrolling the recursion,
        ``P-_n = d_n I - sum_{k>=1} a^(2k) u_{n-k} u_{n-k}^T / s_{n-k}`` with ``d_n = a^2 d_{n-1} + q``.
        A term's weight decays by a^2 per step (0.04 for the paper's A = 0.2 I), so only the last
        K terms are kept (``ar_low_rank_terms``: the first dropped one weighs a^(2 (K + 1)) <= 1e-6
        relative, 1.0e-7 at a = 0.2). Cost O(K p) instead of O(p^2) per step: u = d C - sum_k w_k
        u_k (u_k . C). The stable coefficient filter (A = 0.2 I) does not accumulate the error.
    """
    if k_terms == AR_K4:
        return _ar_step_k4(v, gam, pmat, hist, a, q_ar, r_ar)
    if k_terms >= 0:
        return _ar_step_low_rank(v, gam, pmat, hist, a, q_ar, r_ar, k_terms)
    return _ar_step_full(v, gam, pmat, hist, a, q_ar, r_ar)


@njit(cache=True, inline="always")
def peak_step(n: int, zar: float, sf: np.ndarray, si: np.ndarray, peaks: np.ndarray, par: np.ndarray) -> int:
    """Peak detection on zAR at a decimated step ending at sample n; returns the estimated sweep
    start (sample index, group delay removed) of a newly completed peak, or -1."""
    dec = int(par[SweepParam.DEC])
    si[SweepInt.NDEC] += 1
    sf[SweepFloat.ZAR] = zar
    thr = max(par[SweepParam.THR], par[SweepParam.KAPPA] * sf[SweepFloat.NOISE])
    out = -1
    # after the noise level warms up
    if zar > thr and si[SweepInt.NDEC] > max(2 * AR_ORDER, 1.0 / par[SweepParam.LAMBDA]):
        if si[SweepInt.INPEAK] == 0:
            si[SweepInt.INPEAK] = 1
            sf[SweepFloat.PKMAX] = zar
            si[SweepInt.PKIDX] = n - dec // 2
        elif zar > sf[SweepFloat.PKMAX]:
            sf[SweepFloat.PKMAX] = zar
            si[SweepInt.PKIDX] = n - dec // 2
    else:
        if si[SweepInt.INPEAK] == 1:
            si[SweepInt.INPEAK] = 0
            t_pk = si[SweepInt.PKIDX]
            last = peaks[(si[SweepInt.RPOS] - 1) % peaks.size]
            min_sep = float(par[SweepParam.MINSEP])
            if si[SweepInt.LOCKED] == 1:
                min_sep = max(min_sep, 0.3 * sf[SweepFloat.PERIOD])    # no second peak early in a locked sweep
            if si[SweepInt.RCOUNT] == 0 or t_pk - last >= min_sep:
                peaks[si[SweepInt.RPOS]] = t_pk
                si[SweepInt.RPOS] = (si[SweepInt.RPOS] + 1) % peaks.size
                if si[SweepInt.RCOUNT] < peaks.size:
                    si[SweepInt.RCOUNT] += 1
                si[SweepInt.NPEAKS] += 1
                if par[SweepParam.VOTING] < 0.5:
                    _update_period_intervals(sf, si, peaks, par)
                elif si[SweepInt.LOCKED] == 0 or si[SweepInt.NPEAKS] % 4 == 0:
                    _update_period(sf, si, peaks, par)
                out = t_pk - int(par[SweepParam.DELAY] + 0.5)
        # noise level: EWMA of |zAR| outside peaks
        lam = par[SweepParam.LAMBDA]
        sf[SweepFloat.NOISE] = (1.0 - lam) * sf[SweepFloat.NOISE] + lam * abs(zar)
    return out


@njit(cache=True, fastmath=_AR_FASTMATH, error_model="numpy")
def _run(z: np.ndarray, par: np.ndarray, sign: float, wrap: bool) -> tuple[np.ndarray, np.ndarray,
                                                                           np.ndarray, float, int]:
    sf, si = np.zeros(N_SFSTATE), np.zeros(N_SISTATE, dtype=np.int64)
    sf[SweepFloat.PERIOD] = math.nan
    sf[SweepFloat.CAND] = math.nan
    zhist = np.zeros(LPD_LAG)
    gam = np.zeros(AR_ORDER)
    pmat = np.zeros((AR_PMAT_ROWS, AR_ORDER))
    for i in range(AR_ORDER):
        pmat[i, i] = 1.0
    pmat[AR_LR_WROW, AR_LR_D] = 1.0
    hist = np.zeros(AR_ORDER)
    peaks = np.zeros(PEAK_RING, dtype=np.int64)
    zg_out = np.empty(z.size)
    zar_out = np.empty(z.size)
    starts = np.full(z.size, -1, dtype=np.int64)
    ns = 0
    gamma, norm, dec = par[SweepParam.GAMMA], par[SweepParam.NORM], int(par[SweepParam.DEC])
    zg = 0.0
    acc = 0.0
    ndec = 0
    for n in range(z.size):
        # LPD (eq. 23)
        pos = n % LPD_LAG
        if n >= LPD_LAG:
            dz = z[n] - zhist[pos]
            if wrap:
                dz = dz - math.floor(dz + 0.5)
        else:
            dz = 0.0
        zhist[pos] = z[n]
        zg = gamma * zg - (1.0 - gamma) * dz / norm
        acc += zg * sign
        ndec += 1
        if ndec == dec:
            zar = ar_step(acc / dec, gam, pmat, hist, par[SweepParam.A], par[SweepParam.QAR], par[SweepParam.RAR],
                          int(par[SweepParam.ARK]))
            acc = 0.0
            ndec = 0
            s = peak_step(n, zar, sf, si, peaks, par)
            if s >= 0:
                starts[ns] = s
                ns += 1
        zg_out[n] = zg
        zar_out[n] = sf[SweepFloat.ZAR]
    return zg_out, zar_out, starts[:ns], sf[SweepFloat.PERIOD], si[SweepInt.LOCKED]


def estimate_sweep_period(z: np.ndarray, params: SweepPeriodParams = SweepPeriodParams(), band: float = 0.5,
                          sign: float = 1.0, signed: bool = False
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, bool]:
    """Stand-alone sweep-period estimate from a measurement sequence (the monitor fuses this).

    Args:
        z: IF measurements, cycles/sample, shape (n,), finite.
        params: SweepPeriodParams.
        band: (f_max - f_min) / fs, observable band in cycles/sample (real: 0.5, complex: 1.0).
        sign: +1 up-chirp, -1 down-chirp.
        signed: wrap differences (complex measurements).

    Returns:
        (zG, zAR, sweep_starts, period_samples, locked): zG and zAR shape (n,) (zAR held between
        decimated steps); estimated sweep-start indices; period in samples (NaN if none).
    """
    z = np.ascontiguousarray(z, dtype=np.float64)
    if z.ndim != 1 or not np.all(np.isfinite(z)):
        raise ValueError("z must be 1-D and finite")
    if not band > 0:
        raise ValueError("band must be > 0")
    zg, zar, st, per, lock = _run(z, params.as_array(band), float(sign), bool(signed))
    return zg, zar, st, float(per), bool(lock)
