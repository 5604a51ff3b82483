"""A noise jammer that fills part of the band, behind an AGC: the step it makes in the spectrum's shape.

Pure module (no ROS). Not in Kang et al.; issue 14 item 5 ("any jammer reported from J/N -5 dB within 1 s").

Why: a front end with an automatic gain control (the 2-bit PocketSDR captures; most receivers) keeps the block
power constant, so a noise jammer raises no power against any floor; and one that covers most of the band is
also the noise level the block measures beside it. What it does change is the spectrum's *shape*: inside its
band the PSD rises against the rest. ``SpectralStep`` compares the block's normalised Welch PSD (the
classifier's, ``psd / psd.sum()``) with a reference shape averaged over the blocks that passed as noise, and looks
for a band that rose:

1. The bins are summed in ``G`` adjacent groups of ``g >= 2`` bins (``groups`` of the sampled band; real input
   without its DC and Nyquist bins; the DC bin of complex input, where a local-oscillator leak lives, is replaced
   by its neighbours' mean). ``y_i = P_i / R_i``: P the normalised group power of the last ``m`` blocks (their
   frames summed), R the reference.
2. Without a jammer y is not simply constant: a gain change moves the front end's filtered noise and the
   quantiser's own, white noise differently (measured on the 2-bit captures: the groups outside the front end's
   filter "rise" by up to 1 dB when the total power's make-up changes). The block is therefore modelled as
   ``P_i = a R_i + b`` (the reference's shape plus a flat floor), i.e. ``y_i = a + b x_i`` with
   ``x_i = 1 / R_i`` (scaled to mean 1), fitted by least squares outside the band tested. Under Gaussian noise
   the group power of K Hann frames has relative variance ``c_g / K`` with ``c_g = g^-2 sum_{i,j} rho_|i-j|``
   and ``rho_k`` the squared correlation of a Hann window's DFT bins k apart (4/9, 1/36, 0 ...: from the window,
   ``hann_bin_correlation``); adjacent groups share the correlation of their edge bins (``r_adj``). So
   ``var y_i = y_i^2 c_g (1 / K_P + 1 / K_R) (1 + 2 r_adj)`` (= ``v y_i^2``).
3. For every band ``S`` of ``L`` adjacent groups (``2 <= L <= max_band_fraction G``: a jammer is taken as the
   minority of the band) the rise ``e = mean_S y - mean_S (a + b x)`` of the band over the line fitted outside it,
   and ``z = e / sqrt(v (ybar_S^2 / L + ybar_out^2 (1/(G-L) + (xbar_S - xbar_out)^2 / Sxx_out)))`` (the last
   term: the line's own error where it is read). The slope is fitted only where x spreads by MIN_X_SPREAD of its
   mean outside the band; where it does not, the larger of the two one-parameter predictions (the reference's
   shape, a flat floor) is taken. A band where the line falls below MIN_MODEL_SHARE of the rest's level is
   skipped. A jammer that was on while the reference was learned and switches off leaves ``P`` flat,
   ``y = c x``: a line, no step. Searched at lengths about
   ``LENGTH_RATIO`` apart, then at every length near the best (speed).
4. A step is reported when ``z`` exceeds ``Phi^-1(1 - alpha / M)`` (``M``: bands of every length times scales,
   Bonferroni; at most ``alpha`` = ``false_alarm_per_block`` false alarms per block under noise; z is first
   lowered by the Cornish-Fisher term ``gamma / 6 (thr^2 - 1)`` of the band's summed power, whose skewness
   ``gamma = 2 / sqrt(L K / c_g)`` gives a few frames' sums a heavier right tail than the normal one: measured,
   2-bit noise of 16-frame blocks crossed the plain threshold once in 2,000) **and** the
   rise ``d = ln(1 + e / mu)`` exceeds ``min_step_db`` (the reference's own drift and a front end's small shape
   changes are not jammers). Scales: ``m = 1, 4, 16, 64, 256`` blocks and all the blocks stamped within the
   last ``window_s`` (evidence over blocks: a jammer below one block's resolution is found from the sum; blocks
   need not be contiguous).
5. The band must be the only change (of the bands that rose, the one with the largest z that passes): the sum
   of squares the two-part model leaves (a line in x outside, another inside: a jammer filtered like the noise
   raises a, one that is not, as in rfi_sim, raises b; each part in units of its own variance) is at most the
   ``1 - alpha`` quantile of chi2(G - 4) (noise), or at most ``FLAT_SHARE z^2`` (a strong jammer's own shape, a
   quantiser's products). ``not_flat`` counts the tests where something rose beyond the threshold but no band
   passes (two noise jammers in separate bands, or a changed front end: not reported by this test).

J/N of a step: inside the band the jammer's density over the noise's is the rise ``e / mu`` of the newest block
alone in the band found (a sum over m blocks holds those before a switch-on; the gain scales jammer and noise
alike), so ``J/N = (e / mu) sum_S R_i`` over the sampled band (the reference sums to 1). A 1-3 bit quantiser
compresses it: a lower bound there.

The reference learns (``learn``, called by the monitor for blocks that pass as noise) only from blocks with no
step at any scale above ``learn_z``: a weak jammer that grows does not become the reference. Its memory is
``reference_blocks`` blocks (exponential; the front end's shape drifts over seconds to hours, and a longer
reference makes the test more sensitive). A jammer present before the reference was learned is part of it:
it is not reported (the monitor's other references say so by power where the gain is fixed). When it switches
off, step 5 keeps the change from being reported as a jammer in most cases; where it cannot (a jammer over
more than ``max_band_fraction`` of a complex band, whose rest is one band of the circular spectrum), it is
reported for at most ``relearn_after_s``: a spectrum that differs from the reference (z over ``learn_z``, so
nothing is learned) for that long makes the reference be learned again (``relearned``).

Example
-------
>>> import numpy as np
>>> from rfi_monitor.classifier import welch_psd
>>> st = SpectralStep(SpectralStepParams())
>>> rng = np.random.default_rng(0)
>>> for k in range(8):
...     psd, frames = welch_psd(rng.standard_normal(4096) + 1j * rng.standard_normal(4096), 256, 10**6)
...     d = st.test(psd / psd.sum(), frames, True, stamp_ns=k * 10**6)
...     learned = st.learn()
>>> d.detected
False
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit
from scipy import stats

from rfi_node_common.params import parameter

SCALES_MAX = 512
"""Most blocks summed by the longest scale (1, 4, 16, ... and all the blocks in the window, up to this)."""

FLAT_SHARE = 0.25
"""A band is reported when the two-part model (a line outside, another inside) leaves at most this times z^2 in sum
of squares, or no more than noise (module docstring, step 5)."""

MIN_X_SPREAD = 0.1
"""The line's slope is fitted only where x = 1 / R spreads by at least this share of its mean outside the band
(module docstring, step 2); else the rest is taken as flat."""

MIN_MODEL_SHARE = 0.5
"""A band whose line value falls below this share of the rest's mean level is not measured (an extrapolation)."""

