"""if_source as its own process, fed through a real OS pipe on its standard input (as ``rtl_sdr - | if_source``),
publishing to rfi_monitor_node in this process: the blocks are those of the direct read and the monitor's outputs
those of the core on the directly read blocks; a pause of the writer is a counted gap (a jump of
first_sample_index that the monitor sees), a stream ending inside a block and inside an item is counted, the
process exits 0 at the end of its input. Spins are bounded; the writer's pause is the stimulus, not a wait."""

from __future__ import annotations

import math
import os
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
from ament_index_python.packages import get_package_prefix
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message

from rfi_monitor.monitor import RfiMonitor
from rfi_monitor.rfi_monitor_node import MonitorNodeParams, RfiMonitorNode, decode_samples, full_scale, jammer_state_msg
from rfi_msgs.msg import IfSamples, JammerState
from rfi_node_common import testing
from rfi_node_common.qos import DATA_QOS
from rfi_node_common.stamps import ns_to_stamp, stamp_to_ns

DATA = Path(__file__).resolve().parents[1] / 'src' / 'rfi_monitor' / 'test' / 'data'
CAPTURE = DATA / 'pocketsdr_L1_4MHz_IQ_10ms.bin'   # int8 I/Q, 2-bit values, fs 4 MHz, IF 0
FS = 4.0e6
BLOCK = 4000
START = '2021-12-01T08:47:00Z'
START_NS = 1_638_348_420_000_000_000
FRAME_ID = 'if_source_pipe_test'


def message_fields(msg, wire: bool = True) -> tuple:
    """Every field of a message as it arrives (after a CDR round trip: float32 fields rounded), nested messages
    expanded, NaN made comparable. Serialised bytes cannot be compared: rclpy leaves the CDR padding bytes
    uninitialised."""
    if wire:
        msg = deserialize_message(serialize_message(msg), type(msg))
    out = []
    for name in msg.get_fields_and_field_types():
        v = getattr(msg, name)
        if hasattr(v, 'get_fields_and_field_types'):
            out.append(message_fields(v, wire=False))
        elif isinstance(v, float) and math.isnan(v):
            out.append('nan')
        elif isinstance(v, (bytes, bytearray, list, np.ndarray)) or type(v).__name__ == 'array':
            out.append(bytes(np.asarray(v).tobytes()) if not isinstance(v, (bytes, bytearray)) else bytes(v))
        else:
            out.append(v)
    return tuple(out)


def source_command(*params: str) -> list[str]:
    exe = os.path.join(get_package_prefix('rfi_experiments'), 'lib', 'rfi_experiments', 'if_source')
    args = ['item_type:=ibyte', 'sampling_frequency_hz:=4000000.0', 'bits_per_sample:=2', f'start_time:={START}',
            f'frame_id:={FRAME_ID}', 'pace:=max', 'wait_for_subscribers:=2', *params]
    return [exe, '--ros-args', *[x for a in args for x in ('-p', a)]]


