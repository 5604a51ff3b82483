"""Parameters of fusion_node: one frozen dataclass, declared as ROS parameters by the node.

Pure (no rclpy): :func:`rfi_node_common.params.declare` turns :class:`FusionNodeParams` into
parameter declarations with descriptors; :meth:`FusionNodeParams.fusion_params` gives the core's
:class:`uwb_gnss_fusion.fusion_params.FusionParams`. Documented for users in config/fusion.yaml.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from gnss_common.jamming_weights import TrackingLoopParams
from rfi_node_common.diagnostics import (
    diagnostics_window_parameter,
    hardware_id_parameter,
    input_timeout_parameter,
    max_stamp_jump_parameter,
    stamp_jump_confirmations_parameter,
    warn_lost_fraction_parameter,
    warn_rejected_fraction_parameter,
)
from rfi_node_common.params import parameter, validate_ranges
from uwb_gnss_fusion.fusion_params import FRAME_EARTH, FRAME_MAP, FusionParams
from uwb_gnss_fusion.local_frame import HEADING_SOURCES

LOCAL_ORIGINS = ('first_fix', 'datum')
"""Values of ``local_origin``: the first good fix, or the ``datum`` parameter."""

_FP = FusionParams()
_LOOP = TrackingLoopParams()


@dataclass(frozen=True)
class FusionNodeParams:
    """Parameters of fusion_node (documented for users in config/fusion.yaml).

    The filter fields mirror :class:`uwb_gnss_fusion.fusion_filter.FusionParams` (same names,
    ``loop_*`` = its ``loop`` :class:`TrackingLoopParams`), with the same defaults; the UWB anchor
    registry of FusionParams is not a parameter: anchor positions come in each UwbRange message.

    Settable while running (``ros2 param set``; ``read_only=False`` below, validated as at start and
    applied between two messages): the measurement noise levels (``uwb_range_std_m``, ``loop_*``,
    ``nominal_cn0_dbhz``, ``jammer_quality_factor``), the thresholds (``elevation_mask_deg``,
    ``min_cn0_dbhz``, ``uwb_max_range_m``, ``jammer_info_timeout_s``, ``max_position_std_m``, the Huber
    thresholds, the divergence thresholds ``divergence_gnss_epochs`` / ``divergence_uwb_gated_fraction``,
    ``nonlinearity_threshold`` / ``max_update_iterations``, ``common_mode_screen``), which the core reads at
    each update, and the node's own output and diagnostics settings (``antenna_position_m``,
    ``heading_source``, ``heading_min_speed_mps``, ``hardware_id``, the diagnostics thresholds,
    ``warning_throttle_s``). Read-only, and why:

    * ``gate_probability``, ``accel_psd_m2ps3``, ``motion_detection``, ``static_*``, ``clock_h0_s``,
      ``clock_h_minus2_hz``, ``uwb_lever_arm_m``, ``divergence_uwb_ranges``: the core derives its gate, its
      process-noise cache, its lever arm and the size of its divergence window from them when it is built; it has
      no call to change them in flight, so a change would be silently ignored (or, for the window, resize state).
    * ``use_gnss``, ``use_uwb``, ``use_doppler``, ``use_spp_reference``, ``min_satellites_init``, ``init_*``,
      ``max_prediction_s``, ``uwb_init_window_s``, ``uwb_latency_s``, ``reference_max_age_s``: the filter's
      configuration and its (re)initialisation; the SPP reference cache is sized by ``reference_max_age_s``.
    * frame ids, ``local_origin`` / ``datum``: consumers hold transforms and positions in these frames;
      moving the origin of ``map`` under them would make every pose they hold wrong.
    * ``reorder_window_*``, ``idle_flush_s``, ``max_stamp_jump_s``, ``stamp_jump_confirmations``,
      ``input_timeout_s``, ``diagnostics_period_s``: they size the re-ordering buffer, the stamp gate and
      the timers, which hold state.

    Notes:
        Cao et al.: constant-velocity model (eq. 8-10) driven by ``accel_psd_m2ps3``, pseudorange
        / Doppler / UWB models (eq. 5-7), effective C/N0 under J/S (eq. 4) with the quality
        factor ``jammer_quality_factor``; tracking jitter of Kaplan & Hegarty (``loop_*``).
    """

    # --- node ------------------------------------------------------------------------------
    earth_frame_id: str = parameter(
        FRAME_EARTH, 'Frame id of ECEF (REP 105 earth): expected on /gnss/measurements and on UwbRange '
        'messages with ECEF anchors; header.frame_id of the outputs in ECEF.')
    map_frame_id: str = parameter(
        FRAME_MAP, 'Frame id of the anchors\' local frame (UWB-only mode, axes taken as ENU): UwbRange '
        'messages in this frame run the filter in it; header.frame_id of the outputs then.')
    child_frame_id: str = parameter(
        'gnss_antenna', 'Odometry child_frame_id and NavSatFix frame_id: the point estimated (the GNSS antenna).')
    base_frame_id: str = parameter(
        'base_link', 'child_frame_id of fusion/local_odometry: the robot body frame (REP 105 base_link) whose '
        'origin the local odometry gives, from antenna_position_m.')
    antenna_position_m: tuple = parameter(
        (0.0, 0.0, 0.0), 'Position of the GNSS antenna (the point the filter estimates) in base_link, [forward, '
        'left, up], m (the lever arm; the robot is assumed level).', read_only=False)
    heading_source: str = parameter(
        'none', 'Yaw used to rotate the horizontal lever arm and the velocity into base_link: none (yaw unknown: '
        'base_link lies within the horizontal lever arm of the antenna, covariance grown accordingly) or '
        'velocity (the course over ground is the yaw above heading_min_speed_mps: a robot that moves forward '
        'without side slip).', choices=HEADING_SOURCES, read_only=False)
    heading_min_speed_mps: float = parameter(
        0.5, 'With heading_source velocity: the horizontal speed from which the course is taken as the yaw, '
        'm/s (below it the yaw is unknown).', minimum=0.01, maximum=100.0, read_only=False)
    local_origin: str = parameter(
        'first_fix', 'Origin of the local ENU frame (map_frame_id) of fusion/local_odometry: first_fix (the '
        'antenna position of the first solution published in ECEF) or datum (the datum parameter). Published '
        'on fusion/datum (latched).', choices=LOCAL_ORIGINS)
    datum: tuple = parameter(
        (0.0, 0.0, 0.0), 'With local_origin datum: WGS 84 [latitude deg, longitude deg, ellipsoidal altitude m] '
        'of the origin of the local ENU frame.')
    hardware_id: str = hardware_id_parameter('gnss_receiver+uwb_tag')  # type: ignore[assignment]
    diagnostics_window_s: float = diagnostics_window_parameter()  # type: ignore[assignment]
    warn_rejected_fraction: float = warn_rejected_fraction_parameter()  # type: ignore[assignment]
    warn_lost_fraction: float = warn_lost_fraction_parameter()  # type: ignore[assignment]
    warn_cn0_loss_db: float = parameter(
        3.0, 'WARN (inputs degraded) while the J/S in use costs more than this much C/N0 (Cao et al., eq. 4 at '
        'nominal_cn0_dbhz with jammer_quality_factor; 3 dB at about 15 dB J/S), dB.', minimum=0.0, maximum=100.0,
        read_only=False)
    reorder_window_s: float = parameter(
        0.1, 'Re-ordering window at start: inputs are processed in stamp order once a message this much newer '
        'has arrived; later arrivals are rejected. The outputs lag by it, s (0: process at once).',
        minimum=0.0, maximum=10.0)
    reorder_window_max_s: float = parameter(
        1.0, 'After a late arrival (still rejected) the window grows to 1.5 times its lateness, up to this, s; '
        'the outputs then lag by up to this (<= reorder_window_s: fixed window).', minimum=0.0, maximum=10.0)
    idle_flush_s: float = parameter(
        1.0, 'Process what the re-ordering buffer holds once no input has arrived for this long, s (wall '
        'time, steady clock: the end of a bag or a sensor stop; changes when, never what, is processed; '
        '0: never).', minimum=0.0, maximum=3600.0)
    # the shared helpers return the dataclass field as an object
    max_stamp_jump_s: float = max_stamp_jump_parameter(120.0)  # type: ignore[assignment]
    stamp_jump_confirmations: int = stamp_jump_confirmations_parameter(5)  # type: ignore[assignment]
    input_timeout_s: float = input_timeout_parameter()  # type: ignore[assignment]
    act_on_integrity: bool = parameter(
        True, 'Act on /gnss/integrity (gnss_integrity node): a DETECTED spoofing state excludes the GNSS it '
        'implicates (all, constellations or satellites) until integrity_readmit_clean_s of NONE; its jamming J/S '
        'weights the GNSS (Cao et al., eq. 4) where no SDR /rfi/jammer_state is fresh. False: received and '
        'counted, not used.', read_only=False)
    integrity_readmit_clean_s: float = parameter(
        30.0, 'Spoofing NONE for this long without a break readmits the excluded GNSS (hysteresis), s.',
        minimum=0.0, maximum=3600.0)
    integrity_rollback_s: float = parameter(
        1.0, 'At an exclusion of all GNSS, go back to the filter of this long before the episode\'s first alarm '
        'and apply the UWB ranges since then again, without GNSS (the state the spoofer dragged is dropped); '
        '0: no roll-back, re-anchor on UWB only (also when the first alarm is older than the 60 s of history).',
        minimum=0.0, maximum=30.0)
    use_spp_reference: bool = parameter(
        True, 'Re-initialise after a divergence from the newest valid single-point (SPP) fix of the last '
        'reference_max_age_s of GNSS epochs (solved on demand).')
    diagnostics_period_s: float = parameter(
        1.0, 'Period of /diagnostics in message (stamp) time, s.', minimum=0.01, maximum=3600.0)
    warning_throttle_s: float = parameter(
        5.0, 'Shortest interval between two warnings about rejected input, s (wall time; logging only).',
        minimum=0.0, maximum=3600.0, read_only=False)
    # --- filter (FusionParams) -------------------------------------------------------------
    use_gnss: bool = parameter(_FP.use_gnss, 'Apply GNSS pseudoranges (false: UWB-only filter).')
    use_doppler: bool = parameter(_FP.use_doppler, 'Apply pseudorange rates (Doppler) as well as pseudoranges.')
    use_uwb: bool = parameter(_FP.use_uwb, 'Apply UWB ranges (false: the GNSS-only baseline filter).')
    accel_psd_m2ps3: float = parameter(
        _FP.accel_psd_m2ps3, 'White-acceleration PSD per axis of the constant-velocity model, m^2/s^3.',
        minimum=1e-9, maximum=1e4)
    motion_detection: bool = parameter(
        _FP.motion_detection, 'Find out from the GNSS epochs whether the receiver is static and then run the static '
        'model (uwb_gnss_fusion.motion_model; not while UWB ranges arrive). False: always the moving model.')
    static_enter_s: float = parameter(
        _FP.static_enter_s, 'How long every GNSS epoch must show a velocity consistent with zero before the receiver '
        'is declared static, s.', minimum=0.0, maximum=3600.0)
    static_accel_psd_m2ps3: float = parameter(
        _FP.static_accel_psd_m2ps3, 'White-acceleration PSD per axis of the static model, m^2/s^3.',
        minimum=1e-15, maximum=1e4)
    static_velocity_std_mps: float = parameter(
        _FP.static_velocity_std_mps, '1-sigma per axis of the zero-velocity update applied when the receiver is '
        'declared static, m/s.', minimum=1e-6, maximum=10.0)
    clock_h0_s: float = parameter(
        _FP.clock_h0_s, 'Receiver clock white-FM coefficient h0, s.', minimum=1e-30, maximum=1e-12)
    clock_h_minus2_hz: float = parameter(
        _FP.clock_h_minus2_hz, 'Receiver clock random-walk-FM coefficient h_-2, 1/s.', minimum=0.0, maximum=1e-12)
    uwb_range_std_m: float = parameter(
        _FP.uwb_range_std_m, 'UWB range 1-sigma used when a message gives NaN range_std_m, m.',
        minimum=1e-4, maximum=100.0, read_only=False)
    uwb_lever_arm_m: tuple = parameter(
        _FP.uwb_lever_arm_m, 'UWB tag minus GNSS antenna, in the state frame (ECEF or map), m, [x, y, z].')
    uwb_max_range_m: float = parameter(
        _FP.uwb_max_range_m, 'Longest physical UWB range; longer ranges are rejected, m.',
        minimum=1.0, maximum=1e5, read_only=False)
    gate_probability: float = parameter(
        _FP.gate_probability, 'Per-measurement innovation gate, probability of the 1-dof chi-square (1: no gating).',
        minimum=0.5, maximum=1.0)
    common_mode_screen: bool = parameter(
        _FP.common_mode_screen, 'Drop pseudoranges / rates whose innovation departs from the epoch median '
        '(common clock) beyond the gate with the clock-free variance, before the CKF update (beyond the paper).',
        read_only=False)
    receiver_clock_steps: bool = parameter(
        _FP.receiver_clock_steps, 'Take a pseudorange step common to all satellites (>= 5 and more than half '
        'agreeing) that the predicted clock cannot explain for a receiver clock step (e.g. 1 ms adjustments) and '
        'move the clock by it, instead of rejecting every pseudorange (beyond the paper).',
        read_only=False)
    multi_gnss: bool = parameter(
        _FP.multi_gnss, 'Use Galileo, BeiDou, GLONASS and QZSS as well as GPS, each with an inter-system clock '
        'bias state (false: GPS only, the others counted as skipped_constellation.<name>).')
    pseudorange_correlated_std_m: float = parameter(
        _FP.pseudorange_correlated_std_m, 'Stationary 1-sigma of the time-correlated pseudorange error, m: one '
        'first-order Gauss-Markov state per tracked satellite (0: off, white pseudorange errors).',
        minimum=0.0, maximum=100.0)
    pseudorange_correlated_tau_s: float = parameter(
        _FP.pseudorange_correlated_tau_s, 'Correlation time of that error, s.', minimum=0.1, maximum=86400.0)
    uwb_mirror_test: bool = parameter(
        _FP.uwb_mirror_test, 'Resolve the mirror ambiguity of coplanar anchors (three anchors always are) with a '
        'GNSS log-likelihood ratio of the reflected estimate against the estimate, accumulated over the epochs '
        '(beyond the paper; counted as uwb_mirror_switch).')
    uwb_mirror_switch_log_lr: float = parameter(
        _FP.uwb_mirror_switch_log_lr, 'Jump to the mirror when that log-likelihood ratio exceeds this '
        '(natural log; evidence scaled to independent samples with pseudorange_correlated_tau_s).',
        minimum=0.01, maximum=100.0)
    uwb_tag_side_of_anchor_plane: int = parameter(
        _FP.uwb_tag_side_of_anchor_plane, 'The tag moves below (-1) or above (+1) the plane of its coplanar anchors, '
        'or unknown (0): with -1/+1 an estimate on the other side (the mirror ambiguity of three anchors) is '
        'reflected back across the plane (counted as uwb_side_prior_flip) and uwb_mirror_test is not used.',
        minimum=-1, maximum=1)
    uwb_mirror_covariance: bool = parameter(
        _FP.uwb_mirror_covariance, 'While the side of the anchors\' plane is unknown and the anchors heard are '
        'coplanar, add the mirror ambiguity (p d^2 along the plane normal) to the published position covariance '
        '(beyond the paper).', read_only=False)
    uwb_mirror_gnss_std_m: float = parameter(
        _FP.uwb_mirror_gnss_std_m, '1-sigma of the GNSS position error along the normal of the anchors\' plane, '
        'm: the probability of the wrong side is Phi(-d / (2 sigma)) with GNSS, 0.5 without.',
        minimum=0.01, maximum=100.0, read_only=False)
    uwb_gated_anchor_reinit: bool = parameter(
        _FP.uwb_gated_anchor_reinit, 'Reinitialise the position from a multilateration fix that explains the '
        'latest range of every anchor (at least four; three with uwb_tag_side_of_anchor_plane) and lies outside '
        'the 3-dof gate around the state, when one '
        'anchor has had divergence_uwb_ranges consecutive ranges gated (the state is in a wrong local minimum); at '
        'most once per anchor id. Beyond the paper; counted as uwb_anchor_gated_reinit.')
    uwb_range_curvature_noise: bool = parameter(
        _FP.uwb_range_curvature_noise, 'Add to each range variance the second-order (curvature) variance of the '
        'range over the position uncertainty across its line of sight (beyond the paper).')
    uwb_range_noise_adaptive: bool = parameter(
        _FP.uwb_range_noise_adaptive, "Estimate each anchor's range noise from its innovations, a factor on the "
        'stated variance (range_std_m of the message or uwb_range_std_m); beyond the paper, counted as '
        'uwb_noise_estimates. Acts while GNSS is used (the weight of ranges against pseudoranges).')
    uwb_range_noise_adaptive_without_gnss: bool = parameter(
        _FP.uwb_range_noise_adaptive_without_gnss, 'Also estimate the range noise without GNSS (use_gnss false or the '
        'map frame); off by default: with a moving tag the innovations also carry the motion model errors.')
    uwb_iterate_min_anchors: int = parameter(
        _FP.uwb_iterate_min_anchors, 'With GNSS, refine a range by the iterated update only while at least this many '
        'anchors were heard within uwb_init_window_s (0: always). With 1-2 anchors the iterated point leaks '
        'information across the lines of sight; beyond the paper.', minimum=0, maximum=64)
    uwb_range_bias_std_m: float = parameter(
        _FP.uwb_range_bias_std_m, 'With GNSS and fewer than three anchors heard, the ranges of one anchor share a bias '
        'of this 1-sigma over uwb_range_bias_time_s: the n-th range in that time is applied with variance '
        'std^2 + n * this^2, so a stream of ranges does not leak information across its turning line of sight, m '
        '(0: off). Beyond the paper.', minimum=0.0, maximum=10.0)
    uwb_range_bias_time_s: float = parameter(
        _FP.uwb_range_bias_time_s, 'Time over which the ranges of one anchor share that bias, s.',
        minimum=0.1, maximum=3600.0)
    uwb_range_noise_window: int = parameter(
        _FP.uwb_range_noise_window, 'Fading memory of that estimate, ranges per anchor.', minimum=10, maximum=100000)
    uwb_range_std_floor_m: float = parameter(
        _FP.uwb_range_std_floor_m, 'Smallest estimated range 1-sigma, m (widened to the stated 1-sigma).',
        minimum=1e-4, maximum=10.0)
    uwb_range_std_ceiling_m: float = parameter(
        _FP.uwb_range_std_ceiling_m, 'Largest estimated range 1-sigma, m (widened to the stated 1-sigma).',
        minimum=1e-3, maximum=100.0)
    elevation_mask_deg: float = parameter(
        _FP.elevation_mask_deg, 'Satellites below this elevation are rejected, deg.',
        minimum=-90.0, maximum=89.0, read_only=False)
    min_cn0_dbhz: float = parameter(
        _FP.min_cn0_dbhz, 'Pseudoranges with a lower reported C/N0 are rejected, dB-Hz.',
        minimum=0.0, maximum=70.0, read_only=False)
    nominal_cn0_dbhz: float = parameter(
        _FP.nominal_cn0_dbhz, 'Jammer-free C/N0 fed to eq. 4 when a J/S is known, dB-Hz.',
        minimum=0.0, maximum=70.0, read_only=False)
    jammer_quality_factor: float = parameter(
        _FP.jammer_quality_factor, 'Jamming resistance quality factor Q of eq. 4 (1: narrowband/swept jammer).',
        minimum=0.01, maximum=100.0, read_only=False)
    jammer_info_timeout_s: float = parameter(
        _FP.jammer_info_timeout_s, 'A J/S older than this is ignored, s.',
        minimum=0.01, maximum=3600.0, read_only=False)
    loop_dll_bandwidth_hz: float = parameter(
        _LOOP.dll_bandwidth_hz, 'Code loop (DLL) noise bandwidth of the receiver, Hz.',
        minimum=0.001, maximum=100.0, read_only=False)
    loop_correlator_spacing_chips: float = parameter(
        _LOOP.correlator_spacing_chips, 'Early-late correlator spacing, chips.',
        minimum=0.001, maximum=1.0, read_only=False)
    loop_integration_time_s: float = parameter(
        _LOOP.integration_time_s, 'Predetection integration time, s.', minimum=1e-4, maximum=1.0, read_only=False)
    loop_fll_bandwidth_hz: float = parameter(
        _LOOP.fll_bandwidth_hz, 'Frequency loop noise bandwidth, Hz.', minimum=0.001, maximum=100.0, read_only=False)
    loop_code_floor_m: float = parameter(
        _LOOP.code_floor_m, 'Pseudorange 1-sigma floor added in quadrature (multipath, atmosphere, orbit), m.',
        minimum=0.0, maximum=100.0, read_only=False)
    loop_rate_floor_mps: float = parameter(
        _LOOP.rate_floor_mps, 'Pseudorange-rate 1-sigma floor added in quadrature, m/s.',
        minimum=0.0, maximum=100.0, read_only=False)
    min_satellites_init: int = parameter(
        _FP.min_satellites_init, 'Satellites needed to initialise from GNSS alone.', minimum=4, maximum=64)
    init_position_std_m: float = parameter(
        _FP.init_position_std_m, 'Initial position 1-sigma per axis, m.', minimum=1e-3, maximum=1e7)
    init_velocity_std_mps: float = parameter(
        _FP.init_velocity_std_mps, 'Initial velocity 1-sigma per axis, m/s.', minimum=1e-4, maximum=1e4)
    init_clock_bias_std_m: float = parameter(
        _FP.init_clock_bias_std_m, 'Initial receiver clock bias 1-sigma, m.', minimum=1e-3, maximum=1e7)
    init_clock_drift_std_mps: float = parameter(
        _FP.init_clock_drift_std_mps, 'Initial receiver clock drift 1-sigma, m/s.', minimum=1e-4, maximum=1e4)
    init_clock_drift_unobserved_std_mps: float = parameter(
        _FP.init_clock_drift_unobserved_std_mps, 'Clock drift 1-sigma at an initialisation without Doppler and '
        'without an earlier drift estimate, m/s.', minimum=1e-4, maximum=1e5)
    max_prediction_s: float = parameter(
        _FP.max_prediction_s, 'A measurement further than this after the filter time resets the filter, s.',
        minimum=0.01, maximum=3600.0)
    max_position_std_m: float = parameter(
        _FP.max_position_std_m, 'A larger position 1-sigma (any axis) is declared divergence, m.',
        minimum=0.01, maximum=1e7, read_only=False)
    divergence_gnss_epochs: int = parameter(
        _FP.divergence_gnss_epochs, 'Consecutive GNSS epochs with at least half of >= 4 pseudoranges gated out '
        'that declare divergence.', minimum=1, maximum=100000, read_only=False)
    divergence_fix_confirm_s: float = parameter(
        _FP.divergence_fix_confirm_s, 'Start from a GNSS snapshot fix, or re-initialise from one after a GNSS-declared '
        'divergence, only when an earlier fix this many seconds (up to ten times that) before agrees within 3 '
        'combined sigmas; meanwhile a diverging state is kept (0: at once). Beyond the paper.',
        minimum=0.0, maximum=3600.0)
    divergence_uwb_ranges: int = parameter(
        _FP.divergence_uwb_ranges, 'Window of recent UWB ranges (all anchors) examined for divergence.',
        minimum=1, maximum=100000)
    divergence_uwb_gated_fraction: float = parameter(
        _FP.divergence_uwb_gated_fraction, 'Divergence is declared when at least this fraction of the last '
        'divergence_uwb_ranges ranges was gated out (1.0: that many consecutive gated ranges).',
        minimum=0.01, maximum=1.0, read_only=False)
    reference_max_age_s: float = parameter(
        _FP.reference_max_age_s, 'A reference (SPP) solution older than this is not used to re-initialise, s.',
        minimum=0.01, maximum=3600.0)
    uwb_init_window_s: float = parameter(
        _FP.uwb_init_window_s, 'Ranges used for UWB multilateration must lie within this window, s.',
        minimum=0.01, maximum=3600.0)
    uwb_latency_s: float = parameter(
        _FP.uwb_latency_s, 'Age of a UWB range at its stamp (modelled by constant-velocity back-propagation), s.',
        minimum=0.0, maximum=1.0)
    max_update_iterations: int = parameter(
        _FP.max_update_iterations, 'Gauss-Newton refinement steps allowed after a cubature update with a '
        'significant linearisation error (0: the plain CKF update of the paper).',
        minimum=0, maximum=50, read_only=False)
    nonlinearity_threshold: float = parameter(
        _FP.nonlinearity_threshold, 'Refine an update when its linearisation-error variance exceeds this '
        'fraction of the measurement noise variance.', minimum=1e-6, maximum=1e6, read_only=False)
    uwb_huber_k: float = parameter(
        _FP.uwb_huber_k, 'Huber threshold on the normalised UWB innovation (.inf: off).', minimum=0.01, read_only=False)
    uwb_huber_k_positive: float = parameter(
        _FP.uwb_huber_k_positive, 'Huber threshold for positive UWB innovations (NLOS direction; .inf: not '
        'down-weighted).', minimum=0.01, read_only=False)

    def __post_init__(self) -> None:
        validate_ranges(self)
        for name in ('earth_frame_id', 'map_frame_id', 'child_frame_id', 'base_frame_id'):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise ValueError(f'parameter {name} must be a non-empty string')
        if self.earth_frame_id == self.map_frame_id:
            raise ValueError('parameters earth_frame_id and map_frame_id must differ')
        for name in ('antenna_position_m', 'datum'):
            value = getattr(self, name)
            if len(value) != 3 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in value):
                raise ValueError(f'parameter {name} must be 3 finite numbers, got {list(value)}')
        if self.local_origin == 'datum':
            if not (-90.0 <= self.datum[0] <= 90.0 and -180.0 <= self.datum[1] <= 180.0
                    and -1.0e4 <= self.datum[2] <= 1.0e5):
                raise ValueError(f'parameter datum {list(self.datum)} is not a latitude in [-90, 90] deg, a '
                                 'longitude in [-180, 180] deg and an altitude in [-1e4, 1e5] m')
        elif tuple(self.datum) != (0.0, 0.0, 0.0):
            raise ValueError('parameter datum is only used with local_origin datum '
                             f'(local_origin is {self.local_origin})')
        if len(self.uwb_lever_arm_m) != 3:
            raise ValueError(f'parameter uwb_lever_arm_m must have 3 elements, got {list(self.uwb_lever_arm_m)}')
        try:
            self.fusion_params()
        except (TypeError, ValueError) as err:
            raise ValueError(f'invalid filter parameters: {err}') from None

    def fusion_params(self) -> FusionParams:
        """The core's parameters.

        Raises:
            ValueError: a combination the core rejects (e.g. use_gnss and use_uwb both false).
        """
        loop = TrackingLoopParams(
            dll_bandwidth_hz=self.loop_dll_bandwidth_hz, correlator_spacing_chips=self.loop_correlator_spacing_chips,
            integration_time_s=self.loop_integration_time_s, fll_bandwidth_hz=self.loop_fll_bandwidth_hz,
            code_floor_m=self.loop_code_floor_m, rate_floor_mps=self.loop_rate_floor_mps)
        names = {f.name for f in dataclasses.fields(FusionParams)} - {'loop', 'anchors'}
        values: dict[str, Any] = {n: getattr(self, n) for n in names}
        values['uwb_lever_arm_m'] = tuple(float(v) for v in self.uwb_lever_arm_m)
        return FusionParams(loop=loop, **values)
