"""ubx_source as its own process: a UBX log generated from the simulator gives, on gnss/measurements and
gnss/receiver_interference, exactly the messages ubx_to_bag writes for it (one decoder, one conversion; the epochs
before the ephemerides with NaN satellite states), and the process exits 0 at the end; a serial port that
disappears mid-stream (a pseudo-terminal whose master is closed) is reported and retried, then the node exits 1
with a one-line reason and no traceback; a port that cannot be opened is refused at start (exit 2). In process:
pyubx2's real logs give the receiver's spectra (gnss/receiver_spectrum) and measurements without ephemeris. Spins
are bounded."""

from __future__ import annotations

import math
import os
import select
import subprocess
import threading
import time
from pathlib import Path

import pytest
import rclpy
from ament_index_python.packages import get_package_prefix
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from gnss_common.ephemeris import EphemerisStore
from gnss_common.rinex import read_rinex_nav
from rfi_experiments import ubx_to_bag
from rfi_experiments.ubx_decode import EpochOutput
from rfi_experiments.ubx_messages import report_to_msg
from rfi_experiments.ubx_synth import ephemeris_frames, mon_hw_frame, rawx_frame
from rfi_msgs.msg import GnssMeasurementArray, ReceiverInterference
from rfi_node_common import testing
from rfi_node_common.conversions import epoch_to_msg
from rfi_node_common.qos import DATA_QOS
from rfi_sim.gnss_uwb import BroadcastGeometry, GnssUwbScenario, simulate

NAV = Path(__file__).resolve().parents[1] / 'src' / 'rfi_experiments' / 'data' / 'arlm2000.15n'
REAL = Path(__file__).resolve().parents[1] / 'src' / 'rfi_experiments' / 'test' / 'data' / 'ubx'
DEADLINE_S = 60.0
FRAME_ID = 'ubx_source_test'


def fields(msg: object) -> object:
    """Every field of a message, recursively, NaN as a string (the CDR bytes are not comparable: rclpy
    leaves the alignment padding uninitialised)."""
    if hasattr(msg, 'get_fields_and_field_types'):
        return tuple((name, fields(getattr(msg, name))) for name in msg.get_fields_and_field_types())
    if isinstance(msg, (list, tuple)) or hasattr(msg, 'tolist'):
        return tuple(fields(v) for v in (msg.tolist() if hasattr(msg, 'tolist') else msg))
    if isinstance(msg, float) and math.isnan(msg):
        return 'nan'
    return msg


def executable() -> str:
    return os.path.join(get_package_prefix('rfi_experiments'), 'lib', 'rfi_experiments', 'ubx_source')


def command(*params: str) -> list[str]:
    return [executable(), '--ros-args', *[x for p in params for x in ('-p', p)]]


def read_until_ready(proc: subprocess.Popen) -> bytes:
    """ubx_source's stderr until it logs 'ready', bounded by its progress (CPU: imports, kernels) instead of a fixed
    deadline; the reads wait at most 0.5 s each, so that the bound is checked while the node is silent."""
    log = b''
    watch = testing.Stall(lambda: (len(log), testing.process_cpu_s(proc.pid)), "ubx_source's 'ready'")
    while b'ubx_source ready' not in log:
        assert proc.poll() is None, log.decode()
        watch.check()
        if select.select([proc.stderr], [], [], 0.5)[0]:
            log += os.read(proc.stderr.fileno(), 4096)
    return log


@pytest.fixture(scope='module')
def ubx_log(tmp_path_factory) -> Path:
    nav = read_rinex_nav(NAV)
    run = simulate(GnssUwbScenario(duration_s=20.0, gnss_rate_hz=1.0, seed=5), BroadcastGeometry(NAV),
                   nav.header.iono_alpha, nav.header.iono_beta)
    store = EphemerisStore(nav.ephemerides)
    first = run.gnss_epochs[0]
    prns = sorted({o.svid for e in run.gnss_epochs for o in e.observations})
    used = [store.select(p, first.gps_week, first.gps_time_of_week_s)[0] for p in prns]
    stream = bytearray()
    for k, epoch in enumerate(run.gnss_epochs):
        if k == 2:
            stream += ephemeris_frames(used, epoch.gps_week, epoch.gps_time_of_week_s)
        if k == 5:
            corrupt_at = len(stream) + 40
        stream += rawx_frame(epoch, leap_seconds=17) + mon_hw_frame(2, 40 + k, 1300 - k, 95)  # 2015: 17 s
    stream[corrupt_at] ^= 0xFF  # the RAWX frame of epoch 5: a bad checksum, counted; the stream goes on
    path = tmp_path_factory.mktemp('ubx') / 'sim.ubx'
    path.write_bytes(bytes(stream))
    return path


