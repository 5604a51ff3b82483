"""Parameters of rfi_monitor_node: the core's RfiMonitorParams flattened, plus the node's own (pure: no rclpy).

Documented for users in config/rfi_monitor.yaml (test_config_yaml_equals_defaults keeps the two equal).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from rfi_monitor.classifier import ClassifierParams
from rfi_monitor.integration import IntegrationParams
from rfi_monitor.load_policy import SHED_CREDIT_CAP_S
from rfi_monitor.monitor import RfiMonitorParams
from rfi_monitor.params import ESTIMATORS
from rfi_monitor.ridge import RidgeParams
from rfi_monitor.spectral_step import SpectralStepParams
from rfi_monitor.spectrum_view import WaterfallParams
from rfi_monitor.sweep_analysis import SweepAnalysisParams
from rfi_monitor.sweep_period import SweepPeriodParams
from rfi_monitor.tracker import MAX_REFINE_WINDOW
from rfi_monitor.tracking_filters import MODE_AFKF, MODE_AKF, MODE_KF, TrackingFilterParams
from rfi_node_common.diagnostics import (
    diagnostics_window_parameter,
    hardware_id_parameter,
    input_timeout_parameter,
    max_stamp_jump_parameter,
    stamp_jump_confirmations_parameter,
    warn_lost_fraction_parameter,
    warn_rejected_fraction_parameter,
)
from rfi_node_common.params import parameter, parameter_from, validate_ranges

TRACKER_MODES = {'kf': MODE_KF, 'akf': MODE_AKF, 'afkf': MODE_AFKF}
"""tracker_mode parameter -> tracking_filters mode code."""

NESTED = (('tracker', 'tracker_', TrackingFilterParams), ('sweep', 'sweep_', SweepPeriodParams),
          ('classifier', 'classifier_', ClassifierParams), ('analysis', 'analysis_', SweepAnalysisParams),
          ('ridge', 'ridge_', RidgeParams), ('integration', 'integration_', IntegrationParams),
          ('spectral_step', 'spectral_step_', SpectralStepParams))
"""(RfiMonitorParams field, node parameter prefix, dataclass) of the core's nested parameter groups."""

_M = RfiMonitorParams()
_T = _M.tracker
_S = _M.sweep
_C = _M.classifier
_A = _M.analysis
_R = _M.ridge
_I = _M.integration
_P = _M.spectral_step


