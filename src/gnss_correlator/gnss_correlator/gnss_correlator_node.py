"""ROS node of the correlators: /rfi/if_samples -> /gnss/correlators, /diagnostics.

Thin: declares the parameters (:mod:`gnss_correlator.node_params`), checks and decodes each
``rfi_msgs/IfSamples`` with the checks the monitor uses (:mod:`rfi_node_common.if_blocks`), hands the samples
to :class:`gnss_correlator.receiver.Receiver` (acquisition, tracking, the 1-ms output grid, all the maths) and
publishes one ``rfi_msgs/CorrelatorArray`` per completed 1-ms interval (stamp from the IfSamples stamps,
``frame_id`` from the parameter).

Rejected blocks, each counted as ``rejected_<reason>`` with a throttled warning, never reach the core:
the field checks of :func:`rfi_node_common.if_blocks.check_block` (format, bits, rate, IF, scale, centre
frequency, sizes, index), ``values_exceed_bits``, ``blank_block``, ``rate_below_2mhz`` (the C/A code needs
2 MS/s), ``band_outside_nyquist`` (real samples whose |IF| -+ doppler_max_hz leaves (0, fs/2), complex
ones whose |IF| + doppler_max_hz reaches fs/2), and the stamp checks of
:class:`rfi_node_common.input_checks.StampGate`. A change of rate, IF or sample type, or a gap in
``first_sample_index`` restarts acquisition in the core (``core.restarts_format``, ``core.restarts_gap``).
Should the core raise on a block that passed the checks (a bug), the block is counted as ``core_errors``,
the receiver is rebuilt, /diagnostics says ERROR, and the node keeps running.

Batching: accepted blocks that continue one another (the next ``first_sample_index``, the same rate, IF and sample
type) are gathered until they hold ``batch_ms`` of stream and handed to the receiver as one block (the first's
stamp): its per-call cost made a stream of 1-ms blocks cost 2.5 times as much (``batch_ms``). The receiver
gives the same periods whatever the block sizes, so this moves the answers by up to ``batch_ms``, not their
values; blocks still gathered when the input has been silent for ``idle_flush_ms`` (wall time: the end of a stream)
are processed then; and once the input has been silent that long after a block, a /diagnostics report (stamped
with the last block's stamp) gives the counters of the whole stream. A block that does not continue the
gathered ones (a gap, a format change, a stamp-gate restart) first has them processed.

First acquisition: it runs in the receiver's worker thread (:mod:`gnss_correlator.receiver`), so the callback
returns and the input keeps being taken; the receiver holds the blocks meanwhile (up to ``acquisition_hold_s`` of
stream; ``blocks_held_for_acquisition``) and, when the worker triggers a guard condition, answers them all, the same
intervals as a search in the callback would have given, ``REPLAY_BLOCKS_PER_CALLBACK`` held blocks per callback.
Input first: each such callback takes every block waiting in the subscription before it replays
(``blocks_taken_before_replay``; they join the hold), and blocks handed in meanwhile are held, not replayed (the
receiver's ``replay_per_block`` 0). A single-threaded executor takes one message per subscription per turn, so a
replay of 100 ms of stream per turn used to take one 1-ms block per turn: the input queue (1000 messages, 1 s of
1-ms blocks) filled and the middleware dropped blocks. The backlog is now held in the node, bounded by
``acquisition_hold_s`` (at the bound each block handed in replays two held ones: ``core.hold_bound_replays``, the
input then waits in the subscription's queue, and what it loses is counted as input lost). The end-of-stream
report waits for the replay.

Taking the input: after each block the executor hands over, the node takes the blocks already waiting in the
subscription (up to ``DRAIN_BLOCKS``; ``blocks_taken_in_a_row``) instead of one per executor turn: a node behind
its input (1000 blocks a second) then spends its time on them rather than on rclpy's wait-set turns.

Output: each CorrelatorArray is published serialised, written from the interval's arrays
(:mod:`gnss_correlator.correlator_cdr`: the bytes of its ``correlator_array``), not built field by field.

Diagnostics (every ``diagnostics_period_s`` of accepted stamp time): the counters, the tracked PRNs;
ERROR after a core error since the last report, WARN when more than ``warn_rejected_fraction`` of the
blocks of the last ``diagnostics_window_s`` were rejected, else OK; STALE (node clock) when no block
arrived for ``input_timeout_s`` of wall time.
"""

