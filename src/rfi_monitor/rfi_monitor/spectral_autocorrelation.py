"""The per-block statistic of the CHIRP test of the evidence over blocks (orchestrated by
``rfi_monitor.integration.Integrator``; the test over the summed statistic: ``rfi_monitor.chirp_comb``).

Any periodic sweep: the 2-D autocorrelation over frames of the short-time spectrum,
``r(l) = sum_t sum_b E(t, b) E(t + l, b)`` with ``E = |X| / mean_t |X| - 1`` per bin (amplitudes: lighter tails than
powers) (zero mean per bin and block: a CW and the front end's shape drop out), minus each frame's mean over the bins
(a change of the block's power within it, as an AGC settling after a gain step, moves every bin of a frame alike;
measured: a 2-bit front end whose AGC settled from +10 dB in its first block was reported CHIRP for 8 blocks), summed
over blocks, together with its variance under noise ``(T - l) sum_d sum_bb' C_d(b, b')^2`` (``C_d``: the block's
covariance between bin b and bin b' d frames later, d = -1, 0, 1, every bin pair, measured, so the window's leakage
between bins, the overlap of neighbouring frames and a jammer's own variance are accounted for) and its mean under
noise removed (E has zero mean over the block, so each product has the mean ``-sum_b (C_0 + 2 C_1)(b, b) / T``).

The frame length of the chirp statistic is fixed per stream (``frame_length_s`` of the sample rate, a power of two in
8..128; ``rfi_monitor.integration.frame_length``): the sweep must move by less than about one bin per frame (a sweep
of k cycles/sample^2 moves k L^2 bins per frame: 0.7 at the paper's 1e12 Hz/s, 38.192 MS/s, L = 32).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy import fft as sp_fft

from rfi_monitor.classifier import frame_power
from rfi_monitor.numpy_kernels import pairwise_sum
from rfi_monitor.stft import _frames_complex, _frames_real, _window, fft_inplace, irfft_real, rfft_rows


def spectral_autocorrelation(x: np.ndarray, cplx: bool, L: int, max_lag: int
                              ) -> tuple[np.ndarray, np.ndarray, int, float, float]:
    """(r, var, T, copies, spread): the 2-D autocorrelation r(l), l = 0..max_lag, of E = |X| / mean_t |X| - 1 and its
    variance under noise (module docstring), T frames of L samples at hop L / 2, the number of independent bin
    sequences it sums and E's variance per frame summed over the bins (:func:`_noise_moments`).

    The short-time spectrum is ``stft.stft_power``'s (its framing, window and FFT); its power, the amplitudes, their
    normalisation and the zero padding of the autocorrelation's FFT are one compiled pass
    (:func:`_normalised_amplitudes`), the noise moments another (:func:`_noise_moments`): the same float arithmetic in
    the same order as the numpy expressions and the separate passes they replaced (issue 26 item 2)."""
    hop = L // 2
    T = (x.size - L) // hop + 1
    w = _window(L)
    if cplx:
        xc = np.ascontiguousarray(x, dtype=np.complex128)
        fw = np.empty((T, L), dtype=np.complex64)
        _frames_complex(xc.view(np.float64), hop, w, fw)
        spec = fft_inplace(fw, True)
        shift = L // 2
    else:
        fr32 = np.empty((T, L), dtype=np.float32)
        _frames_real(np.ascontiguousarray(x, dtype=np.float64), hop, w, fr32)
        spec = rfft_rows(fr32)
        shift = 0
    nf = sp_fft.next_fast_len(T + max_lag + 1, real=True)     # no circular wrap up to max_lag
    # amplitudes (lighter tails than powers: Rayleigh, not exponential, at little loss), normalised per bin, laid
    # out (bins, frames) so that the FFTs run along contiguous rows, zero-padded to nf frames
    Et = _normalised_amplitudes(spec, shift, bool(not cplx and spec.shape[1] > 3), nf)
    q, g, copies, spread = _noise_moments(Et, T)
    F = rfft_rows(Et)
    R = irfft_real(frame_power(F), nf)     # sum over bins of |F|^2 (the classifier's pass)
    # E has zero mean over the block's frames in every bin, so under noise each product E(t) E(t + l) has the mean
    # -g / T (g: the bins' long-run variance, lags -1..1), not 0; removed here, as the comb sums many lags (measured
    # before: -0.1 standard deviations per lag at 4 MS/s I/Q, a bias of -0.9 over 83 multiples)
    r, var = _lag_terms(R, max_lag, T, g, q)
    return r, var, T, copies, spread


@njit(cache=True, nogil=True)
def _lag_terms(R: np.ndarray, max_lag: int, T: int, g: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """(r, var) over the lags 0..max_lag: r(l) = R(l) + (T - l) g / T and var(l) = (T - l) q, (T - l) floored at 0
    (the numpy expressions ``R + n_prod * (g / T)`` and ``n_prod * q``, element by element)."""
    r = np.empty(max_lag + 1)
    var = np.empty(max_lag + 1)
    c = g / T
    for lag in range(max_lag + 1):
        n_prod = float(max(T - lag, 0))
        r[lag] = R[lag] + n_prod * c
        var[lag] = n_prod * q
    return r, var


_REASSOC = {"reassoc", "contract"}
"""numba fastmath flags of the reductions below: sums may be reassociated (vectorised); no assumption about NaN or
infinities (the inputs are finite)."""


@njit(cache=True, nogil=True)
def _noise_moments(Et: np.ndarray, nfr: int) -> tuple[float, float, float, float]:
    """(q, g, copies, spread) of E (bins, frames: the first nfr columns), for the comb statistic under noise.

    q: the variance per product of one lag's sum r(l), l >= 2: the sum over d = -1, 0, 1 and every bin pair
    (b, b') of C_d(b, b')^2, C_d the covariance of E(t, b) and E(t + d, b') over the frames. A window leaks
    into the neighbouring bins (for I/Q also across the band's wrap), the frame's mean over the bins couples
    every pair, and frames at hop L/2 overlap their neighbours, so the products E(t) E(t + l) and
    E(t + 1) E(t + 1 + l) are correlated too. Measured under Gaussian noise with d = 0 and |b - b'| <= 3 only
    (before): the per-lag statistic had a standard deviation of 1.04-1.10, and one-block sums exceeded the
    alpha = 1e-4 comb threshold in 1.3-3 of 1,000 blocks at 4-38 MS/s.
    g: the sum over bins of C_0(b, b) + 2 C_1(b, b), the long-run variance: E has zero mean over the block's
    frames in every bin, so each product has the mean -g / T under noise, not 0.
    copies: the number of independent bin sequences the sum over bins is worth, trace(C_0)^2 / |C_0|_F^2 (the
    bins' count when they are uncorrelated). spread: trace(C_0), E's variance per frame summed over the bins (the
    scale of the comb's strength, ``IntegratedDecision.chirp_strength``).
    The two bins x bins covariance matrices come from :func:`_bin_covariances`; the sums over them are numpy's
    (``np.sum`` of the squares, ``np.trace``) in numpy's pairwise order (``numpy_kernels.pairwise_sum``).
    """
    c0, c1 = _bin_covariances(Et, nfr)
    q = _sum_squares(c0)
    g = _trace(c0)
    copies = g * g / q if q > 0 else 0.0
    spread = g
    if nfr > 1:
        q += 2.0 * _sum_squares(c1)
        g += 2.0 * _trace(c1)
    return q, g, copies, spread


@njit(cache=True, nogil=True)
def _sum_squares(c: np.ndarray) -> float:
    """np.sum(c * c) of a C-contiguous matrix (numpy sums it as one contiguous vector, pairwise)."""
    return pairwise_sum((c * c).ravel(), 0.0)


@njit(cache=True, nogil=True)
def _trace(c: np.ndarray) -> float:
    """np.trace(c) of a square matrix (numpy's pairwise sum of the diagonal)."""
    return pairwise_sum(np.diag(c).copy(), 0.0)


@njit(cache=True, nogil=True, fastmath=_REASSOC)
def _bin_covariances(Et: np.ndarray, nfr: int) -> tuple[np.ndarray, np.ndarray]:
    """(C_0, C_1) of E (bins, frames: the first nfr columns): C_d[b, b'] = mean over t of E(t, b) E(t + d, b').
    Compiled rather than two matrix products: numpy hands those to a multi-threaded BLAS, which for these small
    matrices doubled the integration's CPU time (the second core spinning) at the same wall time; this loop is
    single-threaded and faster (0.06 against 0.09 ms wall, 0.19 ms CPU, for 15 bins x 2,386 frames)."""
    nb = Et.shape[0]
    c0 = np.zeros((nb, nb))
    c1 = np.zeros((nb, nb))
    for b in range(nb):
        for b2 in range(b, nb):
            acc = 0.0
            for t in range(nfr):
                acc += float(Et[b, t]) * float(Et[b2, t])
            c0[b, b2] = acc / nfr
            c0[b2, b] = acc / nfr
        if nfr > 1:
            for b2 in range(nb):
                acc = 0.0
                for t in range(nfr - 1):
                    acc += float(Et[b, t]) * float(Et[b2, t + 1])
                c1[b, b2] = acc / (nfr - 1)
    return c0, c1


@njit(cache=True, nogil=True)
def _normalised_amplitudes(spec: np.ndarray, shift: int, drop_edges: bool, nf: int) -> np.ndarray:
    """E transposed, of spectral_autocorrelation, from the complex64 spectrum spec (frames, FFT bins): the bins in
    fftshift order for a complex FFT (``shift`` L / 2; 0 for a real one), without the DC and Nyquist bins of a real
    signal (drop_edges: one degree of freedom). |X|^2 in float32 as ``stft.stft_power`` forms it, its square root,
    E = sqrt(S) / mean_t - 1 per bin, minus each frame's mean over the bins, float32, shape (bins, nf): the frames,
    then zeros (the autocorrelation's padding). The means are summed in double in the frames' (the bins') order."""
    nfr, B = spec.shape
    b0 = 1 if drop_edges else 0
    nb = B - 2 * b0
    Et = np.zeros((nb, nf), dtype=np.float32)
    acc = np.zeros(nb)
    for t in range(nfr):
        for b in range(nb):
            j = b0 + b + shift
            v = spec[t, j - B if j >= B else j]
            re = np.float32(v.real)
            im = np.float32(v.imag)
            a = np.sqrt(np.float32(re * re) + np.float32(im * im))
            Et[b, t] = a
            acc[b] += a
    for b in range(nb):
        m = np.float32(max(acc[b] / nfr, 1e-300))
        for t in range(nfr):
            Et[b, t] = Et[b, t] / m - np.float32(1.0)
    # minus each frame's mean over the bins: a change of the whole block's power within it (an AGC settling, a
    # gain step, a broadband pulse) raises every bin of a frame alike and would correlate all lags; a sweep puts
    # its excess in one bin per frame, which the mean over the bins hardly moves
    if nb > 1:
        facc = np.zeros(nfr)
        for b in range(nb):
            for t in range(nfr):
                facc[t] += float(Et[b, t])
        mf = np.empty(nfr, dtype=np.float32)
        for t in range(nfr):
            mf[t] = np.float32(facc[t] / nb)
        for b in range(nb):
            for t in range(nfr):
                Et[b, t] -= mf[t]
    return Et
