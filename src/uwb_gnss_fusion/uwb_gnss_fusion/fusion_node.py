"""ROS node of the GNSS/UWB fusion: /gnss/measurements, /uwb/ranges, /rfi/jammer_state -> odometry.

The node is thin. It declares the parameters (one frozen dataclass, :class:`FusionNodeParams`,
documented for users in config/fusion.yaml), converts messages to the ``gnss_common.observations``
dataclasses (:mod:`rfi_node_common.conversions`), puts them in stamp order, hands them to the pure
core (:class:`uwb_gnss_fusion.fusion_filter.FusionFilter`, the tightly-coupled cubature Kalman
filter of Cao et al.) and publishes what the core returns. Each GNSS epoch or UWB range is one
predict-to-stamp + update of the core and gives one /fusion/status; /fusion/odometry and
/fusion/fix follow whenever the filter is initialised.

Time. All time is message time (``header.stamp``, integer ns); no estimate depends on a clock, so
a bag replayed at any speed gives identical outputs. Inputs pass through a re-ordering buffer
(:class:`uwb_gnss_fusion.fusion_filter.ReorderBuffer`): a message is processed once a message
stamped the window later has arrived, so measurements that arrive up to that much out of order are
applied in stamp order (the outputs lag by the window). At equal stamps a /gnss/integrity verdict or a
/rfi/jammer_state goes before the measurements: gnss_integrity's verdict of an epoch carries the epoch's
stamp and is computed from it, so it arrives after it, and within the window it still decides whether
that epoch is fused (bags/spoofed: the epoch of the first detection is excluded, not fused and then
excluded). Later arrivals are rejected and counted
(``late_beyond_reorder_window``). Stamps pass :class:`rfi_node_common.input_checks.StampGate`
first: a stamp more than ``max_stamp_jump_s`` away from the latest accepted one is rejected
(``stamp_far_future`` / ``stamp_far_past``) unless ``stamp_jump_confirmations`` messages in a row
agree on the jump (a clock or bag restart): then the pending messages are processed and the filter
restarts (``time_jump_restarts``). Stamps <= 0 are rejected (``stamp_not_positive``: an unset header).

Re-ordering window: latency against late rejections. The window starts at ``reorder_window_s``
(0.1 s: a GNSS receiver delivers its epoch 50-100 ms after the measurement time) and every output
lags the newest input by it. On a loaded computer the inputs also arrive late relative to each
other: the executor takes one message per topic and turn, so a UWB backlog (60 ranges/s) falls
behind the GNSS epochs by about as long as the node was starved (566 ranges of one 1x replay through
separate processes came later than 0.1 s). So the window adapts: a late arrival is still rejected,
but the window grows to 1.5 times how late it was (``reorder_window_growths``), up to
``reorder_window_max_s`` (1 s of outputs lag at most; it never shrinks while the node runs; a
message later than that maximum leaves the window as it is: no window would have taken it).
Measured with the node as its own process fed 20 s of bags/default at 1x and stopped twice (SIGSTOP)
to mimic a starved CPU: the ranges came up to 0.9 times the stop late; stops of 0.6 s: a fixed
0.1 s window rejected 44 ranges, the adaptive one 10 (in the first stop only); stops of 1.5 s: 140
and 40 (window at its 1 s maximum). With in-order input (a bag replayed in one process) nothing is
late and the window stays where it started; the order of processing never depends on the window,
only the lag of the outputs does. ``reorder_window_max_s`` <= ``reorder_window_s`` keeps the
window fixed.

End of input. What the buffer holds is processed (in stamp order, exactly as a newer message would
have released it) when :meth:`FusionNode.end_of_input` is called (a replay's end), when no input at
all has arrived for ``idle_flush_s`` of wall time (a steady-clock timer; a node running as its own
process at the end of a bag or when its sensors stop; ``idle_flush_s`` 0: never), and when the node
is destroyed while its context can still publish. This changes only when buffered messages are
processed, never their order or the results; a message that arrives afterwards with a stamp older
than the last one processed is rejected as late, as any late message.

Input checks. Every input is subscribed by :func:`rfi_node_common.inputs.subscribe_input` (the
publishers' reliability: reliable with play, best effort once a sensor driver is there, so both are
accepted; ``qos_overrides.<topic>.subscription.*``
parameters; arrivals and lost messages counted as ``input.<topic>.*``; a handler that raises is
counted, not fatal). Before the buffer the node rejects and counts, besides the stamps above:

* bytes that rclpy cannot deserialise (``malformed_message``; every input is subscribed raw and
  deserialised by the node, so that such a message is received and counted, not lost unseen);
* a frame_id that is not the earth / map frame (``gnss_frame_id``, ``uwb_frame_id``);
* an exact duplicate: a GNSS epoch with the stamp of an epoch already accepted
  (``duplicate_gnss_epoch``), a UWB range with the stamp and anchor id of a range already accepted
  (``duplicate_uwb_range``);
* a UWB range whose ``range_std_m`` is not NaN ("use uwb_range_std_m") and not finite, > 0 and
  plausible (``invalid_range_std``), or whose anchor position is off the Earth / beyond any local
  frame (``nonphysical_anchor_position``); per satellite of an epoch (the satellite is dropped, the
  epoch goes on): ``nonphysical_cn0``, ``invalid_measurement_std``, ``nonphysical_satellite_state``,
  ``nonphysical_atmospheric_delay`` (:mod:`uwb_gnss_fusion.message_checks` has the bounds). The core
  checks the rest (non-finite or impossible pseudoranges, satellite positions, ranges).

Jammer information. /rfi/jammer_state feeds ``JammerState.jammer_to_signal_db`` to the core's
measurement weighting (Cao et al., eq. 4), in stamp order with the measurements. A ``type`` that
is none of the message's constants is rejected (``jammer_state_unknown_type``). Then:

* ``type`` NONE: the monitor sees no interference; the J/S is cleared (weights from the reported
  C/N0 only), whatever ``jammer_to_signal_db`` holds.
* another type with a finite J/S in [-100, 150] dB: that J/S is used until it is older than
  ``jammer_info_timeout_s`` (core).
* another type with a NaN J/S (e.g. a monitor not yet converged): the message is ignored and
  counted (``jammer_state_nan``); the previous J/S stays until it times out. A non-finite (inf)
  or out-of-range J/S is counted as ``jammer_state_nonphysical`` and ignored likewise.

SPP. The core re-initialises after a divergence from a single-point fix
(:class:`uwb_gnss_fusion.spp.SinglePointPositioner`, ``use_spp_reference``): the most recent valid
(RAIM-consistent) fix no older than ``reference_max_age_s``. The node keeps the GNSS epochs of that
window and solves them only when the core asks (``FusionFilter(reference_provider=...)``), newest
first until one is valid; a solved epoch is not solved again. The reference is the one an SPP run
on every epoch would have supplied (up to the solver's convergence tolerance, as its iteration
starts from the last valid fix), at a fraction of the cost: SPP is not published, and solving every
5 Hz epoch took about 15% of a replay. ``spp_valid`` / ``spp_invalid`` count the epochs solved.
The first initialisation is the core's own (robust snapshot fix of the first epoch with
``min_satellites_init`` satellites, or UWB multilateration from three anchors).

Outputs.

* /fusion/status (rfi_msgs/FusionStatus): one per processed GNSS epoch or UWB range, every
  field filled; ``header.stamp`` is the stamp of the measurement processed; ``rejection_reasons``
  / ``rejection_counts`` are the cumulative counts of the node (reasons above) and of the core
  (``fusion_filter`` reasons such as ``innovation_gate_pseudorange``, ``duplicate_svid``,
  ``negative_range``), sorted by reason.
* /fusion/odometry (nav_msgs/Odometry), only while the filter is initialised and its state is
  finite: ``header.frame_id`` ``earth_frame_id`` (ECEF) or ``map_frame_id`` (the anchors' local
  frame, UWB-only mode), ``child_frame_id`` the parameter; the estimated point is the GNSS antenna
  (the UWB tag is offset by ``uwb_lever_arm_m``). Orientation is not estimated: the quaternion is
  the identity and its covariance diagonal is :data:`ORIENTATION_UNKNOWN_VARIANCE_RAD2` (the
  ``robot_localization`` convention for an unobserved quantity: a large variance, no
  correlations). The twist holds the velocity with the axes of ``header.frame_id`` (with the
  identity orientation those are also the child frame's), angular velocity 0 with variance
  :data:`ORIENTATION_UNKNOWN_VARIANCE_RAD2`. Pose and twist covariances hold the filter's
  position and velocity blocks (the position-velocity correlation has no place in Odometry).
* /fusion/fix (sensor_msgs/NavSatFix), only in the earth frame and only while initialised with
  a finite state: WGS 84 latitude/longitude/ellipsoidal altitude of the antenna, ENU position
  covariance (row-major E, N, U), ``COVARIANCE_TYPE_KNOWN``, ``STATUS_FIX``, service GPS,
  ``header.frame_id`` = ``child_frame_id``. Nothing is published before the first
  initialisation or after a reset to uninitialised: a consumer must not read a NaN position as
  a fix, and ``STATUS_NO_FIX`` with NaN fields would be exactly that for a careless one. The loss
  is visible on /fusion/status (``initialized`` false) and /diagnostics (WARN).
* /diagnostics: every ``diagnostics_period_s`` of stamp time (timed by accepted stamps only), the
  node's counters, the core's counters (``filter.<reason>``), the subscriptions' counters
  (``input.<topic>.received`` / ``lost`` / ``middleware_lost`` / ``callback_errors``), the current
  ``reorder_window_s`` and ``accounting_ok``: for GNSS, UWB and jammer messages, received ==
  rejected by the node + processed + still buffered (lost messages never arrived: counted apart).
  ``hardware_id`` is the parameter (the receiver and UWB tag). Levels (:meth:`FusionNode.diagnostics`) from
  fractions over ``diagnostics_window_s`` of stamp time: ERROR when no valid solution is published although
  input was processed (except OK "starting" while the first GNSS fix waits, up to ten times
  ``divergence_fix_confirm_s``, for a second to confirm it), an estimate was suppressed, the accounting does
  not add up or the core / a handler raised since the last report; WARN when the inputs are degraded (more
  than ``warn_rejected_fraction`` rejected, ``warn_lost_fraction`` lost, a divergence, a J/S costing more than
  ``warn_cn0_loss_db`` of C/N0); else OK. When no input has arrived for ``input_timeout_s`` of wall time, a
  STALE status ("no input for N s", with the counters) is published instead, stamped with the node clock's
  now: the only use of the wall clock besides ``idle_flush_s``.
* /fusion/local_odometry (nav_msgs/Odometry): every published solution again, in the local ENU
  frame ``map_frame_id`` at ``base_frame_id`` (robot_localization's EKF input; origin, lever arm
  and the attitude assumption: :mod:`uwb_gnss_fusion.local_frame`, :meth:`FusionNode._publish_local`).
* /fusion/datum (sensor_msgs/NavSatFix, latched): the WGS 84 origin of ``map_frame_id``, once.

Parameters settable while running (``ros2 param set``): see :class:`FusionNodeParams`; a change is
validated as at start (:class:`rfi_node_common.params.RuntimeParameters`) and applied before the
re-ordering buffer next releases a message to the core (:meth:`FusionNode.apply_parameter_changes`).

A core exception on an input (it should not happen; the core counts bad input itself) is caught,
counted (``core_exception``), logged and reported as ERROR; the node keeps running.
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from dataclasses import dataclass
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import NavSatFix

from gnss_common import multilateration
from gnss_common.jamming_weights import effective_cn0_dbhz
from gnss_common.observations import GnssEpoch, UwbRangeMeasurement
from gnss_common.spp import SinglePointPositioner
from rfi_msgs.msg import FusionStatus, GnssIntegrity, GnssMeasurementArray, JammerState, UwbRange
from rfi_node_common.conversions import decode_uwb_range_cdr, msg_to_observation, msg_to_uwb
from rfi_node_common.diagnostics import (
    ERROR,
    OK,
    STALE,
    WARN,
    CountWindow,
    StampTimer,
    degraded_inputs,
    diagnostic_array,
    fraction,
)
from rfi_node_common.input_checks import STAMP_NOT_POSITIVE, StampGate
from rfi_node_common.inputs import InputHealth, StaleInputWatch, subscribe_input
from rfi_node_common.main import run_node
from rfi_node_common.params import RuntimeParameters, changed_names, declare
from rfi_node_common.qos import DATA_QOS, DIAGNOSTICS_QOS, LATCHED_QOS
from rfi_node_common.stamps import stamp_to_ns
from uwb_gnss_fusion import ckf_kernels, fusion_output, local_frame
from uwb_gnss_fusion.fusion_filter import (
    FRAME_EARTH,
    FRAME_MAP,
    FusionFilter,
    FusionOutput,
    ReorderBuffer,
)
from uwb_gnss_fusion.fusion_node_params import FusionNodeParams
from uwb_gnss_fusion.fusion_output import all_finite
from uwb_gnss_fusion.input_admission import DuplicateFilter, admit_jammer_state
from uwb_gnss_fusion.integrity_policy import integrity_jammer_to_signal, verdict_of
from uwb_gnss_fusion.local_frame import LocalFrame
from uwb_gnss_fusion.message_checks import satellite_reason, uwb_range_reason
from uwb_gnss_fusion.output_messages import (  # noqa: F401 (re-exported: the node's output contract)
    ORIENTATION_UNKNOWN_VARIANCE_RAD2,
    datum_msg,
    fix_msg,
    local_odometry_msg,
    odometry_msg,
    reason_lists,
    status_msg,
)
from uwb_gnss_fusion.reorder_buffer import widened_window_ns
from uwb_gnss_fusion.spoofing_response import SpoofingResponse
from uwb_gnss_fusion.spp_reference import SppReferenceCache

TOPICS = """topics:
  subscribes /gnss/measurements (rfi_msgs/GnssMeasurementArray), /uwb/ranges (rfi_msgs/UwbRange),
             /rfi/jammer_state (rfi_msgs/JammerState), /gnss/integrity (rfi_msgs/GnssIntegrity)
  publishes  /fusion/odometry (nav_msgs/Odometry, ECEF), /fusion/local_odometry (nav_msgs/Odometry, map ->
             base_link), /fusion/fix (sensor_msgs/NavSatFix), /fusion/datum (sensor_msgs/NavSatFix, latched: the
             origin of map), /fusion/status (rfi_msgs/FusionStatus), /diagnostics (diagnostic_msgs/DiagnosticArray)"""

JAMMER_TYPES = frozenset((JammerState.NONE, JammerState.CW, JammerState.CHIRP, JammerState.WIDEBAND,
                          JammerState.UNKNOWN))
"""The ``type`` constants of rfi_msgs/JammerState; any other value is rejected (``jammer_state_unknown_type``)."""

_NS = 1_000_000_000
KINDS = ('gnss', 'uwb', 'jammer', 'integrity')
"""Input kinds, as used in the counter names (``<kind>_received`` ...)."""

@dataclass(frozen=True)
class _Item:
    """One input waiting in the re-ordering buffer."""

    stamp_ns: int
    kind: str
    payload: Any
    dropped_satellites: int = 0


class FusionNode(Node):
    """Thin node around :class:`FusionFilter` (see module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__('uwb_gnss_fusion', **kwargs)
        self.params = declare(self, FusionNodeParams)
        self.runtime = RuntimeParameters(self, self.params)
        self.local_frame = LocalFrame(tuple(self.params.datum) if self.params.local_origin == 'datum' else None)
        self._datum_published = False
        self._count_window = CountWindow(self.params.diagnostics_window_s)
        self._ever_initialized = False
        self._mirror_warned = False   # the three-anchor warning is logged once
        self._first_output_ns: int | None = None   # stamp of the first status published
        self._last_js_db = math.nan
        self.spp = SinglePointPositioner()
        self.spp_cache = SppReferenceCache(self.spp, self.params.reference_max_age_s, self._count_spp)
        self.response = SpoofingResponse(self.params.integrity_readmit_clean_s, self.params.act_on_integrity,
                                         self.params.integrity_rollback_s)
        self.exclusion = self.response.exclusion
        self.filter = self._new_filter()
        self._sdr_js_ns: int | None = None  # stamp of the last SDR J/S processed (it takes precedence)
        self._excluded_now = 0  # satellites excluded from the epoch being published
        self.counts: Counter[str] = Counter({f'{k}_{what}': 0 for k in KINDS
                                             for what in ('received', 'rejected', 'processed')})
        for name in ('reorder_window_growths', 'idle_flushes', 'end_of_input_flushes', 'publish_exceptions',
                     'satellites_used', 'satellites_rejected', 'uwb_used', 'uwb_rejected_by_filter', 'divergences',
                     'nonfinite_estimates_suppressed', 'parameter_changes'):
            self.counts[name] = 0
        self.reasons: Counter[str] = Counter()
        self._retired_filter_counts: Counter[str] = Counter()
        self._buffer = ReorderBuffer(round(self.params.reorder_window_s * _NS))
        self._window_max_ns = round(self.params.reorder_window_max_s * _NS)
        self._buffered: Counter[str] = Counter()
        self._gate = StampGate(self.params.max_stamp_jump_s, self.params.stamp_jump_confirmations,
                               strictly_increasing=False)
        self._released_ns: int | None = None  # stamp of the last message released to the core
        self._seen = DuplicateFilter()  # exact duplicates: keys kept while a copy could still be buffered
        self._diag_timer = StampTimer(self.params.diagnostics_period_s)
        self._at_last_report = {'rejections': 0, 'faults': 0, 'handler_errors': 0, 'lost': 0}
        self._reasons_cache: tuple[tuple, dict[str, int], tuple[list[str], list[int]]] | None = None
        self._uwb_core_frames = {self.params.earth_frame_id: FRAME_EARTH, self.params.map_frame_id: FRAME_MAP}
        self._fix_frames = {FRAME_EARTH: self.params.earth_frame_id, FRAME_MAP: self.params.map_frame_id}
        self.odom_pub = self.create_publisher(Odometry, 'fusion/odometry', DATA_QOS)
        self.fix_pub = self.create_publisher(NavSatFix, 'fusion/fix', DATA_QOS)
        self.local_odom_pub = self.create_publisher(Odometry, 'fusion/local_odometry', DATA_QOS)
        self.datum_pub = self.create_publisher(NavSatFix, 'fusion/datum', LATCHED_QOS)
        self.status_pub = self.create_publisher(FusionStatus, 'fusion/status', DATA_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        # compile before subscribing: the node appears when it can keep up
        ckf_kernels.warm_up()
        fusion_output.warm_up()
        local_frame.warm_up()
        multilateration.warm_up()
        # created after the compilation, so that its silence clock starts when the node can listen
        self.health = InputHealth()
        throttle = self.params.warning_throttle_s
        # Every input is taken raw and deserialised here: bytes that cannot be deserialised are then
        # received and counted (malformed_message); a typed subscription would lose them unseen.
        subscribe_input(self, GnssMeasurementArray, 'gnss/measurements', self.on_gnss_raw, self.health, raw=True,
                        warning_throttle_s=throttle)
        # the ranges (20 Hz per anchor) are decoded by conversions.decode_uwb_range_cdr, not by
        # rclpy's deserialisation (about 10x cheaper); anything it cannot decode goes through rclpy
        subscribe_input(self, UwbRange, 'uwb/ranges', self.on_uwb_raw, self.health, raw=True,
                        warning_throttle_s=throttle)
        subscribe_input(self, JammerState, 'rfi/jammer_state', self.on_jammer_raw, self.health, raw=True,
                        warning_throttle_s=throttle)
        subscribe_input(self, GnssIntegrity, 'gnss/integrity', self.on_integrity_raw, self.health, raw=True,
                        warning_throttle_s=throttle)
        self.stale_watch = StaleInputWatch(self, self.health, self.params.input_timeout_s, self._publish_stale)
        self.idle_flush_timer = None
        if self.params.idle_flush_s > 0:
            self.idle_flush_timer = self.create_timer(self.params.idle_flush_s / 4.0, self.flush_if_idle,
                                                      clock=Clock(clock_type=ClockType.STEADY_TIME))

    # ------------------------------------------------------------------ callbacks
    def _deserialize(self, raw: bytes, cls: Any, kind: str) -> Any:
        """``raw`` as a ``cls`` message, or None after counting it received and rejected
        (``malformed_message``) when rclpy cannot deserialise it."""
        try:
            return deserialize_message(raw, cls)
        except Exception as err:  # rclpy raises RMWError (and may raise others) on malformed bytes
            self.counts[f'{kind}_received'] += 1
            text = str(err).splitlines()[0] if str(err) else ''
            self._reject(kind, 'malformed_message', f'{kind} message of {len(raw)} bytes cannot be deserialised '
                         f'({type(err).__name__}: {text})')
            self._report()
            return None

    def on_gnss_raw(self, raw: bytes) -> None:
        msg = self._deserialize(raw, GnssMeasurementArray, 'gnss')
        if msg is not None:
            self.on_gnss(msg)

    def on_jammer_raw(self, raw: bytes) -> None:
        msg = self._deserialize(raw, JammerState, 'jammer')
        if msg is not None:
            self.on_jammer(msg)

    def on_integrity_raw(self, raw: bytes) -> None:
        msg = self._deserialize(raw, GnssIntegrity, 'integrity')
        if msg is not None:
            self.on_integrity(msg)

    def on_integrity(self, msg: GnssIntegrity) -> None:
        """A /gnss/integrity verdict: buffered in stamp order like every input (integrity_policy)."""
        self.counts['integrity_received'] += 1
        verdict, reason = verdict_of(msg)
        if verdict is None:
            self._reject('integrity', str(reason), f'GnssIntegrity at {stamp_to_ns(msg.header.stamp)} ns ignored')
        else:
            self._enqueue(_Item(verdict.stamp_ns, 'integrity', verdict))
        self._report()

    def on_gnss(self, msg: GnssMeasurementArray) -> None:
        stamp_ns = stamp_to_ns(msg.header.stamp)
        self.counts['gnss_received'] += 1
        self.counts['satellites_received'] += len(msg.measurements)
        if msg.header.frame_id != self.params.earth_frame_id:
            self._reject('gnss', 'gnss_frame_id', f'GNSS frame_id {msg.header.frame_id!r} is not '
                         f'{self.params.earth_frame_id!r}')
        else:
            # Built field by field (not msg_to_epoch, which raises on a duplicate satellite) so that the
            # core drops only the duplicated satellites and counts them (duplicate_svid). Satellites
            # with a value the core would apply although impossible are dropped here (message_checks).
            observations = []
            dropped: Counter[str] = Counter()
            stateless = 0
            for m in msg.measurements:
                obs = msg_to_observation(m)
                if not any(math.isfinite(float(v)) for v in obs.satellite_position_ecef_m):
                    # no ephemeris yet (a receiver stream without navigation data): expected, not a
                    # degraded input; counted apart, never applied
                    stateless += 1
                    continue
                reason = satellite_reason(obs)
                if reason is None:
                    observations.append(obs)
                else:
                    dropped[reason] += 1
            self.counts['satellites_without_state'] += stateless
            epoch = GnssEpoch(stamp_ns=stamp_ns, gps_week=int(msg.gps_week),
                              gps_time_of_week_s=float(msg.gps_time_of_week_s), observations=tuple(observations))
            if stateless and not observations and not dropped:
                self._reject('gnss', 'no_satellite_states', f'GNSS epoch {stamp_ns} ns: no satellite has a state '
                             '(no ephemeris): not applied')
                self._report()
                return
            if self._enqueue(_Item(stamp_ns, 'gnss', epoch, sum(dropped.values())), ('gnss', stamp_ns, '')) \
                    and dropped:
                self.reasons.update(dropped)
                self.get_logger().warn(
                    f'GNSS epoch {stamp_ns} ns: satellites dropped ({", ".join(sorted(dropped))})',
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
            self._reject('uwb', 'uwb_frame_id', f'UWB frame_id {frame!r} is neither '
                         f'{self.params.earth_frame_id!r} nor {self.params.map_frame_id!r}')
        else:
            key = ('uwb', stamp_ns, meas.anchor_id)
            reason = None if key in self._seen else uwb_range_reason(meas)
            if reason is not None:
                self._reject('uwb', reason, f'UWB range from anchor {meas.anchor_id!r} at {stamp_ns} ns: '
                             f'std {meas.range_std_m} m, anchor {meas.anchor_position_m.tolist()} m')
            else:
                self._enqueue(_Item(stamp_ns, 'uwb', meas), key)
        self._report()

    def on_jammer(self, msg: JammerState) -> None:
        stamp_ns = stamp_to_ns(msg.header.stamp)
        self.counts['jammer_received'] += 1
        js, reason = admit_jammer_state(msg.type, msg.jammer_to_signal_db, JammerState.NONE, JAMMER_TYPES)
        if js is not None:
            self._enqueue(_Item(stamp_ns, 'jammer', js))
        elif reason == 'jammer_state_unknown_type':
            self._reject('jammer', reason, f'JammerState type {msg.type} is not a JammerState constant: ignored')
        elif reason == 'jammer_state_nan':
            self._reject('jammer', reason, 'JammerState with a jammer type but a NaN J/S ignored')
        else:
            self._reject('jammer', str(reason), f'JammerState J/S {float(msg.jammer_to_signal_db)} dB ignored')
        self._report()

    # ------------------------------------------------------------------ ordering
    def _reject(self, kind: str, reason: str, text: str) -> None:
        self.counts[f'{kind}_rejected'] += 1
        self.reasons[reason] += 1
        self.get_logger().warn(f'{text} ({reason})', throttle_duration_sec=self.params.warning_throttle_s)

    def _enqueue(self, item: _Item, key: tuple[str, int, str] | None = None) -> bool:
        """Admit the item (duplicate, stamp, lateness), buffer it and process everything the buffer
        releases. ``key``: what makes it an exact duplicate (kind, stamp, anchor id). Returns whether
        it was buffered."""
        stamp_ns = item.stamp_ns
        if key is not None and key in self._seen:
            self._reject(item.kind, f'duplicate_{"gnss_epoch" if item.kind == "gnss" else "uwb_range"}',
                         f'{item.kind} message stamped {stamp_ns} ns{f" from anchor {key[2]!r}" if key[2] else ""} '
                         'was already accepted')
            return False
        previous_ns = self._gate.latest_ns
        decision = self._gate.admit(stamp_ns)
        if not decision.accepted:
            reason = str(decision.reason)
            if reason == STAMP_NOT_POSITIVE:
                text = f'{item.kind} message with stamp {stamp_ns} ns'
            else:
                text = (f'{item.kind} stamp {stamp_ns} ns is {(stamp_ns - (previous_ns or 0)) / _NS:+.3f} s from the '
                        f'latest {previous_ns} ns')
            self._reject(item.kind, reason, text)
            return False
        if decision.restart:
            self._restart(stamp_ns, previous_ns)
        # a verdict or a J/S of an instant applies to the measurements of that instant
        if not self._buffer.push(item, context=item.kind in ('integrity', 'jammer')):
            self._late(item)
            return False
        if key is not None:
            self._seen.add(key, stamp_ns)
        self._buffered[item.kind] += 1
        self._release(self._buffer.pop_ready(self._gate.latest_ns))
        return True

    def _late(self, item: _Item) -> None:
        """Reject a message older than one already processed, and widen the window to cover such lateness."""
        late_ns = (self._gate.latest_ns or item.stamp_ns) - item.stamp_ns
        window_ns = self._buffer.window_ns
        self._reject(item.kind, 'late_beyond_reorder_window',
                     f'{item.kind} stamp {item.stamp_ns} ns arrived {late_ns / _NS:.3f} s after a newer message, '
                     f'later than the re-ordering window {window_ns / _NS:.3f} s')
        wanted_ns = widened_window_ns(window_ns, late_ns, self._window_max_ns)
        if wanted_ns is not None:
            self._buffer.window_ns = wanted_ns
            self.counts['reorder_window_growths'] += 1
            self.get_logger().warn(f're-ordering window widened to {wanted_ns / _NS:.3f} s (inputs arrive late; '
                                   f'maximum reorder_window_max_s {self._window_max_ns / _NS:g} s)')

    def _release(self, items: list) -> None:
        if self.runtime.pending:
            self.apply_parameter_changes()
        for ready in items:
            self._buffered[ready.kind] -= 1
            self._released_ns = ready.stamp_ns
            self._process(ready)
        if items:
            self._forget_released()

    def _forget_released(self) -> None:
        """Drop the duplicate keys stamped more than the largest window before the last released
        message: a copy that late is rejected as late (and would not widen the window); a copy
        less late is recognised as a duplicate (and does not widen it either)."""
        if self._released_ns is not None:
            self._seen.forget_older_than(self._released_ns - max(self._window_max_ns, self._buffer.window_ns))

    def _restart(self, stamp_ns: int, previous_ns: int | None) -> None:
        """A confirmed stamp jump: finish the pending messages, then start a fresh filter."""
        self._release(self._buffer.flush())
        self.counts['time_jump_restarts'] += 1
        self.get_logger().warn(f'stamps jumped to {stamp_ns} ns (from {previous_ns} ns): filter restarted')
        self._retired_filter_counts.update(self.filter.rejection_counts)
        self.filter = self._new_filter()
        self.spp_cache.clear()
        self.response.reset()
        self._buffer = ReorderBuffer(self._buffer.window_ns)
        self._released_ns = None
        self._seen.clear()

    @property
    def buffered(self) -> dict[str, int]:
        """Messages waiting in the re-ordering buffer, per kind."""
        return {kind: self._buffered[kind] for kind in KINDS}

    @property
    def reorder_window_s(self) -> float:
        """The re-ordering window now, s (``reorder_window_s`` at start, widened by late arrivals)."""
        return self._buffer.window_ns / _NS

    def end_of_input(self) -> int:
        """No more input will come (a replay's end): process every buffered message now, in stamp order.

        Returns:
            the number of messages processed. A message arriving afterwards with a stamp older than
            the last one processed is rejected as late.
        """
        return self._flush_buffer('end_of_input_flushes')

    def flush(self) -> int:
        """The same as :meth:`end_of_input`."""
        return self.end_of_input()

    def flush_if_idle(self) -> int:
        """The idle timer (steady clock): process the buffer if no input has arrived for ``idle_flush_s``.

        Returns:
            the number of messages processed (0 if not idle or nothing buffered).
        """
        if not any(self._buffered.values()) or self.health.silent_for_s() < self.params.idle_flush_s:
            return 0
        return self._flush_buffer('idle_flushes')

    def _flush_buffer(self, counter: str) -> int:
        items = self._buffer.flush()
        if items:
            self.counts[counter] += 1
            self._release(items)
        return len(items)

    def destroy_node(self) -> None:
        """Process what is still buffered if the context can still publish, then destroy the node."""
        if getattr(self, '_buffer', None) is not None and self.context.ok():
            try:
                self.end_of_input()
            except Exception as err:  # shutting down: never fail here
                self.get_logger().error(f'buffered input not processed at shutdown: {type(err).__name__}: {err}')
        super().destroy_node()

    # ------------------------------------------------------------------ core
    def _process(self, item: _Item) -> None:
        try:
            if item.kind == 'jammer':
                self.filter.set_jammer_to_signal(item.stamp_ns, item.payload)
                self._sdr_js_ns = item.stamp_ns
                self.counts['jammer_processed'] += 1
                return
            if item.kind == 'integrity':
                self._apply_integrity(item.payload)
                self.counts['integrity_processed'] += 1
                return
            if item.kind == 'gnss':
                epoch, excluded = self.exclusion.filter_epoch(item.payload)
                self._excluded_now = excluded
                if epoch is None:  # all GNSS excluded for spoofing: counted, never applied
                    self.counts['gnss_processed'] += 1
                    self.counts['satellites_excluded_spoofing'] += excluded
                    return
                self.counts['satellites_excluded_spoofing'] += excluded
                if self.params.use_spp_reference and self.params.use_gnss:
                    self.spp_cache.add(epoch)
                out = self.filter.process_gnss(epoch)
                if item.dropped_satellites:  # dropped by the node's checks: rejected satellites too
                    out = dataclasses.replace(
                        out, satellites_rejected=out.satellites_rejected + item.dropped_satellites)
            else:
                self._excluded_now = 0
                out = self.filter.process_uwb(item.payload)
            self.response.after_message(item.stamp_ns, self.filter, item.payload if item.kind == 'uwb' else None)
        except Exception as err:
            # The core validates its input and counts rejections; an exception here is a core bug.
            self.counts[f'{item.kind}_processed'] += 1
            self.counts['core_exceptions'] += 1
            self.reasons['core_exception'] += 1
            self.get_logger().error(
                f'fusion core raised on a {item.kind} message at {item.stamp_ns} ns: {type(err).__name__}: {err}',
                throttle_duration_sec=self.params.warning_throttle_s)
            return
        self.counts[f'{item.kind}_processed'] += 1
        self._count_outcome(out)
        try:
            self._publish(out, item.stamp_ns)
        except Exception as err:  # e.g. the context is shutting down: the next message still gets its turn
            self.counts['publish_exceptions'] += 1
            self.get_logger().error(
                f'publishing the output of a {item.kind} message at {item.stamp_ns} ns failed: '
                f'{type(err).__name__}: {err}', throttle_duration_sec=self.params.warning_throttle_s)

    def _apply_integrity(self, verdict) -> None:
        """Exclusion and readmission of GNSS (logged), and the C/N0 J/S where no SDR J/S is fresh."""
        done = self.response.apply(verdict, self.filter, self.params.fusion_params())
        if done.change == 'excluded':
            self.spp_cache.clear()  # the SPP reference must not bring the spoofed position back
            how = (f'went back to the filter of {done.rolled_back_to_ns} ns (before the first alarm) and applied '
                   f'{done.ranges_replayed} UWB ranges again' if done.rolled_back_to_ns is not None else
                   're-anchored on UWB' if done.reanchored else 'kept the state (fewer than three anchors)')
            self.get_logger().warn(f'spoofing detected at {verdict.stamp_ns} ns: excluding '
                                   f'{self.exclusion.describe()} from the fusion (gnss_integrity); {how}')
        elif done.change == 'readmitted':
            self.get_logger().warn(f'GNSS readmitted at {verdict.stamp_ns} ns after '
                                   f'{self.params.integrity_readmit_clean_s:g} s without spoofing')
        if not self.params.act_on_integrity:
            return
        js = integrity_jammer_to_signal(verdict)
        timeout_ns = self.filter.params.jammer_info_timeout_s * _NS
        sdr_fresh = self._sdr_js_ns is not None and verdict.stamp_ns - self._sdr_js_ns <= timeout_ns
        if js is not None and not sdr_fresh:
            self.filter.set_jammer_to_signal(verdict.stamp_ns, js)
            self.counts['integrity_js_applied'] += 1

    def apply_parameter_changes(self) -> bool:
        """Apply a change of the settable parameters (validated when it was set, :class:`RuntimeParameters`)
        now: called between two messages (before the re-ordering buffer releases any to the core, and
        before a diagnostics report). The core reads the settable filter parameters at each update, so
        the new values hold from the next message on. Returns whether a change was applied."""
        return self.runtime.apply_pending(self._apply_parameters)

    def _apply_parameters(self, old: FusionNodeParams, new: FusionNodeParams) -> None:
        self.params = new
        if self.response.set_acting(new.act_on_integrity, self.filter, new.fusion_params()):
            self.get_logger().warn('act_on_integrity switched off: the GNSS excluded for spoofing is readmitted')
        self.filter.params = self._filter_params()
        self._count_window.window_ns = int(round(new.diagnostics_window_s * 1e9))
        self.counts['parameter_changes'] += 1
        self.get_logger().info('parameters changed: ' + ', '.join(
            f'{name} = {getattr(new, name)!r}' for name in changed_names(old, new)))

    def _new_filter(self) -> FusionFilter:
        use_spp = self.params.use_spp_reference and self.params.use_gnss
        provider = self.spp_cache.reference if use_spp else None
        return FusionFilter(self._filter_params(), reference_provider=provider)

    def _filter_params(self):
        """The core's parameters: the node's, as :class:`SpoofingResponse` changes them while all GNSS is
        excluded for spoofing."""
        return self.response.filter_params(self.params.fusion_params())

    def _count_spp(self, valid: bool) -> None:
        self.counts['spp_valid' if valid else 'spp_invalid'] += 1

    def filter_counts(self) -> dict[str, int]:
        """The core's cumulative counts (including filters replaced after a stamp jump)."""
        total = Counter(self._retired_filter_counts)
        total.update(self.filter.rejection_counts)
        return dict(total)

    def rejection_reasons(self) -> dict[str, int]:
        """Cumulative reasons and counts of the node and of the core, merged."""
        total = Counter(self.filter_counts())
        total.update({k: v for k, v in self.reasons.items() if v})
        return dict(total)

    def _status_reasons(self) -> dict[str, int]:
        """:meth:`rejection_reasons` for a status message, recomputed only when a count changed.

        The key holds the core's current counts, the node's reasons and the restarts (which retire
        core counts), so the result always equals :meth:`rejection_reasons`.
        """
        return self._status_reason_lists()[0]

    def _status_reason_lists(self) -> tuple[dict[str, int], tuple[list[str], list[int]]]:
        """(:meth:`_status_reasons`, its sorted names and clamped counts), cached likewise."""
        key = (self.filter.rejection_counts_key(), tuple(self.reasons.items()), self.counts['time_jump_restarts'])
        cache = self._reasons_cache
        if cache is None or cache[0] != key:
            reasons = self.rejection_reasons()
            cache = self._reasons_cache = (key, reasons, reason_lists(reasons))
        return cache[1], cache[2]

    def _count_outcome(self, out: FusionOutput) -> None:
        """Measurements used and rejected by the core, divergences, J/S: what the diagnostics levels need."""
        c = self.counts
        c['satellites_used'] += out.satellites_used
        c['satellites_rejected'] += out.satellites_rejected
        c['uwb_used'] += out.uwb_used
        c['uwb_rejected_by_filter'] += out.uwb_rejected
        c['divergences'] += bool(out.diverged)
        self._last_js_db = out.jammer_to_signal_db
        if out.initialized:
            self._ever_initialized = True

    def _confirming_first_fix(self, stamp_ns: int) -> bool:
        """The start-up wait of ``divergence_fix_confirm_s``: never initialised, a fix held for confirmation, and
        at most ten times that setting since the first status (later, no solution is an ERROR again: fixes that
        keep disagreeing under jamming)."""
        confirm_s = self.filter.params.divergence_fix_confirm_s
        return (not self._ever_initialized and confirm_s > 0 and self.filter.awaiting_fix_confirmation
                and self._first_output_ns is not None
                and stamp_ns - self._first_output_ns <= 10.0 * confirm_s * 1e9)

    def _publish(self, out: FusionOutput, stamp_ns: int) -> None:
        if self._first_output_ns is None:
            self._first_output_ns = stamp_ns
        frame = self._fix_frames.get(out.frame_id, out.frame_id)
        reasons, lists = self._status_reason_lists()
        self.status_pub.publish(status_msg(out, stamp_ns, frame, reasons, lists, self.exclusion.scope,
                                           self._excluded_now))
        if not out.initialized:
            return
        if not out.is_finite():
            self.counts['nonfinite_estimates_suppressed'] += 1
            return
        self.odom_pub.publish(odometry_msg(out, frame, self.params.child_frame_id))
        if out.frame_id == FRAME_EARTH:
            fix = fix_msg(out, self.params.child_frame_id)
            if (math.isfinite(fix.latitude) and math.isfinite(fix.longitude) and math.isfinite(fix.altitude)
                    and all_finite(fix.position_covariance)):
                self.fix_pub.publish(fix)
            else:
                self.counts['nonfinite_estimates_suppressed'] += 1
                return
        self._publish_local(out)

    def _publish_local(self, out: FusionOutput) -> None:
        """fusion/local_odometry (and, once, fusion/datum) from a published, finite solution.

        ECEF solutions are expressed in the local ENU frame, whose origin is the datum parameter or
        the first of them (``local_origin``); a map-frame solution (UWB-only) is in the local frame
        already. Then the antenna estimate is moved to base_link (:meth:`LocalFrame.base_link_solution`: both in one
        compiled call).
        """
        p = self.params
        earth = out.frame_id == FRAME_EARTH
        if earth and not self.local_frame.defined:
            self.local_frame.set_origin_ecef(out.position_m)
        if earth and not self._datum_published:
            assert self.local_frame.origin_geodetic is not None
            self.datum_pub.publish(datum_msg(out.stamp_ns, p.map_frame_id, self.local_frame.origin_geodetic))
            self._datum_published = True
        sol = self.local_frame.base_link_solution(out.stamp_ns, out.position_m, out.velocity_mps, out.covariance_pv,
                                                  earth, p.antenna_position_m, p.heading_source,
                                                  p.heading_min_speed_mps)
        self.local_odom_pub.publish(local_odometry_msg(sol, p.map_frame_id, p.base_frame_id))

    # ------------------------------------------------------------------ diagnostics
    def accounting(self) -> dict[str, object]:
        """Counters of the node, the core and the input subscriptions, and whether every input adds up.

        For each kind: ``<kind>_received == <kind>_rejected + <kind>_processed + <kind>_buffered``
        (messages lost before the node, ``input.<topic>.lost`` / ``middleware_lost``, never arrived
        and are counted apart).
        """
        values: dict[str, object] = dict(sorted(self.counts.items()))
        buffered = self.buffered
        ok = True
        for kind in KINDS:
            values[f'{kind}_buffered'] = buffered[kind]
            ok = ok and self.counts[f'{kind}_received'] == (
                self.counts[f'{kind}_rejected'] + self.counts[f'{kind}_processed'] + buffered[kind])
        values['reorder_window_s'] = self.reorder_window_s
        values.update({f'rejected.{k}': v for k, v in sorted(self.reasons.items())})
        values.update({f'filter.{k}': v for k, v in sorted(self.filter_counts().items())})
        values.update(self.health.values())
        values['initialized'] = self.filter.initialized
        values['accounting_ok'] = ok
        return values

    def jammer_cn0_loss_db(self) -> float:
        """C/N0 lost to the jammer in use (Cao et al., eq. 4, at ``nominal_cn0_dbhz`` with
        ``jammer_quality_factor``), dB; 0 when no J/S is in use."""
        if not math.isfinite(self._last_js_db):
            return 0.0
        p = self.params
        return p.nominal_cn0_dbhz - float(effective_cn0_dbhz(p.nominal_cn0_dbhz, self._last_js_db,
                                                             p.jammer_quality_factor))

    def _window_totals(self) -> dict[str, int]:
        """The cumulative counts whose increase over ``diagnostics_window_s`` sets the level."""
        c = self.counts
        received = sum(self.health.counts[f'{t}.received'] for t in self.health.topics)
        return {
            'gnss_received': c['gnss_received'], 'gnss_rejected': c['gnss_rejected'],
            'uwb_received': c['uwb_received'], 'uwb_rejected': c['uwb_rejected'] + c['uwb_rejected_by_filter'],
            'jammer_received': c['jammer_received'], 'jammer_rejected': c['jammer_rejected'],
            'satellites_used': c['satellites_used'], 'satellites_rejected': c['satellites_rejected'],
            'messages_received': received, 'messages_lost': self.health.lost_total(),
            'divergences': c['divergences'], 'suppressed': c['nonfinite_estimates_suppressed'],
        }

    def diagnostics(self, stamp_ns: int) -> DiagnosticArray:
        """The /diagnostics message (levels below); the counts "since the last report" restart here.

        ERROR (the output is not valid, or the node is at fault): the accounting does not add up; the
        core, a publisher or an input handler raised since the last report; the filter is not
        initialised although input was processed (no solution is published); a non-finite estimate
        was suppressed within ``diagnostics_window_s``. WARN (inputs degraded, the solution still
        published): over ``diagnostics_window_s`` of stamp time more than ``warn_rejected_fraction`` of
        the GNSS epochs, UWB ranges (rejected by the node or by the filter), jammer states or
        satellites was rejected, or more than ``warn_lost_fraction`` of the messages published to the
        node was lost; the filter diverged (and re-initialised) within the window; the J/S in use costs
        more than ``warn_cn0_loss_db`` of C/N0 (eq. 4 at ``nominal_cn0_dbhz``: 3 dB at about 15 dB J/S).
        OK otherwise, also before anything was processed ("starting"). Isolated rejections (a range
        gated now and then on clean data) stay OK. With exactly three anchors heard within
        ``uwb_init_window_s`` and ``uwb_tag_side_of_anchor_plane`` 0, the OK message says that the mirror
        solution across their plane is not ruled out (values ``uwb_anchors_heard``, ``uwb_mirror_ambiguous``;
        a warning is logged once).
        """
        if self.runtime.pending:
            self.apply_parameter_changes()
        p = self.params
        values = self.accounting()
        now = {'faults': self.counts['core_exceptions'] + self.counts['publish_exceptions'],
               'handler_errors': self.health.callback_errors_total()}
        new = {k: v - self._at_last_report.get(k, 0) for k, v in now.items()}
        self._at_last_report = now
        w = self._count_window.update(stamp_ns, self._window_totals())
        checks = [('GNSS epochs rejected', w['gnss_rejected'], w['gnss_received']),
                  ('satellites rejected', w['satellites_rejected'], w['satellites_used'] + w['satellites_rejected']),
                  ('UWB ranges rejected', w['uwb_rejected'], w['uwb_received']),
                  ('jammer states rejected', w['jammer_rejected'], w['jammer_received'])]
        for what, n, total in checks:
            values[f'window.{what.replace(" ", "_").lower()}_fraction'] = round(fraction(n, total), 4)
        lost = ('messages lost', w['messages_lost'], w['messages_received'] + w['messages_lost'])
        values['window.messages_lost_fraction'] = round(fraction(lost[1], lost[2]), 4)
        values['window_s'] = p.diagnostics_window_s
        values['jammer_to_signal_db'] = self._last_js_db
        values['parameter_changes_refused'] = self.runtime.changes_refused
        values['gnss_excluded_for_spoofing'] = self.exclusion.describe()
        # the side of the anchors' plane the filter holds while all GNSS is excluded (0: none held)
        values['anchor_plane_side_held'] = self.response.held_side if self.exclusion.all_gnss() else 0
        # the motion model the filter found (motion_detection): the static one, or the moving one
        values['motion_static'] = self.filter.motion_static
        values.update({f'integrity.{k}': v for k, v in self.exclusion.counts.items()})
        values.update({f'integrity.{k}': v for k, v in self.response.counts.items()})
        anchors = self.filter.uwb_anchors_heard(stamp_ns)
        mirror = anchors == 3 and self.filter.params.uwb_tag_side_of_anchor_plane == 0
        values['uwb_anchors_heard'] = anchors
        values['uwb_mirror_ambiguous'] = mirror
        if mirror and not self._mirror_warned:
            self._mirror_warned = True
            self.get_logger().warning(
                'three UWB anchors heard and uwb_tag_side_of_anchor_plane is 0: the tag\'s mirror image across the '
                'anchors\' plane fits their ranges as well, and GNSS heights may not tell them apart; set the side '
                '(-1 below the plane, +1 above) if you know it (README, "UWB anchors")')
        processed = self.counts['gnss_processed'] + self.counts['uwb_processed']
        if not values['accounting_ok']:
            level, text = ERROR, 'input accounting does not add up'
        elif new['faults']:
            level, text = ERROR, f'{new["faults"]} core or publishing exceptions since the last report'
        elif new['handler_errors']:
            level, text = ERROR, f'{new["handler_errors"]} input handler exceptions since the last report'
        elif not self.filter.initialized and processed and self._confirming_first_fix(stamp_ns):
            level, text = OK, 'starting: waiting for a second GNSS fix to confirm the first (divergence_fix_confirm_s)'
        elif not self.filter.initialized and processed:
            level, text = ERROR, ('no valid solution: filter not initialised' if not self._ever_initialized
                                  else 'no valid solution: filter reset, not re-initialised yet')
        elif w['suppressed']:
            level, text = ERROR, (f'{w["suppressed"]} non-finite estimates suppressed in the last '
                                  f'{p.diagnostics_window_s:g} s')
        elif not processed:
            level, text = OK, 'starting: nothing processed yet'
        else:
            degraded = (degraded_inputs(checks, p.warn_rejected_fraction)
                        + degraded_inputs([lost], p.warn_lost_fraction))
            if w['divergences']:
                degraded.append(f'filter diverged {w["divergences"]} times')
            if self.exclusion.active:
                degraded.append(f'spoofing: {self.exclusion.describe()} excluded (gnss_integrity)')
            loss_db = self.jammer_cn0_loss_db()
            values['jammer_cn0_loss_db'] = round(loss_db, 2)
            if loss_db > p.warn_cn0_loss_db:
                degraded.append(f'jammer reported: J/S {self._last_js_db:.1f} dB costs {loss_db:.1f} dB of C/N0')
            if degraded:
                level, text = WARN, (f'inputs degraded (window {p.diagnostics_window_s:g} s): '
                                     + '; '.join(degraded))
            else:
                level, text = OK, 'fusing'
        if mirror and level == OK and text == 'fusing':
            text = 'fusing; three UWB anchors: mirror across their plane not ruled out (uwb_tag_side_of_anchor_plane)'
        return diagnostic_array(stamp_ns, 'uwb_gnss_fusion', p.hardware_id, level, text, values)

    def _report(self) -> None:
        """Publish /diagnostics when due, timed by the latest accepted stamp (a rejected stamp never
        drives the timer)."""
        latest = self._gate.latest_ns
        if latest is not None and self._diag_timer.due(latest):
            self.diag_pub.publish(self.diagnostics(latest))

    def _publish_stale(self, silent_s: float) -> None:
        """StaleInputWatch: no input for ``silent_s`` of wall time; a STALE status stamped with the
        node clock's now (the stamp-timed reports resume with the next accepted input)."""
        self.diag_pub.publish(diagnostic_array(
            self.get_clock().now().nanoseconds, 'uwb_gnss_fusion', self.params.hardware_id, STALE,
            f'no input for {silent_s:.1f} s', self.accounting()))

def main(argv=None) -> int:
    return run_node(FusionNode, executable='fusion_node', params_cls=FusionNodeParams, topics=TOPICS,
                    summary='Tightly-coupled GNSS/UWB cubature Kalman filter that survives jamming.', argv=argv)
