"""RFI monitor core: identify and track a jammer in consecutive IF sample blocks (Kang et al.).

Pure module (no ROS). The node converts an ``rfi_msgs/IfSamples`` message to a numpy array and
calls ``RfiMonitor.process``; the returned ``JammerEstimate`` maps field by field onto
``rfi_msgs/JammerState``.

The monitor checks each block (shape, rate, IF, stream continuity, non-finite and clipped samples) and hands it
to its estimator (``estimate.Estimator``), chosen by ``RfiMonitorParams.estimator``:

* ``"kalman"``, the paper's (kalman_estimator module): the fused per-sample loop (``tracker.track_block``:
  three-sample IF measurement, eq. 8/10 or its complex counterpart; adaptive fading KF, eq. 11-20; LPD + AR sweep
  period, eq. 23-27; resets at the predicted sweep starts, eq. 21-22), then block features and the identification
  (``classifier``), J/N from the block power against the calibrated noise floor, and J/S = J/N + N - S from the
  nominal noise and signal powers;
* ``"stft"``, ours and the default (stft_estimator module): the short-time FFT ridge analysis of each block, the
  evidence over blocks and the spectral-step test (docs/rfi_monitor/stft_estimator.md).

What a block returns (``JammerEstimate``), the rejection reasons and J/S are defined once in the estimate module.

Noise-floor calibration ("kalman"; the "stft" estimator's reference: noise_reference module):
``noise_floor_power`` > 0 fixes the floor (sample units^2, i.e. of the
values passed to ``process``); with 0 (default) it is learned from the first
``calibration_blocks`` blocks: the front end's noise shape (median over blocks of the normalised
Welch PSD, median-smoothed across frequency so that a tone never enters it) and the floor
(median over blocks of the block power minus its narrowband excess above that shape). It is
therefore robust to a CW present during calibration, but not to a wideband jammer or a chirp
present from the first block (then set ``noise_floor_power``). Blocks during calibration are
reported as UNKNOWN. ``reset()`` keeps the calibration unless ``keep_calibration=False``.

Blocks that cannot be analysed give ``valid`` False and a ``rejection`` reason (and no type):

* ``saturated``: more than ``max_invalid_fraction`` of the samples non-finite or at full scale;
* ``blank_block``: the analysed Welch frames hold no power (below ``MIN_BLOCK_POWER``: all-zero
  samples, or non-zero samples only where the window is zero); such a block says nothing about a
  jammer, and it never enters the calibration (it would make the learned noise shape NaN). A
  calibration whose learned floor is below ``MIN_BLOCK_POWER`` (blocks of pure narrowband excess, no
  noise) is discarded and learned again (``calibrations_discarded``);
* ``power_overflow``: the block power is not finite;
* ``below_noise_floor``: the block power is more than ``BELOW_FLOOR_DB`` below the calibrated
  noise floor. The thermal noise of a working front end cannot vanish, so such a block means that
  its gain or ``scale`` no longer matches the calibration, and neither "no jammer" nor a J/N can be
  read from it;
* ``implausible_power``: the block power is more than ``MAX_POWER_JN_DB`` above the calibrated
  floor: no jammer reaches an analysed block that strongly (see the constant), so it is the
  ``scale`` or the gain that changed, and a J/N read from it would be the scale's, not a jammer's.
  When either lasts ``calibration_blocks`` blocks in a row, the learned floor is taken as wrong (e.g.
  learned while a wideband jammer was on, or the front end's gain changed for good) and learned
  again (``recalibrations``); a fixed ``noise_floor_power`` is never relearned.

J/N of a NONE block: the measured J/N (power or spectral, whichever is larger), but at least the
block's power resolution ``10 log10(sqrt(2 / n))`` dB (real; ``sqrt(1 / n)`` complex, n samples in the
Welch frames: the 1-sigma relative error of the block power). A measurement below it, including no
excess at all (minus infinity), is reported as that resolution: "J/N below x dB". A published NONE
therefore always carries a finite J/N (an upper bound of what a jammer could have), and a NaN J/S: with no jammer
there is no jammer-to-signal ratio to report (issue 27 item 5: the -2 dB that ``J/N + N - S`` gives at the
resolution was plotted as a measured J/S through the jammer-free blocks). ``jammer_to_signal_db`` is the one place
J/S is computed.

Time: ``stamp_ns`` (int, ns) is passed in and copied to the result; no clock is read.

Example
-------
>>> import numpy as np
>>> mon = RfiMonitor(RfiMonitorParams())
>>> x = np.random.default_rng(0).standard_normal(38192)
>>> est = mon.process(x, sample_rate_hz=38.192e6, intermediate_frequency_hz=9.548e6,
...                   first_sample_index=0, stamp_ns=0)
>>> est.type   # NONE: the "stft" estimator measures J/N against the block's own noise until a floor is learned
0
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

import numpy as np
from numba import njit

from rfi_monitor.analysis_worker import AnalysisWorker
from rfi_monitor.estimate import (  # noqa: F401  (re-exported: the names users import from the monitor)
    NON_FINITE,
    REF_FIXED,
    REF_IN_BLOCK,
    REF_LEARNED,
    REJECTIONS,
    Block,
    BlockCounters,
    BlockSpectrum,
    BlockTraces,
    Estimator,
    JammerEstimate,
    jammer_to_signal_db,
)
from rfi_monitor.integration import IntegratedDecision
from rfi_monitor.kalman_estimator import KalmanEstimator
from rfi_monitor.params import RfiMonitorParams
from rfi_monitor.spectral_step import StepDecision
from rfi_monitor.stft_estimator import StftEstimator


@njit(cache=True)
def _count_bad_samples(v: np.ndarray, step: int, full_scale: float) -> tuple[int, int]:
    """Non-finite samples and finite samples at or beyond full_scale (magnitude; complex: the
    larger of |I| and |Q|) of a block, in one compiled pass (speed). v: the real samples
    (step 1) or the interleaved I, Q of complex ones (step 2)."""
    n_bad = 0
    n_sat = 0
    if step == 1:
        for i in range(v.size):
            a = abs(v[i])
            fin = a < math.inf                    # False for NaN and inf
            n_bad += not fin
            n_sat += fin and a >= full_scale
    else:
        for i in range(0, v.size - 1, 2):
            a = max(abs(v[i]), abs(v[i + 1]))
            fin = math.isfinite(v[i]) and math.isfinite(v[i + 1])
            n_bad += not fin
            n_sat += fin and a >= full_scale
    return n_bad, n_sat



COARSE_BITS = 3
"""Front ends with at most this many bits per value: the J/N of a reported jammer is a lower bound (``process``)."""
FRAME_KEEP_GAP_S = 0.1
"""A gap in the sample index shorter than this, both in samples (at the sample rate) and in stamp time (from the end of
the last block to the start of this one), such as blocks a node shed on purpose because it was behind its stream or a
dropped message, keeps the "stft" estimator's frame length: a jammer's sweep does not change over a few blocks, and
the periodic choice (``stft_estimator.RESELECT_BLOCKS``, ``RESELECT_IDLE_BLOCKS``) and the choice at once when a
block shows a jammer still apply. After a longer gap (a snapshot front end, a restart) the length is chosen again on
the next block, as before. (Choosing costs about a block's analysis: choosing after every shed block made a node
behind its stream fall further behind, measured in docs/rfi_monitor/live_stream.md.) The samples of a short gap are
also charged to the integration's processing budget (``Integrator.skipped``): a node behind its stream answers blocks
before it integrates more of them. The per-sample state of the "kalman" estimator is reset at any gap."""

_COUNTERS = ("blocks", "blocks_rejected", "gaps", "rate_changes", "non_finite_samples", "saturated_samples",
             "recalibrations", "calibrations_discarded", "clipped_blocks", "frequency_not_tracked",
             "tracker_resets_invalid", "integrated_reports", "integration_window_blocks", "integration_blocks_thinned",
             "integration_switch_offs", "integration_submultiple_periods", "integration_ambiguous_periods",
             "worker_blocks", "worker_failures", "block_periods_from_integration", "block_periods_unconfirmed",
             "jn_from_envelope", "spectral_step_reports", "light_blocks", "light_escalations", "integrated_frequencies",
             "integrated_frequency_reanalyses")
"""The monitor's cumulative counters (``JammerEstimate.counters``; the estimator adds its own,
``estimate.TRACKER_COUNTERS`` and ``estimate.SPECTRAL_STEP_COUNTERS``)."""


class RfiMonitor:
    """Jammer identification and tracking over a stream of IF blocks (module docstring).

    Args:
        params: RfiMonitorParams (``estimator`` chooses the estimator).
        worker: an AnalysisWorker for the "stft" estimator's ridge analysis (analysis_worker module), or None.
        estimator: builds the estimator from (params, the monitor's counters) instead of ``params.estimator``: any
            implementation of ``estimate.Estimator`` (KalmanEstimator and StftEstimator are the two shipped).

    Notes:
        Kang et al., eq. 8-27 (kalman_estimator); see the module docstrings of if_measurement, tracking_filters,
        sweep_period, tracker and classifier for each part.
    """

    def __init__(self, params: RfiMonitorParams = RfiMonitorParams(), worker: AnalysisWorker | None = None,
                 estimator: Callable[[RfiMonitorParams, BlockCounters], Estimator] | None = None) -> None:
        self.params = params
        self.worker = worker
        self._block_counters = BlockCounters(_COUNTERS)
        self.estimator: Estimator
        """The estimator blocks are handed to."""
        if estimator is not None:
            self.estimator = estimator(params, self._block_counters)
        elif params.estimator == "kalman":
            self.estimator = KalmanEstimator(params, self._block_counters)
        else:
            self.estimator = StftEstimator(params, self._block_counters, worker)
        self._block_counters.extra.append(self.estimator.counters)
        self._last_end_ns: int | None = None
        self.reset()

    def reset(self, keep_calibration: bool = True) -> None:
        """Forget the per-sample state (call on a gap in sample index or a sample-rate change).

        Args:
            keep_calibration: keep the learned noise floor and shape (False: learn again).
        """
        self._next_index: int | None = None
        self._rate: float | None = None
        self._if: float | None = None
        self._complex: bool | None = None
        self.estimator.reset(keep_calibration)

    @property
    def calibrated(self) -> bool:
        """True once the noise floor (and shape, unless fixed) is known. The "stft" estimator does not wait
        for it (its J/N reference is the in-block noise level until then): True once a floor is fixed
        (``noise_floor_power``) or learned from ``calibration_blocks`` blocks that passed as noise."""
        return self.estimator.calibrated

    @property
    def last_step(self) -> StepDecision | None:
        """The "stft" estimator's last spectral-step decision (None: none yet, or the "kalman" estimator)."""
        return getattr(self.estimator, "last_step", None)

    @property
    def last_integration(self) -> IntegratedDecision | None:
        """The "stft" estimator's last decision of the evidence over blocks (None: none yet, or "kalman")."""
        return getattr(self.estimator, "last_integration", None)

    @property
    def last_spectrum(self) -> BlockSpectrum | None:
        """The Welch spectrum of the last block the estimator analysed in full (``estimate.BlockSpectrum``; None:
        none yet). A light analysis or a rejected block leaves the previous one (its ``stamp_ns`` says which)."""
        return getattr(self.estimator, "last_spectrum", None)

    @property
    def state_summary(self) -> dict[str, float]:
        """The "kalman" estimator's tracker state (KalmanEstimator.state_summary)."""
        if not isinstance(self.estimator, KalmanEstimator):
            raise AttributeError('state_summary: the "stft" estimator has no per-sample tracker state')
        return self.estimator.state_summary

    def _counters(self) -> Mapping[str, int]:
        return self._block_counters.snapshot()

    def process(self, samples: np.ndarray, sample_rate_hz: float, intermediate_frequency_hz: float,
                first_sample_index: int, stamp_ns: int, is_complex: bool | None = None,
                full_scale: float | None = None, return_traces: bool = False,
                bits: int | None = None, light: bool = False) -> JammerEstimate:
        """Analyse one block.

        Args:
            samples: shape (n,) real (float or int counts) or complex; or, with is_complex=True
                and a real dtype, interleaved I, Q of shape (2n,). Any consistent unit (counts or
                volts; the noise floor is in the same unit squared).
            sample_rate_hz: samples (complex: I/Q pairs) per second, > 0.
            intermediate_frequency_hz: IF, Hz; 0 complex baseband; < 0 spectral inversion (real).
            first_sample_index: running index of samples[0] since the stream started (a jump is a
                gap: the per-sample state is reset and the gap counted; ``FRAME_KEEP_GAP_S``).
            stamp_ns: time of the first sample, ns (copied to the result).
            is_complex: see samples; None: complex iff the dtype is complex.
            full_scale: largest magnitude the quantiser delivers (same unit); values at or beyond it
                count as saturated. None: no saturation check.
            return_traces: attach per-sample BlockTraces.
            bits: quantisation of the front end, bits per real value (None: unknown). With 1-3 bits the J/N
                of a reported jammer is flagged as a lower bound: a coarse quantiser compresses a strong
                jammer's power (measured: a J/N 10 dB saw-tooth added to 2-bit PocketSDR captures read
                4.9-6.5 dB), and its top level is a normal value, so no clipping is counted.
            light: a light analysis will do ("stft" estimator; a node behind its stream asks for it rather than shed
                the block): the block's Welch spectrum only, its type and J/N checked against the last full analysis
                (at most ``LIGHT_MAX_AGE_S`` older, ``LIGHT_MAX_AGE_QUIET_S`` after a NONE), whose sweep period,
                band, rate and shape it carries; a chirp's
                frequency is NaN (not tracked in this block). The block is analysed in full instead when there is no
                such analysis or the spectrum disagrees with it (a jammer appearing, leaving or changing power by
                ``LIGHT_JN_TOLERANCE_DB``): counted as ``light_escalations``; light answers as ``light_blocks``. The
                evidence over blocks, the spectral-step test and the floor learning skip light blocks.

        Returns:
            JammerEstimate.

        Raises:
            ValueError: empty/too short block, odd-length interleaved I/Q, non-finite or
                non-positive sample rate, |IF| beyond the sampled band, bad shapes.
        """
        x = np.asarray(samples)
        if x.ndim != 1:
            raise ValueError(f"samples must be 1-D, got shape {x.shape}")
        sample_rate_hz = float(sample_rate_hz)
        intermediate_frequency_hz = float(intermediate_frequency_hz)
        if not (math.isfinite(sample_rate_hz) and sample_rate_hz > 0):
            raise ValueError(f"sample_rate_hz must be finite and > 0, got {sample_rate_hz}")
        if not math.isfinite(intermediate_frequency_hz):
            raise ValueError("intermediate_frequency_hz must be finite")
        cplx = np.iscomplexobj(x) if is_complex is None else bool(is_complex)
        if cplx and not np.iscomplexobj(x):
            if x.size % 2:
                raise ValueError(f"interleaved I/Q needs an even number of values, got {x.size}")
            # a copy of the pairs as float64, seen as complex128 (the values of xf[0::2] + 1j * xf[1::2], without
            # its three temporaries; a non-finite part makes the whole sample invalid either way)
            xc = np.array(x, dtype=np.float64, order="C").view(np.complex128)
        elif cplx:
            xc = np.asarray(x, dtype=np.complex128)      # no copy when already complex128 (read only)
        elif np.iscomplexobj(x):
            raise ValueError("complex samples passed with is_complex=False")
        else:
            xc = np.asarray(x, dtype=np.float64)         # no copy when already float64 (read only)
        n = xc.size
        if n < self.params.min_block_samples:
            raise ValueError(f"block of {n} samples is shorter than min_block_samples "
                             f"{self.params.min_block_samples}")
        nyq = sample_rate_hz if cplx else sample_rate_hz / 2
        if abs(intermediate_frequency_hz) >= nyq:
            raise ValueError(f"|IF| {intermediate_frequency_hz} Hz must be below {nyq} Hz")
        if full_scale is not None and not (math.isfinite(full_scale) and full_scale > 0):
            raise ValueError("full_scale must be finite and > 0")
        # --- stream continuity ---------------------------------------------------------------
        if self._rate is not None and (sample_rate_hz != self._rate or intermediate_frequency_hz != self._if
                                       or cplx != self._complex):
            self._block_counters["rate_changes"] += 1
            self.reset(keep_calibration=False)
        elif self._next_index is not None and int(first_sample_index) != self._next_index:
            self._block_counters["gaps"] += 1
            missing = int(first_sample_index) - self._next_index
            short = (self._last_end_ns is not None and 0 < missing <= FRAME_KEEP_GAP_S * sample_rate_hz
                     and 0 <= int(stamp_ns) - self._last_end_ns <= int(FRAME_KEEP_GAP_S * 1e9))
            self.estimator.gap(missing, int(stamp_ns), short)
        self._rate, self._if, self._complex = float(sample_rate_hz), float(intermediate_frequency_hz), cplx
        self._next_index = int(first_sample_index) + n
        self._last_end_ns = int(stamp_ns) + int(round(n / sample_rate_hz * 1e9))
        self._block_counters["blocks"] += 1
        # --- bad samples ---------------------------------------------------------------------
        n_bad, n_sat = _count_bad_samples(np.ascontiguousarray(xc).view(np.float64), 2 if cplx else 1,
                                          math.inf if full_scale is None else float(full_scale))
        self._block_counters["non_finite_samples"] += n_bad
        self._block_counters["saturated_samples"] += n_sat
        clipped = n_sat / n
        if n_sat:
            self._block_counters["clipped_blocks"] += 1
        xs = xc if n_bad == 0 else np.where(np.isfinite(xc), xc, 0)
        block = Block(xs, cplx, float(sample_rate_hz), float(intermediate_frequency_hz), int(stamp_ns),
                      int(first_sample_index), clipped, full_scale, bits is not None and int(bits) <= COARSE_BITS)
        if n_bad > self.params.max_invalid_fraction * n:
            self.estimator.skip_invalid(block)
            return self._block_counters.rejected(NON_FINITE, block)
        return self.estimator.analyse(block, return_traces, light)
