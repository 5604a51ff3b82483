"""ROS node of the integrity monitor: GNSS, UWB, receiver and SDR evidence -> /gnss/integrity.

Thin: it declares the parameters, converts each message into the core's plain types
(:mod:`gnss_integrity.integrity_messages`), hands them to one
:class:`gnss_integrity.monitor.IntegrityMonitor`, and publishes one rfi_msgs/GnssIntegrity per GNSS
epoch, stamped with the epoch's stamp (so the fusion orders it with its inputs). Every input is
optional; a test whose input is missing says UNKNOWN.

Inputs (each through :func:`rfi_node_common.inputs.subscribe_input`: the publishers' reliability by
default, best effort once a best-effort driver is there; losses and handler errors counted per topic):

* ``gnss/measurements`` (GnssMeasurementArray): the epochs judged. Rejected, counted by reason:
  ``malformed`` (bytes rclpy cannot read), ``gnss_frame_id`` (not ``earth_frame_id``), and the stamp
  reasons of :class:`rfi_node_common.input_checks.StampGate` (not positive, not increasing, a jump
  beyond ``max_stamp_jump_s``; a jump confirmed ``stamp_jump_confirmations`` times restarts the
  monitor, ``restarts``).
  A satellite with a corrupt field (:mod:`rfi_node_common.message_checks`, as in the fusion: a 1-sigma that is
  not NaN and not in its plausible range, an impossible C/N0, satellite state or atmospheric delay) is dropped
  from the epoch before the monitor, counted per reason (``dropped_satellites.<reason>``), and the epoch judged
  on the rest.
* ``uwb/ranges`` (UwbRange) with anchors in ``earth_frame_id`` (ECEF): the kinematic tests. A range
  in another frame is rejected (``uwb_frame_unsupported``: the monitor needs ECEF anchors), as is what
  :func:`rfi_node_common.message_checks.uwb_range_reason` finds implausible, counted under its reason (as in the
  fusion): a 1-sigma that is not NaN and not plausible (``invalid_range_std``), a non-finite anchor or one off the
  Earth (``nonfinite_anchor_position``, ``nonphysical_anchor_position``), a range that is not finite, negative, or
  outside [``UWB_RANGE_MIN_M``, ``UWB_RANGE_MAX_M``] (``nonfinite_range``, ``negative_range``, ``range_too_short``,
  ``range_too_long``): the monitor keeps each anchor's newest range, so one corrupt range made every epoch raise
  until the anchor was heard again (found by the long fuzz: 3 of its 10 valid tail epochs unanswered).
* ``gnss/receiver_interference`` (ReceiverInterference): the receiver's AGC, jam indicator,
  jamming and spoofing flags.
* ``gnss/receiver_spectrum`` (ReceiverSpectrum): a spectrum that does not fit (bins, span) is
  rejected as ``spectrum_invalid``.
* ``rfi/jammer_state`` (JammerState): an SDR monitor's verdict.

A side input (UWB, receiver, spectrum, SDR) stamped at or before 0 (``stamp_not_positive``) or more than
``max_stamp_jump_s`` after the latest accepted GNSS epoch (``stamp_far_future``) is rejected: the monitor holds
side inputs until the epoch they precede, and one hostile stamp must not sit there.

Arrival order: each epoch's verdict depends on the stamps and contents of the messages, not on the order in which
the executor happens to run the callbacks. Before an epoch is judged, every side input that has already reached
the node is taken (:meth:`rfi_node_common.inputs.InputSubscription.take_pending`: rclpy's executor serves one
message per ready subscription per wait, GNSS first, so under load an epoch was judged before ranges that came
earlier), and the monitor uses only the side inputs stamped at or before the epoch, in stamp order, holding the
later ones for the next epoch (:mod:`gnss_integrity.monitor`). ``play --sync`` (which sends an epoch only after
every earlier message, and the next messages only after the verdict) therefore gives the verdicts of an
in-process replay; a side input stamped at or before an epoch that reaches the node only after the epoch's
verdict is used from the next epoch on. Nothing waits for input that may never come.

A core exception on one message is counted (``core_exceptions``), logged, and the message dropped:
no message kills the node and nothing is published from a failed evaluation. /diagnostics every
``diagnostics_period_s`` of accepted GNSS stamp time: ERROR if the accounting does not add up or the
core raised since the last report; WARN while spoofing or jamming is DETECTED (with the deciding
tests) or inputs are degraded (over ``diagnostics_window_s`` more than ``warn_rejected_fraction``
rejected or ``warn_lost_fraction`` lost); OK otherwise; STALE after ``input_timeout_s`` of silence.

The C/N0 model can be loaded at start from ``cn0_model_file`` (a JSON written by
:meth:`gnss_integrity.cn0_model.Cn0Models.save`; a file that does not exist is reported and the
model is learned from scratch) and is saved there at shutdown when ``save_cn0_model`` is true.
"""

