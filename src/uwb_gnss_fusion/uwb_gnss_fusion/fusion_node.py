"""ROS node of the GNSS/UWB fusion: /gnss/measurements, /uwb/ranges, /rfi/jammer_state, /gnss/integrity -> odometry.

The node only plumbs. It declares the parameters (one frozen dataclass, :class:`FusionNodeParams`,
documented for users in config/fusion.yaml), converts messages to the ``gnss_common.observations``
dataclasses (:mod:`rfi_node_common.conversions`), offers them to the admission
(:class:`.input_admission.InputAdmission`: stamps, duplicates, the re-ordering window, restarts), which
releases them in stamp order to the core (:class:`.fusion_core.FusionCore`: the tightly-coupled cubature
Kalman filter of Cao et al., :class:`.fusion_filter.FusionFilter`, with the spoofing response and the SPP
reference), and publishes what the core returns; /diagnostics comes from :mod:`.fusion_diagnostics`. Each
GNSS epoch or UWB range is one predict-to-stamp + update of the filter and gives one /fusion/status;
/fusion/odometry and /fusion/fix follow whenever the filter is initialised.

Time. All time is message time (``header.stamp``, integer ns); no estimate depends on a clock, so a bag
replayed at any speed gives identical outputs. Buffered input is processed at a replay's end
(:meth:`FusionNode.end_of_input`), when no input at all has arrived for ``idle_flush_s`` of wall time (a
steady-clock timer; ``idle_flush_s`` 0: never), and when the node is destroyed while its context can
still publish.

Input checks. Every input is subscribed raw by :func:`rfi_node_common.inputs.subscribe_input`
(reliable or best-effort publishers; ``qos_overrides.<topic>.subscription.*`` parameters; arrivals and
lost messages counted as ``input.<topic>.*``; a handler that raises is counted, not fatal). The node
rejects and counts bytes that rclpy cannot deserialise (``malformed_message``), a frame_id that is not
the earth / map frame (``gnss_frame_id``, ``uwb_frame_id``), an epoch whose satellites have no state
(``no_satellite_states``), and what :mod:`rfi_node_common.message_checks` finds implausible (a UWB range with
a bad 1-sigma or anchor, not finite, negative or outside 1 mm - 10 km is rejected by reason; a satellite dropped
from its epoch); /rfi/jammer_state by :func:`.input_admission.admit_jammer_state` (``type`` NONE clears the J/S;
a bad J/S is counted and ignored); stamps, duplicates and lateness by :class:`.input_admission.InputAdmission`.

Outputs (contents: :mod:`.output_messages`): /fusion/status (one per processed GNSS epoch or UWB
range), /fusion/odometry and /fusion/fix (only while the filter is initialised and its state finite),
/fusion/local_odometry (``map_frame_id`` -> ``base_frame_id``), /fusion/datum (latched, once), and
/diagnostics every ``diagnostics_period_s`` of stamp time (:mod:`.fusion_diagnostics`; ``hardware_id``
the parameter). When no input has arrived for ``input_timeout_s`` of wall time, a STALE status ("no
input for N s", with the counters) is published instead, stamped with the node clock's now: the only
use of the wall clock besides ``idle_flush_s``. Drawn topics (issue 30: /fusion/path, /fusion/markers,
/fusion/satellites), only while subscribed: :mod:`.view_topics`.

Parameters settable while running (``ros2 param set``): see :class:`FusionNodeParams`; a change is
validated as at start (:class:`rfi_node_common.params.RuntimeParameters`) and applied before the
re-ordering buffer next releases a message to the core (:meth:`FusionNode.apply_parameter_changes`).
A core exception on an input is counted, logged and reported as ERROR (:mod:`.fusion_core`).
"""

from __future__ import annotations

import math
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import NavSatFix

