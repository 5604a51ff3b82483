"""Fused per-sample loop: IF measurement -> tracking filter -> LPD/AR sweep period -> sweep resets.

One compiled loop (numba, no Python per sample, no per-sample temporaries) runs, for each new
sample, the three-sample measurement (if_measurement), the filter (tracking_filters), the
sweep-period estimator (sweep_period, AR step at the decimated rate) and the reset scheduler. The
hot state (filter, LPD, decimation, lattice) lives in local variables inside the loop and is
loaded from / stored to the arrays of ``TrackerState`` once per block, so that a stream fed as
one block or as many gives bit-identical per-sample estimates.

Speed (see docs/rfi_monitor/speed.md): the filter's covariance recursion is a serial chain with one
division per sample; everything else is kept off that chain so that the CPU overlaps it:

* arccos by a polynomial (``acos_fast``) instead of libm;
* the chirp correction of eq. 10 uses the sweep estimate ``df`` of ``DF_LAG`` samples earlier
  (a sweep rate changes little over 8 samples; after a reset eq. 21-22 keep df), so the
  measurement of sample n does not wait for the filter update of sample n - 1;
* the AR(10) Kalman step runs every ``decimation`` samples with full-matrix loops under
  NaN-preserving fast-math flags (vectorised).

Reset scheduler, paper method (Kang et al., Sec. 3.1-3.2: "the estimated time index at the peak is
sent to the filter and used to reset the filter"): a peak is detected some samples after the sweep
start, so resetting at the detection time would be late. Once the LPD period is locked we keep a
lattice of predicted sweep starts ``next + k T^`` and reset the filter at each predicted start
(eq. 21-22); every detected peak (minus the estimator's group delay) nudges the lattice phase by
``phase_gain`` times its error when the error is within ``2 tol T^`` (first-order loop).

Additions on top ("ours", switchable, reported separately in the benchmarks):

* Sweep-start refinement (``refine_window`` > 0): ``W`` samples after each reset, the start of the
  sweep just begun is re-estimated from the raw measurements around it by a least-squares step
  fit: with slope df (the filter's) and jump ``B = df T``, ``h_i = z_i - df i`` is ``a + B [i < k]``
  around a start at window index k; the k minimising the squared error (prefix sums, O(W)) is the
  measured start. Its error against the prediction drives a second-order loop on the lattice
  phase and period (gains ``fit_gain``, ``fit_gain^2 / 4``). Four misses in a row (|error| > W/2)
  drop the lattice. This removes the group-delay bias and the decimation jitter of the LPD peaks.
* Lattice seeding from the block-level periodicity detector (``sweep_analysis``), done by the
  monitor at absolute sample boundaries (so block splitting cannot change it), when the LPD
  estimator has not locked (fast or slow sweeps, low J/N).

Sample alignment: the measurement for sample n needs x_{n+1}, so a block of samples
[a, a + N) yields estimates for samples [a - 1, a + N - 1) (the first block: [1, N - 1)).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from rfi_monitor.if_measurement import N_STATUS, STATUS_OK, measure_complex, measure_real
from rfi_monitor.sweep_period import (
    _AR_FASTMATH,
    AR_ORDER,
    J_LOCKED,
    LPD_LAG,
    N_SFSTATE,
    N_SISTATE,
    PEAK_RING,
    Q_A,
    Q_DEC,
    Q_GAMMA,
    Q_NORM,
    Q_QAR,
    Q_RAR,
    Q_TOL,
    S_PERIOD,
    S_ZAR,
    ar_step,
    peak_step,
)
from rfi_monitor.tracking_filters import (
    F_DF,
    F_F,
    F_P11,
    F_P12,
    F_P22,
    F_WSUM,
    I_WCOUNT,
    I_WPOS,
    kf_gain_scale,
    kf_predict,
    kf_sweep_reset,
    kf_update,
    window_push,
)

# monitor float state
(M_RE2, M_IM2, M_RE1, M_IM1, M_POW, M_NEXT, M_F0, M_P11_0, M_TLAT, M_PPRED, M_ZG, M_ACC,
 M_ZACC) = range(13)
N_MSTATE = 13
# monitor int state
(K_NBUF, K_LAST_START, K_NRESETS, K_STARTED, K_NMEAS, K_FITAT, K_MISSES, K_DECN, K_LATSRC, K_NDEC,
 K_NFIT, K_ZPOS) = range(12)
N_MISTATE = 12
# lattice sources
LAT_NONE, LAT_LPD, LAT_COARSE = 0, 1, 2
# packed monitor parameters
(P_CHIRP_CORR, P_MIN_ABS, P_DOMAIN, P_POW_LAMBDA, P_RESET, P_PHASE_GAIN, P_WRAP, P_MAX_DF, P_REFINE_W,
 P_FIT_GAIN) = range(10)
N_MPAR = 10

MAX_ABS_RATE = 0.02
"""Clamp of |df| used inside the chirp correction, cycles/sample^2 (guards a diverged estimate)."""
DF_LAG = 8
"""Samples by which the df used in the chirp correction lags the filter (power of two)."""
Z_RING = 64
"""Recent measurements kept for the sweep-start fit (power of two, > 2 * max refine window)."""
MAX_REFINE_WINDOW = 24
"""Largest half-window W of the sweep-start fit, samples."""
DEC_HISTORY = 4096
"""Decimated measurements kept for the block-level periodicity detector (power of two)."""
MAX_MISSES = 4
"""Consecutive failed sweep-start fits that drop the lattice."""


class TrackerState:
    """All per-sample state of the fused loop (arrays, mutated in place by ``track_block``)."""

    def __init__(self, fst: np.ndarray, ist: np.ndarray, ring: np.ndarray, sp_state: tuple) -> None:
        self.fst, self.ist, self.ring = fst, ist, ring
        (self.sf, self.si, self.zhist, self.gam, self.pmat, self.hist, self.peaks) = sp_state
        assert self.sf.size == N_SFSTATE and self.si.size == N_SISTATE
        assert self.zhist.size == LPD_LAG and self.gam.size == AR_ORDER and self.peaks.size == PEAK_RING
        self.mst = np.zeros(N_MSTATE)
        self.mst[M_NEXT] = -1.0
        self.mst[M_F0] = math.nan
        self.mst[M_P11_0] = math.nan
        self.mst[M_TLAT] = math.nan
        self.mist = np.zeros(N_MISTATE, dtype=np.int64)
        self.mist[K_FITAT] = -1
        self.counters = np.zeros(N_STATUS, dtype=np.int64)
        self.dfring = np.zeros(DF_LAG)
        self.zring = np.zeros(Z_RING)
        self.zdec = np.zeros(DEC_HISTORY)


@njit(cache=True, inline="always")
def _step_fit(zring: np.ndarray, c: int, w: int, df: float, period: float, wrap: bool) -> float:
    """Least-squares start of the sweep around sample c from zring[c - w .. c + w - 1] (module doc).

    Returns the estimated first sample of the new sweep (absolute index).
    """
    mask = zring.size - 1
    b = df * period                       # z is higher by b before the start (up-chirp: b > 0)
    n0 = c - w
    ref = zring[n0 & mask]
    L = 2 * w
    tot = 0.0
    for i in range(L):
        h = zring[(n0 + i) & mask] - ref - df * i
        if wrap:
            h = h - math.floor(h + 0.5)
        tot += h
    best = 1e300
    best_k = w
    pk = 0.0
    for k in range(1, L):
        h = zring[(n0 + k - 1) & mask] - ref - df * (k - 1)
        if wrap:
            h = h - math.floor(h + 0.5)
        pk += h
        u = tot - b * k
        sse = -2.0 * b * pk + b * b * k - u * u / L
        if sse < best:
            best = sse
            best_k = k
    return float(n0 + best_k)


@njit(cache=True, fastmath=_AR_FASTMATH, error_model="numpy")
def track_block(xr: np.ndarray, xi: np.ndarray, is_complex: bool, first_index: int, tpar: np.ndarray,
                spar: np.ndarray, mpar: np.ndarray, fst: np.ndarray, ist: np.ndarray, ring: np.ndarray,
                sf: np.ndarray, si: np.ndarray, zhist: np.ndarray, gam: np.ndarray, pmat: np.ndarray,
                hist: np.ndarray, peaks: np.ndarray, mst: np.ndarray, mist: np.ndarray, counters: np.ndarray,
                dfring: np.ndarray, zring: np.ndarray, zdec: np.ndarray,
                store: bool, o_idx: np.ndarray, o_z: np.ndarray, o_f: np.ndarray, o_df: np.ndarray,
                o_p11: np.ndarray, o_zar: np.ndarray, o_reset: np.ndarray) -> int:
    """Run the fused loop over one block; returns the number of estimates produced.

    Args:
        xr, xi: real part and imaginary part (complex only; else any array) of the block, shape (N,).
        is_complex: I/Q input.
        first_index: absolute index of xr[0].
        tpar, spar, mpar: packed filter, sweep-period and monitor parameters.
        fst ... zdec: state (see TrackerState), updated in place.
        store: write per-sample outputs o_* (each shape (N,)); else they may have size 1.
    """
    mode = int(tpar[0])
    r, q_f, q_df = tpar[1], tpar[2], tpar[3]
    chirp_corr = mpar[P_CHIRP_CORR] > 0.5
    min_abs_ratio = mpar[P_MIN_ABS]
    margin = mpar[P_DOMAIN]
    lam = mpar[P_POW_LAMBDA]
    reset_on = mpar[P_RESET] > 0.5
    phase_gain = mpar[P_PHASE_GAIN]
    wrap = mpar[P_WRAP] > 0.5
    refine_w = int(mpar[P_REFINE_W])
    g1 = mpar[P_FIT_GAIN]
    g2 = 0.25 * g1 * g1
    tol = spar[Q_TOL]
    gamma, norm, dec = spar[Q_GAMMA], spar[Q_NORM], int(spar[Q_DEC])
    a_ar, q_ar, r_ar = spar[Q_A], spar[Q_QAR], spar[Q_RAR]
    m_win = ring.size
    # ---- load the hot state into locals ---------------------------------------------------------
    f, df, p11, p12, p22, wsum = fst[F_F], fst[F_DF], fst[F_P11], fst[F_P12], fst[F_P22], fst[F_WSUM]
    wcount, wpos = ist[I_WCOUNT], ist[I_WPOS]
    re2, im2, re1, im1 = mst[M_RE2], mst[M_IM2], mst[M_RE1], mst[M_IM1]
    pw = mst[M_POW]
    nxt, tlat, ppred = mst[M_NEXT], mst[M_TLAT], mst[M_PPRED]
    zg, acc, zacc = mst[M_ZG], mst[M_ACC], mst[M_ZACC]
    nbuf, last_start, nresets, started = mist[K_NBUF], mist[K_LAST_START], mist[K_NRESETS], mist[K_STARTED]
    fitat, misses, decn, latsrc, ndec = mist[K_FITAT], mist[K_MISSES], mist[K_DECN], mist[K_LATSRC], mist[K_NDEC]
    zpos = mist[K_ZPOS]
    nmeas = mist[K_NMEAS]
    zmask = zring.size - 1
    dmask = zdec.size - 1
    dfmask = dfring.size - 1
    n_out = 0
    for j in range(xr.size):
        re_n = xr[j]
        im_n = xi[j] if is_complex else 0.0
        if nbuf < 2:
            re2, im2 = re1, im1
            re1, im1 = re_n, im_n
            nbuf += 1
            if math.isfinite(re_n) and math.isfinite(im_n):
                pw = re_n * re_n + im_n * im_n
            continue
        m = first_index + j - 1                     # index of the middle sample
        p_m = re1 * re1 + im1 * im1
        if math.isfinite(p_m):
            pw = (1.0 - lam) * pw + lam * p_m
        min_abs = min_abs_ratio * math.sqrt(pw)
        # --- time update and scheduled sweep reset ------------------------------------------
        did_reset = False
        if started == 1:
            f, df, p11, p12, p22 = kf_predict(f, df, p11, p12, p22, q_f, q_df)
            if reset_on and nxt >= 0.0 and m >= nxt:
                # back to the posterior at T - 1, then eq. 21-22
                f, p11, p12 = kf_sweep_reset(f - df, df, p11, p22, float(m - 1 - last_start))
                if wrap:
                    f = f - math.floor(f + 0.5)
                mst[M_F0] = f
                mst[M_P11_0] = p11
                last_start = m
                nresets += 1
                ppred = nxt
                nxt += tlat
                did_reset = True
                w = min(refine_w, int((tlat - 2.0) * 0.5))
                fitat = m + w if w >= 4 else -1
        started = 1
        prior_f = f
        # --- measurement (eq. 8/10 or complex counterpart) ------------------------------------
        if is_complex:
            z, status = measure_complex(re2, im2, re1, im1, re_n, im_n, min_abs)
        else:
            dfl = dfring[m & dfmask]                 # df of DF_LAG samples ago
            dfc = min(MAX_ABS_RATE, max(-MAX_ABS_RATE, dfl))
            z, status = measure_real(re2, re1, re_n, dfc, chirp_corr, min_abs, margin)
        dfring[m & dfmask] = df
        counters[status] += 1
        if status == STATUS_OK:
            nu = z - f
            if wrap:
                nu = nu - math.floor(nu + 0.5)
            wpos, wcount, wsum = window_push(ring, wpos, wcount, wsum, nu * nu)
            c_hat = max(wsum, 0.0) / (m_win - 1) if wcount >= m_win else -1.0
            g = kf_gain_scale(mode, p11 + r, c_hat, p11)
            f, df, p11, p12, p22 = kf_update(f, df, p11, p12, p22, nu, r, g)
            zl = z
        else:
            zl = prior_f
        nmeas += 1
        zring[m & zmask] = zl
        # --- LPD (eq. 23) and decimation -------------------------------------------------------
        # zpos counts 0..2 LPD_LAG - 1: >= LPD_LAG once the history is full (no modulo per sample)
        hpos = zpos - LPD_LAG if zpos >= LPD_LAG else zpos
        if zpos >= LPD_LAG:
            dz = zl - zhist[hpos]
            if wrap:
                dz = dz - math.floor(dz + 0.5)
        else:
            dz = 0.0
        zhist[hpos] = zl
        zpos = zpos + 1 if zpos + 1 < 2 * LPD_LAG else LPD_LAG
        zg = gamma * zg - (1.0 - gamma) * dz / norm
        sgn = 1.0 if df >= 0.0 else -1.0
        acc += zg * sgn
        zacc += zl
        decn += 1
        start = -1
        if decn >= dec:
            zdec[ndec & dmask] = zacc / dec
            ndec += 1
            zar = ar_step(acc / dec, gam, pmat, hist, a_ar, q_ar, r_ar)
            acc = 0.0
            zacc = 0.0
            decn = 0
            start = peak_step(m, zar, sf, si, peaks, spar)
        # --- reset lattice ------------------------------------------------------------------------
        per = sf[S_PERIOD]
        lpd_locked = si[J_LOCKED] == 1 and per > 0.0
        if refine_w == 0:
            # paper method: the lattice exists while the LPD period is locked
            if not lpd_locked:
                nxt = -1.0
                latsrc = 0
            else:
                tlat = per
                if start >= 0:
                    if nxt < 0.0:
                        k = math.ceil((m + 1 - start) / per)
                        nxt = start + k * per
                        latsrc = 1
                        if nresets == 0:
                            last_start = start
                    else:
                        u = (start - nxt) / per
                        e = (u - math.floor(u + 0.5)) * per
                        if abs(e) <= 2.0 * tol * per:
                            nxt += phase_gain * e
        else:
            # ours: acquire from the LPD (or the monitor's coarse detector), then the step-fit loop
            if nxt < 0.0 and lpd_locked and start >= 0:
                k = math.ceil((m + 1 - start) / per)
                nxt = start + k * per
                tlat = per
                latsrc = 1
                misses = 0
                if nresets == 0:
                    last_start = start
            if fitat >= 0 and m == fitat:
                fitat = -1
                w = m - int(math.ceil(ppred))
                if nxt >= 0.0 and w >= 4:
                    s_hat = _step_fit(zring, m - w, w, df, tlat, wrap)
                    e = s_hat - ppred - 0.5          # E[ceil(t) - t] = 0.5
                    if abs(e) <= 0.5 * w:
                        nxt += g1 * e
                        tlat += g2 * e
                        misses = 0
                        mist[K_NFIT] += 1
                    else:
                        misses += 1
                        if misses >= MAX_MISSES:
                            nxt = -1.0
                            latsrc = 0
        # --- shift the 3-sample window ---------------------------------------------------------
        re2, im2 = re1, im1
        re1, im1 = re_n, im_n
        if store:
            o_idx[n_out] = m
            o_z[n_out] = z
            o_f[n_out] = f
            o_df[n_out] = df
            o_p11[n_out] = p11
            o_zar[n_out] = sf[S_ZAR]
            o_reset[n_out] = did_reset
        n_out += 1
    # ---- store the state -------------------------------------------------------------------------
    fst[F_F], fst[F_DF], fst[F_P11], fst[F_P12], fst[F_P22], fst[F_WSUM] = f, df, p11, p12, p22, wsum
    ist[I_WCOUNT], ist[I_WPOS] = wcount, wpos
    mst[M_RE2], mst[M_IM2], mst[M_RE1], mst[M_IM1] = re2, im2, re1, im1
    mst[M_POW] = pw
    mst[M_NEXT], mst[M_TLAT], mst[M_PPRED] = nxt, tlat, ppred
    mst[M_ZG], mst[M_ACC], mst[M_ZACC] = zg, acc, zacc
    mist[K_NBUF], mist[K_LAST_START], mist[K_NRESETS], mist[K_STARTED] = nbuf, last_start, nresets, started
    mist[K_FITAT], mist[K_MISSES], mist[K_DECN], mist[K_LATSRC], mist[K_NDEC] = fitat, misses, decn, latsrc, ndec
    mist[K_ZPOS] = zpos
    mist[K_NMEAS] = nmeas
    return n_out

