"""Stage 2 of the ridge analysis (orchestrated by ``rfi_monitor.ridge.analyse``): the short-time spectrum of a block
and its in-block noise level (ours).

The block is cut into Hann frames of L samples at hop L/2 (``stft_power``: |STFT|^2 in float32, fftshift order for
complex input). In-block noise level per bin (``noise_levels``; no clean start needed): the lower 10 % quantile over
frames of each bin's power, scaled to the exponential mean (``/ -ln(0.9)``); then the mean of the frames below three
times that, widened by one bin and one frame (divided by the mean of a unit exponential truncated at 3, 0.8428); then
a median across ``noise_smooth_bins`` bins (a CW or a slowly swept jammer that holds one or two bins all the time
never enters it; the front end's filter shape does), and a cap at ``PLATEAU_DB`` over the lower envelope of the
neighbouring bins. A jammer that occupies a bin in fewer than ~60 % of the frames (a sweep, a pulse) or fewer than
half of ``noise_smooth_bins`` adjacent bins all the time (a tone) cannot poison it; a noise jammer that fills the band
can (then only a fixed or learned floor sees it, monitor module docstring). The block's noise power N follows by
Parseval (``_noise_power``, the estimator's own bias on white noise divided out: ``estimator_gain``).

Powers in sample units^2; frequencies in cycles/sample.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy import fft as sp_fft

from rfi_monitor.numpy_kernels import _kth_of_few, column_order_statistic

try:
    # scipy.fft's own pocketfft binding, called as scipy.fft calls it (the same transform to the bit) without its
    # dispatch (5-15 us a call; issue 26 item 2); scipy.fft itself where a scipy version lacks it
    from scipy.fft._pocketfft import pypocketfft as _pfft
except ImportError:                      # pragma: no cover
    _pfft = None

_Q_LOW = 0.1
_Q_LOW_EXP = -math.log(1.0 - _Q_LOW)
"""The 10 % quantile of a unit exponential (the power of a noise bin over its mean)."""


PLATEAU_DB = 1.5
"""A bin's noise level may exceed the lower envelope of its neighbours by this much, dB (noise_levels)."""
_CUT = 3.0
_TRUNC_MEAN = 1.0 - _CUT * math.exp(-_CUT) / (1.0 - math.exp(-_CUT))
"""Mean of a unit exponential truncated at _CUT (0.8428)."""


LONG_COLUMN_FRAMES = 768
"""noise_levels: from this many frames on, the lower quantile of each bin is taken by the compiled histogram select
(``numpy_kernels.column_order_statistic``), below it by numpy's sort of each bin's frames (speed only: the same
value). Measured on the arrays the monitor's blocks give (cycling through 40-120 different ones, thread time, loaded
machine; numpy 2.4's SIMD sort, us a call): 511 x 33 frames x bins sort 38, histogram 55, np.partition 48; 255 x 65
38 / 54 / 48; 155 x 128 53 / 67 / 62; 1023 x 17 115 / 57 / 101; 1249 x 16 163 / 62 / 121; 2047 x 5 92 / 41 / 63.
(The earlier choice of a compiled Floyd-Rivest selection, 160-220 us on these, had been timed on one array called
again and again, its branches predicted.)"""

_WIN: dict[int, np.ndarray] = {}


def _window(n: int) -> np.ndarray:
    w = _WIN.get(n)
    if w is None:
        w = np.hanning(n + 2)[1:-1].astype(np.float32)   # no zero end points
        w.flags.writeable = False
        _WIN[n] = w
    return w