MIN_FRAMES = 32
"""Fewest Welch frames a tested sum holds: the z of a few frames' chi2 powers has a heavier tail than the normal
one its threshold assumes (measured: 1024-sample blocks of the 2-bit captures, 4 frames each, gave false alarms
at scale 1)."""

LENGTH_RATIO = 1.4
"""Ratio of consecutive band lengths of the first search (speed); the best one's neighbourhood is searched at
every length."""

SCALE_FACTOR = 4
"""Ratio of consecutive scales (speed: 6 scales up to SCALES_MAX instead of 10; sqrt(4) = 2 in z between them)."""

N_SCALES = 6
"""Scales tested at most: 1, 4, 16, 64, 256 blocks and all the window's blocks (Bonferroni count)."""


@dataclass(frozen=True)
class SpectralStepParams:
    """Parameters of the spectral-step test (module docstring).

    Attributes:
        enabled: run the test (estimator stft; False: a partial-band noise jammer behind an AGC is not seen).
        window_s: the last blocks stamped within this many seconds are summed (scales 1, 4, 16, ... blocks and all), s.
        groups: target number of groups the sampled band is cut into (>= 8; groups hold at least 2 bins).
        false_alarm_per_block: alpha, false alarms per block under Gaussian noise (Bonferroni), (0, 0.1].
        min_step_db: smallest rise of a band over the rest reported, dB (> 0): drift of the front end's shape
            and of the reference is not a jammer.
        max_band_fraction: widest band reported, share of the groups, (0, 0.5].
        reference_blocks: memory of the reference shape, blocks (exponential), >= 1.
        min_reference_blocks: blocks the reference needs before the test runs, >= 1.
        learn_z: a block whose best z at any scale exceeds this does not enter the reference, > 0.
        relearn_after_s: a spectrum that differs from the reference (z over learn_z) without a break for this
            long makes the reference be learned again, s (0: never). The shape alone cannot always tell a jammer
            that switched on from one that was on while the reference was learned and then switched off; this
            bounds the second to relearn_after_s, at the price of a partial-band noise jammer behind an AGC that
            stays on longer becoming the reference (reported until then).
        decide_interval_s: the sums are tested at most once per this many seconds of stamps (speed: a block costs
            about 40 us with a test, 10 us without, on a 2-vCPU AMD EPYC); blocks in between are added and get the
            last decision, s (0: every block; the default tests every other 1 ms block).
    """

    enabled: bool = parameter(
        True,
        'stft: a noise jammer in part of the band behind an AGC (which hides its power): the band of the spectrum '
        'that rose against the shape of the blocks that passed as noise (rfi_monitor.spectral_step, '
        'docs/rfi_monitor/sensitivity.md). The sums of the last 1, 4, 16, ... blocks (and all) stamped within '
        'spectral_step_window_s are tested; bands of 2 groups up to spectral_step_max_band_fraction of the sampled '
        'band; z threshold from spectral_step_false_alarm_per_block under Gaussian noise (Bonferroni), and the rise '
        "must exceed spectral_step_min_step_db (dB). WIDEBAND, frequency_hz the band's centre, frequency_std_hz its "
        'width / sqrt(12), J/N against the learned shape.')
    window_s: float = parameter(
        1.0,
        'stft: the spectral-step test sums the blocks stamped within this many seconds (1, 4, 16, ... and all of '
        'them), s.', minimum=0.0, maximum=60.0)
    groups: int = parameter(
        64, 'stft: groups (of >= 2 Welch bins) the band is cut into by the spectral-step test.',
        minimum=8, maximum=4096)
    false_alarm_per_block: float = parameter(
        1e-4,
        'stft: false-alarm probability per block of the spectral-step test under Gaussian noise (Bonferroni over '
        'bands and scales), (0, 0.1].', minimum=1e-12, maximum=0.1)
    min_step_db: float = parameter(
        0.25,
        "stft: smallest rise of a band over the rest of the spectrum reported, dB (drift of the front end's shape is "
        'no jammer).', minimum=1e-3, maximum=60.0)
    max_band_fraction: float = parameter(
        0.5, 'stft: widest band that rose reported, share of the sampled band, (0, 0.5].',
        minimum=0.01, maximum=0.5)
    reference_blocks: int = parameter(
        200, 'stft: memory of the spectral-step reference shape, blocks (exponential).',
        minimum=1, maximum=10**7)
    min_reference_blocks: int = parameter(
        5, 'stft: blocks in the reference shape before the spectral-step test runs.',
        minimum=1, maximum=10**7)
    learn_z: float = parameter(
        4.5, 'stft: a block whose spectral-step z (any scale) exceeds this does not enter the reference.',
        minimum=0.1, maximum=1e3)
    relearn_after_s: float = parameter(
        30.0,
        'stft: a spectrum that differs from the spectral-step reference (z over spectral_step_learn_z) without a '
        'break for this long makes the reference be learned again, s: a changed front end is not reported for ever; a'
        ' partial-band noise jammer behind an AGC that stays on longer becomes the reference. 0: never.',
        minimum=0.0, maximum=1e6)
    decide_interval_s: float = parameter(
        0.002,
        'stft: the spectral-step sums are tested at most once per this many seconds of stamps (a test costs a few '
        'times adding a block); blocks in between are added and get the last decision, s. 0: every block.',
        minimum=0.0, maximum=10.0)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.window_s) and self.window_s >= 0):
            raise ValueError("window_s must be finite and >= 0")
        if int(self.groups) < 8:
            raise ValueError("groups must be >= 8")
        if not 0 < self.false_alarm_per_block <= 0.1:
            raise ValueError("false_alarm_per_block must be in (0, 0.1]")
        if not (math.isfinite(self.min_step_db) and self.min_step_db > 0):
            raise ValueError("min_step_db must be finite and > 0")
        if not 0 < self.max_band_fraction <= 0.5:
            raise ValueError("max_band_fraction must be in (0, 0.5]")
        if int(self.reference_blocks) < 1 or int(self.min_reference_blocks) < 1:
            raise ValueError("reference_blocks and min_reference_blocks must be >= 1")
        if not (math.isfinite(self.learn_z) and self.learn_z > 0):
            raise ValueError("learn_z must be finite and > 0")
        if not (math.isfinite(self.relearn_after_s) and self.relearn_after_s >= 0):
            raise ValueError("relearn_after_s must be finite and >= 0")
        if not (math.isfinite(self.decide_interval_s) and self.decide_interval_s >= 0):
            raise ValueError("decide_interval_s must be finite and >= 0")


