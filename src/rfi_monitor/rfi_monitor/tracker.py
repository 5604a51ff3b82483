"""Fused per-sample loop: IF measurement -> tracking filter -> LPD/AR sweep-period -> sweep resets.

One compiled loop (numba, no Python per sample) runs, for each new sample, the three-sample
measurement (if_measurement), the filter (tracking_filters), the sweep-period estimator
(sweep_period) and the reset scheduler. All state lives in arrays owned by ``TrackerState`` so
that a stream fed as one block or as many gives bit-identical per-sample estimates.

Reset scheduler (Kang et al., Sec. 3.1-3.2: "the estimated time index at the peak is sent to the
filter and used to reset the filter"): a peak is detected some samples after the sweep start,
so resetting at the detection time would be late. Once the period is locked we instead keep a
lattice of predicted sweep starts ``next_start + k T^`` and reset the filter exactly at each
predicted start (eq. 21-22); every detected peak (minus the estimator's group delay) nudges the
lattice phase by ``phase_gain`` times its error when the error is within ``2 tol T^`` (a
first-order phase-locked loop). Before lock, and for a CW, no reset happens.

Sample alignment: the measurement for sample n needs x_{n+1}, so a block of samples
[a, a + N) yields estimates for samples [a - 1, a + N - 1) (the first block: [1, N - 1)).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from rfi_monitor.if_measurement import N_STATUS, STATUS_OK, measure_complex, measure_real
from rfi_monitor.sweep_period import (
    AR_ORDER,
    J_LOCKED,
    LPD_LAG,
    N_SFSTATE,
    N_SISTATE,
    PEAK_RING,
    S_PERIOD,
    S_ZAR,
    sweep_step,
)
from rfi_monitor.tracking_filters import F_DF, F_F, F_P11, kf_predict, kf_sweep_reset, kf_update

# monitor float state
M_RE2, M_IM2, M_RE1, M_IM1, M_POW, M_NEXT, M_F0, M_P11_0 = range(8)
N_MSTATE = 8
# monitor int state
K_NBUF, K_LAST_START, K_NRESETS, K_STARTED, K_NMEAS = range(5)
N_MISTATE = 5
# packed monitor parameters
P_CHIRP_CORR, P_MIN_ABS, P_DOMAIN, P_POW_LAMBDA, P_RESET, P_PHASE_GAIN, P_WRAP, P_MAX_DF = range(8)
N_MPAR = 8

MAX_ABS_RATE = 0.02
"""Clamp of |df| used inside the chirp correction, cycles/sample^2 (guards a diverged estimate)."""


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
        self.mist = np.zeros(N_MISTATE, dtype=np.int64)
        self.counters = np.zeros(N_STATUS, dtype=np.int64)


@njit(cache=True)
def track_block(xr: np.ndarray, xi: np.ndarray, is_complex: bool, first_index: int, tpar: np.ndarray,
                spar: np.ndarray, mpar: np.ndarray, fst: np.ndarray, ist: np.ndarray, ring: np.ndarray,
                sf: np.ndarray, si: np.ndarray, zhist: np.ndarray, gam: np.ndarray, pmat: np.ndarray,
                hist: np.ndarray, peaks: np.ndarray, mst: np.ndarray, mist: np.ndarray, counters: np.ndarray,
                store: bool, o_idx: np.ndarray, o_z: np.ndarray, o_f: np.ndarray, o_df: np.ndarray,
                o_p11: np.ndarray, o_zar: np.ndarray, o_reset: np.ndarray) -> int:
    """Run the fused loop over one block; returns the number of estimates produced.

    Args:
        xr, xi: real part and imaginary part (complex only; else any array) of the block, shape (N,).
        is_complex: I/Q input.
        first_index: absolute index of xr[0].
        tpar, spar, mpar: packed filter, sweep-period and monitor parameters.
        fst ... counters: state (see TrackerState), updated in place.
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
    tol = spar[11]
    n_out = 0
    for j in range(xr.size):
        re_n = xr[j]
        im_n = xi[j] if is_complex else 0.0
        if mist[K_NBUF] < 2:
            mst[M_RE2], mst[M_IM2] = mst[M_RE1], mst[M_IM1]
            mst[M_RE1], mst[M_IM1] = re_n, im_n
            mist[K_NBUF] += 1
            if math.isfinite(re_n) and math.isfinite(im_n):
                mst[M_POW] = re_n * re_n + im_n * im_n
            continue
        m = first_index + j - 1                     # index of the middle sample
        re_m, im_m = mst[M_RE1], mst[M_IM1]
        p_m = re_m * re_m + im_m * im_m
        if math.isfinite(p_m):
            mst[M_POW] = (1.0 - lam) * mst[M_POW] + lam * p_m
        min_abs = min_abs_ratio * math.sqrt(mst[M_POW])
        # --- time update and scheduled sweep reset ------------------------------------------
        did_reset = False
        if mist[K_STARTED] == 1:
            kf_predict(fst, q_f, q_df)
            if reset_on and si[J_LOCKED] == 1 and mst[M_NEXT] >= 0.0 and m >= int(mst[M_NEXT] + 0.5):
                fst[F_F] -= fst[F_DF]               # back to the posterior at T - 1
                kf_sweep_reset(fst, float(m - 1 - mist[K_LAST_START]))
                if wrap:
                    fst[F_F] = fst[F_F] - math.floor(fst[F_F] + 0.5)
                mst[M_F0] = fst[F_F]
                mst[M_P11_0] = fst[F_P11]
                mist[K_LAST_START] = m
                mist[K_NRESETS] += 1
                mst[M_NEXT] += sf[S_PERIOD]
                did_reset = True
        mist[K_STARTED] = 1
        prior_f = fst[F_F]
        # --- measurement (eq. 8/10 or complex counterpart) ------------------------------------
        if is_complex:
            z, status = measure_complex(mst[M_RE2], mst[M_IM2], re_m, im_m, re_n, im_n, min_abs)
        else:
            dfc = min(MAX_ABS_RATE, max(-MAX_ABS_RATE, fst[F_DF]))
            z, status = measure_real(mst[M_RE2], re_m, re_n, dfc, chirp_corr, min_abs, margin)
        counters[status] += 1
        if status == STATUS_OK:
            kf_update(fst, ist, ring, z, r, mode, wrap)
            zl = z
        else:
            zl = prior_f
        mist[K_NMEAS] += 1
        # --- sweep period and reset lattice ----------------------------------------------------
        sgn = 1.0 if fst[F_DF] >= 0.0 else -1.0
        start = sweep_step(m, zl, sf, si, zhist, gam, pmat, hist, peaks, spar, sgn, wrap)
        per = sf[S_PERIOD]
        if si[J_LOCKED] == 0 or not per > 0.0:
            mst[M_NEXT] = -1.0
        elif start >= 0:
            if mst[M_NEXT] < 0.0:
                k = math.ceil((m + 1 - start) / per)
                mst[M_NEXT] = start + k * per
                if mist[K_NRESETS] == 0:
                    mist[K_LAST_START] = start
            else:
                u = (start - mst[M_NEXT]) / per
                e = (u - math.floor(u + 0.5)) * per
                if abs(e) <= 2.0 * tol * per:
                    mst[M_NEXT] += phase_gain * e
        # --- shift the 3-sample window ---------------------------------------------------------
        mst[M_RE2], mst[M_IM2] = re_m, im_m
        mst[M_RE1], mst[M_IM1] = re_n, im_n
        if store:
            o_idx[n_out] = m
            o_z[n_out] = z
            o_f[n_out] = fst[F_F]
            o_df[n_out] = fst[F_DF]
            o_p11[n_out] = fst[F_P11]
            o_zar[n_out] = sf[S_ZAR]
            o_reset[n_out] = did_reset
        n_out += 1
    return n_out