def stft_power(x: np.ndarray, frame_length: int, cplx: bool) -> tuple[np.ndarray, np.ndarray]:
    """|STFT|^2 of a block: Hann frames of frame_length, hop frame_length / 2.

    Args:
        x: samples, shape (n,), float64 or complex128, n >= frame_length.
        frame_length: L, samples.
        cplx: complex input (fft, fftshift order) or real (rfft).

    Returns:
        (S, freqs): S shape (frames, bins) float32; freqs shape (bins,), cycles/sample.

    The framing, the float32 conversion and the window, and |X|^2 after the FFT are compiled passes
    (``_frames_real``, ``_frames_complex``, ``_power_real``, ``_power_shifted``; issue 26 item 2): the same float32
    arithmetic in the same order as the numpy expressions they replaced (astype, multiply, square, add; fftshift as
    an index shift), without their temporaries.
    """
    L = int(frame_length)
    hop = L // 2
    nfr = (x.size - L) // hop + 1
    w = _window(L)
    # scipy's pocketfft in single precision (numpy's float32 path is slower; see classifier.welch_psd)
    if cplx:
        xc = np.ascontiguousarray(x, dtype=np.complex128)
        fw = np.empty((nfr, L), dtype=np.complex64)
        _frames_complex(xc.view(np.float64), hop, w, fw)
        spec = fft_inplace(fw, True)
        freqs = (np.arange(L) - L // 2) / L
        return _power_shifted(spec, L // 2), freqs
    xr = np.ascontiguousarray(x, dtype=np.float64)
    fr32 = np.empty((nfr, L), dtype=np.float32)
    _frames_real(xr, hop, w, fr32)
    spec = rfft_rows(fr32)
    freqs = np.arange(L // 2 + 1) / L
    return _power_real(spec), freqs


def rfft_rows(a: np.ndarray) -> np.ndarray:
    """``scipy.fft.rfft(a, axis=-1)`` of a real float32 or float64 C-contiguous array: scipy's own pocketfft call
    without its dispatch (5-15 us a call; issue 26 item 2), the same transform to the bit."""
    if _pfft is not None:
        return _pfft.r2c(a, (a.ndim - 1,), True, 0, None, 1)
    return sp_fft.rfft(a, axis=-1)


def irfft_rows(X: np.ndarray, n: int) -> np.ndarray:
    """``scipy.fft.irfft(X, n, axis=-1)`` of a complex C-contiguous array of n // 2 + 1 values along its last axis:
    scipy's own pocketfft call (scaled by 1 / n) without its dispatch."""
    if _pfft is not None and X.shape[-1] == n // 2 + 1 and np.iscomplexobj(X):
        return _pfft.c2r(X, (X.ndim - 1,), int(n), False, 2, None, 1)
    return sp_fft.irfft(X, n, axis=-1)


def irfft_real(p: np.ndarray, n: int) -> np.ndarray:
    """``scipy.fft.irfft(p, n)`` of a real float64 vector p of n // 2 + 1 values (a spectrum whose imaginary part is
    zero): scipy's own pocketfft call (as scipy makes it: p + 0j, scaled by 1 / n) without its dispatch."""
    if _pfft is not None and p.ndim == 1 and p.size == n // 2 + 1:
        return _pfft.c2r(p + 0j, (0,), int(n), False, 2, None, 1)
    return sp_fft.irfft(p, n)


def fft_inplace(a: np.ndarray, forward: bool) -> np.ndarray:
    """The FFT (forward) or inverse FFT (scaled by 1 / n) of a complex C-contiguous array along its last axis, in
    place: what ``scipy.fft.fft`` / ``ifft(a, axis=-1, overwrite_x=True)`` give, and for complex128 what ``np.fft.fft``
    / ``ifft`` give (numpy 2 and scipy run the same pocketfft; bit-identical here, test_ridge_stages.py)."""
    ax = a.ndim - 1
    if _pfft is not None:
        return _pfft.c2c(a, (ax,), forward, 0 if forward else 2, a, 1)
    return sp_fft.fft(a, axis=ax, overwrite_x=True) if forward else sp_fft.ifft(a, axis=ax, overwrite_x=True)


@njit(cache=True, nogil=True)
def _frames_real(x: np.ndarray, hop: int, w: np.ndarray, out: np.ndarray) -> None:
    """out[t, j] = float32(x[t hop + j]) * w[j] (float32 arithmetic)."""
    nfr, L = out.shape
    for t in range(nfr):
        o = t * hop
        for j in range(L):
            out[t, j] = np.float32(x[o + j]) * w[j]


@njit(cache=True, nogil=True)
def _frames_complex(xv: np.ndarray, hop: int, w: np.ndarray, out: np.ndarray) -> None:
    """out[t, j] = complex64(x[t hop + j]) * w[j], x given as its float64 view (re, im pairs): each part rounded
    to float32 and multiplied by the float32 window (what complex64 times a real float32 gives)."""
    nfr, L = out.shape
    for t in range(nfr):
        o = 2 * t * hop
        for j in range(L):
            re = np.float32(xv[o + 2 * j]) * w[j]
            im = np.float32(xv[o + 2 * j + 1]) * w[j]
            out[t, j] = complex(re, im)


@njit(cache=True, nogil=True)
def _power_real(spec: np.ndarray) -> np.ndarray:
    """|X|^2 in float32: re * re + im * im, each product rounded to float32 (as np.square then add)."""
    nfr, nb = spec.shape
    out = np.empty((nfr, nb), dtype=np.float32)
    for t in range(nfr):
        for b in range(nb):
            v = spec[t, b]
            re = np.float32(v.real)
            im = np.float32(v.imag)
            out[t, b] = np.float32(re * re) + np.float32(im * im)
    return out


@njit(cache=True, nogil=True)
def _power_shifted(spec: np.ndarray, shift: int) -> np.ndarray:
    """|X|^2 in float32 of a complex FFT in fftshift order: out[t, b] = |spec[t, (b + shift) mod L]|^2."""
    nfr, L = spec.shape
    out = np.empty((nfr, L), dtype=np.float32)
    for t in range(nfr):
        for b in range(L):
            v = spec[t, (b + shift) % L]
            re = np.float32(v.real)
            im = np.float32(v.imag)
            out[t, b] = np.float32(re * re) + np.float32(im * im)
    return out


def noise_levels(S: np.ndarray, smooth_bins: int, cplx: bool) -> np.ndarray:
    """Per-bin noise power of |STFT|^2 (module docstring), shape (bins,) float64.

    S: float32 (frames, bins), as from stft_power (other dtypes are converted). One compiled pass
    (``_noise_levels_kernel``); the same arithmetic as the numpy version it replaced (float32 quantile,
    medians and threshold, float64 masked means); its properties: test_ridge_stages.py."""
    S = np.ascontiguousarray(S, dtype=np.float32)
    nfr, B = S.shape
    k = max(0, min(nfr - 1, int(_Q_LOW * nfr)))
    # the same quantile either way (LONG_COLUMN_FRAMES); contiguous either way, so that _noise_levels_kernel has one
    # compiled version, the one warm_up compiles (a strided q compiled a second one, 1.1-1.6 s, on its first block)
    if nfr >= LONG_COLUMN_FRAMES:
        q = column_order_statistic(S, k)
    else:
        St = np.ascontiguousarray(S.T)
        St.sort(axis=1)
        q = np.ascontiguousarray(St[:, k])
    w = min(int(smooth_bins), B - (1 - B % 2))
    return _noise_levels_kernel(S, q, w, bool(cplx), bool(cplx), (B // 3) | 1)


@njit(cache=True, inline="always")
def _neighbour(q: int, n: int, wrap: bool) -> int:
    """Index q of a 1-D array of n values wrapped around (scipy.ndimage's mode "wrap") or held at its ends
    ("nearest")."""
    if wrap:
        return q % n
    return min(max(q, 0), n - 1)


@njit(cache=True)
def _median_filter_1d(a: np.ndarray, w: int, wrap: bool) -> np.ndarray:
    """scipy.ndimage.median_filter(a, size=w, mode="wrap" if wrap else "nearest") of a 1-D array, w odd. Each
    window's middle value found by counting ranks (ties by place: the value a sort puts in the middle) for w up to
    ``_RANK_MEDIAN_MAX`` and a NaN-free a: no branch on the values and no sort call (numba's sort of 5 values cost
    ~180 ns, 6 us a filter of 33 bins); else by sorting the window."""
    n = a.size
    h = w // 2
    out = np.empty_like(a)
    buf = np.empty(w, dtype=a.dtype)
    by_rank = w <= _RANK_MEDIAN_MAX
    for i in range(n):
        by_rank = by_rank and a[i] == a[i]
    for i in range(n):
        for j in range(w):
            q = _neighbour(i + j - h, n, wrap)
            buf[j] = a[q]
        if by_rank:
            out[i] = _kth_of_few(buf, w, h)
        else:
            buf.sort()
            out[i] = buf[h]
    return out


_RANK_MEDIAN_MAX = 31
"""_median_filter_1d: the largest window whose median is found by counting ranks."""


@njit(cache=True)
def _min_max_filter_1d(a: np.ndarray, w: int, wrap: bool, take_max: bool) -> np.ndarray:
    """scipy.ndimage minimum_filter / maximum_filter of a 1-D array (size w odd, mode wrap or nearest)."""
    n = a.size
    h = w // 2
    out = np.empty_like(a)
    for i in range(n):
        v = a[i]
        for j in range(w):
            q = _neighbour(i + j - h, n, wrap)
            if take_max:
                if a[q] > v:
                    v = a[q]
            elif a[q] < v:
                v = a[q]
        out[i] = v
    return out


@njit(cache=True)
def _noise_levels_kernel(S: np.ndarray, q: np.ndarray, w: int, wrap: bool, cplx: bool, w2: int) -> np.ndarray:
    """noise_levels after the quantile (module docstring), compiled. S float32 (frames, bins); q the
    ``_Q_LOW`` quantile of each bin over frames, float32."""
    nfr, B = S.shape
    q_exp = np.float32(_Q_LOW_EXP)
    lvl0 = np.empty(B, dtype=np.float32)
    for b in range(B):
        lvl0[b] = q[b] / q_exp
    if w >= 3:
        lvl0 = _median_filter_1d(lvl0, w, wrap)
    tiny = np.float32(1e-37)
    cut = np.float32(_CUT)
    thr = np.empty(B, dtype=np.float32)
    for b in range(B):
        if lvl0[b] < tiny:
            lvl0[b] = tiny
        thr[b] = cut * lvl0[b]
    # jammer cells: above the cut, widened by one bin and one frame (its skirts): a 3 x 3 dilation (hot cells
    # with an empty border, widened along bins, then along frames where the others are summed per bin in
    # frame order; branch-free loops that the compiler vectorises across bins)
    H = np.zeros((nfr + 2, B + 2), dtype=np.uint8)
    for t in range(nfr):
        for b in range(B):
            H[t + 1, b + 1] = S[t, b] > thr[b]
    R = np.empty((nfr + 2, B), dtype=np.uint8)
    for t in range(nfr + 2):
        for b in range(B):
            R[t, b] = H[t, b] | H[t, b + 1] | H[t, b + 2]
    acc = np.zeros(B)
    cnt = np.zeros(B, dtype=np.int64)
    for t in range(nfr):
        for b in range(B):
            keep = (R[t, b] | R[t + 1, b] | R[t + 2, b]) == 0
            acc[b] += np.float64(S[t, b]) if keep else 0.0
            cnt[b] += 1 if keep else 0
    lvl1 = np.empty(B)
    for b in range(B):
        if cnt[b] >= 8:
            lvl1[b] = acc[b] / max(cnt[b], 1) / _TRUNC_MEAN
        else:
            lvl1[b] = np.float64(lvl0[b])
    if not cplx:
        # the DC and Nyquist bins of a real signal are chi-square with one degree of freedom
        lvl1[0], lvl1[-1] = lvl1[1], lvl1[-2]
    if w >= 3:
        lvl1 = _median_filter_1d(lvl1, w, wrap)
    # a jammer that holds a band of bins in most frames is a plateau above the front end's shape: bins more
    # than PLATEAU_DB above the lower envelope (a grey opening over w2 bins) take the envelope's value
    if w2 >= 3 and B > w2:
        env = _min_max_filter_1d(_min_max_filter_1d(lvl1, w2, wrap, False), w2, wrap, True)
        f = 10 ** (PLATEAU_DB / 10)
        for b in range(B):
            lvl1[b] = min(lvl1[b], env[b] * f)
    for b in range(B):
        lvl1[b] = max(lvl1[b], 1e-300)
    return lvl1


_ENERGY: dict[int, float] = {}


def _parseval(levels: np.ndarray, L: int, cplx: bool) -> float:
    e = _ENERGY.get(L)
    if e is None:
        w = _window(L).astype(np.float64)
        e = _ENERGY[L] = L * float(np.dot(w, w))         # per frame length (it does not change between blocks)
    if cplx:
        tot = float(levels.sum())
    else:
        tot = float(levels[0] + levels[-1] + 2.0 * levels[1:-1].sum())
    return tot / e


_BIAS: dict[tuple[int, bool, int], float] = {}


def estimator_gain(L: int, cplx: bool, smooth_bins: int) -> float:
    """Mean ratio of the noise power from ``noise_levels`` to the true power on white Gaussian noise (the
    correlation of overlapping Hann frames and neighbouring bins makes the masked mean ~0.3 dB low for
    complex samples, 0.5-2 dB for real ones at L = 128..8). Measured once per (L, kind) on 1,000 frames of
    seeded noise (deterministic) and divided out by ``_noise_power``."""
    key = (int(L), bool(cplx), int(smooth_bins))
    g = _BIAS.get(key)
    if g is None:
        rng = np.random.default_rng(12345)
        n = 500 * L + L
        vals = []
        for _ in range(4):
            x = ((rng.standard_normal(n) + 1j * rng.standard_normal(n)) / math.sqrt(2.0) if cplx
                 else rng.standard_normal(n))
            S, _ = stft_power(x, L, cplx)
            vals.append(_parseval(noise_levels(S, smooth_bins, cplx), L, cplx) / float(np.mean(np.abs(x) ** 2)))
        g = float(np.mean(vals))
        _BIAS[key] = g
    return g


def _noise_power(levels: np.ndarray, L: int, cplx: bool, smooth_bins: int) -> float:
    """Noise power per sample from the per-bin levels (Parseval with the Hann window), bias removed."""
    return _parseval(levels, L, cplx) / estimator_gain(L, cplx, smooth_bins)


def _f32(lvl: np.ndarray) -> np.ndarray:
    """Noise levels as float32 divisors (never zero: a block without noise gives huge excesses, not NaN)."""
    return np.maximum(lvl, 1e-37).astype(np.float32)
