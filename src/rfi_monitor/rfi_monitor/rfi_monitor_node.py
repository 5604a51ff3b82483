"""ROS node of the RFI monitor: /rfi/if_samples -> /rfi/jammer_state, /diagnostics.

The node is thin: it declares the parameters (the core's :class:`rfi_monitor.monitor.RfiMonitorParams`,
flattened, plus a few of its own), checks and decodes each ``rfi_msgs/IfSamples`` block into a numpy
array (``np.frombuffer`` by ``sample_format``, little-endian, times ``scale``: volts), hands it to one
:class:`rfi_monitor.monitor.RfiMonitor` (Kang et al., eq. 8-27, plus the identification of
docs/rfi_monitor/README.md) and publishes the returned estimate as a ``rfi_msgs/JammerState``.

Input: ``/rfi/if_samples`` is subscribed with :func:`rfi_node_common.inputs.subscribe_input`: it takes
its publishers' reliability (reliable with ``play`` or ``if_source``, best effort once a best-effort
sensor driver appears; rclpy's ``qos_overrides./rfi/if_samples.subscription.reliability`` parameter
fixes it), every arrival and every message lost before the node saw it (publisher sequence gaps, the
middleware's lost-message event, counted once) counted as ``input./rfi/if_samples.*``. The
subscription is raw: bytes that rclpy cannot deserialise are counted as
``rejected_malformed_message`` (:meth:`RfiMonitorNode.on_raw_block`). Nothing raises out of
:meth:`RfiMonitorNode.on_block`: every block that reaches it is either processed or rejected under
a named reason; the subscription's own guard (``callback_errors``) is only the last net and makes the diagnostics ERROR.

Output policy: :mod:`rfi_monitor.block_io` (one JammerState per analysed block, nothing for a rejected one).

Stream continuity: the core owns it. A jump in ``first_sample_index`` resets the per-sample tracker
(the calibration is kept) and is counted as a gap; a change of sample rate, IF or complexness resets
it and the calibration and is counted as ``rate_changes``. A snapshot front end (1 ms every second)
therefore produces one gap per block; gaps are reported but are not a warning. A block rejected here
never reaches the core, so the block after it counts as a gap (also after a lost message).

Stamps: :class:`rfi_node_common.input_checks.StampGate` admits every block's stamp first (a block
whose stamp is accepted moves the time line even if its content is then rejected). A stamp
<= 0 is ``stamp_not_positive``; one that does not increase is ``stamp_not_increasing``; one more than
``max_stamp_jump_s`` from the latest accepted stamp is ``stamp_far_future`` / ``stamp_far_past`` and
does not move the node's time line, so a single bad stamp never stalls the node. A jump confirmed by
``stamp_jump_confirmations`` consecutive blocks is accepted as a new time line (``stamp_restarts``;
nothing in the monitor depends on stamp continuity, which the sample index carries). A stamp whose
nanoseconds are not below 1e9 is ``bad_stamp_nanosec`` (not a canonical ROS time).

Block checks, saturation and every ``rejected_<reason>`` with the physical range it enforces (the node's, the core's,
``core_error`` and ``node_error``): :mod:`rfi_monitor.block_io`.

Diagnostics (/diagnostics, every ``diagnostics_period_s`` of *stamp* time via StampTimer, driven only
by stamps the StampGate accepted, after the block of that stamp is counted): blocks_received,
blocks_processed, states_published, each rejected_* count, stamp_restarts, gaps, rate_changes, the
core's counters (``core.*``), calibrated, the last type, the subscription's ``input.*`` counters and
``accounting_ok`` (every block that reached the subscription reached the handler, and
blocks_received == blocks_processed + sum of rejected_*). Level: ERROR if the accounting does not
add up, the core or the node raised, or the subscription's guard caught an exception since the last report;
WARN (input degraded) if over the last ``diagnostics_window_s`` of stamp time more than
``warn_rejected_fraction`` of the blocks was rejected or more than ``warn_lost_fraction`` lost before
reaching the node (one rejected block among many stays OK); else OK. ``hardware_id`` of every status is
the parameter (the front end), and it, the window, the thresholds and ``warning_throttle_s`` can be set
while the node runs (rfi_node_common.params.RuntimeParameters; the core's parameters are read-only).

Load policy (issue 26 item 1): :mod:`rfi_monitor.load_policy` (pure, tested on its own) defines "live" and
decides per block: a replay (stamps in the past: a bag, ``play --max``, ``--rate N``) gets the full analysis on every
block, whatever it costs; only a live stream has the safety net of the CPU budget (``max_cpu_load``), the light
analysis (``light_analysis_debt_s``, ``blocks_light``), shedding (``blocks_shed``, judged on the stamp read from the
raw bytes, ``peek_stamp_ns``) and the age limit (``max_block_age_s``, ``blocks_shed_stale``); the decisions are
counted as ``load.*`` on /diagnostics, with ``live_stream``. ``accounting_ok``: received == processed + shed +
rejected. :func:`warm_up` compiles the numba functions before the node subscribes.

Second core: ``analysis_worker`` (off by default; :mod:`rfi_monitor.analysis_worker`): the ridge analysis in a child
process, the same estimates; a child that fails is counted (``core.worker_failures``); slower on 2 vCPUs.
Drawn topics (issue 30: the waterfall and its swept band), only while subscribed: :mod:`rfi_monitor.spectrum_topics`.
Stale input: :class:`rfi_node_common.inputs.StaleInputWatch` publishes a STALE status (stamped with the node clock,
the only wall-clock use; no estimate depends on it) while nothing has arrived for ``input_timeout_s``.
"""

