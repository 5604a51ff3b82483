"""Fused per-sample loop: IF measurement -> tracking filter -> LPD/AR sweep period -> sweep resets.

One compiled loop (numba, no Python per sample, no per-sample temporaries) runs, chunk by chunk of
CHUNK = 16 samples, the three-sample measurement (if_measurement), the filter (tracking_filters),
then the sweep-period estimator (sweep_period: LPD, AR step at the decimated rate, peaks) and the
reset scheduler. The
hot state (filter, LPD, decimation, lattice) lives in local variables inside the loop and is
loaded from / stored to the arrays of ``TrackerState`` once per block, so that a stream fed as
one block or as many gives bit-identical per-sample estimates.

Speed (see docs/rfi_monitor/speed.md):

* the three-sample measurements are computed one chunk of CHUNK = 16 samples ahead of the serial
  part (software pipeline) in a loop the compiler vectorises; they need the filter's df only
  ``DF_LAG`` = 32 samples late (a sweep rate changes little over 32 samples; after a reset eq.
  21-22 keep df), written without data-dependent branches and with one division
  (``if_measurement.measure_real_sq``); arccos by a polynomial, sin/cos of pi df by Taylor terms;
* the filter step (``tracking_filters.filter_step``) has one division and no branch: a rejected
  sample runs the same arithmetic with K = 0; the update and the next prediction are fused;
* the LPD, the AR(10) Kalman step and the peak detector of one chunk run interleaved with the
  filter of the next chunk (one loop body: the filter only queues the LPD inputs, z or the prior
  when rejected, and the sign of df, in one half of a double buffer, and the LPD pass consumes the
  other half), so that the CPU overlaps the two independent serial recursions; after the last
  chunk of a block one more pass runs the LPD alone (so the LPD state at a block end is complete,
  as the monitor's block-level detector needs). The AR step keeps its covariance in
  a low-rank form (``sweep_period.ar_step``, K = 4 rank-one terms at A = 0.2 I, relative error
  1e-7, unrolled in ``_ar_step_k4``) and runs every ``decimation`` samples;
* the status counters are counted per chunk, one byte per status code packed in one integer;
* the running power P (near-zero guard ``|x_n|^2 <= min_abs_ratio^2 P``, noise compensation
  kappa = 1 - N / P) is the exponential average ``P <- P + lam (p_m - P)`` evaluated once per
  aligned CHUNK window: P stays constant inside the window and at its end becomes
  ``P + sum_j lam (1 - lam)^(CHUNK - 1 - j) (p_j - P)``, which is the same average (to rounding;
  a non-finite sample contributes p_j = P instead of being skipped), without a per-sample serial
  recursion in the measurement loop. The deviations are kept in ``pdev`` and summed in a fixed
  order, so block splitting cannot change the result; the guard's threshold lags by < CHUNK
  samples of a 1024-sample average (docs/rfi_monitor/speed.md);
* the hot state lives in local variables, the per-status counters too; per-sample helpers take
  scalars only (an array argument costs reference counting on every call).

Reset scheduler, paper method (Kang et al., Sec. 3.1-3.2: "the estimated time index at the peak is
sent to the filter and used to reset the filter"): a peak is detected some samples after the sweep
start, so resetting at the detection time would be late. Once the LPD period is locked we keep a
lattice of predicted sweep starts ``next + k T^`` and reset the filter at each predicted start
(eq. 21-22); every detected peak (minus the estimator's group delay) nudges the lattice phase by
``phase_gain`` times its error when the error is within ``2 tol T^`` (first-order loop). The peaks
found in the aligned CHUNK window V are queued in ``lev`` with the sample that completed them and act
on the lattice at the end of window V + 1 (the LPD pass of V runs during the filter of V + 1; also
across a block boundary inside a window, so block splitting cannot change the result), i.e. CHUNK to
2 CHUNK - 1 = 16..31 samples after the decimated step that completed them; a lattice acquired then
starts at the first predicted start after that window.

Additions on top ("ours", switchable, reported separately in the benchmarks):

* Sweep-start refinement (``refine_window`` > 0): ``W`` samples after each reset, the start of the
  sweep just begun is re-estimated from the raw measurements around it by a least-squares step
  fit: with slope df (the filter's) and jump ``B = df T``, ``h_i = z_i - df i`` is ``a + B [i < k]``
  around a start at window index k; the k minimising the squared error (prefix sums, O(W)) is the
  measured start. The lattice (start of the current sweep, period) is then a two-state Kalman
  filter: predicted by one period at each reset (process noise ``tracker_steps.LATTICE_PHASE_Q`` on the start,
  a relative random walk ``lattice_period_drift`` on the period), updated by the measured start
  with the variance ``2 s^2 / B^2 + 1/12`` samples^2 (s^2 the fit's residual variance, 1/12 the
  integer start), so that its gains shrink as sweeps accumulate (at J/N 11 dB the reset falls one
  sample early or late in 20 % of the sweeps, against 29 % with a fixed-gain loop). A fit
  is a miss when it lies outside the window half, fails the filter's 4-sigma gate, or shows no
  significant step of the expected sign (``step_threshold``: a lattice locked on noise must not
  be confirmed by it); four misses in a row drop the lattice. This removes the group-delay bias
  and the decimation jitter of the LPD peaks.
* Lattice seeding from the block-level periodicity detector (``sweep_analysis``), done by the
  monitor at absolute sample boundaries (so block splitting cannot change it), when the LPD
  estimator has not locked (fast or slow sweeps, low J/N).
* Tracking mode (``confirm_fits`` > 0, needs the step fit; speed, as acquisition vs tracking in a
  GNSS receiver; the paper keeps everything running): while a lattice exists, the LPD peaks are
  not read (they only acquire a lattice), so after ``confirm_fits`` successful fits in a row
  (``MonitorInt.TRACK``) the LPD / AR(10) / peak pass is suspended; only the decimated history of the
  periodicity detector (``zdec``) is kept up, and the monitor skips that detector too
  (``SweepAnalysisParams.skip_while_tracking``). ``RESUME_MISSES`` = 2 failed fits in a row end
  the tracking mode: the pass resumes with a warm restart (``tracker_steps.period_search_resume``: peaks,
  lock and period forgotten, the LPD delay line restarted, the AR(10) filter and the zAR noise
  level kept, so that peaks are found at once), and has run for two sweeps when the fourth miss
  drops the lattice. The per-sample frequency track does not change while the lattice is held;
  after a drop, re-acquisition starts from the restarted search instead of a continuously running
  one (a 7.3 us chirp replacing a 5.1 us one is re-acquired at its period; the continuous search
  locked twice that period at J/N 8 dB; test_tracking_mode.py). While suspended the zAR trace is
  NaN and ``sweep_period``'s lock and period are frozen (the lattice gives the period). The switch
  is decided at the end of an aligned CHUNK window and acts on the LPD pass from the next window
  on (``MonitorInt.SWAT``, ``MonitorInt.SWMODE``; the LPD pass of a window always runs after the filter of the
  window before it), so block splitting cannot change it (tested).

Sample alignment: the measurement for sample n needs x_{n+1}, so a block of samples
[a, a + N) yields estimates for samples [a - 1, a + N - 1) (the first block: [1, N - 1)).
The filter state stored between blocks (``fst``) is the prediction for the next sample; the
per-sample traces hold the posterior of each sample.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from rfi_monitor.if_measurement import N_STATUS, STATUS_OK, measure_complex_sq, measure_real_sq
from rfi_monitor.sweep_period import _AR_FASTMATH, LPD_LAG, SweepFloat, SweepInt, SweepParam, ar_step, peak_step
from rfi_monitor.tracker_state import (
    CHUNK,
    MonitorFloat,
    MonitorInt,
    MonitorParam,
    TraceBuffers,
    TrackerState,
)
from rfi_monitor.tracker_steps import (
    MAX_ABS_RATE,
    MIN_KAPPA,
    FilterState,
    LatticeState,
    LoopControl,
    SearchState,
    apply_peaks,
    extended_window,
    hold_trace,
    lattice_fit,
    loop_params,
    lpd_sample,
    queue_peak,
    sweep_reset,
    switch_period_search,
)
from rfi_monitor.tracking_filters import FilterFloat, FilterInt, filter_step

MF, MI, MP = MonitorFloat, MonitorInt, MonitorParam
SF, SI, SQ = SweepFloat, SweepInt, SweepParam
FF, FI = FilterFloat, FilterInt
"""Short names of the packed layouts (tracker_state, sweep_period, tracking_filters) in the kernel."""


_NO_TRACES = TraceBuffers(np.empty(1, dtype=np.int64), np.empty(1), np.empty(1), np.empty(1), np.empty(1),
                         np.empty(1), np.empty(1, dtype=np.bool_))


def track_block(xr: np.ndarray, xi: np.ndarray, is_complex: bool, first_index: int, tpar: np.ndarray,
                spar: np.ndarray, mpar: np.ndarray, state: TrackerState, out: TraceBuffers | None) -> int:
    """Run the fused loop over one block; returns the number of estimates produced.

    Args:
        xr, xi: real part and imaginary part (complex only; else any array) of the block, shape (N,).
        is_complex: I/Q input.
        first_index: absolute index of xr[0].
        tpar, spar, mpar: packed filter, sweep-period and monitor (``MonitorParam``) parameters.
        state: updated in place.
        out: per-sample outputs (each shape (N,)), or None for none.
    """
    store = out is not None
    return _track_block(xr, xi, is_complex, first_index, tpar, spar, mpar, *state, store,
                        *(out if out is not None else _NO_TRACES))


@njit(cache=True, fastmath=_AR_FASTMATH, error_model="numpy")
def _track_block(xr: np.ndarray, xi: np.ndarray, is_complex: bool, first_index: int, tpar: np.ndarray,
                spar: np.ndarray, mpar: np.ndarray, fst: np.ndarray, ist: np.ndarray, ring: np.ndarray,
                sf: np.ndarray, si: np.ndarray, zhist: np.ndarray, gam: np.ndarray, pmat: np.ndarray,
                hist: np.ndarray, peaks: np.ndarray, mst: np.ndarray, mist: np.ndarray, counters: np.ndarray,
                dfring: np.ndarray, zring: np.ndarray, zdec: np.ndarray, lev: np.ndarray, pdev: np.ndarray,
                store: bool, o_idx: np.ndarray, o_z: np.ndarray, o_f: np.ndarray, o_df: np.ndarray,
                o_p11: np.ndarray, o_zar: np.ndarray, o_reset: np.ndarray) -> int:
    """The compiled entry of ``track_block`` (the fields of TrackerState and TraceBuffers unpacked, in order): the
    hot state loaded from its arrays into the tuples of tracker_steps, the loop run once over the block
    (``_track_loop``), the state stored back."""
    filt = (fst[FF.F], fst[FF.DF], fst[FF.P11], fst[FF.P12], fst[FF.P22], fst[FF.WSUM], ist[FI.WCOUNT], ist[FI.WPOS])
    lat = (mst[MF.NEXT], mst[MF.TLAT], mst[MF.PPRED], mst[MF.L11], mst[MF.L12], mst[MF.L22], mist[MI.LAST_START],
           mist[MI.NRESETS], mist[MI.FITAT], mist[MI.MISSES], mist[MI.NCONS], mist[MI.TRACK], mist[MI.LATSRC])
    search = (mist[MI.ZPOS], mst[MF.ZG], mst[MF.ACC], mst[MF.ZACC], mist[MI.DECN], mist[MI.NDEC], mist[MI.NLEV])
    pw, nbuf = mst[MF.POW], mist[MI.NBUF]
    n = xr.size
    xe, xie = extended_window(xr, xi, is_complex, mst)
    j0 = 0
    while nbuf < 2 and j0 < n:                      # stream start: fill the 3-sample window
        p0 = xe[j0 + 2] * xe[j0 + 2] + (xie[j0 + 2] * xie[j0 + 2] if is_complex else 0.0)
        if math.isfinite(p0):
            pw = p0
        nbuf += 1
        j0 += 1
    ctrl = (mist[MI.SWAT], mist[MI.SWMODE], mist[MI.LPDOFF], mist[MI.NMEAS], sf[SF.ZAR], pw, mst[MF.IKAP])
    filt, lat, search, ctrl, o0 = _track_loop(
        xe, xie, is_complex, first_index, j0, filt, lat, search, ctrl, tpar, spar, mpar,
        (ring, dfring, zring, zhist, zdec, gam, pmat, hist, sf, si, peaks, lev, mst, mist, pdev, counters),
        store, (o_idx, o_z, o_f, o_df, o_p11, o_zar, o_reset))
    n_out = ctrl[3] - mist[MI.NMEAS]                # the estimates of this block (one per measurement)
    if store:
        hold_trace(o_zar, o0, n_out, ctrl[4])       # zAR trace: held after the last decimated step

    # ---- store the state -------------------------------------------------------------------------
    mst[MF.RE2], mst[MF.RE1] = xe[n], xe[n + 1]
    if is_complex:
        mst[MF.IM2], mst[MF.IM1] = xie[n], xie[n + 1]
    fst[FF.F], fst[FF.DF], fst[FF.P11], fst[FF.P12], fst[FF.P22], fst[FF.WSUM], ist[FI.WCOUNT], ist[FI.WPOS] = filt
    (mst[MF.NEXT], mst[MF.TLAT], mst[MF.PPRED], mst[MF.L11], mst[MF.L12], mst[MF.L22], mist[MI.LAST_START],
     mist[MI.NRESETS], mist[MI.FITAT], mist[MI.MISSES], mist[MI.NCONS], mist[MI.TRACK], mist[MI.LATSRC]) = lat
    mist[MI.ZPOS], mst[MF.ZG], mst[MF.ACC], mst[MF.ZACC], mist[MI.DECN], mist[MI.NDEC], mist[MI.NLEV] = search
    mist[MI.SWAT], mist[MI.SWMODE], mist[MI.LPDOFF], mist[MI.NMEAS], sf[SF.ZAR], mst[MF.POW], mst[MF.IKAP] = ctrl
    mist[MI.NBUF] = nbuf
    return n_out


@njit(cache=True, fastmath=_AR_FASTMATH, error_model="numpy")
def _track_loop(xe: np.ndarray, xie: np.ndarray, is_complex: bool, first_index: int, j0: int, filt: FilterState,
                lat: LatticeState, search: SearchState, ctrl: LoopControl, tpar: np.ndarray, spar: np.ndarray,
                mpar: np.ndarray, arrays: tuple, store: bool,
                outs: tuple) -> tuple[FilterState, LatticeState, SearchState, LoopControl, int]:
    """The loop over the block xe[2:] from index j0 (module doc: software pipeline over aligned CHUNK windows); arrays =
    the state arrays, outs = the traces, ctrl: ``tracker_steps.LoopControl``. Steps inside take scalars only: an array
    argument of an inlined call costs reference counting per call (measured: +40 % per block)."""
    ring, dfring, zring, zhist, zdec, gam, pmat, hist, sf, si, peaks, lev, mst, mist, pdev, counters = arrays
    o_idx, o_z, o_f, o_df, o_p11, o_zar, o_reset = outs
    swat, swmode, lpdoff, nmeas, zprev, pw, ikap_w = ctrl
    (mode, r, q_f, q_df, reset_on, wrap, chirp_corr, margin, refine_w, drift, cross, confirm_n, floor, near_sq,
     gamma, dec, lpd_scale, inv_dec, a_ar, q_ar, r_ar, k_ar, pwt) = loop_params(tpar, spar, mpar, mst, is_complex)
    zmask, dmask, dfmask, m_win, n = zring.size - 1, zdec.size - 1, dfring.size - 1, ring.size, xe.size - 2
    f, df, p11, p12, p22, wsum, wcount, wpos = filt
    nxt, tlat, ppred, l11, l12, l22, last_start, nresets, fitat, misses, ncons, trk, latsrc = lat
    zpos, zg, acc, zacc, decn, ndec, nlev = search
    zbuf, zlb, sgb, dfc, sbuf = (np.empty(2 * CHUNK), np.empty(2 * CHUNK), np.empty(2 * CHUNK), np.empty(CHUNK),
                                 np.empty(2 * CHUNK, dtype=np.int64))
    qh, lq, mq0, qbase = 0, 0, 0, 0       # LPD queue (zlb: z or the prior, sgb: df after it): half, length, ...
    o0, n_out, jf, jp, lp, slot = 0, 0, j0, j0, 0, 0   # jf: next chunk to measure, jp: chunk to run (measured)
    while True:
        lf = 0
        if jf < n:     # measure chunk jf (the filter's df of DF_LAG samples ago suffices: module doc, "Speed")
            m0, b0, o_w = first_index + jf - 1, slot * CHUNK, (first_index + jf - 1) & (CHUNK - 1)
            lf = min(CHUNK - o_w, n - jf)
            if o_w == 0:   # noise compensation factor, once per aligned window (block splitting cannot change it)
                kap = 1.0 - floor / pw if pw > 0.0 else 1.0
                ikap_w = 1.0 / kap if kap >= MIN_KAPPA else 1.0
            thr_w, packed = near_sq * pw, 0   # running power: constant in an aligned window (module doc)
            for i in range(lf):
                p_m = xe[jf + i + 1] * xe[jf + i + 1] + (xie[jf + i + 1] * xie[jf + i + 1] if is_complex else 0.0)
                pdev[o_w + i] = p_m - pw if math.isfinite(p_m) else 0.0
                dfc[i] = min(MAX_ABS_RATE, max(-MAX_ABS_RATE, dfring[(m0 + i) & dfmask]))
            if o_w + lf == CHUNK:
                u = 0.0
                for j in range(CHUNK):              # fixed order: block splitting cannot change it
                    u, pdev[j] = u + pwt[j] * pdev[j], 0.0
                pw = pw + u
            if is_complex:
                for i, k in enumerate(range(jf + 1, jf + lf + 1)):
                    zbuf[b0 + i], sbuf[b0 + i] = measure_complex_sq(xe[k - 1], xie[k - 1], xe[k], xie[k],
                                                                    xe[k + 1], xie[k + 1], thr_w)
            else:
                for i, k in enumerate(range(jf + 1, jf + lf + 1)):
                    zbuf[b0 + i], sbuf[b0 + i] = measure_real_sq(xe[k - 1], xe[k], xe[k + 1], dfc[i],
                                                                 chirp_corr, thr_w, margin, ikap_w)
            for i in range(lf):
                packed += 1 << (8 * sbuf[b0 + i])
            for code in range(N_STATUS):   # statuses counted off the serial loop: one byte per code
                counters[code] += (packed >> (8 * code)) & 0xFF
        m0, bp, ch, base = first_index + jp - 1, (1 - slot) * CHUNK, CHUNK - qh, n_out
        if lq > 0 and mq0 >= swat >= 0 and lpdoff != swmode:    # tracking mode switched (module doc)
            zpos, zg, acc, zacc, decn, ndec, nlev = switch_period_search(
                lpdoff, (zpos, zg, acc, zacc, decn, ndec, nlev), sf, si, peaks, mist)
            lpdoff = swmode
        for i in range(max(lp, lq)):
            if i < lp:     # the filter over sample m, interleaved with the period search of the chunk before
                m, z, valid = m0 + i, zbuf[bp + i], sbuf[bp + i] == STATUS_OK
                did_reset = reset_on and nxt >= 0.0 and m >= nxt
                if did_reset:      # scheduled sweep reset (the state is the prior of sample m), eq. 21-22
                    f, p11, p12, ppred, nxt, l11, l12, l22, fitat = sweep_reset(
                        m, f, df, p11, p12, p22, last_start, cross, wrap, nxt, tlat, l11, l12, l22, drift,
                        refine_w, mst)
                    last_start, nresets = m, nresets + 1
                prior_f = f
                dfring[m & dfmask] = df             # read by the measurement of m + DF_LAG
                wp0 = wpos         # filter: update with z (K = 0 if rejected), predict sample m + 1
                (f_post, df_post, p11_post, f, df, p11, p12, p22, ring[wp0], wpos, wcount,
                 wsum) = filter_step(mode, f, df, p11, p12, p22, z, valid, wrap, ring[wpos], wpos, wcount,
                                     m_win, wsum, r, q_f, q_df)
                zl = z if valid else prior_f
                nmeas += 1
                zring[m & zmask] = zl
                zlb[ch + i], sgb[ch + i] = zl, df   # LPD input (pass during the next chunk)
                if refine_w > 0 and fitat >= 0 and m == fitat:    # sweep-start fit (ours)
                    fitat = -1
                    nxt, tlat, l11, l12, l22, misses, ncons, trk, latsrc = lattice_fit(
                        zring, m, ppred, nxt, tlat, df, wrap, l11, l12, l22, misses, ncons, trk, latsrc, confirm_n,
                        mist)
                if store:
                    o_idx[n_out], o_z[n_out], o_f[n_out], o_df[n_out] = m, z, f_post, df_post
                    o_p11[n_out], o_reset[n_out] = p11_post, did_reset
                n_out += 1
            if i < lq:     # the period search over sample mq0 + i: LPD (eq. 23) unless suspended, decimation
                zl = zlb[qh + i]
                if lpdoff == 0:
                    hpos = zpos - LPD_LAG if zpos >= LPD_LAG else zpos   # zpos counts 0 .. 2 LPD_LAG - 1
                    zg, acc = lpd_sample(zl, zhist[hpos], zpos >= LPD_LAG, sgb[qh + i], zg, acc, wrap, gamma,
                                         lpd_scale)
                    zhist[hpos] = zl
                    zpos = zpos + 1 if zpos + 1 < 2 * LPD_LAG else LPD_LAG
                zacc, decn = zacc + zl, decn + 1
                if decn >= dec:    # decimated step: AR(10) step (eq. 24-27) and peaks unless suspended
                    zdec[ndec & dmask], zar = zacc * inv_dec, math.nan
                    if lpdoff == 0:
                        zar = ar_step(acc * inv_dec, gam, pmat, hist, a_ar, q_ar, r_ar, k_ar)
                        start = peak_step(mq0 + i, zar, sf, si, peaks, spar)
                        if start >= 0 and nlev < CHUNK:    # (at most one peak per two decimated steps)
                            nlev = queue_peak(lev, nlev, start, sf[SF.PERIOD], si[SI.LOCKED], mq0 + i)
                    ndec, acc, zacc, decn = ndec + 1, (0.0 if lpdoff == 0 else acc), 0.0, 0
                    if store:                            # zAR trace: held between decimated steps
                        o0 = hold_trace(o_zar, o0, qbase + i, zprev)
                    zprev = zar
        if store and lq > 0:                    # zAR trace of the previous chunk: held after its last step
            o0 = hold_trace(o_zar, o0, qbase + lq, zprev)
        m_end = m0 + lp - 1   # the reset lattice: the peaks of window V act at the end of window V + 1 (module doc)
        if lp > 0 and (m_end & (CHUNK - 1)) == CHUNK - 1:
            if nlev > 0:
                nlev, nxt, tlat, latsrc, misses, ncons, l11, l12, l22, last_start = apply_peaks(
                    lev, nlev, m_end + 1, refine_w, spar[SQ.TOL], mpar[MP.PHASE_GAIN], nxt, tlat, latsrc, misses, ncons,
                    l11, l12, l22, nresets, last_start)
            if confirm_n > 0 and trk != swmode:
                swmode, swat = trk, m_end + 1        # tracking mode from the next aligned window on
        qh, lq, mq0, qbase = ch, lp, m0, base
        if lf == 0 and lq == 0:
            break
        jp, lp, jf, slot = jf, lf, jf + lf, 1 - slot   # (after the last chunk, a pass with lp = 0: its LPD)
    return ((f, df, p11, p12, p22, wsum, wcount, wpos),
            (nxt, tlat, ppred, l11, l12, l22, last_start, nresets, fitat, misses, ncons, trk, latsrc),
            (zpos, zg, acc, zacc, decn, ndec, nlev), (swat, swmode, lpdoff, nmeas, zprev, pw, ikap_w), o0)
