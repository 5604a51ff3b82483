"""Short-time FFT ridge analysis of one IF block (ours): in-block noise level, swept-jammer detection,
sweep period, shape, swept band and rate, for real jammers at common SDR rates.

Why: Kang et al.'s per-sample tracker (tracker.py) follows a saw-tooth whose rate per sample squared is
small (1e12 Hz/s at 38.192 MS/s: 7e-4 cycles/sample^2). Real jammers seen by 4-20 MS/s front ends sweep
10-50x faster per sample, in triangles, hooked saw-tooths, with non-constant rates and beyond the sampled
band (the jammer is then in band only part of each period). The short-time spectrum sees all of these the
same way: in every frame a swept tone is one ridge a few bins wide, wherever it is and however it moves.
Everything here is vectorised numpy over the frames of one block (no per-sample loop).

Steps (``analyse``):

1. Frame length. Frames of L samples (Hann, hop L/2) for each L in ``RidgeParams.frame_lengths``, tried
   on a slice of the block: a tone sweeping ``k`` cycles/sample^2 spreads over ``k L^2`` bins of a frame,
   so its peak excess over the noise grows with L up to ``L ~ 1 / sqrt(k)`` and falls after. The L with
   the largest mean frame peak excess above what noise alone gives (the expectation of the largest of
   B exponential variables, the harmonic number ``H_B``) is used for the block.
2. In-block noise level per bin (no clean start needed): the lower quartile over frames of each bin's
   power, scaled to the exponential mean (``/ -ln(0.75)``); then the mean of the frames below three
   times that (divided by the mean of a unit exponential truncated at 3, 0.8428); then a median across
   ``noise_smooth_bins`` bins (a CW or a slowly swept jammer that holds one or two bins all the time
   never enters it; the front end's filter shape does). A jammer that occupies a bin in fewer than
   ~60 % of the frames (a sweep, a pulse) or fewer than half of ``noise_smooth_bins`` adjacent bins all
   the time (a tone) cannot poison it; a noise jammer that fills the band can (then only a fixed or
   learned floor sees it, monitor module docstring). The block's noise power N follows by Parseval.
3. Ridge per frame: the strongest bin, its frequency interpolated (parabola on log power), present when
   its excess over the noise level exceeds ``ln(B) + presence_nats`` (a false alarm in
   ``exp(-presence_nats)`` of the noise frames).
4. Period: the autocorrelation over frames of the spectral phasor ``u_t = sum_b max(S_tb / N_b - 1, 0)
   exp(2 pi i b / B)`` (mean removed): a CW is constant (removed with the mean), noise is white, any
   periodic sweep (any shape, pulsed or not) is periodic. The first lag whose peak reaches 0.6 of the
   highest one and stands ``detect_sigma`` noise standard deviations (``1 / sqrt(2 (T - lag))`` for T
   frames) and ``min_strength`` above the lowest value before it is the coarse period; it is refined by
   a least-squares fit over the interpolated peaks at its multiples (up to half the block: the error of
   one peak is divided by the number of periods).
5. Sweep profile: the ridge frequencies of the present frames folded on the period into
   ``phase_bins`` bins (median of each bin) and the share of present frames per bin. Bins with at least
   half of the largest share are "in band"; ``in_band_fraction`` is their share of the period (< 1: a
   sweep that leaves the sampled band, or a pulsed one). Complex input: a ridge in the first or last bin
   (the +-0.5 cycles/sample edge, where the circular spectrum joins) is present but its frequency stays
   out of the medians (it may be either edge). Steps between consecutive in-band bins larger than
   ``JUMP_SPAN`` of the swept span are flybacks; the others are swept steps, up or down.
   Shape (issue 14 item 3), a statistic of the profile's slope sequence with this decision rule:
   a swept step *counts* when it exceeds ``STEP_SIGMA`` (3) standard errors of the two bin medians it
   joins (each from its bin's interquartile range / sqrt(frames)): a ridge that is only scatter gives no
   counted steps. Fewer than 3 counted steps: unknown. Of the counted steps, up in a share of 30-70 %,
   or a way back from the sweep's end (``_return_bins``) lasting >= 30 % of the period
   (``TRIANGLE_SIDE``): triangle (at least 2 counted steps each way, else unknown). Otherwise the main
   direction's saw-tooth when its sign test (``_sign_tail``, Binomial(n, 1/2)) is <= ``SAW_P`` (0.01),
   or all counted steps go its way and a flyback is seen between two in-band bins (a triangle seen only in
   pieces also goes one way within each piece); steps against it in 15-30 % of the counted ones, or the
   direction unproven: unknown. It is hooked when its way
   back from the sweep's end is swept (``MIN_RETURN_BINS`` = 2 bins of the profile strictly inside the
   span, 10 % from its ends: an instantaneous flyback gives at most one such bin) or when the two steps
   after its flyback both exceed ``hook_rate_ratio`` times the median step (an overshoot relaxing back
   fast). The return is also looked for in the finer ``phase_bins`` profile, and then at the resolution of a
   sample (``fine_profile``: the lag products a[n + 1] conj(a[n]) of the samples, analytic for real input, folded
   on the period and averaged over the block's periods, the noise's own lag product removed; ``fine_return``:
   hooked when the way back crosses the span in >= ``FINE_MIN_RETURN`` bins at full strength, where an
   instantaneous flyback gives at most two). A hook whose return crosses the span in fewer than about 4 samples,
   or a weak one, is not resolved: the jammer is reported as the saw-tooth it is otherwise. Measured (a hook of
   15 % of an 18 us period overshooting by 10 % of the span, 4 seeds, 1 ms blocks): hooked in 4 of 4 from J/N 6 dB
   at 10 MS/s I/Q and from 10-15 dB at 16.368 and 38.192 MS/s real (2 of 4 and 1 of 4 at 6 dB), never at 0-3 dB;
   at 4 MS/s I/Q (a return of about 5 samples) in at most 2 of 4. Rate: the median counted step of the main
   direction; swept band: the extremes of the profile (of its in-band part: a lower bound of a sweep wider than
   the band).
   A periodic ridge is a sweep when it moves over >= 4 bins, or over >= 2 bins with a saw-tooth
   direction whose sign test is <= ``SAW_P`` (a narrow saw-tooth seen with short frames); a pulsed tone
   is periodic but does not move.
6. Current frequency: the ridge of the last frame when present, else NaN (the jammer is out of the band
   at the block end, or not tracked). Its 1-sigma: the RMS deviation of the present frames' ridge from
   the profile (periodic), else from the local straight line through three consecutive frames, but at
   least one bin / sqrt(12).

A sweep too weak for the per-frame ridge whose period is known from elsewhere (the evidence over blocks,
integration.py) gets its shape from ``folded_shape``: the short-time spectrum averaged per phase of the period
(synchronous averaging), the strongest bin per phase bin where it stands out of noise, the same shape rule; when too
few phase bins stand out for it, the sweep law (saw-tooth up or down, triangle) whose line through the whole folded
map has the largest sum (``_line_shape``: K phase bins of z each sum to sqrt(K) z; Bonferroni over the laws, and a
margin over the other classes). The demo's chirp at J/S +6 dB (J/N -13 dB) gets its shape so (real_jammers.md).

A frequency track that is coherent but not periodic inside the block (a single slow sweep, a period
longer than ``max_period_s``) is reported as ``sweeping`` without a period: present in at least
``min_present_fraction`` of the frames, consecutive ridges within 2 bins in most of them, and a span of
at least 4 bins.

Frequencies are digital, cycles/sample: complex input signed in [-0.5, 0.5) (fftshift order), real input
in [0, 0.5]. Powers in sample units^2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy import fft as sp_fft
from scipy.special import ndtri

SHAPE_UNKNOWN, SAWTOOTH_UP, SAWTOOTH_DOWN, TRIANGLE, HOOKED_SAWTOOTH = 0, 1, 2, 3, 4
"""Sweep shape codes, identical to rfi_msgs/JammerState.SHAPE_*."""
SHAPE_NAMES = {SHAPE_UNKNOWN: "unknown", SAWTOOTH_UP: "sawtooth_up", SAWTOOTH_DOWN: "sawtooth_down",
               TRIANGLE: "triangle", HOOKED_SAWTOOTH: "hooked_sawtooth"}
_Q_LOW = 0.1
_Q_LOW_EXP = -math.log(1.0 - _Q_LOW)
"""The 10 % quantile of a unit exponential (the power of a noise bin over its mean)."""
MIN_SELECT_EXCESS = 2.0
"""choose_frame_length: below this best mean peak excess (white noise: -0.1..1.3 over 8192 samples, real
input the higher) the longest frame within 0.5 of the best is taken instead of the best; and the longest frame of
all when no score stands ``SELECT_Z`` of its noise-only standard deviations above its noise-only mean
(``null_peak_excess``): nothing in the slice but noise."""
SELECT_Z = 3.0
"""choose_frame_length: significance of a frame-length score over noise, standard deviations of the score on white
Gaussian noise at that frame length."""
SHORT_FRAME_SCORE = 1.0
"""choose_frame_length takes the shortest frame whose peak excess is at least this share of the best one (1: the
best; 0.5 lost the 5.1 MHz sweep of the paper front end at J/N 10 dB, a 16-sample frame has 2.4 MHz bins)."""
JUMP_SPAN = 0.6
"""A step between consecutive in-band profile bins larger than this share of the swept span is a flyback
(a saw-tooth's is ~1; a sweep that crosses the band in two or three bins, as a triangle wider than the
band does, steps by a half or a third of the span and is still a sweep)."""
SHAPE_BINS = 16
"""Phase bins of the profile the sweep shape and rate are read from (the finer ``phase_bins`` profile gives
the frequency at the block end)."""
RETURN_MARGIN = 0.1
"""_return_bins: a bin on a saw-tooth's way back counts when it lies more than this share of the swept span inside
either end of it."""
MIN_RETURN_BINS = 2
"""A saw-tooth with at least this many profile bins on a swept way back is hooked (an instantaneous flyback
gives none, or one where the frames around it are mixed)."""
TRIANGLE_SIDE = 0.3
"""_shape: a triangle's shorter side takes at least this share of the period (of the counted steps, or of the
profile's bins on the way back from the sweep's end); a swept return shorter than that is a hook."""
STEP_SIGMA = 3.0
"""_shape: a swept step of the folded profile counts for the shape when it exceeds this many standard errors of
the two medians it joins (a ridge that is only scatter gives few such steps, and no runs of them)."""
SAW_P = 0.01
"""_shape: a saw-tooth whose counted steps do not all go one way needs a sign test (``_sign_tail``) of at most this
(6 of 7 steps up: 0.06, unknown; 13 of 15: 0.004, a saw-tooth). analyse: a periodic ridge that moves over only 2-4
bins is a sweep when its saw-tooth direction has a sign test of at most this (7 of 7 steps: 0.008)."""
PLATEAU_DB = 1.5
"""A bin's noise level may exceed the lower envelope of its neighbours by this much, dB (noise_levels)."""
_CUT = 3.0
_TRUNC_MEAN = 1.0 - _CUT * math.exp(-_CUT) / (1.0 - math.exp(-_CUT))
"""Mean of a unit exponential truncated at _CUT (0.8428)."""