def direct_blocks(raw: bytes, first_index: int = 0) -> list[IfSamples]:
    """IfSamples built by hand from the bytes (np.frombuffer), not with rfi_experiments.if_formats."""
    x = np.frombuffer(raw, dtype=np.int8)
    out = []
    for k in range(x.size // (2 * BLOCK)):
        m = IfSamples()
        index = first_index + k * BLOCK
        m.header.stamp = ns_to_stamp(START_NS + round(index * 1e9 / FS))
        m.header.frame_id = FRAME_ID
        m.sample_rate_hz, m.intermediate_frequency_hz, m.center_frequency_hz = FS, 0.0, 1575.42e6
        m.is_complex, m.first_sample_index, m.scale, m.bits_per_sample = True, index, 1.0, 2
        m.sample_format = IfSamples.INT8
        m.samples = x[2 * k * BLOCK:2 * (k + 1) * BLOCK].tobytes()
        out.append(m)
    return out


def core_states(blocks: list[IfSamples]) -> list[JammerState]:
    mon = RfiMonitor(MonitorNodeParams().monitor_params())
    out = []
    for m in blocks:
        est = mon.process(decode_samples(m), m.sample_rate_hz, m.intermediate_frequency_hz, m.first_sample_index,
                          stamp_to_ns(m.header.stamp), is_complex=True, full_scale=full_scale(m))
        if est.valid:
            out.append(jammer_state_msg(est, m))
    return out


class Monitor:
    """rfi_monitor_node and a probe in this process; if_source in another, reading ``pieces`` from a pipe."""

    def __init__(self) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = RfiMonitorNode(context=self.context, parameter_overrides=[
            Parameter('input_timeout_s', value=0.0),
            Parameter('max_cpu_load', value=0.0),   # no load shedding: every block analysed, as by the core
            Parameter('qos_overrides./rfi/if_samples.subscription.reliability', value='reliable')])
        self.probe = Node('if_source_pipe_probe', context=self.context)
        self.blocks: list[IfSamples] = []
        self.states: list[JammerState] = []
        self.final: dict[str, str] | None = None
        self.got_blocks = threading.Event()
        self.want_blocks = 0
        self.probe.create_subscription(IfSamples, '/rfi/if_samples', self._block, DATA_QOS)
        self.probe.create_subscription(JammerState, '/rfi/jammer_state',
                                       lambda m: self.states.append(m) if m.header.frame_id == FRAME_ID else None,
                                       DATA_QOS)
        self.probe.create_subscription(DiagnosticArray, '/diagnostics', self._diag, DATA_QOS)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.probe)

    def _block(self, msg: IfSamples) -> None:
        if msg.header.frame_id == FRAME_ID:
            self.blocks.append(msg)
            if self.want_blocks and len(self.blocks) >= self.want_blocks:
                self.got_blocks.set()

    def _diag(self, msg: DiagnosticArray) -> None:
        s = msg.status[0] if msg.status else None
        if s is not None and s.name == 'if_source' and s.message.startswith('end of input'):
            values = {kv.key: kv.value for kv in s.values}
            self.final = values

    def run(self, command: list[str], writer) -> subprocess.CompletedProcess:
        proc = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        thread = threading.Thread(target=writer, args=(proc.stdin,), daemon=True)
        thread.start()
        # bounded by progress: a block or a state received, or CPU spent by if_source (its start-up compiles its
        # kernels on a cold numba cache); a fixed 90 s failed beside a CPU hog after a reinstall
        watch = testing.Stall(lambda: (len(self.blocks), len(self.states), self.final is None,
                                       testing.process_cpu_s(proc.pid)), 'if_source did not finish', look_every_s=0.5)
        try:
            while proc.poll() is None or self.final is None:
                watch.check()
                self.executor.spin_once(timeout_sec=0.05)
        finally:
            if proc.poll() is None:
                proc.kill()
            proc.wait(timeout=10)
        thread.join(timeout=10)
        out, err = proc.stdout.read(), proc.stderr.read()
        proc.stdout.close()
        proc.stderr.close()
        return subprocess.CompletedProcess(command, proc.returncode, out, err)

    def settle(self, n_states: int) -> None:
        def progress() -> tuple[int, int]:
            return len(self.states), self.node.accounting()['blocks_received']

        watch = testing.Stall(progress, 'the monitor did not take every block')
        while len(self.states) < n_states or self.node.accounting()['blocks_received'] < len(self.blocks):
            try:
                watch.check()
            except AssertionError as e:
                raise AssertionError(f'{e}: {len(self.states)} states, {len(self.blocks)} blocks, '
                                     f'{self.node.accounting()}') from None
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.probe.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def monitor():
    m = Monitor()
    yield m
    m.close()


def pieces(raw: bytes, size: int = 777):
    return [raw[k:k + size] for k in range(0, len(raw), size)]


def test_pipe_into_if_source_gives_the_direct_blocks_and_the_core_outputs(monitor):
    raw = CAPTURE.read_bytes()

    def write(stdin) -> None:
        for p in pieces(raw):   # short writes: items and blocks split across reads
            stdin.write(p)
            stdin.flush()
        stdin.close()

    done = monitor.run(source_command('gap_tolerance_s:=5.0'), write)
    assert done.returncode == 0, done.stderr.decode()
    assert b'Traceback' not in done.stderr
    direct = direct_blocks(raw)
    expected = core_states(direct)
    monitor.settle(len(expected))
    assert [message_fields(b) for b in monitor.blocks] == [message_fields(b) for b in direct]
    assert [message_fields(s) for s in monitor.states] == [message_fields(s) for s in expected]
    assert monitor.final is not None
    assert monitor.final['blocks_published'] == '10' and monitor.final['gaps'] == '0'
    assert monitor.final['bytes_in'] == str(len(raw)) and monitor.final['trailing_bytes'] == '0'
    assert monitor.node.accounting()['gaps'] == 0


