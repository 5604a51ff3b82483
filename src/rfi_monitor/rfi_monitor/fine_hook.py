"""The hook test of a saw-tooth at the resolution of a sample (ours; called by ``rfi_monitor.ridge.analyse`` after the
shape of stage 5, ``rfi_monitor.sweep_shape``).

A hook's return shorter than two profile bins and a frame is not seen by the short-time spectrum. ``fine_profile``:
the lag products a[n + 1] conj(a[n]) of the samples, analytic for real input (``analytic_signal``), folded on the
period and averaged over the block's periods, the noise's own lag product removed (``noise_lag_product``);
``fine_return``: hooked when the way back crosses the span in >= ``FINE_MIN_RETURN`` bins at full strength, where an
instantaneous flyback gives at most two (``fine_hook_shape``: the shape after the test; a way back lasting a
triangle's side makes a triangle). A hook whose return crosses the span in fewer than about 4 samples, or a weak one,
is not resolved: the jammer is reported as the saw-tooth it is otherwise. Measured (a hook of 15 % of an 18 us period
overshooting by 10 % of the span, 4 seeds, 1 ms blocks): hooked in 4 of 4 from J/N 6 dB at 10 MS/s I/Q and from
10-15 dB at 16.368 and 38.192 MS/s real (2 of 4 and 1 of 4 at 6 dB), never at 0-3 dB; at 4 MS/s I/Q (a return of
about 5 samples) in at most 2 of 4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy import fft as sp_fft

from rfi_monitor.sweep_shape import HOOKED_SAWTOOTH, RETURN_MARGIN, SAWTOOTH_UP, TRIANGLE, TRIANGLE_SIDE

FINE_MAX_BINS = 512
"""fine_profile: at most this many phase bins (one per sample for periods up to this many samples, else
ceil(period / FINE_MAX_BINS) samples per bin: a hook lasting a share of the period stays as many bins long)."""
FINE_PRESENT_Z = 6.0
"""fine_profile: a phase bin holds the jammer when the modulus of its mean lag product (the noise's removed) exceeds
this many standard errors of that mean (and ``FINE_MIN_JN``). Were the mean circular Gaussian, |mean|^2 / se^2 would
be a unit exponential (4 standard errors: 1e-7 of the bins); it is not quite (products of Gaussian samples have heavy
tails, a bin holds only as many runs as the block has periods, and the standard error is estimated from them):
measured on white noise, real and complex, 4,000-38,192 samples, periods 20-2,500 samples, 1.8e5 bins: block maxima
3.8 (median), 6.5 (90 %)."""
FINE_MIN_JN = 0.25
"""fine_profile: a present phase bin's mean lag product (the jammer's power there) is at least this share of the
noise power (J/N -6 dB in the bin): the profile is meant for jammers from about J/N 0 dB (below, the frames'
coherent gain of ``folded_shape`` is needed), and noise alone, with the small error of its lag product estimated
from the in-block spectrum, stays under it (white noise and the real clean captures: no bin present). Limit: on a
strongly coloured noise (a 7-tap low-pass passing ~20 % of a complex band) that estimate is off by more and bins of
noise alone pass; the hook decision still needs a saw-tooth found by the STFT profile and a way back of
``FINE_MIN_RETURN`` bins at its full strength."""
FINE_MIN_RETURN = 4
"""analyse: a saw-tooth is hooked when its way back from the sweep's end (``fine_return``) crosses the swept span
(more than ``RETURN_MARGIN`` of it from either end) in at least this many phase bins at full strength. An
instantaneous flyback gives at most two such bins: the lag product that straddles it reads the two frequencies
weighted by where the flyback falls between its samples (an intermediate frequency at full strength), and the phase
bin that straddles it averages both sides (a period off by its ~1e-5 relative error adds < 0.2 samples over a
1 ms block). Measured on the plain saw-tooths of real_jammers.md (10 MS/s complex, 16.368 and 38.192 MS/s real,
2-bit captures): 0-2 bins; on its hooked saw-tooth (a 0.9 us return at 10 MS/s): 6-7."""
FINE_MAG_SHARE = 0.5
"""fine_return: a bin on the way back counts at full strength when the modulus of its mean lag product is at least
this share of the median over the profile's present bins (a swept return is the jammer itself, at its amplitude;
a bin whose samples fall on both sides of an instantaneous flyback averages two phasors apart by the swept span
times 2 pi, and loses strength)."""


def analytic_signal(x: np.ndarray) -> np.ndarray:
    """The analytic signal of real samples (the negative frequencies removed, the positive ones doubled, by FFT over
    the next fast length: the padding's edge effect reaches only the last few samples), complex128, shape (n,).
    Complex samples are returned as they are (complex128)."""
    x = np.asarray(x)
    if np.iscomplexobj(x):
        return np.ascontiguousarray(x, dtype=np.complex128)
    n = x.size
    m = sp_fft.next_fast_len(n, real=True)
    X = sp_fft.rfft(np.asarray(x, dtype=np.float64), m)
    A = np.zeros(m, dtype=np.complex128)
    A[:X.size] = X
    A[1:(m + 1) // 2] *= 2.0
    return sp_fft.ifft(A, overwrite_x=True)[:n]


@njit(cache=True)
def _lag_fold_kernel(a: np.ndarray, period: float, K: int, lag: int, split: int
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per phase bin (K bins of the period) and per half of the block (products before ``split``: bins 0..K-1, after:
    K..2K-1) the sums that fine_profile needs of the lag products z[n] = a[n + lag] conj(a[n]) (phase of their mid
    point n + lag / 2). The consecutive products that fall in one bin in one pass of the period form a run (their
    noise is correlated: coloured noise, a lag > 1): per bin the sum of the products, and over its runs j of n_j
    products summing to r_j: sum |r_j|^2, sum n_j r_j, sum n_j^2 and sum n_j (so the variance of the bin's mean is
    taken over runs, not over correlated products). One pass, compiled."""
    s = np.zeros(2 * K, dtype=np.complex128)
    q = np.zeros(2 * K)
    u = np.zeros(2 * K, dtype=np.complex128)
    n2 = np.zeros(2 * K)
    c = np.zeros(2 * K)
    cur = -1
    rr = 0j
    nr = 0.0
    for i in range(a.size - lag + 1):
        k = -2
        z = 0j
        if i < a.size - lag:
            z = a[i + lag] * np.conj(a[i])
            k = int((((i + 0.5 * lag) / period) % 1.0) * K)
            if k > K - 1:
                k = K - 1
            if i >= split:
                k += K
        if k != cur:
            if cur >= 0:                                 # flush the run
                s[cur] += rr
                q[cur] += rr.real * rr.real + rr.imag * rr.imag
                u[cur] += nr * rr
                n2[cur] += nr * nr
                c[cur] += nr
            cur, rr, nr = k, 0j, 0.0
        rr += z
        nr += 1.0
    return s, q, u, n2, c


def noise_lag_product(levels: np.ndarray, freqs: np.ndarray, noise_power: float, cplx: bool, lag: int = 1
                      ) -> complex:
    """Expected lag product of the noise alone, E[n[m + lag] conj(n[m])] of the (analytic) samples: the noise's
    autocorrelation at ``lag`` from its in-block spectrum (``noise_levels``: the Wiener-Khinchin sum of the levels
    times exp(2 pi i f lag), normalised) times its power (the analytic signal of real noise has twice the real
    power). A coloured front end (a filter not centred on 0 Hz, a real IF's one-sided band) makes it non-zero: a
    bias of the profile towards the noise's mean frequency, removed before the angle is read."""
    lv = np.asarray(levels, dtype=np.float64)
    tot = float(np.sum(lv))
    if not (tot > 0 and math.isfinite(tot) and math.isfinite(noise_power)):
        return 0j
    rho = complex(np.sum(lv * np.exp(2j * np.pi * np.asarray(freqs, dtype=np.float64) * lag)) / tot)
    return rho * float(noise_power) * (1.0 if cplx else 2.0)


@dataclass(frozen=True)
class FineProfile:
    """Sample-resolution sweep profile (``fine_profile``), per phase bin of the period.

    Attributes:
        frequency: instantaneous frequency, cycles/sample (complex input in [-0.5, 0.5), real in [-0.25, 0.75)),
            NaN where the jammer is absent; shape (K,).
        magnitude: modulus of the mean lag product less the noise's, sample units^2; shape (K,).
        z: that modulus over its standard error; shape (K,).
        present: z > ``FINE_PRESENT_Z`` and magnitude above ``FINE_MIN_JN`` of the noise power; shape (K,).
        bin_samples: samples per phase bin.
    """

    frequency: np.ndarray
    magnitude: np.ndarray
    z: np.ndarray
    present: np.ndarray
    bin_samples: float


def fine_profile(x: np.ndarray, cplx: bool, period_samples: float, noise_lag: complex = 0j, noise_power: float = 0.0,
                 lag: int = 1) -> FineProfile | None:
    """Sweep profile at the resolution of a sample, by synchronous averaging of lag products (ours).

    The instantaneous frequency of a tone a[n] = A exp(2 pi i phi(n)) is read from its lag product
    z[n] = a[n + lag] conj(a[n]) = |A|^2 exp(2 pi i (phi(n + lag) - phi(n))): the mean frequency over the lag, with
    no frame and so no smearing over a frame's L samples (the STFT profile's limit: a hook lasting less than two
    phase bins and a frame is not resolved). Noise makes z noisy but not biased beyond the noise's own lag product
    (``noise_lag_product``, removed here): folding z on the known period into K phase bins (one per sample up to
    ``FINE_MAX_BINS`` bins) and averaging over the block's periods (synchronous averaging) gives, per phase bin, a
    mean whose angle / (2 pi lag) is the jammer's frequency there and whose modulus against its standard error
    (from the spread of the bin's own products, / sqrt(count)) says whether the jammer is there (a sweep wider than
    the band is absent in band for part of the period). Real input is made analytic first (``analytic_signal``).

    The per-bin signal-to-noise ratio is J sqrt(n / (N^2 + 2 J N)) for n products per bin: good for a jammer
    around J/N 0 dB and above; a weaker one needs the frames' coherent gain (``folded_shape``). Kang et al. track
    the frequency per sample with a Kalman filter on the same three-sample phase differences (tracker.py); this
    averages them over periods instead, which needs the period (found by ``analyse``) but no rate model.

    Args:
        x: samples, shape (n,), real or complex.
        cplx: complex input.
        period_samples: sweep period, samples (> 4; accurate to ~1e-5 relative: the drift over the block must stay
            below a sample).
        noise_lag: the noise's lag product (``noise_lag_product``), sample units^2.
        noise_power: the noise power per sample of x, sample units^2 (``analyse``'s; 0: no floor on the strength).
        lag: lag d, samples (>= 1; d > 1 gains precision where f d does not alias).

    Returns:
        FineProfile, or None when the block holds fewer than 4 periods or its two halves disagree (``FINE_MAX_DRIFT``).
    """
    T = float(period_samples)
    if not (math.isfinite(T) and T > 4 and x.size >= 4 * T):
        return None
    w = max(1.0, math.ceil(T / FINE_MAX_BINS))
    K = int(max(4, math.floor(T / w)))
    a = analytic_signal(x)
    half = (a.size - lag) // 2
    floor = FINE_MIN_JN * max(float(noise_power), 0.0) * (1.0 if cplx else 2.0)   # the analytic signal: twice
    for _ in range(FINE_FOLDS):
        sums = _lag_fold_kernel(a, T, K, int(lag), half)
        fp, drift = _fine_from_sums(sums, K, noise_lag, floor, lag, cplx, T)
        if not abs(drift) > FINE_MAX_DRIFT * fp.bin_samples:
            return fp
        # the second half's profile sits drift samples from the first's, half a block (half / T periods) later
        T += drift * T / half
    return None


FINE_MAX_DRIFT = 1.5
"""fine_profile: the profile of the block's second half may sit at most this many phase bins from the first half's. A
period error drifts the phase linearly over the block and smears an instantaneous flyback over as many bins as the
drift: ``analyse``'s period is within ~1e-5 relative for short periods (< 0.2 samples between the halves of a 1 ms
block at 38.192 MS/s) but 1e-4 for a 50 us period (20 periods in the block: 1.7 samples). A period of nearly a whole
number of bins puts each sample at the same place in its bin in every period, so the drift measured moves in whole
bins: one bin must pass. Beyond this the period is corrected by the drift measured and the block folded again
(``FINE_FOLDS``)."""
FINE_FOLDS = 3
"""fine_profile: at most this many folds of the block (the first, then corrections of the period by the measured
drift); still drifting after them: no fine profile."""


def _fine_from_sums(sums: tuple[np.ndarray, ...], K: int, noise_lag: complex, floor: float, lag: int, cplx: bool,
                    T: float) -> tuple[FineProfile, float]:
    """fine_profile from the per-half sums of ``_lag_fold_kernel``: the whole block's profile, and the drift of the
    second half's profile against the first, samples (NaN when not measurable): where each half's profile crosses
    the middle of the swept span across its largest step (a saw-tooth's flyback, a hook's return: the one feature
    of a saw-tooth's profile whose place does not depend on its sweep rate or noise level), the second's minus the
    first's, wrapped to +-half a period."""
    fp = _fine_bins(tuple(v[:K] + v[K:] for v in sums), noise_lag, floor, lag, cplx, T / K)
    if np.count_nonzero(fp.present) < 8:
        return fp, math.nan
    f = fp.frequency
    fv = f[fp.present]
    mid = 0.5 * (float(np.percentile(fv, 2)) + float(np.percentile(fv, 98)))
    d = f - np.roll(f, -1)                              # f[k] - f[k + 1]: the whole profile's largest step
    d = np.where(np.isfinite(d), np.abs(d), -1.0)
    j = int(np.argmax(d))
    if not d[j] > 0:
        return fp, math.nan
    pos = []
    for h in (0, 1):
        ph = _fine_bins(tuple(v[h * K:(h + 1) * K] for v in sums), noise_lag, floor, lag, cplx, T / K)
        fh = ph.frequency
        p, best = math.nan, math.inf
        for i in range(-FINE_CROSS_BINS, FINE_CROSS_BINS + 1):   # the half's crossing of the middle nearest j
            k0, k1 = (j + i) % K, (j + i + 1) % K
            a0, a1 = fh[k0] - mid, fh[k1] - mid
            if np.isfinite(a0) and np.isfinite(a1) and a0 * a1 <= 0 and a0 != a1 and abs(i) < best:
                p, best = j + i + a0 / (a0 - a1), abs(i)
        if not math.isfinite(p):
            return fp, math.nan
        pos.append(p)
    dk = (pos[1] - pos[0] + 0.5 * K) % K - 0.5 * K
    return fp, dk * T / K


FINE_CROSS_BINS = 8
"""_fine_from_sums: each half's crossing of the middle of the span is looked for this many bins either side of the
whole profile's largest step (the drift measured is at most this many bins)."""


def _fine_bins(sums: tuple[np.ndarray, ...], noise_lag: complex, floor: float, lag: int, cplx: bool, w: float
               ) -> FineProfile:
    """FineProfile from per-bin sums of ``_lag_fold_kernel``; w: samples per bin; floor: the smallest modulus of a
    present bin, sample units^2. The mean lag product per bin less the noise's, and the variance of that mean over the
    bin's runs: sum_j |r_j - n_j m|^2 / (sum_j n_j)^2."""
    s, q, u, n2, c = sums
    cc = np.maximum(c, 1.0)
    m0 = s / cc
    var = np.maximum(q - 2.0 * np.real(np.conj(m0) * u) + np.abs(m0) ** 2 * n2, 1e-300) / cc ** 2
    m = m0 - noise_lag
    mag = np.abs(m)
    z = np.where(c >= 2, mag / np.sqrt(var), 0.0)
    present = (z > FINE_PRESENT_Z) & (mag > floor)
    f = np.angle(m) / (2 * np.pi * lag)
    if not cplx:
        f = np.where(f < -0.25, f + 1.0, f)
    f = np.where(present, f, np.nan)
    return FineProfile(f, mag, z, present, w)


@njit(cache=True)
def _fine_return_kernel(f: np.ndarray, mag: np.ndarray, z: np.ndarray, present: np.ndarray, up: bool, margin: float,
                        mag_share: float) -> tuple[int, int]:
    """fine_return, compiled: (bins at full strength strictly inside the span on the way back, bins of the way
    back)."""
    K = f.size
    sgn = 1.0 if up else -1.0
    n = 0
    for k in range(K):
        if present[k]:
            n += 1
    if n < 8:
        return 0, 0
    v = np.empty(n)
    mg = np.empty(n)
    i = 0
    for k in range(K):
        if present[k]:
            v[i] = f[k]
            mg[i] = mag[k]
            i += 1
    v.sort()
    lo = v[int(0.02 * (n - 1))]
    hi = v[int(math.ceil(0.98 * (n - 1)))]
    if not hi > lo:
        return 0, 0
    mg.sort()
    full = mag_share * mg[n // 2]
    # the largest step against the sweep between consecutive present bins starts the way back
    j, best = -1, 0.0
    for k in range(K):
        nx = (k + 1) % K
        if present[k] and present[nx] and sgn * (f[k] - f[nx]) > best:
            best, j = sgn * (f[k] - f[nx]), k
    if j < 0:
        return 0, 0
    # the way back: the run of consecutive present bins moving against the sweep that holds that step, from its
    # first bin (after the sweep's end) to its last (the return's far end)
    a = j
    for _ in range(K):
        pv = (a - 1) % K
        if present[pv] and sgn * (f[pv] - f[a]) > 0:
            a = pv
        else:
            break
    b = (j + 1) % K
    for _ in range(K):
        nx = (b + 1) % K
        if present[nx] and sgn * (f[b] - f[nx]) > 0 and nx != a:
            b = nx
        else:
            break
    m = margin * (hi - lo)
    inside = 0
    steps = 0
    k = a
    for _ in range(K):
        steps += 1
        e = 2.0 / (2.0 * math.pi * max(z[k], 1.0))        # two standard errors of the bin's frequency
        if lo + m + e < f[k] < hi - m - e and mag[k] >= full:
            inside += 1
        if k == b:
            break
        k = (k + 1) % K
    return inside, steps


def fine_return(fp: FineProfile, up: bool) -> tuple[int, int]:
    """The way back of a saw-tooth in a sample-resolution profile (``fine_profile``): the run of consecutive present
    phase bins moving against the sweep (down for an up-sweep) that holds the largest such step. Returns (its bins
    that lie more than ``RETURN_MARGIN`` of the swept span (2-98 % of the present bins' frequencies) inside either
    end, by two standard errors of the bin's frequency (1 / (2 pi z) cycles/sample for a mean lag product z standard
    errors strong) beyond that, and hold the jammer at full strength (``FINE_MAG_SHARE``), its bins). An
    instantaneous flyback has at most two bins inside (``FINE_MIN_RETURN``); a hook's swept return has one per sample
    of its crossing."""
    n, steps = _fine_return_kernel(np.ascontiguousarray(fp.frequency, dtype=np.float64),
                                   np.ascontiguousarray(fp.magnitude, dtype=np.float64),
                                   np.ascontiguousarray(fp.z, dtype=np.float64),
                                   np.ascontiguousarray(fp.present, dtype=np.bool_), bool(up), RETURN_MARGIN,
                                   FINE_MAG_SHARE)
    return int(n), int(steps)


def fine_hook_shape(x: np.ndarray, cplx: bool, period_samples: float, levels: np.ndarray, freqs: np.ndarray,
                    noise_power: float, shape: int) -> int:
    """The shape of a saw-tooth (``shape``: SAWTOOTH_UP or SAWTOOTH_DOWN, from the short-time profile) after the
    sample-resolution hook test (module docstring): TRIANGLE when its way back lasts a triangle's side
    (``TRIANGLE_SIDE`` of the period: the coarse profile saw the sweep in pieces), HOOKED_SAWTOOTH when it crosses
    the span in at least ``FINE_MIN_RETURN`` bins, else the saw-tooth. levels, freqs: the block's noise levels and
    their frequencies (``rfi_monitor.stft``); noise_power: its noise power per sample."""
    fp = fine_profile(x, cplx, period_samples, noise_lag_product(levels, freqs, noise_power, cplx), noise_power)
    n_back = fine_return(fp, shape == SAWTOOTH_UP)[0] if fp is not None else 0
    if fp is not None and n_back >= TRIANGLE_SIDE * fp.frequency.size:
        return TRIANGLE
    if n_back >= FINE_MIN_RETURN:
        return HOOKED_SAWTOOTH
    return shape