from gnss_common import multilateration
from gnss_common.observations import GnssEpoch, UwbRangeMeasurement
from rfi_msgs.msg import FusionStatus, GnssIntegrity, GnssMeasurementArray, JammerState, UwbRange
from rfi_node_common.conversions import decode_uwb_range_cdr, msg_to_observation, msg_to_uwb
from rfi_node_common.diagnostics import STALE, StampTimer, diagnostic_array
from rfi_node_common.inputs import InputHealth, StaleInputWatch, subscribe_input
from rfi_node_common.main import run_node
from rfi_node_common.message_checks import checked_satellites, uwb_range_reason
from rfi_node_common.params import RuntimeParameters, changed_names, declare
from rfi_node_common.qos import DATA_QOS, DIAGNOSTICS_QOS, LATCHED_QOS
from rfi_node_common.stamps import stamp_to_ns
from uwb_gnss_fusion import ckf_kernels, fusion_output, local_frame
from uwb_gnss_fusion import output_messages as msgs
from uwb_gnss_fusion.fusion_core import FusionCore
from uwb_gnss_fusion.fusion_diagnostics import MIRROR_WARNING, FusionDiagnostics, accounting
from uwb_gnss_fusion.fusion_filter import FRAME_EARTH, FRAME_MAP, FusionOutput
from uwb_gnss_fusion.fusion_node_params import TOPICS, FusionNodeParams
from uwb_gnss_fusion.fusion_output import all_finite
from uwb_gnss_fusion.input_admission import InputAdmission, Item, admit_jammer_state, jammer_rejection_text
from uwb_gnss_fusion.integrity_policy import verdict_of
from uwb_gnss_fusion.local_frame import LocalFrame, LocalSolution
from uwb_gnss_fusion.view_topics import FusionView

JAMMER_TYPES = frozenset((JammerState.NONE, JammerState.CW, JammerState.CHIRP, JammerState.WIDEBAND,
                          JammerState.UNKNOWN))
"""The ``type`` constants of rfi_msgs/JammerState; any other value is rejected (``jammer_state_unknown_type``)."""
ORIENTATION_UNKNOWN_VARIANCE_RAD2 = msgs.ORIENTATION_UNKNOWN_VARIANCE_RAD2
"""Re-exported: the orientation variance of the node's Odometry (:mod:`.output_messages`)."""