from __future__ import annotations

import os
import sys
import time
from collections import Counter

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.serialization import deserialize_message

from gnss_correlator import tracking
from gnss_correlator.acquisition import MIN_SAMPLE_RATE_HZ
from gnss_correlator.correlator_cdr import CorrelatorArrayWriter, correlator_array_bytes
from gnss_correlator.node_params import CorrelatorNodeParams
from gnss_correlator.receiver import CorrelatorInterval, IfBlock, Receiver, continues
from rfi_msgs.msg import CorrelatorArray, IfSamples
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
from rfi_node_common.if_blocks import check_block, decode_counts, exceeds_bits, is_blank
from rfi_node_common.input_checks import STAMP_REASONS, StampGate
from rfi_node_common.inputs import InputHealth, StaleInputWatch, subscribe_input
from rfi_node_common.main import run_node
from rfi_node_common.params import RuntimeParameters, changed_names, declare
from rfi_node_common.qos import DATA_QOS, DIAGNOSTICS_QOS
from rfi_node_common.stamps import NS_PER_S

TOPICS = """topics:
  subscribes /rfi/if_samples (rfi_msgs/IfSamples)
  publishes  /gnss/correlators (rfi_msgs/CorrelatorArray), /diagnostics (diagnostic_msgs/DiagnosticArray)"""

IF_TOPIC = 'rfi/if_samples'
OUTPUT_TOPIC = 'gnss/correlators'
BLOCK_REASONS = ('unknown_sample_format', 'bad_bits_per_sample', 'bad_sample_rate', 'bad_intermediate_frequency',
                 'bad_scale', 'bad_center_frequency', 'empty_block', 'truncated_sample', 'odd_length_iq',
                 'short_block', 'long_block', 'bad_first_sample_index', 'values_exceed_bits', 'blank_block',
                 'rate_below_2mhz', 'band_outside_nyquist', 'stamp_malformed', *STAMP_REASONS)
"""Why a block is rejected (``rejected_<reason>``, module docstring)."""

DRAIN_BLOCKS = 100
"""Blocks waiting in the subscription taken after each block the executor hands over, at most (module docstring):
0.1 s of 1-ms blocks, so the timers and the replay still get their turns."""

REPLAY_BLOCKS_PER_CALLBACK = 10
"""Blocks held during a first acquisition answered per callback after it (module docstring): the executor takes
the input between two such callbacks, and the arrays leave at that pace, not in one burst of thousands that a
subscriber's 1000-message queue would lose."""


def block_problem(msg: IfSamples, doppler_max_hz: float, max_block_samples: int) -> str | None:
    """Why a block cannot be correlated (a key of :data:`BLOCK_REASONS` without the stamp ones), or None."""
    reason = check_block(msg, 1, max_block_samples)
    if reason is not None:
        return reason
    if msg.sample_rate_hz < MIN_SAMPLE_RATE_HZ:
        return 'rate_below_2mhz'
    fs, if_hz = msg.sample_rate_hz, abs(msg.intermediate_frequency_hz)
    if msg.is_complex:
        if if_hz + doppler_max_hz >= fs / 2:
            return 'band_outside_nyquist'
    elif not (if_hz - doppler_max_hz > 0 and if_hz + doppler_max_hz < fs / 2):
        return 'band_outside_nyquist'
    counts = decode_counts(msg)
    if exceeds_bits(counts, msg.bits_per_sample):
        return 'values_exceed_bits'
    if is_blank(counts, msg.is_complex):
        return 'blank_block'
    return None