from __future__ import annotations

import time
from collections import Counter
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.serialization import deserialize_message

from rfi_monitor.analysis_worker import AnalysisWorker
from rfi_monitor.block_io import (
    MAX_SAMPLE_INDEX,
    SAMPLE_DTYPES,
    SAMPLE_WIDTH_BYTES,
    check_block,
    count_range,
    decode_counts,
    decode_samples,
    exceeds_bits,
    full_scale,
    is_blank,
    jammer_state_msg,
    peek_stamp_ns,
)
from rfi_monitor.load_policy import FULL, LIGHT, SHED, LoadPolicy, LoadPolicyParams
from rfi_monitor.monitor import NON_FINITE, RfiMonitor
from rfi_monitor.node_params import NESTED, TOPICS, TRACKER_MODES, MonitorNodeParams
from rfi_monitor.spectrum_topics import SpectrumTopics
from rfi_monitor.warm_up import warm_up
from rfi_msgs.msg import IfSamples, JammerState
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
from rfi_node_common.input_checks import StampGate
from rfi_node_common.inputs import InputHealth, StaleInputWatch, subscribe_input
from rfi_node_common.main import run_node
from rfi_node_common.params import RuntimeParameters, changed_names, declare
from rfi_node_common.qos import DATA_QOS, DIAGNOSTICS_QOS
from rfi_node_common.stamps import NS_PER_S, stamp_to_ns

__all__ = ['MAX_SAMPLE_INDEX', 'NESTED', 'SAMPLE_DTYPES', 'SAMPLE_WIDTH_BYTES', 'TRACKER_MODES', 'MonitorNodeParams',
           'RfiMonitorNode', 'check_block', 'count_range', 'decode_counts', 'decode_samples', 'exceeds_bits',
           'full_scale', 'is_blank', 'jammer_state_msg', 'main', 'peek_stamp_ns', 'rejected_total', 'warm_up']
"""Also re-exported here: the message conversions (rfi_monitor.block_io), the parameters (rfi_monitor.node_params) and
warm_up (rfi_monitor.warm_up)."""


IF_TOPIC = 'rfi/if_samples'
"""Input topic, relative: /rfi/if_samples without a namespace, /<ns>/rfi/if_samples with ``-r __ns:=/<ns>``."""

TYPE_NAMES = {JammerState.NONE: 'NONE', JammerState.CW: 'CW', JammerState.CHIRP: 'CHIRP',
              JammerState.WIDEBAND: 'WIDEBAND', JammerState.UNKNOWN: 'UNKNOWN'}
"""JammerState type code -> name (for diagnostics and logs)."""

def rejected_total(counts: Counter[str]) -> int:
    """Sum of the ``rejected_*`` counters."""
    return sum(v for k, v in counts.items() if k.startswith('rejected_'))


