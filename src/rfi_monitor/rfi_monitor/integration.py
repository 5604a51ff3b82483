"""Evidence integrated over blocks: weak stationary jammers that no single block shows (issue 14 item 5).

Pure module (no ROS). ``RfiMonitor`` (the "stft" estimator) feeds every analysed block to an
``Integrator`` and asks it for a decision when the block alone reports NONE. The integrator keeps,
summed over the blocks of the last ``window_s`` seconds (stamps, not the wall clock), two statistics
that do not depend on where a block starts, so that blocks need not be contiguous (the demo's 1 ms
snapshots once a second are integrated as well as a continuous stream):

* **CW**: a tone of at least ``min_cw_jn_db`` over the whole band's noise (front-end spurs, -11 to -20 dB
  in the real clean captures, are significant but no jammer), significant in the Welch PSD (the
  classifier's Welch PSD of the block at ``nfft``, all frames) summed over blocks. Under
  Gaussian noise each bin of the sum over ``K`` independent Hann frames is ``N_b chi2(2K) / 2K``
  (real input: the DC and Nyquist bins ``chi2(K) / K``). The reference ``N_b`` is the summed PSD's
  own running median over ``smooth_bins`` bins (a tone never enters it). A bin is a tone when
  ``P_b / N_b`` exceeds the ``1 - alpha / B`` quantile of ``Gamma(K, 1/K)`` (Bonferroni over the
  ``B`` bins: a false alarm per block of at most ``alpha``; the median's own scatter, ~1.25 /
  sqrt(K smooth_bins), taken at 4 sigma, multiplies the threshold).
* **CHIRP** (any periodic sweep): the 2-D autocorrelation over frames of the short-time spectrum,
  ``r(l) = sum_t sum_b E(t, b) E(t + l, b)`` with ``E = |X| / mean_t |X| - 1`` per bin (amplitudes: lighter
  tails than powers) (zero mean per bin
  and block: a CW and the front end's shape drop out), minus each frame's mean over the bins (a change of the
  block's power within it, as an AGC settling after a gain step, moves every bin of a frame alike; measured: a
  2-bit front end whose AGC settled from +10 dB in its first block was reported CHIRP for 8 blocks), summed
  over blocks, together with its variance
  under noise ``(T - l) sum_d sum_bb' C_d(b, b')^2`` (``C_d``: the block's covariance between bin b and bin b' d
  frames later, d = -1, 0, 1, every bin pair, measured, so the window's leakage between bins, the overlap of
  neighbouring frames and a jammer's own variance are accounted for) and its mean under noise removed (E has zero
  mean over the block, so each product has the mean ``-sum_b (C_0 + 2 C_1)(b, b) / T``). A periodic sweep puts
  the same spectrum at every multiple of its period, so the statistic is the comb
  ``Z(p) = sum_k r(k p) / sqrt(sum_k var r(k p))`` (``k = 1..K_p``, up to ``max_multiples``, lags
  rounded to frames; candidate periods on a grid of ``0.5 / K_p`` frames: the folding of the spectrogram
  at the period, written with the autocorrelation so that blocks add without knowing their sweep phase).
  Under noise ``Z`` is standard normal per candidate (lags >= 2 frames: Hann frames at hop L/2 do not
  overlap); the threshold is ``Phi^-1(1 - alpha / M)`` for ``M`` candidates (Bonferroni).
  A sweep periodic in T is periodic in 2 T, 3 T, ... as well: before the best candidate's period is published, its
  sub-multiples are tested on the same sums (``resolve_submultiple``), and a period that cannot be told from a
  multiple of a shorter one is published NaN.

Sub-windows. Noise blocks in the sum dilute a jammer that has just switched on: the comb's numerator grows with
the jammed blocks only, its noise with all blocks. After 600 clean 1 ms blocks a chirp at J/N -8 dB on the 2-bit
captures was not found within 80 blocks of switch-on from the whole window (3-5 blocks with the sub-windows below).
So the statistics are also
summed over the newest ``window_s / 4**k`` seconds, ``k = 1..sub_windows`` (running sums of their own, no extra
analysis per block), and each distinct sum (sub-windows holding the same blocks as a longer one are not tested
again: 1 ms snapshots once a second test one sum) is tested at ``alpha / m`` for ``m`` distinct sums (Bonferroni:
the false alarm per block stays at most ``alpha``). The reported decision is the one of the sum that detects with
the largest margin over its threshold (CHIRP before CW), else the whole window's.

The frame length of the chirp statistic is fixed per stream (``frame_length_s`` of the sample rate,
a power of two in 8..128): the sweep must move by less than about one bin per frame (a sweep of k
cycles/sample^2 moves k L^2 bins per frame: 0.7 at the paper's 1e12 Hz/s, 38.192 MS/s, L = 32).

The window restarts on a change of sample rate, IF or real/complex (``reset``), when the monitor's
single-block analysis stops seeing a jammer it saw in the block before (``restart``: a jammer switched
off is not reported on for window_s), and drops blocks older than ``window_s`` (a stamp that goes
backwards restarts it). A jammer too weak for any single block that switches off is still reported
until its evidence leaves the window (at most ``window_s``), unless a shorter sum shows that a periodic sweep is
gone (``SWITCH_OFF_SIGMA``: the window then restarts; counted as ``Integrator.switch_offs``). The decision says how
many blocks and
seconds it rests on (``IntegratedDecision``).

Example
-------
>>> import numpy as np
>>> integ = Integrator(IntegrationParams())
>>> x = np.random.default_rng(0).standard_normal(38192)
>>> d = integ.add(x, False, 38.192e6, stamp_ns=0)
>>> d.type   # noise: NONE
0
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy import fft as sp_fft
from scipy import special
from scipy.ndimage import median_filter

from rfi_monitor import ridge as rg
from rfi_monitor.classifier import frame_power, welch_psd

NONE, CW, CHIRP = 0, 1, 2
"""Types, identical to classifier.NONE / CW / CHIRP (rfi_msgs/JammerState)."""


@dataclass(frozen=True)
class IntegrationParams:
    """Parameters of the integration over blocks (module docstring).

    Attributes:
        window_s: evidence of the blocks stamped within the last window_s seconds is summed, s (0: off).
        false_alarm_per_block: alpha, the false-alarm probability of each statistic per block under
            Gaussian noise (Bonferroni over bins / candidate periods), (0, 0.1].
        frame_length_s: frame of the chirp statistic, s of samples (rounded to a power of two, 8..128).
        max_period_s: longest sweep period searched, s.
        max_multiples: most multiples of a candidate period summed (sets the grid: 0.5 / K frames).
        nfft: frame length of the CW statistic (the classifier's Welch frames), samples.
        smooth_bins: width of the running median that is the CW statistic's noise reference, odd >= 5.
        decide_interval_s: the statistics are tested at most once per this many seconds of stamps (speed: the
            test costs about as much as adding a block) unless the window's frames grew by 10 % since the last
            test (a young window is tested at every block); blocks in between get the last decision, s (0: every
            block). The first block of a window is always tested.
        min_chirp_strength: a periodic sweep is reported only when this share of the amplitudes' variance repeats at
            its period (``IntegratedDecision.chirp_strength``), [0, 1). Without the comb's bias under noise (see
            ``spectral_autocorrelation``), a sum over hundreds of blocks finds the faint periodic modulations of a
            real front end: the clean 4 MS/s PocketSDR capture has one at 58 samples, strength 0.0008-0.0019,
            significant after 280 1 ms blocks. Chirps at J/N -5 dB (the issue's goal) measured 0.017-0.03 in their
            weakest decisions and 0.10-0.15 typically on four front ends; 0.005 is a third of the weakest.
        sub_windows: the statistics are also tested on the newest window_s / 4**k seconds, k = 1..sub_windows
            (module docstring; 0: the whole window only), 0..4.
        max_samples_per_s: processing budget of the integration, samples per second of stamps (0: no limit). A
            block is added only while the budget allows (a token bucket filled at this rate along the stamps,
            holding at most ``BUDGET_HOLD_S`` of it or one block); the others get the last decision and are counted
            (``Integrator.thinned``). The integration costs about 15 ns per sample on a 2020s server core, more than
            the rest of a quiet block's analysis: at 38.192 MS/s it alone would take about half of a core, so the
            default integrates every block up to 16.5 MS/s and 43 % of them at 38.192 MS/s, where the frames are
            still more than at 16 MS/s (the detection over the window is that of a 16.5 MS/s stream). Deterministic:
            it depends on the stamps only, never on the machine.
    """

    window_s: float = 1.0
    false_alarm_per_block: float = 1e-4
    frame_length_s: float = 1e-6
    max_period_s: float = 100e-6
    max_multiples: int = 128
    nfft: int = 1024
    smooth_bins: int = 31
    decide_interval_s: float = 0.01
    min_chirp_strength: float = 0.005
    sub_windows: int = 3
    max_samples_per_s: float = 16.5e6

    def __post_init__(self) -> None:
        if not (math.isfinite(self.window_s) and self.window_s >= 0):
            raise ValueError("window_s must be finite and >= 0")
        if not (0 < self.false_alarm_per_block <= 0.1):
            raise ValueError("false_alarm_per_block must be in (0, 0.1]")
        if not (math.isfinite(self.frame_length_s) and self.frame_length_s > 0):
            raise ValueError("frame_length_s must be > 0")
        if not (math.isfinite(self.max_period_s) and self.max_period_s > 0):
            raise ValueError("max_period_s must be > 0")
        if self.max_multiples < 2:
            raise ValueError("max_multiples must be >= 2")
        if self.nfft < 64 or self.nfft & (self.nfft - 1):
            raise ValueError("nfft must be a power of two >= 64")
        if self.smooth_bins < 5 or self.smooth_bins % 2 == 0:
            raise ValueError("smooth_bins must be odd and >= 5")
        if not (math.isfinite(self.decide_interval_s) and self.decide_interval_s >= 0):
            raise ValueError("decide_interval_s must be finite and >= 0")
        if not (math.isfinite(self.min_chirp_strength) and 0 <= self.min_chirp_strength < 1):
            raise ValueError("min_chirp_strength must be in [0, 1)")
        if not 0 <= int(self.sub_windows) <= 4 or int(self.sub_windows) != self.sub_windows:
            raise ValueError("sub_windows must be an integer in 0..4")
        if not (math.isfinite(self.max_samples_per_s) and self.max_samples_per_s >= 0):
            raise ValueError("max_samples_per_s must be finite and >= 0")


@dataclass(frozen=True)
class IntegratedDecision:
    """Decision from the evidence of the window.

    Attributes:
        type: NONE, CW or CHIRP.
        blocks: blocks summed; window_s: stamp span they cover (first to last block start + its length), s.
        cw_score: largest normalised PSD bin over its threshold (> 1: a tone); cw_frequency: its bin centre,
            cycles/sample (fftshift order for complex input, -0.5..0.5; real 0..0.5).
        chirp_z: largest comb statistic, standard deviations; chirp_threshold: its threshold;
            period_samples: the sweep period, samples: the best candidate's, or its sub-multiple that the same sums
                show to be the period (``resolve_submultiple``); NaN unless CHIRP, and for a CHIRP whose period is
                ambiguous (a sub-multiple the test cannot tell from noise).
        excess_db: the strongest bin's tone power (5 bins' excess over the reference) over the noise of the whole
            band, dB (-inf: none).
        chirp_strength: the share of the amplitudes' variance that repeats at the comb's best period, the comb's
            sum over its multiples over the same sum for a perfectly periodic E (0 under noise; NaN: not tested).
    """

    type: int
    blocks: int
    window_s: float
    cw_score: float
    cw_frequency: float
    chirp_z: float
    chirp_threshold: float
    period_samples: float
    excess_db: float
    chirp_strength: float = math.nan


BUDGET_HOLD_S = 0.01
"""The processing budget (``IntegrationParams.max_samples_per_s``) left unused is kept for at most this many seconds of
stamps (or one block): a pause in the stream does not let a burst of blocks through later."""
MIN_CHIRP_FRAMES = 512
"""The chirp statistic decides once the window holds this many frames: a sum of products of few frames has heavier
tails than the normal law its threshold assumes (measured on Gaussian noise: 1024-sample blocks of 12 MS/s real IF,
127 frames each, exceeded the alpha = 1e-4 threshold in 1 of 3,000 single blocks)."""
COARSE_MULTIPLES = 16
"""Multiples summed by the coarse comb that selects the candidates of the fine one."""
FINE_CANDIDATES = 12
"""Best coarse candidates refined with ``max_multiples`` multiples."""
SWITCH_OFF_SIGMA = 5.0
"""A periodic sweep found over a window is gone when a shorter sum (a sub-window) at its period reads this many standard
deviations below what the sweep, at the strength the window measured, would give it (``Integrator.switch_offs``)."""
SWITCH_OFF_MIN_EXPECTED = 8.0
"""... and that shorter sum would show the sweep at no less than this many standard deviations (else it cannot tell)."""
FINE_HALF_WIDTH = 1.5
"""Half-width of the fine search around a coarse candidate, in units of 1 / K_p frames (K_p: the coarse multiples):
the coarse comb is flat over up to two of its steps (0.5 / K_p), and the true period may lie at either end."""
SUBMULTIPLES = (2, 3)
"""Sub-multiples P / m of a chirp decision's period P tested before it is published (:func:`resolve_submultiple`)."""
SUBMULTIPLE_Z = 4.0
"""A sub-multiple p / m is the period when the comb over its lags that are not lags of p reads at least this many
standard deviations (``resolve_submultiple``). Where p is the period those lags fall between its multiples, where a
sweep's amplitudes are anti-correlated (in a bin at one lag, elsewhere at the other): measured over 11,854 tests
(5,927 correct decisions: the demo's chirp, saw-tooths, triangles and hooked saw-tooths at 4 MS/s I/Q and 16.368 MS/s
real, J/N -12 to 0 dB, 1 ms blocks) median -2 to -90 and at most 2.9."""
SUBMULTIPLE_ABSENT_Z = 0.0
"""... and p is the period when that comb reads below this. Where p / m is the period those lags carry the sweep as
p's own multiples do: measured 1.6 to 11.6 in the 32 decisions (of the same runs) that had picked 2 p or 3 p."""
SUBMULTIPLE_MARGIN = 3.0
"""Where p / m, were it the period, would show on those lags at ``Z_pred`` (predicted from p's strength): it is the
period from ``Z_pred / 2`` (the midpoint between the two outcomes) on, and p is kept below ``Z_pred / 2`` minus this
many standard deviations (p's strength is that of the largest comb of the search, so ``Z_pred`` errs high by up to
about this: measured 1.6 against a predicted 6.8 in a decision that had picked 2 p)."""
SUBMULTIPLE_MIN_EXPECTED = 4.0
"""The test decides only when p / m, were it the period, would show on those lags at no less than this many standard
deviations as predicted from p's strength (else neither outcome could be told from noise): below, and between
``SUBMULTIPLE_ABSENT_Z`` and ``SUBMULTIPLE_Z``, the period is ambiguous and published NaN."""