class Probe:
    def __init__(self) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = Node('ubx_source_probe', context=self.context)
        self.arrays: list[GnssMeasurementArray] = []
        self.reports: list[ReceiverInterference] = []
        self.final: dict[str, str] | None = None
        self.node.create_subscription(GnssMeasurementArray, '/gnss/measurements', self.arrays.append, DATA_QOS)
        self.node.create_subscription(ReceiverInterference, '/gnss/receiver_interference',
                                      lambda m: self.reports.append(m) if m.header.frame_id == FRAME_ID else None,
                                      DATA_QOS)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._diag, DATA_QOS)
        self.executor = testing.CountingExecutor(context=self.context)
        self.executor.add_node(self.node)

    def _diag(self, msg: DiagnosticArray) -> None:
        s = msg.status[0] if msg.status else None
        if s is not None and s.name == 'ubx_source' and s.message.startswith('end of input'):
            values = {kv.key: kv.value for kv in s.values}
            if values.get('input', '').endswith('sim.ubx'):
                self.final = values

    def run(self, cmd: list[str]) -> subprocess.CompletedProcess:
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        # bounded by progress (a message taken, CPU spent by ubx_source), not by a fixed DEADLINE_S
        watch = testing.Stall(lambda: (self.executor.messages_taken, testing.process_cpu_s(proc.pid)),
                              'ubx_source did not finish', look_every_s=0.5)
        try:
            while proc.poll() is None or self.final is None:
                watch.check()
                self.executor.spin_once(timeout_sec=0.05)
        finally:
            if proc.poll() is None:
                proc.kill()
            out, err = proc.communicate(timeout=10)
        return subprocess.CompletedProcess(cmd, proc.returncode, out, err)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def test_file_gives_the_messages_of_ubx_to_bag(ubx_log):
    probe = Probe()
    try:
        done = probe.run(command(f'input:={ubx_log}', 'pace:=max', 'wait_for_subscribers:=1',
                                 f'frame_id:={FRAME_ID}'))
    finally:
        probe.close()
    assert done.returncode == 0, done.stderr.decode()
    assert b'Traceback' not in done.stderr
    conversion = ubx_to_bag.convert_ubx(ubx_log, ubx_to_bag.make_decoder())
    expected = [epoch_to_msg(e.epoch) for e in conversion.epochs if isinstance(e, EpochOutput)]
    assert len(expected) == 20 - 1  # one corrupted RAWX frame (epoch 5)
    assert [fields(m) for m in probe.arrays] == [fields(m) for m in expected]
    without = [o for e in conversion.epochs[:2] for o in e.epoch.observations]  # before the ephemerides
    assert without and all(math.isnan(o.satellite_clock_bias_m) for o in without)
    reports = [report_to_msg(r, FRAME_ID) for r in conversion.interference]
    assert [fields(m) for m in probe.reports] == [fields(m) for m in reports]
    assert probe.final is not None
    assert probe.final['bad_checksum'] == '1' and probe.final['epochs_waiting_for_ephemeris'] == '0'
    assert probe.final['satellites_without_ephemeris'] == str(len(without))
    assert probe.final['leap_seconds_disagree'] == '0' and probe.final['port_losses'] == '0'
    assert probe.final['epochs_sent'] == str(len(expected)) and probe.final['port_state'] == 'closed'


def test_serial_port_gone_is_reported_retried_and_ends_cleanly(ubx_log):
    master, slave = os.openpty()
    port = f'/dev/fd/{slave}'  # the pseudo-terminal's slave, passed down (/dev/pts may not be mounted here)
    proc = subprocess.Popen(command(f'input:={port}', 'max_reconnect_attempts:=2', 'reconnect_period_s:=0.2'),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, pass_fds=(slave,))
    try:
        log = read_until_ready(proc)  # the port is open once the node says it is ready
        os.write(master, ubx_log.read_bytes()[:4000])  # a receiver sending, then unplugged
        os.close(slave)
        os.close(master)
        out, err = testing.communicate(proc, 'ubx_source did not end after its port was lost')
        err = log + err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=10)
    text = err.decode() + out.decode()
    assert proc.returncode == 1, text
    assert 'Traceback' not in text
    assert f'serial port {port} lost' in text
    assert 'not back after 2 attempt(s)' in text


