"""Parameters of rfi_monitor_node, each written once: the core's RfiMonitorParams flattened, plus the node's own
(pure: no rclpy).

The core's scalar parameters are defined in :class:`rfi_monitor.params.RfiMonitorParams` (default, description,
range, group) and taken with :func:`rfi_node_common.params.parameter_from`; so are those of its nested groups
(prefixes tracker_, sweep_, classifier_, analysis_, ridge_, integration_, spectral_step_: :data:`NESTED`), each defined
on the field of its dataclass (TrackingFilterParams in tracking_filters.py, SweepPeriodParams in sweep_period.py,
ClassifierParams in classifier.py, SweepAnalysisParams in sweep_analysis.py, RidgeParams in ridge.py,
IntegrationParams in integration.py, SpectralStepParams in spectral_step.py) and taken with the default of
``RfiMonitorParams()`` (:func:`_nested`); the stamp gate's and /diagnostics' come from
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


def _nested(group: str, name: str) -> Any:
    """The node parameter ``<group>_<name>``: the field ``name`` of the core's nested dataclass ``group`` (defined
    there with :func:`rfi_node_common.params.parameter`: description, range), with the default of
    ``RfiMonitorParams().<group>`` (e.g. sweep_lattice_voting: true, the Method table's "ours", where
    SweepPeriodParams alone defaults to the paper's false)."""
    owner = next(cls for field, _, cls in NESTED if field == group)
    core = parameter_from(owner, name)
    return dataclasses.field(default=getattr(getattr(_M, group), name), metadata=core.metadata)


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
    ridge_min_frame_length: int = _nested('ridge', 'min_frame_length')
    ridge_max_frame_length: int = _nested('ridge', 'max_frame_length')
    ridge_select_samples: int = _nested('ridge', 'select_samples')
    ridge_min_period_frames: int = _nested('ridge', 'min_period_frames')
    ridge_presence_nats: float = _nested('ridge', 'presence_nats')
    ridge_noise_smooth_bins: int = _nested('ridge', 'noise_smooth_bins')
    ridge_phase_bins: int = _nested('ridge', 'phase_bins')
    ridge_hook_rate_ratio: float = _nested('ridge', 'hook_rate_ratio')
    ridge_min_present_fraction: float = _nested('ridge', 'min_present_fraction')
    ridge_tracking_samples: int = _nested('ridge', 'tracking_samples')
    ridge_acquisition_samples: int = _nested('ridge', 'acquisition_samples')
    ridge_max_period_s: float = _nested('ridge', 'max_period_s')
    ridge_detect_sigma: float = _nested('ridge', 'detect_sigma')
    ridge_min_strength: float = _nested('ridge', 'min_strength')
    integration_window_s: float = _nested('integration', 'window_s')
    integration_false_alarm_per_block: float = _nested('integration', 'false_alarm_per_block')
    integration_frame_length_s: float = _nested('integration', 'frame_length_s')
    integration_max_period_s: float = _nested('integration', 'max_period_s')
    integration_max_multiples: int = _nested('integration', 'max_multiples')
    integration_nfft: int = _nested('integration', 'nfft')
    integration_smooth_bins: int = _nested('integration', 'smooth_bins')
    integration_decide_interval_s: float = _nested('integration', 'decide_interval_s')
    integration_min_chirp_strength: float = _nested('integration', 'min_chirp_strength')
    integration_sub_windows: int = _nested('integration', 'sub_windows')
    integration_max_samples_per_s: float = _nested('integration', 'max_samples_per_s')
    spectral_step_enabled: bool = _nested('spectral_step', 'enabled')
    spectral_step_window_s: float = _nested('spectral_step', 'window_s')
    spectral_step_groups: int = _nested('spectral_step', 'groups')
    spectral_step_false_alarm_per_block: float = _nested('spectral_step', 'false_alarm_per_block')
    spectral_step_min_step_db: float = _nested('spectral_step', 'min_step_db')
    spectral_step_max_band_fraction: float = _nested('spectral_step', 'max_band_fraction')
    spectral_step_reference_blocks: int = _nested('spectral_step', 'reference_blocks')
    spectral_step_min_reference_blocks: int = _nested('spectral_step', 'min_reference_blocks')
    spectral_step_learn_z: float = _nested('spectral_step', 'learn_z')
    spectral_step_relearn_after_s: float = _nested('spectral_step', 'relearn_after_s')
    spectral_step_decide_interval_s: float = _nested('spectral_step', 'decide_interval_s')
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
        next(key for key, code in TRACKER_MODES.items() if code == _M.tracker.mode),
        'Frequency tracking filter: kf (eq. 11-17), akf (adaptive gain) or afkf (adaptive fading, the proposed '
        'filter).', choices=tuple(TRACKER_MODES))
    tracker_measurement_std: float = _nested('tracker', 'measurement_std')
    tracker_process_std: float = _nested('tracker', 'process_std')
    tracker_process_rate_std: float = _nested('tracker', 'process_rate_std')
    tracker_window: int = _nested('tracker', 'window')
    tracker_initial_frequency: float = _nested('tracker', 'initial_frequency')
    tracker_initial_frequency_std: float = _nested('tracker', 'initial_frequency_std')
    tracker_initial_rate_std: float = _nested('tracker', 'initial_rate_std')
    # --- sweep period (Kang et al., eq. 23-27) -------------------------------------------------
    sweep_forgetting: float = _nested('sweep', 'forgetting')
    sweep_beta: float = _nested('sweep', 'beta')
    sweep_beta_en: float = _nested('sweep', 'beta_en')
    sweep_kappa: float = _nested('sweep', 'kappa')
    sweep_noise_time_constant: float = _nested('sweep', 'noise_time_constant')
    sweep_decimation: int = _nested('sweep', 'decimation')
    sweep_ar_process_var: float = _nested('sweep', 'ar_process_var')
    sweep_ar_measurement_var: float = _nested('sweep', 'ar_measurement_var')
    sweep_ar_transition: float = _nested('sweep', 'ar_transition')
    sweep_delay: float = _nested('sweep', 'delay')
    sweep_min_separation: int = _nested('sweep', 'min_separation')
    sweep_tolerance: float = _nested('sweep', 'tolerance')
    sweep_min_consistent: int = _nested('sweep', 'min_consistent')
    sweep_min_tolerance_samples: float = _nested('sweep', 'min_tolerance_samples')
    sweep_max_period: float = _nested('sweep', 'max_period')
    sweep_lattice_voting: bool = _nested('sweep', 'lattice_voting')
    # --- periodicity detector (ours) -----------------------------------------------------------
    analysis_enabled: bool = _nested('analysis', 'enabled')
    analysis_hop_s: float = _nested('analysis', 'hop_s')
    analysis_min_strength: float = _nested('analysis', 'min_strength')
    analysis_min_lag: int = _nested('analysis', 'min_lag')
    analysis_max_period_fraction: float = _nested('analysis', 'max_period_fraction')
    analysis_min_window: int = _nested('analysis', 'min_window')
    analysis_skip_while_tracking: bool = _nested('analysis', 'skip_while_tracking')
    # --- identification (not in the paper) ----------------------------------------------------
    classifier_nfft: int = _nested('classifier', 'nfft')
    classifier_max_frames: int = _nested('classifier', 'max_frames')
    classifier_sig_sigma: float = _nested('classifier', 'sig_sigma')
    classifier_min_excess: float = _nested('classifier', 'min_excess')
    classifier_detect_jn_db: float = _nested('classifier', 'detect_jn_db')
    classifier_cw_max_occupancy: float = _nested('classifier', 'cw_max_occupancy')
    classifier_min_chirp_rate: float = _nested('classifier', 'min_chirp_rate')
    classifier_template_smooth_bins: int = _nested('classifier', 'template_smooth_bins')
    classifier_sidelobe_db: float = _nested('classifier', 'sidelobe_db')
    classifier_confidence_slope_db: float = _nested('classifier', 'confidence_slope_db')

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
core's scalar ones in rfi_monitor/params.py (RfiMonitorParams), those of its nested groups (tracker_,
sweep_, ...) on the fields of their dataclasses (rfi_monitor/tracking_filters.py, sweep_period.py,
classifier.py, sweep_analysis.py, ridge.py, integration.py, spectral_step.py), the node's own in
node_params.py, the stamp gate's and /diagnostics' in rfi_node_common/diagnostics.py
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
