"""ROS node of the carrier trackers: /gnss/correlators -> /carrier/estimates, /diagnostics.

The node is thin: it declares the parameters, reads each ``rfi_msgs/CorrelatorArray`` into arrays,
hands them to one :class:`imm_carrier.tracker.CarrierTracker` per method (the IMM of Zhao, Khanafseh &
Pervan and the Costas PLL baseline, or both side by side on the same input), and publishes the
returned estimates as one ``rfi_msgs/CarrierPhaseArray`` per accepted input array (header copied from
the input, so the stamp is the input's). All maths, the channel life cycle (start on first sight,
drop after ``channel_timeout_s``, restart after a gap) and the per-sample input checks are in the core;
the node only rejects whole arrays whose stamp does not increase, and counts.

Speed (32 satellites at 1 kHz): the subscription is raw and the answer is published as bytes. The
compiled codec :mod:`imm_carrier.cdr` reads the correlators straight into numpy arrays and writes the
CarrierPhaseArray from the tracker's result table; each tracker handles all channels of an array in
one compiled call. No Python object is made per channel. Input that is not little-endian CDR goes
through rclpy's deserialisation first (slower, same result).

Accounting (reported on /diagnostics, every ``diagnostics_period_s`` of *stamp* time): every
correlator received is either in a rejected array or, for each tracker, processed or rejected with a
reason (``<method>.rejected_*``); ``accounting_ok`` says that these add up. Rejections also give a
throttled warning. An estimate is published with ``locked = true`` only when the core says so and its
phase and frequency are finite.

Core faults: should the core raise an ArithmeticError (it should not; up to commit 8350ac4 the IMM's
mode-probability normalisation divided 0 by 0 when one mode's probability had underflowed to 0 and a
correlator favoured that mode by more than ~745 in log-likelihood, fixed by keeping the mode
probabilities as logarithms), the node counts it (``<method>.core_faults``), drops that tracker's
answer for the array (its correlators counted as ``<method>.dropped_core_fault``), restarts that
tracker's channels, reports ERROR and keeps running.

/rfi/jammer_state is not subscribed: the trackers take the signal level from the correlators'
C/N0 (which already reflects the jamming), and CarrierPhase has no field a jammer state would fill.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.serialization import deserialize_message, serialize_message

from gnss_common.clock_model import PRESETS, PROCESS_NOISE_FORMS, RUBIDIUM_LPFRS, ClockHCoefficients
from gnss_common.constants import GPS_L1_FREQUENCY_HZ
from imm_carrier.cdr import DecodedCorrelatorArray, decode_correlator_array, encode_carrier_phase_array
from imm_carrier.imm import ImmParams
from imm_carrier.measurement_model import IQ_SCALINGS
from imm_carrier.pll import PllParams
from imm_carrier.tracker import CarrierTracker, TrackerParams
from rfi_msgs.msg import CarrierPhaseArray, CorrelatorArray
from rfi_node_common.diagnostics import ERROR, OK, WARN, StampTimer, diagnostic_array
from rfi_node_common.main import run_node
from rfi_node_common.params import declare, parameter, validate_ranges
from rfi_node_common.qos import DATA_QOS

TOPICS = """topics:
  subscribes /gnss/correlators (rfi_msgs/CorrelatorArray)
  publishes  /carrier/estimates (rfi_msgs/CarrierPhaseArray), /diagnostics (diagnostic_msgs/DiagnosticArray)"""

CUSTOM_CLOCK = 'custom'
"""clock_preset value that takes the clock from clock_h0 and clock_h_minus2."""


@dataclass(frozen=True)
class CarrierNodeParams:
    """Parameters of the imm_carrier node (documented for users in config/imm_carrier.yaml).

    Notes:
        Zhao, Khanafseh & Pervan: clock model eq. 6-8 and Fig. 4 (h-coefficients, W), two-mode IMM
        with bit transition probability 0.5 (Section II), PLL bandwidth schedule eq. 10 (15 -> 1 Hz
        over 70 s). See imm_carrier.imm.ImmParams, imm_carrier.pll.PllParams and
        imm_carrier.tracker.TrackerParams for the decisions taken where the paper is silent.
    """

    method: str = parameter('imm', 'Tracker to run: imm, pll or both (side by side on the same input).',
                            choices=('imm', 'pll', 'both'))
    clock_preset: str = parameter(
        'rubidium', 'Receiver clock model (h-coefficients) of the IMM: a preset of gnss_common.clock_model, or '
        'custom to use clock_h0 and clock_h_minus2.', choices=(*PRESETS, CUSTOM_CLOCK))
    clock_h0: float = parameter(
        RUBIDIUM_LPFRS.h0, 'White-FM coefficient h0 of the custom clock, s (1/Hz). Only with clock_preset custom.',
        minimum=0.0, maximum=1e-15)
    clock_h_minus2: float = parameter(
        RUBIDIUM_LPFRS.h_minus2, 'Random-walk-FM coefficient h_-2 of the custom clock, 1/s (Hz). Only with '
        'clock_preset custom.', minimum=0.0, maximum=1e-15)
    process_noise_form: str = parameter(
        'brown_hwang', 'Discretisation of the clock process noise W: brown_hwang (exact, W22 = S_g T) or '
        'zhao_eq8 (text of the paper, W22 = S_f/T + 4 S_g T/3).', choices=PROCESS_NOISE_FORMS)
    process_noise_scale: float = parameter(
        1.0, 'Factor on the whole process noise W of the IMM (sensitivity study), dimensionless.',
        minimum=1e-6, maximum=1e12)
    bit_transition_probability: float = parameter(
        0.5, 'Probability that the navigation data bit changes between two 20 ms bits (IMM mode transition), '
        '0..1; 0.5 = independent bits (the paper).', minimum=0.0, maximum=1.0)
    bit_period_s: float = parameter(
        0.02, 'Known data-bit timing: with T shorter than this, bit changes are allowed only on intervals '
        'starting on a bit edge of the GPS time grid (stamps are GPS time), s; 0 = edges unknown.',
        minimum=0.0, maximum=1.0)
    iq_scaling: str = parameter(
        'unit_amplitude', 'Normalisation of the input correlators: unit_amplitude (A = 1, noise std from C/N0) '
        'or unit_noise (noise std 1, A from C/N0).', choices=IQ_SCALINGS)
    carrier_frequency_hz: float = parameter(
        GPS_L1_FREQUENCY_HZ, 'Carrier frequency of the tracked signal, Hz (scales the clock noise).',
        minimum=1e6, maximum=1e11)
    initial_phase_std_rad: float = parameter(
        0.5, 'IMM phase 1-sigma when a channel starts from its first correlator, rad.', minimum=1e-6, maximum=10.0)
    initial_frequency_std_hz: float = parameter(
        1.0, 'IMM frequency 1-sigma when a channel starts, Hz.', minimum=1e-9, maximum=1e4)
    lock_phase_std_max_rad: float = parameter(
        0.5, 'IMM estimate reported locked only while its phase 1-sigma is below this, rad.',
        minimum=1e-6, maximum=math.pi)
    slip_jump_threshold_rad: float = parameter(
        math.pi / 2.0, 'An IMM update moving the phase more than this from its prediction counts as a detected '
        'cycle slip, rad.', minimum=1e-3, maximum=2.0 * math.pi)
    pll_start_bandwidth_hz: float = parameter(
        15.0, 'PLL noise bandwidth when a channel starts, Hz (paper: 15).', minimum=0.01, maximum=100.0)
    pll_end_bandwidth_hz: float = parameter(
        1.0, 'PLL noise bandwidth after the tightening, Hz (paper: 1); <= pll_start_bandwidth_hz.',
        minimum=0.01, maximum=100.0)
    pll_tightening_duration_s: float = parameter(
        70.0, 'Time over which the PLL bandwidth goes from start to end (eq. 10 shape), s (paper: 70).',
        minimum=1e-3, maximum=1e5)
    pll_lock_time_constant_s: float = parameter(
        1.0, 'Time constant of the PLL lock indicator averages, s.', minimum=1e-3, maximum=1e3)
    pll_lock_threshold: float = parameter(
        0.5, 'PLL reported locked while the estimate of cos(2 phase error) exceeds this, dimensionless.',
        minimum=0.01, maximum=0.99)
    channel_timeout_s: float = parameter(
        1.0, 'A satellite channel not seen for longer than this (stamp time) is dropped, s.',
        minimum=1e-3, maximum=3600.0)
    max_gap_intervals: float = parameter(
        1.5, 'A gap longer than this many integration times breaks phase continuity: the channel restarts, '
        'integration intervals.', minimum=1.01, maximum=1e6)
    diagnostics_period_s: float = parameter(
        1.0, 'Period of /diagnostics in message (stamp) time, s.', minimum=0.01, maximum=3600.0)
    warning_throttle_s: float = parameter(
        5.0, 'Shortest interval between two warnings about rejected input, s (wall time; logging only).',
        minimum=0.0, maximum=3600.0)

    def __post_init__(self) -> None:
        validate_ranges(self)
        if self.clock_preset != CUSTOM_CLOCK:
            for name in ('clock_h0', 'clock_h_minus2'):
                default = getattr(RUBIDIUM_LPFRS, name[len('clock_'):])
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
            return ClockHCoefficients(h0=self.clock_h0, h_minus2=self.clock_h_minus2, name='custom')
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
                             max_gap_intervals=self.max_gap_intervals, bit_period_s=self.bit_period_s)


def decode_input(msg: CorrelatorArray | bytes) -> tuple[DecodedCorrelatorArray, bytes]:
    """A CorrelatorArray (serialised, as the raw subscription delivers it, or a message object) -> its
    fields as arrays, and the serialised encapsulation + header to copy into the answer.

    Little-endian CDR is decoded by the compiled codec; anything else (another encoding, a message
    object) is first re-serialised by rclpy, which gives little-endian CDR.
    """
    raw = msg if isinstance(msg, bytes) else serialize_message(msg)
    decoded = decode_correlator_array(raw)
    if decoded is None:
        raw = serialize_message(deserialize_message(raw, CorrelatorArray))
        decoded = decode_correlator_array(raw)
        if decoded is None:
            raise ValueError('CorrelatorArray could not be decoded')
    return decoded, raw[:4 + decoded.header_end]


def rejected_total(counters: dict[str, int]) -> int:
    """Sum of the ``rejected_*`` counters."""
    return sum(v for k, v in counters.items() if k.startswith('rejected_'))


class ImmCarrierNode(Node):
    """Thin node around the carrier trackers (see module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__('imm_carrier', **kwargs)
        self.params = declare(self, CarrierNodeParams)
        self.trackers = {m: CarrierTracker(self.params.tracker_params(m)) for m in self.params.methods}
        self.counts: Counter[str] = Counter()
        self._retired: dict[str, Counter[str]] = {m: Counter() for m in self.trackers}
        self._locked: dict[str, int] = dict.fromkeys(self.trackers, 0)
        self._last_stamp_ns: int | None = None
        self._rejected_at_last_report = 0
        self._faults_at_last_report = 0
        self._diag_timer = StampTimer(self.params.diagnostics_period_s)
        self.estimates_pub = self.create_publisher(CarrierPhaseArray, '/carrier/estimates', DATA_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', DATA_QOS)
        self.create_subscription(CorrelatorArray, '/gnss/correlators', self.on_correlators, DATA_QOS, raw=True)

    def on_correlators(self, msg: CorrelatorArray | bytes) -> None:
        """One CorrelatorArray, serialised (the raw subscription) or as a message object."""
        decoded, header = decode_input(msg)
        stamp_ns = decoded.stamp_ns
        n = decoded.constellation.shape[0]
        self.counts['arrays_received'] += 1
        self.counts['correlators_received'] += n
        if self._last_stamp_ns is not None and stamp_ns <= self._last_stamp_ns:
            self.counts['rejected_arrays_stamp_not_increasing'] += 1
            self.counts['correlators_in_rejected_arrays'] += n
            self._warn(f'correlator array rejected: stamp {stamp_ns} ns does not increase '
                       f'(last {self._last_stamp_ns} ns)')
        else:
            self._last_stamp_ns = stamp_ns
            self._track(stamp_ns, decoded, header)
        if self._diag_timer.due(stamp_ns):
            self.diag_pub.publish(self.diagnostics(stamp_ns))

    def _track(self, stamp_ns: int, d: DecodedCorrelatorArray, header: bytes) -> None:
        n = d.constellation.shape[0]
        tables = []
        for method in self.params.methods:
            tracker = self.trackers[method]
            rejected_before = tracker.rejected_total
            try:
                batch = tracker.process_arrays(stamp_ns, d.constellation, d.svid, d.integration_time_s, d.in_phase,
                                               d.quadrature, d.cn0_dbhz, d.predicted_phase_change_rad)
            except ArithmeticError as err:
                self._core_fault(method, n, err)
                continue
            tables.append((batch.values, batch.method))
            self._locked[method] = int(batch.locked.sum())
            if tracker.rejected_total > rejected_before:
                reasons = ', '.join(f'{k}={v}' for k, v in tracker.counters.items() if k.startswith('rejected_') and v)
                self._warn(f'{method}: correlators rejected (totals: {reasons})')
        self.counts['arrays_processed'] += 1
        self.estimates_pub.publish(encode_carrier_phase_array(header, tables))

    def _core_fault(self, method: str, n_samples: int, err: ArithmeticError) -> None:
        """The core raised on an array: count it, drop that tracker's answer, restart its channels.

        The tracker's counters are unchanged by a call that raises, so the array's correlators are all
        counted as ``<method>.dropped_core_fault`` and the accounting still adds up. The faulted tracker
        is replaced by a fresh one (its channels restart from their next correlator and are counted
        again in channels_started); its counters are carried over. Diagnostics go to ERROR.
        """
        self.counts[f'{method}.core_faults'] += 1
        self.counts[f'{method}.dropped_core_fault'] += n_samples
        self._retired[method].update(self.trackers[method].counters)
        self.trackers[method] = CarrierTracker(self.params.tracker_params(method))
        self._locked[method] = 0
        self.get_logger().error(f'{method} tracker fault ({type(err).__name__}: {err}); its channels restart',
                                throttle_duration_sec=self.params.warning_throttle_s)

    def tracker_counters(self, method: str) -> dict[str, int]:
        """Counters of tracker ``method`` since start (including trackers replaced after a fault)."""
        total = Counter(self._retired[method])
        total.update(self.trackers[method].counters)
        return {k: total[k] for k in self.trackers[method].counters}

    def _warn(self, text: str) -> None:
        self.get_logger().warn(text, throttle_duration_sec=self.params.warning_throttle_s)

    def accounting(self) -> dict[str, object]:
        """Counters of the node and of each tracker (``<method>.<key>``), and whether every input adds up.

        For each tracker: correlators_received == correlators_in_rejected_arrays + processed +
        rejected_* + dropped_core_fault.
        """
        values: dict[str, object] = dict(sorted(self.counts.items()))
        ok = True
        for method, tracker in self.trackers.items():
            c = self.tracker_counters(method)
            values.update({f'{method}.{k}': v for k, v in c.items()})
            values[f'{method}.channels'] = tracker.channel_count
            values[f'{method}.channels_locked'] = self._locked[method]
            accounted = (self.counts['correlators_in_rejected_arrays'] + c['processed'] + rejected_total(c)
                         + self.counts[f'{method}.dropped_core_fault'])
            ok = ok and accounted == self.counts['correlators_received']
        values['accounting_ok'] = ok
        return values

    def diagnostics(self, stamp_ns: int) -> DiagnosticArray:
        """The /diagnostics message at ``stamp_ns``: ERROR if the accounting does not add up or the core
        faulted since the last report, WARN if input was rejected since the last report, else OK."""
        values = self.accounting()
        rejected = self.counts['rejected_arrays_stamp_not_increasing'] + sum(
            rejected_total(self.tracker_counters(m)) for m in self.trackers)
        new = rejected - self._rejected_at_last_report
        self._rejected_at_last_report = rejected
        faults = sum(self.counts[f'{m}.core_faults'] for m in self.trackers)
        new_faults = faults - self._faults_at_last_report
        self._faults_at_last_report = faults
        channels = ', '.join(f'{m}: {values[f"{m}.channels"]} channels, {values[f"{m}.channels_locked"]} locked'
                             for m in self.trackers)
        if not values['accounting_ok']:
            level, text = ERROR, 'input accounting does not add up'
        elif new_faults:
            level, text = ERROR, f'{new_faults} tracker faults since the last report (channels restarted)'
        elif new:
            level, text = WARN, f'{new} inputs rejected since the last report'
        else:
            level, text = OK, 'tracking'
        return diagnostic_array(stamp_ns, 'imm_carrier', self.get_name(), level, f'{text}; {channels}', values)


def main(argv=None) -> int:
    return run_node(ImmCarrierNode, executable='imm_carrier_node', params_cls=CarrierNodeParams, topics=TOPICS,
                    summary='IMM carrier-phase tracking through interference, beside a Costas PLL.', argv=argv)

