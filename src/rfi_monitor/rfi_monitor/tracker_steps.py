"""The steps of the fused per-sample loop of ``tracker.track_block``, one function each.

Every function here is compiled inline into the loop (numba ``inline="always"``): the loop keeps its
hot state in local variables and passes it through these functions as scalars and tuples, so that the
compiled code is that of one function (tracker module docstring: method, "Speed" and the paper's
equations). They are split out only to keep each piece readable; they are not meant to be called
alone (the tests call ``step_fit`` and ``step_threshold`` directly).

State tuples passed between the loop and its steps:

* ``FilterState``: the tracking filter's prediction for the next sample (f, df, P11, P12, P22) and its
  adaptive window (wsum, wcount, wpos), as in ``tracking_filters.filter_step``;
* ``LatticeState``: the reset lattice (next start, period, predicted start of the current sweep, its
  covariance l11, l12, l22), the start of the current sweep, the resets so far, the sample of the next
  step fit, the failed fits in a row, the confirmed fits in a row, the tracking mode, the lattice source;
* ``SearchState``: the period search (LPD history position, LPD output, the sweep-signed LPD sum, the
  decimation's running sum, samples in it, decimated steps so far, peaks queued in ``lev``);
* ``LoopControl``: the tracking mode's switch (the aligned window it acts from, the mode, the mode the period
  search is in), the measurements so far, the held zAR, the running power and 1 / kappa of the current window.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from rfi_monitor.sweep_period import SweepFloat, SweepInt, SweepParam
from rfi_monitor.tracker_state import CHUNK, MonitorFloat, MonitorInt, MonitorParam
from rfi_monitor.tracking_filters import kf_sweep_reset

MF, MI, MP = MonitorFloat, MonitorInt, MonitorParam
SF, SI, SQ = SweepFloat, SweepInt, SweepParam

FilterState = tuple[float, float, float, float, float, float, int, int]
LatticeState = tuple[float, float, float, float, float, float, int, int, int, int, int, int, int]
SearchState = tuple[int, float, float, float, int, int, int]
LoopControl = tuple[int, int, int, int, float, float, float]

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
def step_fit(zring: np.ndarray, c: int, w: int, df: float, period: float,
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
def period_search_resume(sf: np.ndarray, si: np.ndarray, peaks: np.ndarray) -> None:
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


@njit(cache=True)
def loop_params(tpar: np.ndarray, spar: np.ndarray, mpar: np.ndarray, mst: np.ndarray, is_complex: bool) -> tuple:
    """The loop's parameters from the packed filter (tpar), sweep-period (spar) and monitor (mpar) parameters:
    (filter mode, R, Q_f, Q_df, reset at sweep starts, wrap, chirp correction, domain margin, step-fit half window,
    lattice period drift, reset cross-covariance, fits that confirm the tracking mode, noise floor of the noise
    compensation (0: none; if_measurement: kappa = 1 - floor / running power), squared near-zero ratio, LPD gamma,
    decimation, LPD scale (1 - gamma) / norm, 1 / decimation, AR(10) a, Q, R, rank terms, the running power's
    window weights (``power_weights``))."""
    refine_w = int(mpar[MP.REFINE_W])
    gamma, dec = spar[SQ.GAMMA], int(spar[SQ.DEC])
    return (int(tpar[0]), tpar[1], tpar[2], tpar[3], mpar[MP.RESET] > 0.5, mpar[MP.WRAP] > 0.5,
            mpar[MP.CHIRP_CORR] > 0.5, mpar[MP.DOMAIN], refine_w, mpar[MP.LAT_DRIFT], mpar[MP.RESET_CROSS] > 0.5,
            int(mpar[MP.CONFIRM]) if refine_w > 0 else 0,
            mst[MF.FLOOR] if (mpar[MP.NOISE_COMP] > 0.5 and not is_complex) else 0.0,
            mpar[MP.MIN_ABS] * mpar[MP.MIN_ABS], gamma, dec, (1.0 - gamma) / spar[SQ.NORM], 1.0 / dec, spar[SQ.A],
            spar[SQ.QAR], spar[SQ.RAR], int(spar[SQ.ARK]), power_weights(mpar[MP.POW_LAMBDA]))


@njit(cache=True, inline="always")
def power_weights(lam: float) -> np.ndarray:
    """Weights lam (1 - lam)^(CHUNK - 1 - j) of the running power's update at the end of an aligned window
    (tracker module doc, "Speed")."""
    pwt = np.empty(CHUNK)
    wj = lam
    for j in range(CHUNK - 1, -1, -1):
        pwt[j] = wj
        wj *= 1.0 - lam
    return pwt


@njit(cache=True, inline="always")
def sweep_reset(m: int, f: float, df: float, p11: float, p12: float, p22: float, last_start: int,
                reset_cross: bool, wrap: bool, nxt: float, tlat: float, l11: float, l12: float, l22: float,
                lat_drift: float, refine_w: int,
                mst: np.ndarray) -> tuple[float, float, float, float, float, float, float, float, int]:
    """Scheduled sweep reset at sample m (the state is the prior of m): back to the posterior at T - 1, then
    eq. 21-22; the lattice filter [start, period] predicted to this sweep and the step fit scheduled.
    Returns (f, P11, P12, the predicted start, the next start, the lattice covariance l11, l12, l22, the sample
    of the step fit or -1)."""
    f, p11, p12 = kf_sweep_reset(f - df, df, p11, p12, p22, float(m - 1 - last_start), reset_cross)
    if wrap:
        f = f - math.floor(f + 0.5)
    mst[MF.F0] = f
    mst[MF.P11_0] = p11
    ppred = nxt
    nxt += tlat
    l11 = l11 + 2.0 * l12 + l22 + LATTICE_PHASE_Q
    l12 = l12 + l22
    l22 = l22 + (lat_drift * tlat) ** 2
    w = min(refine_w, int((tlat - 2.0) * 0.5))
    fitat = m + w if w >= 4 else -1
    return f, p11, p12, ppred, nxt, l11, l12, l22, fitat


@njit(cache=True, inline="always")
def lattice_fit(zring: np.ndarray, m: int, ppred: float, nxt: float, tlat: float, df: float, wrap: bool,
                l11: float, l12: float, l22: float, misses: int, ncons: int, trk: int, latsrc: int,
                confirm_n: int,
                mist: np.ndarray) -> tuple[float, float, float, float, float, int, int, int, int]:
    """Sweep-start fit (ours, module doc) at sample m, the fit window's end: the lattice filter [start, period]
    updated by the measured start, or a miss counted (the lattice dropped after MAX_MISSES, the tracking mode
    ended after RESUME_MISSES). Returns (next start, period, l11, l12, l22, misses, confirmed fits in a row,
    tracking mode, lattice source)."""
    w = m - int(math.ceil(ppred))
    if nxt >= 0.0 and w >= 4:
        s_hat, sz2, sig = step_fit(zring, m - w, w, df, tlat, wrap)
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
    return nxt, tlat, l11, l12, l22, misses, ncons, trk, latsrc


@njit(cache=True, inline="always")
def lpd_sample(zl: float, zold: float, full: bool, sg: float, zg: float, acc: float, wrap: bool, gamma: float,
               lpd_scale: float) -> tuple[float, float]:
    """The LPD (eq. 23) for one sample: its input zl, the input LPD_LAG samples before (zold, used once the
    history is full), the filter's sweep sg after the sample. Returns (the LPD output, the sweep-signed LPD sum).
    Scalars only: it runs every sample (an array argument costs reference counting on every call)."""
    if full:
        dz = zl - zold
        if wrap:
            dz = dz - math.floor(dz + 0.5)
    else:
        dz = 0.0
    zg = gamma * zg - lpd_scale * dz
    return zg, acc + (zg if sg >= 0.0 else -zg)


@njit(cache=True, inline="always")
def queue_peak(lev: np.ndarray, nlev: int, start: int, period: float, locked: int, m: int) -> int:
    """A peak completed at sample m (its sweep start, the LPD period and lock then) queued in lev, to act on the
    lattice at the end of the next aligned window (tracker module doc). Returns the entries queued."""
    lev[4 * nlev] = start
    lev[4 * nlev + 1] = period
    lev[4 * nlev + 2] = locked
    lev[4 * nlev + 3] = m
    return nlev + 1


@njit(cache=True, inline="always")
def apply_peaks(lev: np.ndarray, nlev: int, m_app: int, refine_w: int, tol: float, phase_gain: float, nxt: float,
                tlat: float, latsrc: int, misses: int, ncons: int, l11: float, l12: float, l22: float, nresets: int,
                last_start: int) -> tuple[int, float, float, int, int, int, float, float, float, int]:
    """The queued LPD peaks of the window before the one ending at m_app - 1 act on the reset lattice from
    sample m_app on (module doc): the paper's lattice follows the locked LPD period and is nudged by each peak;
    ours is acquired from a locked peak and then kept by the step fits. The applied entries leave lev.
    Returns (entries left, next start, period, lattice source, misses, confirmed fits, l11, l12, l22, the start
    of the current sweep)."""
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
    return nlev - n_app, nxt, tlat, latsrc, misses, ncons, l11, l12, l22, last_start


@njit(cache=True, inline="always")
def switch_period_search(lpdoff: int, search: SearchState, sf: np.ndarray, si: np.ndarray, peaks: np.ndarray,
                         mist: np.ndarray) -> SearchState:
    """The tracking mode switched (tracker module doc): from suspended (lpdoff 1) the period search resumes
    with a warm restart (the LPD delay line restarted too), otherwise its suspension is counted. The sweep-signed
    LPD sum starts again in both cases. Returns the search state."""
    zpos, zg, acc, zacc, decn, ndec, nlev = search
    if lpdoff == 1:
        period_search_resume(sf, si, peaks)
        zpos = 0
        zg = 0.0
    else:
        mist[MI.NSUSP] += 1
    return zpos, zg, 0.0, zacc, decn, ndec, nlev


@njit(cache=True, inline="always")
def extended_window(xr: np.ndarray, xi: np.ndarray, is_complex: bool, mst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The block behind the two samples carried from the block before (sample k of the block is xe[k + 2]);
    for complex input its imaginary parts likewise (else a placeholder)."""
    n = xr.size
    xe = np.empty(n + 2)
    xe[0], xe[1] = mst[MF.RE2], mst[MF.RE1]
    xe[2:] = xr
    xie = np.empty(n + 2 if is_complex else 1)
    if is_complex:
        xie[0], xie[1] = mst[MF.IM2], mst[MF.IM1]
        xie[2:] = xi
    return xe, xie


@njit(cache=True, inline="always")
def hold_trace(o_zar: np.ndarray, o0: int, upto: int, zprev: float) -> int:
    """The zAR trace held at zprev over the estimates o0 .. upto - 1 (between decimated steps); returns upto."""
    for j in range(o0, upto):
        o_zar[j] = zprev
    return upto