@dataclass(frozen=True)
class StepDecision:
    """Outcome of one block's test.

    Attributes:
        tested: the test ran (a reference exists and the block's layout matches it).
        detected: a band rose (z over the threshold and the rise over min_step_db).
        z: the z of the reportable band (a rise of at least min_step_db over a smooth rest, module docstring
            steps 4-5) with the largest z over bands and scales; -inf when there is none, NaN when not tested.
        z_any: the largest z of any band (what gates ``learn``; NaN when not tested).
        threshold: z threshold (Bonferroni).
        step_db: rise of that band over the rest, dB.
        jn_db: J/N of the rise over the sampled band, dB (-inf when no rise).
        low, high: the band's edges, cycles/sample of the analysed PSD (complex: -0.5..0.5; real: 0..0.5).
        blocks: blocks summed at the best scale.
    """

    tested: bool
    detected: bool
    z: float
    z_any: float
    threshold: float
    step_db: float
    jn_db: float
    low: float
    high: float
    blocks: int


NOT_TESTED = StepDecision(False, False, math.nan, math.nan, math.nan, math.nan, -math.inf, math.nan, math.nan, 0)


@lru_cache(maxsize=16)
def hann_bin_correlation(nfft: int) -> tuple[float, ...]:
    """rho_k, k = 0, 1, 2, 3: squared correlation of the DFT bins k apart of a periodic Hann window's frame
    under white noise, ``|sum w^2 e^(-2 pi i k n / N)|^2 / (sum w^2)^2``."""
    n = np.arange(nfft)
    w2 = (0.5 - 0.5 * np.cos(2 * np.pi * n / nfft)) ** 2
    s0 = float(w2.sum())
    return tuple(float(abs(np.sum(w2 * np.exp(-2j * np.pi * k * n / nfft))) ** 2 / s0 ** 2) for k in range(4))