def test_a_port_that_cannot_be_opened_is_refused_at_start(tmp_path):
    done = testing.run_process(command(f'input:={tmp_path / "ttyNONE"}'), 'ubx_source did not refuse its port')
    assert done.returncode == 2
    err = done.stderr.decode()
    assert 'cannot open the serial port' in err and 'Traceback' not in err


def test_config_file_values_equal_the_dataclass_defaults():
    import dataclasses

    import yaml

    from rfi_experiments.ubx_source import UbxSourceParams

    config = Path(__file__).resolve().parents[1] / 'src' / 'rfi_experiments' / 'config' / 'ubx_source.yaml'
    data = yaml.safe_load(config.read_text())['ubx_source']['ros__parameters']
    defaults = UbxSourceParams()
    assert set(data) == {f.name for f in dataclasses.fields(UbxSourceParams)}
    for name, value in data.items():
        assert value == getattr(defaults, name) and type(value) is type(getattr(defaults, name)), name


def test_ctrl_c_while_reading_a_port_is_a_clean_exit(ubx_log):
    import signal

    master, slave = os.openpty()
    proc = subprocess.Popen(command(f'input:=/dev/fd/{slave}'), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            pass_fds=(slave,))
    try:
        log = read_until_ready(proc)
        os.write(master, ubx_log.read_bytes()[:3000])
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=DEADLINE_S)  # fixed on purpose: Ctrl-C must end the node promptly
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=10)
        os.close(slave)
        os.close(master)
    text = (log + err + out).decode()
    assert proc.returncode == 0, text
    assert 'Traceback' not in text  # (rcl may print that a log line could not reach /rosout: a race it owns)
    assert 'end of input' in text


def test_ctrl_c_while_the_reader_is_busy_still_logs_the_end_of_input_once(ubx_log, monkeypatch, capfd):
    """The race of the Ctrl-C test above (failed on a cold numba cache beside a hog: exit 0, nothing logged after
    'ready'): the reader was still busy with its first bytes (compiling) when the shutdown's join gave up, and its
    report died with the process. Now the shutdown writes the report itself, and the reader, done later, does not
    write a second one."""
    from rclpy.parameter import Parameter

    from rfi_experiments import ubx_source

    monkeypatch.setattr(ubx_source, 'STOP_JOIN_S', 0.2)
    master, slave = os.openpty()
    context = Context()
    rclpy.init(context=context)
    busy, release = threading.Event(), threading.Event()
    node = None
    try:
        node = ubx_source.UbxSourceNode(context=context, parameter_overrides=[
            Parameter('input', value=f'/dev/fd/{slave}')])
        feed = node.decoder.feed

        def slow_feed(data):  # a first feed that takes long (a cold-cache compile beside a hog)
            busy.set()
            release.wait(60.0)
            return feed(data)

        monkeypatch.setattr(node.decoder, 'feed', slow_feed)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        os.write(master, ubx_log.read_bytes()[:3000])
        testing.wait_until(busy.is_set, lambda: executor.spin_once(timeout_sec=0.02), lambda: busy.is_set(),
                           'the reader did not read')
        node.destroy_node()   # what run_node does on Ctrl-C
        first = capfd.readouterr().err
        release.set()
        node._thread.join(timeout=DEADLINE_S)
        node = None
        assert first.count('end of input') == 1 and 'the reader was still busy' in first, first
        assert 'end of input' not in capfd.readouterr().err
    finally:
        release.set()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
        os.close(slave)
        os.close(master)


