"""Parameters of the RFI monitor, and the table of its "paper method vs ours" switches.

:class:`Method` is the one table of the switches that choose between Kang et al.'s method and the
additions of this package (each documented in the module named in its row, and in
docs/rfi_monitor/README.md, "Paper method vs ours"):

=========================== ======= ====== ===============================================================
switch (RfiMonitorParams)   paper   ours   what "ours" does
=========================== ======= ====== ===============================================================
chirp_correction            on      on     eq. 10 (real samples) with the filter's sweep estimate
reset_at_sweep_start        on      on     filter reset at the predicted sweep starts, eq. 21-22
sweep.lattice_voting        off     on     period by voting over the last peaks (sweep_period)
sweep.decimation            2       4      samples per AR(10) step (paper: its best setting, 2)
refine_window               0       24     sweep-start step fit + lattice Kalman filter (tracker)
noise_compensation          off     on     eq. 8's ratio divided by kappa = 1 - N / P (if_measurement)
reset_cross_covariance      off     on     exact covariance of eq. 21 at a reset (tracking_filters)
analysis.enabled            off     on     block-level periodicity detector (sweep_analysis)
confirm_fits                0       4      tracking mode: period search suspended (tracker)
=========================== ======= ====== ===============================================================

``RfiMonitorParams()`` is "ours"; ``RfiMonitorParams.paper_method()`` = ``Method.paper().apply(...)``.
The node's parameters keep their names (``sweep_lattice_voting``, ``sweep_decimation``,
``analysis_enabled``, the others as above).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from rfi_monitor.classifier import ClassifierParams
from rfi_monitor.integration import IntegrationParams
from rfi_monitor.ridge import RidgeParams
from rfi_monitor.spectral_step import SpectralStepParams
from rfi_monitor.sweep_analysis import SweepAnalysisParams
from rfi_monitor.sweep_period import SweepPeriodParams
from rfi_monitor.tracker_steps import MAX_REFINE_WINDOW
from rfi_monitor.tracking_filters import MODE_AFKF, TrackingFilterParams
from rfi_node_common.params import USER, parameter

ESTIMATORS = ("stft", "kalman")
"""Values of ``RfiMonitorParams.estimator``."""


@dataclass(frozen=True)
class Method:
    """The "paper method vs ours" switches of :class:`RfiMonitorParams` (the table in the module
    docstring). ``Method()`` is "ours"; :meth:`paper` is Kang et al.'s method.

    Decimation of the paper method (benchmarks/rfi_monitor_paper.py, 1e12 Hz/s, median of 3-5 seeds,
    RMSE in cycles/sample at J/N 11.2 / 21.2 / 31.2 dB): D = 1 (the paper's full rate) 0.018 / 0.030 /
    0.027 (at high J/N the period locks in 2/3 seeds only); D = 2 0.019 / 0.017 / 0.012; D = 4 0.027 /
    0.012 / 0.010 with 4/5 locks at 11.2 dB (the peak times jitter by +-D/2).
    """

    chirp_correction: bool = True
    reset_at_sweep_start: bool = True
    lattice_voting: bool = True
    decimation: int = 4
    refine_window: int = 24
    noise_compensation: bool = True
    reset_cross_covariance: bool = True
    analysis_enabled: bool = True
    confirm_fits: int = 4

    @staticmethod
    def ours() -> Method:
        """The default: the paper's method plus every addition."""
        return Method()

    @staticmethod
    def paper() -> Method:
        """Kang et al.'s method only, at its best decimation."""
        return Method(lattice_voting=False, decimation=2, refine_window=0, noise_compensation=False,
                      reset_cross_covariance=False, analysis_enabled=False, confirm_fits=0)

    @staticmethod
    def of(p: RfiMonitorParams) -> Method:
        """The switches of the parameters p."""
        return Method(p.chirp_correction, p.reset_at_sweep_start, p.sweep.lattice_voting, int(p.sweep.decimation),
                      int(p.refine_window), p.noise_compensation, p.reset_cross_covariance, p.analysis.enabled,
                      int(p.confirm_fits))

    def apply(self, p: RfiMonitorParams) -> RfiMonitorParams:
        """p with these switches (its other fields kept)."""
        return dataclasses.replace(
            p, chirp_correction=self.chirp_correction, reset_at_sweep_start=self.reset_at_sweep_start,
            sweep=dataclasses.replace(p.sweep, lattice_voting=self.lattice_voting, decimation=self.decimation),
            refine_window=self.refine_window, noise_compensation=self.noise_compensation,
            reset_cross_covariance=self.reset_cross_covariance,
            analysis=dataclasses.replace(p.analysis, enabled=self.analysis_enabled), confirm_fits=self.confirm_fits)


@dataclass(frozen=True)
class RfiMonitorParams:
    """Validated parameters of the monitor.

    Its scalar fields are parameters of rfi_monitor_node: default, description and range written here once
    (:func:`rfi_node_common.params.parameter`; the node takes them with ``parameter_from``).

    Attributes:
        estimator: ``"stft"`` (default, ours: the short-time FFT ridge analysis of each block, module
            rfi_monitor.ridge; no per-sample loop, no clean start needed, real sweep shapes) or
            ``"kalman"`` (Kang et al.'s per-sample tracker with the switches of the ``Method`` table;
            ``paper_method()`` selects it).
        ridge: RidgeParams of the "stft" estimator.
        integration: IntegrationParams of the "stft" estimator's evidence over blocks (rfi_monitor.integration:
            a weak stationary CW or chirp that no single block shows; window_s 0: off).
        spectral_step: SpectralStepParams of the "stft" estimator's test for a noise jammer in part of the band
            behind an AGC (rfi_monitor.spectral_step: the step it makes in the spectrum's shape).
        noise_floor_dbfs: the front end's thermal noise power per real component relative to
            full_scale^2 (as passed to ``process``), dB (e.g. -30: rms 3.2 % of full scale); 0: not
            documented (noise at full scale is no working front end). Used as the J/N reference when
            set (and full_scale is known), unless ``noise_floor_power`` is set.
        clip_lower_bound_fraction: above this fraction of samples at full scale the J/N is flagged
            as a lower bound (clipping compresses the jammer's power), in [0, 1].
        tracker: TrackingFilterParams (default: the proposed adaptive fading KF).
        sweep: SweepPeriodParams (default here: with lattice voting and decimation 4, ours;
            ``paper_method()`` switches voting off and uses decimation 2).
        classifier: ClassifierParams.
        chirp_correction: use eq. 10 (real samples) with the tracker's sweep estimate.
        reset_at_sweep_start: reset the filter at estimated sweep starts (eq. 21-22).
        min_abs_ratio: near-zero guard, |x_n| <= ratio * running RMS rejects a sample, >= 0.
        domain_margin: arccos domain margin, >= 0.
        power_time_constant: samples of the running RMS used by the guard, >= 1.
        phase_gain: gain of the sweep-start lattice phase correction, (0, 1].
        noise_floor_power: fixed noise power (sample units^2); 0: learn it (see module docstring).
        calibration_blocks: blocks used to learn the noise floor and shape, >= 1.
        signal_power_dbm: nominal GNSS signal power S for J/S, dBm (Kang et al.: -130).
        noise_density_dbm_per_mhz: nominal noise density for J/S, dBm/MHz (Kang et al.: -114).
        noise_bandwidth_hz: bandwidth of the nominal noise power, Hz; 0: the sampled band.
        max_invalid_fraction: a block with more non-finite samples than this fraction is rejected
            (``non_finite``: result valid=False, type UNKNOWN), in [0, 1]. Samples at full scale never
            reject a block: clipping is evidence of a strong jammer (``clipped_fraction``).
        min_block_samples: shorter blocks raise ValueError (>= the classifier's nfft).
        refine_window: half-window W (samples) of the sweep-start step fit that refines the reset
            lattice (ours, tracker module docstring), 0..MAX_REFINE_WINDOW; 0 runs the paper's
            lattice (LPD peaks only).
        lattice_period_drift: random walk of the sweep period per sweep, relative, of the
            step-fit lattice filter (ours; tracker module docstring), in [0, 0.01]. Larger: the
            lattice follows a drifting sweep period faster, with more reset jitter.
        noise_compensation: divide the real three-sample ratio by kappa = 1 - N / P (running power
            P, calibrated noise floor N), which removes eq. 8's bias towards fs/4 at moderate J/N
            (ours; if_measurement module docstring). No effect on complex samples or before the
            noise floor is known.
        reset_cross_covariance: at a sweep reset keep the exact covariance of eq. 21's linear map
            instead of eq. 22's uncorrelated P(1,1) (ours; tracking_filters.kf_sweep_reset).
        confirm_fits: tracking mode (ours; tracker module docstring): after this many consecutive
            successful sweep-start fits the lattice is confirmed and the LPD / AR(10) / peak pass is
            suspended until the lattice drops (MAX_MISSES failed fits), then resumed from its initial
            state; 0: the period search always runs (the paper). Needs refine_window > 0, >= 0.
        analysis: SweepAnalysisParams of the block-level periodicity detector (ours).
    """

    estimator: str = parameter(
        "stft",
        'The estimator. stft (default, ours): a short-time FFT of each block; its noise level is measured inside the '
        'block (no clean start needed: a jammer on from the first sample cannot become the floor), a swept jammer of '
        'any shape (saw-tooth up/down, triangle, hooked, non-linear rate, wider than the band) is a ridge whose '
        "autocorrelation gives the sweep period; no per-sample loop. kalman: Kang et al.'s per-sample tracker (the "
        'parameters from chirp_correction to the sweep_* and analysis_* groups below; they do nothing with stft). '
        'docs/rfi_monitor/stft_estimator.md.', choices=ESTIMATORS, group=USER)
    tracker: TrackingFilterParams = field(default_factory=lambda: TrackingFilterParams(mode=MODE_AFKF))
    sweep: SweepPeriodParams = field(default_factory=lambda: SweepPeriodParams(lattice_voting=True))
    classifier: ClassifierParams = field(default_factory=ClassifierParams)
    chirp_correction: bool = parameter(
        True, 'Correct the three-sample measurement for the sweep during the three samples (Kang et al., eq. 10, '
        're-derived; real samples only). Set false only to reproduce the uncorrected eq. 8.')
    reset_at_sweep_start: bool = parameter(
        True,
        'Reset the tracking filter at the estimated sweep starts (Kang et al., eq. 21-22). Set false to compare with '
        "the plain adaptive fading filter (the paper's AFKF baseline).")
    min_abs_ratio: float = parameter(
        0.02,
        'Near-zero guard, dimensionless: a sample with |x| <= this times the running RMS gives no measurement (the '
        'arccos ratio would divide by ~0). Raise it if the measurement is noisy.', minimum=0.0, maximum=1.0)
    domain_margin: float = parameter(
        0.05, 'arccos domain margin, dimensionless: ratios beyond 1 + this are rejected (not clipped).',
        minimum=0.0, maximum=10.0)
    power_time_constant: float = parameter(
        1024.0, 'Time constant of the running RMS used by the near-zero guard, samples.', minimum=1.0, maximum=1e9)
    phase_gain: float = parameter(
        0.3,
        'Gain of the phase correction of the predicted sweep-start lattice by detected peaks, (0, 1]. Lower it if '
        'resets jitter at low J/N; raise it for sweeps whose period drifts.', minimum=1e-6, maximum=1.0)
    noise_floor_power: float = parameter(
        0.0,
        'Fixed noise power of the decoded samples, V^2 (counts * scale, squared). 0 (default): learn the noise floor '
        'and the front-end noise shape from the first calibration_blocks blocks. Set it when a chirp or wideband '
        'jammer may be on at start-up (learning would take it for noise).', minimum=0.0, maximum=1e12)
    calibration_blocks: int = parameter(
        5, 'Blocks used to learn the noise floor (median over blocks). kalman: the first blocks, reported as UNKNOWN. '
        'stft: the last blocks that passed as noise inside the block too (no jammer seen, no clipping); blocks are '
        'reported from the first one. A change of sample rate, IF or complexness starts the learning again.',
        minimum=1, maximum=100000)
    signal_power_dbm: float = parameter(
        -130.0, 'Nominal GNSS signal power S for J/S = J/N + N - S, dBm (Kang et al.: -130).',
        minimum=-250.0, maximum=50.0, group=USER)
    noise_density_dbm_per_mhz: float = parameter(
        -114.0, "Nominal noise density for N, dBm/MHz (Kang et al.: -114). Set to the front end's value.",
        minimum=-250.0, maximum=50.0, group=USER)
    noise_bandwidth_hz: float = parameter(
        0.0, 'Bandwidth over which N is counted, Hz; 0: the sampled band (fs/2 real, fs complex). Set it to the front '
        "end's noise bandwidth (e.g. 2000000.0 for a 2 MHz C/A front end) so that J/S matches the link budget the "
        'user has in mind.', minimum=0.0, maximum=1e10, group=USER)
    max_invalid_fraction: float = parameter(
        0.05, 'A block with more non-finite samples than this fraction is rejected (non_finite); samples at full '
        'scale never reject a block (clipping is evidence of a strong jammer).', minimum=0.0, maximum=1.0)
    min_block_samples: int = parameter(
        1024,
        'Shortest block analysed, samples (complex: I/Q pairs); shorter blocks are rejected (short_block). Must be >='
        ' classifier_nfft. 1 ms at 38.192 MHz is 38192 samples.', minimum=32, maximum=2**31 - 1)
    refine_window: int = parameter(
        24, 'Half-window W of the step fit that refines the predicted sweep starts (ours), samples, 0..24. 0 runs the '
        "paper's lattice from the LPD peaks only (for comparison with Kang et al.).",
        minimum=0, maximum=MAX_REFINE_WINDOW)
    lattice_period_drift: float = parameter(
        1e-5,
        'Random walk of the sweep period per sweep, relative, of the step-fit lattice filter (ours), 0..0.01. Raise '
        'it for a jammer whose sweep period drifts (e.g. 1e-4 for a free-running analog sweep); the resets then '
        'jitter more.', minimum=0.0, maximum=0.01)
    noise_compensation: bool = parameter(
        True,
        'Divide the real three-sample ratio of eq. 8/10 by kappa = 1 - N/P (running power P, calibrated noise floor '
        "N): removes the measurement's bias towards fs/4 at moderate J/N (ours). No effect on complex samples. false "
        "runs the paper's measurement.")
    reset_cross_covariance: bool = parameter(
        True,
        "At a sweep reset keep the exact covariance of eq. 21's linear map instead of eq. 22's uncorrelated P(1,1) "
        "(ours). false runs the paper's eq. 22.")
    confirm_fits: int = parameter(
        4, 'Tracking mode (ours): after this many consecutive significant sweep-start fits the LPD / AR(10) / peak '
        'search of the paper is suspended (the step-fit lattice holds the sweep) and resumed after two failed fits; '
        'it roughly doubles the throughput on a steady chirp. 0: always search (the paper).', minimum=0, maximum=10**6)
    analysis: SweepAnalysisParams = field(default_factory=SweepAnalysisParams)
    ridge: RidgeParams = field(default_factory=RidgeParams)
    noise_floor_dbfs: float = parameter(
        0.0,
        'Thermal noise of the front end per real component relative to full scale squared, dB (needs bits_per_sample '
        '>= 4: full scale = (2^(bits-1) - 1) * scale). The J/N reference when set (e.g. -30.0 for noise at 3.2 % rms '
        'of full scale), which also sees a wideband noise jammer that is on from the start. 0.0: not documented (the '
        'floor learned from blocks that passed as noise, else the in-block noise level).',
        minimum=-300.0, maximum=0.0, group=USER)
    clip_lower_bound_fraction: float = parameter(
        1e-3, 'Above this share of samples at full scale the J/N of a reported jammer is flagged as a lower bound '
        '(jammer_to_noise_is_lower_bound): clipping caps the measured power. 0..1.', minimum=0.0, maximum=1.0)
    integration: IntegrationParams = field(default_factory=IntegrationParams)
    spectral_step: SpectralStepParams = field(default_factory=SpectralStepParams)

    def __post_init__(self) -> None:
        if self.estimator not in ESTIMATORS:
            raise ValueError(f"estimator must be one of {ESTIMATORS}, got {self.estimator!r}")
        if not -300.0 <= self.noise_floor_dbfs <= 0.0:
            raise ValueError("noise_floor_dbfs must be in [-300, 0] (0: not set)")
        if not 0.0 <= self.clip_lower_bound_fraction <= 1.0:
            raise ValueError("clip_lower_bound_fraction must be in [0, 1]")
        for name in ("min_abs_ratio", "domain_margin", "noise_floor_power", "noise_bandwidth_hz"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {v}")
        if not self.power_time_constant >= 1:
            raise ValueError("power_time_constant must be >= 1")
        if not 0 < self.phase_gain <= 1:
            raise ValueError("phase_gain must be in (0, 1]")
        if int(self.calibration_blocks) < 1:
            raise ValueError("calibration_blocks must be >= 1")
        for name in ("signal_power_dbm", "noise_density_dbm_per_mhz"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite")
        if not 0 <= self.max_invalid_fraction <= 1:
            raise ValueError("max_invalid_fraction must be in [0, 1]")
        if self.min_block_samples < self.classifier.nfft:
            raise ValueError("min_block_samples must be >= classifier.nfft")
        if not 0 <= int(self.refine_window) <= MAX_REFINE_WINDOW:
            raise ValueError(f"refine_window must be in 0..{MAX_REFINE_WINDOW}")
        if int(self.confirm_fits) < 0:
            raise ValueError("confirm_fits must be >= 0")
        if not 0.0 <= self.lattice_period_drift <= 0.01:
            raise ValueError("lattice_period_drift must be in [0, 0.01]")

    @staticmethod
    def paper_method(**kw: Any) -> RfiMonitorParams:
        """Parameters that run Kang et al.'s method only (``Method.paper()``: no step-fit lattice, no
        periodicity detector, the period from successive peak intervals, the AR enhancement at
        decimation 2); keyword arguments set the other fields."""
        kw.setdefault("estimator", "kalman")
        return Method.paper().apply(RfiMonitorParams(**kw))

    @property
    def method(self) -> Method:
        """The paper-vs-ours switches of these parameters."""
        return Method.of(self)