@njit(cache=True, nogil=True)
def _comb_z(r: np.ndarray, v: np.ndarray, idx: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Comb statistic Z(p) per candidate row (module docstring): sum of r over the row's lags over the square root of
    the sum of their variances; -inf where the variance is zero. Compiled (one pass over the candidates' lags)."""
    M, K = idx.shape
    out = np.empty(M)
    for i in range(M):
        num = 0.0
        den = 0.0
        for k in range(K):
            if mask[i, k]:
                num += r[idx[i, k]]
                den += v[idx[i, k]]
        out[i] = num / math.sqrt(den) if den > 0 else -math.inf
    return out


@njit(cache=True, nogil=True)
def _comb_z_direct(r: np.ndarray, v: np.ndarray, P: np.ndarray, Kp: np.ndarray, lag_limit: int) -> np.ndarray:
    """:func:`_comb_z` of the candidates P (frames) without their lag and mask arrays (issue 26 item 2: the fine
    comb's 128 multiples of a few hundred candidates): lag rint(P k), k = 1..Kp (Kp from the caller, as
    ``Integrator._comb_lags`` clips it), kept while <= lag_limit; the same sums in the same order."""
    M = P.size
    out = np.empty(M)
    for i in range(M):
        num = 0.0
        den = 0.0
        for k in range(1, Kp[i] + 1):
            lag = np.int64(np.rint(P[i] * float(k)))
            if lag <= lag_limit:
                num += r[lag]
                den += v[lag]
        out[i] = num / math.sqrt(den) if den > 0 else -math.inf
    return out


@njit(cache=True, nogil=True)
def _separated(order: np.ndarray, periods: np.ndarray, count: int) -> np.ndarray:
    """The first ``count`` indices of ``order`` whose periods lie more than 0.5 frames from every one taken before
    (the fine comb's candidates, best first)."""
    top = np.empty(count, dtype=np.int64)
    n = 0
    for i in order:
        ok = True
        for j in range(n):
            if not abs(periods[i] - periods[top[j]]) > 0.5:
                ok = False
                break
        if ok:
            top[n] = i
            n += 1
            if n == count:
                break
    return top[:n]


def _multiples(p: float, lag_limit: int, kmax: int) -> tuple[np.ndarray, np.ndarray]:
    """(k, lags) of the comb of a period of p frames (as ``Integrator._comb_lags``): k = 1..K_p with
    K_p = clip(lag_limit // p, 2, kmax), lag = rint(k p), kept while lag <= lag_limit."""
    kp = int(min(max(lag_limit // p, 2), kmax))
    ks = np.arange(1, kp + 1)
    lags = np.rint(p * ks).astype(np.int64)
    keep = lags <= lag_limit
    return ks[keep], lags[keep]


def comb_strength(r: np.ndarray, lags: np.ndarray, spread: float, spread_frames: float) -> float:
    """Share of the amplitudes' variance that repeats at ``lags`` (``IntegratedDecision.chirp_strength``): the sum of r
    over them over the same sum for a perfectly periodic E, whose r(l) is ``spread_frames - spread l`` (the variance
    per frame summed over the frames that have a partner l frames later); NaN when that is not positive."""
    scale = lags.size * spread_frames - spread * float(lags.sum())
    return float(r[lags].sum()) / scale if scale > 0 else math.nan


def resolve_submultiple(r: np.ndarray, v: np.ndarray, spread: float, spread_frames: float, p: float, lmin: float,
                        lag_limit: int, kmax: int) -> tuple[float, int, float]:
    """The sweep period a comb that detected a periodic sweep at p frames stands for: p, a sub-multiple p / m, or NaN.

    A frequency law periodic in T (Kang et al., eq. 4-5: ``f_n = f_0 + Delta f (n - T)`` from n = T on) is periodic in
    every multiple m T as well, so the comb ``Z(p)`` (module docstring) is large at T, 2 T, 3 T, ...; the search takes
    the largest Z, which is T's in expectation, but a noisy coarse comb can leave T out of the fine search (measured:
    the demo's +6 dB chirp, J/N -14 dB in one 1 ms snapshot, 5.10 us published as 10.2 us in 3 of its 20 blocks; 15
    of 200 such snapshots simulated). So, for m in ``SUBMULTIPLES`` (repeatedly, so that 4 T and 6 T come down to T),
    the lags of p / m that are not lags of p (the multiples k p / m, k not divisible by m) are tested with the same
    evidence: r summed over them over the square root of the sum of its variances under noise, ``Z_x``, a comb of
    its own (none of its lags entered the detection, so it is not biased by the search). Were p / m the period, those
    lags repeat the sweep as p's do (``Z_x`` about the detection's own significance); were p the period, they fall
    between its multiples, where the amplitudes of a sweep are anti-correlated (``Z_x`` mostly negative). p's strength
    s (:func:`comb_strength`) predicts what p / m would give: ``Z_pred = s * sum_l (spread_frames - spread l) /
    sqrt(sum_l var r(l))``. Rule: p / m when ``Z_x >= max(SUBMULTIPLE_Z, Z_pred / 2)``; p when
    ``Z_x < max(SUBMULTIPLE_ABSENT_Z, Z_pred / 2 - SUBMULTIPLE_MARGIN)``; otherwise, or when ``Z_pred <
    SUBMULTIPLE_MIN_EXPECTED`` (p / m could not show), the period is ambiguous: NaN. A
    multiple of the true period is then never published as valid. Sub-multiples below ``lmin`` frames (shorter than
    any period searched) are not tested. Ours: the paper estimates the period from successive LPD peaks (Sec. 3.2,
    eq. 23-27), where a missed peak doubles an interval in the same way (``sweep_period``: q = 2 intervals).
    Measured on single 1 ms blocks, 200 per case (the demo's chirp at +6 dB J/S; saw-tooths up and down, triangles,
    a hooked saw-tooth at 4 MS/s I/Q and 16.368 MS/s real, J/N -14 to -8 dB): multiples of the period published in
    30 of 2,852 chirp decisions before, none after; NaN in 32 (at most 7 of the 95 decisions of a case, all at J/N
    -10 and -12 dB, where a decision barely reaches its threshold), none from J/N -8 dB (4 MS/s) and -10 dB (16 MS/s).

    Args:
        r, v: the window's summed autocorrelation over frames and its variance under noise, lags 0..lag_limit.
        spread, spread_frames: the window's sums of E's variance per frame (``_Sums``).
        p: the detected period, frames (fractional).
        lmin: shortest period searched, frames.
        lag_limit: longest lag summed, frames; kmax: most multiples of a comb.

    Returns:
        (period in frames or NaN, m: p over the returned period (1: p kept), its strength).
    """
    m_total = 1
    _, lags = _multiples(p, lag_limit, kmax)
    strength = comb_strength(r, lags, spread, spread_frames)
    changed = True
    while changed:
        changed = False
        for m in SUBMULTIPLES:
            q = p / m
            if q < lmin:
                continue
            ks, lags_q = _multiples(q, lag_limit, kmax)
            extra = lags_q[ks % m != 0]
            var = float(v[extra].sum()) if extra.size else 0.0
            if not (var > 0 and math.isfinite(strength) and strength > 0):
                continue
            scale = extra.size * spread_frames - spread * float(extra.sum())
            expected = strength * scale / math.sqrt(var)
            z_extra = float(r[extra].sum()) / math.sqrt(var)
            if z_extra >= max(SUBMULTIPLE_Z, 0.5 * expected):
                p, m_total, changed = q, m_total * m, True
                strength = comb_strength(r, lags_q, spread, spread_frames)
                break
            if expected < SUBMULTIPLE_MIN_EXPECTED or z_extra >= max(SUBMULTIPLE_ABSENT_Z,
                                                                     0.5 * expected - SUBMULTIPLE_MARGIN):
                return math.nan, m_total, strength
    return p, m_total, strength


class _Sums:
    """Running sums of the statistics over the newest ``count`` blocks of the window (one per window length)."""

    __slots__ = ("psd", "r", "v", "k", "frames", "count", "copies", "copy_frames", "spread", "spread_frames")

    def __init__(self) -> None:
        self.psd: np.ndarray | None = None
        self.r: np.ndarray | None = None
        self.v: np.ndarray | None = None
        self.k = 0
        self.frames = 0
        self.count = 0
        self.copies = 0.0        # independent bin sequences summed (skew of the comb: _comb_skew)
        self.copy_frames = 0.0   # the same, each weighted by its frames
        self.spread = 0.0        # sum over blocks of trace(C_0): E's variance per frame, summed over bins
        self.spread_frames = 0.0  # the same, each weighted by its frames

    def add(self, b: _BlockStats) -> None:
        if self.psd is None or self.r is None or self.v is None:
            self.psd, self.r, self.v = b.psd_sum.copy(), b.r.copy(), b.var.copy()
        else:
            self.psd += b.psd_sum
            self.r += b.r
            self.v += b.var
        self.k += b.psd_frames
        self.frames += b.frames
        self.count += 1
        self.copies += b.copies
        self.copy_frames += b.copies * b.frames
        self.spread += b.spread
        self.spread_frames += b.spread * b.frames

    def remove(self, b: _BlockStats) -> None:
        assert self.psd is not None and self.r is not None and self.v is not None
        self.psd -= b.psd_sum
        self.r -= b.r
        self.v -= b.var
        self.k -= b.psd_frames
        self.frames -= b.frames
        self.count -= 1
        self.copies -= b.copies
        self.copy_frames -= b.copies * b.frames
        self.spread -= b.spread
        self.spread_frames -= b.spread * b.frames


class _BlockStats:
    __slots__ = ("stamp_ns", "n", "psd_sum", "psd_frames", "power", "r", "var", "frames", "copies", "spread")

    def __init__(self, stamp_ns: int, n: int, psd_sum: np.ndarray, psd_frames: int, power: float,
                 r: np.ndarray, var: np.ndarray, frames: int, copies: float, spread: float) -> None:
        self.stamp_ns, self.n = stamp_ns, n
        self.psd_sum, self.psd_frames, self.power = psd_sum, psd_frames, power
        self.r, self.var, self.frames, self.copies, self.spread = r, var, frames, copies, spread


def frame_length(fs: float, par: IntegrationParams) -> int:
    """Frame length of the chirp statistic at sample rate fs (module docstring)."""
    L = 2 ** int(round(math.log2(max(fs * par.frame_length_s, 1.0))))
    return int(min(max(L, 8), 128))


def spectral_autocorrelation(x: np.ndarray, cplx: bool, L: int, max_lag: int
                              ) -> tuple[np.ndarray, np.ndarray, int, float, float]:
    """(r, var, T, copies, spread): the 2-D autocorrelation r(l), l = 0..max_lag, of E = |X| / mean_t |X| - 1 and its
    variance under noise (module docstring), T frames of L samples at hop L / 2, the number of independent bin
    sequences it sums and E's variance per frame summed over the bins (:func:`_noise_moments`)."""
    S, _ = rg.stft_power(x, L, cplx)
    T = S.shape[0]
    # amplitudes (lighter tails than powers: Rayleigh, not exponential, at little loss), normalised per bin, laid
    # out (bins, frames) so that the FFTs run along contiguous rows, and the bin covariances, in one compiled pass
    Et = _normalised_amplitudes(np.ascontiguousarray(S), bool(not cplx and S.shape[1] > 3))
    q, g, copies, spread = _noise_moments(Et)
    nf = sp_fft.next_fast_len(T + max_lag + 1, real=True)     # no circular wrap up to max_lag
    F = sp_fft.rfft(Et, nf, axis=1)
    R = sp_fft.irfft(frame_power(F), nf)[: max_lag + 1]     # sum over bins of |F|^2 (the classifier's pass)
    lags = np.arange(max_lag + 1)
    n_prod = np.maximum(T - lags, 0)
    # E has zero mean over the block's frames in every bin, so under noise each product E(t) E(t + l) has the mean
    # -g / T (g: the bins' long-run variance, lags -1..1), not 0; removed here, as the comb sums many lags (measured
    # before: -0.1 standard deviations per lag at 4 MS/s I/Q, a bias of -0.9 over 83 multiples)
    R = R + n_prod * (g / T)
    var = n_prod * q
    return R, var, T, copies, spread


_REASSOC = {"reassoc", "contract"}
"""numba fastmath flags of the reductions below: sums may be reassociated (vectorised); no assumption about NaN or
infinities (the inputs are finite)."""


def _noise_moments(Et: np.ndarray) -> tuple[float, float, float, float]:
    """(q, g, copies, spread) of E (bins, frames), for the comb statistic under noise.

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
    The two bins x bins covariance matrices are compiled (:func:`_bin_covariances`).
    """
    c0, c1 = _bin_covariances(Et)
    q = float(np.sum(c0 * c0))
    g = float(np.trace(c0))
    copies = g * g / q if q > 0 else 0.0
    spread = g
    if Et.shape[1] > 1:
        q += 2.0 * float(np.sum(c1 * c1))
        g += 2.0 * float(np.trace(c1))
    return q, g, copies, spread


@njit(cache=True, nogil=True, fastmath=_REASSOC)
def _bin_covariances(Et: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(C_0, C_1) of E (bins, frames): C_d[b, b'] = mean over t of E(t, b) E(t + d, b'). Compiled rather than two matrix
    products: numpy hands those to a multi-threaded BLAS, which for these small matrices doubled the integration's CPU
    time (the second core spinning) at the same wall time; this loop is single-threaded and faster (0.06 against
    0.09 ms wall, 0.19 ms CPU, for 15 bins x 2,386 frames)."""
    nb, nfr = Et.shape
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


def _comb_skew(p: float, K: int, copies: float, copy_frames: float) -> float:
    """Skewness of the comb statistic Z(p) under noise (K multiples of p frames), summed over ``copies`` independent bin
    sequences of ``copy_frames / copies`` frames on average (Gaussian amplitudes assumed).

    Z is a quadratic form, per bin sequence ``Q = sum_t sum_k E(t) E(t + l_k)`` (l_k = k p), not a sum of independent
    terms: its cumulants are ``kappa_2 = sum_k (T - l_k)`` and ``kappa_3 = 6 sum_(a, b) (T - l_a - l_b)`` over the
    ordered pairs of multiples whose lags add up to another one (a + b <= K: the comb's triangles), so the skewness
    ``kappa_3 / kappa_2^1.5`` grows as sqrt(K / T) and falls as 1 / sqrt(copies). A sum over few frames is markedly
    skewed: measured on Gaussian noise with the normal threshold alone, one-block sums exceeded the alpha = 1e-4
    threshold in 1.3-3.5 of 1,000 blocks at 4-38 MS/s (a 16.368 MS/s block: skewness about 0.2, the threshold 1 sigma
    higher). Closed forms of the sums for l_k = k p:
    ``kappa_2 = K A - C p K (K + 1) / 2``, ``kappa_3 = 6 (A K (K - 1) / 2 - C p (K - 1) K (K + 1) / 3)``,
    A = copy_frames, C = copies (copy_frames sums each copy's frames).
    """
    if K < 2 or copies <= 0:
        return 0.0
    k2 = K * copy_frames - copies * p * K * (K + 1) / 2.0
    k3 = 6.0 * (copy_frames * K * (K - 1) / 2.0 - copies * p * (K - 1) * K * (K + 1) / 3.0)
    if not k2 > 0 or not k3 > 0:
        return 0.0
    return k3 / k2 ** 1.5



@njit(cache=True, nogil=True, fastmath=_REASSOC)
def _normalised_amplitudes(S: np.ndarray, drop_edges: bool) -> np.ndarray:
    """E transposed, of spectral_autocorrelation. S float32 (frames, bins) = |X|^2. E = sqrt(S) / mean_t - 1 per
    bin, minus each frame's mean over the bins, float32, shape (bins, frames), without the DC and Nyquist bins of a
    real signal (drop_edges: one degree of freedom)."""
    nfr, B = S.shape
    b0 = 1 if drop_edges else 0
    nb = B - 2 * b0
    Et = np.empty((nb, nfr), dtype=np.float32)
    for b in range(nb):
        acc = 0.0
        for t in range(nfr):
            a = np.sqrt(S[t, b0 + b])
            Et[b, t] = a
            acc += a
        m = np.float32(max(acc / nfr, 1e-300))
        for t in range(nfr):
            Et[b, t] = Et[b, t] / m - np.float32(1.0)
    # minus each frame's mean over the bins: a change of the whole block's power within it (an AGC settling, a
    # gain step, a broadband pulse) raises every bin of a frame alike and would correlate all lags; a sweep puts
    # its excess in one bin per frame, which the mean over the bins hardly moves
    if nb > 1:
        for t in range(nfr):
            acc = 0.0
            for b in range(nb):
                acc += float(Et[b, t])
            mf = np.float32(acc / nb)
            for b in range(nb):
                Et[b, t] -= mf
    return Et


class Integrator:
    """Sums block evidence over a time window and decides (module docstring).

    Args:
        params: IntegrationParams.
        min_cw_jn_db: a significant tone is a CW only from this J/N, dB (the classifier's ``detect_jn_db``: the
            spurs of real front ends, -11 to -20 dB in the clean captures, are significant in a 1 s sum but
            are no jammer).
    """

    def __init__(self, params: IntegrationParams = IntegrationParams(), min_cw_jn_db: float = -6.0) -> None:
        self.params = params
        self.min_cw_jn_db = float(min_cw_jn_db)
        self._blocks: deque[_BlockStats] = deque()
        self._key: tuple[float, bool] | None = None
        self._grids: dict[tuple[int, int, int, int], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._cw_thr: dict[tuple[int, int, bool, float], np.ndarray] = {}
        self._med: dict[int, float] = {}
        self._chirp_thr: dict[tuple[int, int, int, int, float], float] = {}
        self.thinned = 0
        """Blocks not added because of the processing budget (``IntegrationParams.max_samples_per_s``), since
        construction."""
        self.switch_offs = 0
        """Windows restarted because a sweep found over them is gone from the newest blocks (SWITCH_OFF_SIGMA), since
        construction."""
        self.submultiples = 0
        """Chirp decisions whose comb's best period was a multiple of the one published (``resolve_submultiple``), since
        construction."""
        self.ambiguous_periods = 0
        """Chirp decisions published without a period: a sub-multiple the test could not tell from noise
        (``resolve_submultiple``), since construction."""
        self._tokens = math.inf
        self._token_stamp: int | None = None
        self._clear()

    @property
    def enabled(self) -> bool:
        return self.params.window_s > 0

    def reset(self) -> None:
        """Forget the window (a change of sample rate, IF or kind)."""
        self._clear()
        self._key = None

    def restart(self) -> None:
        """Drop the evidence gathered so far (the stream stays the same): the monitor calls it when a jammer that
        one block showed is gone from a block, so that its evidence does not outlive it."""
        self._clear()

    def _clear(self) -> None:
        self._last: IntegratedDecision | None = None
        self._last_stamp = 0
        self._last_frames = 0
        self._blocks.clear()
        # the whole window's sums, then those of the sub-windows, longest first
        self._sums = [_Sums() for _ in range(1 + int(self.params.sub_windows))]
        self._last_sums = self._sums[0]

    def _push(self, b: _BlockStats) -> None:
        for sums in self._sums:
            sums.add(b)
        self._blocks.append(b)

    def _trim(self, stamp_ns: int) -> None:
        """Drop from each sum the blocks stamped at or before its window's start (each keeps its newest block);
        the sub-windows first (they hold the newest blocks of the deque), then the whole window."""
        window_ns = self.params.window_s * 1e9
        for k in range(len(self._sums) - 1, -1, -1):
            sums = self._sums[k]
            horizon = int(stamp_ns) - int(round(window_ns / 4 ** k))
            n = len(self._blocks)
            while sums.count > 1 and self._blocks[n - sums.count].stamp_ns <= horizon:
                sums.remove(self._blocks[n - sums.count])
        while len(self._blocks) > self._sums[0].count:
            self._blocks.popleft()

    def _comb_grid(self, lmin: int, lmax: int, lag_limit: int, kmax: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(periods (M,), lags (M, kmax), mask (M, kmax)): candidate periods from lmin to lmax frames on a grid of
        0.5 / K_p frames, K_p = min(kmax, lag_limit // p) multiples (cached)."""
        key = (lmin, lmax, lag_limit, kmax)
        hit = self._grids.get(key)
        if hit is not None:
            return hit
        periods: list[float] = []
        p = float(lmin)
        while p <= lmax:
            periods.append(p)
            p += 0.5 / max(2, min(kmax, int(lag_limit // p)))
        P = np.asarray(periods)
        out = self._comb_lags(P, lag_limit, kmax)
        self._grids[key] = out
        return out

    @staticmethod
    def _comb_lags(P: np.ndarray, lag_limit: int, kmax: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        ks = np.arange(1, kmax + 1)
        Kp = np.clip((lag_limit // P).astype(np.int64), 2, kmax)
        idx = np.rint(P[:, None] * ks[None, :]).astype(np.int64)
        mask = (ks[None, :] <= Kp[:, None]) & (idx <= lag_limit)
        return P, np.where(mask, idx, 0), mask

    @staticmethod
    def _fine_count(lmin: int, lmax: int, lag_limit: int, kmax: int) -> float:
        """Candidates of the fine grid (0.5 / K_p frames, K_p up to kmax) over lmin..lmax: the Bonferroni count."""
        p = np.linspace(lmin, lmax, 20001)
        K = np.clip(lag_limit // p, 2, kmax)
        return float(np.trapezoid(2.0 * K, p)) + 1.0

    def skipped(self, samples: int, stamp_ns: int) -> None:
        """Samples of the stream that were never seen before the block stamped stamp_ns (blocks a node shed because
        it was behind its stream, a lost message; the monitor calls it for a short gap, ``monitor.FRAME_KEEP_GAP_S``):
        charged to the processing budget as if they had been integrated, so that a monitor behind its stream spends
        its time answering blocks rather than integrating more of the few it sees (the budget is a share of the
        stream, not of the blocks seen). The debt is bounded by the budget's holding (``BUDGET_HOLD_S``)."""
        par = self.params
        if not (self.enabled and par.max_samples_per_s > 0 and samples > 0):
            return
        hold = par.max_samples_per_s * BUDGET_HOLD_S
        self._tokens = max(self._bucket(0, stamp_ns) - float(samples), -hold)
        self._token_stamp = int(stamp_ns)

    def _bucket(self, n: int, stamp_ns: int) -> float:
        """Tokens of the processing budget at stamp_ns before a block of n samples is taken (module docstring)."""
        par = self.params
        cap = max(par.max_samples_per_s * BUDGET_HOLD_S, float(n))
        if self._token_stamp is None or stamp_ns < self._token_stamp:
            return cap
        return min(cap, self._tokens + par.max_samples_per_s * (stamp_ns - self._token_stamp) * 1e-9)

    def add(self, x: np.ndarray, cplx: bool, fs: float, stamp_ns: int) -> IntegratedDecision:
        """Add one block (finite samples, float64 or complex128) and decide on the window.

        Args:
            x: samples, shape (n,).
            cplx: complex samples.
            fs: sample rate, Hz.
            stamp_ns: time of the block's first sample, ns.

        Returns:
            IntegratedDecision.
        """
        par = self.params
        key = (float(fs), bool(cplx))
        if key != self._key:
            self.reset()
            self._key = key
        if self._blocks and stamp_ns < self._blocks[-1].stamp_ns:
            self._clear()
        if par.max_samples_per_s > 0:
            # the processing budget: a token bucket filled along the stamps (deterministic, never the wall clock)
            self._tokens = self._bucket(x.size, stamp_ns)
            self._token_stamp = int(stamp_ns)
            if self._tokens < x.size and self._last is not None and self._blocks:
                self.thinned += 1
                return dataclasses.replace(self._last, blocks=self._last_sums.count)
            self._tokens -= x.size
        L = frame_length(fs, par)
        hop = L // 2
        lmin = 4
        T_blk = (x.size - L) // hop + 1
        lag_limit = int(0.75 * T_blk)
        lmax = min(int(par.max_period_s * fs / hop), lag_limit // 4)
        nfft = min(par.nfft, 1 << int(math.floor(math.log2(max(x.size, 64)))))
        psd, frames = welch_psd(x, nfft, 1 << 30)
        power = float(psd.sum())
        r, var, T, copies, spread = spectral_autocorrelation(x, cplx, L, lag_limit)
        if self._blocks and (self._blocks[-1].psd_sum.size != psd.size or self._blocks[-1].r.size != r.size):
            self._clear()
        self._push(_BlockStats(int(stamp_ns), x.size, psd * frames, frames, power, r, var, T, copies, spread))
        self._trim(int(stamp_ns))
        n_frames = self._sums[0].frames
        if (self._last is not None and len(self._blocks) > 1 and n_frames < 1.1 * self._last_frames
                and int(stamp_ns) - self._last_stamp < int(round(par.decide_interval_s * 1e9))):
            return dataclasses.replace(self._last, blocks=self._last_sums.count)
        self._last = self._decide_all(cplx, fs, lmin, lmax, lag_limit)
        if self._last.type == CHIRP and self._switched_off(self._last, lag_limit, fs):
            # a sweep found only over the blocks gone by: the window restarts with this block (without this, a weak
            # jammer that switched off was reported until its evidence left the window, up to window_s)
            self.switch_offs += 1
            newest = self._blocks[-1]
            self._clear()
            self._push(newest)
            self._last = self._decide_all(cplx, fs, lmin, lmax, lag_limit)
            n_frames = self._sums[0].frames
        self._last_stamp = int(stamp_ns)
        self._last_frames = n_frames
        return self._last

    def _switched_off(self, d: IntegratedDecision, lag_limit: int, fs: float) -> bool:
        """Whether the sweep of decision d (CHIRP, from the sum self._last_sums) is gone from a shorter sum: at d's
        period, the shorter sum's comb reads SWITCH_OFF_SIGMA below what d's strength predicts for it, where that
        prediction is at least SWITCH_OFF_MIN_EXPECTED (the comb over K multiples of the strength's reference)."""
        if not (math.isfinite(d.chirp_strength) and d.chirp_strength > 0 and math.isfinite(d.period_samples)):
            return False
        p = d.period_samples / (frame_length(fs, self.params) // 2)
        _, idx, mask = self._comb_lags(np.asarray([p]), lag_limit, int(self.params.max_multiples))
        lags = idx[0][mask[0]]
        if lags.size == 0:
            return False
        for sums in self._sums:
            if sums.count >= self._last_sums.count or sums.frames < MIN_CHIRP_FRAMES:
                continue
            assert sums.r is not None and sums.v is not None
            var = float(sums.v[lags].sum())
            if not var > 0:
                continue
            scale = lags.size * sums.spread_frames - sums.spread * float(lags.sum())
            expected = d.chirp_strength * scale / math.sqrt(var)
            z = float(sums.r[lags].sum()) / math.sqrt(var)
            if expected >= SWITCH_OFF_MIN_EXPECTED and z < min(expected - SWITCH_OFF_SIGMA, 0.5 * expected):
                return True
        return False

    def _median_ratio(self, K: int) -> float:
        """Median over mean of Gamma(K, 1/K) (cached)."""
        v = self._med.get(int(K))
        if v is None:
            v = float(special.gammaincinv(float(K), 0.5)) / float(K)   # scipy.stats.gamma.median, without its overhead
            if len(self._med) > 256:
                self._med.clear()
            self._med[int(K)] = v
        return v

    def _cw_threshold(self, K: int, B: int, cplx: bool, alpha: float) -> np.ndarray:
        """Per-bin threshold of P_b / N_b (module docstring) at false-alarm probability alpha, cached per
        (K, B, kind, alpha)."""
        key = (int(K), int(B), bool(cplx), float(alpha))
        thr = self._cw_thr.get(key)
        if thr is None:
            # the upper alpha / B quantile of Gamma(dof, 1 / dof): dof K, and K / 2 at DC and Nyquist of a real IF
            # (scipy.special directly: scipy.stats.gamma.isf gives the same numbers at ~0.3 ms a call, per decision)
            q = alpha / B
            thr_g = np.full(B, float(special.gammainccinv(float(K), q)) / float(K))
            if not cplx:
                thr_g[0] = thr_g[-1] = float(special.gammainccinv(0.5 * K, q)) / (0.5 * K)
            # the reference's own scatter (a median of smooth_bins bins of the same chi-square: 1.2533 / sqrt(K w)
            # relative, 1 sigma), taken at 4 sigma as a relative error of the reference
            rel_ref = 1.2533 / math.sqrt(K * self.params.smooth_bins)
            thr = thr_g * (1.0 + 4.0 * rel_ref)
            if len(self._cw_thr) > 64:
                self._cw_thr.clear()
            self._cw_thr[key] = thr
        return thr

    def _decide_all(self, cplx: bool, fs: float, lmin: int, lmax: int, lag_limit: int) -> IntegratedDecision:
        """Test the whole window's sums and every sub-window's that holds fewer blocks than the next longer one, each
        at alpha / (sums tested); the detecting decision with the largest margin (CHIRP before CW), else the whole
        window's (module docstring)."""
        distinct = [self._sums[0]]
        for sums in self._sums[1:]:
            if sums.count < distinct[-1].count:
                distinct.append(sums)
        alpha = float(self.params.false_alarm_per_block) / len(distinct)
        decisions = [self._decide(sums, alpha, cplx, fs, lmin, lmax, lag_limit) for sums in distinct]

        def margin(d: IntegratedDecision) -> tuple[int, float]:
            if d.type == CHIRP:
                return 2, d.chirp_z - d.chirp_threshold
            if d.type == CW:
                return 1, d.cw_score
            return 0, 0.0

        best = max(range(len(decisions)), key=lambda i: (margin(decisions[i]), -i))
        if decisions[best].type == NONE:
            best = 0
        self._last_sums = distinct[best]
        return decisions[best]

    def _decide(self, sums: _Sums, alpha: float, cplx: bool, fs: float, lmin: int, lmax: int,
                lag_limit: int) -> IntegratedDecision:
        """The decision on one window's sums (the newest ``sums.count`` blocks) at false-alarm probability alpha."""
        par = self.params
        nb = sums.count
        first, last = self._blocks[len(self._blocks) - nb], self._blocks[-1]
        span = (last.stamp_ns - first.stamp_ns) * 1e-9 + last.n / fs
        # --- CW: summed PSD against its running median --------------------------------------
        assert sums.psd is not None and sums.r is not None and sums.v is not None
        P = sums.psd
        K = sums.k
        Pm = P
        if not cplx and P.size > 3:
            Pm = P.copy()
            Pm[0], Pm[-1] = P[1], P[-2]      # DC and Nyquist (one degree of freedom) do not enter the median
        # the running median of a Gamma(K, 1/K) variable is its median, not its mean (ln 2 at K = 1): corrected
        ref = median_filter(Pm, size=par.smooth_bins, mode="wrap" if cplx else "reflect") / self._median_ratio(K)
        ref = np.maximum(ref, 1e-300)
        ratio = P / ref
        B = P.size
        thr = self._cw_threshold(K, B, cplx, alpha)
        score = ratio / thr
        if not cplx:
            score[0] = score[-1] = 0.0     # DC and Nyquist of a real IF: outside any front end's pass band
        j = int(np.argmax(score))
        cw_score = float(score[j])
        cw_f = (j - B // 2) / B if cplx else j / (2 * (B - 1))
        # the tone's power: the excess over the reference of its bin and two on either side (a Hann window puts
        # 0.4-0.67 of a tone in its strongest bin), over the noise of the whole band
        lo_j, hi_j = max(j - 2, 0), min(j + 3, B)
        excess = float(np.sum(P[lo_j:hi_j] - ref[lo_j:hi_j]) / max(float(ref.sum()), 1e-300))
        # --- CHIRP: comb over the summed 2-D autocorrelation ---------------------------------
        chirp_z, chirp_thr, per, strength = -math.inf, math.inf, math.nan, math.nan
        chirp = False
        if lmax >= lmin + 2 and sums.frames >= MIN_CHIRP_FRAMES:
            r, v = sums.r, sums.v
            kf = int(par.max_multiples)
            kc = min(COARSE_MULTIPLES, kf)
            # coarse comb (kc multiples) over all periods, then the fine one (kf multiples, a finer grid) around
            # the best coarse candidates; the threshold counts every fine candidate over the whole range
            # (Bonferroni), so evaluating only some of them keeps the false-alarm rate below alpha
            periods, idx, mask = self._comb_grid(lmin, lmax, lag_limit, kc)
            zc = _comb_z(r, v, idx, mask)
            n_top = min(20 * FINE_CANDIDATES, zc.size)
            order = np.argpartition(zc, zc.size - n_top)[zc.size - n_top:]   # the n_top largest, then sorted
            order = order[np.argsort(zc[order], kind="stable")[::-1]]
            top = _separated(order, periods, FINE_CANDIDATES).tolist()
            # around each: +-1.5 coarse steps. The coarse comb rounds k p to whole frames for k <= kc, so it is flat
            # over up to 1 / kc frames of p (two coarse steps) and the candidate taken from such a plateau may sit at
            # either end of it; a fine search of +-0.5 step missed the period when the true one lay at the plateau's
            # other end, and the comb then picked twice the period (measured: a 4 MS/s I/Q saw-tooth of 8.972 frames,
            # its period published doubled in 1 of 3 decisions)
            cand: list[float] = []
            for i in top:
                p0 = float(periods[i])
                k0 = max(2, min(kc, int(lag_limit // p0)))
                k1 = max(2, min(kf, int(lag_limit // p0)))
                cand.extend(np.arange(p0 - FINE_HALF_WIDTH / k0, p0 + FINE_HALF_WIDTH / k0 + 1e-12, 0.5 / k1).tolist())
            Pf = np.asarray([c for c in cand if lmin <= c <= lmax] or [float(periods[top[0]])])
            zf = _comb_z_direct(r, v, Pf, np.clip((lag_limit // Pf).astype(np.int64), 2, kf), lag_limit)
            ck = (lmin, lmax, lag_limit, kf, alpha)
            if ck not in self._chirp_thr:
                self._chirp_thr[ck] = -float(special.ndtri(alpha / self._fine_count(lmin, lmax, lag_limit, kf)))
            i = int(np.argmax(zf))
            chirp_z = float(zf[i])
            _, idf, mf = self._comb_lags(Pf[i:i + 1], lag_limit, kf)     # the lags of the best candidate
            # the normal quantile, moved by the comb's skew (Cornish-Fisher): Z is a quadratic form of the amplitudes
            z0 = self._chirp_thr[ck]
            gamma = _comb_skew(float(Pf[i]), int(mf[0].sum()), sums.copies, sums.copy_frames)
            chirp_thr = z0 + gamma / 6.0 * (z0 * z0 - 1.0)
            lags = idf[0][mf[0]]
            strength = comb_strength(r, lags, sums.spread, sums.spread_frames)
            if chirp_z > chirp_thr and strength >= par.min_chirp_strength:
                chirp = True
                # the comb is large at every multiple of the period: the best candidate's sub-multiples are tested on
                # the same sums (resolve_submultiple); an ambiguous one leaves the period NaN (counted)
                p_res, m, s_res = resolve_submultiple(r, v, sums.spread, sums.spread_frames, float(Pf[i]), lmin,
                                                      lag_limit, kf)
                if m > 1:
                    self.submultiples += 1
                    strength = s_res
                if math.isfinite(p_res):
                    per = p_res * (frame_length(fs, par) // 2)
                else:
                    self.ambiguous_periods += 1
        if chirp:
            jtype = CHIRP
        elif cw_score > 1.0 and excess > 0 and 10 * math.log10(excess) >= self.min_cw_jn_db:
            jtype = CW
        else:
            jtype = NONE
        return IntegratedDecision(jtype, nb, float(span), cw_score, float(cw_f), chirp_z, chirp_thr,
                                  per if jtype == CHIRP else math.nan,
                                  10 * math.log10(excess) if excess > 0 else -math.inf, strength)
