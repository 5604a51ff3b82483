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
  under noise ``(T - l) sum_bb' C_bb'^2`` (``C``: the block's covariance between bins, measured, so the
  window's leakage between bins and a jammer's own variance are accounted for). A periodic sweep puts
  the same spectrum at every multiple of its period, so the statistic is the comb
  ``Z(p) = sum_k r(k p) / sqrt(sum_k var r(k p))`` (``k = 1..K_p``, up to ``max_multiples``, lags
  rounded to frames; candidate periods on a grid of ``0.5 / K_p`` frames: the folding of the spectrogram
  at the period, written with the autocorrelation so that blocks add without knowing their sweep phase).
  Under noise ``Z`` is standard normal per candidate (lags >= 2 frames: Hann frames at hop L/2 do not
  overlap); the threshold is ``Phi^-1(1 - alpha / M)`` for ``M`` candidates (Bonferroni).

The frame length of the chirp statistic is fixed per stream (``frame_length_s`` of the sample rate,
a power of two in 8..128): the sweep must move by less than about one bin per frame (a sweep of k
cycles/sample^2 moves k L^2 bins per frame: 0.7 at the paper's 1e12 Hz/s, 38.192 MS/s, L = 32).

The window restarts on a change of sample rate, IF or real/complex (``reset``), when the monitor's
single-block analysis stops seeing a jammer it saw in the block before (``restart``: a jammer switched
off is not reported on for window_s), and drops blocks older than ``window_s`` (a stamp that goes
backwards restarts it). A jammer too weak for any single block that switches off is still reported
until its evidence leaves the window (at most ``window_s``). The decision says how many blocks and
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
from scipy import stats
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
            period_samples: the candidate period that gave it (NaN unless CHIRP).
        excess_db: the strongest bin's tone power (5 bins' excess over the reference) over the noise of the whole
            band, dB (-inf: none).
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


BUDGET_HOLD_S = 0.01
"""The processing budget (``IntegrationParams.max_samples_per_s``) left unused is kept for at most this many seconds of
stamps (or one block): a pause in the stream does not let a burst of blocks through later."""
NEIGHBOUR_BINS = 3
"""Bin covariances summed for the variance of the chirp statistic: offsets 0..this (a Hann window leaks into the
next bin, little beyond; a bin's correlation with far bins under noise is zero)."""
MIN_CHIRP_FRAMES = 512
"""The chirp statistic decides once the window holds this many frames: a sum of products of few frames has heavier
tails than the normal law its threshold assumes (measured on Gaussian noise: 1024-sample blocks of 12 MS/s real IF,
127 frames each, exceeded the alpha = 1e-4 threshold in 1 of 3,000 single blocks)."""
COARSE_MULTIPLES = 16
"""Multiples summed by the coarse comb that selects the candidates of the fine one."""
FINE_CANDIDATES = 12
"""Best coarse candidates refined with ``max_multiples`` multiples."""


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


class _BlockStats:
    __slots__ = ("stamp_ns", "n", "psd_sum", "psd_frames", "power", "r", "var", "frames")

    def __init__(self, stamp_ns: int, n: int, psd_sum: np.ndarray, psd_frames: int, power: float,
                 r: np.ndarray, var: np.ndarray, frames: int) -> None:
        self.stamp_ns, self.n = stamp_ns, n
        self.psd_sum, self.psd_frames, self.power = psd_sum, psd_frames, power
        self.r, self.var, self.frames = r, var, frames


def frame_length(fs: float, par: IntegrationParams) -> int:
    """Frame length of the chirp statistic at sample rate fs (module docstring)."""
    L = 2 ** int(round(math.log2(max(fs * par.frame_length_s, 1.0))))
    return int(min(max(L, 8), 128))


def spectral_autocorrelation(x: np.ndarray, cplx: bool, L: int, max_lag: int) -> tuple[np.ndarray, np.ndarray, int]:
    """(r, var, T): the 2-D autocorrelation r(l), l = 0..max_lag, of E = |X| / mean_t |X| - 1 and its variance under
    noise (module docstring), T frames of L samples at hop L / 2."""
    S, _ = rg.stft_power(x, L, cplx)
    T = S.shape[0]
    # amplitudes (lighter tails than powers: Rayleigh, not exponential, at little loss), normalised per bin, laid
    # out (bins, frames) so that the FFTs run along contiguous rows, and the bin covariances, in one compiled pass
    Et, q = _normalised_amplitudes(np.ascontiguousarray(S), bool(not cplx and S.shape[1] > 3), NEIGHBOUR_BINS)
    nf = sp_fft.next_fast_len(T + max_lag + 1, real=True)     # no circular wrap up to max_lag
    F = sp_fft.rfft(Et, nf, axis=1)
    R = sp_fft.irfft(frame_power(F), nf)[: max_lag + 1]     # sum over bins of |F|^2 (the classifier's pass)
    lags = np.arange(max_lag + 1)
    var = np.maximum(T - lags, 0) * q
    return R, var, T


