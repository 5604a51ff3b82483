"""Parameters of imm_carrier_node, each written once (pure: no rclpy): the trackers' own come from the core dataclasses
(``ImmParams``, ``PllParams``, ``TrackerParams``) through ``parameter_from``; the node adds its own; the shipped
``config/imm_carrier.yaml`` and the user table of docs/reference/parameters.md are generated from them
(:data:`CONFIG_FILE`, ``tools/generate_config.py``, checked by a test)."""

from __future__ import annotations

from dataclasses import dataclass

from gnss_common.clock_model import PRESETS, RUBIDIUM_LPFRS, ClockHCoefficients
from imm_carrier.imm import ImmParams
from imm_carrier.pll import PllParams
from imm_carrier.tracker import TrackerParams
from rfi_node_common.diagnostics import NodeDiagnosticsParams, hardware_id_parameter
from rfi_node_common.params import (
    USER,
    ConfigFile,
    parameter,
    parameter_from,
    validate_ranges,
)

CUSTOM_CLOCK = 'custom'
"""clock_preset value that takes the clock from clock_h0_s and clock_h_minus2_hz."""

@dataclass(frozen=True)
class CarrierNodeParams(NodeDiagnosticsParams):
    """Parameters of the imm_carrier node (documented for users in config/imm_carrier.yaml).

    Notes:
        Zhao, Khanafseh & Pervan: clock model eq. 6-8 and Fig. 4 (h-coefficients, W), two-mode IMM
        with bit transition probability 0.5 (Section II), PLL bandwidth schedule eq. 10 (15 -> 1 Hz
        over 70 s). See imm_carrier.imm.ImmParams, imm_carrier.pll.PllParams and
        imm_carrier.tracker.TrackerParams for the decisions taken where the paper is silent.
    """

    method: str = parameter(
        'imm',
        'Which tracker runs: imm (the interacting multiple model filter, two modes = data bit +1/-1), pll '
        '(Costas PLL baseline, third-order loop) or both, side by side on the same correlators (both sets of '
        'estimates in each output array, told apart by CarrierPhase.method). Change to both to compare the '
        'trackers; pll alone is only a baseline.',
        choices=('imm', 'pll', 'both'), group=USER,
    )
    clock_preset: str = parameter(
        'rubidium',
        'Receiver clock model (h-coefficients) of the IMM (Zhao et al., eq. 6-8, Fig. 4), by preset: '
        "rubidium (SpectraTime LPFRS bound, the paper's), rubidium_vibration (the paper's vibration bound, "
        'h0 = 2e-21), tcxo, ocxo (Van Dierendonck, in Kaplan & Hegarty), ocxo_brown_hwang, '
        'compensated_crystal_brown_hwang (Brown & Hwang), or custom (then clock_h0_s and clock_h_minus2_hz '
        "are used). Change to match the receiver's oscillator: a filter that assumes a better clock than the "
        'real one slips; one that assumes a worse clock is noisier.',
        choices=(*PRESETS, CUSTOM_CLOCK), group=USER,
    )
    clock_h0_s: float = parameter(
        RUBIDIUM_LPFRS.h0,
        'White-FM coefficient h0 of the custom clock, s (= 1/Hz). Default: the LPFRS value. Used only with '
        'clock_preset custom (setting it with another preset is an error).',
        minimum=0.0, maximum=1e-15, group=USER,
    )
    clock_h_minus2_hz: float = parameter(
        RUBIDIUM_LPFRS.h_minus2,
        'Random-walk-FM coefficient h_-2 of the custom clock, 1/s (= Hz). Default: the LPFRS value. Used '
        'only with clock_preset custom. h_-1 (flicker FM) cannot be represented in the two-state model and '
        'is not a parameter.',
        minimum=0.0, maximum=1e-15, group=USER,
    )
    process_noise_form: str = parameter_from(ImmParams, 'process_noise_form')
    process_noise_scale: float = parameter_from(ImmParams, 'process_noise_scale')
    bit_transition_probability: float = parameter_from(ImmParams, 'bit_transition_probability')
    bit_period_s: float = parameter_from(TrackerParams, 'bit_period_s')
    iq_scaling: str = parameter_from(ImmParams, 'iq_scaling')
    carrier_frequency_hz: float = parameter_from(ImmParams, 'carrier_hz')
    initial_phase_std_rad: float = parameter_from(ImmParams, 'initial_phase_std_rad')
    initial_frequency_std_hz: float = parameter_from(ImmParams, 'initial_frequency_std_hz')
    lock_phase_std_max_rad: float = parameter_from(ImmParams, 'lock_phase_std_max_rad')
    slip_jump_threshold_rad: float = parameter_from(ImmParams, 'slip_jump_threshold_rad')
    pll_start_bandwidth_hz: float = parameter_from(PllParams, 'start_bandwidth_hz')
    pll_end_bandwidth_hz: float = parameter_from(PllParams, 'end_bandwidth_hz')
    pll_tightening_duration_s: float = parameter_from(PllParams, 'tightening_duration_s')
    pll_lock_time_constant_s: float = parameter_from(PllParams, 'lock_time_constant_s')
    pll_lock_threshold: float = parameter_from(PllParams, 'lock_threshold')
    channel_timeout_s: float = parameter_from(TrackerParams, 'channel_timeout_s')
    max_gap_intervals: float = parameter_from(TrackerParams, 'max_gap_intervals')
    min_integration_time_s: float = parameter_from(TrackerParams, 'min_integration_time_s')
    max_integration_time_s: float = parameter_from(TrackerParams, 'max_integration_time_s')
    max_iq_magnitude_ratio: float = parameter_from(TrackerParams, 'max_iq_magnitude_ratio')
    correlator_unlocked: str = parameter_from(TrackerParams, 'correlator_unlocked')
    hardware_id: str = hardware_id_parameter('gnss_receiver')

    def __post_init__(self) -> None:
        validate_ranges(self)
        if self.clock_preset != CUSTOM_CLOCK:
            for name, default in (('clock_h0_s', RUBIDIUM_LPFRS.h0), ('clock_h_minus2_hz', RUBIDIUM_LPFRS.h_minus2)):
                if getattr(self, name) != default:
                    raise ValueError(f'parameter {name} is only used with clock_preset {CUSTOM_CLOCK} '
                                     f'(clock_preset is {self.clock_preset})')
        for method in ('imm', 'pll'):
            try:
                self.tracker_params(method)
            except ValueError as err:
                raise ValueError(f'invalid tracker parameters: {err}') from None

    @property
    def methods(self) -> tuple[str, ...]:
        """The trackers to run, in output order."""
        return ('imm', 'pll') if self.method == 'both' else (self.method,)

    @property
    def clock(self) -> ClockHCoefficients:
        """The IMM's clock model."""
        if self.clock_preset == CUSTOM_CLOCK:
            return ClockHCoefficients(h0=self.clock_h0_s, h_minus2=self.clock_h_minus2_hz, name='custom')
        return PRESETS[self.clock_preset]

    def tracker_params(self, method: str) -> TrackerParams:
        """The core's parameters for tracker ``method`` ('imm' or 'pll').

        Raises:
            ValueError: a combination the core rejects (e.g. end bandwidth above start bandwidth).
        """
        imm = ImmParams(
            clock=self.clock, process_noise_form=self.process_noise_form,
            process_noise_scale=self.process_noise_scale, carrier_hz=self.carrier_frequency_hz,
            bit_transition_probability=self.bit_transition_probability, iq_scaling=self.iq_scaling,
            initial_phase_std_rad=self.initial_phase_std_rad, initial_frequency_std_hz=self.initial_frequency_std_hz,
            lock_phase_std_max_rad=self.lock_phase_std_max_rad, slip_jump_threshold_rad=self.slip_jump_threshold_rad)
        pll = PllParams(
            start_bandwidth_hz=self.pll_start_bandwidth_hz, end_bandwidth_hz=self.pll_end_bandwidth_hz,
            tightening_duration_s=self.pll_tightening_duration_s, iq_scaling=self.iq_scaling,
            lock_time_constant_s=self.pll_lock_time_constant_s, lock_threshold=self.pll_lock_threshold)
        return TrackerParams(method=method, imm=imm, pll=pll, channel_timeout_s=self.channel_timeout_s,
                             max_gap_intervals=self.max_gap_intervals, bit_period_s=self.bit_period_s,
                             min_integration_time_s=self.min_integration_time_s,
                             max_integration_time_s=self.max_integration_time_s,
                             max_iq_magnitude_ratio=self.max_iq_magnitude_ratio,
                             correlator_unlocked=self.correlator_unlocked)