from __future__ import annotations

import os
from collections import Counter
from dataclasses import replace
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.serialization import deserialize_message

from gnss_integrity import kernels, uwb_range_rate
from gnss_integrity.cn0_model import Cn0Models
from gnss_integrity.integrity_messages import receiver_report, report_to_msg, spectrum_input
from gnss_integrity.monitor import IntegrityMonitor
from gnss_integrity.node_params import IntegrityNodeParams
from gnss_integrity.outcome import STATE_DETECTED
from rfi_msgs.msg import (
    GnssIntegrity,
    GnssMeasurementArray,
    JammerState,
    ReceiverInterference,
    ReceiverSpectrum,
    UwbRange,
)
from rfi_node_common.conversions import msg_to_epoch, msg_to_uwb
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
from rfi_node_common.input_checks import STAMP_FAR_FUTURE, STAMP_NOT_POSITIVE, StampGate
from rfi_node_common.inputs import InputHealth, InputSubscription, StaleInputWatch, subscribe_input
from rfi_node_common.main import run_node
from rfi_node_common.message_checks import FRAME_EARTH, satellite_reason, uwb_range_reason
from rfi_node_common.params import RuntimeParameters, changed_names, declare
from rfi_node_common.qos import DATA_QOS, DIAGNOSTICS_QOS
from rfi_node_common.stamps import stamp_to_ns

TOPICS = """topics:
  subscribes gnss/measurements (rfi_msgs/GnssMeasurementArray), uwb/ranges (rfi_msgs/UwbRange, anchors in ECEF),
             gnss/receiver_interference (rfi_msgs/ReceiverInterference), gnss/receiver_spectrum
             (rfi_msgs/ReceiverSpectrum), rfi/jammer_state (rfi_msgs/JammerState); every input optional
  publishes  gnss/integrity (rfi_msgs/GnssIntegrity, one per GNSS epoch), /diagnostics"""

KINDS = ('gnss', 'uwb', 'receiver', 'spectrum', 'sdr')
"""Input kinds, as used in the counter names (``<kind>_received``, ``_rejected``, ``_processed``)."""
__all__ = ['GnssIntegrityNode', 'IntegrityNodeParams', 'main']