def test_a_pause_of_the_writer_is_a_counted_gap_and_a_truncated_end_is_counted(monitor):
    raw = CAPTURE.read_bytes()
    before, after = raw[:3 * 2 * BLOCK], raw[3 * 2 * BLOCK:6 * 2 * BLOCK + 1001]  # +500 samples and one byte
    monitor.want_blocks = 3

    def write(stdin) -> None:
        stdin.write(before)
        stdin.flush()
        monitor.got_blocks.wait(testing.LIMIT_S)   # the first three blocks are out: the reader has caught up
        time.sleep(1.0)                       # the stimulus: 1 s of samples that never arrive
        # the rest in one write: then it all waits in the pipe (which if_source counts as received), so the writer's
        # pause is the only gap, however long this thread or if_source are descheduled while the monitor analyses
        # (short writes split across reads: test_pipe_into_if_source_gives_the_direct_blocks_and_the_core_outputs)
        stdin.write(after)
        stdin.flush()
        stdin.close()

    done = monitor.run(source_command('gap_tolerance_s:=0.2'), write)
    assert done.returncode == 0, done.stderr.decode()
    assert b'gap of' in done.stderr
    first = [b.first_sample_index for b in monitor.blocks]
    assert len(first) == 6 and first[:3] == [0, 4000, 8000]
    jump = first[3] - 3 * BLOCK
    assert jump >= 0.2 * FS                   # at least the tolerance: a gap of the writer's 1 s pause
    assert first[4:] == [first[3] + BLOCK, first[3] + 2 * BLOCK]
    final = monitor.final
    assert final is not None
    assert final['gaps'] == '1' and final['samples_lost'] == str(jump) and final['samples_dropped_at_gap'] == '0'
    assert final['final_partial_block_samples'] == '500' and final['trailing_bytes'] == '1'
    # the samples after the gap are the writer's, unchanged, at their new index and stamp
    expected = direct_blocks(before) + direct_blocks(after[:3 * 2 * BLOCK], first_index=first[3])
    assert [message_fields(b) for b in monitor.blocks] == [message_fields(b) for b in expected]
    monitor.settle(6)
    assert monitor.node.accounting()['gaps'] == 1   # the monitor saw the jump


def tool(name: str) -> str:
    return os.path.join(get_package_prefix('rfi_experiments'), 'lib', 'rfi_experiments', name)


@pytest.mark.parametrize('name', ['if_source', 'if_to_bag'])
def test_help(name):
    done = subprocess.run([tool(name), '--help'], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and 'usage' in done.stdout.lower() and 'Traceback' not in done.stderr
    for word in ('item_type' if name == 'if_source' else '--item-type', 'sampling', 'intermediate', 'center',
                 'spectral'):
        assert word in done.stdout


def test_misspelt_parameter_is_refused_before_the_input_is_read():
    """A misspelt -p stops the node (exit 2, one line naming the closest parameter) without taking a byte of
    standard input (the reader starts only once the parameters are checked)."""
    r, w = os.pipe()
    os.write(w, CAPTURE.read_bytes()[:8000])
    os.close(w)
    try:
        done = testing.run_process(source_command('sampling_frequency:=4000000.0'), stdin=r, text=True)
        left = len(os.read(r, 100_000))
    finally:
        os.close(r)
    assert done.returncode == 2, done.stderr
    assert 'unknown parameter sampling_frequency (did you mean sampling_frequency_hz?)' in done.stderr
    assert 'Traceback' not in done.stderr
    assert left == 8000


def test_bad_format_is_refused_with_one_line():
    done = testing.run_process(source_command('intermediate_frequency_hz:=3000000.0'), stdin=subprocess.DEVNULL,
                               text=True)
    assert done.returncode == 2 and 'Traceback' not in done.stderr
    assert done.stderr.strip().endswith('must be below fs/2 = 2000000.0 Hz for complex samples'), done.stderr


def test_named_pipe(monitor, tmp_path):
    """input:=<a named pipe>: opened by the reader (a FIFO's open waits for its writer), read as a live stream."""
    fifo = tmp_path / 'sdr.fifo'
    os.mkfifo(fifo)
    raw = CAPTURE.read_bytes()

    def write(stdin) -> None:
        stdin.close()
        with open(fifo, 'wb') as f:
            for p in pieces(raw, 5000):
                f.write(p)

    done = monitor.run(source_command(f'input:={fifo}', 'gap_tolerance_s:=5.0'), write)
    assert done.returncode == 0, done.stderr.decode()
    assert [message_fields(b) for b in monitor.blocks] == [message_fields(b) for b in direct_blocks(raw)]
    assert monitor.final is not None and monitor.final['gaps'] == '0'