CONFIG_FILE = ConfigFile('imm_carrier', 'config/imm_carrier.yaml', 'imm_carrier', CarrierNodeParams, """
Parameters of imm_carrier_node (imm_carrier/imm_carrier_node.py, CarrierNodeParams).
GENERATED by tools/generate_config.py from the parameter definitions: the trackers' in
imm_carrier/imm.py (ImmParams), pll.py (PllParams) and tracker.py (TrackerParams), the node's own in
imm_carrier_node.py (CarrierNodeParams). Change a default or a description there and run
`python tools/generate_config.py`; a test checks this file equals it.
Method: Zhao, Khanafseh & Pervan, "Clock Dynamics Analysis in IMM Filter for Carrier Phase
Estimation Through Interference". Design decisions: docs/imm_carrier/README.md.

Use:   ros2 run imm_carrier imm_carrier_node --ros-args --params-file imm_carrier.yaml
Every value below is the default. The user parameters (tracker, clock model, input scaling and
range) come first; the tuning parameters after them are the tested values of the method.
An invalid value stops the node with a one-line error naming the parameter, and so does a
parameter the node does not have. Floats must be written with a decimal point.
Parameters marked [settable while running] can be changed with `ros2 param set /imm_carrier NAME
VALUE` (validated as at start, applied before the next array). The others are read-only: each
tracker compiles its parameters into its kernel when it is built, and a new tracker would restart
every channel.

Input  /gnss/correlators (rfi_msgs/CorrelatorArray): prompt correlators, one array per
       integration interval, stamp = end of the interval, ROS (UTC) time (gnss_common.gps_time).
       Subscribed with the publishers' reliability (reliable with play or the suite's nodes, best
       effort once a best-effort sensor driver is there, so it is accepted); fix it with
       -p qos_overrides./gnss/correlators.subscription.reliability:=reliable (or best_effort).
Output /carrier/estimates (rfi_msgs/CarrierPhaseArray): one array per accepted input array,
       same header; /diagnostics: counters every diagnostics_period_s of accepted stamp time,
       and a STALE report when no input arrives for input_timeout_s (wall time).
""")
"""The shipped config/imm_carrier.yaml (:func:`rfi_node_common.params.config_yaml`)."""


