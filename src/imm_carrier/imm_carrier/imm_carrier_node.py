"""ROS node of the carrier trackers: /gnss/correlators -> /carrier/estimates, /diagnostics.

The node is thin: it declares the parameters, reads each ``rfi_msgs/CorrelatorArray`` into arrays,
hands them to one :class:`imm_carrier.tracker.CarrierTracker` per method (the IMM of Zhao, Khanafseh &
Pervan and the Costas PLL baseline, or both side by side on the same input), and publishes the
returned estimates as one ``rfi_msgs/CarrierPhaseArray`` per accepted input array (header copied from
the input, so the stamp is the input's). All maths, the channel life cycle (start on first sight,
drop after ``channel_timeout_s``, restart after a gap or a diverged estimate) and the per-correlator
input checks (integration time within the receiver's range, finite and plausible I/Q, physical C/N0
and predicted phase change) are in the core; the node only admits or rejects whole arrays, and counts.

Input: subscribed with :func:`rfi_node_common.inputs.subscribe_input` (the publishers' reliability by
default: reliable with play, best effort once a sensor driver's best-effort publisher is there, so both are
accepted; ``qos_overrides.
/gnss/correlators.subscription.*`` parameters change it). Arrivals, messages lost before reaching the
node and handler errors are counted per topic (``input./gnss/correlators.received``, ``.lost``,
``.middleware_lost``, ``.callback_errors``).

Whole arrays are rejected, each counted as ``rejected_arrays_<reason>`` (their correlators as
``correlators_in_rejected_arrays``), when:

* ``malformed``: the payload is not a CorrelatorArray (truncated, overwritten or random bytes, which
  neither the compiled decoder nor rclpy's deserialisation accept);
* ``stamp_malformed``: header.stamp.nanosec is 1e9 or more (not a valid builtin_interfaces/Time);
* ``stamp_not_positive``, ``stamp_not_increasing``, ``stamp_far_future``, ``stamp_far_past``: the
  stamp is refused by :class:`rfi_node_common.input_checks.StampGate` (zero or negative; not after the
  latest accepted stamp; further than ``max_stamp_jump_s`` from it). A jump confirmed by
  ``stamp_jump_confirmations`` arrays in a row is accepted as a new time line (``stamp_restarts``):
  every tracker's channels restart (``<method>.channels_restarted_stamp_jump``). One bad stamp
  therefore never stalls the node, and a refused stamp never reaches the trackers or /diagnostics.

Speed (32 satellites at 1 kHz): the subscription is raw and the answer is published as bytes. The
compiled codec :mod:`imm_carrier.cdr` reads the correlators straight into numpy arrays and writes the
CarrierPhaseArray from the tracker's result table; each tracker handles all channels of an array in
one compiled call. No Python object is made per channel. Little-endian CDR that the codec declines is
malformed; another encoding goes through rclpy's deserialisation (slower, same result) and is counted
as malformed if that fails too.

Accounting (reported on /diagnostics, every ``diagnostics_period_s`` of *accepted stamp* time): every
array received is processed, rejected with a reason, or (only if a handler raised, which the
subscription counts as ``callback_errors``) ``arrays_dropped_handler_error``; every correlator
received is either in a rejected array or, for each tracker, processed or rejected with a reason
(``<method>.rejected_*``). ``accounting_ok`` says that these add up. Rejections also give a throttled
warning. An estimate is published with ``locked = true`` only when the core's final check passes
(phase and frequency finite, the IMM's standard deviations finite and > 0, the state sane; see
:class:`imm_carrier.tracker.CarrierTracker`), and the codec checks the same again.

Levels (``hardware_id``: the receiver, from the parameter): ERROR when the accounting does not add
up, a tracker raised or a handler raised since the last report; WARN (inputs degraded) when over the
last ``diagnostics_window_s`` of stamp time more than ``warn_rejected_fraction`` of the arrays or of the
correlators was rejected, more than ``warn_lost_fraction`` of the arrays published was lost, or a
channel was restarted or its lock suppressed after an invalid estimate (each such event is rare and
means the input misled a tracker); else OK, so an isolated rejection on a clean stream stays OK
(:class:`rfi_node_common.diagnostics.CountWindow`). When no input has arrived for ``input_timeout_s``
of wall time, a STALE report (stamped with the node clock) says so, with the same counters
(:class:`rfi_node_common.inputs.StaleInputWatch`); no estimate depends on the wall clock.

Parameters settable while running (``ros2 param set``, validated as at start, applied before the next
array): ``hardware_id``, ``diagnostics_window_s``, ``warn_rejected_fraction``, ``warn_lost_fraction``,
``warning_throttle_s``. The tracker parameters are read-only: each tracker compiles them into its
kernel's configuration when it is built (imm_carrier.tracker.CarrierTracker) and has no call to change
them in flight, and a new tracker would restart every channel; ``method`` sets which trackers exist,
the stamp and timeout parameters size the stamp gate and the timers.

Core faults: should a tracker raise (it should not: the IMM keeps its mode probabilities as
logarithms, so that a mode whose probability underflowed to 0 and a correlator that favours it by
more than ~745 in log-likelihood cannot make it divide 0 by 0), the node counts it
(``<method>.core_faults``), drops that tracker's answer for the array (its correlators counted as
``<method>.dropped_core_fault``), restarts that tracker's channels, reports ERROR and keeps running.

The correlator's own carrier lock (``Correlator.carrier_lock``, e.g. gnss_correlator's lock rule): a correlator
reported LOST is tracked as any other, or with ``correlator_unlocked: coast`` the IMM only predicts over it
(docs/imm_carrier/correlator_lock.md says why tracking is the default). Such correlators are counted apart, per
tracker: ``<method>.correlator_unlocked`` (processed while the correlator's loop was unlocked),
``<method>.locked_on_correlator_unlocked`` (estimates published locked on them),
``<method>.slips_on_correlator_unlocked`` (slips the tracker detected on them, also in ``slips_detected``),
``imm.coasted_correlator_unlocked``, and
``<method>.correlator_lock_unknown`` (a producer that does not say, such as the simulator); the summary line
gives the unlocked count.

/rfi/jammer_state is not subscribed: the trackers take the signal level from the correlators'
C/N0 (which already reflects the jamming), and CarrierPhase has no field a jammer state would fill.
"""