@lru_cache(maxsize=16)
def _layout(n_bins: int, cplx: bool, target_groups: int, nfft: int) -> tuple[int, int, int, float, float]:
    """(first bin, bins per group g, groups G, c_g, r_adj) of a PSD of n_bins bins."""
    first = 0 if cplx else 1
    usable = n_bins if cplx else n_bins - 2
    g = max(2, usable // target_groups)
    n_groups = usable // g
    rho = hann_bin_correlation(nfft)
    c_g = sum(rho[min(abs(i - j), 3)] for i in range(g) for j in range(g)) / g ** 2
    # covariance of two adjacent groups: the bin pairs across their common edge
    cov = sum(rho[min(j + 1 + (g - 1 - i), 3)] for i in range(g) for j in range(g) if j + 1 + (g - 1 - i) <= 3) / g ** 2
    return first, g, n_groups, c_g, cov / c_g


@lru_cache(maxsize=64)
def _chi2_isf(alpha: float, dof: int) -> float:
    return float(stats.chi2.isf(alpha, dof))


@lru_cache(maxsize=64)
def threshold_z(n_groups: int, max_band_fraction: float, n_scales: int, alpha: float) -> float:
    """z threshold: Bonferroni over the bands (2..max_band_fraction G groups) and scales."""
    lmax = max(2, int(max_band_fraction * n_groups))
    bands = sum(n_groups - length + 1 for length in range(2, lmax + 1))
    return float(stats.norm.isf(alpha / max(1, bands * n_scales)))


class SpectralStep:
    """The spectral-step test over a stream of blocks (module docstring)."""

    def __init__(self, params: SpectralStepParams, nfft: int = 256) -> None:
        self.params = params
        self.nfft = int(nfft)
        self.relearned = 0           # references learned again (relearn_after_s), since construction
        self.not_flat = 0            # tests where something rose beyond the threshold but no band passed (step 5)
        self.reset()

    def reset(self) -> None:
        """Forget the reference and the recent blocks (new stream, or a change of rate / IF / real-complex)."""
        self._key: tuple | None = None
        self._ref_sum: np.ndarray | None = None    # decayed sum of K-weighted group shapes
        self._ref_k = 0.0                          # decayed sum of frames
        self._ref_blocks = 0.0
        self._ref_count = 0                        # blocks learned since the reference was (re)started
        self._run_start_ns: int | None = None      # stamp of the first block of the current run of z > learn_z
        # the recent blocks: a ring of cumulative group powers / frames / stamps; row head is the newest block,
        # rows head - count .. head - 1 the ones before it, row head - count the sums before the oldest (its base)
        self._cum: np.ndarray | None = None
        self._kcum = np.zeros(SCALES_MAX + 1)
        self._stamps = np.zeros(SCALES_MAX + 1, dtype=np.int64)
        self._head = 0
        self._count = 0
        self._last: tuple[np.ndarray, int] | None = None
        self._last_z = math.inf
        self._decision: tuple[int, StepDecision] | None = None     # (stamp, decision) of the last test

    def restart(self) -> None:
        """Forget the recent blocks, keep the reference (a jammer the single block saw: its blocks are not summed)."""
        self._count = 0
        self._last = None
        self._decision = None

    @property
    def reference_blocks(self) -> float:
        """Blocks in the reference (decayed)."""
        return self._ref_blocks

    def _layout(self, norm_psd: np.ndarray, cplx: bool) -> tuple[int, int, int, float, float]:
        return _layout(norm_psd.size, cplx, int(self.params.groups), self.nfft)

    def test(self, norm_psd: np.ndarray, frames: int, cplx: bool, stamp_ns: int) -> StepDecision:
        """Add a block (its normalised Welch PSD of ``frames`` Hann frames) to the recent blocks and test the sums.

        The block is held for ``learn``. Returns NOT_TESTED while the reference is too young."""
        par = self.params
        first, g, n_groups, c_g, r_adj = self._layout(norm_psd, cplx)
        key = (norm_psd.size, bool(cplx))
        if key != self._key:
            self.reset()
            self._key = key
            self._cum = np.zeros((SCALES_MAX + 1, n_groups))
        assert self._cum is not None
        stamp_ns = int(stamp_ns)
        if self._count and stamp_ns < int(self._stamps[self._head]):
            self._count = 0               # stamps went back: a new stream
        v = _add_block(np.asarray(norm_psd, dtype=np.float64), bool(cplx), first, g, float(frames), self._cum,
                       self._kcum, self._head)
        if v is None or not frames > 0:
            self._last = None
            return NOT_TESTED
        self._head = (self._head + 1) % (SCALES_MAX + 1)
        self._stamps[self._head] = stamp_ns
        self._count = min(self._count + 1, SCALES_MAX)
        oldest = stamp_ns - par.window_s * 1e9
        ring = SCALES_MAX + 1
        while self._count > 1 and self._stamps[(self._head - self._count + 1) % ring] < oldest:
            self._count -= 1
        self._last = (v, int(frames))
        if (self._decision is not None and 0 <= stamp_ns - self._decision[0] < par.decide_interval_s * 1e9
                and self._count > 1):
            return self._decision[1]      # tested less than decide_interval_s ago (its z still gates learn)
        d = self._test(norm_psd, cplx, n_groups, c_g, r_adj, first, g)
        self._decision = (stamp_ns, d) if d.tested else None
        if not (d.tested and d.z_any > par.learn_z):
            self._run_start_ns = None
        elif self._run_start_ns is None or stamp_ns < self._run_start_ns:
            self._run_start_ns = stamp_ns
        elif 0 < par.relearn_after_s <= (stamp_ns - self._run_start_ns) * 1e-9:
            # the spectrum has differed from the reference for relearn_after_s on end (a step reported, or a
            # shape no band explains): the reference is taken as wrong (learned while a jammer was on, which has
            # gone; or the front end changed) and learned again from the next blocks
            self._forget_reference()
            self._count = 0               # the sums held the blocks that differed: they would differ again
            self.relearned += 1
            self._decision = None
            self._run_start_ns = None
            return NOT_TESTED
        return d

    def _forget_reference(self) -> None:
        self._ref_sum, self._ref_k, self._ref_blocks, self._ref_count = None, 0.0, 0.0, 0
        self._last_z = 0.0

    def _test(self, norm_psd: np.ndarray, cplx: bool, n_groups: int, c_g: float, r_adj: float, first: int,
              g: int) -> StepDecision:
        par = self.params
        if self._ref_sum is None or self._ref_count < par.min_reference_blocks:
            self._last_z = 0.0
            return NOT_TESTED
        ref = self._ref_sum / self._ref_k
        lmax = max(2, int(par.max_band_fraction * n_groups))
        thr = threshold_z(n_groups, par.max_band_fraction, N_SCALES, par.false_alarm_per_block)
        assert self._cum is not None
        min_rise = 10 ** (par.min_step_db / 10) - 1.0
        flat_sse = _chi2_isf(par.false_alarm_per_block, n_groups - 4)
        z_any, z, d, lo, hi, m, rise1 = _best_band(self._cum, self._kcum, self._head, self._count, ref,
                                                   self._ref_k, band_lengths(lmax), c_g * (1.0 + 2.0 * r_adj),
                                                   SCALE_FACTOR, N_SCALES, float(MIN_FRAMES), min_rise, flat_sse,
                                                   thr)
        self._last_z = z_any
        if not math.isfinite(z_any):
            return NOT_TESTED
        detected = z > thr
        if z_any > thr and not detected:
            self.not_flat += 1        # something differs, but no band that rose over a smooth rest explains it
        if not math.isfinite(z):
            return StepDecision(True, False, z_any, z_any, thr, math.nan, -math.inf, math.nan, math.nan, 0)
        step_db = 10 * d / math.log(10)
        share = float(ref[lo:hi].sum())
        jn = 10 * math.log10(rise1 * share) if rise1 > 0 and share > 0 else -math.inf
        b0, b1 = first + lo * g, first + hi * g
        if cplx:
            low, high = (b0 - norm_psd.size // 2) / self.nfft, (b1 - norm_psd.size // 2) / self.nfft
        else:
            low, high = b0 / self.nfft, b1 / self.nfft
        return StepDecision(True, bool(detected), float(z), float(z_any), thr, float(step_db), float(jn), low, high,
                            int(m))

    def learn(self) -> bool:
        """Add the block last tested to the reference, unless it showed a step above ``learn_z`` (then False)."""
        if self._last is None or not self._last_z <= self.params.learn_z:
            return False
        v, k = self._last
        self._last = None
        decay = 1.0 - 1.0 / float(self.params.reference_blocks)
        self._ref_count += 1
        if self._ref_sum is None or self._ref_sum.size != v.size:
            self._ref_sum = v * k
            self._ref_k = float(k)
            self._ref_blocks = 1.0
        else:
            self._ref_sum = self._ref_sum * decay + v * k
            self._ref_k = self._ref_k * decay + k
            self._ref_blocks = self._ref_blocks * decay + 1.0
        return True


def warm_up(nfft: int = 256) -> None:
    """Compile (or load from numba's cache) the test's kernels on throw-away blocks of both layouts, so that a node
    does not pay for it on its first blocks (the monitor's own warm-up stops before a reference exists)."""
    rng = np.random.default_rng(0)
    for cplx in (False, True):
        st = SpectralStep(SpectralStepParams(min_reference_blocks=1, decide_interval_s=0.0), nfft)
        n_bins = nfft if cplx else nfft // 2 + 1
        for k in range(3):
            p = 1.0 + 0.1 * rng.random(n_bins)
            st.test(p / p.sum(), 16, cplx, stamp_ns=k * 1_000_000)
            st.learn()


def _add_block(p: np.ndarray, cplx: bool, first: int, g: int, frames: float, cum: np.ndarray, kcum: np.ndarray,
               head: int) -> np.ndarray | None:
    """The block's group powers (step 1), written as the ring's next cumulative row; None if not finite (the ring
    untouched). One compiled pass (:func:`_add_block_kernel`)."""
    v = _add_block_kernel(p, cplx, first, g, frames, cum, kcum, head)
    return v if v.size else None


@njit(cache=True)
def _add_block_kernel(p: np.ndarray, cplx: bool, first: int, g: int, frames: float, cum: np.ndarray,
                      kcum: np.ndarray, head: int) -> np.ndarray:
    """:func:`_add_block`: the group powers (:func:`_group_powers`), an empty array if one is not finite, else the
    ring's next row ``cum[head] + v * frames`` and ``kcum[head] + frames`` written (numpy's element-wise
    arithmetic, the same values)."""
    n_groups = cum.shape[1]
    v = _group_powers(p, cplx, first, g, n_groups)
    for i in range(n_groups):
        if not np.isfinite(v[i]):
            return np.empty(0)
    nxt = (head + 1) % cum.shape[0]
    for i in range(n_groups):
        cum[nxt, i] = cum[head, i] + v[i] * frames
    kcum[nxt] = kcum[head] + frames
    return v


@njit(cache=True)
def _group_powers(p: np.ndarray, cplx: bool, first: int, g: int, n_groups: int) -> np.ndarray:
    """Sums of g adjacent bins from ``first`` (complex: the DC bin replaced by its neighbours' mean)."""
    v = np.zeros(n_groups)
    dc = p.size // 2
    for i in range(n_groups):
        acc = 0.0
        for j in range(first + i * g, first + (i + 1) * g):
            if cplx and j == dc:
                acc += 0.5 * (p[j - 1] + p[(j + 1) % p.size])
            else:
                acc += p[j]
        v[i] = acc
    return v


@lru_cache(maxsize=64)
def band_lengths(lmax: int) -> np.ndarray:
    """Band lengths searched first (groups): 2, 3, 4, then about LENGTH_RATIO apart up to lmax (speed: the best
    one's neighbourhood is then searched at every length, ``_best_band``)."""
    out = [2]
    while out[-1] < lmax:
        out.append(min(lmax, max(out[-1] + 1, int(round(out[-1] * LENGTH_RATIO)))))
    return np.array(out, dtype=np.int64)


@njit(cache=True)
def _prefix(cum: np.ndarray, kcum: np.ndarray, head: int, m: int, ref: np.ndarray, pre: np.ndarray) -> float:
    """Prefix sums (rows y, x, x^2, x y, y^2; step 2) of the last m blocks into pre; their frames (0: not usable).
    y = P / R, x = 1 / R scaled to mean 1."""
    ring, n = cum.shape
    base = (head - m) % ring
    frames = kcum[head] - kcum[base]
    if not frames > 0:
        return 0.0
    xm = 0.0
    for j in range(n):
        xm += 1.0 / ref[j]
    xm /= n
    for j in range(n):
        s = cum[head, j] - cum[base, j]
        if not s > 0:
            return 0.0
        y = s / frames / ref[j]
        x = 1.0 / ref[j] / xm
        pre[0, j + 1] = pre[0, j] + y
        pre[1, j + 1] = pre[1, j] + x
        pre[2, j + 1] = pre[2, j] + x * x
        pre[3, j + 1] = pre[3, j] + x * y
        pre[4, j + 1] = pre[4, j] + y * y
    return frames


@njit(cache=True)
def _line(n: float, sy: float, sx: float, sxx: float, sxy: float) -> tuple[float, float]:
    """Least-squares y = a + b x over n points from their sums; b = 0 when x spreads by less than MIN_X_SPREAD of
    its mean (a front end as flat as its reference's own noise: no slope to fit)."""
    den = n * sxx - sx * sx
    if den <= (MIN_X_SPREAD * sx) ** 2:
        return sy / n, 0.0
    b = (n * sxy - sx * sy) / den
    return (sy - b * sx) / n, b


@njit(cache=True)
def _band(pre: np.ndarray, lo: int, hi: int, var_group: float, with_sse: bool) -> tuple[float, float, float]:
    """(z, rise ratio - 1, sum of squares left by the two-part model / group variance) of band [lo, hi): the rest
    fitted by a + b x (step 2), the band's mean against that line's mean over the band. Without ``with_sse`` the
    third is 0 (not computed: the scan needs it only for a band that would be the best reportable one)."""
    n = pre.shape[1] - 1
    length = hi - lo
    no = n - length
    sy_i = pre[0, hi] - pre[0, lo]
    sx_i = pre[1, hi] - pre[1, lo]
    syy_i = pre[4, hi] - pre[4, lo]
    sy_o = pre[0, n] - sy_i
    sx_o = pre[1, n] - sx_i
    sxx_o = pre[2, n] - (pre[2, hi] - pre[2, lo])
    sxy_o = pre[3, n] - (pre[3, hi] - pre[3, lo])
    syy_o = pre[4, n] - syy_i
    a, b = _line(no, sy_o, sx_o, sxx_o, sxy_o)
    model = (a * length + b * sx_i) / length
    level_o = sy_o / no
    if b == 0.0 and sx_o > 0:
        # x does not spread outside: the rest cannot tell the reference's shape (a) from a flat floor (b), which
        # predict the band at level_o and at level_o x_S / x_out; the larger (the smaller rise) is taken (a
        # jammer in the reference that switched off leaves y = c x, a floor only)
        model = max(model, level_o * (sx_i / length) / (sx_o / no))
    if not model > MIN_MODEL_SHARE * level_o:
        return -np.inf, 0.0, np.inf      # the line read far from where it was fitted: no rise to measure against
    level_i = sy_i / length
    e = level_i - model
    # the error of the band's mean (relative variance v at its level) and of the line where it is read:
    # 1/no + (x_S - x_o)^2 / Sxx about x_o (none when b is fixed at 0), at the outside's level
    sxxc = sxx_o - sx_o * sx_o / no
    lever = (sx_i / length - sx_o / no) ** 2 / sxxc if b != 0.0 and sxxc > 0 else 0.0
    z = e / math.sqrt(var_group * (level_i * level_i / length + level_o * level_o * (1.0 / no + lever)))
    if not with_sse:
        return z, e / model, 0.0
    # what the two lines (outside, inside: a jammer filtered like the noise adds to a, an unfiltered one to b)
    # leave
    sxx_i = pre[2, hi] - pre[2, lo]
    sxy_i = pre[3, hi] - pre[3, lo]
    a_i, b_i = _line(length, sy_i, sx_i, sxx_i, sxy_i)
    # in units of each part's own variance (relative variance v at its level)
    sse = ((syy_o - a * sy_o - b * sxy_o) / (level_o * level_o)
           + (syy_i - a_i * sy_i - b_i * sxy_i) / (level_i * level_i)) / var_group
    return z, e / model, sse


@njit(cache=True)
def _scan(pre: np.ndarray, lengths: np.ndarray, var_group: float, frames: float, c_g: float, thr: float,
          min_rise: float, flat_sse: float, best: np.ndarray) -> bool:
    """Bands of the given lengths at every position (step 3). best[0]: the largest z of any band; best[1:5]:
    [z, rise, lo, hi] of the reportable band with the largest z (a rise of at least min_rise, one band over a
    smooth rest: step 5, sum of squares left at most flat_sse or FLAT_SHARE z^2). z is skew-corrected (step 4:
    minus ``gamma / 6 (thr^2 - 1)``, gamma the skewness of the band's summed power). True if best[1:5] improved."""
    n = pre.shape[1] - 1
    improved = False
    for length in lengths:
        shift = 2.0 / math.sqrt(length * frames / c_g) / 6.0 * (thr * thr - 1.0)
        for i in range(n - length + 1):
            z, rise, _ = _band(pre, i, i + length, var_group, False)
            z -= shift
            if z > best[0]:
                best[0] = z
            if z > best[1] and rise >= min_rise:
                sse = _band(pre, i, i + length, var_group, True)[2]
                if sse <= flat_sse or sse <= FLAT_SHARE * z * z:
                    best[1], best[2], best[3], best[4] = z, rise, i, i + length
                    improved = True
    return improved


@njit(cache=True)
def _best_band(cum: np.ndarray, kcum: np.ndarray, head: int, count: int, ref: np.ndarray, ref_frames: float,
               lengths: np.ndarray, c_g: float, factor: int, n_scales: int, min_frames: float, min_rise: float,
               flat_sse: float, thr: float) -> tuple[float, float, float, int, int, int, float]:
    """(largest z of any band, z and rise d (nepers) of the reportable band with the largest z, its first and end
    group, blocks summed) over the scales 1, factor, factor^2, ... and ``count`` blocks (the ring's cumulative
    rows; module docstring, steps 2-5; a scale of fewer than ``min_frames`` frames is skipped): the bands of
    ``lengths`` first, then every length within LENGTH_RATIO of the best reportable one at its scale."""
    n = cum.shape[1]
    lmax = lengths[-1]
    best = np.array([-np.inf, -np.inf, 0.0, 0.0, 0.0])
    best_m = 0
    pre = np.zeros((5, n + 1))
    m = 1
    for _ in range(n_scales):
        if m > count:
            m = count
        frames = _prefix(cum, kcum, head, m, ref, pre)
        if frames >= min_frames:
            if _scan(pre, lengths, c_g * (1.0 / frames + 1.0 / ref_frames), frames, c_g, thr, min_rise, flat_sse,
                     best):
                best_m = m
        if m >= count:
            break
        m *= factor
    if best_m == 0:
        return best[0], -np.inf, 0.0, 0, 0, 0, np.nan
    frames = _prefix(cum, kcum, head, best_m, ref, pre)
    length = int(best[4] - best[3])
    lo_len = max(2, int(length / LENGTH_RATIO))
    hi_len = min(lmax, int(math.ceil(length * LENGTH_RATIO)))
    _scan(pre, np.arange(lo_len, hi_len + 1), c_g * (1.0 / frames + 1.0 / ref_frames), frames, c_g, thr, min_rise,
          flat_sse, best)
    lo, hi = int(best[3]), int(best[4])
    # the newest block's own rise in that band (its J/N: a sum over m blocks holds those before a switch-on)
    rise1 = np.nan
    if _prefix(cum, kcum, head, 1, ref, pre) > 0:
        _, r1, _ = _band(pre, lo, hi, c_g * (1.0 / frames + 1.0 / ref_frames), False)
        rise1 = r1
    return best[0], best[1], math.log1p(best[2]), lo, hi, best_m, rise1
