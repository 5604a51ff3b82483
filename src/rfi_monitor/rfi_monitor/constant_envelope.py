"""Noise power under a constant-envelope jammer from the block's own moments (no clean start, no spectrum).

Pure module (no ROS). A CW or a chirp is a constant-envelope signal: its samples have one magnitude, the noise
added to them does not. The second and fourth moments of the block tell the two apart (the "M2M4" estimator of
signal-to-noise ratio, Pauluzzi & Beaulieu 2000, IEEE Trans. Commun. 48(10), eq. 36-37; Matzner 1993):

* complex samples x = J + n, |J|^2 = P, n circular Gaussian of power N:
  ``M2 = E|x|^2 = P + N``, ``M4 = E|x|^4 = P^2 + 4 P N + 2 N^2``, hence ``N = M2 - sqrt(2 M2^2 - M4)``
  (``gnss_common.moments.m2m4_powers``; the moment sums are taken here).
* real samples are made analytic first (a real tone becomes a complex exponential of constant magnitude, real
  band-pass Gaussian noise circular Gaussian noise of twice the power), then as above. The analytic signal is
  ``x + j H(x)``, its squared magnitude ``x^2 + H(x)^2``: only the Hilbert transform ``H(x)`` is computed, by a real
  FFT and its inverse (:func:`hilbert_transform`; the analytic signal of ``ridge.analytic_signal`` to rounding,
  at about 60 % of its cost: no complex inverse FFT of the doubled spectrum). The
  moments of the real samples themselves (``M4 = 1.5 P^2 + 6 P N + 3 N^2`` with E cos^4 = 3/8) are not used: E cos^4
  over the samples of a tone is 3/8 only when its phase steps spread over the circle, not for a tone near DC,
  fs / 4 or fs / 2, a common IF (a saw-tooth around fs / 4 at J/N 25 dB read 49 dB).

Noise alone gives N = M2 (J/N -> -inf, up to the scatter of the moments). The noise need not be white (each sample
is Gaussian whatever the front end's filter), which is why this reference survives what the short-time spectrum's
noise estimate does not: a strong chirp that sweeps fast against the frame length leaks into every bin of every
frame, and the per-bin noise levels measured beside it read high (J/N read 6-12 dB low at 30-40 dB, 4 MS/s).

Anything that modulates the jammer's magnitude (a sweep leaving the front end's band, a second jammer, the
ripple of the front end's filter, a pulsed jammer, a real tone within a few FFT bins of DC or fs / 2 whose analytic
signal ripples) adds to M4 as if it were noise, so N comes out too large and the
J/N too small: the estimate errs low, never high. Clipping and coarse quantisers flatten the magnitude and would
make it err high; the monitor uses it only without them (``RfiMonitor``: a CW or chirp in band all the time, in
a block with its own in-block noise reference, at least 4 bits, clipped values below ``clip_lower_bound_fraction``)
and keeps the larger of this J/N and the spectral one.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy import fft as sp_fft

from gnss_common.moments import m2m4_powers
from rfi_monitor.stft import irfft_rows, rfft_rows


@njit(cache=True, nogil=True)
def _moments_complex(x: np.ndarray) -> tuple[float, float]:
    s2 = 0.0
    s4 = 0.0
    for v in x:
        q = v.real * v.real + v.imag * v.imag
        s2 += q
        s4 += q * q
    n = max(x.size, 1)
    return s2 / n, s4 / n


@njit(cache=True, nogil=True)
def _moments_analytic(x: np.ndarray, h: np.ndarray, lo: int, hi: int) -> tuple[float, float]:
    """(M2, M4) of the analytic signal x + j h over the samples lo..hi - 1 (x real, h its Hilbert transform)."""
    s2 = 0.0
    s4 = 0.0
    for i in range(lo, hi):
        q = x[i] * x[i] + h[i] * h[i]
        s2 += q
        s4 += q * q
    n = max(hi - lo, 1)
    return s2 / n, s4 / n


@njit(cache=True, nogil=True)
def _quadrature(X: np.ndarray, even: bool) -> None:
    """X (the rfft of m samples) times -j in place, its DC bin and (m even) its Nyquist bin zeroed: the spectrum of
    the Hilbert transform."""
    for k in range(1, X.size):
        v = X[k]
        X[k] = complex(v.imag, -v.real)
    X[0] = 0.0
    if even:
        X[X.size - 1] = 0.0


def hilbert_transform(x: np.ndarray) -> np.ndarray:
    """The Hilbert transform H(x) of real samples x (float64, shape (n,)), by FFT over the next fast length (the
    padding's edge effect reaches only the last few samples): the imaginary part of the analytic signal
    (``ridge.analytic_signal``, the same padding), float64, shape (n,)."""
    n = x.size
    m = sp_fft.next_fast_len(n, real=True)
    xp = np.zeros(m)
    xp[:n] = x
    X = rfft_rows(xp)                            # scipy.fft.rfft(x, m) (its zero padding) without the dispatch
    _quadrature(X, m % 2 == 0)
    return irfft_rows(X, m)[:n]


ENVELOPE_MAX_SAMPLES = 8192
"""The moments of complex samples are taken over at most the last this many samples of a block (their scatter is then
about 1 %; a pass over the samples, ~10 us)."""
ENVELOPE_MAX_SAMPLES_REAL = 4096
"""The moments of real samples over at most the last this many (their scatter about 1.4 %): their analytic signal
(two FFTs) costs ~45 us over 4096 samples, ~95 us over 8192 (the length until 2026-12-08: ~0.4 bare STFTs of a
38.192 MS/s block; docs/rfi_monitor/real_jammers.md's J/N medians moved by at most 0.1 dB)."""
EDGE_SAMPLES = 32
"""Samples left out at each end of a real block's analytic signal (the FFT's Hilbert transform rings there)."""


def constant_envelope_noise(x: np.ndarray, cplx: bool) -> tuple[float, float]:
    """(noise power per sample, block power) of a block holding one constant-envelope jammer plus Gaussian noise
    (module docstring), in the samples' unit squared (real input: of its analytic signal, both twice the real
    samples'); the noise is NaN when the block has no power. Over the last ``ENVELOPE_MAX_SAMPLES`` samples
    (real samples: ``ENVELOPE_MAX_SAMPLES_REAL``).

    Args:
        x: samples, shape (n,): float64 (real) or complex128 (complex baseband / I-Q).
        cplx: complex samples.
    """
    seg = np.asarray(x)[-(ENVELOPE_MAX_SAMPLES if cplx else ENVELOPE_MAX_SAMPLES_REAL):]
    if cplx:
        m2, m4 = _moments_complex(np.ascontiguousarray(seg, dtype=np.complex128))
    else:
        if seg.size <= 4 * EDGE_SAMPLES:
            return math.nan, 0.0
        xr = np.ascontiguousarray(seg, dtype=np.float64)
        m2, m4 = _moments_analytic(xr, hilbert_transform(xr), EDGE_SAMPLES, xr.size - EDGE_SAMPLES)
    if not m2 > 0.0:
        return math.nan, 0.0
    noise = m2m4_powers(m2, m4)[1]
    return max(noise, 0.0), m2


def constant_envelope_jn_db(x: np.ndarray, cplx: bool) -> float:
    """J/N of the block against the noise of :func:`constant_envelope_noise`, dB (+inf when the moments leave no
    noise: a block of a jammer alone, or one flattened by a limiter; -inf when they leave no jammer; NaN for a block
    without power)."""
    noise, power = constant_envelope_noise(x, cplx)
    if not math.isfinite(noise):
        return math.nan
    if noise <= 0.0:
        return math.inf
    ratio = power / noise - 1.0
    return 10.0 * math.log10(ratio) if ratio > 0.0 else -math.inf
