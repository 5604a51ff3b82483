"""Evidence integrated over blocks: weak stationary jammers that no single block shows (issue 14 item 5).

Pure module (no ROS). ``RfiMonitor`` (the "stft" estimator) feeds every analysed block to an
``Integrator`` and asks it for a decision when the block alone reports NONE. The integrator keeps,
summed over the blocks of the last ``window_s`` seconds (stamps, not the wall clock), two statistics
that do not depend on where a block starts, so that blocks need not be contiguous (the demo's 1 ms
snapshots once a second are integrated as well as a continuous stream):

* **CW** (``rfi_monitor.cw_statistic``): a tone significant in the Welch PSD summed over blocks, against the summed
  PSD's own running median, at a Bonferroni threshold over the bins.
* **CHIRP** (any periodic sweep): the 2-D autocorrelation over frames of the block's short-time spectrum and its
  variance under noise (``rfi_monitor.spectral_autocorrelation``), summed over blocks; the comb over the multiples of
  each candidate period, at a Bonferroni threshold over the candidates, and the sub-multiples of the best period
  tested before it is published (``rfi_monitor.chirp_comb``).

Sub-windows. Noise blocks in the sum dilute a jammer that has just switched on: the comb's numerator grows with
the jammed blocks only, its noise with all blocks. After 600 clean 1 ms blocks a chirp at J/N -8 dB on the 2-bit
captures was not found within 80 blocks of switch-on from the whole window (3-5 blocks with the sub-windows below).
So the statistics are also
summed over the newest ``window_s / 4**k`` seconds, ``k = 1..sub_windows`` (running sums of their own, no extra
analysis per block), and each distinct sum (sub-windows holding the same blocks as a longer one are not tested
again: 1 ms snapshots once a second test one sum) is tested at ``alpha / m`` for ``m`` distinct sums (Bonferroni:
the false alarm per block stays at most ``alpha``). The reported decision is the one of the sum that detects with
the largest margin over its threshold (CHIRP before CW), else the whole window's.

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

from rfi_monitor.chirp_comb import (
    MIN_CHIRP_FRAMES,
    ChirpComb,
    _comb_skew,
    comb_lags,
    comb_strength,
    resolve_submultiple,
)
from rfi_monitor.classifier import welch_psd
from rfi_monitor.cw_statistic import CwStatistic
from rfi_monitor.spectral_autocorrelation import spectral_autocorrelation
from rfi_node_common.params import parameter

__all__ = [
    "CHIRP", "CW", "NONE", "IntegratedDecision", "IntegrationParams", "Integrator", "_comb_skew", "comb_strength",
    "frame_length", "resolve_submultiple", "spectral_autocorrelation",
]

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

    window_s: float = parameter(
        1.0,
        'stft: evidence over blocks (docs/rfi_monitor/integration.md). When a block alone shows nothing, the sums '
        'over the blocks stamped within the last integration_window_s seconds decide: a tone in the summed Welch PSD '
        '(CW, from classifier_detect_jn_db) or a periodic sweep in the summed 2-D autocorrelation of the short-time '
        'spectrum (CHIRP, with its period). Blocks need not be contiguous (1 ms snapshots once a second are summed '
        'too); a change of rate/IF restarts it. Thresholds from the noise statistics: false alarm per block <= '
        'integration_false_alarm_per_block under Gaussian noise (Bonferroni). 0: off.', minimum=0.0, maximum=60.0)
    false_alarm_per_block: float = parameter(
        1e-4,
        'stft: false-alarm probability per block of each integrated statistic under Gaussian noise (sets the '
        'thresholds), (0, 0.1].', minimum=1e-12, maximum=0.1)
    frame_length_s: float = parameter(
        1e-6,
        'stft: frame of the integrated chirp statistic, s (power of two of 8..128 samples); a sweep must move less '
        'than about a bin per frame (k L^2 bins at k cycles/sample^2).', minimum=1e-9, maximum=1.0)
    max_period_s: float = parameter(
        100e-6, 'stft: longest sweep period of the integrated chirp statistic, s.', minimum=1e-7, maximum=1.0)
    max_multiples: int = parameter(
        128, 'stft: most multiples of a candidate sweep period summed by the integrated chirp statistic.',
        minimum=2, maximum=4096)
    nfft: int = parameter(
        1024, 'stft: Welch frame of the integrated CW statistic, samples (power of two >= 64).',
        minimum=64, maximum=2**20)
    smooth_bins: int = parameter(
        31, "stft: running median (bins, odd >= 5) that is the integrated CW statistic's noise reference.",
        minimum=5, maximum=4095)
    decide_interval_s: float = parameter(
        0.01,
        'stft: the integrated statistics are tested at most once per this many seconds of stamps (the test costs '
        'about as much as adding a block); blocks in between get the last decision. 0: every block.',
        minimum=0.0, maximum=10.0)
    min_chirp_strength: float = parameter(
        0.005,
        "stft: a periodic sweep found over blocks is reported only when this share of the amplitudes' variance "
        'repeats at its period: the clean 4 MS/s PocketSDR capture has a periodic modulation of 0.0008-0.0019, '
        'significant after 280 blocks; chirps at J/N -5 dB measured 0.017 and more.', minimum=0.0, maximum=0.999)
    sub_windows: int = parameter(
        3,
        'stft: the sums are also tested over the newest integration_window_s / 4**k seconds, k = 1..this (0: the '
        'whole window only): after 600 clean 1 ms blocks a chirp at J/N -8 dB on the 2-bit captures was not found '
        'within 80 blocks of switch-on with the whole window alone, after 13-25 with 2 sub-windows, 3-5 with 3. '
        'Bonferroni over the sums tested; 3 cost about 0.15 ms per 1 ms block of 38.192 MS/s real IF.',
        minimum=0, maximum=4)
    max_samples_per_s: float = parameter(
        16.5e6,
        'stft: processing budget of the evidence over blocks, samples per second of stamps (deterministic, not the '
        "machine's load): every block is added up to 16.5 MS/s, 43 % of the 1 ms blocks of a 38.192 MS/s stream (the "
        'rest get the last decision; counted as integration_blocks_thinned). 0: all.', minimum=0.0, maximum=1e12)

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
SWITCH_OFF_SIGMA = 5.0
"""A periodic sweep found over a window is gone when a shorter sum (a sub-window) at its period reads this many standard
deviations below what the sweep, at the strength the window measured, would give it (``Integrator.switch_offs``)."""
SWITCH_OFF_MIN_EXPECTED = 8.0
"""... and that shorter sum would show the sweep at no less than this many standard deviations (else it cannot tell)."""


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
        """Add the block's counts (its arrays are added to every sum at once: ``Integrator._push``)."""
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
    """Frame length of the chirp statistic at sample rate fs (``rfi_monitor.spectral_autocorrelation`` module
    docstring)."""
    L = 2 ** int(round(math.log2(max(fs * par.frame_length_s, 1.0))))
    return int(min(max(L, 8), 128))


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
        self._cw = CwStatistic(params.smooth_bins)
        self._comb = ChirpComb()
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
        self._stacked: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._last_sums = self._sums[0]

    def _push(self, b: _BlockStats) -> None:
        """Add a block to every sum: its arrays to the rows of the stacked sums (one numpy call per statistic for all
        the window lengths; the sums' arrays are views of those rows), its counts to each."""
        if self._stacked is None:
            m = len(self._sums)
            self._stacked = (np.zeros((m, b.psd_sum.size)), np.zeros((m, b.r.size)), np.zeros((m, b.var.size)))
            for i, sums in enumerate(self._sums):
                sums.psd, sums.r, sums.v = self._stacked[0][i], self._stacked[1][i], self._stacked[2][i]
        psd, r, v = self._stacked
        psd += b.psd_sum
        r += b.r
        v += b.var
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
                return self._last_decision()
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
            return self._last_decision()
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

    def _last_decision(self) -> IntegratedDecision:
        """The last decision with the blocks its sum holds now (the same object while that count is unchanged:
        ``dataclasses.replace`` costs more than the rest of a thinned block)."""
        assert self._last is not None
        if self._last.blocks != self._last_sums.count:
            self._last = dataclasses.replace(self._last, blocks=self._last_sums.count)
        return self._last

    def _switched_off(self, d: IntegratedDecision, lag_limit: int, fs: float) -> bool:
        """Whether the sweep of decision d (CHIRP, from the sum self._last_sums) is gone from a shorter sum: at d's
        period, the shorter sum's comb reads SWITCH_OFF_SIGMA below what d's strength predicts for it, where that
        prediction is at least SWITCH_OFF_MIN_EXPECTED (the comb over K multiples of the strength's reference)."""
        if not (math.isfinite(d.chirp_strength) and d.chirp_strength > 0 and math.isfinite(d.period_samples)):
            return False
        p = d.period_samples / (frame_length(fs, self.params) // 2)
        _, idx, mask = comb_lags(np.asarray([p]), lag_limit, int(self.params.max_multiples))
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
        assert sums.psd is not None and sums.r is not None and sums.v is not None
        # CW: summed PSD against its running median (cw_statistic)
        cw_score, cw_f, excess = self._cw.test(sums.psd, sums.k, cplx, alpha)
        # CHIRP: comb over the summed 2-D autocorrelation (chirp_comb)
        chirp_z, chirp_thr, per, strength = -math.inf, math.inf, math.nan, math.nan
        chirp = False
        if lmax >= lmin + 2 and sums.frames >= MIN_CHIRP_FRAMES:
            c = self._comb.test(sums.r, sums.v, sums.copies, sums.copy_frames, sums.spread, sums.spread_frames, alpha,
                                lmin, lmax, lag_limit, int(par.max_multiples), par.min_chirp_strength)
            chirp_z, chirp_thr, strength, chirp = c.z, c.threshold, c.strength, c.detected
            if chirp:
                # a sub-multiple of the comb's best period taken, or an ambiguous one (period NaN): counted
                if c.multiple > 1:
                    self.submultiples += 1
                if math.isfinite(c.period_frames):
                    per = c.period_frames * (frame_length(fs, par) // 2)
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