from __future__ import annotations

from collections import Counter

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.serialization import deserialize_message, serialize_message

from imm_carrier.cdr import CDR_LE, DecodedCorrelatorArray, decode_correlator_array, encode_carrier_phase_array
from imm_carrier.node_params import CarrierNodeParams
from imm_carrier.tracker import CarrierTracker
from rfi_msgs.msg import CarrierPhaseArray, CorrelatorArray
from rfi_node_common.diagnostics import (
    ERROR,
    OK,
    STALE,
    WARN,
    CountWindow,
    StampTimer,
    degraded_inputs,
    diagnostic_array,
)
from rfi_node_common.input_checks import NS_PER_S, STAMP_REASONS, StampGate
from rfi_node_common.inputs import InputHealth, StaleInputWatch, subscribe_input
from rfi_node_common.main import run_node
from rfi_node_common.params import (
    RuntimeParameters,
    changed_names,
    declare,
)
from rfi_node_common.qos import DATA_QOS, DIAGNOSTICS_QOS

TOPICS = """topics:
  subscribes /gnss/correlators (rfi_msgs/CorrelatorArray)
  publishes  /carrier/estimates (rfi_msgs/CarrierPhaseArray), /diagnostics (diagnostic_msgs/DiagnosticArray)"""

INPUT_TOPIC = 'gnss/correlators'
"""Input topic, relative: /gnss/correlators without a namespace, /<ns>/gnss/correlators with ``-r __ns:=/<ns>``."""
MALFORMED = 'malformed'
STAMP_MALFORMED = 'stamp_malformed'
ARRAY_REJECTION_REASONS = (MALFORMED, STAMP_MALFORMED, *STAMP_REASONS)
"""Why a whole CorrelatorArray is rejected (``rejected_arrays_<reason>``; module docstring)."""
TRACKER_PROBLEM_KEYS = ('locked_suppressed_invalid', 'channels_restarted_nonfinite', 'channels_restarted_diverged')
"""Tracker counters of invalid estimates (each raises the level to WARN)."""