class RfiMonitorNode(Node):
    """Thin node around :class:`rfi_monitor.monitor.RfiMonitor` (see module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__('rfi_monitor', **kwargs)
        self.params = declare(self, MonitorNodeParams)
        self.runtime = RuntimeParameters(self, self.params)  # the settable parameters: applied between blocks
        self._window = CountWindow(self.params.diagnostics_window_s)
        self.worker: AnalysisWorker | None = None
        if self.params.analysis_worker and self.params.estimator == 'stft':
            try:
                self.worker = AnalysisWorker()
            except (RuntimeError, OSError) as err:
                self.get_logger().error(f'analysis_worker: the worker process did not start ({err}); analysing '
                                        'every block in this process')
        self.monitor = RfiMonitor(self.params.monitor_params(), worker=self.worker)
        warm_up(self.params.monitor_params())
        self.counts: Counter[str] = Counter()
        self.health = InputHealth()
        self._gate = StampGate(self.params.max_stamp_jump_s, self.params.stamp_jump_confirmations)
        self._core_counters: dict[str, int] = {}
        self._last_type: int | None = None
        self._last_clipped_fraction = 0.0
        self.load = LoadPolicy(self._load_params(self.params))
        self._errors_at_last_report = 0
        self._handler_errors_at_last_report = 0
        self._diag_timer = StampTimer(self.params.diagnostics_period_s)
        self.state_pub = self.create_publisher(JammerState, 'rfi/jammer_state', DATA_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self.spectrum = SpectrumTopics(self, self.params)   # the waterfall: published only while subscribed
        # raw: bytes that rclpy cannot deserialise reach on_raw_block and are counted as malformed
        # (a non-raw subscription would drop them inside rclpy, seen only as a sequence gap)
        self.subscription = subscribe_input(self, IfSamples, IF_TOPIC, self.on_raw_block, self.health, raw=True,
                                            warning_throttle_s=self.params.warning_throttle_s)
        self.stale_watch = StaleInputWatch(self, self.health, self.params.input_timeout_s, self.publish_stale)

    def destroy_node(self) -> None:
        """Stop the analysis worker (if any), then the node."""
        if self.worker is not None:
            self.worker.close()
        super().destroy_node()

    def on_raw_block(self, raw: bytes | IfSamples) -> None:
        """A serialised block: deserialised by rclpy, or counted as ``rejected_malformed_message`` (a message
        object, as an in-process hand-over may give, goes straight to :meth:`on_block`)."""
        if self.runtime.pending:
            self.runtime.apply_pending(self._apply_parameters)
        if isinstance(raw, IfSamples):
            self.on_block(raw)
            return
        cpu0 = time.thread_time()
        try:
            stamp = peek_stamp_ns(raw)
            mode = self._load_mode(stamp, None) if stamp is not None else None
            if mode == SHED:
                # shed before the bytes are even deserialised: a node behind its stream must get cheaper
                self.counts['blocks_received'] += 1
                decision = self._gate.admit(stamp)
                if not decision.accepted:
                    self.counts[f'rejected_{decision.reason}'] += 1
                    return
                self.counts['blocks_shed'] += 1
                if self._diag_timer.due(stamp):
                    self._publish(lambda: self.diagnostics(stamp))
                return
            try:
                msg = deserialize_message(raw, IfSamples)
            except Exception as err:  # noqa: BLE001 - rclpy raises RMWError (and others) on malformed CDR
                self.counts['blocks_received'] += 1
                self.counts['rejected_malformed_message'] += 1
                self.get_logger().warn(f'IF block rejected: malformed message ({len(raw)} bytes: '
                                       f'{type(err).__name__})', throttle_duration_sec=self.params.warning_throttle_s)
                return
            self._handle(msg, load_mode=mode)
        finally:
            self.load.spend(time.thread_time() - cpu0)

    def on_block(self, msg: IfSamples) -> None:
        """Account for one block: processed (one JammerState), shed or rejected under a named reason; never
        raises."""
        cpu0 = time.thread_time()
        try:
            self._handle(msg, load_mode=None)
        finally:
            self.load.spend(time.thread_time() - cpu0)

    def _handle(self, msg: IfSamples, load_mode: str | None) -> None:
        """on_block's work; ``load_mode``: FULL or LIGHT when the load decision (:meth:`_load_mode`) was made on the
        raw bytes already, None when it is to be made here."""
        self.counts['blocks_received'] += 1
        stamp_ns: int | None = None
        try:
            reason, stamp_ns = self._admit_stamp(msg)
            if reason is None:
                reason = check_block(msg, self.params.min_block_samples, self.params.max_block_samples)
            mode = load_mode if load_mode is not None else (
                self._load_mode(stamp_ns, msg) if reason is None and stamp_ns is not None else FULL)
            if reason is None and mode == SHED:
                self.counts['blocks_shed'] += 1
            elif reason is None:
                reason = self._analyse(stamp_ns, msg, light=mode == LIGHT)
        except Exception as err:  # noqa: BLE001 - a bug in the checks: count it, never lose the block
            self.get_logger().error(f'IF block dropped, the node raised {type(err).__name__}: {err}',
                                    throttle_duration_sec=self.params.warning_throttle_s)
            reason = 'node_error'
        if reason is not None:
            self.counts[f'rejected_{reason}'] += 1
            self.get_logger().warn(f'IF block at {stamp_to_ns(msg.header.stamp)} ns rejected: {reason}',
                                   throttle_duration_sec=self.params.warning_throttle_s)
        if stamp_ns is not None and self._diag_timer.due(stamp_ns):
            self._publish(lambda: self.diagnostics(stamp_ns))

    @staticmethod
    def _load_params(params: MonitorNodeParams) -> LoadPolicyParams:
        return LoadPolicyParams(max_cpu_load=params.max_cpu_load, light_analysis_debt_s=params.light_analysis_debt_s,
                                max_block_age_s=params.max_block_age_s, light_allowed=params.estimator == 'stft')

    def _load_mode(self, stamp_ns: int, msg: IfSamples | None) -> str:
        """FULL, LIGHT or SHED for this block: :class:`rfi_monitor.load_policy.LoadPolicy` (a replay: FULL, always),
        given the block's duration (``msg`` None: a block judged on its raw bytes), its reception time (the system
        clock when the middleware does not report it) and its time in the input queue."""
        covered_s = 0.0
        if msg is not None and msg.sample_format in SAMPLE_WIDTH_BYTES and msg.sample_rate_hz > 0:
            n = len(msg.samples) // SAMPLE_WIDTH_BYTES[msg.sample_format] // (2 if msg.is_complex else 1)
            covered_s = n / msg.sample_rate_hz
        received_ns = self.health.last_received_ns
        return self.load.decide(stamp_ns, received_ns if received_ns > 0 else time.time_ns(), covered_s,
                                self.health.queued_s())

    def _admit_stamp(self, msg: IfSamples) -> tuple[str | None, int | None]:
        """(rejection reason or None, the stamp in ns if the StampGate accepted it)."""
        if msg.header.stamp.nanosec >= NS_PER_S:
            return 'bad_stamp_nanosec', None
        stamp_ns = stamp_to_ns(msg.header.stamp)
        decision = self._gate.admit(stamp_ns)
        if not decision.accepted:
            return decision.reason, None
        if decision.restart:
            self.counts['stamp_restarts'] += 1
            self.load.restart()
            self.get_logger().warn(f'IF block stamps jumped to {stamp_ns} ns (confirmed by '
                                   f'{self.params.stamp_jump_confirmations} blocks): new time line')
        return None, stamp_ns

    def _analyse(self, stamp_ns: int, msg: IfSamples, light: bool = False) -> str | None:
        """Run the core on a well-formed block (``light``: the light analysis will do) and publish its estimate;
        return a rejection reason."""
        counts = decode_counts(msg)
        if exceeds_bits(counts, int(msg.bits_per_sample)):
            return 'values_exceed_bits'
        if is_blank(counts, bool(msg.is_complex)):
            return 'blank_block'
        try:
            est = self.monitor.process(
                counts.astype(np.float64) * msg.scale, msg.sample_rate_hz, msg.intermediate_frequency_hz,
                msg.first_sample_index, stamp_ns, is_complex=bool(msg.is_complex),
                full_scale=full_scale(msg) if self.params.check_saturation else None, bits=int(msg.bits_per_sample),
                light=light)
        except Exception as err:  # noqa: BLE001 - the checks should make this unreachable; count it, keep going
            self.get_logger().error(f'core raised on a checked IF block ({type(err).__name__}: {err})',
                                    throttle_duration_sec=self.params.warning_throttle_s)
            return 'core_error'
        self._core_counters = dict(est.counters)
        if not est.valid:
            return est.rejection or NON_FINITE
        self.counts['blocks_processed'] += 1
        if est.light:
            self.counts['blocks_light'] += 1
        self._last_type = int(est.type)
        self._last_clipped_fraction = float(est.clipped_fraction)
        self.state_pub.publish(jammer_state_msg(est, msg))
        self.counts['states_published'] += 1
        # the topics made to be drawn (nothing done unless subscribed; a failure counted, spectrum_errors)
        self.spectrum.on_estimate_logged(self.counts, self.params.warning_throttle_s, stamp_ns, est,
                                         self.monitor.last_spectrum, int(msg.bits_per_sample), msg.scale)
        return None

    def _publish(self, make: Any) -> None:
        """Publish the diagnostics ``make()`` builds; a failure is logged, never raised (diagnostics only)."""
        try:
            self.diag_pub.publish(make())
        except Exception as err:  # noqa: BLE001 - a report must never end the node
            self.get_logger().error(f'/diagnostics not published: {type(err).__name__}: {err}',
                                    throttle_duration_sec=self.params.warning_throttle_s)

    def _apply_parameters(self, old: MonitorNodeParams, new: MonitorNodeParams) -> None:
        """A change of the settable parameters (node-level only: hardware_id, the diagnostics window and
        thresholds, warning_throttle_s; the core's parameters are read-only)."""
        self.params = new
        self._window.window_ns = int(round(new.diagnostics_window_s * 1e9))
        self.get_logger().info('parameters changed: ' + ', '.join(
            f'{name} = {getattr(new, name)!r}' for name in changed_names(old, new)))

    def publish_stale(self, silent_s: float) -> None:
        """StaleInputWatch: a STALE status stamped with the node clock (no input for ``silent_s`` s)."""
        def make() -> DiagnosticArray:
            topic = self.subscription.topic_name
            return diagnostic_array(max(0, self.get_clock().now().nanoseconds), 'rfi_monitor', self.params.hardware_id,
                                    STALE, f'no input on {topic} for {silent_s:.1f} s', self.accounting())
        self._publish(make)

    def accounting(self) -> dict[str, object]:
        """Counters of the node, the core and the subscription, and whether every block received is accounted for."""
        values: dict[str, object] = dict(sorted(self.counts.items()))
        for key in ('blocks_received', 'blocks_processed', 'blocks_light', 'states_published', 'stamp_restarts',
                    'blocks_shed', 'blocks_shed_stale'):
            values.setdefault(key, 0)
        core = self._core_counters
        values['gaps'] = core.get('gaps', 0)
        values['rate_changes'] = core.get('rate_changes', 0)
        values.update({f'core.{k}': v for k, v in sorted(core.items()) if k not in ('gaps', 'rate_changes')})
        values['calibrated'] = self.monitor.calibrated
        values['last_type'] = 'none yet' if self._last_type is None else TYPE_NAMES.get(self._last_type, '?')
        values['last_clipped_fraction'] = self._last_clipped_fraction
        values['live_stream'] = 'unknown' if self.load.live is None else self.load.live
        values['blocks_shed_stale'] = self.load.counts['shed_stale']
        for key in ('full', 'light', 'shed', 'shed_stale', 'not_live'):
            values[f'load.{key}'] = self.load.counts[key]
        values.update(self.health.values())
        received = self.counts['blocks_received']
        values['accounting_ok'] = (self.health.counts[f'{self.subscription.topic_name}.received'] == received
                                   == self.counts['blocks_processed'] + self.counts['blocks_shed']
                                   + rejected_total(self.counts))
        return values

    def diagnostics(self, stamp_ns: int) -> DiagnosticArray:
        """The /diagnostics message at ``stamp_ns`` (levels: see the module docstring)."""
        values = self.accounting()
        rejected = rejected_total(self.counts)
        errors = self.counts['rejected_core_error'] + self.counts['rejected_node_error']
        new_errors = errors - self._errors_at_last_report
        self._errors_at_last_report = errors
        lost = self.health.lost_total()
        handler_errors = self.health.callback_errors_total()
        new_handler_errors = handler_errors - self._handler_errors_at_last_report
        self._handler_errors_at_last_report = handler_errors
        state = f'last type {values["last_type"]}' if self.monitor.calibrated else 'learning the noise floor'
        degraded = self._degraded(stamp_ns, rejected, lost)  # every report moves the window
        if not values['accounting_ok']:
            level, text = ERROR, 'block accounting does not add up'
        elif new_errors:
            level, text = ERROR, f'{new_errors} blocks made the core or the node raise since the last report'
        elif new_handler_errors:
            level, text = ERROR, f'the input handler raised {new_handler_errors} times since the last report'
        elif degraded:
            level, text = WARN, (f'inputs degraded (window {self.params.diagnostics_window_s:g} s): '
                                 + '; '.join(degraded))
        else:
            level, text = OK, 'monitoring'
        return diagnostic_array(stamp_ns, 'rfi_monitor', self.params.hardware_id, level, f'{text}; {state}', values)

    def _degraded(self, stamp_ns: int, rejected: int, lost: int) -> list[str]:
        """WARN texts: rejected / lost fractions of the blocks over diagnostics_window_s above their thresholds
        (an isolated rejected block among many stays OK)."""
        w = self._window.update(stamp_ns, {'received': self.counts['blocks_received'], 'rejected': rejected,
                                           'lost': lost})
        return (degraded_inputs([('blocks rejected', w['rejected'], w['received'])], self.params.warn_rejected_fraction)
                + degraded_inputs([('messages lost', w['lost'], w['received'] + w['lost'])],
                                  self.params.warn_lost_fraction))


def main(argv=None) -> int:
    return run_node(RfiMonitorNode, executable='rfi_monitor_node', params_cls=MonitorNodeParams, topics=TOPICS,
                    summary='Detect, classify and track GNSS jammers from IF sample blocks (Kang et al.).',
                    argv=argv)
