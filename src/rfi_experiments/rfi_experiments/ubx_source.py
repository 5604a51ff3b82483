"""ROS node ``ubx_source``: a u-blox receiver (serial port) or a UBX log file -> gnss/measurements.

Thin: the bytes go to :class:`rfi_experiments.ubx_decode.UbxDecoder` (framing, pyubx2 decoding,
GPS LNAV / Galileo I/NAV ephemerides from RXM-SFRBX, epochs built by the same code as
``rinex_to_bag``); this node
declares the parameters, reads on a thread of its own (a blocking serial read must not stall the
executor), publishes and reports /diagnostics.

Outputs (relative names, so ``-r __ns:=/robot1`` moves them), all reliable:
``gnss/measurements`` (rfi_msgs/GnssMeasurementArray, one per RXM-RAWX epoch with at least
``min_satellites`` satellites; fewer are counted as ``epochs_waiting_for_ephemeris``, not
published; a satellite without a usable ephemeris, e.g. with RXM-SFRBX off, is published with NaN
satellite states and its real pseudorange, rate and C/N0 under ``publish_without_ephemeris``,
counted as ``satellites_without_ephemeris``), ``gnss/receiver_interference``
(rfi_msgs/ReceiverInterference: MON-HW, MON-RF per RF block, SEC-SIG) and
``gnss/receiver_spectrum`` (rfi_msgs/ReceiverSpectrum: MON-SPAN, one per RF block, stamped like
the interference reports with the latest RAWX epoch); /diagnostics.

Input (``input``): a serial device (``/dev/ttyACM0``, ``/dev/ttyUSB0``; ``baud_rate``), or a
UBX log file. The receiver must output UBX-RXM-RAWX (and RXM-SFRBX unless ``nav_file`` gives the
ephemerides); u-center or ``ubxtool`` configure that. A file is read to its end and published at
the pace of its RAWX epochs (``pace`` ``real_time``) or as fast as the subscribers take it
(``max``: nothing dropped for a reliable subscriber, see :data:`ACK_EVERY`); then, with ``exit_at_end``,
the node shuts down (exit code 0).

A serial port that fails (unplugged receiver, EIO) is reported (ERROR in /diagnostics and the
log, ``port_losses``) and reopened every ``reconnect_period_s``; after ``max_reconnect_attempts``
failed attempts in a row (0: none) the node logs why and exits with code 1, without a traceback.

Stamps: ROS time (UTC-based) of the receive epoch (:func:`rfi_experiments.ubx_decode.header_stamp_ns`);
GPS week and time of week are in the message fields; nothing is stamped from the wall clock.
"""

from __future__ import annotations

import math
import os
import stat
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node

from rfi_experiments.source_start import SubscriberWaitParams, wait_for_subscribers
from rfi_experiments.ubx_decode import EpochOutput, SpectrumReport, UbxDecoder, UbxDecoderParams
from rfi_msgs.msg import GnssMeasurementArray, ReceiverInterference, ReceiverSpectrum
from rfi_node_common.diagnostics import (
    StampTimer,
    counted_level,
    diagnostics_period_parameter,
    hardware_id_parameter,
    publish_status,
)
from rfi_node_common.main import run_node
from rfi_node_common.params import USER, ConfigFile, declare, parameter, parameter_from, validate_ranges
from rfi_node_common.qos import DATA_QOS, DATA_QOS_DEPTH, DIAGNOSTICS_QOS

TOPICS = """topics:
  publishes  gnss/measurements (rfi_msgs/GnssMeasurementArray), gnss/receiver_interference
             (rfi_msgs/ReceiverInterference), gnss/receiver_spectrum (rfi_msgs/ReceiverSpectrum),
             /diagnostics (diagnostic_msgs/DiagnosticArray)"""