@dataclass(frozen=True)
class MonitorNodeParams:
    """Parameters of rfi_monitor_node (documented for users in config/rfi_monitor.yaml).

    The core's RfiMonitorParams, flattened: its nested groups get the prefixes ``tracker_``,
    ``sweep_``, ``analysis_`` and ``classifier_``; the defaults are the core's own. Node-only parameters:
    diagnostics_period_s, warning_throttle_s, input_timeout_s, max_stamp_jump_s, stamp_jump_confirmations,
    check_saturation, max_block_samples.

    Notes:
        Kang et al.: tracking filters eq. 11-22 (tracker_*), sweep period eq. 23-27 (sweep_*);
        Kang et al. give no values for most of them (see docs/rfi_monitor/README.md for ours). The
        identification (classifier_*) is not in the paper.
    """

    # --- node ---------------------------------------------------------------------------------
    diagnostics_period_s: float = parameter(
        1.0, 'Period of /diagnostics in message (stamp) time, s.', minimum=0.001, maximum=3600.0)
    warning_throttle_s: float = parameter(
        5.0, 'Shortest interval between two warnings about rejected blocks, s (wall time; logging only).',
        minimum=0.0, maximum=3600.0, read_only=False)
    # diagnostics levels and hardware_id (rfi_node_common.diagnostics), settable while running
    hardware_id: str = hardware_id_parameter('rf_front_end')  # type: ignore[assignment]
    diagnostics_window_s: float = diagnostics_window_parameter()  # type: ignore[assignment]
    warn_rejected_fraction: float = warn_rejected_fraction_parameter()  # type: ignore[assignment]
    warn_lost_fraction: float = warn_lost_fraction_parameter()  # type: ignore[assignment]
    input_timeout_s: float = input_timeout_parameter()  # type: ignore[assignment]
    max_stamp_jump_s: float = max_stamp_jump_parameter(10.0)  # type: ignore[assignment]
    stamp_jump_confirmations: int = stamp_jump_confirmations_parameter(3)  # type: ignore[assignment]
    check_saturation: bool = parameter(
        True, 'Count samples at full scale (two\'s-complement front ends, bits_per_sample >= 4): the block is '
        'analysed, its clipped fraction reported and its J/N flagged as a lower bound.')
    max_cpu_load: float = parameter(
        0.9, 'Live streams only (a replay is analysed in full, always): share of one core the analysis may use, over '
        'the stream time the blocks cover (a continuous stream: the block durations; snapshots: the time between '
        'them). Beyond it blocks get the light analysis '
        '(light_analysis_debt_s) and, beyond that, are shed whole on purpose (blocks_shed on /diagnostics, no '
        'JammerState for them) until it fits again; 0: never shed.',
        minimum=0.0, maximum=1000.0)
    light_analysis_debt_s: float = parameter(
        0.02, 'Estimator stft: while the node is over its max_cpu_load budget by at most this much CPU time, a block '
        'gets the light analysis instead of being shed (its Welch spectrum: type and J/N checked against the last full '
        'analysis, whose sweep period, band and shape it carries; a chirp\'s frequency NaN; blocks_light on '
        '/diagnostics), so that every block is answered while the light analysis keeps up; beyond it blocks are shed. '
        '0: no light analysis (shed at once, as before session 11).', minimum=0.0, maximum=SHED_CREDIT_CAP_S)
    max_block_age_s: float = parameter(
        0.05, 'Live streams only: a block stamped more than this many seconds behind the node clock is shed before '
        'it is deserialised (blocks_shed and blocks_shed_stale), so the answers stay within this latency when the '
        'node is short of CPU. A stream is live when its first block (after the start or a stamp restart) is '
        'stamped within 1 s of the receive clock (live_stream on /diagnostics; rfi_monitor.load_policy); a replay, '
        'whose stamps lie in the past, is never shed nor given the light analysis. 0: off.',
        minimum=0.0, maximum=3600.0)
    analysis_worker: bool = parameter(
        False, 'Run the ridge analysis of each block (estimator stft) in a child process on another core while this '
        'one does the rest of the block (rfi_monitor.analysis_worker): about half the CPU time per block in this '
        'process, the same estimates. For live streams on a machine with a core to spare; a worker that fails is '
        'counted (core.worker_failures) and the node carries on without it.')
    max_block_samples: int = parameter(
        2 ** 22, 'Longest block analysed, samples (complex: I/Q pairs); longer blocks are rejected (long_block). '
        'Bounds memory (about 40 bytes per sample) and the time of one callback.', minimum=1024, maximum=2**31 - 1)
    # --- monitor ------------------------------------------------------------------------------
    estimator: str = parameter(
        _M.estimator, 'stft: short-time FFT ridge analysis per block (ours; real sweep shapes, no clean start '
        'needed); kalman: Kang et al.\'s per-sample tracker (with the switches below).', choices=ESTIMATORS)
    noise_floor_dbfs: float = parameter(
        _M.noise_floor_dbfs, 'Thermal noise power of the front end per real component relative to full scale '
        'squared, dB; the J/N reference when set (needs bits_per_sample >= 4); 0: not documented.',
        minimum=-300.0, maximum=0.0)
    clip_lower_bound_fraction: float = parameter(
        _M.clip_lower_bound_fraction, 'Above this share of samples at full scale the J/N is flagged as a lower '
        'bound, 0..1.', minimum=0.0, maximum=1.0)
    ridge_min_frame_length: int = parameter(
        _R.min_frame_length, 'Shortest short-time FFT frame tried by the stft estimator, samples (power of two).',
        minimum=8, maximum=2**16)
    ridge_max_frame_length: int = parameter(
        _R.max_frame_length, 'Longest short-time FFT frame tried by the stft estimator, samples (power of two).',
        minimum=8, maximum=2**16)
    ridge_select_samples: int = parameter(
        _R.select_samples, 'Samples of a block used to choose the frame length (stft); 0: the whole block.',
        minimum=0, maximum=2**31 - 1)
    ridge_min_period_frames: int = parameter(
        _R.min_period_frames, 'Shortest sweep period searched (stft), frames of half the frame length.',
        minimum=3, maximum=10**6)
    ridge_presence_nats: float = parameter(
        _R.presence_nats, 'Per-frame ridge threshold above ln(bins) (stft), nats of the exponential.',
        minimum=0.1, maximum=100.0)
    ridge_noise_smooth_bins: int = parameter(
        _R.noise_smooth_bins, 'Width of the median across bins of the in-block noise level (stft), odd.',
        minimum=3, maximum=10**4)
    ridge_phase_bins: int = parameter(
        _R.phase_bins, 'Bins of the folded sweep profile (stft).', minimum=8, maximum=4096)
    ridge_hook_rate_ratio: float = parameter(
        _R.hook_rate_ratio, 'A saw-tooth whose two steps after its flyback both exceed this times its median step '
        'is hooked (stft; also hooked: a way back swept over at least two profile bins).', minimum=1.0001, maximum=1e3)
    ridge_min_present_fraction: float = parameter(
        _R.min_present_fraction, 'A non-periodic ridge must be present in at least this share of the frames '
        '(stft), (0, 1].', minimum=1e-6, maximum=1.0)
    ridge_tracking_samples: int = parameter(
        _R.tracking_samples, 'While a chirp is tracked the stft estimator analyses only the last this many '
        'samples of a block (speed; J/N and the CW test use the whole block); 0: the whole block.',
        minimum=0, maximum=2**31 - 1)
    ridge_acquisition_samples: int = parameter(
        _R.acquisition_samples, 'While nothing is tracked the stft estimator analyses only the last this many '
        'samples of a block first and the whole block when that part shows anything (speed; J/N, the CW test and '
        'the evidence over blocks use the whole block); 0: the whole block.', minimum=0, maximum=2**31 - 1)
    ridge_max_period_s: float = parameter(
        _R.max_period_s, 'Longest sweep period searched by the stft estimator, s.', minimum=1e-7, maximum=10.0)
    ridge_detect_sigma: float = parameter(
        _R.detect_sigma, 'Significance of a sweep period (stft), noise standard deviations.',
        minimum=1.0, maximum=100.0)
    ridge_min_strength: float = parameter(
        _R.min_strength, 'Smallest normalised autocorrelation peak of a periodic sweep (stft), (0, 1].',
        minimum=1e-6, maximum=1.0)
    integration_window_s: float = parameter(
        _I.window_s, 'stft: evidence of the blocks stamped within this many seconds is summed to find a weak '
        'stationary CW or chirp that no single block shows, s; 0: off.', minimum=0.0, maximum=60.0)
    integration_false_alarm_per_block: float = parameter(
        _I.false_alarm_per_block, 'stft: false-alarm probability per block of each integrated statistic under '
        'Gaussian noise (sets the thresholds), (0, 0.1].', minimum=1e-12, maximum=0.1)
    integration_frame_length_s: float = parameter(
        _I.frame_length_s, 'stft: frame of the integrated chirp statistic, s (rounded to a power of two of '
        '8..128 samples).', minimum=1e-9, maximum=1.0)
    integration_max_period_s: float = parameter(
        _I.max_period_s, 'stft: longest sweep period of the integrated chirp statistic, s.', minimum=1e-7,
        maximum=1.0)
    integration_max_multiples: int = parameter(
        _I.max_multiples, 'stft: most multiples of a candidate sweep period summed by the integrated chirp '
        'statistic.', minimum=2, maximum=4096)
    integration_nfft: int = parameter(
        _I.nfft, 'stft: Welch frame of the integrated CW statistic, samples (power of two >= 64).', minimum=64,
        maximum=2**20)
    integration_smooth_bins: int = parameter(
        _I.smooth_bins, 'stft: running median (bins, odd >= 5) that is the integrated CW statistic\'s noise '
        'reference.', minimum=5, maximum=4095)
    integration_decide_interval_s: float = parameter(
        _I.decide_interval_s, 'stft: the integrated statistics are tested at most once per this many seconds of '
        'stamps (speed); blocks in between get the last decision, s; 0: every block.', minimum=0.0, maximum=10.0)
    integration_min_chirp_strength: float = parameter(
        _I.min_chirp_strength, 'stft: a periodic sweep found over blocks is reported only when this share of the '
        'amplitudes\' variance repeats at its period (the faint periodic modulations of real front ends stay below '
        'it; a chirp at J/N -5 dB measures 0.017 or more), [0, 1).', minimum=0.0, maximum=0.999)
    integration_sub_windows: int = parameter(
        _I.sub_windows, 'stft: the integrated statistics are also tested on the newest integration_window_s / 4**k '
        'seconds, k = 1..this (a jammer that just switched on is found without the dilution of a window of clean '
        'blocks; Bonferroni over the sums tested); 0: the whole window only.', minimum=0, maximum=4)
    integration_max_samples_per_s: float = parameter(
        _I.max_samples_per_s, 'stft: processing budget of the evidence over blocks, samples per second of stamps '
        '(deterministic): beyond it blocks are left out of the sums (counted, integration_blocks_thinned); 0: no '
        'limit.', minimum=0.0, maximum=1e12)
    spectral_step_enabled: bool = parameter(
        _P.enabled, 'stft: look for a band of the spectrum that rose against the shape of the blocks that passed as '
        'noise (a noise jammer in part of the band, seen behind an AGC that hides its power): WIDEBAND with the '
        'band\'s centre in frequency_hz.')
    spectral_step_window_s: float = parameter(
        _P.window_s, 'stft: the spectral-step test sums the blocks stamped within this many seconds (1, 4, 16, ... '
        'and all of them), s.', minimum=0.0, maximum=60.0)
    spectral_step_groups: int = parameter(
        _P.groups, 'stft: groups (of >= 2 Welch bins) the band is cut into by the spectral-step test.', minimum=8,
        maximum=4096)
    spectral_step_false_alarm_per_block: float = parameter(
        _P.false_alarm_per_block, 'stft: false-alarm probability per block of the spectral-step test under Gaussian '
        'noise (Bonferroni over bands and scales), (0, 0.1].', minimum=1e-12, maximum=0.1)
    spectral_step_min_step_db: float = parameter(
        _P.min_step_db, 'stft: smallest rise of a band over the rest of the spectrum reported, dB (drift of the '
        'front end\'s shape is no jammer).', minimum=1e-3, maximum=60.0)
    spectral_step_max_band_fraction: float = parameter(
        _P.max_band_fraction, 'stft: widest band that rose reported, share of the sampled band, (0, 0.5].',
        minimum=0.01, maximum=0.5)
    spectral_step_reference_blocks: int = parameter(
        _P.reference_blocks, 'stft: memory of the spectral-step reference shape, blocks (exponential).', minimum=1,
        maximum=10**7)
    spectral_step_min_reference_blocks: int = parameter(
        _P.min_reference_blocks, 'stft: blocks in the reference shape before the spectral-step test runs.',
        minimum=1, maximum=10**7)
    spectral_step_learn_z: float = parameter(
        _P.learn_z, 'stft: a block whose spectral-step z (any scale) exceeds this does not enter the reference.',
        minimum=0.1, maximum=1e3)
    spectral_step_relearn_after_s: float = parameter(
        _P.relearn_after_s, 'stft: a spectrum that differs from the spectral-step reference (z over '
        'spectral_step_learn_z) without a break for this long makes the reference be learned again, s (a changed '
        'front end; also a partial-band noise jammer behind an AGC that stays on longer); 0: never.', minimum=0.0,
        maximum=1e6)
    spectral_step_decide_interval_s: float = parameter(
        _P.decide_interval_s, 'stft: the spectral-step sums are tested at most once per this many seconds of stamps '
        '(speed); blocks in between are added and get the last decision, s; 0: every block.', minimum=0.0,
        maximum=10.0)
    chirp_correction: bool = parameter(
        _M.chirp_correction, 'Correct the three-sample IF measurement for the sweep (Kang et al., eq. 10; '
        'real samples only).')
    reset_at_sweep_start: bool = parameter(
        _M.reset_at_sweep_start, 'Reset the tracking filter at estimated sweep starts (Kang et al., eq. 21-22).')
    min_abs_ratio: float = parameter(
        _M.min_abs_ratio, 'Near-zero guard: a sample with |x| <= this times the running RMS gives no '
        'measurement, dimensionless.', minimum=0.0, maximum=1.0)
    domain_margin: float = parameter(
        _M.domain_margin, 'arccos domain margin: a measurement ratio beyond 1 + this is rejected, dimensionless.',
        minimum=0.0, maximum=10.0)
    power_time_constant: float = parameter(
        _M.power_time_constant, 'Time constant of the running RMS used by the near-zero guard, samples.',
        minimum=1.0, maximum=1e9)
    phase_gain: float = parameter(
        _M.phase_gain, 'Gain of the sweep-start lattice phase correction, (0, 1].', minimum=1e-6, maximum=1.0)
    noise_floor_power: float = parameter(
        _M.noise_floor_power, 'Fixed noise power of the decoded samples, V^2 (counts * scale, squared); '
        '0: learn it from the first calibration_blocks blocks.', minimum=0.0, maximum=1e12)
    calibration_blocks: int = parameter(
        _M.calibration_blocks, 'Blocks used to learn the noise floor and the front-end noise shape.',
        minimum=1, maximum=100000)
    signal_power_dbm: float = parameter(
        _M.signal_power_dbm, 'Nominal GNSS signal power S for J/S, dBm (Kang et al.: -130).',
        minimum=-250.0, maximum=50.0)
    noise_density_dbm_per_mhz: float = parameter(
        _M.noise_density_dbm_per_mhz, 'Nominal noise density for J/S, dBm/MHz (Kang et al.: -114).',
        minimum=-250.0, maximum=50.0)
    noise_bandwidth_hz: float = parameter(
        _M.noise_bandwidth_hz, 'Bandwidth of the nominal noise power for J/S, Hz; 0: the sampled band.',
        minimum=0.0, maximum=1e10)
    max_invalid_fraction: float = parameter(
        _M.max_invalid_fraction, 'A block with more saturated (or non-finite) samples than this fraction is '
        'rejected, 0..1.', minimum=0.0, maximum=1.0)
    min_block_samples: int = parameter(
        _M.min_block_samples, 'Shortest block analysed, samples (complex: I/Q pairs); >= classifier_nfft.',
        minimum=32, maximum=2**31 - 1)
    refine_window: int = parameter(
        _M.refine_window, 'Half-window W of the sweep-start step fit that refines the reset lattice (ours), '
        'samples; 0 runs the paper\'s lattice (LPD peaks only).', minimum=0, maximum=MAX_REFINE_WINDOW)
    lattice_period_drift: float = parameter(
        _M.lattice_period_drift, 'Random walk of the sweep period per sweep, relative, of the step-fit lattice '
        'filter (ours), 0..0.01.', minimum=0.0, maximum=0.01)
    noise_compensation: bool = parameter(
        _M.noise_compensation, 'Divide the real three-sample ratio by kappa = 1 - N/P (removes eq. 8\'s bias '
        'towards fs/4 at moderate J/N; ours). No effect on complex samples.')
    confirm_fits: int = parameter(
        _M.confirm_fits, 'Tracking mode (ours): after this many consecutive significant sweep-start fits the '
        'LPD/AR(10)/peak search is suspended until fits fail; 0: always search (the paper).',
        minimum=0, maximum=10**6)
    reset_cross_covariance: bool = parameter(
        _M.reset_cross_covariance, 'At a sweep reset keep the exact covariance of eq. 21 instead of eq. 22 '
        '(ours).')
    # --- tracking filter (Kang et al., eq. 11-22) ----------------------------------------------
    tracker_mode: str = parameter(
        'afkf', 'Frequency tracking filter: kf (eq. 11-17), akf (adaptive gain) or afkf (adaptive fading, '
        'the proposed filter).', choices=tuple(TRACKER_MODES))
    tracker_measurement_std: float = parameter(
        _T.measurement_std, 'sigma_v of the IF measurement (eq. 20), cycles/sample.', minimum=1e-9, maximum=1.0)
    tracker_process_std: float = parameter(
        _T.process_std, 'sigma_w on the frequency (eq. 19), cycles/sample.', minimum=0.0, maximum=1.0)
    tracker_process_rate_std: float = parameter(
        _T.process_rate_std, 'Process noise on the sweep rate per sample, cycles/sample^2 (eq. 19: 0).',
        minimum=0.0, maximum=1.0)
    tracker_window: int = parameter(
        _T.window, 'Innovation window M of the adaptive filters (eq. 12), samples.', minimum=2, maximum=100000)
    tracker_initial_frequency: float = parameter(
        _T.initial_frequency, 'Frequency at start and after a reset, cycles/sample.', minimum=-1.0, maximum=1.0)
    tracker_initial_frequency_std: float = parameter(
        _T.initial_frequency_std, '1-sigma of the initial frequency, cycles/sample.', minimum=1e-12, maximum=1.0)
    tracker_initial_rate_std: float = parameter(
        _T.initial_rate_std, '1-sigma of the initial sweep rate, cycles/sample^2.', minimum=1e-12, maximum=1.0)
    # --- sweep period (Kang et al., eq. 23-27) -------------------------------------------------
    sweep_forgetting: float = parameter(
        _S.forgetting, 'Forgetting factor gamma of the LPD (eq. 23), [0, 1).', minimum=0.0, maximum=0.999999)
    sweep_beta: float = parameter(
        _S.beta, 'Normalisation beta of the LPD (eq. 23), dimensionless.', minimum=1e-12, maximum=1e6)
    sweep_beta_en: float = parameter(
        _S.beta_en, 'Enhancement rate beta_en of the peak threshold, dimensionless.', minimum=0.0, maximum=1e6)
    sweep_kappa: float = parameter(
        _S.kappa, 'Peak threshold in multiples of the running mean |zAR|, dimensionless.',
        minimum=1e-6, maximum=1e6)
    sweep_noise_time_constant: float = parameter(
        _S.noise_time_constant, 'Time constant of the running mean |zAR|, decimated steps.',
        minimum=1.0, maximum=1e9)
    sweep_decimation: int = parameter(
        _S.decimation, 'Samples averaged per AR(10) step (speed), samples.', minimum=1, maximum=1000)
    sweep_ar_process_var: float = parameter(
        _S.ar_process_var, 'Diagonal of Q_AR (eq. 25), dimensionless.', minimum=1e-12, maximum=1e12)
    sweep_ar_measurement_var: float = parameter(
        _S.ar_measurement_var, 'sigma_AR^2 (eq. 26), dimensionless.', minimum=1e-12, maximum=1e12)
    sweep_ar_transition: float = parameter(
        _S.ar_transition, 'Diagonal of the AR transition A (eq. 25; paper: 0.2), (-1, 1).',
        minimum=-0.999999, maximum=0.999999)
    sweep_delay: float = parameter(
        _S.delay, 'Samples from a sweep start to its detected peak (group delay), samples.',
        minimum=0.0, maximum=1e6)
    sweep_min_separation: int = parameter(
        _S.min_separation, 'Refractory time between two detected sweep starts, samples.', minimum=1, maximum=10**9)
    sweep_tolerance: float = parameter(
        _S.tolerance, 'Relative tolerance of a sweep interval to a multiple of the period, (0, 0.5).',
        minimum=1e-6, maximum=0.499999)
    sweep_min_consistent: int = parameter(
        _S.min_consistent, 'Peaks fitting the period lattice needed to lock, minus one.', minimum=1, maximum=100000)
    sweep_min_tolerance_samples: float = parameter(
        _S.min_tolerance_samples, 'Absolute floor of the lattice tolerance, samples.', minimum=0.0, maximum=1e6)
    sweep_max_period: float = parameter(
        _S.max_period, 'Longest sweep period considered by the lattice voting, samples (> sweep_min_separation).',
        minimum=1.0, maximum=1e9)
    sweep_lattice_voting: bool = parameter(
        _S.lattice_voting, 'Sweep period by lattice voting over all recent peaks (ours) instead of successive '
        'intervals (the paper).')
    # --- periodicity detector (ours) -----------------------------------------------------------
    analysis_enabled: bool = parameter(
        _A.enabled, 'Run the block-level periodicity detector of the frequency track (seeds the reset lattice '
        'and the identification).')
    analysis_hop_s: float = parameter(
        _A.hop_s, 'Interval between two periodicity analyses (at absolute sample indices), s.',
        minimum=1e-7, maximum=10.0)
    analysis_min_strength: float = parameter(
        _A.min_strength, 'Normalised autocorrelation peak-to-trough of a periodic track, (0, 1.5].',
        minimum=1e-6, maximum=1.5)
    analysis_min_lag: int = parameter(
        _A.min_lag, 'Shortest period detected, decimated samples.', minimum=2, maximum=10**9)
    analysis_max_period_fraction: float = parameter(
        _A.max_period_fraction, 'Longest period as a fraction of the analysed window, (0, 0.5].',
        minimum=1e-6, maximum=0.5)
    analysis_min_window: int = parameter(
        _A.min_window, 'Fewest decimated values for an analysis.', minimum=64, maximum=10**9)
    analysis_skip_while_tracking: bool = parameter(
        _A.skip_while_tracking, 'No periodicity analysis while in tracking mode (the confirmed lattice is then '
        'the periodicity evidence).')
    # --- identification (not in the paper) ----------------------------------------------------
    classifier_nfft: int = parameter(
        _C.nfft, 'Welch frame length, samples (a power of two).', minimum=32, maximum=2**20)
    classifier_max_frames: int = parameter(
        _C.max_frames, 'At most this many Welch frames per block.', minimum=8, maximum=10**7)
    classifier_sig_sigma: float = parameter(
        _C.sig_sigma, 'Significance of an occupied spectral bin, standard deviations of the Welch average.',
        minimum=1e-6, maximum=1e3)
    classifier_min_excess: float = parameter(
        _C.min_excess, 'Smallest relative excess of an occupied bin over the noise, dimensionless.',
        minimum=1e-6, maximum=1e6)
    classifier_detect_jn_db: float = parameter(
        _C.detect_jn_db, 'J/N above which a jammer is declared, dB.', minimum=-100.0, maximum=100.0)
    classifier_cw_max_occupancy: float = parameter(
        _C.cw_max_occupancy, 'Largest occupied fraction of the band of a CW, (0, 1).',
        minimum=1e-6, maximum=0.999999)
    classifier_min_chirp_rate: float = parameter(
        _C.min_chirp_rate, '|Sweep rate| that marks a chirp before the period locks, cycles/sample^2.',
        minimum=1e-12, maximum=1.0)
    classifier_template_smooth_bins: int = parameter(
        _C.template_smooth_bins, 'Width of the median filter smoothing the learned noise shape, bins.',
        minimum=1, maximum=2**20)
    classifier_sidelobe_db: float = parameter(
        _C.sidelobe_db, 'Bins more than this below the strongest excess are not occupied, dB.',
        minimum=0.0, maximum=300.0)
    classifier_confidence_slope_db: float = parameter(
        _C.confidence_slope_db, 'J/N margin that maps to a logistic confidence of 0.73, dB.',
        minimum=1e-6, maximum=100.0)

    # --- topics made to be drawn (issue 30; defined in rfi_monitor.spectrum_view) ---------------
    spectrum_rate_hz: float = parameter_from(WaterfallParams, 'spectrum_rate_hz')
    spectrum_rows: int = parameter_from(WaterfallParams, 'spectrum_rows')
    spectrum_min_dbfs: float = parameter_from(WaterfallParams, 'spectrum_min_dbfs')
    spectrum_max_dbfs: float = parameter_from(WaterfallParams, 'spectrum_max_dbfs')
    spectrum_frame_id: str = parameter_from(WaterfallParams, 'spectrum_frame_id')

    def __post_init__(self) -> None:
        validate_ranges(self)
        WaterfallParams(**{f.name: getattr(self, f.name) for f in dataclasses.fields(WaterfallParams)})
        if self.max_block_samples < self.min_block_samples:
            raise ValueError(f'max_block_samples {self.max_block_samples} must be >= min_block_samples '
                             f'{self.min_block_samples}')
        try:
            self.monitor_params()
        except ValueError as err:
            raise ValueError(f'invalid monitor parameters: {err}') from None

    def monitor_params(self) -> RfiMonitorParams:
        """The core's parameters. Core fields without a node parameter keep the core's default.

        Raises:
            ValueError: a combination the core rejects (e.g. min_block_samples < classifier_nfft).
        """
        own = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        nested: dict[str, Any] = {}
        for name, prefix, cls in NESTED:
            values = {f.name: own[prefix + f.name] for f in dataclasses.fields(cls) if prefix + f.name in own}
            if cls is TrackingFilterParams:
                values['mode'] = TRACKER_MODES[self.tracker_mode]
            nested[name] = dataclasses.replace(getattr(_M, name), **values)
        top = {f.name: own[f.name] for f in dataclasses.fields(RfiMonitorParams)
               if f.name in own and f.name not in nested}
        return dataclasses.replace(_M, **top, **nested)
