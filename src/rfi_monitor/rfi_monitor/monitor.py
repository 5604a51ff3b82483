"""RFI monitor core: identify and track a jammer in consecutive IF sample blocks (Kang et al.).

Pure module (no ROS). The node converts an ``rfi_msgs/IfSamples`` message to a numpy array and
calls ``RfiMonitor.process``; the returned ``JammerEstimate`` maps field by field onto
``rfi_msgs/JammerState``.

Pipeline per block: the fused per-sample loop (``tracker.track_block``: three-sample IF
measurement, eq. 8/10 or its complex counterpart; adaptive fading KF, eq. 11-20; LPD + AR sweep
period, eq. 23-27; resets at the predicted sweep starts, eq. 21-22), then block features and the
identification (``classifier``), J/N from the block power against the calibrated noise floor,
and J/S = J/N + N - S from the nominal noise and signal powers.

Noise-floor calibration: ``noise_floor_power`` > 0 fixes the floor (sample units^2, i.e. of the
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
>>> est.type   # UNKNOWN while calibrating
4
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np
from numba import njit

from rfi_monitor import ridge as rg
from rfi_monitor import sweep_period as sp
from rfi_monitor.analysis_worker import AnalysisWorker
from rfi_monitor.classifier import (
    CHIRP,
    CW,
    CW_MIN_LINE_FRACTION,
    NONE,
    UNKNOWN,
    WIDEBAND,
    BlockFeatures,
    block_features,
    classify,
    features_from_psd,
    logistic,
    smooth_template,
    welch_psd,
)
from rfi_monitor.constant_envelope import constant_envelope_jn_db
from rfi_monitor.if_measurement import (
    STATUS_CORRECTION,
    STATUS_DOMAIN,
    STATUS_NEAR_ZERO,
    STATUS_NON_FINITE,
    STATUS_OK,
)
from rfi_monitor.integration import IntegratedDecision, Integrator
from rfi_monitor.params import RfiMonitorParams
from rfi_monitor.spectral_step import SpectralStep, StepDecision
from rfi_monitor.sweep_analysis import SweepAnalysis, analyse
from rfi_monitor.sweep_period import SweepFloat, SweepInt
from rfi_monitor.tracker import MAX_ABS_RATE, lattice_init, track_block
from rfi_monitor.tracker_state import (
    DEC_HISTORY,
    LAT_COARSE,
    MonitorFloat,
    MonitorInt,
    MonitorParam,
    new_trace_buffers,
    new_tracker_state,
)
from rfi_monitor.tracking_filters import FilterFloat


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


@dataclass(frozen=True)
class BlockTraces:
    """Per-sample estimates of one block (for figures). All shape (n,) with n = estimates made.

    Attributes:
        sample_index: absolute index of each estimate.
        z: IF measurement, cycles/sample (NaN where rejected).
        f: filter frequency, cycles/sample; df: sweep, cycles/sample^2; p11: P(1,1).
        z_ar: enhanced LPD pattern (eq. 27), held between decimated steps.
        reset: True where the filter was reset at a sweep start.
    """

    sample_index: np.ndarray
    z: np.ndarray
    f: np.ndarray
    df: np.ndarray
    p11: np.ndarray
    z_ar: np.ndarray
    reset: np.ndarray


@dataclass(frozen=True)
class JammerEstimate:
    """Result of one block; maps onto rfi_msgs/JammerState (NaN where unknown).

    Attributes:
        stamp_ns: time of the block's first sample, ns (copied from the input).
        type: NONE 0, CW 1, CHIRP 2, WIDEBAND 3, UNKNOWN 4.
        confidence: 0..1.
        jammer_to_noise_db, jammer_to_signal_db: dB.
        frequency_hz: instantaneous jammer frequency at the block end, relative to the RF centre, Hz.
        frequency_std_hz: 1-sigma of frequency_hz, Hz.
        sweep_rate_hz_per_s: Hz/s (0 for CW).
        sweep_period_s: s.
        sweep_start_frequency_hz: relative to the RF centre, Hz.
        sweep_bandwidth_hz: Hz.
        sample_rate_hz: of the analysed block.
        first_sample_index, n_samples: the block.
        valid: False when the block was rejected (then type UNKNOWN, confidence 0, NaN fields).
        counters: cumulative counts (measurement status, rejected blocks, gaps, resets).
        traces: per-sample estimates when requested, else None.
        rejection: why the block was rejected (module docstring: ``non_finite``, ``blank_block``,
            ``power_overflow``, ``below_noise_floor``, ``implausible_power``); empty when valid.
        noise_reference: REF_* code of the noise power J/N is measured against.
        jammer_to_noise_is_lower_bound: clipping limits the J/N (more than
            ``clip_lower_bound_fraction`` of the samples at full scale).
        clipped_fraction: share of the block's samples at or beyond full scale, 0..1.
        sweep_shape: ridge.SHAPE_* code (CHIRP only, else 0 = unknown).
        in_band_fraction: share of the sweep period with the jammer inside the sampled band (CHIRP with
            a period; NaN otherwise).
        light: the block had the light analysis (``process(light=True)``): type and J/N measured on its spectrum,
            the sweep fields carried from the last full analysis, ``frequency_hz`` of a chirp NaN.
    """

    stamp_ns: int
    type: int
    confidence: float
    jammer_to_noise_db: float
    jammer_to_signal_db: float
    frequency_hz: float
    frequency_std_hz: float
    sweep_rate_hz_per_s: float
    sweep_period_s: float
    sweep_start_frequency_hz: float
    sweep_bandwidth_hz: float
    sample_rate_hz: float
    first_sample_index: int
    n_samples: int
    valid: bool
    counters: Mapping[str, int]
    traces: BlockTraces | None = field(default=None, repr=False)
    rejection: str = ""
    noise_reference: int = 0
    jammer_to_noise_is_lower_bound: bool = False
    clipped_fraction: float = 0.0
    sweep_shape: int = 0
    in_band_fraction: float = math.nan
    light: bool = False


SATURATED = "saturated"
"""Former rejection of clipped blocks (no longer produced: clipped blocks are analysed)."""
NON_FINITE = "non_finite"
BLANK_BLOCK = "blank_block"
POWER_OVERFLOW = "power_overflow"
BELOW_NOISE_FLOOR = "below_noise_floor"
IMPLAUSIBLE_POWER = "implausible_power"
REJECTIONS = (NON_FINITE, BLANK_BLOCK, POWER_OVERFLOW, BELOW_NOISE_FLOOR, IMPLAUSIBLE_POWER)
"""``JammerEstimate.rejection`` reasons (module docstring)."""
BELOW_FLOOR_DB = 10.0
"""A calibrated block whose power is more than this below the noise floor is rejected, dB. The block power
of noise scatters by sqrt(2 / n) (0.2 dB at n = 1024 samples, 1 sigma) and a front end's gain drifts by a
dB or two with temperature; a 10 dB drop is a front end that no longer delivers the calibrated noise."""
MAX_POWER_JN_DB = 120.0
"""A calibrated block whose power J/N exceeds this is rejected (``implausible_power``), dB. A jammer 120 dB above
the noise floor puts at least -114 + 120 = +6 dBm into the antenna port (noise density -114 dBm/MHz, band
>= 1 MHz), beyond the 1 dB compression of GNSS low-noise amplifiers (about -20..0 dBm input) and the range of
front-end AGCs (about 60 dB): such a block would be clipped, never a clean measurement of the jammer."""
COARSE_BITS = 3
"""Front ends with at most this many bits per value: the J/N of a reported jammer is a lower bound (``process``)."""
RESELECT_BLOCKS = 64
"""The "stft" estimator chooses its frame length again every this many blocks while it reports a CW or a
chirp (choosing costs a few short-time FFTs of a slice of the block, about the cost of the analysis)."""
RESELECT_IDLE_BLOCKS = 16
"""... and every this many blocks while it reports neither (a jammer that appears is analysed at its best
frame length from at most this many blocks later; before that at the current one, which mostly sees it too, and
a block that shows anything at all makes it choose again at once). 4 before the speed work of issue 14 item 6:
choosing costs about 0.8 ms at 38.192 MS/s, 0.2 ms per quiet block at 4; on noise the choice is now the longest
frame whatever the block (ridge.choose_frame_length), so choosing often bought nothing there."""
FRAME_KEEP_GAP_S = 0.1
"""A gap in the sample index shorter than this, both in samples (at the sample rate) and in stamp time (from the end
of the last block to the start of this one), such as blocks a node shed on purpose because it was behind its stream
or a dropped message, keeps the "stft" estimator's frame length: a jammer's sweep does not change over a few
blocks, and the periodic choice (``RESELECT_BLOCKS``, ``RESELECT_IDLE_BLOCKS``) and the choice at once when a
block shows a jammer still apply. After a longer gap (a snapshot front end, a restart) the length is chosen again
on the next block, as before. (Choosing costs about a block's analysis: choosing after every shed block made a
node behind its stream fall further behind, measured in docs/rfi_monitor/live_stream.md.) The samples of a short
gap are also charged to the integration's processing budget (``Integrator.skipped``): a node behind its stream
answers blocks before it integrates more of them. The per-sample state of the "kalman" estimator is reset at any
gap."""
ENVELOPE_MIN_IN_BAND = 0.9
"""The J/N of a chirp with an in-block noise reference is also read from the block's moments
(``constant_envelope``) only when the chirp is in band for at least this share of its period: a sweep that leaves
the band is pulsed in band, not of constant envelope (its estimate would err low, and the spectral one is kept
anyway; this spares the cost)."""
HOOK_RECHECK_S = 0.1
"""While the "stft" estimator tracks a chirp, the sample-resolution hook test of a saw-tooth (``ridge.fine_profile``:
0.3-1.4 ms per block, as much as the rest of a tracking block's analysis) runs on at most one block per this many
seconds of stamps; the blocks in between keep its verdict for a saw-tooth of the same period (within
``SUBHARMONIC_TOLERANCE``): a jammer's sweep shape does not change within a tenth of a second, and a hook is a
property of the sweep, not of a block. Any block that starts a track, and any change of period, is tested again."""
MIN_BLOCK_POWER = 1e-60
"""Smallest block power analysed, sample units^2 (1e-30 rms): below it the block is blank. The Welch PSD is
computed in single precision, whose numbers lose precision below 1.2e-38 (subnormal) and end at 1.4e-45;
no unit a front end reports in (volts, full scale, counts) comes near."""

APERIODIC_MARGIN_DB = 3.0
"""A moving ridge without a period in the block (ridge: present in half the frames, coherent, over >= 4 bins) is a
chirp only from ``detect_jn_db`` minus this, dB (the in-block J/N of sweeps reads up to 1.3 dB low). On the whole
real clean captures in 1024-sample blocks (few frames) such ridges appeared by chance at J/N -16 to -5 dB (5 of
3,139 blocks, 3 of them below -9 dB); a periodic ridge (a 7-sigma period) needs no level."""
REF_IN_BLOCK, REF_LEARNED, REF_FIXED = 0, 1, 2
"""J/N references, identical to rfi_msgs/JammerState.REF_*: the noise level measured inside the block
(ridge module, step 2), the floor learned from earlier blocks that passed as noise, the configured one
(``noise_floor_power`` or ``noise_floor_dbfs``)."""

_STATUS_NAMES = {STATUS_OK: "measurements_ok", STATUS_NEAR_ZERO: "rejected_near_zero",
                 STATUS_DOMAIN: "rejected_arccos_domain", STATUS_NON_FINITE: "rejected_non_finite",
                 STATUS_CORRECTION: "rejected_chirp_correction"}


SUBHARMONIC_TOLERANCE = 0.02
"""A block's ridge period within this fraction of an integer multiple (>= 3; 2 for a block below the detection J/N)
of the period the evidence over blocks found is that multiple (a sub-harmonic lock), not a second jammer."""


PERIOD_CONFIRM_MARGIN_DB = 3.0
"""A block's own sweep period is published unconfirmed only from ``detect_jn_db`` + this J/N. Below, it must agree
with the evidence over blocks' period when there is one, else, from ``detect_jn_db`` on, with one of the last
``PERIOD_HISTORY`` blocks' own periods (within ``PERIOD_AGREEMENT``; consecutive weak blocks can agree on twice the
period, so the window's period, when there is one, decides).
Measured (3 rates x 6 periods x 3 J/N, saw-tooths, I/Q): before, 14 of 2,036 published periods were 1.1-100 % off, all
from single blocks at J/N -5 dB, just above the detection level, mostly isolated among right ones; after, 0 of 2,002
(the window's period agreeing within PERIOD_AGREEMENT, not SUBHARMONIC_TOLERANCE: 2 of 2,004, 1.1 and 1.3 % off)."""
PERIOD_HISTORY = 4
"""Recent blocks' own periods kept for the confirmation above (stamped within PERIOD_HISTORY_S)."""
PERIOD_HISTORY_S = 1.0
"""How old a recent block's period may be to confirm another's, s of stamps."""
PERIOD_AGREEMENT = 0.01
"""Relative agreement of two blocks' own periods that confirms them (the issue's 1 % goal)."""


def _agrees(period: float, base: float, tolerance: float = SUBHARMONIC_TOLERANCE) -> bool:
    """Whether period is within tolerance (relative) of base (False when either is not finite)."""
    ok = math.isfinite(period) and math.isfinite(base) and base > 0
    return ok and abs(period - base) <= tolerance * base


def _multiple(period: float, base: float) -> int:
    """m if period is an integer multiple m >= 2 of base within SUBHARMONIC_TOLERANCE (relative), else 0."""
    if not (math.isfinite(period) and math.isfinite(base) and base > 0):
        return 0
    m = round(period / base)
    return m if m >= 2 and abs(period - m * base) <= SUBHARMONIC_TOLERANCE * m * base else 0


LIGHT_MAX_AGE_S = 0.01
"""A light analysis (``RfiMonitor.process(light=True)``) carries the last full analysis of a jammer only if that block
is stamped at most this long before, s: a jammer's type, sweep period, band and shape do not change within 10 ms, and
a node behind its stream analyses a block in full at least this often while it reports one (the light path
escalates itself when the last full analysis is older)."""
LIGHT_MAX_AGE_QUIET_S = 0.05
"""... and of a block without a jammer (NONE), s. A quiet block's full analysis costs most (the evidence over blocks
decides with it: 3-5 ms at 38.192 MS/s on a 2-vCPU AMD EPYC, against 1 ms for a tracked chirp's), so one in 10 would
keep a node behind its stream behind (measured in live_stream.md); a jammer that appears is seen by the light
analysis itself from ``detect_jn_db`` - ``LIGHT_NONE_MARGIN_DB``, a weaker one by the next full analysis, at most
this much later."""
LIGHT_JN_TOLERANCE_DB = 3.0
"""A light analysis of a block whose jammer's power J/N moved more than this from the last full analysis's escalates
to a full analysis, dB (a jammer switching on, off, or changing: twice the 1-sigma scatter of a weak jammer's block
J/N at the common front ends)."""
LIGHT_NONE_MARGIN_DB = 3.0
"""... and a block after a NONE answer escalates from ``detect_jn_db`` minus this (power or spectral J/N), dB: what the
light path cannot see (a sweep the ridge analysis finds below the detection J/N) is left to the next full block."""


@dataclass(frozen=True)
class _LastFull:
    """What a light analysis carries (RfiMonitor._identify_light): the last fully analysed block's estimate, its block
    power, the noise power its J/N was measured against, its power J/N (dB) and the digital frequency of its spectral
    peak (cycles per sample), whether the estimate came from the evidence over blocks, and the stream it was on."""

    est: JammerEstimate
    power: float
    noise: float
    jn_power_db: float
    peak: float
    integrated: bool
    fs: float
    cplx: bool


@dataclass
class _Ahead:
    """A block's ridge analysis started on the worker (RfiMonitor._identify_stft): on the last ``size`` samples,
    at ``frame_length`` (0: the worker chose it on the whole block first); its answer once collected."""

    size: int
    frame_length: int
    result: rg.RidgeResult | None = None
    collected: bool = False



def jammer_to_signal_db(jtype: int, jn_db: float, fs: float, cplx: bool, params: RfiMonitorParams) -> float:
    """J/S of a block from its J/N and the nominal powers: ``J/S = J/N + N - S`` (dB), N the nominal noise density
    ``noise_density_dbm_per_mhz`` over ``noise_bandwidth_hz`` (0: the sampled band, fs real / 2 or fs complex), S
    ``signal_power_dbm`` (Kang et al. give J/S against S = -130 dBm and N = -114 dBm/MHz, Sec. 4).

    NaN when the type is NONE (no jammer: no J/S, module docstring; consumers read type NONE as "no jammer") or the
    J/N is not finite.

    Args:
        jtype: the block's type (NONE, CW, CHIRP, WIDEBAND, UNKNOWN).
        jn_db: its J/N, dB.
        fs: sample rate, Hz; cplx: complex samples.
        params: the monitor's parameters (nominal powers, noise bandwidth).
    """
    if jtype == NONE or not math.isfinite(jn_db):
        return math.nan
    p = params
    bw_noise = p.noise_bandwidth_hz if p.noise_bandwidth_hz > 0 else (fs if cplx else fs / 2)
    n_dbm = p.noise_density_dbm_per_mhz + 10 * math.log10(bw_noise / 1e6)
    return jn_db + n_dbm - p.signal_power_dbm

class RfiMonitor:
    """Jammer identification and tracking over a stream of IF blocks.

    Args:
        params: RfiMonitorParams.

    Notes:
        Kang et al., eq. 8-27; see the module docstrings of if_measurement, tracking_filters,
        sweep_period, tracker and classifier for each part.
    """

    def __init__(self, params: RfiMonitorParams = RfiMonitorParams(), worker: AnalysisWorker | None = None) -> None:
        self.params = params
        self.worker = worker
        """An AnalysisWorker that runs the "stft" estimator's ridge analysis beside the rest of each block (the
        analysis_worker module; the results are the same with or without it), or None."""
        self._tpar = params.tracker.as_array()
        self._packed: dict[bool, tuple[np.ndarray, np.ndarray]] = {}
        self._block_counters = {"blocks": 0, "blocks_rejected": 0, "gaps": 0, "rate_changes": 0,
                                "non_finite_samples": 0, "saturated_samples": 0, "recalibrations": 0,
                                "calibrations_discarded": 0, "clipped_blocks": 0, "frequency_not_tracked": 0,
                                "tracker_resets_invalid": 0, "integrated_reports": 0,
                                "integration_window_blocks": 0, "integration_blocks_thinned": 0,
                                "integration_switch_offs": 0, "integration_submultiple_periods": 0,
                                "integration_ambiguous_periods": 0,
                                "worker_blocks": 0, "worker_failures": 0, "block_periods_from_integration": 0,
                                "block_periods_unconfirmed": 0, "jn_from_envelope": 0,
                                "spectral_step_reports": 0, "light_blocks": 0, "light_escalations": 0}
        self._last_full: _LastFull | None = None
        self._full_levels: tuple[float, float, float, bool] | None = None
        self._integrator = Integrator(params.integration, params.classifier.detect_jn_db)
        self._step = SpectralStep(params.spectral_step, params.classifier.nfft)
        self.last_step: StepDecision | None = None
        self.last_integration: IntegratedDecision | None = None
        self._last_single = NONE
        self._off_floor_run = 0
        self._cal_psd: list[np.ndarray] = []
        self._cal_pow: list[float] = []
        self._template: np.ndarray | None = None
        self._floor: float = params.noise_floor_power if params.noise_floor_power > 0 else math.nan
        self._cal_key: tuple | None = None
        self._learn_pow: list[float] = []
        self._learn_psd: list[np.ndarray] = []
        self._lfloor = math.nan
        self._ltemplate: np.ndarray | None = None
        self._learn_since_tpl = 0
        self._frame_length = 0
        self._blocks_since_select = 0
        self._tracking = False
        self._chirp = False
        self._last_end_ns: int | None = None
        self._int_period: tuple[float, int] | None = None
        self._block_periods: deque[tuple[float, int]] = deque(maxlen=PERIOD_HISTORY)
        self._hook_memory: tuple[float, bool, int] | None = None   # (period, hooked, stamp) of the last hook test
        self.reset()

    # ------------------------------------------------------------------------------------------
    def reset(self, keep_calibration: bool = True) -> None:
        """Forget the per-sample state (call on a gap in sample index or a sample-rate change).

        Args:
            keep_calibration: keep the learned noise floor and shape (False: learn again).
        """
        fst, ist, ring = self.params.tracker.initial_state()
        self._state = new_tracker_state(fst, ist, ring, sp.initial_state())
        self._analysis: SweepAnalysis | None = None
        self._stream_first: int | None = None
        self._next_index: int | None = None
        self._rate: float | None = None
        self._if: float | None = None
        self._complex: bool | None = None
        if not keep_calibration:
            self._hook_memory = None   # a new stream; a gap (shed blocks) keeps it: the sweep is the same
            self._integrator.reset()
            self._step.reset()
            self._int_period = None
            self._block_periods.clear()
            self._forget_calibration()
            self._cal_key = None
            self._forget_learned()
            self._last_full = None
        self._frame_length = 0

    def _forget_learned(self) -> None:
        self._learn_pow, self._learn_psd = [], []
        self._lfloor, self._ltemplate = math.nan, None
        self._learn_since_tpl = 0

    def _reset_tracker(self) -> None:
        """Fresh per-sample tracker state (stream position and calibration kept)."""
        fst, ist, ring = self.params.tracker.initial_state()
        self._state = new_tracker_state(fst, ist, ring, sp.initial_state())
        self._analysis = None
        self._stream_first = None

    @property
    def calibrated(self) -> bool:
        """True once the noise floor (and shape, unless fixed) is known. The "stft" estimator does not wait
        for it (its J/N reference is the in-block noise level until then): True once a floor is fixed
        (``noise_floor_power``) or learned from ``calibration_blocks`` blocks that passed as noise."""
        if self.params.estimator == "stft":
            return self.params.noise_floor_power > 0 or math.isfinite(self._lfloor)
        return math.isfinite(self._floor) and self._template is not None

    # ------------------------------------------------------------------------------------------
    def _counters(self) -> Mapping[str, int]:
        d = dict(self._block_counters)
        for code, name in _STATUS_NAMES.items():
            d[name] = int(self._state.counters[code])
        d["sweep_resets"] = int(self._state.mist[MonitorInt.NRESETS])
        d["sweep_start_fits"] = int(self._state.mist[MonitorInt.NFIT])
        d["period_search_suspensions"] = int(self._state.mist[MonitorInt.NSUSP])
        d["spectral_step_not_flat"] = self._step.not_flat
        d["spectral_step_relearned"] = self._step.relearned
        return MappingProxyType(d)

    def _js_db(self, jtype: int, jn_db: float, fs: float, cplx: bool) -> float:
        """J/S of a block: :func:`jammer_to_signal_db` with this monitor's nominal powers."""
        return jammer_to_signal_db(jtype, jn_db, fs, cplx, self.params)

    def _to_rel_hz(self, f_dig: float, fs: float, fif: float, cplx: bool) -> float:
        if not cplx and fif < 0:
            return -fif - f_dig * fs
        return f_dig * fs - fif

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
            xf = x.astype(np.float64)
            xc = xf[0::2] + 1j * xf[1::2]
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
        key = (float(sample_rate_hz), float(intermediate_frequency_hz), cplx)
        if self._rate is not None and (sample_rate_hz != self._rate or intermediate_frequency_hz != self._if
                                       or cplx != self._complex):
            self._block_counters["rate_changes"] += 1
            self.reset(keep_calibration=False)
        elif self._next_index is not None and int(first_sample_index) != self._next_index:
            self._block_counters["gaps"] += 1
            length, missing = self._frame_length, int(first_sample_index) - self._next_index
            short = (self._last_end_ns is not None and 0 < missing <= FRAME_KEEP_GAP_S * sample_rate_hz
                     and 0 <= int(stamp_ns) - self._last_end_ns <= int(FRAME_KEEP_GAP_S * 1e9))
            self.reset(keep_calibration=True)
            if short:
                self._frame_length = length      # FRAME_KEEP_GAP_S
                if self.params.estimator == "stft":
                    self._integrator.skipped(missing, int(stamp_ns))
        self._rate, self._if, self._complex = float(sample_rate_hz), float(intermediate_frequency_hz), cplx
        self._next_index = int(first_sample_index) + n
        self._last_end_ns = int(stamp_ns) + int(round(n / sample_rate_hz * 1e9))
        self._block_counters["blocks"] += 1
        if self._cal_key is None:
            self._cal_key = key
        # --- bad samples ---------------------------------------------------------------------
        n_bad, n_sat = _count_bad_samples(np.ascontiguousarray(xc).view(np.float64), 2 if cplx else 1,
                                          math.inf if full_scale is None else float(full_scale))
        self._block_counters["non_finite_samples"] += n_bad
        self._block_counters["saturated_samples"] += n_sat
        clipped = n_sat / n
        if n_sat:
            self._block_counters["clipped_blocks"] += 1
        if n_bad > self.params.max_invalid_fraction * n:
            if self.params.estimator == "kalman":
                self._run_chunks(np.where(np.isfinite(xc), xc, 0), cplx, int(first_sample_index),
                                 float(sample_rate_hz), False)
            return self._rejected(NON_FINITE, int(stamp_ns), float(sample_rate_hz), int(first_sample_index), n,
                                  None)
        xs = xc if n_bad == 0 else np.where(np.isfinite(xc), xc, 0)
        if self.params.estimator == "stft":
            coarse = bits is not None and int(bits) <= COARSE_BITS
            if light:
                est = self._identify_light(xs, cplx, float(sample_rate_hz), float(intermediate_frequency_hz),
                                           int(stamp_ns), int(first_sample_index), clipped, full_scale, coarse)
                if est is not None:
                    return est
                self._block_counters["light_escalations"] += 1
            est = self._identify_stft(xs, cplx, float(sample_rate_hz), float(intermediate_frequency_hz),
                                      int(stamp_ns), int(first_sample_index), clipped, full_scale, coarse)
            levels, self._full_levels = self._full_levels, None
            self._last_full = None
            if est.valid and levels is not None:
                power, noise, peak, integrated = levels
                jn_pow = 10 * math.log10(power / noise - 1.0) if power > noise > 0 else -math.inf
                self._last_full = _LastFull(est, power, noise, jn_pow, peak, integrated, float(sample_rate_hz), cplx)
            return est
        # --- per-sample loop (always run: keeps the state continuous) ---------------------------
        resets_before = int(self._state.mist[MonitorInt.NRESETS])
        if self._stream_first is None:
            self._stream_first = int(first_sample_index)
        traces = self._run_chunks(xs, cplx, int(first_sample_index), float(sample_rate_hz), return_traces)
        self._resets_in_block = int(self._state.mist[MonitorInt.NRESETS]) - resets_before
        est = self._identify(xs, cplx, float(sample_rate_hz), float(intermediate_frequency_hz),
                             int(stamp_ns), int(first_sample_index), traces)
        lower = clipped > self.params.clip_lower_bound_fraction or (bits is not None and int(bits) <= COARSE_BITS)
        ref = REF_FIXED if self.params.noise_floor_power > 0 else REF_LEARNED
        return dataclasses.replace(est, noise_reference=ref, jammer_to_noise_is_lower_bound=lower and est.valid,
                                   clipped_fraction=clipped)

    # ------------------------------------------------------------------------------------------
    def _run_chunks(self, xc: np.ndarray, cplx: bool, first: int, fs: float, store: bool) -> BlockTraces | None:
        """Run the fused loop, stopping at absolute analysis boundaries (multiples of the hop) to run
        the periodicity detector, so that the result does not depend on how the stream is cut."""
        ap = self.params.analysis
        if not ap.enabled:
            return self._run_tracker(xc, cplx, first, store)
        hop = max(1, int(round(ap.hop_s * fs)))
        n = xc.size
        cuts = [0]
        b = (first // hop + 1) * hop
        while b <= first + n:
            cuts.append(b - first)
            b += hop
        if cuts[-1] != n:
            cuts.append(n)
        parts = []
        for i0, i1 in zip(cuts[:-1], cuts[1:], strict=False):
            if i1 <= i0:
                continue
            parts.append(self._run_tracker(xc[i0:i1], cplx, first + i0, store))
            if (first + i1) % hop == 0:
                # tracking mode (confirmed lattice): the detector has nothing to seed, and the
                # identification takes the confirmed lattice as the periodicity evidence
                if not (ap.skip_while_tracking and int(self._state.mist[MonitorInt.TRACK]) == 1):
                    self._run_analysis(first + i1)
        if not store:
            return None
        tr = [p for p in parts if p is not None]
        return BlockTraces(*(np.concatenate([getattr(t, name) for t in tr]) for name in
                             ("sample_index", "z", "f", "df", "p11", "z_ar", "reset")))

    def _run_analysis(self, at_index: int) -> None:
        """Periodicity detector on the decimated history; seeds the reset lattice when none runs."""
        st = self._state
        dec = int(self.params.sweep.decimation)
        ndec = int(st.mist[MonitorInt.NDEC])
        L = min(ndec, DEC_HISTORY)
        if L < self.params.analysis.min_window or self._stream_first is None:
            return
        idx = np.arange(ndec - L, ndec) & (DEC_HISTORY - 1)
        w = st.zdec[idx]
        # decimated value k averages measurements of samples m_first + k D .. + D - 1
        m_first = self._stream_first + 1
        first_centre = m_first + (ndec - L) * dec + 0.5 * (dec - 1)
        a = analyse(w, dec, first_centre, at_index, self.params.analysis)
        self._analysis = a
        if (a.periodic and self.params.refine_window > 0 and self.params.reset_at_sweep_start
                and st.mst[MonitorFloat.NEXT] < 0.0):
            per = a.period_samples
            k = math.ceil((at_index - a.start_index) / per)
            st.mst[MonitorFloat.NEXT] = a.start_index + k * per
            st.mst[MonitorFloat.TLAT] = per
            st.mist[MonitorInt.LATSRC] = LAT_COARSE
            l11, l12, l22 = lattice_init(per, float(self.params.refine_window))
            st.mst[MonitorFloat.L11], st.mst[MonitorFloat.L12], st.mst[MonitorFloat.L22] = l11, l12, l22
            st.mist[MonitorInt.MISSES] = 0
            st.mist[MonitorInt.NCONS] = 0
            st.mist[MonitorInt.FITAT] = -1
            if int(st.mist[MonitorInt.NRESETS]) == 0:
                st.mist[MonitorInt.LAST_START] = int(math.floor(st.mst[MonitorFloat.NEXT] - per))

    def _packed_params(self, cplx: bool) -> tuple[np.ndarray, np.ndarray]:
        """Packed sweep-period and monitor parameters of the fused loop for real / complex input
        (built once per kind: the parameters are frozen)."""
        packed = self._packed.get(cplx)
        if packed is not None:
            return packed
        p = self.params
        band = 1.0 if cplx else 0.5
        spar = p.sweep.as_array(band)
        mpar = np.zeros(len(MonitorParam))
        mpar[MonitorParam.CHIRP_CORR] = 1.0 if (p.chirp_correction and not cplx) else 0.0
        mpar[MonitorParam.MIN_ABS] = p.min_abs_ratio
        mpar[MonitorParam.DOMAIN] = p.domain_margin
        mpar[MonitorParam.POW_LAMBDA] = 1.0 / p.power_time_constant
        mpar[MonitorParam.RESET] = 1.0 if p.reset_at_sweep_start else 0.0
        mpar[MonitorParam.PHASE_GAIN] = p.phase_gain
        mpar[MonitorParam.WRAP] = 1.0 if cplx else 0.0
        mpar[MonitorParam.MAX_DF] = MAX_ABS_RATE
        mpar[MonitorParam.REFINE_W] = float(p.refine_window)
        mpar[MonitorParam.LAT_DRIFT] = p.lattice_period_drift
        mpar[MonitorParam.NOISE_COMP] = 1.0 if (p.noise_compensation and not cplx) else 0.0
        mpar[MonitorParam.RESET_CROSS] = 1.0 if p.reset_cross_covariance else 0.0
        mpar[MonitorParam.CONFIRM] = float(p.confirm_fits)
        self._packed[cplx] = (spar, mpar)
        return spar, mpar

    def _run_tracker(self, xc: np.ndarray, cplx: bool, first: int, store: bool) -> BlockTraces | None:
        st = self._state
        spar, mpar = self._packed_params(cplx)
        out = new_trace_buffers(xc.size) if store else None
        xr = np.ascontiguousarray(xc.real, dtype=np.float64)
        xi = np.ascontiguousarray(xc.imag, dtype=np.float64) if cplx else xr
        st.mst[MonitorFloat.FLOOR] = self._floor if math.isfinite(self._floor) else 0.0
        k = track_block(xr, xi, cplx, first, self._tpar, spar, mpar, st, out)
        if out is None:
            return None
        return BlockTraces(out.idx[:k], out.z[:k], out.f[:k], out.df[:k], out.p11[:k], out.zar[:k], out.reset[:k])

    def _rejected(self, reason: str, stamp_ns: int, fs: float, first: int, n: int,
                  traces: BlockTraces | None) -> JammerEstimate:
        """The result of a block that is not analysed: valid False, UNKNOWN, confidence 0, NaN fields."""
        self._block_counters["blocks_rejected"] += 1
        nan = math.nan
        return JammerEstimate(stamp_ns, UNKNOWN, 0.0, nan, nan, nan, nan, nan, nan, nan, nan, fs, first, n, False,
                              self._counters(), traces, reason)

    def _forget_calibration(self) -> None:
        """Learn the noise floor (unless fixed) and shape again from the next blocks."""
        self._cal_psd, self._cal_pow, self._template = [], [], None
        self._floor = self.params.noise_floor_power if self.params.noise_floor_power > 0 else math.nan
        self._off_floor_run = 0

    def _identify(self, xs: np.ndarray, cplx: bool, fs: float, fif: float, stamp_ns: int, first: int,
                  traces: BlockTraces | None) -> JammerEstimate:
        p = self.params
        cp = p.classifier
        st = self._state
        nan = math.nan
        # while calibrating the template is None (flat), as block_features needs it then
        feat = block_features(xs, self._template, cp)
        if not math.isfinite(feat.power):
            return self._rejected(POWER_OVERFLOW, stamp_ns, fs, first, xs.size, traces)
        if not feat.power >= MIN_BLOCK_POWER:
            return self._rejected(BLANK_BLOCK, stamp_ns, fs, first, xs.size, traces)
        if self.calibrated:
            off_floor = None
            if feat.power < self._floor * 10 ** (-BELOW_FLOOR_DB / 10):
                off_floor = BELOW_NOISE_FLOOR
            elif feat.power > self._floor * 10 ** (MAX_POWER_JN_DB / 10):
                off_floor = IMPLAUSIBLE_POWER
            if off_floor is not None:
                self._off_floor_run += 1
                if self._off_floor_run >= p.calibration_blocks and not p.noise_floor_power > 0:
                    self._block_counters["recalibrations"] += 1
                    self._forget_calibration()
                return self._rejected(off_floor, stamp_ns, fs, first, xs.size, traces)
        self._off_floor_run = 0
        if not self.calibrated:
            self._cal_psd.append(feat.psd / feat.psd.sum())
            self._cal_pow.append(feat.power)
            if len(self._cal_psd) >= p.calibration_blocks:
                med = np.median(np.stack(self._cal_psd), axis=0)
                self._template = smooth_template(med, cp.template_smooth_bins)
                if not math.isfinite(self._floor):
                    # floor = median over blocks of (power - narrowband excess above the shape)
                    resid = []
                    for psd in self._cal_psd:
                        white = psd / self._template
                        s = float(np.median(white))
                        exc = np.sum(np.maximum(white - s * (1 + cp.min_excess), 0.0) * self._template)
                        resid.append(max(1.0 - exc, 0.0))
                    self._floor = float(np.median(np.array(self._cal_pow) * np.array(resid)))
                    if not (math.isfinite(self._floor) and self._floor >= MIN_BLOCK_POWER):
                        # the blocks were all narrowband excess (no noise seen): nothing to measure J/N against
                        self._block_counters["calibrations_discarded"] += 1
                        self._forget_calibration()
            return JammerEstimate(stamp_ns, UNKNOWN, 0.5, nan, nan, nan, nan, nan, nan, nan, nan, fs, first,
                                  xs.size, True, self._counters(), traces)
        jn_pow = 10 * math.log10(feat.power / self._floor - 1.0) if feat.power > self._floor else -math.inf
        locked = bool(st.si[SweepInt.LOCKED] == 1)
        df = float(st.fst[FilterFloat.DF])
        # a chirp's swept band |df| T must explain the occupied band (a lock on noise peaks does not)
        band = 1.0 if cplx else 0.5
        per_s = float(st.sf[SweepFloat.PERIOD])
        lattice = float(st.mst[MonitorFloat.NEXT]) >= 0.0 and int(st.mist[MonitorInt.LATSRC]) > 0
        if lattice and float(st.mst[MonitorFloat.TLAT]) > 0:
            per_s = float(st.mst[MonitorFloat.TLAT])
        swept = abs(df) * per_s if per_s > 0 else 0.0
        chirp_ok = (locked or lattice or self._resets_in_block > 0) and swept >= 0.5 * feat.occupancy * band
        an = self._analysis
        hop = max(1, int(round(p.analysis.hop_s * fs)))
        periodic = (p.analysis.enabled and an is not None and an.periodic
                    and an.sample_index >= first + xs.size - 2 * hop)
        if int(st.mist[MonitorInt.TRACK]) == 1:
            # tracking mode: confirm_fits significant sweep-start steps in a row at the lattice's
            # period are the periodicity evidence (the detector may not run then)
            chirp_ok = True
        if periodic and an is not None:
            chirp_ok = True
            if not (locked or lattice):
                per_s = an.period_samples
        locked = locked or lattice or periodic
        jtype, conf = classify(feat, jn_pow, chirp_ok, df, True, cp)
        jn = max(jn_pow, feat.jn_spectral_db)
        if jtype == NONE:
            # at least the block power's resolution (module docstring): a NONE never carries a NaN J/N
            jn = max(jn, 5.0 * math.log10((1.0 if cplx else 2.0) / (feat.frames * cp.nfft)))
        js = self._js_db(jtype, jn, fs, cplx)
        freq = fstd = rate = per = f0 = bw = nan
        if jtype in (CW, CHIRP):
            freq = self._to_rel_hz(float(st.fst[FilterFloat.F]), fs, fif, cplx)
            fstd = math.sqrt(max(float(st.fst[FilterFloat.P11]), 0.0)) * fs
            sgn = -1.0 if (not cplx and fif < 0) else 1.0
            if jtype == CW:
                # the three-sample measurement is biased towards fs/4 at low J/N (arccos of a
                # noisy ratio, clipped tails), so a CW's frequency comes from the interpolated
                # Welch peak; its 1-sigma is taken as one bin / sqrt(12)
                freq = self._to_rel_hz(feat.peak_frequency, fs, fif, cplx)
                fstd = fs / cp.nfft / math.sqrt(12.0)
                rate = 0.0
            else:
                f_dig = float(st.fst[FilterFloat.F])
                lo_dig = -0.5 if cplx else 0.0
                if not (lo_dig <= f_dig <= 0.5 and math.isfinite(fstd) and fstd < 0.25 * fs
                        and abs(df) < 0.5):
                    # a run-away track (outside the sampled band, or a std no measurement supports):
                    # never published as valid; the per-sample tracker starts again (issue 14 item 4)
                    self._block_counters["tracker_resets_invalid"] += 1
                    self._block_counters["frequency_not_tracked"] += 1
                    self._reset_tracker()
                    return JammerEstimate(stamp_ns, int(jtype), float(conf), float(jn), float(js), nan, nan, nan,
                                          nan, nan, nan, fs, first, xs.size, True, self._counters(), traces)
                rate = sgn * df * fs * fs
                if locked:
                    per = per_s / fs
                    bw = abs(rate) * per
                    if math.isfinite(st.mst[MonitorFloat.F0]):
                        f0 = self._to_rel_hz(float(st.mst[MonitorFloat.F0]), fs, fif, cplx)
        if not math.isfinite(jn):
            jn = nan
        return JammerEstimate(stamp_ns, int(jtype), float(conf), float(jn), float(js), freq, fstd, rate, per,
                              f0,
                              bw, fs, first, xs.size, True, self._counters(), traces)

    # ------------------------------------------------------------------------------------------
    def _reference(self, fs: float, cplx: bool, full_scale: float | None, inblock: float) -> tuple[float, int]:
        """(noise power, REF_* code) J/N is measured against (module docstring, "stft")."""
        p = self.params
        if p.noise_floor_power > 0:
            return p.noise_floor_power, REF_FIXED
        if p.noise_floor_dbfs < 0 and full_scale is not None:
            return (2.0 if cplx else 1.0) * full_scale ** 2 * 10 ** (p.noise_floor_dbfs / 10), REF_FIXED
        if math.isfinite(self._lfloor):
            return self._lfloor, REF_LEARNED
        return inblock, REF_IN_BLOCK

    def _identify_stft(self, xs: np.ndarray, cplx: bool, fs: float, fif: float, stamp_ns: int, first: int,
                       clipped: float, full_scale: float | None, coarse: bool = False) -> JammerEstimate:
        """Identification and estimates of the "stft" estimator (module docstring). With a worker (constructor),
        the block's ridge analysis starts there first, on the part of the block and at the frame length this
        process would use (when the frame length is due to be chosen again, the worker chooses it on the whole
        block first, as here); the result is used only if this process then analyses that part at that length,
        as it would have done itself (analysis_worker module docstring)."""
        w = self.worker
        ahead = None
        if w is not None and w.alive:
            due = self._frame_length == 0 or self._blocks_since_select >= (RESELECT_BLOCKS if self._tracking
                                                                             else RESELECT_IDLE_BLOCKS)
            tail = self._part_samples(xs.size)
            if w.submit(xs, cplx, fs, self.params.ridge, 0 if due else self._frame_length, tail,
                        fine_hook=self._hook_test_due(stamp_ns)):
                ahead = _Ahead(tail if tail else xs.size, 0 if due else self._frame_length)
        try:
            return self._identify_stft_block(xs, cplx, fs, fif, stamp_ns, first, clipped, full_scale, coarse, ahead)
        finally:
            if w is not None:
                w.cancel()               # not used (an early return, or another length or part): dropped
                self._block_counters["worker_failures"] = w.failures

    def _identify_light(self, xs: np.ndarray, cplx: bool, fs: float, fif: float, stamp_ns: int, first: int,
                        clipped: float, full_scale: float | None, coarse: bool) -> JammerEstimate | None:
        """The light analysis of a block (``process(light=True)``), or None when the block needs the full one.

        The block's Welch PSD gives its power, its J/N against the reference of the last full analysis and its
        spectral features (the first steps of the full analysis, docs/rfi_monitor/stft_estimator.md). The answer
        keeps the last full analysis's type when the block agrees with it:

        * NONE (or a jammer found only by the evidence over blocks): neither the power J/N (against the floor, or
          before one is learned against the last full analysis's in-block noise level) nor the spectral J/N reaches
          ``detect_jn_db`` - ``LIGHT_NONE_MARGIN_DB``;
        * CW: the block still shows a narrow line (the full analysis's CW rule) within two bins of the last one's;
          its frequency is this block's spectral peak, as in the full analysis;
        * CHIRP, WIDEBAND: the block power's J/N against the last full analysis's noise power is within
          ``LIGHT_JN_TOLERANCE_DB`` of that analysis's own; the J/N published is the last one moved by the change.

        The sweep period, band, rate, start, shape and in-band fraction (and a wideband jammer's band) are the last
        full analysis's; a chirp's frequency is NaN (the ridge, which tracks it, does not run). J/S, the clipped
        fraction and the lower-bound flag are this block's."""
        lf = self._last_full
        p = self.params
        cp = p.classifier
        if lf is None or lf.fs != fs or lf.cplx != cplx or lf.est.type == UNKNOWN:
            return None
        max_age_s = LIGHT_MAX_AGE_QUIET_S if lf.est.type == NONE and not lf.integrated else LIGHT_MAX_AGE_S
        if not 0 < stamp_ns - lf.est.stamp_ns <= max_age_s * 1e9:
            return None
        psd, frames = welch_psd(xs, cp.nfft, cp.max_frames)
        power = float(psd.sum())
        if not (math.isfinite(power) and power >= MIN_BLOCK_POWER):
            return None                               # the full analysis rejects it, counted
        floor, ref = self._reference(fs, cplx, full_scale, math.nan)
        if ref != REF_IN_BLOCK and not (floor * 10 ** (-BELOW_FLOOR_DB / 10) <= power
                                        <= floor * 10 ** (MAX_POWER_JN_DB / 10)):
            return None
        norm = psd / power
        tpl = self._ltemplate if self._ltemplate is not None else smooth_template(norm, cp.template_smooth_bins)
        feat = features_from_psd(psd, frames, tpl, cp, cplx)
        thr = cp.detect_jn_db
        last = lf.est
        jtype = last.type
        conf = last.confidence
        freq, fstd = last.frequency_hz, last.frequency_std_hz
        if jtype == NONE or lf.integrated:
            if ref == REF_IN_BLOCK:
                floor = lf.noise                      # no floor yet: the last full analysis's in-block noise level
                if not (math.isfinite(floor) and floor > 0):
                    return None
            jn_ref = 10 * math.log10(power / floor - 1.0) if power > floor else -math.inf
            jn = max(jn_ref, feat.jn_spectral_db)
            if not jn < thr - LIGHT_NONE_MARGIN_DB:
                return None
            if jtype == NONE:
                conf = 1.0 - logistic(jn - thr, cp.confidence_slope_db)
            jn = max(jn, 5.0 * math.log10((1.0 if cplx else 2.0) / (frames * cp.nfft)))   # the resolution
        elif jtype == CW:
            narrow = feat.jn_spectral_db >= thr
            cw = narrow and (feat.occupancy <= cp.cw_max_occupancy or feat.line_fraction >= CW_MIN_LINE_FRACTION)
            if not cw or not abs(feat.peak_frequency - lf.peak) <= 2.0 / cp.nfft:
                return None
            noise = floor if ref != REF_IN_BLOCK else lf.noise
            jn_ref = 10 * math.log10(power / noise - 1.0) if power > noise else -math.inf
            jn = max(jn_ref, feat.jn_spectral_db)
            if not abs(jn - last.jammer_to_noise_db) <= LIGHT_JN_TOLERANCE_DB:
                return None
            conf = logistic(feat.jn_spectral_db - thr, cp.confidence_slope_db)
            freq = self._to_rel_hz(feat.peak_frequency, fs, fif, cplx)
        else:
            jn_pow = 10 * math.log10(power / lf.noise - 1.0) if power > lf.noise > 0 else -math.inf
            delta = jn_pow - lf.jn_power_db
            if not abs(delta) <= LIGHT_JN_TOLERANCE_DB:
                return None
            jn = last.jammer_to_noise_db + delta
            if jtype == CHIRP:
                freq = fstd = math.nan
        js = self._js_db(jtype, jn, fs, cplx)
        lower = (clipped > p.clip_lower_bound_fraction or coarse) and jtype != NONE
        self._block_counters["light_blocks"] += 1
        return dataclasses.replace(
            last, stamp_ns=int(stamp_ns), confidence=float(conf), jammer_to_noise_db=float(jn),
            jammer_to_signal_db=float(js), frequency_hz=float(freq), frequency_std_hz=float(fstd),
            first_sample_index=int(first), n_samples=int(xs.size), counters=self._counters(), traces=None,
            jammer_to_noise_is_lower_bound=bool(lower or lf.integrated), clipped_fraction=float(clipped), light=True)

    def _integrated_period(self, stamp_ns: int) -> float:
        """The sweep period (samples) of the evidence over blocks' last CHIRP decision, if it was made within the
        integration window before stamp_ns; else NaN."""
        if self._int_period is None:
            return math.nan
        per, at = self._int_period
        return per if 0 <= stamp_ns - at <= self._integrator.params.window_s * 1e9 else math.nan

    def _period_confirmed(self, period: float, stamp_ns: int, detected: bool) -> bool:
        """Whether a weak block's own sweep period is confirmed (PERIOD_CONFIRM_MARGIN_DB): by the evidence over blocks'
        period when there is one within its window (it is the authority: consecutive weak blocks can agree on twice
        the period); else, for a block at or above the detection J/N (detected), by one of the last PERIOD_HISTORY
        blocks' own periods stamped within PERIOD_HISTORY_S, within PERIOD_AGREEMENT."""
        p_int = self._integrated_period(stamp_ns)
        if math.isfinite(p_int):
            return _agrees(period, p_int, PERIOD_AGREEMENT)
        horizon = PERIOD_HISTORY_S * 1e9
        return detected and any(0 < stamp_ns - at <= horizon and _agrees(period, p, PERIOD_AGREEMENT)
                                for p, at in self._block_periods)

    def _part_samples(self, n: int) -> int:
        """How many of a block's last samples the ridge analysis takes first (0: the whole block):
        ``RidgeParams.tracking_samples`` while a chirp is tracked, ``acquisition_samples`` while nothing is (the
        last block was neither CW nor CHIRP), the whole block while a CW is."""
        r = self.params.ridge
        k = int(r.tracking_samples) if self._chirp else (0 if self._tracking else int(r.acquisition_samples))
        return k if 0 < k < n else 0

    def _collect_ahead(self, ahead: _Ahead) -> None:
        """The worker's answer for this block, into ``ahead.result`` (None if it failed); counted."""
        assert self.worker is not None
        ahead.result = self.worker.collect()
        ahead.collected = True
        self._block_counters["worker_blocks"] += ahead.result is not None
        self._block_counters["worker_failures"] = self.worker.failures

    def _hook_test_due(self, stamp_ns: int) -> bool:
        """Whether this block's analysis runs the sample-resolution hook test (``HOOK_RECHECK_S``)."""
        mem = self._hook_memory
        return not (self._chirp and mem is not None and 0 <= stamp_ns - mem[2] < HOOK_RECHECK_S * 1e9)

    def _remember_hook(self, rr: rg.RidgeResult, stamp_ns: int) -> rg.RidgeResult:
        """Keep the verdict of a block whose analysis ran the hook test; give it to a saw-tooth of the same period
        analysed without the test (``HOOK_RECHECK_S``)."""
        if rr.hook_checked:
            self._hook_memory = (rr.period_samples, rr.shape == rg.HOOKED_SAWTOOTH, int(stamp_ns))
            return rr
        mem = self._hook_memory
        if (mem is not None and mem[1] and rr.shape in (rg.SAWTOOTH_UP, rg.SAWTOOTH_DOWN)
                and _agrees(rr.period_samples, mem[0])):
            return dataclasses.replace(rr, shape=rg.HOOKED_SAWTOOTH)
        return rr

    def _identify_stft_block(self, xs: np.ndarray, cplx: bool, fs: float, fif: float, stamp_ns: int, first: int,
                             clipped: float, full_scale: float | None, coarse: bool,
                             ahead: _Ahead | None) -> JammerEstimate:
        p = self.params
        cp = p.classifier
        nan = math.nan
        n = xs.size
        self._full_levels = None
        psd, frames = welch_psd(xs, cp.nfft, cp.max_frames)
        power = float(psd.sum())
        if not math.isfinite(power):
            return self._rejected(POWER_OVERFLOW, stamp_ns, fs, first, n, None)
        if not power >= MIN_BLOCK_POWER:
            return self._rejected(BLANK_BLOCK, stamp_ns, fs, first, n, None)
        floor, ref = self._reference(fs, cplx, full_scale, math.nan)
        if ref != REF_IN_BLOCK:
            # a block far below or above a known floor: gain or scale no longer match it (module docstring);
            # a learned floor that stays off for calibration_blocks blocks is learned again
            off = (BELOW_NOISE_FLOOR if power < floor * 10 ** (-BELOW_FLOOR_DB / 10) else
                   IMPLAUSIBLE_POWER if power > floor * 10 ** (MAX_POWER_JN_DB / 10) else None)
            if off is not None:
                self._off_floor_run += 1
                if ref == REF_LEARNED and self._off_floor_run >= p.calibration_blocks:
                    self._block_counters["recalibrations"] += 1
                    self._forget_learned()
                    self._step.reset()           # the shape learned with that floor is as doubtful
                    self._off_floor_run = 0
                return self._rejected(off, stamp_ns, fs, first, n, None)
        self._off_floor_run = 0
        norm = psd / power
        tpl = self._ltemplate if self._ltemplate is not None else smooth_template(norm, cp.template_smooth_bins)
        feat = features_from_psd(psd, frames, tpl, cp, cplx)
        # frame length: chosen on the first block, every RESELECT_IDLE_BLOCKS blocks while nothing is tracked,
        # every RESELECT_BLOCKS while something is, and at once (the block analysed again) when a block shows
        # a chirp or a wideband rise at a frame length chosen while nothing was tracked (a length chosen on
        # noise can resolve a sweep as noise, or fold its period)
        reselected = False
        if self._frame_length == 0 or self._blocks_since_select >= (RESELECT_BLOCKS if self._tracking
                                                                    else RESELECT_IDLE_BLOCKS):
            if ahead is not None and ahead.frame_length == 0:
                self._collect_ahead(ahead)       # the worker chose it on the whole block, as below
            self._frame_length = (ahead.result.frame_length if ahead is not None and ahead.result is not None
                                  else rg.choose_frame_length(xs, cplx, p.ridge))
            self._blocks_since_select = 0
            reselected = True
        self._blocks_since_select += 1
        tail = self._part_samples(n)
        part = xs[-tail:] if tail else xs
        while True:
            rr = None
            if ahead is not None and ahead.size == part.size:
                # started on the worker at the top (_identify_stft): the same samples (the whole block, or its
                # tail: the rule there is this one, on state that has not changed since) at the same length
                if not ahead.collected:
                    self._collect_ahead(ahead)
                if ahead.result is not None and ahead.result.frame_length == self._frame_length:
                    rr = ahead.result
            ahead = None
            if rr is None:
                rr = rg.analyse(part, cplx, fs, p.ridge, self._frame_length, fine_hook=self._hook_test_due(stamp_ns))
            rr = self._remember_hook(rr, stamp_ns)
            jtype, conf, jn, jn_ref, jn_in, floor = self._decide(power, feat, rr, floor, ref)
            self._full_levels = (power, floor, feat.peak_frequency, False)   # for the light analysis
            if part.size < n and self._chirp and not rr.sweeping:
                part = xs            # the tail shows no sweep (any more): the whole block decides
                continue
            if part.size < n and not self._chirp and (jtype != NONE or rr.sweeping or rr.periodic):
                part = xs            # a quiet stream's part shows something: the whole block decides
                continue
            # a jammer seen at a frame length chosen on blocks without one: choose again on this block
            if jtype in (NONE, CW) or reselected or self._tracking or rr.noise_power < MIN_BLOCK_POWER:
                break
            length = rg.choose_frame_length(xs, cplx, p.ridge)
            reselected = True
            self._blocks_since_select = 1
            if length == self._frame_length:
                break
            self._frame_length = length
        if not rr.noise_power >= MIN_BLOCK_POWER:
            # no noise at all in the block (a few non-zero samples): nothing to measure against
            return self._rejected(BLANK_BLOCK, stamp_ns, fs, first, n, None)
        if ref == REF_IN_BLOCK and power > rr.noise_power * 10 ** (MAX_POWER_JN_DB / 10):
            return self._rejected(IMPLAUSIBLE_POWER, stamp_ns, fs, first, n, None)
        integrated: IntegratedDecision | None = None
        if self._integrator.enabled and jtype in (CW, CHIRP):
            self._last_single = jtype          # one block suffices: no evidence gathered (speed while tracking)
        elif self._integrator.enabled:
            # evidence of the blocks of the last integration_window_s (integration module): decides only when
            # this block alone shows no CW or chirp (a single block that suffices adds no latency)
            if self._last_single in (CW, CHIRP):
                self._integrator.restart()     # the jammer one block showed is gone: its evidence goes too
                self._int_period = None
            self._last_single = jtype
            d = self._integrator.add(xs, cplx, fs, stamp_ns)
            self.last_integration = d
            if d.type == CHIRP and math.isfinite(d.period_samples):
                self._int_period = (float(d.period_samples), int(stamp_ns))
            self._block_counters["integration_window_blocks"] = d.blocks
            self._block_counters["integration_blocks_thinned"] = self._integrator.thinned
            self._block_counters["integration_switch_offs"] = self._integrator.switch_offs
            self._block_counters["integration_submultiple_periods"] = self._integrator.submultiples
            self._block_counters["integration_ambiguous_periods"] = self._integrator.ambiguous_periods
            if d.type == CHIRP and jtype in (NONE, WIDEBAND):
                # a periodic sweep in the window: no noise jammer makes one (the per-bin mean is removed, its
                # frames are independent), so a block reported WIDEBAND from its broad excess is a sweep seen
                # too weakly per frame for the ridge (measured: saw-tooths at J/N -2..0 dB on 2-bit captures)
                jtype = NONE
            if jtype == NONE and d.type != NONE:
                integrated = d
                self._block_counters["integrated_reports"] += 1
        step: StepDecision | None = None
        if p.spectral_step.enabled:
            # a noise jammer in part of the band behind an AGC: the step it makes in the spectrum's shape against
            # the shape of the blocks that passed as noise (spectral_step module); blocks with a tone or a sweep
            # are not summed
            if jtype in (NONE, WIDEBAND) and integrated is None:
                step = self._step.test(norm, frames, cplx, stamp_ns)
                self.last_step = step
                if step.detected:
                    # a block already WIDEBAND from its power or spectral excess gets the band (and the larger J/N)
                    if jtype == NONE:
                        jtype = WIDEBAND
                        conf = logistic(step.z - step.threshold, 1.0)
                    if step.jn_db > jn:
                        jn, ref = step.jn_db, REF_LEARNED     # measured against the learned noise shape
                    self._block_counters["spectral_step_reports"] += 1
                else:
                    step = None
            else:
                self._step.restart()
        if jtype == NONE:
            jn = max(jn, 5.0 * math.log10((1.0 if cplx else 2.0) / (frames * cp.nfft)))
        if integrated is not None:
            if self._full_levels is not None:
                self._full_levels = self._full_levels[:3] + (True,)
            return self._integrated_estimate(integrated, jn, stamp_ns, fs, fif, cplx, first, n, ref, clipped, xs)
        if jtype in (CW, CHIRP) and ref != REF_IN_BLOCK and math.isfinite(jn) and jn == jn_in and jn_in > jn_ref:
            # an AGC (or a gain change) hides the jammer from the block power; the noise measured in the block
            # beside the jammer shows it: J/N against REF_IN_BLOCK, and said so
            ref = REF_IN_BLOCK
        if (jtype in (CW, CHIRP) and ref == REF_IN_BLOCK and not coarse and clipped <= p.clip_lower_bound_fraction
                and (jtype == CW or rr.in_band_fraction >= ENVELOPE_MIN_IN_BAND)):
            # the in-block noise beside a strong fast sweep reads high (its leakage fills every bin of every frame):
            # the noise from the block's moments under a constant envelope (constant_envelope module) errs only
            # low in J/N, so the larger of the two J/Ns is kept
            jn_env = constant_envelope_jn_db(xs, cplx)
            if math.isfinite(jn_env) and jn_env > jn:
                jn = jn_env
                self._block_counters["jn_from_envelope"] += 1
        if jtype == NONE:
            # the floor learns only from blocks that pass as noise inside the block too
            if clipped <= p.clip_lower_bound_fraction and not rr.periodic and jn_in < cp.detect_jn_db:
                self._learn(power, norm)
                self._step.learn()
        if not math.isfinite(jn):
            jn = nan
        js = self._js_db(jtype, jn, fs, cplx)
        freq = fstd = rate = per = f0 = bw = inb = nan
        shape = rg.SHAPE_UNKNOWN
        inverted = (not cplx) and fif < 0
        if jtype == CW:
            freq = self._to_rel_hz(feat.peak_frequency, fs, fif, cplx)
            fstd = fs / cp.nfft / math.sqrt(12.0)
            rate = 0.0
        elif step is not None:
            # the band that rose: its centre, and the std of a uniform spread over it
            freq = self._to_rel_hz(0.5 * (step.low + step.high), fs, fif, cplx)
            fstd = (step.high - step.low) * fs / math.sqrt(12.0)
        elif jtype == CHIRP:
            lo_dig = -0.5 if cplx else 0.0
            if math.isfinite(rr.frequency) and lo_dig <= rr.frequency <= 0.5:
                freq = self._to_rel_hz(rr.frequency, fs, fif, cplx)
                fstd = rr.frequency_std * fs
            else:
                self._block_counters["frequency_not_tracked"] += 1
            sgn = -1.0 if inverted else 1.0
            rate = sgn * rr.rate * fs * fs if math.isfinite(rr.rate) else nan
            shape = rr.shape
            if inverted and shape in (rg.SAWTOOTH_UP, rg.SAWTOOTH_DOWN):
                shape = rg.SAWTOOTH_DOWN if shape == rg.SAWTOOTH_UP else rg.SAWTOOTH_UP
            if rr.periodic:
                per = rr.period_samples / fs
                inb = rr.in_band_fraction
            if math.isfinite(rr.low) and math.isfinite(rr.high):
                a, b = self._to_rel_hz(rr.low, fs, fif, cplx), self._to_rel_hz(rr.high, fs, fif, cplx)
                bw = abs(b - a)
                if math.isfinite(rr.start):
                    f0 = self._to_rel_hz(rr.start, fs, fif, cplx)
            m = _multiple(rr.period_samples, self._integrated_period(stamp_ns)) if rr.periodic else 0
            if m >= 3 or (m == 2 and jn < cp.detect_jn_db):
                # SUBHARMONIC_TOLERANCE: the block's ridge locked on a multiple of the period the evidence over
                # the window found (a weak sweep whose period is near a whole number of hops beats with the frame
                # grid); the window's period is reported, the sweep law fitted on the multiple is not (frequency,
                # rate, band and start NaN), the shape and in-band fraction come from the block folded on it. Twice
                # the window's period only from a block below the detection J/N: the window's comb on amplitudes
                # sees a symmetric triangle (the same in-band pattern on the way up and down) at half its period,
                # where a strong block is right
                p_int = self._integrated_period(stamp_ns)
                self._block_counters["block_periods_from_integration"] += 1
                per = p_int / fs
                freq = fstd = rate = f0 = bw = nan
                shape, inb, _, _ = rg.folded_shape(xs, cplx, p_int, p.ridge)
                if inverted and shape in (rg.SAWTOOTH_UP, rg.SAWTOOTH_DOWN):
                    shape = rg.SAWTOOTH_DOWN if shape == rg.SAWTOOTH_UP else rg.SAWTOOTH_UP
                if shape == rg.SHAPE_UNKNOWN:
                    inb = nan
            elif rr.periodic and not jn >= cp.detect_jn_db + PERIOD_CONFIRM_MARGIN_DB and not self._period_confirmed(
                    rr.period_samples, stamp_ns, jn >= cp.detect_jn_db):
                # a block below (or just above) the detection J/N has a ridge in a few of its frames, and the
                # autocorrelation of so few can peak at a multiple of the period or beside it (stft_shapes.md at J/N
                # -5 dB: 4-100 % off): its period, and the sweep law fitted on it (frequency, rate, start) and the band
                # read with it, are published only when the evidence over blocks or a recent block found the same
                # period (PERIOD_CONFIRM_MARGIN_DB); else NaN (counted). The type, J/N and the block's shape stay.
                self._block_counters["block_periods_unconfirmed"] += 1
                per = inb = freq = fstd = rate = f0 = bw = nan
            if rr.periodic:
                self._block_periods.append((float(rr.period_samples), int(stamp_ns)))
        self._tracking = jtype in (CW, CHIRP)
        self._chirp = jtype == CHIRP
        lower = (clipped > p.clip_lower_bound_fraction or coarse) and jtype != NONE
        return JammerEstimate(stamp_ns, int(jtype), float(conf), float(jn), float(js), freq, fstd, rate, per, f0,
                              bw, fs, first, n, True, self._counters(), None, "", ref, bool(lower), float(clipped),
                              int(shape), inb)

    def _integrated_estimate(self, d: IntegratedDecision, jn: float, stamp_ns: int, fs: float, fif: float,
                             cplx: bool, first: int, n: int, ref: int, clipped: float,
                             xs: np.ndarray) -> JammerEstimate:
        """A CW or chirp found only by the evidence over blocks (integration module). Type, confidence (0.5 at the
        threshold) and, for a CW, its frequency; a chirp's sweep period from the comb, and its sweep shape and
        in-band fraction from this block's short-time spectrum folded on that period (``ridge.folded_shape``:
        synchronous averaging over the block's periods; unknown / NaN when the block does not show it); the J/N
        is this block's own measurement (mostly its resolution: such a jammer is below what one block measures),
        flagged as a lower bound; the other fields NaN."""
        p = self.params
        nan = math.nan
        freq = fstd = rate = per = inb = nan
        shape = rg.SHAPE_UNKNOWN
        if d.type == CW:
            conf = logistic(10 * math.log10(max(d.cw_score, 1e-30)), 0.5)
            jn = max(jn, d.excess_db)
            freq = self._to_rel_hz(d.cw_frequency, fs, fif, cplx)
            fstd = fs / self._integrator.params.nfft / math.sqrt(12.0)
            rate = 0.0
        elif not math.isfinite(d.period_samples):
            # a sweep whose period the window's comb cannot tell from a multiple of a shorter one
            # (integration.resolve_submultiple): CHIRP without a period, shape or in-band fraction
            conf = logistic(d.chirp_z - d.chirp_threshold, 1.0)
        else:
            conf = logistic(d.chirp_z - d.chirp_threshold, 1.0)
            per = d.period_samples / fs
            shape, inb, _, _ = rg.folded_shape(xs, cplx, d.period_samples, p.ridge)
            if (not cplx) and fif < 0 and shape in (rg.SAWTOOTH_UP, rg.SAWTOOTH_DOWN):
                # spectral inversion: the IF runs against RF (as in the CHIRP path of _identify_stft)
                shape = rg.SAWTOOTH_DOWN if shape == rg.SAWTOOTH_UP else rg.SAWTOOTH_UP
            if shape == rg.SHAPE_UNKNOWN:
                inb = nan
        js = self._js_db(d.type, jn, fs, cplx)
        self._tracking = False
        self._chirp = False
        return JammerEstimate(stamp_ns, int(d.type), float(conf), float(jn), float(js), freq, fstd, rate, per, nan,
                              nan, fs, first, n, True, self._counters(), None, "", ref, True, float(clipped),
                              int(shape), float(inb))

    def _decide(self, power: float, feat: BlockFeatures, rr: rg.RidgeResult, floor: float, ref: int
                ) -> tuple[int, float, float, float, float, float]:
        """(type, confidence, J/N, J/N against the reference, J/N against the in-block level, the floor used)
        of the "stft" estimator (docs/rfi_monitor/stft_estimator.md, step 6)."""
        cp = self.params.classifier
        if ref == REF_IN_BLOCK:
            floor = rr.noise_power
        jn_ref = 10 * math.log10(power / floor - 1.0) if power > floor else -math.inf
        jn_in = 10 * math.log10(power / rr.noise_power - 1.0) if power > rr.noise_power > 0 else -math.inf
        thr = cp.detect_jn_db
        s = cp.confidence_slope_db
        narrow = feat.jn_spectral_db >= thr
        cw = narrow and (feat.occupancy <= cp.cw_max_occupancy or feat.line_fraction >= CW_MIN_LINE_FRACTION)
        jn = jn_ref
        if cw and not rr.sweeping:
            return (CW, logistic(feat.jn_spectral_db - thr, s), max(jn_ref, feat.jn_spectral_db, jn_in), jn_ref, jn_in,
                    floor)
        if rr.sweeping and (rr.periodic or max(jn_ref, jn_in) >= thr - APERIODIC_MARGIN_DB):
            conf = logistic(max(jn_ref, jn_in) - thr, s) * (1.0 if rr.periodic else 0.6)
            return CHIRP, conf, max(jn_ref, jn_in), jn_ref, jn_in, floor
        if ref != REF_IN_BLOCK and jn_ref >= thr:
            return WIDEBAND, logistic(jn_ref - thr, s), jn, jn_ref, jn_in, floor
        if narrow:
            return (WIDEBAND, 0.5 * logistic(feat.jn_spectral_db - thr, s), max(jn_ref, feat.jn_spectral_db), jn_ref,
                    jn_in, floor)
        conf = 1.0 - logistic(max(feat.jn_spectral_db, jn_ref) - thr, s)
        return NONE, conf, max(jn_ref, feat.jn_spectral_db), jn_ref, jn_in, floor

    def _learn(self, power: float, norm_psd: np.ndarray) -> None:
        """Add a block that passed as noise to the learned floor and shape (the last calibration_blocks).

        The floor (a median of k numbers) follows every such block; the shape (a median of k spectra, then a
        running median across bins: ~0.15 ms, more than the rest of a quiet block's bookkeeping) is formed again
        once every k blocks learned, from the last k (the front end's shape drifts over seconds, not blocks)."""
        k = int(self.params.calibration_blocks)
        self._learn_pow = (self._learn_pow + [power])[-k:]
        self._learn_psd = (self._learn_psd + [norm_psd])[-k:]
        self._learn_since_tpl += 1
        if len(self._learn_pow) >= k:
            self._lfloor = float(np.median(self._learn_pow))
            if self._ltemplate is None or self._learn_since_tpl >= k:
                med = np.median(np.stack(self._learn_psd), axis=0)
                self._ltemplate = smooth_template(med, self.params.classifier.template_smooth_bins)
                self._learn_since_tpl = 0

    # ------------------------------------------------------------------------------------------
    @property
    def state_summary(self) -> dict[str, float]:
        """Current tracker state: frequency (cycles/sample), rate, P, period (samples), last start."""
        st = self._state
        lattice = float(st.mst[MonitorFloat.NEXT]) >= 0.0 and int(st.mist[MonitorInt.LATSRC]) > 0
        per = float(st.mst[MonitorFloat.TLAT]) if lattice else float(st.sf[SweepFloat.PERIOD])
        locked = lattice or int(st.si[SweepInt.LOCKED]) == 1
        return {"f": float(st.fst[FilterFloat.F]), "df": float(st.fst[FilterFloat.DF]),
                "p11": float(st.fst[FilterFloat.P11]),
                "p22": float(st.fst[FilterFloat.P22]), "period_samples": per if locked else math.nan,
                "locked": float(locked), "lpd_locked": float(st.si[SweepInt.LOCKED]),
                "lpd_period_samples": float(st.sf[SweepFloat.PERIOD]),
                "lattice_source": float(st.mist[MonitorInt.LATSRC]),
                "last_start": float(st.mist[MonitorInt.LAST_START]),
                "tracking_mode": float(st.mist[MonitorInt.TRACK])}