MEASUREMENTS_TOPIC = 'gnss/measurements'
INTERFERENCE_TOPIC = 'gnss/receiver_interference'
SPECTRUM_TOPIC = 'gnss/receiver_spectrum'
READ_BYTES = 1 << 14
"""Bytes asked of one read."""
SERIAL_TIMEOUT_S = 0.1
"""Timeout of one serial read, s (the reader checks for shutdown between reads)."""
ACK_TIMEOUT_S = 30.0
"""Longest wait for the acknowledgements in ``max`` pace, s."""
ACK_EVERY = DATA_QOS_DEPTH // 2
"""``max`` pace: after this many messages on a topic the reader waits until every reliable subscriber has
acknowledged them, so the publisher's history (DATA_QOS_DEPTH) never drops one a subscriber has not taken.
Not after every message: Fast DDS acknowledges on its heartbeat period (about 3 s measured here)."""
FINAL_ACK_TIMEOUT_S = 2.0
"""At the end of the input: longest wait for reliable subscribers to acknowledge what was sent, s."""
STOP_JOIN_S = 2.0
"""At shutdown (Ctrl-C): longest wait for the reader to end and write its report, s. A reader still busy then
(compiling a kernel on its first bytes with a cold numba cache, a publish that blocks) is left to die with the
process, and the report is written from the shutdown instead, so that Ctrl-C stays prompt and the counts are
always logged."""


@dataclass(frozen=True)
class UbxSourceParams:
    """Parameters of ubx_source (``--help`` lists them). The decoder's (``min_satellites``, ``use_sfrbx``,
    ``publish_without_ephemeris``, ``use_receiver_std``) are :class:`rfi_experiments.ubx_decode.UbxDecoderParams`'s,
    written there once."""

    input: str = parameter(
        '/dev/ttyACM0', 'Serial device of the receiver (/dev/ttyACM0 for USB, /dev/ttyUSB0 or /dev/ttyS0 for UART), '
        'or a UBX log file (read to its end).', group=USER)
    baud_rate: int = parameter(
        115200, "Serial baud rate, bit/s. Must match the receiver's UART setting; USB CDC-ACM ignores it.",
        minimum=1200, maximum=4_000_000, group=USER)
    nav_file: str = parameter(
        '', 'RINEX navigation file (2.x or 3.x, GPS and other systems) with broadcast ephemerides, used together '
        "with those decoded from RXM-SFRBX (empty: only those). Give one (e.g. the day's BRDC file) to publish from "
        'the first epoch instead of after ~30 s of navigation data, or for BeiDou, QZSS and GLONASS satellites '
        '(only GPS LNAV and Galileo I/NAV are decoded from SFRBX here).', group=USER)
    use_sfrbx: bool = parameter_from(UbxDecoderParams, 'use_sfrbx')
    reference_position_ecef_m: str = parameter(
        '', 'Receiver ECEF position "X,Y,Z", m, used only to evaluate the ionosphere and troposphere models; '
        'empty: a coarse single-point fix per epoch (tens of metres are enough there).', group=USER)
    min_satellites: int = parameter_from(UbxDecoderParams, 'min_satellites')
    publish_without_ephemeris: bool = parameter_from(UbxDecoderParams, 'publish_without_ephemeris')
    use_receiver_std: bool = parameter_from(UbxDecoderParams, 'use_receiver_std')
    pace: str = parameter(
        'real_time', 'Files only: real_time publishes at the pace of the RAWX epochs (as the receiver did); max as '
        'fast as the subscribers take it (nothing dropped for a reliable subscriber). A serial port is paced by '
        'the receiver.', choices=('real_time', 'max'), group=USER)
    frame_id: str = parameter(
        'gnss', 'header.frame_id of gnss/receiver_interference and gnss/receiver_spectrum (the receiver); the '
        'measurements are in "earth".', group=USER)
    reconnect_period_s: float = parameter(
        1.0, 'Serial only: a lost port (receiver unplugged) is reopened every reconnect_period_s, s, at most '
        'max_reconnect_attempts times in a row.', minimum=0.01, maximum=3600.0)
    max_reconnect_attempts: int = parameter(
        30, 'Serial only: failed reopen attempts in a row before the node exits with code 1 and the reason; 0: '
        'exit at the first loss (let a supervisor restart it).', minimum=0, maximum=1_000_000)
    hardware_id: str = hardware_id_parameter('gnss_receiver', read_only=True)
    diagnostics_period_s: float = diagnostics_period_parameter()
    exit_at_end: bool = parameter(True, 'Files only: shut the node down (exit code 0) at the end of the file.')
    wait_for_subscribers: int = parameter(
        0, 'Hold the input until this many subscribers of gnss/measurements have matched (a log replayed into a '
        'fusion node started at the same moment loses nothing); 0: start at once.', minimum=0, maximum=1000)
    wait_timeout_s: float = parameter_from(SubscriberWaitParams, 'wait_timeout_s')

    def __post_init__(self) -> None:
        validate_ranges(self)
        parse_position(self.reference_position_ecef_m)

    def decoder_params(self) -> UbxDecoderParams:
        return UbxDecoderParams(min_satellites=self.min_satellites, use_receiver_std=self.use_receiver_std,
                                use_sfrbx=self.use_sfrbx, publish_without_ephemeris=self.publish_without_ephemeris)



