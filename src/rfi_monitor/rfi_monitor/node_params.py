"""Parameters of rfi_monitor_node, each written once: the core's RfiMonitorParams flattened, plus the node's own
(pure: no rclpy).

The core's scalar parameters are defined in :class:`rfi_monitor.params.RfiMonitorParams` (default, description,
range, group) and taken with :func:`rfi_node_common.params.parameter_from`; those of its nested groups (tracker_,
sweep_, classifier_, analysis_, ridge_, integration_, spectral_step_) take their defaults from the core's dataclasses
and are described here; the stamp gate's and /diagnostics' come from
:class:`rfi_node_common.diagnostics.NodeDiagnosticsParams`. The shipped ``config/rfi_monitor.yaml`` and the user table
of docs/reference/parameters.md are generated from them (:data:`CONFIG_FILE`, ``tools/generate_config.py``, checked by
a test).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from rfi_monitor.classifier import ClassifierParams
from rfi_monitor.integration import IntegrationParams
from rfi_monitor.load_policy import SHED_CREDIT_CAP_S
from rfi_monitor.monitor import RfiMonitorParams
from rfi_monitor.ridge import RidgeParams
from rfi_monitor.spectral_step import SpectralStepParams
from rfi_monitor.spectrum_view import WaterfallParams
from rfi_monitor.sweep_analysis import SweepAnalysisParams
from rfi_monitor.sweep_period import SweepPeriodParams
from rfi_monitor.tracking_filters import MODE_AFKF, MODE_AKF, MODE_KF, TrackingFilterParams
from rfi_node_common.diagnostics import (
    NodeDiagnosticsParams,
    hardware_id_parameter,
    max_stamp_jump_parameter,
    stamp_jump_confirmations_parameter,
)
from rfi_node_common.params import USER, ConfigFile, parameter, parameter_from, validate_ranges

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
class MonitorNodeParams(NodeDiagnosticsParams):
    """Parameters of rfi_monitor_node (config/rfi_monitor.yaml, generated from them, documents each).

    The core's RfiMonitorParams, flattened: its nested groups get the prefixes ``tracker_``, ``sweep_``,
    ``classifier_``, ``analysis_``, ``ridge_``, ``integration_`` and ``spectral_step_``; the defaults are the
    core's own. Node-only parameters: those of :class:`NodeDiagnosticsParams` (``hardware_id``,
    ``max_stamp_jump_s`` and ``stamp_jump_confirmations`` with the monitor's defaults), check_saturation, the
    load policy's (max_cpu_load, light_analysis_debt_s, max_block_age_s), analysis_worker, max_block_samples.

    Notes:
        Kang et al.: tracking filters eq. 11-22 (tracker_*), sweep period eq. 23-27 (sweep_*);
        Kang et al. give no values for most of them (see docs/rfi_monitor/README.md for ours). The
        identification (classifier_*) is not in the paper.
    """

    # --- node ---------------------------------------------------------------------------------
    hardware_id: str = hardware_id_parameter('rf_front_end')
    max_stamp_jump_s: float = max_stamp_jump_parameter(10.0)
    stamp_jump_confirmations: int = stamp_jump_confirmations_parameter(3)
    check_saturation: bool = parameter(
        True,
        "Count samples at full scale ((2^(bits-1) - 1) * scale; two's-complement front ends with bits_per_sample >= 4"
        ' only). A clipped block is analysed (clipping is evidence of a strong jammer): the clipped fraction goes '
        'into the JammerState and /diagnostics.')
    max_cpu_load: float = parameter(
        0.9, 'Live streams only (rfi_monitor/load_policy.py: the first block of a time line stamped within 1 s of the '
        'receive clock); a replay (bag, play --max, --rate N) is analysed in full, always. Share of one core the '
        'analysis may use over the stream time the blocks cover (continuous stream: the block durations; snapshots: '
        'the time between blocks). Beyond it blocks get the light analysis (light_analysis_debt_s) and, beyond '
        'that, are shed whole on purpose (blocks_shed on /diagnostics, no JammerState for them) until the CPU time '
        'fits again; the estimates of the analysed blocks stay valid. 0.0: never shed (a slow machine then falls '
        'behind and the middleware drops blocks). docs/rfi_monitor/speed.md has the measured cost.',
        minimum=0.0, maximum=1000.0, group=USER)
    light_analysis_debt_s: float = parameter(
        0.02,
        'Live streams only. Estimator stft: while the node is over its max_cpu_load budget by at most this much CPU '
        'time (s), or on a live stream after 10 ms in the input queue or 10 ms behind the clock, a block gets the '
        'light analysis instead of the full one or being shed: its Welch spectrum, type and J/N checked against the '
        'last full analysis (at most 10 ms before; 50 ms after a NONE), whose sweep period, band, rate and shape it '
        "carries; a chirp's frequency_hz is NaN. A block that disagrees (a jammer appearing, leaving, changing power "
        'by 3 dB) is analysed in full. blocks_light and core.light_escalations on /diagnostics; '
        'docs/rfi_monitor/live_stream.md. 0.0: off (shed at once, as before session 11).',
        minimum=0.0, maximum=SHED_CREDIT_CAP_S)
    max_block_age_s: float = parameter(
        0.05,
        'Live streams only: a block stamped more than this many seconds behind the node clock is shed before it is '
        'deserialised (blocks_shed and blocks_shed_stale on /diagnostics), so a node that is short of CPU answers the'
        ' newest blocks within this latency instead of working through its input queue. A stream is live when its '
        'first block (after the start or a stamp restart) is stamped within 1 s of the receive clock (live_stream on '
        '/diagnostics): a replay, whose stamps lie in the past, is never shed nor given the light analysis. 0.0: off.',
        minimum=0.0, maximum=3600.0)
    analysis_worker: bool = parameter(
        False,
        'Run the ridge analysis of each block (estimator stft) in a child process on another core while the node does'
        " the rest of the block (rfi_monitor/analysis_worker.py): about half the CPU time per block in the node's own"
        ' process, the same estimates. For live streams on a machine with a core to spare; a worker that fails is '
        'counted (core.worker_failures) and the node carries on alone.', group=USER)
    max_block_samples: int = parameter(
        2 ** 22,
        'Longest block analysed, samples (complex: I/Q pairs); longer blocks are rejected (long_block). Bounds the '
        'memory of one block (about 40 bytes per sample) and the time of one callback: 4194304 samples are 110 ms at '
        '38.192 MHz. Raise it for a front end that sends longer blocks.', minimum=1024, maximum=2**31 - 1)
    # --- monitor ------------------------------------------------------------------------------
    estimator: str = parameter_from(RfiMonitorParams, 'estimator')
    noise_floor_dbfs: float = parameter_from(RfiMonitorParams, 'noise_floor_dbfs')
    clip_lower_bound_fraction: float = parameter_from(RfiMonitorParams, 'clip_lower_bound_fraction')
    ridge_min_frame_length: int = parameter(
        _R.min_frame_length,
        'Shortest short-time FFT frame tried by the stft estimator, samples (power of two): the frame lengths tried '
        'are the powers of two from ridge_min_frame_length to ridge_max_frame_length; the one where the ridge stands '
        'highest above the noise is used (a sweep of k cycles/sample^2 is sharpest near 1/sqrt(k) samples), chosen '
        'every 4 blocks while no jammer is tracked, every 64 blocks while one is.', minimum=8, maximum=2**16)
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
        _R.presence_nats,
        "stft: a frame's ridge is present when its excess over the noise exceeds ln(bins) + this (nats of the "
        'exponential; 4.6: 1 % of noise frames).', minimum=0.1, maximum=100.0)
    ridge_noise_smooth_bins: int = parameter(
        _R.noise_smooth_bins, 'Width of the median across bins of the in-block noise level (stft), odd.',
        minimum=3, maximum=10**4)
    ridge_phase_bins: int = parameter(
        _R.phase_bins, 'stft: bins of the folded sweep profile (shape, swept band, rate).', minimum=8, maximum=4096)
    ridge_hook_rate_ratio: float = parameter(
        _R.hook_rate_ratio,
        'stft: a saw-tooth whose two steps after its flyback both exceed this times its median step is hooked (so is '
        'one whose way back is swept over at least two profile bins).', minimum=1.0001, maximum=1e3)
    ridge_min_present_fraction: float = parameter(
        _R.min_present_fraction,
        'A non-periodic ridge must be present in at least this share of the frames (stft), (0, 1].',
        minimum=1e-6, maximum=1.0)
    ridge_tracking_samples: int = parameter(
        _R.tracking_samples,
        'stft: while a chirp is tracked only the last this many samples of a block are analysed (speed: 16384 samples'
        ' are 0.43 ms at 38.192 MS/s, 1.6 ms at 10 MS/s; the J/N and the CW test use the whole block; a block whose '
        'tail shows no sweep is analysed whole). 0: always the whole block.', minimum=0, maximum=2**31 - 1)
    ridge_acquisition_samples: int = parameter(
        _R.acquisition_samples,
        'stft: while nothing is tracked only the last this many samples of a block are analysed first, and the whole '
        "block when that part shows anything (a type other than NONE, a sweep, a period): quiet blocks at the paper's"
        " 38.192 MS/s are analysed as a 16.4 MS/s front end's 1 ms block is (speed; the J/N, the CW test and the "
        'evidence over blocks use the whole block). 0: always the whole block.', minimum=0, maximum=2**31 - 1)
    ridge_max_period_s: float = parameter(
        _R.max_period_s, 'stft: longest sweep period searched, s (also at most a quarter of the analysed samples).',
        minimum=1e-7, maximum=10.0)
    ridge_detect_sigma: float = parameter(
        _R.detect_sigma, 'stft: significance of a sweep period, standard deviations of the noise autocorrelation.',
        minimum=1.0, maximum=100.0)
    ridge_min_strength: float = parameter(
        _R.min_strength, 'stft: smallest normalised autocorrelation peak-to-trough of a periodic sweep, (0, 1].',
        minimum=1e-6, maximum=1.0)
    integration_window_s: float = parameter(
        _I.window_s,
        'stft: evidence over blocks (docs/rfi_monitor/integration.md). When a block alone shows nothing, the sums '
        'over the blocks stamped within the last integration_window_s seconds decide: a tone in the summed Welch PSD '
        '(CW, from classifier_detect_jn_db) or a periodic sweep in the summed 2-D autocorrelation of the short-time '
        'spectrum (CHIRP, with its period). Blocks need not be contiguous (1 ms snapshots once a second are summed '
        'too); a change of rate/IF restarts it. Thresholds from the noise statistics: false alarm per block <= '
        'integration_false_alarm_per_block under Gaussian noise (Bonferroni). 0: off.', minimum=0.0, maximum=60.0)
    integration_false_alarm_per_block: float = parameter(
        _I.false_alarm_per_block,
        'stft: false-alarm probability per block of each integrated statistic under Gaussian noise (sets the '
        'thresholds), (0, 0.1].', minimum=1e-12, maximum=0.1)
    integration_frame_length_s: float = parameter(
        _I.frame_length_s,
        'stft: frame of the integrated chirp statistic, s (power of two of 8..128 samples); a sweep must move less '
        'than about a bin per frame (k L^2 bins at k cycles/sample^2).', minimum=1e-9, maximum=1.0)
    integration_max_period_s: float = parameter(
        _I.max_period_s, 'stft: longest sweep period of the integrated chirp statistic, s.', minimum=1e-7, maximum=1.0)
    integration_max_multiples: int = parameter(
        _I.max_multiples, 'stft: most multiples of a candidate sweep period summed by the integrated chirp statistic.',
        minimum=2, maximum=4096)
    integration_nfft: int = parameter(
        _I.nfft, 'stft: Welch frame of the integrated CW statistic, samples (power of two >= 64).',
        minimum=64, maximum=2**20)
    integration_smooth_bins: int = parameter(
        _I.smooth_bins, "stft: running median (bins, odd >= 5) that is the integrated CW statistic's noise reference.",
        minimum=5, maximum=4095)
    integration_decide_interval_s: float = parameter(
        _I.decide_interval_s,
        'stft: the integrated statistics are tested at most once per this many seconds of stamps (the test costs '
        'about as much as adding a block); blocks in between get the last decision. 0: every block.',
        minimum=0.0, maximum=10.0)
    integration_min_chirp_strength: float = parameter(
        _I.min_chirp_strength,
        "stft: a periodic sweep found over blocks is reported only when this share of the amplitudes' variance "
        'repeats at its period: the clean 4 MS/s PocketSDR capture has a periodic modulation of 0.0008-0.0019, '
        'significant after 280 blocks; chirps at J/N -5 dB measured 0.017 and more.', minimum=0.0, maximum=0.999)
    integration_sub_windows: int = parameter(
        _I.sub_windows,
        'stft: the sums are also tested over the newest integration_window_s / 4**k seconds, k = 1..this (0: the '
        'whole window only): after 600 clean 1 ms blocks a chirp at J/N -8 dB on the 2-bit captures was not found '
        'within 80 blocks of switch-on with the whole window alone, after 13-25 with 2 sub-windows, 3-5 with 3. '
        'Bonferroni over the sums tested; 3 cost about 0.15 ms per 1 ms block of 38.192 MS/s real IF.',
        minimum=0, maximum=4)
    integration_max_samples_per_s: float = parameter(
        _I.max_samples_per_s,
        'stft: processing budget of the evidence over blocks, samples per second of stamps (deterministic, not the '
        "machine's load): every block is added up to 16.5 MS/s, 43 % of the 1 ms blocks of a 38.192 MS/s stream (the "
        'rest get the last decision; counted as integration_blocks_thinned). 0: all.', minimum=0.0, maximum=1e12)
    spectral_step_enabled: bool = parameter(
        _P.enabled,
        'stft: a noise jammer in part of the band behind an AGC (which hides its power): the band of the spectrum '
        'that rose against the shape of the blocks that passed as noise (rfi_monitor.spectral_step, '
        'docs/rfi_monitor/sensitivity.md). The sums of the last 1, 4, 16, ... blocks (and all) stamped within '
        'spectral_step_window_s are tested; bands of 2 groups up to spectral_step_max_band_fraction of the sampled '
        'band; z threshold from spectral_step_false_alarm_per_block under Gaussian noise (Bonferroni), and the rise '
        "must exceed spectral_step_min_step_db (dB). WIDEBAND, frequency_hz the band's centre, frequency_std_hz its "
        'width / sqrt(12), J/N against the learned shape.')
    spectral_step_window_s: float = parameter(
        _P.window_s,
        'stft: the spectral-step test sums the blocks stamped within this many seconds (1, 4, 16, ... and all of '
        'them), s.', minimum=0.0, maximum=60.0)
    spectral_step_groups: int = parameter(
        _P.groups, 'stft: groups (of >= 2 Welch bins) the band is cut into by the spectral-step test.',
        minimum=8, maximum=4096)
    spectral_step_false_alarm_per_block: float = parameter(
        _P.false_alarm_per_block,
        'stft: false-alarm probability per block of the spectral-step test under Gaussian noise (Bonferroni over '
        'bands and scales), (0, 0.1].', minimum=1e-12, maximum=0.1)
    spectral_step_min_step_db: float = parameter(
        _P.min_step_db,
        "stft: smallest rise of a band over the rest of the spectrum reported, dB (drift of the front end's shape is "
        'no jammer).', minimum=1e-3, maximum=60.0)
    spectral_step_max_band_fraction: float = parameter(
        _P.max_band_fraction, 'stft: widest band that rose reported, share of the sampled band, (0, 0.5].',
        minimum=0.01, maximum=0.5)
    spectral_step_reference_blocks: int = parameter(
        _P.reference_blocks, 'stft: memory of the spectral-step reference shape, blocks (exponential).',
        minimum=1, maximum=10**7)
    spectral_step_min_reference_blocks: int = parameter(
        _P.min_reference_blocks, 'stft: blocks in the reference shape before the spectral-step test runs.',
        minimum=1, maximum=10**7)
    spectral_step_learn_z: float = parameter(
        _P.learn_z, 'stft: a block whose spectral-step z (any scale) exceeds this does not enter the reference.',
        minimum=0.1, maximum=1e3)
    spectral_step_relearn_after_s: float = parameter(
        _P.relearn_after_s,
        'stft: a spectrum that differs from the spectral-step reference (z over spectral_step_learn_z) without a '
        'break for this long makes the reference be learned again, s: a changed front end is not reported for ever; a'
        ' partial-band noise jammer behind an AGC that stays on longer becomes the reference. 0: never.',
        minimum=0.0, maximum=1e6)
    spectral_step_decide_interval_s: float = parameter(
        _P.decide_interval_s,
        'stft: the spectral-step sums are tested at most once per this many seconds of stamps (a test costs a few '
        'times adding a block); blocks in between are added and get the last decision, s. 0: every block.',
        minimum=0.0, maximum=10.0)
    chirp_correction: bool = parameter_from(RfiMonitorParams, 'chirp_correction')
    reset_at_sweep_start: bool = parameter_from(RfiMonitorParams, 'reset_at_sweep_start')
    min_abs_ratio: float = parameter_from(RfiMonitorParams, 'min_abs_ratio')
    domain_margin: float = parameter_from(RfiMonitorParams, 'domain_margin')
    power_time_constant: float = parameter_from(RfiMonitorParams, 'power_time_constant')
    phase_gain: float = parameter_from(RfiMonitorParams, 'phase_gain')
    noise_floor_power: float = parameter_from(RfiMonitorParams, 'noise_floor_power')
    calibration_blocks: int = parameter_from(RfiMonitorParams, 'calibration_blocks')
    signal_power_dbm: float = parameter_from(RfiMonitorParams, 'signal_power_dbm')
    noise_density_dbm_per_mhz: float = parameter_from(RfiMonitorParams, 'noise_density_dbm_per_mhz')
    noise_bandwidth_hz: float = parameter_from(RfiMonitorParams, 'noise_bandwidth_hz')
    max_invalid_fraction: float = parameter_from(RfiMonitorParams, 'max_invalid_fraction')
    min_block_samples: int = parameter_from(RfiMonitorParams, 'min_block_samples')
    refine_window: int = parameter_from(RfiMonitorParams, 'refine_window')
    lattice_period_drift: float = parameter_from(RfiMonitorParams, 'lattice_period_drift')
    noise_compensation: bool = parameter_from(RfiMonitorParams, 'noise_compensation')
    confirm_fits: int = parameter_from(RfiMonitorParams, 'confirm_fits')
    reset_cross_covariance: bool = parameter_from(RfiMonitorParams, 'reset_cross_covariance')
    # --- tracking filter (Kang et al., eq. 11-22) ----------------------------------------------
    tracker_mode: str = parameter(
        'afkf',
        'Frequency tracking filter: kf (eq. 11-17), akf (adaptive gain) or afkf (adaptive fading, the proposed '
        'filter).', choices=tuple(TRACKER_MODES))
    tracker_measurement_std: float = parameter(
        _T.measurement_std, 'sigma_v of the IF measurement (eq. 20), cycles/sample. Raise it at low J/N.',
        minimum=1e-9, maximum=1.0)
    tracker_process_std: float = parameter(
        _T.process_std, 'sigma_w on the frequency (eq. 19), cycles/sample.', minimum=0.0, maximum=1.0)
    tracker_process_rate_std: float = parameter(
        _T.process_rate_std,
        "Process noise on the sweep rate per sample, cycles/sample^2. The paper's eq. 19 has none; with 0 the rate "
        'variance collapses before the period locks and the rate estimate freezes.', minimum=0.0, maximum=1.0)
    tracker_window: int = parameter(
        _T.window, 'Innovation window M of the adaptive filters (eq. 12), samples.', minimum=2, maximum=100000)
    tracker_initial_frequency: float = parameter(
        _T.initial_frequency,
        'Frequency of the tracking filter at start and after every reset (gaps between snapshots included), '
        "cycles/sample. 0.25 is the paper's IF at fs/4; set to the IF / fs of another front end.",
        minimum=-1.0, maximum=1.0)
    tracker_initial_frequency_std: float = parameter(
        _T.initial_frequency_std, '1-sigma of the initial frequency, cycles/sample.', minimum=1e-12, maximum=1.0)
    tracker_initial_rate_std: float = parameter(
        _T.initial_rate_std, '1-sigma of the initial sweep rate, cycles/sample^2 (1e12 Hz/s at 38.192 MHz is 6.9e-4).',
        minimum=1e-12, maximum=1.0)
    # --- sweep period (Kang et al., eq. 23-27) -------------------------------------------------
    sweep_forgetting: float = parameter(
        _S.forgetting, 'Forgetting factor gamma of the linear prediction detector (eq. 23), [0, 1).',
        minimum=0.0, maximum=0.999999)
    sweep_beta: float = parameter(
        _S.beta, 'Normalisation beta of eq. 23, dimensionless (scaled by the band internally).',
        minimum=1e-12, maximum=1e6)
    sweep_beta_en: float = parameter(
        _S.beta_en, 'Enhancement rate beta_en of the peak threshold, dimensionless.', minimum=0.0, maximum=1e6)
    sweep_kappa: float = parameter(
        _S.kappa,
        'Peak threshold in multiples of the running mean |zAR|, dimensionless. Lower it if the period does not lock '
        'at low J/N (more false peaks), raise it if it locks on noise.', minimum=1e-6, maximum=1e6)
    sweep_noise_time_constant: float = parameter(
        _S.noise_time_constant, 'Time constant of the running mean |zAR|, decimated steps.', minimum=1.0, maximum=1e9)
    sweep_decimation: int = parameter(
        _S.decimation, 'Samples averaged per AR(10) step, samples (speed; 1 = full rate).', minimum=1, maximum=1000)
    sweep_ar_process_var: float = parameter(
        _S.ar_process_var, 'Diagonal of the AR process noise Q_AR (eq. 25), dimensionless.',
        minimum=1e-12, maximum=1e12)
    sweep_ar_measurement_var: float = parameter(
        _S.ar_measurement_var, 'AR measurement variance sigma_AR^2 (eq. 26), dimensionless.',
        minimum=1e-12, maximum=1e12)
    sweep_ar_transition: float = parameter(
        _S.ar_transition, 'Diagonal of the AR transition matrix A (eq. 25; the paper: 0.2), (-1, 1).',
        minimum=-0.999999, maximum=0.999999)
    sweep_delay: float = parameter(
        _S.delay, 'Samples from a sweep start to its detected peak (detector group delay), samples.',
        minimum=0.0, maximum=1e6)
    sweep_min_separation: int = parameter(
        _S.min_separation,
        'Refractory time between two detected sweep starts, samples. Sweeps shorter than this cannot lock: lower it '
        'for very fast sweeps.', minimum=1, maximum=10**9)
    sweep_tolerance: float = parameter(
        _S.tolerance, 'Relative tolerance of a sweep interval to a multiple of the period, (0, 0.5).',
        minimum=1e-6, maximum=0.499999)
    sweep_min_consistent: int = parameter(
        _S.min_consistent, 'Peaks fitting the period lattice needed to lock, minus one.', minimum=1, maximum=100000)
    sweep_min_tolerance_samples: float = parameter(
        _S.min_tolerance_samples, 'Absolute floor of the lattice tolerance, samples (matters for short periods).',
        minimum=0.0, maximum=1e6)
    sweep_max_period: float = parameter(
        _S.max_period,
        'Longest sweep period considered by the lattice voting, samples (10000 = 262 us at 38.192 MHz). Raise it for '
        'slow sweeps; must exceed sweep_min_separation.', minimum=1.0, maximum=1e9)
    sweep_lattice_voting: bool = parameter(
        _S.lattice_voting,
        'Period by lattice voting over all recent peaks (ours; robust to missed and false peaks) instead of the '
        'successive intervals of the paper. Set false to reproduce the paper.')
    # --- periodicity detector (ours) -----------------------------------------------------------
    analysis_enabled: bool = parameter(
        _A.enabled,
        'Run the block-level periodicity detector of the frequency track (ours): it seeds the reset lattice and tells'
        " the identification that the track is periodic. Set false to run Kang et al.'s method only.")
    analysis_hop_s: float = parameter(
        _A.hop_s,
        'Interval between two periodicity analyses, s (at absolute sample indices multiple of hop_s * fs, so the '
        'result does not depend on how the stream is cut into blocks). Blocks much shorter than 2 hop_s cannot use '
        'it. Cost: ~0.2-0.3 ms of CPU per analysis (one per ms by default).', minimum=1e-7, maximum=10.0)
    analysis_min_strength: float = parameter(
        _A.min_strength,
        'Normalised autocorrelation peak-to-trough of a periodic track, (0, 1.5] (1.5: noise-free saw-tooth). Raise '
        'it if noise is taken for a sweep.', minimum=1e-6, maximum=1.5)
    analysis_min_lag: int = parameter(
        _A.min_lag, 'Shortest period detected, decimated samples (x sweep_decimation samples).',
        minimum=2, maximum=10**9)
    analysis_max_period_fraction: float = parameter(
        _A.max_period_fraction, 'Longest period as a fraction of the analysed window, (0, 0.5].',
        minimum=1e-6, maximum=0.5)
    analysis_min_window: int = parameter(
        _A.min_window, 'Fewest decimated values for an analysis (1024 x 4 samples = 107 us at 38.192 MHz).',
        minimum=64, maximum=10**9)
    analysis_skip_while_tracking: bool = parameter(
        _A.skip_while_tracking,
        'No periodicity analysis while in tracking mode (confirm_fits): the confirmed reset lattice is then the '
        'evidence of a periodic sweep. false: analyse every hop (more CPU).')
    # --- identification (not in the paper) ----------------------------------------------------
    classifier_nfft: int = parameter(
        _C.nfft,
        'Welch frame length, samples (a power of two). Sets the spectral resolution fs / nfft (149 kHz at 38.192 MHz)'
        ' and the CW frequency resolution.', minimum=32, maximum=2**20)
    classifier_max_frames: int = parameter(
        _C.max_frames, 'At most this many Welch frames per block (evenly spaced; speed).', minimum=8, maximum=10**7)
    classifier_sig_sigma: float = parameter(
        _C.sig_sigma, 'Significance of an occupied spectral bin, standard deviations of the Welch average.',
        minimum=1e-6, maximum=1e3)
    classifier_min_excess: float = parameter(
        _C.min_excess,
        'Smallest relative excess of an occupied bin over the noise, dimensionless (guards a mismatch between the '
        'learned noise shape and the front end).', minimum=1e-6, maximum=1e6)
    classifier_detect_jn_db: float = parameter(
        _C.detect_jn_db,
        'J/N above which a jammer is declared, dB. Front-end spurs of real captures are at -11 to -20 dB; raise it if'
        ' spurs are reported as CW.', minimum=-100.0, maximum=100.0)
    classifier_cw_max_occupancy: float = parameter(
        _C.cw_max_occupancy, 'Largest occupied fraction of the band of a CW, (0, 1).', minimum=1e-6, maximum=0.999999)
    classifier_min_chirp_rate: float = parameter(
        _C.min_chirp_rate,
        '|Sweep rate| that marks a chirp before the period locks, cycles/sample^2 (1.5e11 Hz/s at 38.192 MHz is '
        '1e-4).', minimum=1e-12, maximum=1.0)
    classifier_template_smooth_bins: int = parameter(
        _C.template_smooth_bins, 'Width of the median filter smoothing the learned noise shape, bins.',
        minimum=1, maximum=2**20)
    classifier_sidelobe_db: float = parameter(
        _C.sidelobe_db,
        'Bins more than this below the strongest excess are not occupied, dB (Hann sidelobes of a strong CW are below'
        ' -31 dB).', minimum=0.0, maximum=300.0)
    classifier_confidence_slope_db: float = parameter(
        _C.confidence_slope_db, 'J/N margin over the threshold that maps to a confidence of 0.73, dB.',
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


CONFIG_FILE = ConfigFile('rfi_monitor', 'config/rfi_monitor.yaml', 'rfi_monitor', MonitorNodeParams, """
Parameters of rfi_monitor_node (rfi_monitor/rfi_monitor_node.py; MonitorNodeParams in
rfi_monitor/node_params.py). GENERATED by tools/generate_config.py from the parameter definitions: the
core's scalar ones in rfi_monitor/params.py (RfiMonitorParams), its nested groups' and the node's own
in node_params.py, the stamp gate's and /diagnostics' in rfi_node_common/diagnostics.py
(NodeDiagnosticsParams). Change a default or a description there and run
`python tools/generate_config.py`; a test checks this file equals it.
Method: Kang et al. (three-sample IF frequency measurement, adaptive fading Kalman filter, sweep
period by a linear prediction detector); identification and calibration are ours. Design
decisions and measured performance: docs/rfi_monitor/README.md and paper_results.md.