def test_a_lost_port_that_comes_back_is_reopened_and_decoding_goes_on(ubx_log, monkeypatch):
    import serial
    from rclpy.parameter import Parameter

    from rfi_experiments.ubx_source import UbxSourceNode

    m1, s1 = os.openpty()
    m2, s2 = os.openpty()
    context = Context()
    rclpy.init(context=context)
    node = None
    back = serial.Serial(f'/dev/fd/{s2}', 115200, timeout=0.1)  # the port as it is after the receiver is back
    try:
        node = UbxSourceNode(context=context, parameter_overrides=[
            Parameter('input', value=f'/dev/fd/{s1}'), Parameter('reconnect_period_s', value=0.05),
            Parameter('max_reconnect_attempts', value=3)])
        monkeypatch.setattr(node, '_open_serial', lambda: back)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)

        def spin_until(done, what):
            deadline = time.monotonic() + DEADLINE_S
            while not done():
                assert time.monotonic() < deadline, what
                executor.spin_once(timeout_sec=0.02)

        data = ubx_log.read_bytes()
        cut = len(data) // 2 + 7  # inside a frame
        os.write(m1, data[:cut])
        spin_until(lambda: node.decoder.counts['rawx_epochs'] >= 5, 'the first half was not read')
        first = node.decoder.counts['rawx_epochs']
        os.close(m1)  # unplugged
        spin_until(lambda: node.counts['reconnects'] == 1, 'the port was not reopened')
        assert node.counts['port_losses'] == 1 and node.port_state == 'open'
        os.write(m2, data[cut:])
        spin_until(lambda: node.decoder.counts['frames'] + node.decoder.counts['bad_checksum']
                   + node.decoder.counts['truncated'] >= 65, 'the second half was not read')
        assert node.decoder.counts['truncated'] == 1  # the frame cut by the loss, dropped and counted
        assert node.decoder.counts['rawx_epochs'] > first
        assert node.exit_code == 0
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
        back.close()
        for fd in (s1, m2, s2):
            os.close(fd)


def test_real_logs_in_process_give_the_spectra_and_measurements_without_ephemeris(tmp_path):
    """pyubx2's real captures (14 RXM-RAWX epochs without navigation data, then MON-HW / MON-RF /
    MON-SPAN): the node publishes what ubx_to_bag writes for them, the measurements with NaN satellite
    states, one ReceiverSpectrum per MON-SPAN block stamped with the latest RAWX epoch, and counts them."""
    from rfi_experiments.ubx_messages import spectrum_to_msg
    from rfi_experiments.ubx_source import UbxSourceNode
    from rfi_msgs.msg import ReceiverSpectrum
    from rfi_node_common.testing import NodeRig

    log = tmp_path / 'real.ubx'
    log.write_bytes(b''.join((REAL / f'pygpsdata-{k}.log').read_bytes() for k in ('RXMRAWX', 'MON', 'ALL')))

    def make(context, overrides):
        node = UbxSourceNode(context=context, parameter_overrides=overrides)
        node._start_timer.cancel()  # read only once the rig has discovered every output
        return node

    def ours(msg):
        return msg.header.frame_id == FRAME_ID

    rig = NodeRig(make, inputs={}, params={'input': str(log), 'pace': 'max', 'exit_at_end': False,
                                           'frame_id': FRAME_ID},
                  outputs={'/gnss/measurements': (GnssMeasurementArray, lambda m: m.gps_week == 2327),
                           '/gnss/receiver_interference': (ReceiverInterference, ours),
                           '/gnss/receiver_spectrum': (ReceiverSpectrum, ours)}, spin_deadline_s=DEADLINE_S)
    try:
        rig.node._start_reading()
        rig.settle_until(rig.node.done.is_set, 'the end of the log')
        counts = rig.node.values()
    finally:
        rig.close()
    conversion = ubx_to_bag.convert_ubx(log, ubx_to_bag.make_decoder())
    assert (len(conversion.epochs), len(conversion.interference), len(conversion.spectra)) == (14, 5, 2)
    assert [fields(m) for m in rig.out['/gnss/receiver_spectrum']] == [
        fields(spectrum_to_msg(s, FRAME_ID)) for s in conversion.spectra]
    assert [fields(m) for m in rig.out['/gnss/measurements']] == [
        fields(epoch_to_msg(e.epoch)) for e in conversion.epochs]
    assert len(rig.out['/gnss/receiver_interference']) == 5
    spectrum = rig.out['/gnss/receiver_spectrum'][0]
    assert (spectrum.header.stamp.sec, spectrum.gps_time_of_week_s) == (1723558188, 223806.0)  # last RAWX epoch
    assert spectrum.center_frequency_hz == 1583.4e6 and len(spectrum.power_db) == 256
    n_sat = 0
    for msg in rig.out['/gnss/measurements']:
        for m in msg.measurements:
            assert math.isnan(m.satellite_position_ecef_m[0]) and math.isnan(m.satellite_clock_bias_m)
            assert m.pseudorange_m > 1.9e7 and math.isfinite(m.pseudorange_rate_mps) and m.cn0_dbhz > 0.0
            n_sat += 1
    assert counts['spectrum_reports'] == counts['spectrum_sent'] == 2 and counts['spectrum_before_time'] == 0
    assert counts['satellites_without_ephemeris'] == n_sat and counts['epochs_sent'] == 14
    assert counts['skipped_no_ephemeris'] == 0 and counts['publish_errors'] == 0