CONFIG_FILE = ConfigFile('rfi_experiments', 'config/ubx_source.yaml', 'ubx_source', UbxSourceParams, """
Parameters of ubx_source (rfi_experiments/ubx_source.py, UbxSourceParams): a u-blox receiver
(serial port) or a UBX log file -> gnss/measurements, gnss/receiver_interference and
gnss/receiver_spectrum.
GENERATED by tools/generate_config.py from the parameter definitions: the decoder's in
rfi_experiments/ubx_decode.py (UbxDecoderParams), the node's own in ubx_source.py (UbxSourceParams).
Change a default or a description there and run `python tools/generate_config.py`; a test checks
this file equals it.

Use:   ros2 run rfi_experiments ubx_source --ros-args --params-file ubx_source.yaml
       (or -p input:=/dev/ttyACM0 alone). Every value below is the default; the user parameters (the
port or file, its navigation data and pace, the frame) come first. An invalid value, or a parameter
the node does not have, stops the node with a one-line error (exit 2); so does a port or file that
cannot be opened.

The receiver must send UBX-RXM-RAWX (measurements) and, unless nav_file is given, UBX-RXM-SFRBX
(navigation data; without it the satellites are published with NaN states, see
publish_without_ephemeris); UBX-MON-HW / MON-RF / SEC-SIG feed gnss/receiver_interference,
UBX-MON-SPAN gnss/receiver_spectrum. Configure the port's output with u-center or ubxtool; NMEA
mixed in is skipped (counted as skipped_bytes).

Output gnss/measurements (rfi_msgs/GnssMeasurementArray): one per RXM-RAWX epoch with at least
       min_satellites satellites, header stamp = receive time in ROS (UTC) time.
       gnss/receiver_interference (rfi_msgs/ReceiverInterference): one per MON-HW, per MON-RF
       block, per SEC-SIG, stamped with the latest RAWX epoch's time.
       gnss/receiver_spectrum (rfi_msgs/ReceiverSpectrum): one per MON-SPAN RF block (256 bins,
       dB), stamped with the latest RAWX epoch's time.
       /diagnostics: every counter (frames, bad_checksum, truncated, unknown_messages,
       epochs_waiting_for_ephemeris, satellites_without_ephemeris, spectrum_reports, skipped_*
       per reason, sfrbx_rejected_*, port_state, ...) every diagnostics_period_s of stamp time
       and at the end of the input.
""")
"""The shipped config/ubx_source.yaml (:func:`rfi_node_common.params.config_yaml`)."""

def parse_position(text: str) -> tuple[float, float, float] | None:
    """``"X,Y,Z"`` (m) -> a tuple, ``""`` -> None. Raises ValueError otherwise."""
    if not text.strip():
        return None
    try:
        xyz = tuple(float(p) for p in text.replace(',', ' ').split())
    except ValueError:
        raise ValueError(f'reference_position_ecef_m must be "X,Y,Z" in metres, got {text!r}') from None
    if len(xyz) != 3 or not all(math.isfinite(v) for v in xyz):
        raise ValueError(f'reference_position_ecef_m must be three finite numbers, got {text!r}')
    return xyz  # type: ignore[return-value]


def is_regular_file(path: str) -> bool:
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except OSError:
        return False


