"""ROS node ``if_source``: a capture file, standard input or a named pipe -> /rfi/if_samples (rfi_msgs/IfSamples).

Thin: the bytes are read and cut into blocks by :mod:`rfi_experiments.if_formats` (formats, unpacking,
stamps, gap detection); this node declares the parameters, runs the reading loop on a thread of its own
(a blocking read of a pipe must not stall the executor), publishes and reports /diagnostics.

Input (``input``): a file path, ``-`` for standard input, or a named pipe. A regular file is checked first
(its size must be a whole number of items, usually a wrong ``item_type`` otherwise) and read to its end;
standard input (unless redirected from a regular file, which is read like that file) and pipes are live
streams: ``rtl_sdr -f 1575420000 -s 2048000 - | ros2 run rfi_experiments
if_source --ros-args -p item_type:=uibyte -p sampling_frequency_hz:=2048000.0``. At the end of the input
the node reports its counters and, with ``exit_at_end`` (default), shuts down (exit code 0).

Pacing (``pace``): ``real_time`` publishes each block of a file when it would have been complete had the
capture been live (block end time after the first block's start, on the steady clock); ``max`` publishes as
fast as it reads, and with ``reliability`` ``reliable`` waits every ACK_EVERY_BLOCKS (500, half the queue
depth) blocks and at the end until each matched subscriber has acknowledged them, so the publisher's queue
never overwrites a block a subscriber has not received (waiting after every block would cost a DDS heartbeat
period, 3 s with Fast DDS, per block). A subscriber that does not drain its own queue (the monitor's: 1000
blocks) in time loses blocks and counts them as lost; to lose nothing whatever the subscriber's speed, write a
bag with ``if_to_bag`` and play it with ``play`` / ``run``. A live stream is paced by its source in both modes.
``wait_for_subscribers`` (default 0) holds the input until that many subscribers have matched (a file
replayed into a monitor started at the same time loses nothing), for at most ``wait_timeout_s``, then
``SUBSCRIBER_SETTLE_S`` more: discovery completes on each side separately, and a subscriber this publisher has
matched may not yet have matched it (measured: a 38.192 MS/s best-effort stream into a monitor started with it lost
its first 99 blocks, never seen by the monitor, so never counted there).

QoS (``reliability``): ``reliable`` (default: the suite's DATA_QOS, reliable, keep last 1000) or
``best_effort`` (rclpy's sensor-data profile, REP 2003: a slow subscriber loses blocks instead of slowing
the source; the monitor counts them as gaps and lost messages).

Stamps: ``start_time`` (ISO 8601 UTC ``2021-12-02T08:47:00Z`` or Unix seconds) is the time of the first
sample; empty: the node's ROS clock when the first byte arrives (a live SDR). Every block's stamp is
``start + first_sample_index / sampling_frequency_hz`` (ROS time, UTC based). A sampling clock that is off
by d ppm moves these stamps away from the wall clock by d ppm of the run.

Gaps (live streams only): :class:`rfi_experiments.if_formats.LiveLag` compares the samples received (and
still waiting in the pipe) with what ``sampling_frequency_hz`` delivers in the elapsed steady time; a lag of
more than ``gap_tolerance_s`` is declared a gap before the bytes of the read that revealed it (where in the
stream the samples went missing is known only to within the pipe's content, 64 KiB by default):
``first_sample_index`` jumps by the missing samples (the monitor sees the jump and resets its tracker), the
unfinished block is dropped, and ``gaps`` / ``samples_lost`` / ``samples_dropped_at_gap`` count it. A pipe
found full after a read (the reader fell behind; the writer is blocked and an SDR tool then drops samples) is
counted as ``pipe_full_reads``.

Diagnostics (/diagnostics, name ``if_source``, every ``diagnostics_period_s`` of stamp time and at the end):
bytes_in, blocks, samples, blocks_published, gaps, samples_lost, samples_dropped_at_gap, partial_item_reads,
pipe_full_reads, final_partial_block_samples, trailing_bytes (the input ended inside an item), and for
gr_complex rounded_values, clipped_values, non_finite_values; lag_s, ahead_rebases, subscribers, read_errors.
Level: ERROR after a read error, WARN after gaps, trailing bytes or an inexact float conversion, else OK.
"""