class GnssIntegrityNode(Node):
    """Thin node around :class:`IntegrityMonitor` (module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__('gnss_integrity', **kwargs)
        self.params = declare(self, IntegrityNodeParams)
        self.runtime = RuntimeParameters(self, self.params)  # the settable parameters: applied between messages
        self.monitor = IntegrityMonitor(self.params.monitor_params())
        self.counts: Counter[str] = Counter({f'{k}_{what}': 0 for k in KINDS
                                             for what in ('received', 'rejected', 'processed')})
        self.counts.update({'core_exceptions': 0, 'restarts': 0, 'published': 0, 'side_inputs_taken_before_epoch': 0})
        self.reasons: Counter[str] = Counter()
        self.dropped_satellites: Counter[str] = Counter()  # satellites taken out of accepted epochs, per reason
        self._load_model()
        self.gate = StampGate(self.params.max_stamp_jump_s, self.params.stamp_jump_confirmations)
        self._window = CountWindow(self.params.diagnostics_window_s)
        self._diag_timer = StampTimer(self.params.diagnostics_period_s)
        self._faults_at_report = 0
        self._last: GnssIntegrity | None = None
        self._report_due_ns: int | None = None  # a /diagnostics report due at this GNSS stamp
        self.pub = self.create_publisher(GnssIntegrity, 'gnss/integrity', DATA_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        # compile (or load from numba's cache) before subscribing: the node appears when it can keep up
        kernels.warm_up()
        uwb_range_rate.warm_up()
        # created after the compilation, so that its silence clock starts when the node can listen
        self.health = InputHealth()
        throttle = self.params.warning_throttle_s
        self.inputs: dict[str, InputSubscription] = {}
        for cls, topic, kind in ((GnssMeasurementArray, 'gnss/measurements', 'gnss'), (UwbRange, 'uwb/ranges', 'uwb'),
                                 (ReceiverInterference, 'gnss/receiver_interference', 'receiver'),
                                 (ReceiverSpectrum, 'gnss/receiver_spectrum', 'spectrum'),
                                 (JammerState, 'rfi/jammer_state', 'sdr')):
            self.inputs[kind] = subscribe_input(self, cls, topic, self._handler(cls, kind), self.health, raw=True,
                                                warning_throttle_s=throttle)
        self.stale_watch = StaleInputWatch(self, self.health, self.params.input_timeout_s, self._publish_stale)

    # ------------------------------------------------------------------ inputs
    def _handler(self, cls: Any, kind: str):
        handle = getattr(self, f'on_{kind}')

        def callback(raw: bytes) -> None:
            if kind == 'gnss':  # the side inputs that came before the epoch first (module docstring)
                self.counts['side_inputs_taken_before_epoch'] += self.take_side_inputs()
            if self.runtime.pending:
                self.runtime.apply_pending(self._apply_parameters)
            self.counts[f'{kind}_received'] += 1
            try:
                msg = deserialize_message(raw, cls)
            except Exception:  # rclpy raises RMWError (and may raise others) on malformed bytes
                self._reject(kind, 'malformed', f'{cls.__name__} bytes that cannot be read')
                return
            try:
                reason = handle(msg)
            except Exception as err:  # a core bug: counted and logged, the node goes on
                self.counts['core_exceptions'] += 1
                self.counts[f'{kind}_rejected'] += 1
                self.reasons['core_exception'] += 1
                self.get_logger().error(f'integrity core raised on a {kind} message: {type(err).__name__}: {err}',
                                        throttle_duration_sec=self.params.warning_throttle_s)
                return
            if reason is None:
                self.counts[f'{kind}_processed'] += 1
            else:
                self._reject(kind, reason, f'{cls.__name__} rejected')
            due, self._report_due_ns = self._report_due_ns, None
            if due is not None:  # after the counting: the report's accounting includes this message
                self.diag_pub.publish(self.diagnostics(due))
        return callback

    def take_side_inputs(self) -> int:
        """Handle every side input (UWB, receiver, spectrum, SDR) that has reached the node and waits for the
        executor; returns how many."""
        return sum(self.inputs[kind].take_pending() for kind in KINDS if kind != 'gnss')

    def _side_stamp(self, stamp) -> str | None:
        """Why a side input's stamp is refused (module docstring), or None."""
        stamp_ns = stamp_to_ns(stamp)
        if stamp_ns <= 0:
            return STAMP_NOT_POSITIVE
        latest = self.gate.latest_ns
        if latest is not None and stamp_ns - latest > self.gate.max_jump_ns:
            return STAMP_FAR_FUTURE
        return None

    def _apply_parameters(self, old: IntegrityNodeParams, new: IntegrityNodeParams) -> None:
        """A change of the settable parameters (hardware_id, the diagnostics window and thresholds,
        warning_throttle_s; the tests' parameters are read-only)."""
        self.params = new
        self._window.window_ns = int(round(new.diagnostics_window_s * 1e9))
        self.get_logger().info('parameters changed: ' + ', '.join(
            f'{name} = {getattr(new, name)!r}' for name in changed_names(old, new)))

    def _reject(self, kind: str, reason: str, text: str) -> None:
        self.counts[f'{kind}_rejected'] += 1
        self.reasons[reason] += 1
        self.get_logger().warn(f'{text} ({reason})', throttle_duration_sec=self.params.warning_throttle_s)

    def on_gnss(self, msg: GnssMeasurementArray) -> str | None:
        if msg.header.frame_id != self.params.earth_frame_id:
            return 'gnss_frame_id'
        try:
            epoch = msg_to_epoch(msg, expected_frame_id=None)
        except ValueError:
            return 'gnss_malformed'
        decision = self.gate.admit(epoch.stamp_ns)
        if not decision.accepted:
            return str(decision.reason)
        kept = []
        for obs in epoch.observations:
            if (dropped := satellite_reason(obs)) is None:
                kept.append(obs)
            else:
                self.dropped_satellites[dropped] += 1
        if len(kept) < len(epoch.observations):
            epoch = replace(epoch, observations=tuple(kept))
        if decision.restart:
            self.counts['restarts'] += 1
            self.get_logger().warn(f'GNSS stamps jumped to {epoch.stamp_ns} ns: integrity monitor restarted')
            self.monitor = IntegrityMonitor(self.params.monitor_params())
        report = self.monitor.process_epoch(epoch)
        out = report_to_msg(report, msg.header.frame_id)
        self.pub.publish(out)
        self.counts['published'] += 1
        self._last = out
        if self._diag_timer.due(epoch.stamp_ns):
            self._report_due_ns = epoch.stamp_ns
        return None

    def on_uwb(self, msg: UwbRange) -> str | None:
        if msg.header.frame_id != self.params.earth_frame_id:
            return 'uwb_frame_unsupported'
        if (refused := self._side_stamp(msg.header.stamp)) is not None:
            return refused
        meas = msg_to_uwb(msg)
        if (implausible := uwb_range_reason(replace(meas, frame_id=FRAME_EARTH))) is not None:
            return implausible
        self.monitor.add_uwb(meas)
        return None

    def on_receiver(self, msg: ReceiverInterference) -> str | None:
        if (refused := self._side_stamp(msg.header.stamp)) is not None:
            return refused
        self.monitor.add_receiver_report(receiver_report(msg))
        return None

    def on_spectrum(self, msg: ReceiverSpectrum) -> str | None:
        try:
            spectrum = spectrum_input(msg)
            self.monitor.spectrum.check(spectrum)
        except ValueError:
            return 'spectrum_invalid'
        if (refused := self._side_stamp(msg.header.stamp)) is not None:
            return refused
        self.monitor.add_spectrum(stamp_to_ns(msg.header.stamp), spectrum)
        return None

    def on_sdr(self, msg: JammerState) -> str | None:
        if msg.type > JammerState.UNKNOWN:
            return 'jammer_state_unknown_type'
        if (refused := self._side_stamp(msg.header.stamp)) is not None:
            return refused
        self.monitor.add_sdr_state(stamp_to_ns(msg.header.stamp), int(msg.type), float(msg.jammer_to_signal_db),
                                   float(msg.jammer_to_noise_db))
        return None

    # ------------------------------------------------------------------ model file
    def _load_model(self) -> None:
        path = self.params.cn0_model_file
        if not path:
            return
        if not os.path.exists(path):
            self.get_logger().warn(f'cn0_model_file {path!r} does not exist: the C/N0 model is learned from scratch')
            return
        try:
            self.monitor.cn0_models = Cn0Models.load(path, self.monitor.params.cn0_model)
            self.get_logger().info(f'C/N0 model loaded from {path!r}')
        except (OSError, ValueError) as err:
            self.get_logger().error(f'cn0_model_file {path!r} not loaded ({err}): learned from scratch')

    def destroy_node(self) -> None:
        if self.params.save_cn0_model:
            try:
                self.monitor.cn0_models.save(self.params.cn0_model_file)
            except OSError as err:
                self.get_logger().error(f'C/N0 model not saved to {self.params.cn0_model_file!r}: {err}')
        super().destroy_node()

    # ------------------------------------------------------------------ diagnostics
    def accounting(self) -> dict[str, object]:
        """Counters of the node and the monitor; ``accounting_ok``: every input message adds up
        (received == rejected + processed, per kind)."""
        values: dict[str, object] = dict(sorted(self.counts.items()))
        values.update({f'rejected.{k}': v for k, v in sorted(self.reasons.items())})
        values.update({f'dropped_satellites.{k}': v for k, v in sorted(self.dropped_satellites.items())})
        values.update({f'monitor.{k}': v for k, v in self.monitor.counts.items()})
        values['monitor.held_inputs'] = self.monitor.held_inputs  # side inputs stamped after the latest epoch
        values.update({f'clock.{k}': v for k, v in self.monitor.clock.counts.items()})
        values['accounting_ok'] = all(self.counts[f'{k}_received'] == self.counts[f'{k}_rejected']
                                      + self.counts[f'{k}_processed'] for k in KINDS)
        values.update(self.health.values())
        return values

    def diagnostics(self, stamp_ns: int) -> DiagnosticArray:
        """The /diagnostics message at an accepted GNSS stamp (levels in the module docstring)."""
        p = self.params
        values = self.accounting()
        faults = self.counts['core_exceptions'] + self.health.callback_errors_total()
        new_faults, self._faults_at_report = faults - self._faults_at_report, faults
        received = sum(self.counts[f'{k}_received'] for k in KINDS)
        w = self._window.update(stamp_ns, {'received': received, 'lost': self.health.lost_total(),
                                           'rejected': sum(self.counts[f'{k}_rejected'] for k in KINDS)})
        last = self._last
        if last is not None:
            values['spoofing_state'] = int(last.spoofing_state)
            values['jamming_state'] = int(last.jamming_state)
            values['jammer_to_signal_db'] = float(last.jammer_to_signal_db)
        if not values['accounting_ok']:
            level, text = ERROR, 'input accounting does not add up'
        elif new_faults:
            level, text = ERROR, f'{new_faults} core or handler exceptions since the last report'
        else:
            alarms = []
            if last is not None and last.spoofing_state == STATE_DETECTED:
                names = sorted({t.name for t in last.tests if t.decision >= 2 and t.category != 1})
                alarms.append(f'spoofing DETECTED ({", ".join(names)})')
            if last is not None and last.jamming_state == STATE_DETECTED:
                alarms.append(f'jamming DETECTED (J/S {last.jammer_to_signal_db:.1f} dB)')
            alarms += degraded_inputs([('inputs rejected', w['rejected'], w['received'])], p.warn_rejected_fraction)
            alarms += degraded_inputs([('messages lost', w['lost'], w['received'] + w['lost'])], p.warn_lost_fraction)
            level, text = (WARN, '; '.join(alarms)) if alarms else (OK, 'monitoring')
        return diagnostic_array(stamp_ns, 'gnss_integrity', p.hardware_id, level, text, values)

    def _publish_stale(self, silent_s: float) -> None:
        self.diag_pub.publish(diagnostic_array(
            self.get_clock().now().nanoseconds, 'gnss_integrity', self.params.hardware_id, STALE,
            f'no input for {silent_s:.1f} s', self.accounting()))


def main(argv=None) -> int:
    return run_node(GnssIntegrityNode, executable='gnss_integrity_node', params_cls=IntegrityNodeParams,
                    topics=TOPICS, summary='GNSS jamming and spoofing detection from any receiver.', argv=argv)