class UbxSourceNode(Node):
    """Publishes a u-blox receiver's measurements and interference indicators (module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('ubx_source', **kwargs)
        self.params = declare(self, UbxSourceParams)
        p = self.params
        from rfi_experiments.ubx_to_bag import make_decoder

        try:
            self.decoder: UbxDecoder = make_decoder(p.nav_file or None, parse_position(p.reference_position_ecef_m),
                                                    p.decoder_params())
        except OSError as err:
            raise ValueError(f'nav_file {p.nav_file}: {err}') from None
        self.is_file = is_regular_file(p.input)
        self.pub = self.create_publisher(GnssMeasurementArray, MEASUREMENTS_TOPIC, DATA_QOS)
        self.interference_pub = self.create_publisher(ReceiverInterference, INTERFERENCE_TOPIC, DATA_QOS)
        self.spectrum_pub = self.create_publisher(ReceiverSpectrum, SPECTRUM_TOPIC, DATA_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self.counts = {'epochs_sent': 0, 'interference_sent': 0, 'spectrum_sent': 0, 'port_losses': 0,
                       'reconnects': 0, 'read_errors': 0, 'publish_errors': 0}
        self.port_state = 'closed'
        self.exit_code = 0
        self._unacked = {'epochs_sent': 0, 'interference_sent': 0, 'spectrum_sent': 0}
        self._timer = StampTimer(p.diagnostics_period_s)
        self._last_stamp_ns = 0
        self.stop = threading.Event()
        self.done = threading.Event()
        self._report_lock = threading.Lock()
        self._reported = False  # the end-of-input report is written once, by the reader or by the shutdown
        self._stream: Any = self._open()  # a bad path or port refuses the start (exit 2)
        self._thread = threading.Thread(target=self._run, name='ubx_source_reader', daemon=True)
        self._start_timer = self.create_timer(0.0, self._start_reading)

    # ------------------------------------------------------------------------------------------- input
    def _open(self) -> Any:
        p = self.params
        if self.is_file:
            try:
                stream = open(p.input, 'rb')  # noqa: SIM115 - closed by the reader
            except OSError as err:
                raise ValueError(f'input {p.input}: {err.strerror}') from None
        else:
            stream = self._open_serial()
        self.port_state = 'open'
        return stream

    def _open_serial(self) -> Any:
        import serial

        try:
            return serial.Serial(self.params.input, self.params.baud_rate, timeout=SERIAL_TIMEOUT_S)
        except (serial.SerialException, OSError, ValueError) as err:
            raise ValueError(f'input {self.params.input}: cannot open the serial port ({err})') from None

    def _start_reading(self) -> None:
        self._start_timer.cancel()
        if self._thread.ident is None:
            self._thread.start()

    def _run(self) -> None:
        try:
            wait_for_subscribers(self.pub, self.params.wait_for_subscribers, self.params.wait_timeout_s, self.stop,
                                 self.get_logger())
            if self.stop.is_set():
                return
            if self.is_file:
                self._read_file()
            else:
                self._read_serial()
        except Exception as err:  # noqa: BLE001 - a failure ends the input, reported, never a traceback
            if self.context.ok() and not self.stop.is_set():
                self.counts['read_errors'] += 1
                self.exit_code = 1
                self.get_logger().error(f'input {self.params.input} ended by {type(err).__name__}: {err}')
            # else: Ctrl-C / shutdown while publishing (the context went away under the reader): not a fault
        finally:
            self.decoder.finish()
            self._close()
            try:
                self._report_end(publish=self.context.ok() and not self.stop.is_set())
            except Exception as err:  # noqa: BLE001 - shutting down: the report is best effort, never a traceback
                self.get_logger().warn(f'final report incomplete ({type(err).__name__}: {err})')
            self.done.set()
            stop_now = self.exit_code != 0 or (self.is_file and self.params.exit_at_end)
            if stop_now and not self.stop.is_set() and self.context.ok():
                self.context.try_shutdown()

    def _close(self) -> None:
        stream, self._stream = self._stream, None
        if stream is not None:
            try:
                stream.close()
            except OSError:
                pass
        self.port_state = 'closed'

    def _read_file(self) -> None:
        t_first: float | None = None
        tow_first = 0.0
        while not self.stop.is_set():
            data = self._stream.read(READ_BYTES)
            if not data:
                return
            for item in self.decoder.feed(data):
                if self.params.pace == 'real_time' and isinstance(item, EpochOutput):
                    now = time.monotonic()
                    if t_first is None:
                        t_first, tow_first = now, item.epoch.gps_time_of_week_s
                    due = t_first + _tow_difference(item.epoch.gps_time_of_week_s, tow_first)
                    if due > now and self.stop.wait(due - now):
                        return
                self._publish(item)

    def _read_serial(self) -> None:
        import serial

        while not self.stop.is_set():
            try:
                data = self._stream.read(READ_BYTES) if self._stream is not None else b''
            except (serial.SerialException, OSError) as err:
                self.counts['port_losses'] += 1
                self.port_state = 'lost'
                self.get_logger().error(f'serial port {self.params.input} lost: {err}')
                self.decoder.discard_partial_frame()
                self._close()
                self.port_state = 'lost'
                self._publish_diagnostics(self._last_stamp_ns, final=False)
                if not self._reconnect():
                    return
                continue
            for item in self.decoder.feed(data):
                self._publish(item)

    def _reconnect(self) -> bool:
        p = self.params
        for attempt in range(1, p.max_reconnect_attempts + 1):
            if self.stop.wait(p.reconnect_period_s):
                return False
            try:
                self._stream = self._open_serial()
            except ValueError as err:
                self.get_logger().warn(f'reopen attempt {attempt}/{p.max_reconnect_attempts} failed: {err}')
                continue
            self.port_state = 'open'
            self.counts['reconnects'] += 1
            self.get_logger().info(f'serial port {p.input} reopened (attempt {attempt})')
            return True
        self.exit_code = 1
        self.get_logger().error(
            f'serial port {p.input} lost and not back after {p.max_reconnect_attempts} attempt(s) every '
            f'{p.reconnect_period_s} s: exiting (exit code 1)')
        return False

    # ------------------------------------------------------------------------------------------- output
    def _publish(self, item: Any) -> None:
        from rfi_experiments.ubx_messages import report_to_msg, spectrum_to_msg
        from rfi_node_common.conversions import epoch_to_msg

        try:
            if isinstance(item, EpochOutput):
                pub, msg, key = self.pub, epoch_to_msg(item.epoch), 'epochs_sent'
                stamp = item.epoch.stamp_ns
            elif isinstance(item, SpectrumReport):
                pub, msg, key = self.spectrum_pub, spectrum_to_msg(item, self.params.frame_id), 'spectrum_sent'
                stamp = item.stamp_ns
            else:
                pub, msg, key = self.interference_pub, report_to_msg(item, self.params.frame_id), 'interference_sent'
                stamp = item.stamp_ns
        except ValueError as err:  # a field the message cannot carry: counted, never published
            self.counts['publish_errors'] += 1
            self.get_logger().warn(f'not published: {err}')
            return
        pub.publish(msg)
        self.counts[key] += 1
        self._unacked[key] += 1
        if self.is_file and self.params.pace == 'max' and self._unacked[key] >= ACK_EVERY:
            self._unacked[key] = 0
            if not self._wait_acked(pub, ACK_TIMEOUT_S):
                self.get_logger().warn(f'a subscriber did not acknowledge within {ACK_TIMEOUT_S} s')
        self._last_stamp_ns = max(self._last_stamp_ns, stamp)
        if self._timer.due(stamp):
            self._publish_diagnostics(stamp, final=False)

    def _wait_acked(self, pub: Any, timeout_s: float) -> bool:
        """Poll until every reliable subscriber of ``pub`` acknowledged what it sent (True), or timeout.

        Polled with a zero timeout, so that a shutdown (``stop``) ends the wait at once."""
        deadline = time.monotonic() + timeout_s
        zero = _duration(0.0)
        while pub.get_subscription_count() > 0:
            if pub.wait_for_all_acked(zero):
                return True
            if time.monotonic() >= deadline or self.stop.wait(0.001):
                return False
        return True

    def values(self) -> dict[str, object]:
        """Counters of the decoder and of the node, for /diagnostics."""
        v: dict[str, object] = {'input': self.params.input, 'port_state': self.port_state}
        v.update({k: int(n) for k, n in self.decoder.counts.items()})
        v.update({f'skipped_{k}': int(n) for k, n in self.decoder.skipped.items()})
        v.update({f'sfrbx_rejected_{k}': n for k, n in self.decoder.lnav_rejected.items()})
        v.update({f'inav_rejected_{k}': n for k, n in self.decoder.inav_rejected.items()})
        v['messages_not_used'] = sum(self.decoder.ignored.values())
        v['satellites_with_ephemeris'] = len(self.decoder.satellites_with_ephemeris)
        v.update(self.counts)
        v['subscribers'] = self.pub.get_subscription_count()
        v['interference_subscribers'] = self.interference_pub.get_subscription_count()
        v['spectrum_subscribers'] = self.spectrum_pub.get_subscription_count()
        return v

    def level(self) -> tuple[bytes, str]:
        v = self.values()
        lost = self.port_state == 'lost' or v['read_errors']
        return counted_level(v, ('bad_checksum', 'bad_length', 'truncated', 'unparsable',
                                 'epochs_waiting_for_ephemeris', 'port_losses', 'publish_errors'),
                             f'input {self.params.input} lost' if lost else None)

    def _publish_diagnostics(self, stamp_ns: int, final: bool) -> None:
        level, text = self.level()
        publish_status(self, self.diag_pub, stamp_ns, 'ubx_source', self.params.hardware_id, level, text,
                       self.values(), final)

    def _report_end(self, publish: bool) -> None:
        """Log the counters; with ``publish`` (not shutting down) also the final /diagnostics, after the
        subscribers have acknowledged the data."""
        from rfi_experiments.ubx_to_bag import summary_lines

        if self._reported:
            return
        if publish:
            for pub in (self.pub, self.interference_pub, self.spectrum_pub):  # the data out before the final report
                self._wait_acked(pub, FINAL_ACK_TIMEOUT_S)
            self._publish_diagnostics(self._last_stamp_ns, final=True)
            self._wait_acked(self.diag_pub, FINAL_ACK_TIMEOUT_S)
        self._log_end('\n'.join(summary_lines(self.decoder)))

    def _end_line(self) -> str:
        counts = dict(self.counts)
        return (f'end of input {self.params.input}: {counts["epochs_sent"]} epochs, '
                f'{counts["interference_sent"]} interference reports, {counts["spectrum_sent"]} spectra published')

    def _log_end(self, details: str) -> None:
        """Write the end-of-input report unless it has been written (the reader and the shutdown may both try)."""
        with self._report_lock:
            if self._reported:
                return
            self._reported = True
            text = self._end_line() + ('\n' + details if details else '')
            if self.context.ok():
                self.get_logger().info(text)
            else:  # after a shutdown (Ctrl-C) the ROS logger cannot reach /rosout any more
                print(f'[ubx_source] {text}', file=sys.stderr, flush=True)

    def destroy_node(self) -> None:
        self.stop.set()
        self._start_timer.cancel()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=STOP_JOIN_S)
        if self._thread.ident is None:  # stopped before the reader started: report the (empty) counters too
            self._report_end(publish=False)
        elif self._thread.is_alive():  # still busy (STOP_JOIN_S): its report would die with the process
            self._log_end(f'(the reader was still busy {STOP_JOIN_S} s after the stop; the decoder summary is '
                          'not available, the counts are those published so far)')
        if not self._thread.is_alive():
            self._close()
        super().destroy_node()


def _tow_difference(tow_s: float, tow_first_s: float) -> float:
    dt = tow_s - tow_first_s
    return dt + 604800.0 if dt < -302400.0 else dt


def _duration(seconds: float) -> Any:
    from rclpy.duration import Duration
    return Duration(nanoseconds=int(seconds * 1e9))


def main(argv: Any = None) -> int:
    nodes: list[UbxSourceNode] = []

    def make() -> UbxSourceNode:
        node = UbxSourceNode()
        nodes.append(node)
        return node

    code = run_node(make, executable='ubx_source', params_cls=UbxSourceParams, topics=TOPICS,
                    summary='Publish a u-blox receiver\'s raw measurements (UBX-RXM-RAWX, with ephemerides from '
                            'UBX-RXM-SFRBX or a RINEX nav file) as rfi_msgs/GnssMeasurementArray, its '
                            'interference indicators (UBX-MON-HW / MON-RF / SEC-SIG) as '
                            'rfi_msgs/ReceiverInterference and its spectrum (UBX-MON-SPAN) as '
                            'rfi_msgs/ReceiverSpectrum; from a serial port or a UBX log file.',
                    argv=argv)
    if code == 0 and nodes and nodes[0].exit_code:
        return nodes[0].exit_code
    return code