from __future__ import annotations

import fcntl
import os
import termios
import threading
import time
from collections import Counter
from dataclasses import dataclass
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data

from rfi_experiments.if_formats import (
    ITEM_TYPES,
    BlockAssembler,
    FormatError,
    IfBlock,
    IfFormat,
    LiveLag,
    check_file_size,
    is_live,
    parse_start_time,
)
from rfi_experiments.source_start import SubscriberWaitParams, wait_for_subscribers
from rfi_msgs.msg import IfSamples
from rfi_node_common.diagnostics import (
    StampTimer,
    counted_level,
    diagnostics_period_parameter,
    hardware_id_parameter,
    publish_status,
)
from rfi_node_common.main import run_node
from rfi_node_common.params import USER, ConfigFile, declare, parameter, parameter_from, validate_ranges
from rfi_node_common.qos import DATA_QOS, DIAGNOSTICS_QOS
from rfi_node_common.stamps import ns_to_stamp

TOPICS = """topics:
  publishes  /rfi/if_samples (rfi_msgs/IfSamples), /diagnostics (diagnostic_msgs/DiagnosticArray)"""

IF_TOPIC = 'rfi/if_samples'
"""Output topic, relative (follows the node's namespace, as the monitor's input does)."""

READ_BYTES = 1 << 16
"""Bytes asked of one read (a pipe's default capacity on Linux)."""

ACK_TIMEOUT_S = 30.0
"""Longest wait for the subscribers' acknowledgements (``max`` pace and end of input, reliable), s; then
``unacknowledged_waits`` counts it and reading goes on."""

SUBSCRIBER_SETTLE_S = 0.5
"""After ``wait_for_subscribers`` have matched, the input waits this much longer before reading, s (module
docstring)."""

ACK_EVERY_BLOCKS = 500
"""In ``max`` pace (reliable), wait for the acknowledgements after this many blocks (half DATA_QOS's depth)."""

FORMAT_FIELDS = ('item_type', 'sampling_frequency_hz', 'intermediate_frequency_hz', 'center_frequency_hz',
                 'spectral_inversion', 'sample_type', 'big_endian_bytes', 'big_endian_items', 'bits_per_sample',
                 'scale', 'float_counts_per_unit')
"""Parameters that are :class:`rfi_experiments.if_formats.IfFormat` fields (shared with if_to_bag)."""


