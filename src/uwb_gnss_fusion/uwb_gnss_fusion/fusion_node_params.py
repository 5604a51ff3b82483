"""Parameters of fusion_node: the filter's :class:`FusionParams` plus the node's own, declared as ROS parameters.

Pure (no rclpy). Each parameter is written once, as a field with :func:`rfi_node_common.params.parameter`
(default, description, range, settable or not, group): the filter's in
:class:`uwb_gnss_fusion.fusion_params.FusionParams`, the stamp gate's, silence watch's and /diagnostics' ones shared
by the suite's nodes in :class:`rfi_node_common.diagnostics.NodeDiagnosticsParams`, the node's (frames, re-ordering,
the flattened tracking-loop values) in :class:`FusionNodeParams`, which extends both.
:func:`rfi_node_common.params.declare` declares them all; :meth:`FusionNodeParams.fusion_params` gives the
core's frozen config; ``--help`` (:func:`rfi_node_common.params.describe`) and config/fusion.yaml
(:data:`CONFIG_FILE`, written by ``tools/generate_config.py``, checked by a test) are generated from them.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from gnss_common.jamming_weights import TrackingLoopParams
from rfi_node_common.diagnostics import NodeDiagnosticsParams, diagnostics_period_parameter, hardware_id_parameter
from rfi_node_common.params import USER, ConfigFile, parameter, parameter_from, validate_ranges
from uwb_gnss_fusion.fusion_params import FRAME_EARTH, FRAME_MAP, FusionParams
from uwb_gnss_fusion.fusion_view import FusionViewParams
from uwb_gnss_fusion.local_frame import HEADING_SOURCES

LOCAL_ORIGINS = ('first_fix', 'datum')
"""Values of ``local_origin``: the first good fix, or the ``datum`` parameter."""

_LOOP = TrackingLoopParams()


@dataclass(frozen=True)
class FusionNodeParams(FusionParams, NodeDiagnosticsParams):
    """Parameters of fusion_node: every parameter of :class:`FusionParams` and of :class:`NodeDiagnosticsParams`
    (inherited with its default and description; ``hardware_id`` and ``diagnostics_period_s`` redefined below with
    the shared helpers) and the node's own below. The core's ``loop`` (:class:`TrackingLoopParams`, in gnss_common,
    whose defaults are used) is made of the ``loop_*`` parameters; its ``anchors`` registry is not a
    parameter: anchor positions come in each UwbRange message.

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
        FRAME_EARTH,
        'Frame id of ECEF (REP 105 earth). GNSS measurement arrays in any other frame are rejected; UWB '
        'ranges in it have ECEF anchor positions; outputs estimated in ECEF carry it. Change only if the '
        'system names ECEF differently.',
        group=USER,
    )
    map_frame_id: str = parameter(
        FRAME_MAP,
        "Frame id of the anchors' local frame (axes taken as east, north, up). UWB ranges in it run the "
        'filter in that frame (UWB-only mode: set use_gnss false); the odometry then carries it and no '
        'NavSatFix is published. Set it to the frame your anchor survey uses.',
        group=USER,
    )
    child_frame_id: str = parameter(
        'gnss_antenna',
        'Odometry child_frame_id and NavSatFix header.frame_id: the point the filter estimates, i.e. the '
        'GNSS antenna (the UWB tag is offset from it by uwb_lever_arm_m).',
        group=USER,
    )
    base_frame_id: str = parameter(
        'base_link', 'child_frame_id of fusion/local_odometry: the robot body frame (REP 105 base_link) whose '
        'origin the local odometry gives, from antenna_position_m.', group=USER)
    antenna_position_m: tuple = parameter(
        (0.0, 0.0, 0.0), 'Position of the GNSS antenna (the point the filter estimates) in base_link, [forward, '
        'left, up], m (the lever arm; the robot is assumed level).', read_only=False, group=USER)
    heading_source: str = parameter(
        'none', 'Yaw used to rotate the horizontal lever arm and the velocity into base_link: none (yaw unknown: '
        'base_link lies within the horizontal lever arm of the antenna, covariance grown accordingly) or '
        'velocity (the course over ground is the yaw above heading_min_speed_mps: a robot that moves forward '
        'without side slip).', choices=HEADING_SOURCES, read_only=False, group=USER)
    heading_min_speed_mps: float = parameter(
        0.5, 'With heading_source velocity: the horizontal speed from which the course is taken as the yaw, '
        'm/s (below it the yaw is unknown).', minimum=0.01, maximum=100.0, read_only=False)
    local_origin: str = parameter(
        'first_fix',
        'Origin of the local ENU frame map_frame_id of /fusion/local_odometry: first_fix (the antenna '
        "position of the first solution published in ECEF; it then stays for the node's life) or datum (the "
        "datum parameter, e.g. the same datum as navsat_transform's). The origin is published once, latched, "
        'on /fusion/datum.',
        choices=LOCAL_ORIGINS, group=USER,
    )
    datum: tuple = parameter(
        (0.0, 0.0, 0.0), 'With local_origin datum: WGS 84 [latitude deg, longitude deg, ellipsoidal altitude m] '
        'of the origin of the local ENU frame.', group=USER)
    hardware_id: str = hardware_id_parameter('gnss_receiver+uwb_tag')
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
    act_on_integrity: bool = parameter(
        True,
        'Act on /gnss/integrity (the gnss_integrity node): a DETECTED spoofing state excludes the GNSS it '
        'implicates (all GNSS, constellations or satellites) from the filter until integrity_readmit_clean_s '
        'of NONE, and the filter keeps positioning on UWB and its motion model; fusion/status says what is '
        'excluded (gnss_excluded) and /diagnostics warns. Its jamming J/S weights the GNSS like the SDR '
        "monitor's (Cao et al., eq. 4) while no /rfi/jammer_state is fresh. False: the verdicts are received "
        'and counted, nothing is done.',
        read_only=False, group=USER,
    )
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
    # fusion_node has refused a /diagnostics period under 10 ms since its first version (the others: 1 ms); kept
    diagnostics_period_s: float = diagnostics_period_parameter(0.01)
    # --- the filter's tracking loops (FusionParams.loop, a TrackingLoopParams, flattened) --------
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
    # --- topics made to be drawn (issue 30; defined in uwb_gnss_fusion.fusion_view) ------------
    view_rate_hz: float = parameter_from(FusionViewParams, 'view_rate_hz')
    path_max_poses: int = parameter_from(FusionViewParams, 'path_max_poses')
    covariance_probability: float = parameter_from(FusionViewParams, 'covariance_probability')
    satellite_marker_distance_m: float = parameter_from(FusionViewParams, 'satellite_marker_distance_m')

    def __post_init__(self) -> None:
        # the core's ``loop`` is not a parameter of its own: it is made of the loop_* parameters
        object.__setattr__(self, 'loop', TrackingLoopParams(
            dll_bandwidth_hz=self.loop_dll_bandwidth_hz, correlator_spacing_chips=self.loop_correlator_spacing_chips,
            integration_time_s=self.loop_integration_time_s, fll_bandwidth_hz=self.loop_fll_bandwidth_hz,
            code_floor_m=self.loop_code_floor_m, rate_floor_mps=self.loop_rate_floor_mps))
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
            super().__post_init__()
        except (TypeError, ValueError) as err:
            raise ValueError(f'invalid filter parameters: {err}') from None

    def fusion_params(self) -> FusionParams:
        """The core's parameters.

        Raises:
            ValueError: a combination the core rejects (e.g. use_gnss and use_uwb both false).
        """
        values: dict[str, Any] = {f.name: getattr(self, f.name) for f in dataclasses.fields(FusionParams)}
        values['uwb_lever_arm_m'] = tuple(float(v) for v in self.uwb_lever_arm_m)
        return FusionParams(**values)


