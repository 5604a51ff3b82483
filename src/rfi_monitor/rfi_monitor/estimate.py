"""What one block's analysis returns, and what both estimators share (pure module, no ROS).

``RfiMonitor`` (monitor module) checks a block and hands it to its estimator as a :class:`Block`; the estimator
(``kalman_estimator.KalmanEstimator``, the paper's per-sample tracker, or ``stft_estimator.StftEstimator``, our
short-time FFT analysis) implements :class:`Estimator` and returns a :class:`JammerEstimate`, which maps field by
field onto ``rfi_msgs/JammerState``. The rejection reasons, the J/N references and J/S (``jammer_to_signal_db``, the
one place J/S is computed) are defined here, once, for both.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import MISSING, dataclass, field, fields
from types import MappingProxyType
from typing import Protocol

import numpy as np

from rfi_monitor.classifier import NONE, UNKNOWN
from rfi_monitor.params import RfiMonitorParams


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


_ESTIMATE_FIELDS = tuple(f.name for f in fields(JammerEstimate))
_ESTIMATE_DEFAULTS = tuple(f.default for f in fields(JammerEstimate) if f.default is not MISSING)


def make_estimate(*values) -> JammerEstimate:
    """``JammerEstimate(*values)`` (positional, in field order; the trailing fields with defaults may be left out)
    without the frozen dataclass's ``__init__``, which sets each of its 24 fields through ``object.__setattr__``
    (~9 us against ~2 us: every analysed block builds one). The same object: same fields, equality, frozen."""
    n_req = len(_ESTIMATE_FIELDS) - len(_ESTIMATE_DEFAULTS)
    if not n_req <= len(values) <= len(_ESTIMATE_FIELDS):
        raise TypeError(f"make_estimate takes {n_req}..{len(_ESTIMATE_FIELDS)} values, got {len(values)}")
    e = object.__new__(JammerEstimate)
    e.__dict__.update(zip(_ESTIMATE_FIELDS, values + _ESTIMATE_DEFAULTS[len(values) - n_req:], strict=True))
    return e


@dataclass(frozen=True)
class BlockSpectrum:
    """The Welch power spectrum an estimator computed for a block's analysis, exposed for display
    (``RfiMonitor.last_spectrum``; rfi_monitor.spectrum_view draws it). Nothing is computed for it: it is the
    array the analysis made (``classifier.welch_psd``), kept by reference.

    Attributes:
        stamp_ns: the block's stamp, ns.
        psd: power per bin, sample units^2 (psd.sum() is the block's mean power), ``welch_psd`` order: real input
            (nfft // 2 + 1,) from 0 to fs/2, complex input (nfft,) from -fs/2 (fftshift order). Read only.
        sample_rate_hz: fs, Hz; intermediate_frequency_hz: the block's IF, Hz; cplx: complex samples.
    """

    stamp_ns: int
    psd: np.ndarray
    sample_rate_hz: float
    intermediate_frequency_hz: float
    cplx: bool


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
MIN_BLOCK_POWER = 1e-60
"""Smallest block power analysed, sample units^2 (1e-30 rms): below it the block is blank. The Welch PSD is
computed in single precision, whose numbers lose precision below 1.2e-38 (subnormal) and end at 1.4e-45;
no unit a front end reports in (volts, full scale, counts) comes near."""
REF_IN_BLOCK, REF_LEARNED, REF_FIXED = 0, 1, 2
"""J/N references, identical to rfi_msgs/JammerState.REF_*: the noise level measured inside the block
(ridge module, step 2), the floor learned from earlier blocks that passed as noise, the configured one
(``noise_floor_power`` or ``noise_floor_dbfs``)."""


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


def off_floor(power: float, floor: float) -> str | None:
    """The rejection of a block whose power is far from a known noise floor (``BELOW_NOISE_FLOOR`` more than
    ``BELOW_FLOOR_DB`` below it, ``IMPLAUSIBLE_POWER`` more than ``MAX_POWER_JN_DB`` above it), else None: the front
    end's gain or scale no longer matches the floor."""
    if power < floor * 10 ** (-BELOW_FLOOR_DB / 10):
        return BELOW_NOISE_FLOOR
    if power > floor * 10 ** (MAX_POWER_JN_DB / 10):
        return IMPLAUSIBLE_POWER
    return None


TRACKER_COUNTERS = ("measurements_ok", "rejected_near_zero", "rejected_arccos_domain", "rejected_non_finite",
                    "rejected_chirp_correction", "sweep_resets", "sweep_start_fits", "period_search_suspensions")
"""Counts of the per-sample tracker (kalman_estimator); the "stft" estimator reports them as 0, so that the diagnostics
carry the same keys whichever estimator runs."""
SPECTRAL_STEP_COUNTERS = ("spectral_step_not_flat", "spectral_step_relearned")
"""Counts of the spectral-step test (stft_estimator); the "kalman" estimator reports them as 0 (same reason)."""


def relative_frequency_hz(f_dig: float, fs: float, fif: float, cplx: bool) -> float:
    """A digital frequency (cycles/sample) as a frequency relative to the RF centre, Hz (a real IF below zero is
    spectrally inverted)."""
    if not cplx and fif < 0:
        return -fif - f_dig * fs
    return f_dig * fs - fif


@dataclass(frozen=True)
class Block:
    """One checked block as the monitor hands it to its estimator.

    Attributes:
        samples: finite samples, shape (n,), float64 (real) or complex128 (non-finite ones set to 0).
        cplx: complex samples; fs: sample rate, Hz; fif: intermediate frequency, Hz.
        stamp_ns: time of the first sample, ns; first: its running sample index.
        clipped: share of the samples at or beyond full scale, 0..1; full_scale: the quantiser's full scale (None:
            unknown).
        coarse: a front end of at most ``monitor.COARSE_BITS`` bits (a jammer's J/N is a lower bound).
    """

    samples: np.ndarray
    cplx: bool
    fs: float
    fif: float
    stamp_ns: int
    first: int
    clipped: float
    full_scale: float | None
    coarse: bool

    @property
    def n(self) -> int:
        return int(self.samples.size)


class BlockCounters:
    """The monitor's cumulative counters, shared by the monitor and its estimator; ``snapshot`` adds the estimator's
    own counts (``Estimator.counters``) and freezes them for a ``JammerEstimate``."""

    def __init__(self, names: tuple[str, ...]) -> None:
        self.values: dict[str, int] = dict.fromkeys(names, 0)
        self.extra: list = []
        """Callables returning more counts (name -> int), added to every snapshot in order."""

    def __getitem__(self, name: str) -> int:
        return self.values[name]

    def __setitem__(self, name: str, value: int) -> None:
        self.values[name] = value

    def snapshot(self) -> Mapping[str, int]:
        d = dict(self.values)
        for more in self.extra:
            d.update(more())
        return MappingProxyType(d)

    def rejected(self, reason: str, block: Block, traces: BlockTraces | None = None) -> JammerEstimate:
        """The result of a block that is not analysed: valid False, UNKNOWN, confidence 0, NaN fields; counted."""
        self.values["blocks_rejected"] += 1
        nan = math.nan
        return make_estimate(block.stamp_ns, UNKNOWN, 0.0, nan, nan, nan, nan, nan, nan, nan, nan, block.fs,
                              block.first, block.n, False, self.snapshot(), traces, reason)


class Estimator(Protocol):
    """What ``RfiMonitor`` asks of an estimator (the paper's Kalman tracker and our STFT analysis implement it)."""

    @property
    def calibrated(self) -> bool:
        """Whether the noise floor J/N is measured against is known."""
        ...

    def counters(self) -> dict[str, int]:
        """The estimator's own cumulative counts, added to the monitor's in every ``JammerEstimate.counters``."""
        ...

    def reset(self, keep_calibration: bool) -> None:
        """A new stream (``keep_calibration`` False: learn the noise floor again) or a gap in this one (True)."""
        ...

    def gap(self, missing_samples: int, stamp_ns: int, short: bool) -> None:
        """A gap of ``missing_samples`` before the block stamped ``stamp_ns``: the per-sample state starts again, the
        calibration stays; a short gap (``monitor.FRAME_KEEP_GAP_S``) keeps the STFT frame length."""
        ...

    def skip_invalid(self, block: Block) -> None:
        """A block rejected for its non-finite samples (zeroed in ``block.samples``): keep the state continuous."""
        ...

    def analyse(self, block: Block, return_traces: bool, light: bool) -> JammerEstimate:
        """Identify and estimate the jammer of one block."""
        ...