@dataclass(frozen=True)
class IfSourceParams:
    """Parameters of if_source (``--help`` lists them; if_to_bag takes the format ones as options). The format
    parameters with a default are :class:`rfi_experiments.if_formats.IfFormat`'s, written there once."""

    input: str = parameter(
        '-', 'Capture file, "-" for standard input, or a named pipe. Standard input and pipes are live streams '
        '(paced by their source, gaps detected); standard input redirected from a regular file is a file.',
        group=USER)
    item_type: str = parameter(
        'ibyte', 'Layout of the bytes (rfi_experiments.if_formats): byte (int8 real: PocketSDR -I files), ibyte / '
        'cbyte (int8 I,Q: PocketSDR IQ files, hackrf_transfer), short, ishort / cshort (int16 LE; UHD sc16), '
        'gr_complex (float32 I,Q), uibyte (uint8 I,Q with zero at 127.5: rtl_sdr), two_bit_packed, '
        "two_bit_packed_short and four_bit_cpx (GNSS-SDR's packed file sources).",
        choices=tuple(ITEM_TYPES), group=USER)
    sampling_frequency_hz: float = parameter(
        4.0e6, 'Samples per second (complex: I/Q pairs per second), Hz.', minimum=1.0e5, maximum=1.0e11, group=USER)
    intermediate_frequency_hz: float = parameter_from(IfFormat, 'intermediate_frequency_hz')
    center_frequency_hz: float = parameter_from(IfFormat, 'center_frequency_hz')
    spectral_inversion: bool = parameter_from(IfFormat, 'spectral_inversion')
    sample_type: str = parameter_from(IfFormat, 'sample_type')
    big_endian_bytes: bool = parameter_from(IfFormat, 'big_endian_bytes')
    big_endian_items: bool = parameter_from(IfFormat, 'big_endian_items')
    bits_per_sample: int = parameter_from(IfFormat, 'bits_per_sample')
    scale: float = parameter_from(IfFormat, 'scale')
    float_counts_per_unit: float = parameter_from(IfFormat, 'float_counts_per_unit')
    block_duration_s: float = parameter(
        0.001, 'Duration of one published block, s (rounded to whole samples). The monitor needs at least '
        'min_block_samples (1024) per block.', minimum=1.0e-6, maximum=10.0)
    start_time: str = parameter(
        '', 'Time of the first sample: ISO 8601 UTC (2021-12-02T08:47:00Z) or Unix seconds written as a string '
        '("\'1638434820.5\'" on the command line); empty: the ROS clock when the first byte arrives. Stamps are '
        'start + first_sample_index / sampling_frequency_hz (ROS time, UTC based).', group=USER)
    pace: str = parameter(
        'real_time', 'real_time: a file is published at its sample rate; max: as fast as the subscribers take '
        'it (reliable: acknowledged every 500 blocks and at the end). A live stream is paced by its source.',
        choices=('real_time', 'max'), group=USER)
    reliability: str = parameter(
        'reliable', 'QoS of /rfi/if_samples: reliable (keep last 1000) or best_effort (sensor data profile).',
        choices=('reliable', 'best_effort'))
    wait_for_subscribers: int = parameter(
        0, 'Hold the input until this many subscribers of /rfi/if_samples have matched (1: wait for the '
        'monitor), for at most wait_timeout_s.', minimum=0, maximum=1000)
    wait_timeout_s: float = parameter_from(SubscriberWaitParams, 'wait_timeout_s')
    gap_tolerance_s: float = parameter(
        0.5, 'Live streams: a lag of the samples received behind the sample rate of more than this is declared a '
        'gap (first_sample_index jumps, gaps and samples_lost counted), s; 0: no gap detection. It must cover the '
        "SDR tool's buffering and the sampling clock's drift over a run (50 ppm x 1 h = 0.18 s).",
        minimum=0.0, maximum=3600.0)
    frame_id: str = parameter(
        'gnss_front_end', 'header.frame_id of the blocks (the front end / antenna).', group=USER)
    hardware_id: str = hardware_id_parameter('rf_front_end', read_only=True)
    diagnostics_period_s: float = diagnostics_period_parameter()
    exit_at_end: bool = parameter(True, 'Shut the node down at the end of the input (exit code 0).')

    def __post_init__(self) -> None:
        validate_ranges(self)
        fmt = self.format()
        fmt.block_samples(self.block_duration_s)
        if self.start_time:
            parse_start_time(self.start_time)

    def format(self) -> IfFormat:
        """The input format (raises FormatError, a ValueError, on a combination that cannot be)."""
        return IfFormat(**{name: getattr(self, name) for name in FORMAT_FIELDS})


CONFIG_FILE = ConfigFile('rfi_experiments', 'config/if_source.yaml', 'if_source', IfSourceParams, """
Parameters of if_source (rfi_experiments/if_source.py, IfSourceParams): a capture file, standard input or
a named pipe -> /rfi/if_samples (rfi_msgs/IfSamples). The byte layouts: rfi_experiments/if_formats.py.
GENERATED by tools/generate_config.py from the parameter definitions: the format's in
rfi_experiments/if_formats.py (IfFormat), the node's own in if_source.py (IfSourceParams). Change a
default or a description there and run `python tools/generate_config.py`; a test checks this file
equals it.

Use:   ros2 run rfi_experiments if_source --ros-args --params-file if_source.yaml
       rtl_sdr -f 1575420000 -s 2048000 - | ros2 run rfi_experiments if_source --ros-args \\
           -p item_type:=uibyte -p sampling_frequency_hz:=2048000.0
Every value below is the default; the user parameters (the input, its format, its start time) come
first. All parameters are read once at start-up. A value that cannot describe a capture stops the
node with a one-line error naming it (exit code 2). Floats must be written with a decimal point.
if_to_bag takes the format parameters as options (--item-type, --sampling-frequency-hz, ...), with
the same meaning.
""")
"""The shipped config/if_source.yaml (:func:`rfi_node_common.params.config_yaml`)."""


