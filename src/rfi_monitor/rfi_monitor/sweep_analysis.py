"""Block-level periodicity detector of the frequency track (ours; not in Kang et al.).

The paper's sweep-period estimator (LPD + AR enhancement + peaks, eq. 23-27) needs clear sweep-start
peaks: it fails at low J/N, for sweeps faster than its smoothing (periods below ~60 samples) and
slow to lock for long periods. This detector looks at the whole recent frequency track instead:

1. Input: the last L decimated measurements (the fused loop averages the three-sample measurements
   over D samples; a rejected sample contributes the filter's prediction), zero mean.
2. Autocorrelation by FFT (zero padded to 2^a or 3 2^a >= L + the lags searched, so that no lag
   read wraps around; biased estimate), normalised to r[0] = 1. A saw-tooth
   frequency track of period T gives a periodic parabola ``rho (1 - 6u + 6u^2)``, u = frac(l / T),
   with peaks rho at multiples of T and troughs -rho / 2 between; measurement noise only scales
   rho. White or short-range-correlated noise (a CW's noisy track, band-limited noise, a clean
   front end) gives no periodic peak.
3. The period: among the local maxima of r over lags [min_lag, L max_period_fraction], the one
   with the largest strength = peak - lowest r before it (1.5 rho for a saw-tooth; a smooth
   track's small-lag bumps have ~0); a sub-multiple L/k that is also a peak of at least half the
   strength is preferred (the sampled cusp of a short period can fall below its multiple).
   Periodic when the strength >= min_strength. The period is refined on multiples 4, 16, 64, ...
   of itself inside the lag range (parabolic interpolation; the error shrinks as 1 / multiple).
4. Sweep phase, direction and jump from the first two Fourier coefficients of the track at 1/T:
   for ``z = f0 + B frac((t - s) / T)``, ``c_k = sum z e^{-j 2 pi k t / T} ~ (j B N / (2 pi k))
   e^{-j 2 pi k s / T}``; so ``sign B = -sign Im(c_2 conj(c_1)^2)``, ``s = -T arg(c_1 / (j sign B))
   / 2 pi`` and ``|B| ~ 2 pi |c_1| / N`` (compressed at low J/N, where the measurement is biased
   towards fs/4). ``|c_2| / |c_1|`` is 1/2 for a saw-tooth and ~0 for a triangular sweep.

Cost: one real FFT pair of ~1.5 L points (6144 for L = 4096; a 2L = 8192-point pair gives the same
r at the lags read) per analysis (the monitor runs it every ``hop_s`` at absolute sample boundaries, so block
splitting cannot change the result); the peak search (``_best_lag``) and the two Fourier
coefficients (``_fourier_12``, a rotating phasor instead of a complex exponential per value) are
compiled (numba): ~0.09 ms per analysis of L = 4096 on this machine (0.11 ms with the 8192-point
pair; identical results on 300 random tracks).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from rfi_node_common.params import parameter


@dataclass(frozen=True)
class SweepAnalysisParams:
    """Parameters of the periodicity detector.

    Attributes:
        enabled: run the detector (and let it seed the reset lattice and the identification).
        hop_s: analysis interval, s (at absolute sample indices multiple of round(hop_s fs)), > 0.
        min_strength: normalised autocorrelation peak-to-trough for a periodic track, in (0, 1.5].
        min_lag: shortest period, decimated samples, >= 2.
        max_period_fraction: longest period as a fraction of the analysed window, in (0, 0.5].
        min_window: fewest decimated values for an analysis, >= 64.
        skip_while_tracking: no analysis while the monitor is in tracking mode (a step-fit
            lattice confirmed, ``RfiMonitorParams.confirm_fits``): it could only seed a lattice
            when none runs; the identification then takes the confirmed lattice as the evidence
            of periodicity (speed, ours).
    """

    enabled: bool = parameter(
        True,
        'Run the block-level periodicity detector of the frequency track (ours): it seeds the reset lattice and tells'
        " the identification that the track is periodic. Set false to run Kang et al.'s method only.")
    hop_s: float = parameter(
        1e-3,
        'Interval between two periodicity analyses, s (at absolute sample indices multiple of hop_s * fs, so the '
        'result does not depend on how the stream is cut into blocks). Blocks much shorter than 2 hop_s cannot use '
        'it. Cost: ~0.2-0.3 ms of CPU per analysis (one per ms by default).', minimum=1e-7, maximum=10.0)
    min_strength: float = parameter(
        0.3,
        'Normalised autocorrelation peak-to-trough of a periodic track, (0, 1.5] (1.5: noise-free saw-tooth). Raise '
        'it if noise is taken for a sweep.', minimum=1e-6, maximum=1.5)
    min_lag: int = parameter(
        3, 'Shortest period detected, decimated samples (x sweep_decimation samples).',
        minimum=2, maximum=10**9)
    max_period_fraction: float = parameter(
        0.25, 'Longest period as a fraction of the analysed window, (0, 0.5].',
        minimum=1e-6, maximum=0.5)
    min_window: int = parameter(
        1024, 'Fewest decimated values for an analysis (1024 x 4 samples = 107 us at 38.192 MHz).',
        minimum=64, maximum=10**9)
    skip_while_tracking: bool = parameter(
        True,
        'No periodicity analysis while in tracking mode (confirm_fits): the confirmed reset lattice is then the '
        'evidence of a periodic sweep. false: analyse every hop (more CPU).')

    def __post_init__(self) -> None:
        if not (math.isfinite(self.hop_s) and self.hop_s > 0):
            raise ValueError("hop_s must be finite and > 0")
        if not 0 < self.min_strength <= 1.5:
            raise ValueError("min_strength must be in (0, 1.5]")
        if self.min_lag < 2:
            raise ValueError("min_lag must be >= 2")
        if not 0 < self.max_period_fraction <= 0.5:
            raise ValueError("max_period_fraction must be in (0, 0.5]")
        if self.min_window < 64:
            raise ValueError("min_window must be >= 64")


@dataclass(frozen=True)
class SweepAnalysis:
    """Result of one analysis (NaN where unknown).

    Attributes:
        periodic: a periodic frequency track was found.
        strength: autocorrelation peak-to-trough (dimensionless, 1.5 for a noise-free saw-tooth).
        period_samples: sweep period, samples.
        start_index: absolute sample index (fractional) of one sweep start.
        jump: signed sweep jump B, cycles/sample (> 0 up-chirp), compressed at low J/N.
        harmonic_ratio: |c2| / |c1| (0.5 saw-tooth, ~0 triangle).
        sample_index: absolute sample index at which the analysis ran.
    """

    periodic: bool
    strength: float
    period_samples: float
    start_index: float
    jump: float
    harmonic_ratio: float
    sample_index: int


@njit(cache=True)
def _fourier_12(x: np.ndarray, t_dec: float) -> tuple[complex, complex]:
    """``c_k = sum_n x_n e^{-j 2 pi k n / T}`` for k = 1, 2 (step 4 of the module docstring).

    The phasor advances by a rotation (one complex product per sample) and is recomputed exactly
    every 256 samples, so its rounding error stays ~1e-14 (the libm exponential of every sample
    cost ~30 ns each).
    """
    w = -2.0 * math.pi / t_dec
    rot = complex(math.cos(w), math.sin(w))
    c1 = 0j
    c2 = 0j
    e = 1.0 + 0j
    for i in range(x.size):
        if (i & 255) == 0:
            e = complex(math.cos(w * i), math.sin(w * i))
        xe = x[i] * e
        c1 += xe
        c2 += xe * e
        e = e * rot
    return c1, c2


@njit(cache=True)
def _best_lag(r: np.ndarray, lo: int, lmax: int) -> tuple[int, np.ndarray]:
    """Step 3 of the module docstring: the lag of the strongest local maximum of r over
    [lo, lmax] (strength = r[k] - min(r[1..k])), replaced by the largest sub-multiple kbest / q
    (q from kbest // lo down to 2) whose neighbourhood (+-1 lag) holds a local maximum of at least
    half that strength; -1 if there is no local maximum.

    Args:
        r: normalised autocorrelation, shape (L,), r[0] = 1.
        lo, lmax: lag range, decimated samples (lo >= 2, lmax < L - 1).

    Returns:
        (lag, trough) with trough[c - 1] = min(r[1..c]), shape (L - 1,).
    """
    n = r.size
    trough = np.empty(n - 1)
    m = math.inf
    for i in range(1, n):
        m = min(m, r[i])
        trough[i - 1] = m
    best = -math.inf
    kbest = -1
    for c in range(lo + 1, lmax):
        if r[c] >= r[c - 1] and r[c] >= r[c + 1]:
            st = r[c] - trough[c - 1]
            if st > best:
                best = st
                kbest = c
    if kbest < 0:
        return kbest, trough
    for q in range(kbest // lo, 1, -1):
        cen = kbest / q
        k_lo = max(1, int(math.floor(cen - 1.0)))
        k_hi = min(n - 2, int(math.ceil(cen + 1.0)))
        if k_hi < k_lo:
            continue
        ks = k_lo
        bv = -math.inf
        for j in range(4):
            idx = k_lo + j
            v = r[min(idx, n - 1)] if idx <= k_hi else -math.inf
            if v > bv:
                bv = v
                ks = idx
        if (ks >= lo and r[ks] >= r[ks - 1] and r[ks] >= r[min(ks + 1, n - 1)]
                and r[ks] - trough[ks - 1] >= 0.5 * best):
            return ks, trough
    return kbest, trough


def _parabolic(r: np.ndarray, k: int) -> float:
    if 0 < k < r.size - 1:
        a, b, c = r[k - 1], r[k], r[k + 1]
        den = a - 2 * b + c
        if den < 0:
            return k + 0.5 * (a - c) / den
    return float(k)


def _local_max_near(r: np.ndarray, centre: float, half: float) -> int:
    lo = max(1, int(math.floor(centre - half)))
    hi = min(r.size - 2, int(math.ceil(centre + half)))
    if hi < lo:
        return -1
    return lo + int(np.argmax(r[lo:hi + 1]))


def _fft_len(k: int) -> int:
    """Smallest 2^a or 3 2^a >= k (fast sizes of the FFT)."""
    p2 = 1 << max(int(math.ceil(math.log2(k))), 0)
    p3 = 3 * (1 << max(int(math.ceil(math.log2(k / 3.0))), 0))
    return min(p2, p3) if p3 >= k else p2


def analyse(zdec: np.ndarray, decimation: int, first_centre: float, sample_index: int,
            par: SweepAnalysisParams) -> SweepAnalysis:
    """Periodicity of a decimated frequency track (module docstring).

    Args:
        zdec: decimated measurements, cycles/sample, chronological, shape (L,), finite.
        decimation: D, samples per decimated value, >= 1.
        first_centre: absolute sample index (fractional) of the centre of zdec[0].
        sample_index: absolute index at which the analysis runs (copied to the result).
        par: SweepAnalysisParams.

    Returns:
        SweepAnalysis.
    """
    nan = math.nan
    none = SweepAnalysis(False, 0.0, nan, nan, nan, nan, sample_index)
    n = zdec.size
    if n < par.min_window or not np.all(np.isfinite(zdec)):
        return none
    x = zdec - zdec.mean()
    lmax = int(n * par.max_period_fraction)
    lo = par.min_lag
    if lmax <= lo + 2:
        return none
    # lags 0..m-1 are all the search reads (peaks up to lmax, the refinement up to lmax (1 + 1/16) + 3);
    # zero padding to nfft >= n + m - 1 keeps them free of circular wrap-around
    m = min(n, lmax + lmax // 8 + 4)
    nfft = _fft_len(n + m - 1)
    spec = np.fft.rfft(x, nfft)
    r = np.fft.irfft(spec.real ** 2 + spec.imag ** 2, nfft)[:m]
    if not r[0] > 0:
        return none
    r = r / r[0]
    kbest, trough = _best_lag(r, lo, lmax)
    if kbest < 0:
        return none
    strength = float(r[kbest] - trough[kbest - 1])
    if strength < par.min_strength:
        return SweepAnalysis(False, strength, nan, nan, nan, nan, sample_index)
    # refine on growing multiples (x4 each) inside the lag range: the error shrinks as 1 / multiple
    t_dec = _parabolic(r, kbest)
    mult = 4
    while mult * t_dec <= lmax:
        k = _local_max_near(r, mult * t_dec, max(1.0, 0.25 * t_dec))
        if k <= 0:
            break
        t_dec = _parabolic(r, k) / mult
        mult *= 4
    if not t_dec > 0:
        return none
    # Fourier coefficients at 1/T and 2/T (decimated time), phase referenced to absolute samples
    c1, c2 = _fourier_12(x, float(t_dec))
    if abs(c1) == 0:
        return none
    sgn = -1.0 if (c2 * np.conj(c1) ** 2).imag > 0 else 1.0
    phi = -np.angle(c1 / (1j * sgn))                     # 2 pi s / T, s in decimated units from zdec[0]
    s_dec = (phi / (2 * np.pi)) % 1.0 * t_dec
    period = t_dec * decimation
    # a decimated value averages samples [c - (D-1)/2, c + (D-1)/2]; a start at decimated time s
    # is at sample first_centre + s D
    start = first_centre + s_dec * decimation
    jump = sgn * 2 * np.pi * abs(c1) / n
    return SweepAnalysis(True, strength, float(period), float(start), float(jump), float(abs(c2) / abs(c1)),
                         sample_index)