_REASSOC = {"reassoc", "contract"}
"""numba fastmath flags of the reductions below: sums may be reassociated (vectorised); no assumption about NaN or
infinities (the inputs are finite)."""


@njit(cache=True, nogil=True, fastmath=_REASSOC)
def _normalised_amplitudes(S: np.ndarray, drop_edges: bool, neighbours: int) -> tuple[np.ndarray, float]:
    """(E transposed, q) of spectral_autocorrelation. S float32 (frames, bins) = |X|^2. E = sqrt(S) / mean_t - 1 per
    bin, float32, shape (bins, frames), without the DC and Nyquist bins of a real signal (drop_edges: one degree of
    freedom). q = sum over bin pairs (b, b') with |b - b'| <= neighbours of C_bb'^2, C the covariance between bins
    over frames (the window's leakage correlates a bin with its next few neighbours only; module docstring)."""
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
    q = 0.0
    for d in range(min(neighbours + 1, nb)):
        for b in range(nb - d):
            c = 0.0
            for t in range(nfr):
                c += float(Et[b, t]) * float(Et[b + d, t])
            c /= nfr
            q += (1.0 if d == 0 else 2.0) * c * c
    return Et, q


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
        self._cw_thr: dict[tuple[int, int, bool], np.ndarray] = {}
        self._med: dict[int, float] = {}
        self._chirp_thr: dict[tuple[int, int, int, int], float] = {}
        self.thinned = 0
        """Blocks not added because of the processing budget (``IntegrationParams.max_samples_per_s``), since
        construction."""
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
        self._sum_psd: np.ndarray | None = None
        self._sum_r: np.ndarray | None = None
        self._sum_v: np.ndarray | None = None
        self._sum_k = 0

    def _push(self, b: _BlockStats) -> None:
        if self._sum_psd is None or self._sum_r is None or self._sum_v is None:
            self._sum_psd, self._sum_r, self._sum_v = b.psd_sum.copy(), b.r.copy(), b.var.copy()
        else:
            self._sum_psd += b.psd_sum
            self._sum_r += b.r
            self._sum_v += b.var
        self._sum_k += b.psd_frames
        self._blocks.append(b)

    def _pop(self) -> None:
        b = self._blocks.popleft()
        assert self._sum_psd is not None and self._sum_r is not None and self._sum_v is not None
        self._sum_psd -= b.psd_sum
        self._sum_r -= b.r
        self._sum_v -= b.var
        self._sum_k -= b.psd_frames

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
                return dataclasses.replace(self._last, blocks=len(self._blocks))
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
        r, var, T = spectral_autocorrelation(x, cplx, L, lag_limit)
        if self._blocks and (self._blocks[-1].psd_sum.size != psd.size or self._blocks[-1].r.size != r.size):
            self._clear()
        self._push(_BlockStats(int(stamp_ns), x.size, psd * frames, frames, power, r, var, T))
        horizon = int(stamp_ns) - int(round(par.window_s * 1e9))
        while len(self._blocks) > 1 and self._blocks[0].stamp_ns <= horizon:
            self._pop()
        n_frames = sum(b.frames for b in self._blocks)
        if (self._last is not None and len(self._blocks) > 1 and n_frames < 1.1 * self._last_frames
                and int(stamp_ns) - self._last_stamp < int(round(par.decide_interval_s * 1e9))):
            return dataclasses.replace(self._last, blocks=len(self._blocks))
        self._last = self._decide(cplx, fs, lmin, lmax, lag_limit)
        self._last_stamp = int(stamp_ns)
        self._last_frames = n_frames
        return self._last

    def _median_ratio(self, K: int) -> float:
        """Median over mean of Gamma(K, 1/K) (cached)."""
        v = self._med.get(int(K))
        if v is None:
            v = float(stats.gamma.median(float(K), scale=1.0 / float(K)))
            if len(self._med) > 256:
                self._med.clear()
            self._med[int(K)] = v
        return v

    def _cw_threshold(self, K: int, B: int, cplx: bool) -> np.ndarray:
        """Per-bin threshold of P_b / N_b (module docstring), cached per (K, B, kind)."""
        key = (int(K), int(B), bool(cplx))
        thr = self._cw_thr.get(key)
        if thr is None:
            alpha = float(self.params.false_alarm_per_block)
            dof = np.full(B, float(K))
            if not cplx:
                dof[0] = dof[-1] = 0.5 * K
            thr_g = stats.gamma.isf(alpha / B, dof, scale=1.0 / dof)
            # the reference's own scatter (a median of smooth_bins bins of the same chi-square: 1.2533 / sqrt(K w)
            # relative, 1 sigma), taken at 4 sigma as a relative error of the reference
            rel_ref = 1.2533 / math.sqrt(K * self.params.smooth_bins)
            thr = thr_g * (1.0 + 4.0 * rel_ref)
            if len(self._cw_thr) > 64:
                self._cw_thr.clear()
            self._cw_thr[key] = thr
        return thr

    def _decide(self, cplx: bool, fs: float, lmin: int, lmax: int, lag_limit: int) -> IntegratedDecision:
        par = self.params
        alpha = float(par.false_alarm_per_block)
        bl = list(self._blocks)
        nb = len(bl)
        span = (bl[-1].stamp_ns - bl[0].stamp_ns) * 1e-9 + bl[-1].n / fs
        # --- CW: summed PSD against its running median --------------------------------------
        assert self._sum_psd is not None and self._sum_r is not None and self._sum_v is not None
        P = self._sum_psd
        K = self._sum_k
        Pm = P
        if not cplx and P.size > 3:
            Pm = P.copy()
            Pm[0], Pm[-1] = P[1], P[-2]      # DC and Nyquist (one degree of freedom) do not enter the median
        # the running median of a Gamma(K, 1/K) variable is its median, not its mean (ln 2 at K = 1): corrected
        ref = median_filter(Pm, size=par.smooth_bins, mode="wrap" if cplx else "reflect") / self._median_ratio(K)
        ref = np.maximum(ref, 1e-300)
        ratio = P / ref
        B = P.size
        thr = self._cw_threshold(K, B, cplx)
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
        chirp_z, chirp_thr, per = -math.inf, math.inf, math.nan
        frames = sum(b.frames for b in bl)
        if lmax >= lmin + 2 and frames >= MIN_CHIRP_FRAMES:
            r, v = self._sum_r, self._sum_v
            kf = int(par.max_multiples)
            kc = min(COARSE_MULTIPLES, kf)
            # coarse comb (kc multiples) over all periods, then the fine one (kf multiples, a finer grid) around
            # the best coarse candidates; the threshold counts every fine candidate over the whole range
            # (Bonferroni), so evaluating only some of them keeps the false-alarm rate below alpha
            periods, idx, mask = self._comb_grid(lmin, lmax, lag_limit, kc)
            zc = _comb_z(r, v, idx, mask)
            order = np.argsort(zc)[::-1]
            top: list[int] = []
            for i in order[: 20 * FINE_CANDIDATES]:
                if all(abs(periods[i] - periods[j]) > 0.5 for j in top):
                    top.append(int(i))
                    if len(top) == FINE_CANDIDATES:
                        break
            cand: list[float] = []
            for i in top:
                p0 = float(periods[i])
                k0 = max(2, min(kc, int(lag_limit // p0)))
                k1 = max(2, min(kf, int(lag_limit // p0)))
                cand.extend(np.arange(p0 - 0.5 / k0, p0 + 0.5 / k0 + 1e-12, 0.5 / k1).tolist())
            Pf = np.asarray([c for c in cand if lmin <= c <= lmax] or [float(periods[top[0]])])
            _, idf, mf = self._comb_lags(Pf, lag_limit, kf)
            zf = _comb_z(r, v, idf, mf)
            ck = (lmin, lmax, lag_limit, kf)
            if ck not in self._chirp_thr:
                self._chirp_thr[ck] = float(stats.norm.isf(alpha / self._fine_count(lmin, lmax, lag_limit, kf)))
            chirp_thr = self._chirp_thr[ck]
            i = int(np.argmax(zf))
            chirp_z = float(zf[i])
            if chirp_z > chirp_thr:
                per = float(Pf[i]) * (frame_length(fs, par) // 2)
        if math.isfinite(per) and chirp_z > chirp_thr:
            jtype = CHIRP
        elif cw_score > 1.0 and excess > 0 and 10 * math.log10(excess) >= self.min_cw_jn_db:
            jtype = CW
        else:
            jtype = NONE
        return IntegratedDecision(jtype, nb, float(span), cw_score, float(cw_f), chirp_z, chirp_thr,
                                  per if jtype == CHIRP else math.nan,
                                  10 * math.log10(excess) if excess > 0 else -math.inf)