def decode_input(msg: CorrelatorArray | bytes) -> tuple[DecodedCorrelatorArray, bytes] | None:
    """A CorrelatorArray (serialised, as the raw subscription delivers it, or a message object) -> its
    fields as arrays, and the serialised encapsulation + header to copy into the answer; None if the
    bytes are not a CorrelatorArray.

    Little-endian CDR (what rclpy itself writes) is decoded by the compiled codec, which is exact for
    it (tested against rclpy): little-endian bytes that it declines are malformed. Another encoding is
    first re-serialised by rclpy, which gives little-endian CDR. Never raises on bytes: what rclpy
    cannot deserialise (it raises RMWError even for a 4-byte payload) is None.
    """
    raw = msg if isinstance(msg, bytes) else serialize_message(msg)
    decoded = decode_correlator_array(raw)
    if decoded is None:
        if raw[:2] == CDR_LE:
            return None
        try:
            raw = serialize_message(deserialize_message(raw, CorrelatorArray))
        except Exception:  # noqa: BLE001 - RMWError and whatever else a corrupt payload makes rclpy raise
            return None
        decoded = decode_correlator_array(raw)
        if decoded is None:
            return None
    return decoded, raw[:4 + decoded.header_end]


def rejected_total(counters: dict[str, int]) -> int:
    """Sum of the ``rejected_*`` counters."""
    return sum(v for k, v in counters.items() if k.startswith('rejected_'))


