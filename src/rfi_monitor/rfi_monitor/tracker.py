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
  filter: predicted by one period at each reset (process noise ``LATTICE_PHASE_Q`` on the start,
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
  the tracking mode: the pass resumes with a warm restart (``_period_search_resume``: peaks,
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

from rfi_monitor.if_measurement import (
    STATUS_CORRECTION,
    STATUS_DOMAIN,
    STATUS_NEAR_ZERO,
    STATUS_NON_FINITE,
    STATUS_OK,
    measure_complex_sq,
    measure_real_sq,
)
from rfi_monitor.sweep_period import (
    _AR_FASTMATH,
    LPD_LAG,
    SweepFloat,
    SweepInt,
    SweepParam,
    ar_step,
    peak_step,
)
from rfi_monitor.tracker_state import (
    CHUNK,
    MonitorFloat,
    MonitorInt,
    MonitorParam,
    TraceBuffers,
    TrackerState,
)
from rfi_monitor.tracking_filters import FilterFloat, FilterInt, filter_step, kf_sweep_reset

MF, MI, MP = MonitorFloat, MonitorInt, MonitorParam
SF, SI, SQ = SweepFloat, SweepInt, SweepParam
FF, FI = FilterFloat, FilterInt
"""Short names of the packed layouts (tracker_state, sweep_period, tracking_filters) in the kernel."""

MAX_ABS_RATE = 0.02
"""Clamp of |df| used inside the chirp correction, cycles/sample^2 (guards a diverged estimate)."""
MAX_REFINE_WINDOW = 24
"""Largest half-window W of the sweep-start fit, samples."""
MAX_MISSES = 4
"""Consecutive failed sweep-start fits that drop the lattice."""
RESUME_MISSES = 2
"""Consecutive failed sweep-start fits that end the tracking mode (the period search resumes, so
that it has run for MAX_MISSES - RESUME_MISSES sweeps when the lattice drops)."""
LATTICE_PHASE_Q = 0.01 ** 2
"""Process noise of the sweep-start lattice filter on the start, samples^2 per sweep (jitter of a
jammer's sweep start that does not accumulate)."""


@njit(cache=True, inline="always")
def lattice_init(period: float, half_window: float) -> tuple[float, float, float]:
    """Initial covariance (start, period) of the lattice filter at acquisition, samples^2."""
    return (0.25 * half_window) ** 2, 0.0, (5e-3 * period) ** 2


LATTICE_GATE = 16.0
"""Gate of the lattice filter on the normalised squared start innovation (4 sigma)."""
STEP_FALSE_ALARM = 0.01
"""Probability that the step fit declares a sweep start in a window of noise (a lattice locked on
something that is not a chirp): such a fit is a miss (``step_threshold``)."""


@njit(cache=True, inline="always")
def step_threshold(n: int) -> float:
    """Threshold on the step fit's significance for a window of n samples.

    Without a step the drop of the squared error at a fixed position is chi-square(1) in units of
    the residual variance; the fit takes the best of ~n positions, so the threshold t solves
    ``n P(chi2_1 > t) = STEP_FALSE_ALARM`` with the tail ``sqrt(2 / (pi t)) exp(-t / 2)``:
    ``t = 2 ln(n / a) - ln(pi ln(n / a))`` (13.7 for n = 48, 11.6 for n = 16).
    """
    u = math.log(n / STEP_FALSE_ALARM)
    return 2.0 * u - math.log(math.pi * u)


MIN_KAPPA = 0.8
"""Smallest tone power fraction kappa = 1 - N / P (J/N = 6 dB) at which the noise compensation is
applied; below it the measurement is mostly noise, the compensation would only push more ratios
out of the arccos domain (measured on bags/default: with a floor of 0.5 instead, 14 fewer of the
chirp snapshots at J/N < 0 dB were identified as chirps), and the ratio is used as it is."""


@njit(cache=True, inline="always")
def _step_fit(zring: np.ndarray, c: int, w: int, df: float, period: float,
              wrap: bool) -> tuple[float, float, float]:
    """Least-squares start of the sweep around sample c from zring[c - w .. c + w - 1] (module doc).

    Returns the estimated first sample of the new sweep (absolute index), the residual variance
    of the measurements about the fitted step (cycles^2/sample^2) and the significance of the step:
    the drop of the squared error against a fit without a step, in units of that variance.
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
    best_pk = 0.0
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
            best_pk = pk
    # Significance of a step at best_k with its height fitted freely (a wrong df scales b but does
    # not move the step): drop of the squared error against no step, in residual variances; a step
    # of the wrong sign counts as none.
    tot2 = 0.0
    for i in range(L):
        h = zring[(n0 + i) & mask] - ref - df * i
        if wrap:
            h = h - math.floor(h + 0.5)
        tot2 += h * h
    n1 = float(best_k)
    n2 = float(L - best_k)
    s2 = tot - best_pk
    fit = best_pk * best_pk / n1 + s2 * s2 / n2
    var = max(tot2 - fit, 0.0) / (L - 2)
    gain = fit - tot * tot / L
    if (best_pk / n1 - s2 / n2) * b <= 0.0:
        gain = 0.0
    return float(n0 + best_k), var, gain / max(var, 1e-300)


@njit(cache=True)
def _period_search_resume(sf: np.ndarray, si: np.ndarray, peaks: np.ndarray) -> None:
    """Warm restart of the period search after a suspension (tracking mode, module doc): the peak
    history, the period lock and the peak in progress are forgotten (the jammer may have changed);
    the AR(10) coefficients and covariance, the zAR noise level and the warm-up count are kept, so
    that peaks are detected at once. (The LPD delay line is restarted by the caller.)"""
    noise, ndec = sf[SF.NOISE], si[SI.NDEC]
    sf[:] = 0.0
    sf[SF.PERIOD] = math.nan
    sf[SF.CAND] = math.nan
    sf[SF.NOISE] = noise
    si[:] = 0
    si[SI.NDEC] = ndec
    peaks[:] = 0


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
    """The compiled loop of ``track_block``: the fields of TrackerState and TraceBuffers unpacked, in order."""
    mode = int(tpar[0])
    r, q_f, q_df = tpar[1], tpar[2], tpar[3]
    chirp_corr = mpar[MP.CHIRP_CORR] > 0.5
    min_abs_ratio = mpar[MP.MIN_ABS]
    margin = mpar[MP.DOMAIN]
    lam = mpar[MP.POW_LAMBDA]
    reset_on = mpar[MP.RESET] > 0.5
    phase_gain = mpar[MP.PHASE_GAIN]
    wrap = mpar[MP.WRAP] > 0.5
    refine_w = int(mpar[MP.REFINE_W])
    lat_drift = mpar[MP.LAT_DRIFT]
    reset_cross = mpar[MP.RESET_CROSS] > 0.5
    confirm_n = int(mpar[MP.CONFIRM]) if refine_w > 0 else 0
    # noise compensation (if_measurement): kappa = 1 - floor / running power, floor 0 (unknown) -> 1
    floor = mst[MF.FLOOR] if (mpar[MP.NOISE_COMP] > 0.5 and not is_complex) else 0.0
    tol = spar[SQ.TOL]
    gamma, norm, dec = spar[SQ.GAMMA], spar[SQ.NORM], int(spar[SQ.DEC])
    a_ar, q_ar, r_ar, k_ar = spar[SQ.A], spar[SQ.QAR], spar[SQ.RAR], int(spar[SQ.ARK])
    lpd_scale = (1.0 - gamma) / norm
    inv_dec = 1.0 / dec
    min_abs_ratio2 = min_abs_ratio * min_abs_ratio
    # running power per aligned window (module doc, "Speed"): weights lam (1 - lam)^(CHUNK - 1 - j)
    pwt = np.empty(CHUNK)
    wj = lam
    for j in range(CHUNK - 1, -1, -1):
        pwt[j] = wj
        wj *= 1.0 - lam
    n_ok = 0
    n_near = 0
    n_dom = 0
    n_nonfin = 0
    n_corr = 0
    # ---- load the hot state into locals ---------------------------------------------------------
    f, df, p11, p12, p22, wsum = fst[FF.F], fst[FF.DF], fst[FF.P11], fst[FF.P12], fst[FF.P22], fst[FF.WSUM]
    wcount, wpos = ist[FI.WCOUNT], ist[FI.WPOS]
    re2, im2, re1, im1 = mst[MF.RE2], mst[MF.IM2], mst[MF.RE1], mst[MF.IM1]
    pw = mst[MF.POW]
    ikap_w = mst[MF.IKAP]
    nxt, tlat, ppred = mst[MF.NEXT], mst[MF.TLAT], mst[MF.PPRED]
    l11, l12, l22 = mst[MF.L11], mst[MF.L12], mst[MF.L22]
    zg, acc, zacc = mst[MF.ZG], mst[MF.ACC], mst[MF.ZACC]
    nbuf, last_start, nresets, started = mist[MI.NBUF], mist[MI.LAST_START], mist[MI.NRESETS], mist[MI.STARTED]
    fitat, misses, decn, latsrc, ndec = mist[MI.FITAT], mist[MI.MISSES], mist[MI.DECN], mist[MI.LATSRC], mist[MI.NDEC]
    zpos = mist[MI.ZPOS]
    nmeas = mist[MI.NMEAS]
    nlev = mist[MI.NLEV]
    ncons, trk, swat, swmode, lpdoff = mist[MI.NCONS], mist[MI.TRACK], mist[MI.SWAT], mist[MI.SWMODE], mist[MI.LPDOFF]
    zmask = zring.size - 1
    dmask = zdec.size - 1
    dfmask = dfring.size - 1
    n_out = 0
    m_win = ring.size
    n = xr.size
    # extended window: the two carried samples, then the block (sample k of the block is xe[k + 2])
    xe = np.empty(n + 2)
    xe[0], xe[1] = re2, re1
    xe[2:] = xr
    xie = np.empty(n + 2 if is_complex else 1)
    if is_complex:
        xie[0], xie[1] = im2, im1
        xie[2:] = xi
    j0 = 0
    while nbuf < 2 and j0 < n:                      # stream start: fill the 3-sample window
        p0 = xe[j0 + 2] * xe[j0 + 2] + (xie[j0 + 2] * xie[j0 + 2] if is_complex else 0.0)
        if math.isfinite(p0):
            pw = p0
        nbuf += 1
        j0 += 1
    zbuf = np.empty(2 * CHUNK)
    zlb = np.empty(2 * CHUNK)                       # z (or the prior if rejected) of two chunks, for the LPD
    sgb = np.empty(2 * CHUNK)                       # the filter's df after each sample (its sign: LPD sum)
    qh, lq, mq0, qbase = 0, 0, 0, 0                 # LPD queue: half, length, first sample, first output
    zprev = sf[SF.ZAR]
    o0 = 0
    sbuf = np.empty(2 * CHUNK, dtype=np.int64)
    dfc = np.empty(CHUNK)
    # Software pipeline over chunks of samples inside aligned CHUNK windows: the measurements of
    # chunk c + 1 are computed (a loop the compiler vectorises) before the serial part of chunk c
    # runs, so that the CPU overlaps them with the filter's serial chain. They need only the
    # samples, the running power and df of DF_LAG = 2 CHUNK samples ago (already known), so their
    # values do not depend on where blocks or chunks start.
    jf = j0                                        # next chunk to measure (block index)
    jp = j0                                        # chunk to run (already measured)
    lp = 0
    slot = 0
    while True:
        lf = 0
        if jf < n:
            m0 = first_index + jf - 1
            lf = min(CHUNK - (m0 & (CHUNK - 1)), n - jf)
            o_w = m0 & (CHUNK - 1)
            if o_w == 0:
                # noise compensation factor, once per aligned window (the running power changes
                # little over CHUNK samples; aligned, so that block splitting cannot change it)
                kap = 1.0 - floor / pw if pw > 0.0 else 1.0
                ikap_w = 1.0 / kap if kap >= MIN_KAPPA else 1.0
            # running power: constant inside an aligned window (the near-zero guard's threshold),
            # updated at the window's end from the deviations of its samples (module doc)
            thr_w = min_abs_ratio2 * pw
            for i in range(lf):
                k = jf + i + 1                      # middle sample in xe
                p_m = xe[k] * xe[k] + (xie[k] * xie[k] if is_complex else 0.0)
                pdev[o_w + i] = p_m - pw if math.isfinite(p_m) else 0.0
                dfc[i] = min(MAX_ABS_RATE, max(-MAX_ABS_RATE, dfring[(m0 + i) & dfmask]))
            if o_w + lf == CHUNK:
                u = 0.0
                for j in range(CHUNK):              # fixed order: block splitting cannot change it
                    u += pwt[j] * pdev[j]
                    pdev[j] = 0.0
                pw = pw + u
            b0 = slot * CHUNK
            if is_complex:
                for i in range(lf):
                    k = jf + i + 1
                    zbuf[b0 + i], sbuf[b0 + i] = measure_complex_sq(xe[k - 1], xie[k - 1], xe[k], xie[k],
                                                                    xe[k + 1], xie[k + 1], thr_w)
            else:
                for i in range(lf):
                    k = jf + i + 1
                    zbuf[b0 + i], sbuf[b0 + i] = measure_real_sq(xe[k - 1], xe[k], xe[k + 1], dfc[i], chirp_corr,
                                                                 thr_w, margin, ikap_w)
            # status counters (off the serial loop): one byte per status code, packed in one integer
            packed = 0
            for i in range(lf):
                packed += 1 << (8 * sbuf[b0 + i])
            n_ok += (packed >> (8 * STATUS_OK)) & 0xFF
            n_near += (packed >> (8 * STATUS_NEAR_ZERO)) & 0xFF
            n_dom += (packed >> (8 * STATUS_DOMAIN)) & 0xFF
            n_nonfin += (packed >> (8 * STATUS_NON_FINITE)) & 0xFF
            n_corr += (packed >> (8 * STATUS_CORRECTION)) & 0xFF
        bp = (1 - slot) * CHUNK
        m0 = first_index + jp - 1
        ch = CHUNK - qh                             # half of zlb / sgb for this chunk's LPD inputs
        base = n_out
        # Tracking mode (module doc): the period search is suspended / resumed from the aligned window
        # swat on (decided at the end of the window before it, which the LPD pass never reached yet).
        if lq > 0 and mq0 >= swat >= 0 and lpdoff != swmode:
            if lpdoff == 1:                         # resume (warm restart)
                _period_search_resume(sf, si, peaks)
                zpos = 0
                zg = 0.0
            else:
                mist[MI.NSUSP] += 1
            acc = 0.0
            lpdoff = swmode
        lpd_on = lpdoff == 0
        # The filter over this chunk, interleaved with the LPD / AR(10) / peak pass over the previous
        # chunk (its inputs are queued in the other half of zlb / sgb): the two serial recursions are
        # independent, so the CPU overlaps them (module doc, "Speed").
        for i in range(max(lp, lq)):
            if i < lp:
                m = m0 + i                          # index of the middle sample
                z = zbuf[bp + i]
                status = sbuf[bp + i]
                # --- scheduled sweep reset (the state is the prior of sample m) --------------------
                did_reset = False
                if reset_on and nxt >= 0.0 and m >= nxt:
                    # back to the posterior at T - 1, then eq. 21-22
                    f, p11, p12 = kf_sweep_reset(f - df, df, p11, p12, p22, float(m - 1 - last_start),
                                                 reset_cross)
                    if wrap:
                        f = f - math.floor(f + 0.5)
                    mst[MF.F0] = f
                    mst[MF.P11_0] = p11
                    last_start = m
                    nresets += 1
                    ppred = nxt
                    nxt += tlat
                    # lattice filter: predict [start, period] to this sweep
                    l11 = l11 + 2.0 * l12 + l22 + LATTICE_PHASE_Q
                    l12 = l12 + l22
                    l22 = l22 + (lat_drift * tlat) ** 2
                    did_reset = True
                    w = min(refine_w, int((tlat - 2.0) * 0.5))
                    fitat = m + w if w >= 4 else -1
                prior_f = f
                dfring[m & dfmask] = df             # read by the measurement of m + DF_LAG
                valid = status == STATUS_OK
                # --- filter: update with z (K = 0 if rejected), predict sample m + 1 -----------------
                wp0 = wpos
                (f_post, df_post, p11_post, f, df, p11, p12, p22, ring[wp0], wpos, wcount,
                 wsum) = filter_step(mode, f, df, p11, p12, p22, z, valid, wrap, ring[wpos], wpos, wcount,
                                     m_win, wsum, r, q_f, q_df)
                zl = z if valid else prior_f
                nmeas += 1
                zring[m & zmask] = zl
                zlb[ch + i] = zl                    # LPD input (pass during the next chunk)
                sgb[ch + i] = df
                # --- sweep-start fit (ours) -----------------------------------------------------------
                if refine_w > 0:
                    if fitat >= 0 and m == fitat:
                        fitat = -1
                        w = m - int(math.ceil(ppred))
                        if nxt >= 0.0 and w >= 4:
                            s_hat, sz2, sig = _step_fit(zring, m - w, w, df, tlat, wrap)
                            e = s_hat - ppred - 0.5          # E[ceil(t) - t] = 0.5
                            bj = df * tlat
                            rr = 2.0 * sz2 / max(bj * bj, 1e-12) + 1.0 / 12.0
                            s11 = l11 + rr
                            if abs(e) <= 0.5 * w and e * e <= LATTICE_GATE * s11 and sig >= step_threshold(2 * w):
                                k1 = l11 / s11
                                k2 = l12 / s11
                                nxt += (k1 + k2) * e
                                tlat += k2 * e
                                l11, l12, l22 = l11 - k1 * l11, l12 - k1 * l12, l22 - k2 * l12
                                misses = 0
                                mist[MI.NFIT] += 1
                                ncons += 1
                                if confirm_n > 0 and ncons >= confirm_n:
                                    trk = 1
                            else:
                                misses += 1
                                ncons = 0
                                if misses >= RESUME_MISSES:
                                    trk = 0              # resume the period search (tracking mode)
                                if misses >= MAX_MISSES:
                                    nxt = -1.0
                                    latsrc = 0
                                    trk = 0
                if store:
                    o_idx[n_out] = m
                    o_z[n_out] = z
                    o_f[n_out] = f_post
                    o_df[n_out] = df_post
                    o_p11[n_out] = p11_post
                    o_reset[n_out] = did_reset
                n_out += 1
            if i < lq and not lpd_on:
                # --- tracking mode: only the decimated history of the periodicity detector -------------
                zacc += zlb[qh + i]
                decn += 1
                if decn >= dec:
                    zdec[ndec & dmask] = zacc * inv_dec
                    ndec += 1
                    zacc = 0.0
                    decn = 0
                    if store:
                        for j in range(o0, qbase + i):
                            o_zar[j] = zprev
                        o0 = qbase + i
                    zprev = math.nan
            elif i < lq:
                # --- LPD (eq. 23), decimation, AR(10) step (eq. 24-27), peaks: sample mq0 + i -----------
                zl = zlb[qh + i]
                # zpos counts 0..2 LPD_LAG - 1: >= LPD_LAG once the history is full
                hpos = zpos - LPD_LAG if zpos >= LPD_LAG else zpos
                if zpos >= LPD_LAG:
                    dz = zl - zhist[hpos]
                    if wrap:
                        dz = dz - math.floor(dz + 0.5)
                else:
                    dz = 0.0
                zhist[hpos] = zl
                zpos = zpos + 1 if zpos + 1 < 2 * LPD_LAG else LPD_LAG
                zg = gamma * zg - lpd_scale * dz
                acc += zg if sgb[qh + i] >= 0.0 else -zg
                zacc += zl
                decn += 1
                if decn >= dec:
                    zdec[ndec & dmask] = zacc * inv_dec
                    ndec += 1
                    zar = ar_step(acc * inv_dec, gam, pmat, hist, a_ar, q_ar, r_ar, k_ar)
                    acc = 0.0
                    zacc = 0.0
                    decn = 0
                    start = peak_step(mq0 + i, zar, sf, si, peaks, spar)
                    if start >= 0 and nlev < CHUNK:    # (at most one peak per two decimated steps)
                        lev[4 * nlev] = start
                        lev[4 * nlev + 1] = sf[SF.PERIOD]
                        lev[4 * nlev + 2] = si[SI.LOCKED]
                        lev[4 * nlev + 3] = mq0 + i
                        nlev += 1
                    if store:                            # zAR trace: held between decimated steps
                        for j in range(o0, qbase + i):
                            o_zar[j] = zprev
                        o0 = qbase + i
                    zprev = zar
        if store and lq > 0:                    # zAR trace of the previous chunk: held after its last step
            for j in range(o0, qbase + lq):
                o_zar[j] = zprev
            o0 = qbase + lq
        # ---- the reset lattice --------------------------------------------------------------------------
        # Peaks found in the aligned CHUNK window V (queued in lev with the sample that completed them)
        # act on the lattice at the end of window V + 1, whatever the block split (module doc).
        m_end = m0 + lp - 1
        if lp > 0 and nlev > 0 and (m_end & (CHUNK - 1)) == CHUNK - 1:
            m_app = m_end + 1                        # first sample the lattice acts on
            n_app = 0
            while n_app < nlev and lev[4 * n_app + 3] < m_app - CHUNK:
                n_app += 1
            for j in range(n_app):
                start = int(lev[4 * j])
                per = lev[4 * j + 1]
                lpd_locked = lev[4 * j + 2] > 0.5 and per > 0.0
                if refine_w == 0:
                    # paper method: the lattice exists while the LPD period is locked
                    if not lpd_locked:
                        nxt = -1.0
                        latsrc = 0
                    else:
                        tlat = per
                        if nxt < 0.0:
                            kp = math.ceil((m_app - start) / per)
                            nxt = start + kp * per
                            latsrc = 1
                            if nresets == 0:
                                last_start = start
                        else:
                            u = (start - nxt) / per
                            e = (u - math.floor(u + 0.5)) * per
                            if abs(e) <= 2.0 * tol * per:
                                nxt += phase_gain * e
                elif nxt < 0.0 and lpd_locked:
                    # ours: acquire from the LPD (or the monitor's coarse detector), then the step-fit loop
                    kp = math.ceil((m_app - start) / per)
                    nxt = start + kp * per
                    tlat = per
                    latsrc = 1
                    misses = 0
                    ncons = 0
                    l11, l12, l22 = lattice_init(per, float(refine_w))
                    if nresets == 0:
                        last_start = start
            for j in range(4 * (nlev - n_app)):     # keep the entries of window V + 1
                lev[j] = lev[4 * n_app + j]
            nlev -= n_app
        if confirm_n > 0 and lp > 0 and (m_end & (CHUNK - 1)) == CHUNK - 1 and trk != swmode:
            swmode = trk                             # tracking mode from the next aligned window on
            swat = m_end + 1
        qh, lq, mq0, qbase = ch, lp, m0, base
        if lf == 0 and lq == 0:
            break
        # (after the last chunk, one more pass with lp = 0 runs the LPD over it: its peaks wait in lev
        # for the end of the next window)
        jp, lp, jf, slot = jf, lf, jf + lf, 1 - slot
    if store:
        for j in range(o0, n_out):
            o_zar[j] = zprev
    re2, re1 = xe[n], xe[n + 1]
    if is_complex:
        im2, im1 = xie[n], xie[n + 1]
    # ---- store the state -------------------------------------------------------------------------
    fst[FF.F], fst[FF.DF], fst[FF.P11], fst[FF.P12], fst[FF.P22], fst[FF.WSUM] = f, df, p11, p12, p22, wsum
    ist[FI.WCOUNT], ist[FI.WPOS] = wcount, wpos
    mst[MF.RE2], mst[MF.IM2], mst[MF.RE1], mst[MF.IM1] = re2, im2, re1, im1
    mst[MF.POW] = pw
    mst[MF.IKAP] = ikap_w
    mst[MF.NEXT], mst[MF.TLAT], mst[MF.PPRED] = nxt, tlat, ppred
    mst[MF.L11], mst[MF.L12], mst[MF.L22] = l11, l12, l22
    mst[MF.ZG], mst[MF.ACC], mst[MF.ZACC] = zg, acc, zacc
    mist[MI.NBUF], mist[MI.LAST_START], mist[MI.NRESETS], mist[MI.STARTED] = nbuf, last_start, nresets, started
    mist[MI.FITAT], mist[MI.MISSES], mist[MI.DECN], mist[MI.LATSRC], mist[MI.NDEC] = fitat, misses, decn, latsrc, ndec
    mist[MI.ZPOS] = zpos
    mist[MI.NMEAS] = nmeas
    mist[MI.NLEV] = nlev
    sf[SF.ZAR] = zprev                                # the held zAR trace value (NaN while suspended)
    mist[MI.NCONS], mist[MI.TRACK], mist[MI.SWAT], mist[MI.SWMODE], mist[MI.LPDOFF] = ncons, trk, swat, swmode, lpdoff
    counters[STATUS_OK] += n_ok
    counters[STATUS_NEAR_ZERO] += n_near
    counters[STATUS_DOMAIN] += n_dom
    counters[STATUS_NON_FINITE] += n_nonfin
    counters[STATUS_CORRECTION] += n_corr
    return n_out

