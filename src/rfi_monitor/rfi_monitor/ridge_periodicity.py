"""Stage 4 of the ridge analysis (orchestrated by ``rfi_monitor.ridge.analyse``): the sweep period (ours).

The autocorrelation over frames of the spectral phasor ``u_t`` (``rfi_monitor.ridge_extraction``; mean removed): a CW
is constant (removed with the mean), noise is white, any periodic sweep (any shape, pulsed or not) is periodic. The
first lag whose peak reaches 0.6 of the highest one and stands ``detect_sigma`` noise standard deviations
(``1 / sqrt(2 (T - lag))`` for T frames) and ``min_strength`` above the lowest value before it is the coarse period
(a third or a half of it when the autocorrelation peaks there too: a period of a few frames is smeared by the frame);
it is refined by a least-squares fit over the interpolated peaks at its multiples (up to half the block: the error of
one peak is divided by the number of periods). A multiple's peak enters the fit when it reaches half the coarse
peak's strength, or half the coarse peak where the trough is deeply negative (a sweep over the whole complex band
turns its phasor as a pure rotation: the trough is minus the peak; before this rule no multiple entered and the
period stayed a whole number of frames, 1-4 % off in 5 % of such sequences).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from rfi_monitor.numpy_kernels import first_argmax, pairwise_sum
from rfi_monitor.stft import fft_inplace


def _periodicity(u: np.ndarray, lmin: int, lmax: int, min_strength: float, detect_sigma: float
                 ) -> tuple[float, float]:
    """(period in frames, strength) of the phasor sequence u, or (nan, 0) (module docstring)."""
    T = u.size
    if lmax <= lmin + 2 or T < 4 * lmin:
        return math.nan, 0.0
    nf = 1 << int(math.ceil(math.log2(2 * T)))
    V = np.zeros(nf, dtype=np.complex128)
    # u.mean() without its Python wrapper: the sum divided by the count, numpy's own scalar arithmetic
    np.subtract(u, np.add.reduce(u) / np.intp(T), out=V[:T])
    fft_inplace(V, True)                                 # np.fft.fft(u - u.mean(), nf), to the bit
    R = fft_inplace(V * np.conj(V), False)[:T].real     # np.fft.ifft(V * np.conj(V))[:T].real
    if not R[0] > 0:
        return math.nan, 0.0
    per, strength = _period_from_autocorrelation(np.ascontiguousarray(R), int(lmin), int(lmax),
                                                 float(min_strength), float(detect_sigma))
    return per, strength


@njit(cache=True)
def _period_from_autocorrelation(R: np.ndarray, lmin: int, lmax: int, min_strength: float, detect_sigma: float
                                 ) -> tuple[float, float]:
    """_periodicity after the autocorrelation R (lags 0 .. T - 1, R[0] > 0), compiled: normalised
    autocorrelation, candidate peaks, coarse period, sub-harmonic check, refinement on multiples."""
    T = R.size
    r = np.empty(T)
    sig = np.empty(T)
    for i in range(T):
        r[i] = R[i] / (T - i) * T / R[0]
        sig[i] = 1.0 / np.sqrt(2.0 * max(T - i, 1))
    # peak-to-trough: the peak over the lowest value between lag 1 and it (trough[i] = min r[1 .. i + 1])
    ntr = min(lmax + 1, T - 1)
    trough = np.empty(ntr)
    mn = r[1]
    for i in range(ntr):
        if r[i + 1] < mn:
            mn = r[i + 1]
        trough[i] = mn
    # local maxima of r[lmin .. lmax] that stand out: the first within 0.6 of the highest is the period
    hi_seg = min(lmax, T - 1)
    top = -np.inf
    n_good = 0
    good = np.empty(max(hi_seg - lmin, 1), dtype=np.int64)
    for c in range(lmin + 1, hi_seg):
        if r[c] >= r[c - 1] and r[c] > r[c + 1]:
            prom = r[c] - trough[c - 1]
            if prom >= min_strength and r[c] >= detect_sigma * sig[c] and prom >= detect_sigma * sig[c]:
                good[n_good] = c
                n_good += 1
                if r[c] > top:
                    top = r[c]
    if n_good == 0:
        return np.nan, 0.0
    T0 = float(good[0])
    for g in range(n_good):
        if r[good[g]] >= 0.6 * top:
            T0 = float(good[g])
            break
    # a period of only a few frames is smeared by the frame (its first peak can fall below the second):
    # take T0 / k when the autocorrelation peaks there too (k = 2, 3), at least half as high
    for k in (3, 2):
        c = int(np.rint(T0 / k))
        if c < max(lmin, 2):
            continue
        lo_c, hi_c = max(c - 1, 1), min(c + 1, T - 2)
        j = first_argmax(r, lo_c, hi_c)
        if (r[j] >= r[j - 1] and r[j] >= r[j + 1] and r[j] >= 0.5 * r[int(T0)]
                and r[j] - trough[j - 1] >= max(min_strength, detect_sigma * sig[j])):
            T0 = float(j)
            break
    strength = r[int(T0)] - trough[int(T0) - 1]
    # a multiple's peak counts when it reaches half the strength, or half the first peak where the trough lies below
    # zero by more than that peak's height would allow (a sweep over the whole complex band: its phasor is a pure
    # rotation, the trough is minus the peak, and no multiple reached half the peak-to-trough)
    keep = min(0.5 * strength, 0.5 * r[int(T0)])
    # refine on multiples (least squares through the origin): 1, 2, 3, 4, 6, 9, 13, ... (geometric: the far
    # ones give the precision, each step keeps the search window of the next one within 15 % of the period)
    num, den = 0.0, 0.0
    Tc = T0
    m = 1
    while m * Tc + 2 < T // 2:
        c = int(np.rint(m * Tc))
        w = max(1, int(np.rint(0.15 * Tc)))
        lo, hi = max(c - w, 1), min(c + w, T - 2)
        j = first_argmax(r, lo, hi)
        if r[j] < keep or j <= 0 or j >= T - 1:
            m = m + 1 if m < 4 else m + m // 2
            continue
        a, b, cc = r[j - 1], r[j], r[j + 1]
        den2 = a - 2 * b + cc
        d = 0.5 * (a - cc) / den2 if den2 < 0 else 0.0
        pos = j + max(-0.5, min(0.5, d))
        num += m * pos
        den += m * m
        Tc = num / den
        m = m + 1 if m < 4 else m + m // 2
    if den <= 0:
        return T0, strength
    # then every multiple at once: the block-end frequency is read at the phase of the last sample, ~T / period
    # periods after the first frame, so it needs the period to ~1e-5
    nm = int((T // 2 - 2) / Tc)
    if nm >= 2:
        w = max(1, int(np.rint(0.1 * Tc)))
        mp = np.empty(nm)
        n_ok = 0
        m2 = 0
        for mi in range(1, nm + 1):
            c = int(np.rint(mi * Tc))
            j = min(max(c - w, 1), T - 2)
            for o in range(-w + 1, w + 1):
                q = min(max(c + o, 1), T - 2)
                if r[q] > r[j]:
                    j = q
            a, b, cc = r[j - 1], r[j], r[j + 1]
            den2 = a - 2 * b + cc
            d = 0.5 * (a - cc) / den2 if den2 < 0 else 0.0
            pos = j + min(max(d, -0.5), 0.5)
            if b >= keep:
                mp[n_ok] = mi * pos
                m2 += mi * mi
                n_ok += 1
        if n_ok >= 2:
            Tc = pairwise_sum(mp[:n_ok], 0.0) / m2
    return Tc, strength