CONFIG_FILE = ConfigFile('uwb_gnss_fusion', 'config/fusion.yaml', 'uwb_gnss_fusion', FusionNodeParams, """
Parameters of fusion_node (uwb_gnss_fusion/fusion_node.py, FusionNodeParams).
GENERATED by tools/generate_config.py from uwb_gnss_fusion/fusion_params.py (FusionParams, the filter's),
rfi_node_common/diagnostics.py (NodeDiagnosticsParams, the stamp gate's and /diagnostics') and
uwb_gnss_fusion/fusion_node_params.py (FusionNodeParams, the node's): change a default or a
description there and run `python tools/generate_config.py`; a test checks this file equals it.
Method: Cao et al., tightly-coupled GNSS/UWB cubature Kalman filter under GNSS jamming; the filter
core is uwb_gnss_fusion/fusion_filter.py, results in docs/uwb_gnss_fusion/.

Use:   ros2 run uwb_gnss_fusion fusion_node --ros-args --params-file fusion.yaml
Every value below is the default. The user parameters (frames, lever arms, sensors used, masks and
the jamming model) come first; the tuning parameters after them are the tested values of the method.
An invalid value stops the node with a one-line error naming the parameter, and so does a
parameter the node does not have. Floats must be written with a decimal point.
Parameters marked [settable while running] can be changed with `ros2 param set /uwb_gnss_fusion
NAME VALUE`: the value is validated exactly as at start (refused with the same reason) and
applied between two messages. The others are read-only; FusionNodeParams' docstring
(fusion_node_params.py) says why for each group (the core derives its gate and process noise
at construction; buffers, timers and frames hold state).

Inputs  /gnss/measurements (rfi_msgs/GnssMeasurementArray, frame earth_frame_id),
        /uwb/ranges (rfi_msgs/UwbRange; anchor position in each message, frame earth_frame_id
        or map_frame_id), /rfi/jammer_state (rfi_msgs/JammerState: J/S for the weighting).
Outputs /fusion/odometry (nav_msgs/Odometry, ECEF), /fusion/local_odometry (nav_msgs/Odometry,
        map_frame_id -> base_frame_id, for robot_localization), /fusion/fix (sensor_msgs/NavSatFix,
        earth frame only, for navsat_transform), /fusion/datum (NavSatFix, latched: origin of
        map_frame_id), /fusion/status (rfi_msgs/FusionStatus, one per processed measurement),
        /diagnostics (every diagnostics_period_s of stamp time); only while subscribed, every
        1/view_rate_hz of stamp time: /fusion/path (nav_msgs/Path), /fusion/markers and
        /fusion/satellites (visualization_msgs/MarkerArray), all in map_frame_id.
""")
"""The shipped config/fusion.yaml (:func:`rfi_node_common.params.config_yaml`)."""

TOPICS = """topics:
  subscribes /gnss/measurements (rfi_msgs/GnssMeasurementArray), /uwb/ranges (rfi_msgs/UwbRange),
             /rfi/jammer_state (rfi_msgs/JammerState), /gnss/integrity (rfi_msgs/GnssIntegrity)
  publishes  /fusion/odometry (nav_msgs/Odometry, ECEF), /fusion/local_odometry (nav_msgs/Odometry, map ->
             base_link), /fusion/fix (sensor_msgs/NavSatFix), /fusion/datum (sensor_msgs/NavSatFix, latched: the
             origin of map), /fusion/status (rfi_msgs/FusionStatus), /diagnostics (diagnostic_msgs/DiagnosticArray),
             /fusion/path (nav_msgs/Path, map), /fusion/markers (visualization_msgs/MarkerArray: UWB anchors,
             covariance ellipse), /fusion/satellites (visualization_msgs/MarkerArray: used, rejected) (the last three
             only while subscribed, every 1/view_rate_hz of stamp time)"""
"""The topics of fusion_node, for its ``--help``."""