class FusionNode(Node):
    """Thin node around :class:`FusionCore` (see module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__('uwb_gnss_fusion', **kwargs)
        self.params = declare(self, FusionNodeParams)
        p = self.params
        self.runtime = RuntimeParameters(self, p)
        self.local_frame = LocalFrame(tuple(p.datum) if p.local_origin == 'datum' else None)
        self._datum_published = False
        self.diag = FusionDiagnostics(p.diagnostics_window_s)
        self.admission = InputAdmission(p.reorder_window_s, p.reorder_window_max_s, p.max_stamp_jump_s,
                                        p.stamp_jump_confirmations, self._process, lambda: self.core.restart(),
                                        self._log, self._before_release)
        self.counts = self.admission.counts
        self.reasons = self.admission.reasons
        self.core = FusionCore(p, self.counts, self.reasons, self._log)
        self._diag_timer = StampTimer(p.diagnostics_period_s)
        self._uwb_core_frames = {p.earth_frame_id: FRAME_EARTH, p.map_frame_id: FRAME_MAP}
        self._fix_frames = {FRAME_EARTH: p.earth_frame_id, FRAME_MAP: p.map_frame_id}
        self.odom_pub = self.create_publisher(Odometry, 'fusion/odometry', DATA_QOS)
        self.fix_pub = self.create_publisher(NavSatFix, 'fusion/fix', DATA_QOS)
        self.local_odom_pub = self.create_publisher(Odometry, 'fusion/local_odometry', DATA_QOS)
        self.datum_pub = self.create_publisher(NavSatFix, 'fusion/datum', LATCHED_QOS)
        self.status_pub = self.create_publisher(FusionStatus, 'fusion/status', DATA_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self.view = FusionView(self, p, self.local_frame)   # path and markers: published only while subscribed
        self._last_solution: LocalSolution | None = None
        # compile before subscribing: the node appears when it can keep up
        for module in (ckf_kernels, fusion_output, local_frame, multilateration):
            module.warm_up()
        # created after the compilation, so that its silence clock starts when the node can listen
        self.health = InputHealth()
        # Every input is taken raw and deserialised here: bytes that cannot be deserialised are then
        # received and counted (malformed_message); a typed subscription would lose them unseen. The
        # ranges (20 Hz per anchor) are decoded by conversions.decode_uwb_range_cdr, not by rclpy's
        # deserialisation (about 10x cheaper); anything it cannot decode goes through rclpy.
        for cls, topic, handler in ((GnssMeasurementArray, 'gnss/measurements', self.on_gnss_raw),
                                    (UwbRange, 'uwb/ranges', self.on_uwb_raw),
                                    (JammerState, 'rfi/jammer_state', self.on_jammer_raw),
                                    (GnssIntegrity, 'gnss/integrity', self.on_integrity_raw)):
            subscribe_input(self, cls, topic, handler, self.health, raw=True, warning_throttle_s=p.warning_throttle_s)
        self.stale_watch = StaleInputWatch(self, self.health, p.input_timeout_s, self._publish_stale)
        self.idle_flush_timer = None
        if p.idle_flush_s > 0:
            self.idle_flush_timer = self.create_timer(p.idle_flush_s / 4.0, self.flush_if_idle,
                                                      clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _log(self, text: str, level: str) -> None:
        """The core's and the admission's messages; 'error' and 'warn_throttled' at most once per
        ``warning_throttle_s`` (one throttle each: rclpy throttles per call site)."""
        if level == 'error':
            self.get_logger().error(text, throttle_duration_sec=self.params.warning_throttle_s)
        elif level == 'warn_throttled':
            self.get_logger().warn(text, throttle_duration_sec=self.params.warning_throttle_s)
        else:
            getattr(self.get_logger(), level)(text)

    # ------------------------------------------------------------------ callbacks
    def _deserialize(self, raw: bytes, cls: Any, kind: str) -> Any:
        """``raw`` as a ``cls`` message, or None after counting it received and rejected
        (``malformed_message``) when rclpy cannot deserialise it."""
        try:
            return deserialize_message(raw, cls)
        except Exception as err:  # rclpy raises RMWError (and may raise others) on malformed bytes
            self.counts[f'{kind}_received'] += 1
            text = str(err).splitlines()[0] if str(err) else ''
            self.admission.reject(kind, 'malformed_message', f'{kind} message of {len(raw)} bytes cannot be '
                                  f'deserialised ({type(err).__name__}: {text})')
            self._report()
            return None

    def on_gnss_raw(self, raw: bytes) -> None:
        self._on_raw(raw, GnssMeasurementArray, 'gnss', self.on_gnss)

    def on_jammer_raw(self, raw: bytes) -> None:
        self._on_raw(raw, JammerState, 'jammer', self.on_jammer)

    def on_integrity_raw(self, raw: bytes) -> None:
        self._on_raw(raw, GnssIntegrity, 'integrity', self.on_integrity)

    def _on_raw(self, raw: bytes, cls: Any, kind: str, handler: Any) -> None:
        msg = self._deserialize(raw, cls, kind)
        if msg is not None:
            handler(msg)

    def on_integrity(self, msg: GnssIntegrity) -> None:
        """A /gnss/integrity verdict: buffered in stamp order like every input (integrity_policy)."""
        self.counts['integrity_received'] += 1
        verdict, reason = verdict_of(msg)
        if verdict is None:
            self.admission.reject('integrity', str(reason),
                                  f'GnssIntegrity at {stamp_to_ns(msg.header.stamp)} ns ignored')
        else:
            self.admission.offer(Item(verdict.stamp_ns, 'integrity', verdict))
        self._report()

    def on_gnss(self, msg: GnssMeasurementArray) -> None:
        stamp_ns = stamp_to_ns(msg.header.stamp)
        self.counts['gnss_received'] += 1
        self.counts['satellites_received'] += len(msg.measurements)
        if msg.header.frame_id != self.params.earth_frame_id:
            self.admission.reject('gnss', 'gnss_frame_id', f'GNSS frame_id {msg.header.frame_id!r} is not '
                                  f'{self.params.earth_frame_id!r}')
            self._report()
            return
        # Field by field (not msg_to_epoch, which raises on a duplicate satellite: the core drops and counts
        # those, duplicate_svid); satellites with impossible values are dropped here (message_checks)
        observations, dropped, stateless = checked_satellites([msg_to_observation(m) for m in msg.measurements])
        self.counts['satellites_without_state'] += stateless
        epoch = GnssEpoch(stamp_ns=stamp_ns, gps_week=int(msg.gps_week),
                          gps_time_of_week_s=float(msg.gps_time_of_week_s), observations=tuple(observations))
        if stateless and not observations and not dropped:
            self.admission.reject('gnss', 'no_satellite_states', f'GNSS epoch {stamp_ns} ns: no satellite has a '
                                  'state (no ephemeris): not applied')
        elif self.admission.offer(Item(stamp_ns, 'gnss', epoch, sum(dropped.values())), ('gnss', stamp_ns, '')) \
                and dropped:
            self.reasons.update(dropped)
            self.get_logger().warn(f'GNSS epoch {stamp_ns} ns: satellites dropped ({", ".join(sorted(dropped))})',
                                   throttle_duration_sec=self.params.warning_throttle_s)
        self._report()

    def on_uwb(self, msg: UwbRange) -> None:
        """A UWB range as a message object (the subscription is raw: :meth:`on_uwb_raw`)."""
        frame = msg.header.frame_id
        core_frame = self._uwb_core_frames.get(frame)
        self._accept_uwb(stamp_to_ns(msg.header.stamp), frame,
                         None if core_frame is None else msg_to_uwb(msg, frame_id=core_frame))

    def on_uwb_raw(self, raw: bytes) -> None:
        """A serialised UWB range: decoded without rclpy (conversions.decode_uwb_range_cdr), or by
        rclpy when that decoder declines (not little-endian CDR, malformed); bytes that rclpy cannot
        deserialise either are counted as received and rejected (``malformed_message``)."""
        decoded = decode_uwb_range_cdr(raw, self._uwb_core_frames)
        if decoded is not None:
            self._accept_uwb(*decoded)
            return
        msg = self._deserialize(raw, UwbRange, 'uwb')
        if msg is not None:
            self.on_uwb(msg)

    def _accept_uwb(self, stamp_ns: int, frame: str, meas: UwbRangeMeasurement | None) -> None:
        """Count a range, check it and buffer it; ``meas`` None: its frame_id is not a core frame."""
        self.counts['uwb_received'] += 1
        if meas is None:
            self.admission.reject('uwb', 'uwb_frame_id', f'UWB frame_id {frame!r} is neither '
                                  f'{self.params.earth_frame_id!r} nor {self.params.map_frame_id!r}')
        else:
            key = ('uwb', stamp_ns, meas.anchor_id)
            reason = None if self.admission.seen(key) else uwb_range_reason(meas)
            if reason is not None:
                self.admission.reject('uwb', reason, f'UWB range from anchor {meas.anchor_id!r} at {stamp_ns} ns: '
                                      f'std {meas.range_std_m} m, anchor {meas.anchor_position_m.tolist()} m')
            else:
                self.admission.offer(Item(stamp_ns, 'uwb', meas), key)
        self._report()

    def on_jammer(self, msg: JammerState) -> None:
        stamp_ns = stamp_to_ns(msg.header.stamp)
        self.counts['jammer_received'] += 1
        js, reason = admit_jammer_state(msg.type, msg.jammer_to_signal_db, JammerState.NONE, JAMMER_TYPES)
        if js is not None:
            self.admission.offer(Item(stamp_ns, 'jammer', js))
        else:
            self.admission.reject('jammer', str(reason), jammer_rejection_text(str(reason), msg.type,
                                                                               float(msg.jammer_to_signal_db)))
        self._report()

    # ------------------------------------------------------------------ admission and core
    buffered = property(lambda self: self.admission.buffered, doc='Messages in the re-ordering buffer, per kind.')
    reorder_window_s = property(lambda self: self.admission.reorder_window_s, doc='The re-ordering window now, s.')
    filter = property(lambda self: self.core.filter, doc="The core's filter (:class:`.fusion_filter.FusionFilter`).")

    def end_of_input(self) -> int:
        """No more input will come (a replay's end): process every buffered message now, in stamp order.
        Returns how many; a message arriving afterwards older than the last one processed is rejected as late."""
        return self.admission.flush('end_of_input_flushes')

    def flush(self) -> int:
        """The same as :meth:`end_of_input`."""
        return self.end_of_input()

    def flush_if_idle(self) -> int:
        """The idle timer (steady clock): process the buffer if no input has arrived for ``idle_flush_s``.
        Returns how many messages were processed (0 if not idle or nothing buffered)."""
        if not any(self.admission.buffered.values()) or self.health.silent_for_s() < self.params.idle_flush_s:
            return 0
        return self.admission.flush('idle_flushes')

    def destroy_node(self) -> None:
        """Process what is still buffered if the context can still publish, then destroy the node."""
        if getattr(self, 'admission', None) is not None and self.context.ok():
            try:
                self.end_of_input()
            except Exception as err:  # shutting down: never fail here
                self.get_logger().error(f'buffered input not processed at shutdown: {type(err).__name__}: {err}')
        super().destroy_node()

    def _before_release(self) -> None:
        if self.runtime.pending:
            self.apply_parameter_changes()

    def _process(self, item: Item) -> None:
        out = self.core.process(item)
        if out is None:
            return
        self.diag.count_outcome(out, self.counts)
        try:
            self._publish(out, item.stamp_ns)
        except Exception as err:  # e.g. the context is shutting down: the next message still gets its turn
            self.counts['publish_exceptions'] += 1
            self.get_logger().error(f'publishing the output of a {item.kind} message at {item.stamp_ns} ns failed: '
                                    f'{type(err).__name__}: {err}',
                                    throttle_duration_sec=self.params.warning_throttle_s)
        p, state = self.params, self.core.filter.state
        self.view.after_input_logged(self.counts, p.warning_throttle_s, item.stamp_ns, item.kind, item.payload, out,
                                     self._last_solution, state.last_used_satellites)

    def apply_parameter_changes(self) -> bool:
        """Apply a change of the settable parameters (validated when it was set, :class:`RuntimeParameters`)
        now: called between two messages (before the re-ordering buffer releases any to the core, and
        before a diagnostics report). The core reads the settable filter parameters at each update, so
        the new values hold from the next message on. Returns whether a change was applied."""
        return self.runtime.apply_pending(self._apply_parameters)

    def _apply_parameters(self, old: FusionNodeParams, new: FusionNodeParams) -> None:
        self.params = new
        self.core.set_params(new)
        self.diag.count_window.window_ns = int(round(new.diagnostics_window_s * 1e9))
        self.counts['parameter_changes'] += 1
        self.get_logger().info('parameters changed: ' + ', '.join(
            f'{name} = {getattr(new, name)!r}' for name in changed_names(old, new)))

    def rejection_reasons(self) -> dict[str, int]:
        """Cumulative reasons and counts of the node and of the core, merged."""
        return self.core.rejection_reasons()

    # ------------------------------------------------------------------ outputs
    def _publish(self, out: FusionOutput, stamp_ns: int) -> None:
        self.diag.note_output(stamp_ns)
        frame = self._fix_frames.get(out.frame_id, out.frame_id)
        reasons, lists = self.core.status_reasons(self.counts['time_jump_restarts'])
        self.status_pub.publish(msgs.status_msg(out, stamp_ns, frame, reasons, lists, self.core.exclusion.scope,
                                                self.core.excluded_now))
        if not out.initialized:
            return
        if not out.is_finite():
            self.counts['nonfinite_estimates_suppressed'] += 1
            return
        self.odom_pub.publish(msgs.odometry_msg(out, frame, self.params.child_frame_id))
        if out.frame_id == FRAME_EARTH:
            fix = msgs.fix_msg(out, self.params.child_frame_id)
            if not (math.isfinite(fix.latitude) and math.isfinite(fix.longitude) and math.isfinite(fix.altitude)
                    and all_finite(fix.position_covariance)):
                self.counts['nonfinite_estimates_suppressed'] += 1
                return
            self.fix_pub.publish(fix)
        self._publish_local(out)

    def _publish_local(self, out: FusionOutput) -> None:
        """fusion/local_odometry (and, once, fusion/datum) from a published, finite solution: ECEF solutions
        in the local ENU frame, whose origin is the datum parameter or the first of them (``local_origin``);
        a map-frame solution (UWB-only) is in it already. Then the antenna estimate is moved to base_link
        (:meth:`LocalFrame.base_link_solution`)."""
        p = self.params
        earth = out.frame_id == FRAME_EARTH
        if earth and not self.local_frame.defined:
            self.local_frame.set_origin_ecef(out.position_m)
        if earth and not self._datum_published:
            assert self.local_frame.origin_geodetic is not None
            self.datum_pub.publish(msgs.datum_msg(out.stamp_ns, p.map_frame_id, self.local_frame.origin_geodetic))
            self._datum_published = True
        sol = self.local_frame.base_link_solution(out.stamp_ns, out.position_m, out.velocity_mps, out.covariance_pv,
                                                  earth, p.antenna_position_m, p.heading_source,
                                                  p.heading_min_speed_mps)
        self.local_odom_pub.publish(msgs.local_odometry_msg(sol, p.map_frame_id, p.base_frame_id))
        self._last_solution = sol

    # ------------------------------------------------------------------ diagnostics
    def accounting(self) -> dict[str, object]:
        """Counters of the node, the core and the inputs, and whether every input adds up
        (:func:`.fusion_diagnostics.accounting`)."""
        return accounting(self.admission, self.core, self.health.values())

    def diagnostics(self, stamp_ns: int) -> DiagnosticArray:
        """The /diagnostics message (levels: :meth:`.fusion_diagnostics.FusionDiagnostics.report`)."""
        if self.runtime.pending:
            self.apply_parameter_changes()
        p = self.params
        values = self.accounting()
        received = sum(self.health.counts[f'{t}.received'] for t in self.health.topics)
        level, text, warn_mirror = self.diag.report(
            stamp_ns, p, values, self.counts, self.core,
            (received, self.health.lost_total(), self.health.callback_errors_total()), self.runtime.changes_refused)
        if warn_mirror:
            self.get_logger().warning(MIRROR_WARNING)
        return diagnostic_array(stamp_ns, 'uwb_gnss_fusion', p.hardware_id, level, text, values)

    def _report(self) -> None:
        """Publish /diagnostics when due, timed by the latest accepted stamp (never by a rejected one)."""
        latest = self.admission.latest_ns
        if latest is not None and self._diag_timer.due(latest):
            self.diag_pub.publish(self.diagnostics(latest))

    def _publish_stale(self, silent_s: float) -> None:
        """No input for ``silent_s`` of wall time: STALE, stamped with the node clock's now (StaleInputWatch)."""
        self.diag_pub.publish(diagnostic_array(
            self.get_clock().now().nanoseconds, 'uwb_gnss_fusion', self.params.hardware_id, STALE,
            f'no input for {silent_s:.1f} s', self.accounting()))


def main(argv=None) -> int:
    return run_node(FusionNode, executable='fusion_node', params_cls=FusionNodeParams, topics=TOPICS,
                    summary='Tightly-coupled GNSS/UWB cubature Kalman filter that survives jamming.', argv=argv)