@dataclass(frozen=True)
class RidgeParams:
    """Parameters of the short-time FFT ridge analysis (module docstring).

    Attributes:
        min_frame_length, max_frame_length: the candidate frame lengths are the powers of two between
            them, samples (>= 8).
        select_samples: samples of the block used to choose the frame length (0: the whole block).
        max_period_s: longest sweep period searched, s (also limited to a quarter of the block).
        min_period_frames: shortest period, frames (hops of L/2), >= 3.
        detect_sigma: significance of the periodicity peak, noise standard deviations.
        min_strength: smallest normalised autocorrelation peak-to-trough of a periodic sweep, (0, 1].
        presence_nats: per-frame ridge threshold above ln(B), nats of the exponential (4.6: 1 % false).
        noise_smooth_bins: width of the median across bins of the noise level (odd, >= 3).
        phase_bins: bins of the folded sweep profile, >= 8.
        hook_rate_ratio: a saw-tooth whose two steps after the flyback both exceed this times its median
            step is hooked (an overshoot relaxing back fast; the other hook test, a swept return, has no
            parameter), > 1.
        min_present_fraction: a non-periodic ridge must be present in at least this share of the frames.
        tracking_samples: while a chirp is tracked (the last block was CHIRP), only the last this many
            samples of a block are analysed (speed; the J/N and the CW test still use the whole block; a
            block whose tail shows no sweep is analysed whole); 0: always the whole block.
        acquisition_samples: while nothing is tracked (the last block was neither CW nor CHIRP), only the last
            this many samples of a block are analysed first: a block whose part shows anything (a type other than
            NONE, a sweep, a period) is analysed whole, so only quiet blocks are analysed in part (speed: a 1 ms
            block at the paper's 38.192 MS/s is analysed as a 16.4 MS/s front end's block would be; the J/N, the CW
            test and the evidence over blocks use the whole block; blocks of at most this many samples are
            always analysed whole); 0: always the whole block.
    """

    min_frame_length: int = 8
    max_frame_length: int = 128
    select_samples: int = 8192
    max_period_s: float = 250e-6
    min_period_frames: int = 4
    detect_sigma: float = 7.0
    min_strength: float = 0.08
    presence_nats: float = 4.6
    noise_smooth_bins: int = 5
    phase_bins: int = 32
    hook_rate_ratio: float = 2.0
    min_present_fraction: float = 0.5
    tracking_samples: int = 16384
    acquisition_samples: int = 16384

    @property
    def frame_lengths(self) -> tuple[int, ...]:
        """The candidate frame lengths, increasing."""
        out, L = [], int(self.min_frame_length)
        while L <= int(self.max_frame_length):
            out.append(L)
            L *= 2
        return tuple(out)

    def __post_init__(self) -> None:
        a, b = int(self.min_frame_length), int(self.max_frame_length)
        if a < 8 or b < a or a & (a - 1) or b & (b - 1):
            raise ValueError("min_frame_length <= max_frame_length must be powers of two >= 8")
        for name in ("max_period_s", "detect_sigma", "min_strength", "presence_nats", "hook_rate_ratio",
                     "min_present_fraction"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be finite and > 0")
        if self.min_strength > 1 or self.min_present_fraction > 1:
            raise ValueError("min_strength and min_present_fraction must be <= 1")
        if int(self.tracking_samples) < 0 or 0 < int(self.tracking_samples) < 1024:
            raise ValueError("tracking_samples must be 0 or >= 1024")
        if int(self.acquisition_samples) < 0 or 0 < int(self.acquisition_samples) < 1024:
            raise ValueError("acquisition_samples must be 0 or >= 1024")
        if int(self.min_period_frames) < 3 or int(self.phase_bins) < 8 or int(self.select_samples) < 0:
            raise ValueError("min_period_frames >= 3, phase_bins >= 8, select_samples >= 0")
        if int(self.noise_smooth_bins) < 3 or int(self.noise_smooth_bins) % 2 == 0:
            raise ValueError("noise_smooth_bins must be odd and >= 3")


@dataclass(frozen=True)
class RidgeResult:
    """What the ridge analysis found in one block (NaN where unknown; frequencies in cycles/sample).

    Attributes:
        frame_length, hop: samples.
        noise_power: in-block noise power per sample (sample units^2).
        peak_excess: mean frame peak excess over noise, minus the noise-only expectation (>= ~0 for noise).
        present_fraction: share of frames with a ridge above the presence threshold.
        periodic: a sweep period was found; period_samples, strength: it and its autocorrelation peak.
        sweeping: a swept jammer (periodic, or a coherent moving ridge) with a span of >= 4 bins.
        shape: SHAPE_* code; in_band_fraction: share of the period with the jammer in band.
        low, high: swept band limits seen in band; start: frequency at the sweep start (shape-dependent).
        rate: sweep rate of the main direction, cycles/sample^2 (signed; triangle: of the up part).
        frequency: ridge at the block end (NaN when absent); frequency_std: its 1-sigma.
        hook_checked: the sample-resolution hook test (``fine_profile``) ran on this block (a saw-tooth analysed with
            ``fine_hook``); False when it did not, so that a saw-tooth's shape says nothing about a hook the coarse
            profile cannot resolve.
    """

    frame_length: int
    hop: int
    noise_power: float
    peak_excess: float
    present_fraction: float
    periodic: bool
    period_samples: float
    strength: float
    sweeping: bool
    shape: int
    in_band_fraction: float
    low: float
    high: float
    start: float
    rate: float
    frequency: float
    frequency_std: float
    hook_checked: bool = False


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
        spec = sp_fft.fft(fw, axis=1, overwrite_x=True)
        freqs = (np.arange(L) - L // 2) / L
        return _power_shifted(spec, L // 2), freqs
    xr = np.ascontiguousarray(x, dtype=np.float64)
    fr32 = np.empty((nfr, L), dtype=np.float32)
    _frames_real(xr, hop, w, fr32)
    spec = sp_fft.rfft(fr32, axis=1, overwrite_x=True)
    freqs = np.arange(L // 2 + 1) / L
    return _power_real(spec), freqs


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
    """Per-bin noise power of |STFT|^2 (module docstring, step 2), shape (bins,) float64.

    S: float32 (frames, bins), as from stft_power (other dtypes are converted). One compiled pass
    (``_noise_levels_kernel``); the same arithmetic as the numpy version it replaced (float32 quantile,
    medians and threshold, float64 masked means; test_ridge_speed_equivalence.py)."""
    S = np.ascontiguousarray(S, dtype=np.float32)
    nfr, B = S.shape
    k = max(0, min(nfr - 1, int(_Q_LOW * nfr)))
    q = np.partition(np.ascontiguousarray(S.T), k, axis=1)[:, k]
    w = min(int(smooth_bins), B - (1 - B % 2))
    return _noise_levels_kernel(S, q, w, bool(cplx), bool(cplx), (B // 3) | 1)


@njit(cache=True)
def _median_filter_1d(a: np.ndarray, w: int, wrap: bool) -> np.ndarray:
    """scipy.ndimage.median_filter(a, size=w, mode="wrap" if wrap else "nearest") of a 1-D array, w odd."""
    n = a.size
    h = w // 2
    out = np.empty_like(a)
    buf = np.empty(w, dtype=a.dtype)
    for i in range(n):
        for j in range(w):
            q = i + j - h
            if wrap:
                q %= n
            else:
                q = min(max(q, 0), n - 1)
            buf[j] = a[q]
        buf.sort()
        out[i] = buf[h]
    return out


@njit(cache=True)
def _min_max_filter_1d(a: np.ndarray, w: int, wrap: bool, take_max: bool) -> np.ndarray:
    """scipy.ndimage minimum_filter / maximum_filter of a 1-D array (size w odd, mode wrap or nearest)."""
    n = a.size
    h = w // 2
    out = np.empty_like(a)
    for i in range(n):
        v = a[i]
        for j in range(w):
            q = i + j - h
            if wrap:
                q %= n
            else:
                q = min(max(q, 0), n - 1)
            if take_max:
                if a[q] > v:
                    v = a[q]
            elif a[q] < v:
                v = a[q]
        out[i] = v
    return out


@njit(cache=True)
def _noise_levels_kernel(S: np.ndarray, q: np.ndarray, w: int, wrap: bool, cplx: bool, w2: int) -> np.ndarray:
    """noise_levels after the quantile (module docstring, step 2), compiled. S float32 (frames, bins); q the
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


@njit(cache=True)
def _pairwise_sum_f32(a: np.ndarray) -> np.float32:
    """Sum of a float32 vector in float32 in numpy's pairwise order (numpy's ``add.reduce`` over a contiguous
    axis: 8 partial sums, combined in pairs, the rest in order; halves above 128), so that the compiled
    phasor equals the numpy expression it replaced to the bit."""
    n = a.size
    if n < 8:
        res = np.float32(0.0)
        for i in range(n):
            res += a[i]
        return res
    if n > 128:
        n2 = n // 2
        n2 -= n2 % 8
        return _pairwise_sum_f32(a[:n2]) + _pairwise_sum_f32(a[n2:])
    r0, r1, r2, r3, r4, r5, r6, r7 = a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]
    i = 8
    while i < n - (n % 8):
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[i]
        i += 1
    return res


@njit(cache=True)
def _excess_kernel(S: np.ndarray, div: np.ndarray, cos32: np.ndarray, sin32: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One pass over |STFT|^2 (module docstring, steps 3-4): per frame the strongest bin of the excess
    E = S / div (float32; the first one, as np.argmax), E there, and the two float32 sums of the spectral
    phasor, sum_b max(E - 1, 0) cos / sin(2 pi b / B)."""
    nfr, B = S.shape
    k = np.empty(nfr, dtype=np.int64)
    pk = np.empty(nfr, dtype=np.float32)
    uc = np.empty(nfr, dtype=np.float32)
    us = np.empty(nfr, dtype=np.float32)
    e = np.empty(B, dtype=np.float32)
    tc = np.empty(B, dtype=np.float32)
    ts = np.empty(B, dtype=np.float32)
    one = np.float32(1.0)
    zero = np.float32(0.0)
    for t in range(nfr):
        for b in range(B):
            e[b] = S[t, b] / div[b]
        kb = 0
        best = e[0]
        for b in range(1, B):
            v = e[b]
            if v > best or (v != v and best == best):
                best = v
                kb = b
        k[t] = kb
        pk[t] = best
        for b in range(B):
            v = e[b] - one
            if v < zero:
                v = zero
            tc[b] = v * cos32[b]
            ts[b] = v * sin32[b]
        uc[t] = _pairwise_sum_f32(tc)
        us[t] = _pairwise_sum_f32(ts)
    return k, pk, uc, us


def _parseval(levels: np.ndarray, L: int, cplx: bool) -> float:
    w = _window(L).astype(np.float64)
    if cplx:
        tot = float(levels.sum())
    else:
        tot = float(levels[0] + levels[-1] + 2.0 * levels[1:-1].sum())
    return tot / (L * float(np.dot(w, w)))


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


_NULL_EXCESS: dict[tuple[int, bool, int, int], tuple[float, float]] = {}
NULL_SLICES = 24
"""Seeded white-noise slices that ``null_peak_excess`` measures its mean and standard deviation on."""


def null_peak_excess(L: int, cplx: bool, n: int, smooth_bins: int) -> tuple[float, float]:
    """(mean, standard deviation) of ``_peak_excess`` on white Gaussian noise for frames of L over n samples
    (choose_frame_length): measured once per (L, kind, n, smooth_bins) on ``NULL_SLICES`` seeded noise slices
    (deterministic) and cached. Neither is zero: the score's noise-only mean is 0.6-1.0 for real input (8192 samples)
    and its scatter 0.2-0.5."""
    key = (int(L), bool(cplx), int(n), int(smooth_bins))
    v = _NULL_EXCESS.get(key)
    if v is None:
        rng = np.random.default_rng(23456)
        vals = []
        for _ in range(NULL_SLICES):
            x = ((rng.standard_normal(n) + 1j * rng.standard_normal(n)) / math.sqrt(2.0) if cplx
                 else rng.standard_normal(n))
            S, _ = stft_power(x, L, cplx)
            vals.append(_peak_excess(S, noise_levels(S, smooth_bins, cplx), cplx))
        v = (float(np.mean(vals)), float(np.std(vals, ddof=1)))
        if len(_NULL_EXCESS) > 256:
            _NULL_EXCESS.clear()
        _NULL_EXCESS[key] = v
    return v


def _noise_power(levels: np.ndarray, L: int, cplx: bool, smooth_bins: int) -> float:
    """Noise power per sample from the per-bin levels (Parseval with the Hann window), bias removed."""
    return _parseval(levels, L, cplx) / estimator_gain(L, cplx, smooth_bins)


def _f32(lvl: np.ndarray) -> np.ndarray:
    """Noise levels as float32 divisors (never zero: a block without noise gives huge excesses, not NaN)."""
    return np.maximum(lvl, 1e-37).astype(np.float32)


def _peak_excess(S: np.ndarray, lvl: np.ndarray, cplx: bool = True) -> float:
    """Mean over frames of the largest bin excess (power / noise level), minus the harmonic number H_B (the
    mean largest of B unit exponentials). Real input: without the DC and Nyquist bins (one degree of freedom:
    heavier tails, which made noise score above zero at short frames)."""
    b0, b1 = (1, S.shape[1] - 1) if (not cplx and S.shape[1] > 3) else (0, S.shape[1])
    B = b1 - b0
    h = float(np.sum(1.0 / np.arange(1, B + 1)))
    return float(np.mean(_row_max_excess(np.ascontiguousarray(S, dtype=np.float32), _f32(lvl), b0, b1))) - h


@njit(cache=True)
def _row_max_excess(S: np.ndarray, div: np.ndarray, b0: int, b1: int) -> np.ndarray:
    """Per frame the largest S / div (float32) over bins b0 .. b1 - 1 (NaN if any is NaN, as np.max)."""
    nfr = S.shape[0]
    out = np.empty(nfr, dtype=np.float32)
    for t in range(nfr):
        best = S[t, b0] / div[b0]
        for b in range(b0 + 1, b1):
            v = S[t, b] / div[b]
            if v > best or v != v:
                best = v
                if v != v:
                    break
        out[t] = best
    return out


def choose_frame_length(x: np.ndarray, cplx: bool, par: RidgeParams) -> int:
    """The frame length of the block (module docstring, step 1)."""
    n = x.size if par.select_samples <= 0 else min(x.size, int(par.select_samples))
    xs = x[:n]
    scores: list[tuple[int, float]] = []
    for L in par.frame_lengths:
        if 8 * L > n:
            break
        S, _ = stft_power(xs, L, cplx)
        lvl = noise_levels(S, par.noise_smooth_bins, cplx)
        scores.append((L, _peak_excess(S, lvl, cplx)))
    if not scores:
        return int(par.min_frame_length)
    scores = [(L, sc) for L, sc in scores if math.isfinite(sc)]
    if not scores:
        return int(par.min_frame_length)
    best = max(sc for _, sc in scores)
    if best < MIN_SELECT_EXCESS:
        # nothing clearly concentrated in the slice: the longest frame within noise's scatter of the best
        # (fewer frames, a cheaper analysis; a chirp that appears makes the monitor choose again at once), and
        # the longest of all when no score is significant over noise: the scores of a noise-only slice scatter
        # by about 0.5 around a mean of up to 1, so "the best" was a random frame length, often the shortest
        # and costliest (band-limited noise at 38.192 MS/s: L = 8, 9,547 frames per 1 ms block)
        z = []
        for L, sc in scores:
            mu, sd = null_peak_excess(L, cplx, n, par.noise_smooth_bins)
            z.append((sc - mu) / sd if sd > 0 else math.inf)
        if max(z) < SELECT_Z:
            return int(max(L for L, _ in scores))
        return int(max(L for L, sc in scores if sc >= best - 0.5))
    # the shortest frame within a factor SHORT_FRAME_SCORE of the best: time resolution (a sweep's ends,
    # short sweeps, the frequency at the block end) at little loss of peak excess
    return next(L for L, sc in scores if sc >= SHORT_FRAME_SCORE * best)


def _periodicity(u: np.ndarray, lmin: int, lmax: int, par: RidgeParams) -> tuple[float, float]:
    """(period in frames, strength) of the phasor sequence u, or (nan, 0) (module docstring, step 4)."""
    T = u.size
    if lmax <= lmin + 2 or T < 4 * lmin:
        return math.nan, 0.0
    v = u - u.mean()
    nf = 1 << int(math.ceil(math.log2(2 * T)))
    V = np.fft.fft(v, nf)
    R = np.fft.ifft(V * np.conj(V))[:T].real
    if not R[0] > 0:
        return math.nan, 0.0
    per, strength = _period_from_autocorrelation(np.ascontiguousarray(R), int(lmin), int(lmax),
                                                 float(par.min_strength), float(par.detect_sigma))
    return per, strength


@njit(cache=True)
def _pairwise_sum_f64(a: np.ndarray) -> float:
    """np.sum of a contiguous float64 vector in numpy's pairwise order (see _pairwise_sum_f32)."""
    n = a.size
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[i]
        return res
    if n > 128:
        n2 = n // 2
        n2 -= n2 % 8
        return _pairwise_sum_f64(a[:n2]) + _pairwise_sum_f64(a[n2:])
    r0, r1, r2, r3, r4, r5, r6, r7 = a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]
    i = 8
    while i < n - (n % 8):
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[i]
        i += 1
    return res


@njit(cache=True)
def _first_argmax(r: np.ndarray, lo: int, hi: int) -> int:
    """Index of the first largest of r[lo .. hi] (np.argmax)."""
    j = lo
    for i in range(lo + 1, hi + 1):
        if r[i] > r[j]:
            j = i
    return j


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
        j = _first_argmax(r, lo_c, hi_c)
        if (r[j] >= r[j - 1] and r[j] >= r[j + 1] and r[j] >= 0.5 * r[int(T0)]
                and r[j] - trough[j - 1] >= max(min_strength, detect_sigma * sig[j])):
            T0 = float(j)
            break
    strength = r[int(T0)] - trough[int(T0) - 1]
    # refine on multiples (least squares through the origin): 1, 2, 3, 4, 6, 9, 13, ... (geometric: the far
    # ones give the precision, each step keeps the search window of the next one within 15 % of the period)
    num, den = 0.0, 0.0
    Tc = T0
    m = 1
    while m * Tc + 2 < T // 2:
        c = int(np.rint(m * Tc))
        w = max(1, int(np.rint(0.15 * Tc)))
        lo, hi = max(c - w, 1), min(c + w, T - 2)
        j = _first_argmax(r, lo, hi)
        if r[j] < 0.5 * strength or j <= 0 or j >= T - 1:
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
            if b >= 0.5 * strength:
                mp[n_ok] = mi * pos
                m2 += mi * mi
                n_ok += 1
        if n_ok >= 2:
            Tc = _pairwise_sum_f64(mp[:n_ok]) / m2
    return Tc, strength

def _ridge(S: np.ndarray, k: np.ndarray, pk: np.ndarray, freqs: np.ndarray, presence: float
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame: interpolated ridge frequency (cycles/sample), peak excess, present flag. k, pk: the
    strongest bin of each frame's excess and the excess there (``_excess_kernel``)."""
    nfr, B = S.shape
    rows = np.arange(nfr)
    km, kp = np.clip(k - 1, 0, B - 1), np.clip(k + 1, 0, B - 1)
    a = np.log(S[rows, km] + 1e-30)
    b = np.log(S[rows, k] + 1e-30)
    c = np.log(S[rows, kp] + 1e-30)
    den = a - 2 * b + c
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where((den < 0) & (k > 0) & (k < B - 1), 0.5 * (a - c) / den, 0.0)
    d = np.clip(d, -0.5, 0.5)
    df = freqs[1] - freqs[0]
    f = freqs[k] + d * df
    present = pk > (math.log(B) + presence)
    return f, pk, present


def _profile(f: np.ndarray, present: np.ndarray, period_frames: float, K: int, fuse: np.ndarray | None = None,
             resolution: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Folded sweep profile: median ridge frequency, present share and the median's standard error per phase
    bin (K bins). fuse: the present frames whose frequency enters the medians (default all present ones).
    Standard error: 1.2533 x the interquartile range / 1.349 / sqrt(n) (a median's, from the bin's own spread),
    at least ``resolution`` / sqrt(12 n); infinite with fewer than 4 frames in the bin. Frame t falls in phase
    bin floor(K (t / period_frames mod 1)). Compiled (``_profile_kernel``; the numpy version it replaced, with
    np.bincount and np.lexsort, is ridge_reference.py's, test_ridge_speed_equivalence.py)."""
    use = present if fuse is None else fuse
    return _profile_kernel(np.ascontiguousarray(f, dtype=np.float64), np.ascontiguousarray(present, dtype=np.bool_),
                           np.ascontiguousarray(use, dtype=np.bool_), float(period_frames), int(K), float(resolution))


@njit(cache=True)
def _phase_bins(nfr: int, period_frames: float, K: int) -> np.ndarray:
    """Phase bin of frames 0..nfr-1 on a period of period_frames frames, K bins: floor(K (t / period mod 1)),
    at most K - 1 (np.minimum((np.mod(t / p, 1.0) * K).astype(np.int64), K - 1); Python's float % is np.mod)."""
    kb = np.empty(nfr, dtype=np.int64)
    for t in range(nfr):
        j = int(((t / period_frames) % 1.0) * K)
        kb[t] = j if j < K - 1 else K - 1
    return kb


@njit(cache=True)
def _profile_kernel(f: np.ndarray, present: np.ndarray, use: np.ndarray, period_frames: float, K: int,
                    resolution: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """_profile, compiled: phase bins, frame counts and present shares, the used frequencies gathered per bin and
    sorted (a counting sort by bin, then each bin's values: the order np.lexsort((f, bin)) gives), then
    ``_bin_stats``."""
    nfr = f.size
    kb = _phase_bins(nfr, period_frames, K)
    n = np.zeros(K)
    npres = np.zeros(K)
    cnt = np.zeros(K, dtype=np.int64)
    m = 0
    for t in range(nfr):
        b = kb[t]
        n[b] += 1.0
        if present[t]:
            npres[b] += 1.0
        if use[t]:
            cnt[b] += 1
            m += 1
    share = np.zeros(K)
    for b in range(K):
        if n[b] > 0:
            share[b] = npres[b] / max(n[b], 1.0)
    if m == 0:
        return np.full(K, np.nan), share, np.full(K, np.inf)
    start = np.empty(K, dtype=np.int64)
    acc = 0
    for b in range(K):
        start[b] = acc
        acc += cnt[b]
    pos = start.copy()
    buf = np.empty(m)
    for t in range(nfr):
        if use[t]:
            b = kb[t]
            buf[pos[b]] = f[t]
            pos[b] += 1
    for b in range(K):
        if cnt[b] > 1:
            buf[start[b]:start[b] + cnt[b]] = np.sort(buf[start[b]:start[b] + cnt[b]])
    prof, se = _bin_stats(buf, cnt, resolution)
    return prof, share, se


@njit(cache=True)
def _lerp(a: float, b: float, t: float) -> float:
    """numpy's quantile interpolation between neighbours (numpy.lib._function_base_impl._lerp)."""
    d = b - a
    if t >= 0.5:
        return b - d * (1.0 - t)
    return a + d * t


@njit(cache=True)
def _quantile_sorted(v: np.ndarray, q: float) -> float:
    """np.percentile(v, 100 q) (method "linear") of a sorted, non-empty, NaN-free vector."""
    n = v.size
    vi = (n - 1) * q
    if vi >= n - 1:
        return float(v[n - 1])
    i = int(math.floor(vi))
    return _lerp(float(v[i]), float(v[i + 1]), vi - i)


@njit(cache=True)
def _fold_residuals(f: np.ndarray, present: np.ndarray, inband: np.ndarray, prof: np.ndarray, period_frames: float,
                    q_lo: float, q_hi: float) -> tuple[float, int, float, float]:
    """The ridge against its folded profile (analyse, a periodic sweep): over the present frames whose phase bin is
    in band, (RMS of the finite differences from the profile, NaN when there are none; their number; the q_lo and
    q_hi quantiles (fractions) of their frequencies, NaN below 20 frames). Compiled: the mean in numpy's pairwise
    order, the quantiles as np.percentile's "linear"."""
    K = prof.size
    nfr = f.size
    kb = _phase_bins(nfr, period_frames, K)
    r2 = np.empty(nfr)
    fsel = np.empty(nfr)
    nres = 0
    nsel = 0
    for t in range(nfr):
        if present[t] and inband[kb[t]]:
            fsel[nsel] = f[t]
            nsel += 1
            r = f[t] - prof[kb[t]]
            if np.isfinite(r):
                r2[nres] = r * r
                nres += 1
    rms = math.sqrt(_pairwise_sum_f64(r2[:nres]) / nres) if nres else np.nan
    lo = hi = np.nan
    if nsel >= 20:
        v = np.sort(fsel[:nsel])
        lo, hi = _quantile_sorted(v, q_lo), _quantile_sorted(v, q_hi)
    return rms, nsel, lo, hi


@njit(cache=True)
def _bin_stats(fs_sorted: np.ndarray, cnt: np.ndarray, resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """_profile's per-bin median and its standard error from the frequencies sorted by (bin, value) and the
    counts per bin (compiled; NaN / inf for an empty bin / fewer than 4 frames)."""
    K = cnt.size
    prof = np.full(K, np.nan)
    se = np.full(K, np.inf)
    start = 0
    floor = resolution / math.sqrt(12.0)
    for k in range(K):
        c = cnt[k]
        if c > 0:
            prof[k] = 0.5 * (fs_sorted[start + (c - 1) // 2] + fs_sorted[start + c // 2])
        if c >= 4:
            iqr = 1.2533 / 1.349 * (fs_sorted[start + (3 * (c - 1)) // 4] - fs_sorted[start + (c - 1) // 4])
            se[k] = max(iqr, floor) / math.sqrt(float(c))
        start += c
    return prof, se


@njit(cache=True)
def _sign_tail(k: int, n: int) -> float:
    """P(X >= k) for X ~ Binomial(n, 1/2): the chance that k or more of n steps go one way with no sweep."""
    if n <= 0:
        return 1.0
    tot = 0.0
    c = 1.0                                # C(n, i), exact in double for the n of a profile (<= 64)
    for i in range(n + 1):
        if i >= k:
            tot += c
        c = c * (n - i) / (i + 1)
    return tot / 2.0 ** n


@njit(cache=True)
def _return_bins(prof: np.ndarray, inband: np.ndarray, up: bool) -> tuple[int, int]:
    """Bins on a saw-tooth's return (module docstring, step 5): from the profile's extreme at the end of the
    sweep (its maximum for an up-sweep), the consecutive in-band bins that keep moving back (down for an
    up-sweep) and lie strictly inside the swept span (more than ``RETURN_MARGIN`` of it from either end).
    0 for an instantaneous flyback (the frames around it see one side or the other; at most one bin, the one
    where the two sides are mixed in equal numbers, can fall in between); >= ``MIN_RETURN_BINS``: a swept
    return (a hook's flyback, or an asymmetric triangle's short side). Returns (those bins, the steps the return
    takes: 1 for an instantaneous flyback). Compiled, O(bins)."""
    K = prof.size
    sgn = 1.0 if up else -1.0
    n_ok = 0
    lo, hi = np.inf, -np.inf
    j, best = -1, -np.inf
    for k in range(K):
        if inband[k] and np.isfinite(prof[k]):
            n_ok += 1
            lo = min(lo, prof[k])
            hi = max(hi, prof[k])
            if sgn * prof[k] > best:
                best, j = sgn * prof[k], k
    if n_ok < 4 or not hi - lo > 0:
        return 0, 0
    m = RETURN_MARGIN * (hi - lo)
    n = steps = 0
    prev = prof[j]
    for i in range(1, K):
        k = (j + i) % K
        if not (inband[k] and np.isfinite(prof[k])):
            break
        v = prof[k]
        if sgn * (v - prev) >= 0:          # moving with the sweep again: the return is over
            break
        steps += 1
        if lo + m < v < hi - m:
            n += 1
        prev = v
    return n, steps


def _shape(prof: np.ndarray, inband: np.ndarray, hook_ratio: float, se: np.ndarray | None = None
           ) -> tuple[int, float, float, float, float, float]:
    """(shape, low, high, start, rate per phase bin, direction p) of a folded profile (module docstring, step 5).

    se: standard error of each bin's median (``_profile``); a swept step counts for the shape only when it
    exceeds ``STEP_SIGMA`` times the standard error of the difference of the two medians it joins (None: every
    swept step counts). direction p: the sign-test probability (``_sign_tail``) of the saw-tooth's main
    direction among the counted steps (NaN for a triangle or an unknown shape). Compiled (``_shape_kernel``)."""
    has_se = se is not None
    out = _shape_kernel(np.ascontiguousarray(prof, dtype=np.float64), np.ascontiguousarray(inband, dtype=np.bool_),
                        float(hook_ratio), np.ascontiguousarray(se if has_se else prof, dtype=np.float64), has_se)
    return int(out[0]), float(out[1]), float(out[2]), float(out[3]), float(out[4]), float(out[5])


@njit(cache=True)
def _median_sorted(v: np.ndarray) -> float:
    s = np.sort(v)
    h = s.size // 2
    return float(s[h]) if s.size % 2 else (s[h - 1] + s[h]) / 2.0


@njit(cache=True)
def _shape_kernel(prof: np.ndarray, inband: np.ndarray, hook_ratio: float, se: np.ndarray, has_se: bool
                  ) -> tuple[int, float, float, float, float, float]:
    """_shape, compiled."""
    K = prof.size
    nan = np.nan
    n_in = 0
    low, high = np.inf, -np.inf
    for k in range(K):
        if inband[k]:
            n_in += 1
            low = min(low, prof[k])
            high = max(high, prof[k])
    if n_in < 4:
        return SHAPE_UNKNOWN, nan, nan, nan, nan, nan
    span = high - low
    d = np.full(K, np.nan)
    jump = np.zeros(K, np.bool_)
    counted = np.zeros(K, np.bool_)
    n_c = n_up = n_dn = n_jump = 0
    for k in range(K):
        nx = (k + 1) % K
        if inband[k] and inband[nx]:
            d[k] = prof[nx] - prof[k]
            if abs(d[k]) > JUMP_SPAN * span:
                jump[k] = True
                n_jump += 1
            elif not has_se or abs(d[k]) > STEP_SIGMA * math.sqrt(se[k] * se[k] + se[nx] * se[nx]):
                counted[k] = True
                n_c += 1
                if d[k] > 0:
                    n_up += 1
                elif d[k] < 0:
                    n_dn += 1
    if n_c < 3 or not span > 0:
        return SHAPE_UNKNOWN, low, high, nan, nan, nan
    ups = np.empty(n_up)
    dns = np.empty(n_dn)
    iu = idn = 0
    for k in range(K):
        if counted[k]:
            if d[k] > 0:
                ups[iu] = d[k]
                iu += 1
            elif d[k] < 0:
                dns[idn] = d[k]
                idn += 1
    frac_up = n_up / max(n_up + n_dn, 1)
    med_up = _median_sorted(ups) if n_up else 0.0
    med_dn = _median_sorted(dns) if n_dn else 0.0
    up = frac_up > 0.5
    n_mid, n_ret = _return_bins(prof, inband, up)
    if TRIANGLE_SIDE <= frac_up <= 1 - TRIANGLE_SIDE or n_ret >= TRIANGLE_SIDE * K:
        # up and down alike (by counted steps, or by the time the way back takes): a triangle when each way has
        # at least two counted steps
        if min(n_up, n_dn) >= 2:
            return TRIANGLE, low, high, low, med_up, nan
        return SHAPE_UNKNOWN, low, high, nan, nan, nan
    med = med_up if up else med_dn
    p_dir = _sign_tail(max(n_up, n_dn), n_up + n_dn)
    start = low if up else high
    # hooked: a swept return (MIN_RETURN_BINS bins inside the span on the way back), or an overshoot that
    # relaxes back faster than the sweep over at least two counted steps after the flyback
    hooked = n_mid >= MIN_RETURN_BINS
    if not hooked:
        for j in range(K):
            if jump[j]:
                a, b = (j + 1) % K, (j + 2) % K
                if (counted[a] and counted[b] and np.sign(d[a]) == np.sign(med) and np.sign(d[b]) == np.sign(med)
                        and min(abs(d[a]), abs(d[b])) > hook_ratio * abs(med)):
                    hooked = True
                    break
    if hooked:
        return HOOKED_SAWTOOTH, low, high, start, med, p_dir
    if 0.15 < min(frac_up, 1 - frac_up) or (p_dir > SAW_P and (min(n_up, n_dn) > 0 or not n_jump > 0)):
        # steps going back but not as a return (scatter: a weak ridge), or a direction seen too few times with
        # no flyback between two in-band bins (a triangle's side seen in pieces looks the same): not a shape
        # that the profile shows
        return SHAPE_UNKNOWN, low, high, nan, med, nan
    return (SAWTOOTH_UP if up else SAWTOOTH_DOWN), low, high, start, med, p_dir


def _sawtooth_law(prof: np.ndarray, inband: np.ndarray, period_samples: float, L: int, span: float
                  ) -> tuple[float, np.ndarray, float] | None:
    """(flyback phase, polynomial in the elapsed sweep fraction, RMS residual of the fit) of a saw-tooth's
    folded profile, or None.

    The flyback is the largest step between consecutive in-band bins. Bins within half a frame (plus one
    bin) of it are left out: their frames straddle the flyback. A quadratic (a rate that changes along the
    sweep; linear with fewer than 8 bins) is fitted to the others against the elapsed fraction of the
    sweep since the flyback; None when fewer than 4 bins remain or the fit leaves an RMS residual above a
    tenth of the span. Compiled (``_sawtooth_law_kernel``: np.polyfit's scaled least squares)."""
    ok, phi_j, coef, rms = _sawtooth_law_kernel(np.ascontiguousarray(prof, dtype=np.float64),
                                                np.ascontiguousarray(inband, dtype=np.bool_), float(period_samples),
                                                int(L), float(span))
    return (phi_j, coef, rms) if ok else None


@njit(cache=True)
def _polyval(coef: np.ndarray, x: float) -> float:
    """np.polyval of one point (Horner, highest power first)."""
    y = 0.0
    for c in coef:
        y = y * x + c
    return y


@njit(cache=True)
def _polyfit(x: np.ndarray, y: np.ndarray, deg: int) -> np.ndarray:
    """np.polyfit(x, y, deg): the Vandermonde columns scaled to unit norm, least squares (LAPACK gelsd, rcond
    n eps), the scale taken back out. Highest power first."""
    n = x.size
    order = deg + 1
    A = np.empty((n, order))
    for i in range(n):
        v = 1.0
        A[i, order - 1] = 1.0
        for j in range(order - 2, -1, -1):
            v = v * x[i]
            A[i, j] = v
    scale = np.zeros(order)
    for i in range(n):
        for j in range(order):
            scale[j] += A[i, j] * A[i, j]
    for j in range(order):
        scale[j] = math.sqrt(scale[j])
    for i in range(n):
        for j in range(order):
            A[i, j] /= scale[j]
    c = np.linalg.lstsq(A, y.copy(), n * 2.220446049250313e-16)[0]
    return c / scale


@njit(cache=True)
def _sawtooth_law_kernel(prof: np.ndarray, inband: np.ndarray, period_samples: float, L: int, span: float
                         ) -> tuple[bool, float, np.ndarray, float]:
    """_sawtooth_law, compiled: (found, flyback phase, coefficients, RMS)."""
    K = prof.size
    none = (False, np.nan, np.zeros(3), np.nan)
    j, best, any_both = 0, -np.inf, False
    for k in range(K):
        nx = (k + 1) % K
        v = -1.0
        if inband[k] and inband[nx] and np.isfinite(prof[k]) and np.isfinite(prof[nx]):
            any_both = True
            v = abs(prof[nx] - prof[k])
        if v > best:
            best, j = v, k
    if not any_both or not span > 0:
        return none
    if best < span / 3.0:
        return none
    phi_j = (j + 1) / K
    guard = 0.5 * L / period_samples + 1.0 / K
    ee = np.empty(K)
    pp = np.empty(K)
    m = 0
    for k in range(K):
        c = (k + 0.5) / K
        e = (c - phi_j) % 1.0                # Python's float % is np.mod: into [0, 1)
        if inband[k] and np.isfinite(prof[k]) and e > guard and e < 1.0 - guard:
            ee[m] = e
            pp[m] = prof[k]
            m += 1
    if m < 4:
        return none
    deg = 2 if m >= 8 else 1
    coef = _polyfit(ee[:m], pp[:m], deg)
    r2 = np.empty(m)
    for i in range(m):
        r = pp[i] - _polyval(coef, ee[i])
        r2[i] = r * r
    rms = math.sqrt(_pairwise_sum_f64(r2) / m * m / max(m - deg - 1, 1))
    if rms > 0.1 * span:
        return none
    return True, phi_j, coef, rms


FOLD_HOPS = 8
"""folded_shape: the frame's hop is at most the period over this (the profile then has >= FOLD_HOPS phases)."""
FOLD_FALSE = 1e-3
"""folded_shape: chance that noise alone makes any of the folded profile's phase bins present."""


@njit(cache=True)
def _fold_kernel(S: np.ndarray, kb: np.ndarray, K: int, freqs: np.ndarray, thr: float, cplx: bool
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """_fold_shape's folded profile, compiled: per phase bin (of K) the frequency bin whose mean of S over the phase
    bin's frames exceeds its mean over all frames the most (the strongest component at that phase, as the ridge
    takes the strongest bin), present when that excess stands z > thr standard errors (the bin's standard
    deviation over all frames / sqrt(n)); its frequency (parabola on the excesses) and standard error (one bin / z).
    Returns (profile, standard errors, present, fewest frames in a phase bin)."""
    nfr, B = S.shape
    M = np.zeros((K, B))
    cnt = np.zeros(K)
    m1 = np.zeros(B)
    m2 = np.zeros(B)
    for t in range(nfr):
        k = kb[t]
        cnt[k] += 1.0
        for b in range(B):
            v = float(S[t, b])
            M[k, b] += v
            m1[b] += v
            m2[b] += v * v
    var = np.empty(B)
    for b in range(B):
        m1[b] /= nfr
        var[b] = max(m2[b] / nfr - m1[b] * m1[b], 1e-30)
    prof = np.full(K, np.nan)
    se = np.full(K, np.inf)
    present = np.zeros(K, np.bool_)
    binw = freqs[1] - freqs[0]
    nmin = nfr
    b_lo, b_hi = (1, B - 1) if cplx else (0, B)   # complex: the +-0.5 edge bins may be either side
    for k in range(K):
        n = cnt[k]
        nmin = min(nmin, int(n))
        if n < 1:
            continue
        for b in range(B):
            M[k, b] /= n
        best, kb_ = -np.inf, -1
        for b in range(b_lo, b_hi):
            if M[k, b] - m1[b] > best:
                best, kb_ = M[k, b] - m1[b], b
        if kb_ < 0:
            continue
        z = best / math.sqrt(var[kb_] / n)
        if not z > thr:
            continue
        present[k] = True
        d = 0.0
        if 0 < kb_ < B - 1:
            a = M[k, kb_ - 1] - m1[kb_ - 1]
            c = M[k, kb_ + 1] - m1[kb_ + 1]
            den = a - 2.0 * best + c
            if den < 0:
                d = min(max(0.5 * (a - c) / den, -0.5), 0.5)
        prof[k] = freqs[kb_] + d * binw
        se[k] = binw / max(z, 1.0)
    return prof, se, present, nmin


def folded_shape(x: np.ndarray, cplx: bool, period_samples: float, par: RidgeParams
                 ) -> tuple[int, float, float, float]:
    """Sweep shape of a periodic jammer of known period too weak for the per-frame ridge (for a chirp found by the
    evidence over blocks, whose comb gives the period): (shape, in-band fraction, low, high), frequencies in
    cycles/sample; SHAPE_UNKNOWN and NaN when the block does not show it.

    The short-time spectrum (frames of the longest L with hop <= period / ``FOLD_HOPS``) is averaged per phase of
    the period (``SHAPE_BINS`` phase bins, or one per hop when the period is nearly a whole number of hops):
    synchronous averaging over the block's periods, n frames per phase bin, raises a sweep that is below the
    per-frame presence threshold by sqrt(n). Per phase bin the strongest frequency bin (the largest phase mean
    minus the bin's mean over all frames) must stand z standard errors high (the bin's standard deviation over
    frames / sqrt(n); no noise level is needed) with z above the Gaussian quantile of
    1 - ``FOLD_FALSE`` / (phase bins x bins) to be present; its frequency is interpolated (parabola on those
    excesses), its standard error taken as one bin / z (the position error of a peak
    about a bin wide that stands z standard errors high). The shape rule is ``_shape``'s (module docstring,
    step 5). Cost: one STFT of the block and one compiled pass over it (0.25-0.4 ms for 1 ms at 38.192 MS/s
    here)."""
    nan = math.nan
    x = np.asarray(x)
    T = float(period_samples)
    L = 0
    for cand in par.frame_lengths:
        if cand // 2 <= T / FOLD_HOPS:
            L = cand
    if L == 0 or not math.isfinite(T) or x.size < 8 * L or x.size < 4 * T:
        return SHAPE_UNKNOWN, nan, nan, nan
    S, freqs = stft_power(x, L, cplx)
    return _fold_shape(S, freqs, T / (L // 2), L, cplx, par.hook_rate_ratio)


def _fold_shape(S: np.ndarray, freqs: np.ndarray, per_fr: float, L: int, cplx: bool, hook_ratio: float
                ) -> tuple[int, float, float, float]:
    """folded_shape on a computed |STFT|^2 S (frames, bins) of frame length L and a period of per_fr frames."""
    nan = math.nan
    nfr, B = S.shape
    K = SHAPE_BINS
    if abs(per_fr - round(per_fr)) * (nfr / per_fr) < 1.0:      # whole number of hops: only round(per_fr) phases
        K = max(4, min(K, int(round(per_fr))))
    kb = np.minimum((np.mod(np.arange(nfr) / per_fr, 1.0) * K).astype(np.int64), K - 1)
    thr = float(-ndtri(FOLD_FALSE / (K * B)))
    prof, se, present, nmin = _fold_kernel(np.ascontiguousarray(S), kb, K, np.asarray(freqs, dtype=np.float64), thr,
                                           bool(cplx))
    if nmin < 4:
        return SHAPE_UNKNOWN, nan, nan, nan
    shape, low, high, _start, _step, _p = _shape(prof, present, hook_ratio, se)
    if shape != SHAPE_UNKNOWN or per_fr < FOLD_HOPS:
        return shape, float(np.mean(present)), low, high
    # too few phase bins stand out on their own: the whole sweep law, integrated along it (_line_shape); only with
    # frames short against the period (>= FOLD_HOPS hops per period, as folded_shape chooses them): a frame that spans
    # much of the period smears a saw-tooth into a shape a triangle's line fits as well (measured: a saw-tooth down
    # at 4 MS/s in 64-sample frames, 3 hops per period, read as a triangle)
    Z = _fold_zmap(np.ascontiguousarray(S), kb, K)
    b_lo, b_hi = (1, B - 1) if cplx else (0, B)
    code, lo_b, hi_b = _line_shape(Z[:, b_lo:b_hi])
    if code == SHAPE_UNKNOWN:
        return shape, float(np.mean(present)), low, high
    binw = float(freqs[1] - freqs[0])
    return code, nan, float(freqs[b_lo]) + lo_b * binw, float(freqs[b_lo]) + hi_b * binw


LINE_MIN_BINS = 2
"""_line_shape: a sweep law spans at least this many frequency bins of the folded map."""
LINE_MAX_BINS = 17
"""_line_shape: a folded map wider than this is searched with pairs of frequency bins merged (until it is not): the
search costs O(bins^2 phase bins^2): 16 phase bins take about 0.2 ms at 9 bins, 1 ms at 17, 16 ms at 65; merged to 9,
the demo's J/S +6 dB chirp (a 4-bin sweep at 17 bins) was found in 1 of 10 blocks instead of 10 of 10)."""
LINE_MARGIN_Z = 2.0
"""_line_shape: the best law's class (saw-tooth up, down, triangle) must beat the best law of every other class by
this many standard deviations of the line sum (a saw-tooth and a triangle with a short side share most of their
line; below this the data do not choose between them: unknown)."""
LINE_FALSE = 1e-3
"""_line_shape: chance that noise alone gives any candidate law a line sum over the threshold (Bonferroni over the
candidates)."""


@njit(cache=True)
def _fold_zmap(S: np.ndarray, kb: np.ndarray, K: int) -> np.ndarray:
    """Per phase bin (of K) and frequency bin, the excess of the phase bin's mean of S over the bin's mean over all
    frames, in standard errors (the bin's standard deviation over frames / sqrt(frames in the phase bin)): the map
    _fold_kernel takes its per-phase maxima from, whole. Shape (K, bins)."""
    nfr, B = S.shape
    M = np.zeros((K, B))
    cnt = np.zeros(K)
    m1 = np.zeros(B)
    m2 = np.zeros(B)
    for t in range(nfr):
        k = kb[t]
        cnt[k] += 1.0
        for b in range(B):
            v = float(S[t, b])
            M[k, b] += v
            m1[b] += v
            m2[b] += v * v
    Z = np.zeros((K, B))
    for b in range(B):
        mean = m1[b] / nfr
        var = max(m2[b] / nfr - mean * mean, 1e-30)
        for k in range(K):
            if cnt[k] > 0:
                Z[k, b] = (M[k, b] / cnt[k] - mean) / math.sqrt(var / cnt[k])
    return Z


@njit(cache=True, inline="always")
def _z_at(Z: np.ndarray, k: int, f: float) -> float:
    """Z[k] linearly interpolated at the fractional bin f (inside the map)."""
    b = int(math.floor(f))
    a = f - b
    if b >= Z.shape[1] - 1:
        return Z[k, Z.shape[1] - 1]
    return (1.0 - a) * Z[k, b] + a * Z[k, b + 1]


def _line_shape(Z: np.ndarray) -> tuple[int, float, float]:
    """(shape, lowest, highest frequency bin) of the sweep law whose line through the folded map Z (phase bins x
    frequency bins, in standard errors) has the largest sum, or SHAPE_UNKNOWN (ours).

    Candidate laws, each a line through every phase bin k at the frequency it gives at the bin's centre: a saw-tooth
    up (down) from bin lo to bin hi (hi to lo) starting at phase bin k0 with an instantaneous flyback, and a triangle
    rising from lo to hi over u phase bins and falling back over K - u (both sides at least ``TRIANGLE_SIDE`` of the
    period), for every lo < hi at least ``LINE_MIN_BINS`` apart and every k0 (``_line_scores``). The score is the
    sum of Z along the line / sqrt(K) (standard normal under noise: the phase bins hold disjoint frames; a value
    interpolated between two bins has at most unit variance); the best must exceed the Gaussian quantile of
    1 - ``LINE_FALSE`` / candidates (Bonferroni) and beat the best law of every other class by ``LINE_MARGIN_Z``. A
    sweep too weak for any phase bin alone (``_fold_kernel``'s threshold) is found from all of them: the line sum of
    K phase bins standing z each is sqrt(K) z. A hook is not a candidate (a hooked saw-tooth reads as its saw-tooth).
    Maps wider than ``LINE_MAX_BINS`` frequency bins are searched with neighbouring bins merged."""
    Z = np.asarray(Z, dtype=np.float64)
    merge = 1
    while Z.shape[1] > LINE_MAX_BINS:
        # pairs of frequency bins summed (/ sqrt 2: still unit variance under noise): the search is O(B^2 K^2)
        m = Z.shape[1] // 2
        Z = (Z[:, 0:2 * m:2] + Z[:, 1:2 * m:2]) / math.sqrt(2.0)
        merge *= 2
    best, arg, n_cand = _line_scores(np.ascontiguousarray(Z))
    if n_cand == 0:
        return SHAPE_UNKNOWN, math.nan, math.nan
    thr = float(-ndtri(LINE_FALSE / n_cand))
    c = int(np.argmax(best))
    other = max(float(best[i]) for i in range(3) if i != c)
    if not (best[c] > thr and best[c] - other >= LINE_MARGIN_Z):
        return SHAPE_UNKNOWN, math.nan, math.nan
    code = SAWTOOTH_UP if c == 0 else (SAWTOOTH_DOWN if c == 1 else TRIANGLE)
    centre = 0.5 * (merge - 1)       # a merged bin's centre in the original bins
    return code, float(arg[c, 0]) * merge + centre, float(arg[c, 1]) * merge + centre


@njit(cache=True)
def _line_scores(Z: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """_line_shape's search, compiled: the best score of each class (saw-tooth up, down, triangle), its (lo, hi), and
    the number of candidates."""
    K, B = Z.shape
    best = np.full(3, -np.inf)
    arg = np.zeros((3, 2))
    n_cand = 0
    rk = 1.0 / math.sqrt(K)
    u_min = max(2, int(math.ceil(TRIANGLE_SIDE * K)))
    u_max = K - u_min
    for lo in range(B):
        for hi in range(lo + LINE_MIN_BINS, B):
            span = float(hi - lo)
            for k0 in range(K):
                up = 0.0
                dn = 0.0
                for j in range(K):
                    k = (k0 + j) % K
                    x = (j + 0.5) / K
                    up += _z_at(Z, k, lo + span * x)
                    dn += _z_at(Z, k, hi - span * x)
                n_cand += 2
                if up * rk > best[0]:
                    best[0] = up * rk
                    arg[0, 0], arg[0, 1] = lo, hi
                if dn * rk > best[1]:
                    best[1] = dn * rk
                    arg[1, 0], arg[1, 1] = lo, hi
                for u in range(u_min, u_max + 1):
                    tri = 0.0
                    for j in range(K):
                        k = (k0 + j) % K
                        if j < u:
                            f = lo + span * (j + 0.5) / u
                        else:
                            f = hi - span * (j - u + 0.5) / (K - u)
                        tri += _z_at(Z, k, f)
                    n_cand += 1
                    if tri * rk > best[2]:
                        best[2] = tri * rk
                        arg[2, 0], arg[2, 1] = lo, hi
    return best, arg, n_cand


# ----- sample-resolution sweep profile: synchronous average of lag products (ours) -----

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


def joined_span(f: np.ndarray, present: np.ndarray, max_step: float) -> float:
    """The 5-95 % span of the ridge frequencies of the frames joined to a present neighbour by a step of at most
    max_step (analyse, a sweep without a period; 0 when fewer than 8 such frames): the span the track itself covers.
    A tone held in one bin with a few isolated frames elsewhere (front-end spurs, noise) spans nothing; a sweep's
    frames are all joined. (The span of all present frames made such blocks of real captures look like sweeps.)"""
    pair = present[1:] & present[:-1] & (np.abs(np.diff(f)) <= max_step)
    joined = np.zeros(f.size, dtype=bool)
    joined[1:] |= pair
    joined[:-1] |= pair
    fj = f[joined]
    return float(np.percentile(fj, 95) - np.percentile(fj, 5)) if fj.size >= 8 else 0.0


def analyse(x: np.ndarray, cplx: bool, fs: float, par: RidgeParams, frame_length: int = 0,
            fine_hook: bool = True) -> RidgeResult:
    """Ridge analysis of one block (module docstring).

    Args:
        x: finite samples, shape (n,), float64 (real) or complex128, n >= 8 * min(frame_lengths).
        cplx: complex samples.
        fs: sample rate, Hz (> 0; converts max_period_s to frames).
        par: RidgeParams.
        frame_length: 0: choose it (step 1); else use this one.
        fine_hook: run the sample-resolution hook test (``fine_profile``, 0.3-1.4 ms per block) on a saw-tooth; the
            monitor skips it on the blocks of a tracked saw-tooth whose hook it tested recently (``hook_checked``).

    Returns:
        RidgeResult.
    """
    L = int(frame_length) if frame_length else choose_frame_length(x, cplx, par)
    hop = L // 2
    hook_checked = False
    S, freqs = stft_power(x, L, cplx)
    lvl = noise_levels(S, par.noise_smooth_bins, cplx)
    noise = _noise_power(lvl, L, cplx, par.noise_smooth_bins)
    nfr, B = S.shape
    # the ridge's strongest bins and the sums of the spectral phasor (its periodicity below) in one pass
    ang = 2.0 * np.pi * np.arange(B) / B
    div = _f32(lvl)
    if not cplx and B > 3:
        # a real IF's DC and Nyquist bins: outside any front end's pass band, one degree of freedom (heavier
        # tails), and where a quantiser's offset and fs/2 products sit: no ridge there (the front-end spurs there
        # made noise blocks of the 2-bit 12 MS/s capture look like sweeps)
        div[0] = div[-1] = np.float32(np.inf)
    kmax, pk32, uc, us = _excess_kernel(S, div, np.cos(ang).astype(np.float32),
                                        np.sin(ang).astype(np.float32))
    f, pk, present = _ridge(S, kmax, pk32, freqs, par.presence_nats)
    h = float(np.sum(1.0 / np.arange(1, B + 1)))
    peak_excess = float(np.mean(pk)) - h
    pres_frac = float(np.mean(present))
    u = uc + 1j * us
    lmax = int(min(par.max_period_s * fs / hop, nfr // 4))
    per_fr, strength = _periodicity(u.astype(np.complex128), int(par.min_period_frames), lmax, par)
    periodic = math.isfinite(per_fr)
    binw = 1.0 / L
    nan = math.nan
    shape, inb, low, high, start, rate = SHAPE_UNKNOWN, nan, nan, nan, nan, nan
    fstd = nan
    prof_k: np.ndarray | None = None
    inband_k: np.ndarray | None = None
    sweeping = False
    shape_fold = SHAPE_UNKNOWN
    if periodic:
        # a period that is not a whole number of frames spreads the frames over all phases, so the profile
        # can be finer than a frame; where it is (nearly) whole, only per_fr phases are seen
        K = int(par.phase_bins)
        # complex input: the spectrum is circular, a ridge in the first or last bin (-0.5 and 0.5 - 1/L cycles/
        # sample, not interpolated) is a tone near the +-0.5 edge on either side; such frames count as present
        # but their frequency does not enter the medians (a sweep through an edge would otherwise mix -0.5 and
        # +0.5 in one phase bin's median)
        fuse = present & (kmax > 0) & (kmax < B - 1) if cplx else present
        prof, share, se = _profile(f, present, per_fr, K, fuse, binw)
        if np.mean(np.isnan(prof) & (share == 0)) > 0.25:
            K = int(max(4, math.floor(per_fr)))
            prof, share, se = _profile(f, present, per_fr, K, fuse, binw)
        top = float(np.max(share))
        inband = (share >= 0.5 * top) & np.isfinite(prof) & (top > 0)
        inb = float(np.mean(inband))
        prof_k, inband_k = prof, inband
        # the shape from a coarser profile (at most SHAPE_BINS bins: steps well above the ridge's scatter)
        Ks = min(K, SHAPE_BINS)
        prof_s, share_s, se_s = (prof, share, se) if Ks == K else _profile(f, present, per_fr, Ks, fuse, binw)
        inband_s = (share_s >= 0.5 * float(np.max(share_s))) & np.isfinite(prof_s) & (top > 0)
        inb = float(np.mean(inband_s))
        if inb < 0.6 and Ks < K:
            # in band only part of the period: the finer profile has more bins in each in-band run
            Ks, prof_s, inband_s, se_s = K, prof, inband, se
        shape, low, high, start, step, p_dir = _shape(prof_s, inband_s, par.hook_rate_ratio, se_s)
        if shape in (SAWTOOTH_UP, SAWTOOTH_DOWN) and K > Ks and \
                _return_bins(prof, inband, shape == SAWTOOTH_UP)[0] >= MIN_RETURN_BINS:
            shape = HOOKED_SAWTOOTH          # a return too short for the coarse profile, seen in the finer one
        if shape in (SAWTOOTH_UP, SAWTOOTH_DOWN) and fine_hook:
            # a return shorter than two profile bins and a frame: the sample-resolution profile of lag products
            # (fine_profile) sees it, or sees the flyback instantaneous
            hook_checked = True
            fp = fine_profile(x, cplx, per_fr * hop, noise_lag_product(lvl, freqs, noise, cplx), noise)
            n_back = fine_return(fp, shape == SAWTOOTH_UP)[0] if fp is not None else 0
            if fp is not None and n_back >= TRIANGLE_SIDE * fp.frequency.size:
                # a way back lasting a triangle's side (the coarse profile saw the sweep in pieces): _shape's rule
                shape = TRIANGLE
            elif n_back >= FINE_MIN_RETURN:
                shape = HOOKED_SAWTOOTH
        if shape == SHAPE_UNKNOWN:
            # the per-frame ridge's profile shows no shape (a weak sweep, or one seen in pieces): the spectrum
            # itself folded on the period (folded_shape's synchronous average, O(frames x bins)) may; only the
            # label is taken from it (no sweep law is fitted to a profile that showed no shape)
            shape_fold = _fold_shape(S, freqs, per_fr, L, cplx, par.hook_rate_ratio)[0]
        if math.isfinite(step):
            rate = step / (per_fr * hop / Ks)
        # a sweep: the ridge moves over >= 4 bins, or over >= 2 with a direction no chance gives (a saw-tooth
        # narrower than 4 bins of a short frame, e.g. 2.5 MHz at 12 MS/s with 16-sample frames)
        span_bins = (high - low) / binw if math.isfinite(high - low) else 0.0
        sweeping = bool(span_bins >= 4 or (span_bins >= 2 and p_dir <= SAW_P))
        if present.any():
            rms_fold, nsel, q_lo, q_hi = _fold_residuals(f, present, inband, prof, float(per_fr), 0.02, 0.98)
            if math.isfinite(rms_fold):
                fstd = rms_fold
            if nsel >= 20 and math.isfinite(low):
                # the profile averages over a phase bin and the frame: the swept band's edges come from the
                # ridge itself (2 % and 98 % points of the in-band ridge frequencies)
                low, high = q_lo, q_hi
                if shape in (SAWTOOTH_UP, TRIANGLE):
                    start = low
                elif shape == SAWTOOTH_DOWN:
                    start = high
    elif pres_frac >= par.min_present_fraction and nfr >= 8:
        fp = f[present]
        dd = np.abs(np.diff(f))[present[1:] & present[:-1]]
        coherent = dd.size > 0 and float(np.mean(dd <= 2 * binw)) >= 0.8
        span = joined_span(f, present, 2 * binw)
        if coherent and span >= 4 * binw:
            sweeping = True
            low, high = float(np.percentile(fp, 5)), float(np.percentile(fp, 95))
            tt = np.flatnonzero(present)
            slope = float(np.polyfit(tt, fp, 1)[0]) if tt.size >= 3 else nan
            rate = slope / hop
            shape = SAWTOOTH_UP if slope > 0 else SAWTOOTH_DOWN
            start = low if slope > 0 else high
            inb = 1.0
    if not math.isfinite(fstd) and nfr >= 3:
        # local straight line through three consecutive present frames
        ok = present[:-2] & present[1:-1] & present[2:]
        r2 = (f[1:-1] - 0.5 * (f[:-2] + f[2:]))[ok]
        if r2.size:
            fstd = float(np.sqrt(np.mean(r2 * r2) / 1.5))
    fstd = max(fstd, binw / math.sqrt(12.0)) if math.isfinite(fstd) else binw / math.sqrt(12.0)
    # frequency at the block's last sample: frame t's ridge is the frequency near its centre,
    # t hop + L / 2 - 1/2; a periodic sweep is read off its folded profile at the last sample's phase
    # (the last frame's centre is up to hop + L / 2 samples before the end), else the last ridge
    # moved on by the rate
    t_end = (x.size - 1 - (L - 1) / 2.0) / hop          # the last sample, in frame units
    freq = nan
    law = None
    if periodic and prof_k is not None and inband_k is not None and shape in (SAWTOOTH_UP, SAWTOOTH_DOWN,
                                                                              HOOKED_SAWTOOTH):
        law = _sawtooth_law(prof_k, inband_k, per_fr * hop, L, high - low)
    if law is not None and inband_k is not None:
        # saw-tooth: the sweep law fitted away from the flyback (where frames straddle it) gives the
        # swept band's ends, the mean rate and the frequency at the block end
        phi_j, coef, rms = law
        # the block-end error measured on the paper front end (12 blocks, J/N 21 dB) had an RMS of about
        # twice the profile-fit residual (the flyback phase is quantised to a bin, frames smear)
        fstd = max(2.0 * rms, 1e-4 / L)
        f0, f1 = _polyval(coef, 0.0), _polyval(coef, 1.0)
        low, high = min(f0, f1), max(f0, f1)
        start = f0
        rate = (f1 - f0) / (per_fr * hop)
        ph_end = float(np.mod(t_end / per_fr, 1.0))
        e_end = (ph_end - phi_j) % 1.0
        if inband_k[min(int(ph_end * inband_k.size), inband_k.size - 1)]:
            freq = _polyval(coef, e_end)
    elif periodic and prof_k is not None and inband_k is not None:
        K = prof_k.size
        pos = np.mod(t_end / per_fr, 1.0) * K - 0.5
        k0 = int(math.floor(pos)) % K
        k1 = (k0 + 1) % K
        a = pos - math.floor(pos)
        if inband_k[k0] and inband_k[k1] and abs(prof_k[k1] - prof_k[k0]) < 0.5 * (high - low):
            freq = float((1 - a) * prof_k[k0] + a * prof_k[k1])
        elif inband_k[k0 if a < 0.5 else k1]:
            freq = float(prof_k[k0 if a < 0.5 else k1])
    elif present[-1]:
        freq = float(f[-1]) + (float(rate) * (t_end - (nfr - 1)) * hop if math.isfinite(rate) else 0.0)
    if math.isfinite(freq) and not (float(freqs[0]) - 0.5 / L <= freq <= float(freqs[-1]) + 0.5 / L):
        freq = nan
    if shape == SHAPE_UNKNOWN:
        shape = shape_fold
    return RidgeResult(L, hop, noise, peak_excess, pres_frac, periodic, float(per_fr * hop) if periodic else nan,
                       float(strength), sweeping, int(shape), inb, low, high, start, rate, freq, fstd, hook_checked)