class ImmCarrierNode(Node):
    """Thin node around the carrier trackers (see module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__('imm_carrier', **kwargs)
        self.params = declare(self, CarrierNodeParams)
        self.runtime = RuntimeParameters(self, self.params)
        self._window = CountWindow(self.params.diagnostics_window_s)
        self.trackers = {m: CarrierTracker(self.params.tracker_params(m)) for m in self.params.methods}
        self.counts: Counter[str] = Counter()
        for key in ('arrays_received', 'arrays_processed', 'arrays_dropped_handler_error', 'stamp_restarts',
                    'correlators_received', 'correlators_in_rejected_arrays'):
            self.counts[key] += 0
        for reason in ARRAY_REJECTION_REASONS:
            self.counts[f'rejected_arrays_{reason}'] += 0
        self._retired: dict[str, Counter[str]] = {m: Counter() for m in self.trackers}
        self._locked: dict[str, int] = dict.fromkeys(self.trackers, 0)
        self.gate = StampGate(self.params.max_stamp_jump_s, self.params.stamp_jump_confirmations)
        self._at_last_report: Counter[str] = Counter()
        self._diag_timer = StampTimer(self.params.diagnostics_period_s)
        self.health = InputHealth()
        self.estimates_pub = self.create_publisher(CarrierPhaseArray, 'carrier/estimates', DATA_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self.subscription = subscribe_input(self, CorrelatorArray, INPUT_TOPIC, self.on_correlators, self.health,
                                            raw=True, warning_throttle_s=self.params.warning_throttle_s)
        self.stale_watch = StaleInputWatch(self, self.health, self.params.input_timeout_s, self._publish_stale)

    def on_correlators(self, msg: CorrelatorArray | bytes) -> None:
        """One CorrelatorArray, serialised (the raw subscription) or as a message object."""
        if self.runtime.pending:  # between two arrays: the safe point for a parameter change
            self.runtime.apply_pending(self._apply_parameters)
        self.counts['arrays_received'] += 1
        try:
            stamp_ns = self._on_array(msg)
        except Exception:
            # Only a fault of the node itself gets here (the subscription's guard counts and logs it as
            # callback_errors, ERROR): the array is counted so the accounting still adds up.
            self.counts['arrays_dropped_handler_error'] += 1
            raise
        if stamp_ns is not None and self._diag_timer.due(stamp_ns):  # driven by accepted stamps only
            self.diag_pub.publish(self.diagnostics(stamp_ns))

    def _on_array(self, msg: CorrelatorArray | bytes) -> int | None:
        """Decode, admit and track one array; returns its stamp if accepted (None if rejected, counted)."""
        decoded = decode_input(msg)
        if decoded is None:
            size = len(msg) if isinstance(msg, bytes) else -1
            return self._reject_array(MALFORMED, 0, f'malformed payload ({size} bytes) is not a CorrelatorArray')
        d, header = decoded
        n = d.constellation.shape[0]
        self.counts['correlators_received'] += n
        if not 0 <= d.stamp_nanosec < NS_PER_S:
            return self._reject_array(STAMP_MALFORMED, n, f'header.stamp.nanosec {d.stamp_nanosec} is not below 1e9')
        decision = self.gate.admit(d.stamp_ns)
        if not decision.accepted:
            return self._reject_array(decision.reason, n, f'stamp {d.stamp_ns} ns refused ({decision.reason}; latest '
                                      f'accepted {self.gate.latest_ns} ns)')
        if decision.restart:
            self.counts['stamp_restarts'] += 1
            dropped = sum(tracker.reset_channels() for tracker in self.trackers.values())
            self._warn(f'stamps jumped to {d.stamp_ns} ns (confirmed by {self.params.stamp_jump_confirmations} '
                       f'arrays): new time line, {dropped} channels restart')
        self._track(d.stamp_ns, d, header)
        return d.stamp_ns

    def _reject_array(self, reason: str, n_correlators: int, text: str) -> None:
        self.counts[f'rejected_arrays_{reason}'] += 1
        self.counts['correlators_in_rejected_arrays'] += n_correlators
        self._warn(f'correlator array rejected: {text}')
        return None

    def _track(self, stamp_ns: int, d: DecodedCorrelatorArray, header: bytes) -> None:
        n = d.constellation.shape[0]
        tables = []
        for method in self.params.methods:
            tracker = self.trackers[method]
            rejected_before = tracker.rejected_total
            try:
                batch = tracker.process_arrays(stamp_ns, d.constellation, d.svid, d.integration_time_s, d.in_phase,
                                               d.quadrature, d.cn0_dbhz, d.predicted_phase_change_rad,
                                               d.carrier_lock)
            except Exception as err:  # noqa: BLE001 - a core fault must not end the node (see _core_fault)
                self._core_fault(method, n, err)
                continue
            tables.append((batch.values, batch.method))
            self._locked[method] = int(batch.locked.sum())
            if tracker.rejected_total > rejected_before:
                reasons = ', '.join(f'{k}={v}' for k, v in tracker.counters.items() if k.startswith('rejected_') and v)
                self._warn(f'{method}: correlators rejected (totals: {reasons})')
        self.estimates_pub.publish(encode_carrier_phase_array(header, tables))
        self.counts['arrays_processed'] += 1

    def _core_fault(self, method: str, n_samples: int, err: Exception) -> None:
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

    def _apply_parameters(self, old: CarrierNodeParams, new: CarrierNodeParams) -> None:
        """A change of the settable parameters (node-level only: module docstring)."""
        self.params = new
        self._window.window_ns = int(round(new.diagnostics_window_s * 1e9))
        self.get_logger().info('parameters changed: ' + ', '.join(
            f'{name} = {getattr(new, name)!r}' for name in changed_names(old, new)))

    def tracker_counters(self, method: str) -> dict[str, int]:
        """Counters of tracker ``method`` since start (including trackers replaced after a fault)."""
        total = Counter(self._retired[method])
        total.update(self.trackers[method].counters)
        return {k: total[k] for k in self.trackers[method].counters}

    def _warn(self, text: str) -> None:
        self.get_logger().warn(text, throttle_duration_sec=self.params.warning_throttle_s)

    def accounting(self) -> dict[str, object]:
        """Counters of the node and of each tracker (``<method>.<key>``), and whether every input adds up.

        Arrays: arrays_received == arrays_processed + rejected_arrays_* + arrays_dropped_handler_error.
        For each tracker: correlators_received == correlators_in_rejected_arrays + processed +
        rejected_* + dropped_core_fault.
        """
        values: dict[str, object] = dict(sorted(self.counts.items()))
        c = self.counts
        ok = c['arrays_received'] == (c['arrays_processed'] + c['arrays_dropped_handler_error']
                                      + sum(c[f'rejected_arrays_{r}'] for r in ARRAY_REJECTION_REASONS))
        for method, tracker in self.trackers.items():
            tc = self.tracker_counters(method)
            values.update({f'{method}.{k}': v for k, v in tc.items()})
            values[f'{method}.channels'] = tracker.channel_count
            values[f'{method}.channels_locked'] = self._locked[method]
            accounted = (c['correlators_in_rejected_arrays'] + tc['processed'] + rejected_total(tc)
                         + c[f'{method}.dropped_core_fault'])
            ok = ok and accounted == c['correlators_received']
        values['accounting_ok'] = ok
        return values

    def _values(self) -> dict[str, object]:
        """Everything /diagnostics reports: the accounting and the input health (``input.<topic>.*``)."""
        values = self.accounting()
        values.update(self.health.values())
        return values

    def _channels_text(self, values: dict[str, object]) -> str:
        text = ', '.join(f'{m}: {values[f"{m}.channels"]} channels, {values[f"{m}.channels_locked"]} locked'
                         for m in self.trackers)
        first = next(iter(self.trackers))  # every tracker sees the same correlators
        return f'{text}; {values[f"{first}.correlator_unlocked"]} correlators came with the correlator unlocked'

    def diagnostics(self, stamp_ns: int) -> DiagnosticArray:
        """The /diagnostics message at ``stamp_ns`` (an accepted input stamp); levels in the module docstring."""
        values = self._values()
        p = self.params
        totals = Counter({
            'faults': sum(self.counts[f'{m}.core_faults'] for m in self.trackers),
            'callback_errors': self.health.callback_errors_total(),
        })
        new = totals - self._at_last_report  # Counter subtraction keeps the positive differences
        self._at_last_report = totals
        rejected_arrays = sum(self.counts[f'rejected_arrays_{r}'] for r in ARRAY_REJECTION_REASONS)
        w = self._window.update(stamp_ns, {
            'arrays': self.counts['arrays_received'], 'rejected_arrays': rejected_arrays,
            'correlators': self.counts['correlators_received'] * len(self.trackers),
            'rejected_correlators': sum(rejected_total(self.tracker_counters(m)) for m in self.trackers),
            'lost': self.health.lost_total(),
            'invalid': sum(self.tracker_counters(m)[k] for m in self.trackers for k in TRACKER_PROBLEM_KEYS)})
        checks = [('arrays rejected', w['rejected_arrays'], w['arrays']),
                  ('correlators rejected', w['rejected_correlators'], w['correlators'])]
        lost = ('messages lost', w['lost'], w['arrays'] + w['lost'])
        values['window_s'] = p.diagnostics_window_s
        if not values['accounting_ok']:
            level, text = ERROR, 'input accounting does not add up'
        elif new['faults'] or new['callback_errors']:
            level, text = ERROR, (f'{new["faults"]} tracker faults (channels restarted) and {new["callback_errors"]} '
                                  f'handler errors since the last report')
        else:
            degraded = degraded_inputs(checks, p.warn_rejected_fraction) + degraded_inputs([lost], p.warn_lost_fraction)
            if w['invalid']:
                degraded.append(f'{w["invalid"]} invalid estimates (channels restarted or unlocked)')
            if degraded:
                level, text = WARN, f'inputs degraded (window {p.diagnostics_window_s:g} s): ' + '; '.join(degraded)
            else:
                level, text = OK, 'tracking'
        return diagnostic_array(stamp_ns, 'imm_carrier', p.hardware_id, level,
                                f'{text}; {self._channels_text(values)}', values)

    def _publish_stale(self, silent_s: float) -> None:
        """STALE report of the StaleInputWatch (wall clock): no input for ``silent_s``; stamped with the node clock."""
        values = self._values()
        self.diag_pub.publish(diagnostic_array(
            self.get_clock().now().nanoseconds, 'imm_carrier', self.params.hardware_id, STALE,
            f'no input on {self.subscription.topic_name} for {silent_s:.1f} s (wall clock); '
            f'{self._channels_text(values)}', values))


def main(argv=None) -> int:
    return run_node(ImmCarrierNode, executable='imm_carrier_node', params_cls=CarrierNodeParams, topics=TOPICS,
                    summary='IMM carrier-phase tracking through interference, beside a Costas PLL.', argv=argv)