class GnssCorrelatorNode(Node):
    """Thin node around the receiver (module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__('gnss_correlator', **kwargs)
        self.params = declare(self, CorrelatorNodeParams)
        tracking.warm_up()  # the kernel loaded now, not at the stream's first tracked block
        # the first acquisition of a stream runs in the receiver's worker thread; it triggers this when done
        self._search_done = self.create_guard_condition(self._poll_receiver)
        self.receiver = self._new_receiver()
        self.counts: Counter[str] = Counter()
        for key in ('blocks_received', 'blocks_processed', 'core_errors', 'stamp_restarts', 'arrays_published',
                    'blocks_taken_before_replay', 'blocks_taken_in_a_row'):
            self.counts[key] += 0
        for reason in BLOCK_REASONS:
            self.counts[f'rejected_{reason}'] += 0
        self.gate = StampGate(self.params.max_stamp_jump_s, self.params.stamp_jump_confirmations)
        self._window = CountWindow(self.params.diagnostics_window_s)
        self.runtime = RuntimeParameters(self, self.params)
        self._diag_timer = StampTimer(self.params.diagnostics_period_s)
        self._errors_at_report = 0
        self.health = InputHealth()
        self.publisher = self.create_publisher(CorrelatorArray, OUTPUT_TOPIC, DATA_QOS)
        self._writer = CorrelatorArrayWriter(self.params.frame_id)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        # raw: bytes that rclpy cannot deserialise are then received and counted (rejected_malformed_message); a
        # typed subscription would lose them unseen
        self.subscription = subscribe_input(self, IfSamples, IF_TOPIC, self.on_raw_block, self.health, raw=True,
                                            warning_throttle_s=self.params.warning_throttle_s)
        self.stale_watch = StaleInputWatch(self, self.health, self.params.input_timeout_s, self._publish_stale)
        self._draining = False  # in a take_pending of the subscription (on_raw_block, _poll_receiver)
        self._pending: list[IfBlock] = []  # accepted blocks gathered for the receiver (module docstring)
        self._blocks_in_search = 0  # blocks handed to the receiver while its first acquisition runs (it holds them)
        self._pending_samples = 0
        self._last_block_at = time.monotonic()
        self._idle_report_ns: int | None = None  # stamp of the last block accepted since the last idle report
        self._idle_timer = self.create_timer(self.params.idle_flush_ms * 5e-4, self._flush_when_idle)

    def _reject(self, reason: str) -> None:
        self.counts[f'rejected_{reason}'] += 1
        self.get_logger().warning(f'IF block rejected: {reason}', throttle_duration_sec=self.params.warning_throttle_s)

    def on_raw_block(self, raw: bytes | IfSamples) -> None:
        """A block from the executor: handled (:meth:`_take_block`), then up to ``DRAIN_BLOCKS`` more that wait in
        the subscription (``blocks_taken_in_a_row``, module docstring)."""
        self._take_block(raw)
        if not self._draining:
            self._draining = True
            try:
                self.counts['blocks_taken_in_a_row'] += self.subscription.take_pending(limit=DRAIN_BLOCKS)
            finally:
                self._draining = False

    def _take_block(self, raw: bytes | IfSamples) -> None:
        """A serialised block: deserialised by rclpy and handed to :meth:`on_block`, or counted as received and
        ``rejected_malformed_message`` (a message object, as an in-process hand-over may give, goes straight on)."""
        if isinstance(raw, IfSamples):
            self.on_block(raw)
            return
        try:
            msg = deserialize_message(raw, IfSamples)
        except Exception as err:  # noqa: BLE001 - rclpy raises RMWError (and others) on malformed CDR
            self.counts['blocks_received'] += 1
            self.counts['rejected_malformed_message'] += 1
            self.get_logger().warning(f'IF block rejected: malformed message ({len(raw)} bytes: {type(err).__name__})',
                                      throttle_duration_sec=self.params.warning_throttle_s)
            return
        self.on_block(msg)

    def on_block(self, msg: IfSamples) -> None:
        """One IfSamples block: check, correlate, publish the completed intervals."""
        if self.runtime.pending:  # between two blocks: the safe point for a parameter change
            self.runtime.apply_pending(self._apply_parameters)
        self.counts['blocks_received'] += 1
        if msg.header.stamp.nanosec >= NS_PER_S:
            self._reject('stamp_malformed')
            return
        reason = block_problem(msg, self.params.doppler_max_hz, self.params.max_block_samples)
        if reason is not None:
            self._reject(reason)
            return
        stamp_ns = msg.header.stamp.sec * NS_PER_S + msg.header.stamp.nanosec
        decision = self.gate.admit(stamp_ns)
        if decision.reason is not None:
            self._reject(decision.reason)
            return
        if decision.restart:
            self._flush()  # the blocks before the jump belong to the old time line
            self.counts['stamp_restarts'] += 1
            self.receiver.close()
            self.receiver = self._new_receiver()
        counts = decode_counts(msg).astype('float64') * msg.scale
        samples = counts[0::2] + 1j * counts[1::2] if msg.is_complex else counts
        block = IfBlock(stamp_ns=stamp_ns, sample_rate_hz=msg.sample_rate_hz,
                        intermediate_frequency_hz=msg.intermediate_frequency_hz, is_complex=msg.is_complex,
                        first_sample_index=int(msg.first_sample_index), samples=samples)
        if self._pending and not continues(self._pending[-1], block):
            self._flush()
        self._pending.append(block)
        self._pending_samples += samples.size
        self._last_block_at = time.monotonic()
        self._idle_report_ns = stamp_ns
        if self._pending_samples >= self.params.batch_ms * 1e-3 * block.sample_rate_hz:
            self._flush()
        if self._diag_timer.due(stamp_ns):
            self.diag_pub.publish(self.diagnostics(stamp_ns))

    def _new_receiver(self) -> Receiver:
        # the blocks handed in after the first search are held, not replayed: _poll_receiver replays them after
        # taking the input that waits (module docstring)
        return Receiver(self.params.receiver(), on_search_done=self._search_done.trigger, replay_per_block=0)

    def _flush(self) -> None:
        """Hand the gathered blocks to the receiver as one, publish the completed intervals."""
        if not self._pending:
            return
        blocks, self._pending, self._pending_samples = self._pending, [], 0
        first = blocks[0]
        samples = first.samples if len(blocks) == 1 else np.concatenate([b.samples for b in blocks])
        try:
            intervals = self.receiver.process(IfBlock(
                stamp_ns=first.stamp_ns, sample_rate_hz=first.sample_rate_hz,
                intermediate_frequency_hz=first.intermediate_frequency_hz, is_complex=first.is_complex,
                first_sample_index=first.first_sample_index, samples=samples))
        except Exception as err:  # noqa: BLE001 - a core fault must not end the node (module docstring)
            self._core_failed(err, len(blocks))
            return
        self.counts['blocks_processed'] += len(blocks)
        self._blocks_in_search = self._blocks_in_search + len(blocks) if self.receiver.acquiring else 0
        self._publish(intervals)

    def _poll_receiver(self) -> None:
        """The receiver's first acquisition ended (its worker triggered the guard condition): first the input
        waiting in the subscription is taken (held by the receiver), then ``REPLAY_BLOCKS_PER_CALLBACK`` of the
        blocks it holds are answered (module docstring)."""
        self._draining = True  # each block taken here is held: no drain after each
        try:
            self.counts['blocks_taken_before_replay'] += self.subscription.take_pending()
        finally:
            self._draining = False
        try:
            intervals = self.receiver.poll(max_blocks=REPLAY_BLOCKS_PER_CALLBACK)
        except Exception as err:  # noqa: BLE001 - a core fault must not end the node (module docstring)
            self._core_failed(err, 0)
            return
        if not self.receiver.acquiring:
            self._blocks_in_search = 0
        self._publish(intervals)
        if self.receiver.poll_ready:  # more held: after the input that arrived meanwhile
            self._search_done.trigger()

    def _core_failed(self, err: Exception, blocks: int) -> None:
        """A receiver fault on ``blocks`` blocks handed in now: counted with those it held for its first
        acquisition (counted processed when handed in), logged, the receiver rebuilt."""
        self.counts['blocks_processed'] -= self._blocks_in_search
        blocks += self._blocks_in_search
        self._blocks_in_search = 0
        self.counts['core_errors'] += blocks
        self.get_logger().error(f'receiver failed on {blocks} blocks ({type(err).__name__}: {err}); restarted')
        self.receiver.close()
        self.receiver = self._new_receiver()

    def _publish(self, intervals: list[CorrelatorInterval]) -> None:
        """Each interval as one CorrelatorArray, published serialised (:func:`correlator_array_bytes`)."""
        if self._writer.frame_id != self.params.frame_id:
            self._writer = CorrelatorArrayWriter(self.params.frame_id)
        for interval in intervals:
            self.publisher.publish(correlator_array_bytes(interval, self._writer))
            self.counts['arrays_published'] += 1

    def _flush_when_idle(self) -> None:
        """The end of a stream (no block for ``idle_flush_ms``): process what is gathered, report once."""
        idle_s = time.monotonic() - self._last_block_at
        if self._idle_report_ns is not None and idle_s >= self.params.idle_flush_ms * 1e-3:
            self._flush()
            if self.receiver.acquiring:  # the blocks it holds are answered when the search ends: report then
                return
            self.diag_pub.publish(self.diagnostics(self._idle_report_ns))
            self._idle_report_ns = None

    def _apply_parameters(self, old: CorrelatorNodeParams, new: CorrelatorNodeParams) -> None:
        """A change of the settable parameters (the diagnostics ones of NodeDiagnosticsParams)."""
        self.params = new
        self._window.window_ns = int(round(new.diagnostics_window_s * 1e9))
        self.get_logger().info('parameters changed: ' + ', '.join(
            f'{name} = {getattr(new, name)!r}' for name in changed_names(old, new)))

    def destroy_node(self) -> None:
        """Stop the receiver's reacquisition worker, then destroy the node."""
        self.receiver.close()
        super().destroy_node()

    def _values(self) -> dict[str, object]:
        values: dict[str, object] = dict(self.counts)
        values.update({f'core.{k}': v for k, v in self.receiver.counts.items()})
        values['tracked_prns'] = ' '.join(str(p) for p in self.receiver.tracked_prns)
        values.update(self.health.values())
        rejected = sum(v for k, v in self.counts.items() if k.startswith('rejected_'))
        values['blocks_pending'] = len(self._pending)
        values['blocks_held_for_acquisition'] = self._blocks_in_search
        # every block that reached the subscription reached the handler, and each was processed, rejected (with
        # its reason), failed in the receiver (counted, restarted) or is gathered for the next call
        values['accounting_ok'] = (
            self.health.counts[f'{self.subscription.topic_name}.received'] == self.counts['blocks_received']
            == self.counts['blocks_processed'] + rejected + self.counts['core_errors'] + len(self._pending))
        return values

    def diagnostics(self, stamp_ns: int) -> DiagnosticArray:
        """The /diagnostics report at ``stamp_ns`` (module docstring)."""
        values = self._values()
        rejected = sum(v for k, v in self.counts.items() if k.startswith('rejected_'))
        w = self._window.update(stamp_ns, {'received': self.counts['blocks_received'], 'rejected': rejected})
        errors = self.counts['core_errors'] - self._errors_at_report
        self._errors_at_report = self.counts['core_errors']
        if errors:
            level, text = ERROR, f'{errors} receiver faults since the last report (restarted)'
        else:
            degraded = degraded_inputs([('rejected blocks', w['rejected'], w['received'])],
                                       self.params.warn_rejected_fraction)
            level, text = (WARN, 'inputs degraded: ' + '; '.join(degraded)) if degraded else (OK, 'correlating')
        return diagnostic_array(stamp_ns, 'gnss_correlator', self.params.hardware_id, level,
                                f'{text}; tracking PRN {values["tracked_prns"] or "none"}', values)

    def _publish_stale(self, silent_s: float) -> None:
        self.diag_pub.publish(diagnostic_array(
            self.get_clock().now().nanoseconds, 'gnss_correlator', self.params.hardware_id, STALE,
            f'no input on {self.subscription.topic_name} for {silent_s:.1f} s (wall clock)', self._values()))