Use:   ros2 run rfi_monitor rfi_monitor_node --ros-args --params-file rfi_monitor.yaml
Every value below is the default. The user parameters (the estimator, the front end's noise and
the J/S reference, the CPU budget) come first; the tuning parameters after them are the tested
values of the method. An invalid value, or a parameter the node does not have, stops the node with
a one-line error naming it. Floats must be written with a decimal point. Parameters marked
[settable while running] can be changed with `ros2 param set /rfi_monitor NAME VALUE` (validated as
at start, applied before the next block); the others are read-only (the core sizes its state from
them). "Digital" frequencies are in cycles/sample of the sampled stream (0.25 = fs/4).
Snapshot front ends (a short block every second or so): set diagnostics_period_s to the snapshot
period or longer, input_timeout_s above the block period, and max_stamp_jump_s above the longest
pause between blocks (else stamp_jump_confirmations - 1 blocks are lost after each pause).

Input  /rfi/if_samples (rfi_msgs/IfSamples): IF blocks, INT8/INT16 little-endian, volts = count * scale.
       The subscription takes its publishers' reliability: reliable with play or if_source's default
       (nothing lost), best effort once a best-effort sensor driver is there (it is accepted);
       -p qos_overrides./rfi/if_samples.subscription.reliability:=reliable (or best_effort) fixes it. Messages
       lost before the node saw them are counted (input./rfi/if_samples.lost) on /diagnostics.