def block_message(block: IfBlock, fmt: IfFormat, frame_id: str) -> IfSamples:
    """An :class:`IfBlock` of format ``fmt`` as rfi_msgs/IfSamples (the one conversion; if_to_bag uses it)."""
    m = IfSamples()
    m.header.stamp = ns_to_stamp(block.stamp_ns)
    m.header.frame_id = frame_id
    m.sample_rate_hz = float(fmt.sampling_frequency_hz)
    m.intermediate_frequency_hz = fmt.published_intermediate_frequency_hz
    m.center_frequency_hz = float(fmt.center_frequency_hz)
    m.is_complex = fmt.is_complex
    m.first_sample_index = int(block.first_sample_index)
    m.scale = fmt.published_scale
    m.bits_per_sample = fmt.published_bits_per_sample
    m.sample_format = fmt.sample_format
    m.samples = block.counts.astype(fmt.dtype, copy=False).tobytes()
    return m


def pipe_capacity(fd: int) -> int | None:
    """Capacity of the pipe behind ``fd``, bytes, or None (not a pipe, or not Linux)."""
    try:
        return int(fcntl.fcntl(fd, getattr(fcntl, 'F_GETPIPE_SZ', 1032)))
    except OSError:
        return None


def bytes_waiting(fd: int) -> int:
    """Bytes readable without blocking (FIONREAD), 0 if unknown."""
    try:
        buf = fcntl.ioctl(fd, termios.FIONREAD, b'\0\0\0\0')
        return int.from_bytes(buf, 'little', signed=True)
    except OSError:
        return 0