PROFILE_ENV = 'GNSS_CORRELATOR_PROFILE'
"""Environment variable: a path; when set, the node's executor thread runs under cProfile (timed by the thread's CPU
time) and its statistics are written there at exit (``python -m pstats PATH``), to see where a live stream's CPU
goes."""


GIL_SWITCH_INTERVAL_S = 0.0005
"""The interpreter's switch interval in the node's process, s (Python's default 0.005): while the acquisition worker
runs Python code, the executor thread, back from each wait for a message, waits for the GIL up to this long; at
the default, at most ~200 messages a second were taken during a first acquisition (docs/gnss_correlator/
live_stream.md)."""


def main(argv=None) -> int:
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
    path = os.environ.get(PROFILE_ENV)
    if not path:
        return _run(argv)
    import cProfile
    profile = cProfile.Profile(time.thread_time)  # CPU time of the executor thread, not wall time
    profile.enable()
    try:
        return _run(argv)
    finally:
        profile.disable()
        profile.dump_stats(path)


def _run(argv=None) -> int:
    return run_node(GnssCorrelatorNode, executable='gnss_correlator_node', params_cls=CorrelatorNodeParams,
                    topics=TOPICS, summary='GPS L1 C/A correlators (acquisition, DLL, FLL-assisted PLL) from the '
                    'front-end IF stream, for imm_carrier.', argv=argv)