Output /rfi/jammer_state (rfi_msgs/JammerState): one per analysed block, same header; frequencies
       relative to the block's center_frequency_hz; NaN where unknown (a NONE carries a finite J/N:
       at least the block power's resolution, "J/N below x dB"). Rejected blocks give no state; each
       is counted on /diagnostics as rejected_<reason>: bad stamps (stamp_not_positive,
       stamp_not_increasing, stamp_far_future, stamp_far_past, bad_stamp_nanosec), malformed or
       physically impossible fields (sample rate outside 1e5..1e11 Hz, scale outside 1e-12..1e3
       V/count, centre frequency outside 0..1e11 Hz, |IF| at or above Nyquist, first_sample_index
       + samples beyond 2^53, ...), blank blocks (no variation, or no power), non-finite samples, blocks
       10 dB below or 120 dB above the calibrated noise floor (after calibration_blocks of them in a
       row the floor is learned again). The full list: rfi_monitor/rfi_monitor_node.py.
""")
"""The shipped config/rfi_monitor.yaml (:func:`rfi_node_common.params.config_yaml`)."""

TOPICS = """topics:
  subscribes /rfi/if_samples (rfi_msgs/IfSamples)
  publishes  /rfi/jammer_state (rfi_msgs/JammerState), /diagnostics (diagnostic_msgs/DiagnosticArray),
             /rfi/spectrum/waterfall (sensor_msgs/Image), /rfi/spectrum/swept_band (visualization_msgs/ImageMarker)
             (the last two only while subscribed, every 1/spectrum_rate_hz of stamp time)"""
"""The topics of rfi_monitor_node, for its ``--help``."""