class IfSourceNode(Node):
    """Publishes the blocks of a capture file or live stream (module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('if_source', **kwargs)
        self.params = declare(self, IfSourceParams)
        p = self.params
        self.fmt = p.format()
        self.block_samples = self.fmt.block_samples(p.block_duration_s)
        self.live = is_live(p.input)
        if not self.live and p.input != '-':
            check_file_size(p.input, self.fmt, self.block_samples)
        self.start_ns = parse_start_time(p.start_time) if p.start_time else None
        qos = DATA_QOS if p.reliability == 'reliable' else qos_profile_sensor_data
        self.pub = self.create_publisher(IfSamples, IF_TOPIC, qos)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self.counts: Counter[str] = Counter()
        self.assembler: BlockAssembler | None = None
        self.lag = LiveLag(self.fmt.sampling_frequency_hz, p.gap_tolerance_s) if p.gap_tolerance_s > 0 else None
        self._timer = StampTimer(p.diagnostics_period_s)
        self._last_stamp_ns = 0
        self.stop = threading.Event()
        self.done = threading.Event()
        """Set when the input has ended and the final diagnostics are out."""
        self._fd: int | None = None
        self._own_fd = False
        if p.input == '-':
            self._fd = 0
        elif self.live and os.path.exists(p.input):
            pass  # a named pipe: opened by the reader thread (opening blocks until a writer opens it)
        else:
            try:
                self._fd = os.open(p.input, os.O_RDONLY)
            except OSError as err:
                raise ValueError(f'input {p.input}: {err.strerror}') from None
            self._own_fd = True
        self._thread = threading.Thread(target=self._run, name='if_source_reader', daemon=True)
        # started by the executor's first spin, after main() has checked the parameters (a misspelt -p
        # must not have consumed the input)
        self._start_timer = self.create_timer(0.0, self._start_reading)

    def _start_reading(self) -> None:
        self._start_timer.cancel()
        if self._thread.ident is None:  # never started
            self._thread.start()

    # --------------------------------------------------------------------------------------------- reading
    def _run(self) -> None:
        try:
            wait_for_subscribers(self.pub, self.params.wait_for_subscribers, self.params.wait_timeout_s, self.stop,
                                 self.get_logger(), settle_s=SUBSCRIBER_SETTLE_S)
            if not self.stop.is_set():
                self._read_loop()
        except Exception as err:  # noqa: BLE001 - a read or publish failure ends the input, reported
            self.counts['read_errors'] += 1
            self.get_logger().error(f'input {self.params.input} ended by {type(err).__name__}: {err}')
        finally:
            if self.assembler is not None:
                self.assembler.finish()
            try:
                if not self.stop.is_set():  # not while the node is being destroyed
                    self._wait_for_acks()
                self._report_end()
                if not self.stop.is_set():  # the final report delivered before exit_at_end ends the process
                    self._wait_for_acks(self.diag_pub)
            except Exception as err:  # noqa: BLE001 - the node may be going away under the reader
                self.get_logger().error(f'end of input not reported: {type(err).__name__}: {err}')
            self.done.set()
            if self.params.exit_at_end and not self.stop.is_set() and self.context.ok():
                self.get_logger().info('end of input: shutting down (exit_at_end)')
                self.context.try_shutdown()

    def _wait_for_acks(self, pub: Any = None) -> None:
        """Wait for the reliable subscribers of ``pub`` (the blocks by default) to acknowledge what was sent, at most
        ACK_TIMEOUT_S. The final /diagnostics (always reliable) too: without that wait the process could exit
        before the end-of-input report reached a subscriber (test_if_source_pipe, 1 of 1 runs beside a hog at load
        15: every block received, the final report never)."""
        if pub is None:
            if self.params.reliability != 'reliable':
                return
            pub = self.pub
        if pub.get_subscription_count() > 0 and not pub.wait_for_all_acked(_duration(ACK_TIMEOUT_S)):
            self.counts['unacknowledged_waits'] += 1

    def _read_loop(self) -> None:
        if self._fd is None:  # a named pipe
            self._fd = os.open(self.params.input, os.O_RDONLY)
            self._own_fd = True
        fd = self._fd
        capacity = pipe_capacity(fd) if self.live else None
        t_first: float | None = None
        while not self.stop.is_set():
            data = os.read(fd, READ_BYTES)
            if not data:
                return
            now = time.monotonic()
            if self.assembler is None:
                start = self.start_ns if self.start_ns is not None else self.get_clock().now().nanoseconds
                self.assembler = BlockAssembler(self.fmt, self.block_samples, start)
                t_first = now
            asm = self.assembler
            if self.live:
                waiting = bytes_waiting(fd)
                if capacity and waiting >= capacity:
                    self.counts['pipe_full_reads'] += 1
                if self.lag is not None:
                    unread = (asm.pending_bytes + len(data) + waiting) // self.fmt.chunk_bytes
                    seen = asm.next_sample_index + unread * self.fmt.chunk_samples
                    missing = self.lag.update(now, seen)
                    if missing:  # placed before this read's bytes (uncertain by the pipe's content)
                        asm.skip(missing)
                        self.get_logger().warn(f'live input fell {missing / self.fmt.sampling_frequency_hz:.3f} s '
                                               f'behind the sample rate: gap of {missing} samples declared')
            self._publish_all(asm.feed(data), t_first)

    def _publish_all(self, blocks: list[IfBlock], t_first: float | None) -> None:
        for block in blocks:
            if self.stop.is_set():
                return
            if not self.live and self.params.pace == 'real_time' and t_first is not None:
                due = t_first + (block.first_sample_index + block.n_samples) / self.fmt.sampling_frequency_hz
                delay = due - time.monotonic()
                if delay > 0 and self.stop.wait(delay):
                    return
            self.pub.publish(block_message(block, self.fmt, self.params.frame_id))
            self.counts['blocks_published'] += 1
            if self.params.pace == 'max' and self.counts['blocks_published'] % ACK_EVERY_BLOCKS == 0:
                self._wait_for_acks()
            self._last_stamp_ns = block.stamp_ns
            if self._timer.due(block.stamp_ns):
                self._publish_diagnostics(block.stamp_ns, final=False)

    # --------------------------------------------------------------------------------------------- reporting
    def values(self) -> dict[str, object]:
        """Counters of the reader and of the node."""
        v: dict[str, object] = {}
        asm = self.assembler.counters if self.assembler is not None else Counter()
        for key in ('bytes_in', 'blocks', 'samples', 'gaps', 'samples_lost', 'samples_dropped_at_gap',
                    'partial_item_reads', 'final_partial_block_samples', 'trailing_bytes'):
            v[key] = asm.get(key, 0)
        if self.fmt.item_type == 'gr_complex':
            for key in ('rounded_values', 'clipped_values', 'non_finite_values'):
                v[key] = asm.get(key, 0)
        for key in ('blocks_published', 'pipe_full_reads', 'read_errors', 'unacknowledged_waits'):
            v[key] = self.counts.get(key, 0)
        v['lag_s'] = round(self.lag.lag_s, 6) if self.lag is not None else 'off'
        v['ahead_rebases'] = self.lag.ahead_rebases if self.lag is not None else 0
        v['subscribers'] = self.pub.get_subscription_count()
        v['input'] = self.params.input
        v['item_type'] = self.fmt.item_type
        return v

    def level(self) -> tuple[bytes, str]:
        v = self.values()
        return counted_level(v, ('gaps', 'trailing_bytes', 'rounded_values', 'clipped_values', 'non_finite_values',
                                 'pipe_full_reads', 'unacknowledged_waits'),
                             'the input failed' if v['read_errors'] else None)

    def _publish_diagnostics(self, stamp_ns: int, final: bool) -> None:
        level, text = self.level()
        publish_status(self, self.diag_pub, stamp_ns, 'if_source', self.params.hardware_id, level, text,
                       self.values(), final)

    def _report_end(self) -> None:
        v = self.values()
        self._publish_diagnostics(self._last_stamp_ns, final=True)
        text = ', '.join(f'{k} {v[k]}' for k in ('blocks_published', 'samples', 'gaps', 'samples_lost',
                                                 'final_partial_block_samples', 'trailing_bytes'))
        self.get_logger().info(f'end of input {self.params.input}: {text}')
        if v['final_partial_block_samples']:
            self.get_logger().warn(f'the last {v["final_partial_block_samples"]} samples did not fill a block '
                                   'and were not published')
        if v['trailing_bytes']:
            self.get_logger().warn(f'the input ended inside an item: {v["trailing_bytes"]} trailing bytes ignored')

    def destroy_node(self) -> None:
        self.stop.set()
        self._start_timer.cancel()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=2.0)
        if self._own_fd and self._fd is not None and not self._thread.is_alive():  # a blocked read keeps it
            os.close(self._fd)
            self._fd = None
        super().destroy_node()


def _duration(seconds: float) -> Any:
    from rclpy.duration import Duration
    return Duration(nanoseconds=int(seconds * 1e9))


def main(argv: Any = None) -> int:
    def make() -> IfSourceNode:
        try:
            return IfSourceNode()
        except FormatError as err:
            raise ValueError(str(err)) from None
    return run_node(make, executable='if_source', params_cls=IfSourceParams, topics=TOPICS,
                    summary='Publish GNSS front-end samples from a capture file, standard input or a named pipe '
                            '(rtl_sdr, hackrf_transfer, PocketSDR, GNSS-SDR formats) as rfi_msgs/IfSamples.',
                    argv=argv)


if __name__ == '__main__':
    import sys
    sys.exit(main())

