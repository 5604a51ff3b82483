"""Fuzzing the nodes, each as its own process, with hostile input (issue 12; gnss_correlator_node since issue 29).

For each node: valid messages of bags/default keep it running while at least ``FUZZ_COUNT``
hostile messages per input topic (:mod:`fuzz_inputs`: random bytes, truncated and overwritten
payloads, hostile field values and stamps, duplicates, and the explicit faults of the issue) are
published between them. Then:

* the process is alive and printed no traceback;
* every message sent reached the node and is accounted for: ``input.<topic>.received`` equals what
  was sent (the inputs are made reliable with the ``qos_overrides`` parameters so the count is
  exact), no handler raised (``callback_errors`` 0: every rejection has a named reason) and the
  node's own ``accounting_ok`` holds;
* nothing invalid was published as valid (:func:`invalid_outputs`);
* the valid messages after the fuzz are still processed (a single bad stamp stalls nothing): each answered with its
  stamp (``ANSWERS``), or, for the correlator, which answers a continuous stream only, each taken by its receiver.

Seeded and bounded in time. ``RFI_FUZZ_COUNT=20000`` runs the long variant (run before resolving
the issue; the default keeps `make test` fast). Further tests: a silent node reports STALE; a
best-effort publisher (a sensor driver) is accepted; messages lost at a high rate are counted.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from fuzz_inputs import HostileStream, issue_faults
from rclpy.executors import SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.qos import qos_profile_sensor_data
from rclpy.serialization import deserialize_message
from ros_fixtures import make_context
from test_executables import executable

from rfi_experiments.bag_io import BagReader, message_class
from rfi_node_common.qos import DATA_QOS, PLAYER_QOS

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / 'bags' / 'default'
FUZZ_COUNT = int(os.environ.get('RFI_FUZZ_COUNT', '1000'))
SEED = 20261201
IF_TEMPLATE_SAMPLES = 4096
SETTLE_S = 120.0 + 0.05 * FUZZ_COUNT
"""Longest wait for a node to take what was sent, s (the long variant queues minutes of work)."""

NODES = {
    'rfi_monitor_node': ('rfi_monitor', ['/rfi/if_samples'], ['/rfi/jammer_state'], 8.0),
    'imm_carrier_node': ('imm_carrier', ['/gnss/correlators'], ['/carrier/estimates'], 4.0),
    'fusion_node': ('uwb_gnss_fusion', ['/gnss/measurements', '/uwb/ranges', '/rfi/jammer_state'],
                    ['/fusion/odometry', '/fusion/fix', '/fusion/status'], 6.0),
    'gnss_integrity_node': ('gnss_integrity', ['/gnss/measurements', '/uwb/ranges', '/rfi/jammer_state'],
                            ['/gnss/integrity'], 6.0),
    'gnss_correlator_node': ('gnss_correlator', ['/rfi/if_samples'], ['/gnss/correlators'], 8.0),
}
"""executable -> (package, input topics, output topics, seconds of bags/default used as valid input)."""


def shorten(topic: str, msg):
    """IF blocks cut to IF_TEMPLATE_SAMPLES samples (still valid, faster to analyse)."""
    if topic == '/rfi/if_samples':
        msg.samples = bytes(msg.samples[:IF_TEMPLATE_SAMPLES])
    return msg


SOURCES = {'/rfi/jammer_state': '/truth/jammer'}
"""Input topics that bags/default does not hold, and the bag topic of the same type that stands in."""


def valid_messages(topics: list[str], seconds: float) -> list[tuple[str, object]]:
    """The first ``seconds`` of bags/default on ``topics``, as (topic, message) in log-time order."""
    source = {SOURCES.get(t, t): t for t in topics}
    with BagReader(BAG) as reader:
        stop = reader.start_ns + int(seconds * 1e9)
        return [(source[m.topic], shorten(source[m.topic], m.decode()))
                for m in reader.messages(list(source), stop_ns=stop)]


# ---------------------------------------------------------------------------------- output checks
def _finite(*values) -> bool:
    return all(math.isfinite(v) for v in values)


def invalid_outputs(topic: str, msg) -> list[str]:
    """Why ``msg`` on ``topic`` would be an invalid estimate published as valid (empty: fine)."""
    bad = []
    if topic == '/rfi/jammer_state':
        if msg.type not in (0, 1, 2, 3, 4):
            bad.append(f'type {msg.type}')
        if not (math.isfinite(msg.confidence) and 0.0 <= msg.confidence <= 1.0):
            bad.append(f'confidence {msg.confidence}')
        if msg.type in (1, 2, 3) and not math.isfinite(msg.jammer_to_noise_db):
            bad.append(f'type {msg.type} with J/N {msg.jammer_to_noise_db}')
        if msg.type == 0 and msg.confidence >= 0.999 and not math.isfinite(msg.jammer_to_noise_db):
            bad.append('certainly NONE with an unknown J/N')
        if math.isfinite(msg.frequency_hz) and not (math.isfinite(msg.frequency_std_hz) and msg.frequency_std_hz > 0):
            bad.append(f'frequency {msg.frequency_hz} with std {msg.frequency_std_hz}')
    elif topic == '/gnss/correlators':
        for c in msg.correlators:  # a C/N0 may be NaN (unknown), never infinite
            if not (_finite(c.in_phase, c.quadrature, c.predicted_phase_change_rad) and c.integration_time_s > 0
                    and math.isfinite(c.integration_time_s) and not math.isinf(c.cn0_dbhz)
                    and c.carrier_lock in (c.CARRIER_LOCK_UNKNOWN, c.CARRIER_LOCK_LOST, c.CARRIER_LOCK_HELD)):
                bad.append(f'sv {c.svid}: I {c.in_phase}, Q {c.quadrature}, T {c.integration_time_s}, '
                           f'C/N0 {c.cn0_dbhz}, predicted {c.predicted_phase_change_rad}, lock {c.carrier_lock}')
    elif topic == '/carrier/estimates':
        for e in msg.estimates:  # a std may be NaN (unknown: the PLL has none), never 0 or inf when locked
            if e.locked and not (_finite(e.phase_rad, e.frequency_hz)
                                 and all(math.isnan(v) or (math.isfinite(v) and v > 0)
                                         for v in (e.phase_std_rad, e.frequency_std_hz))):
                bad.append(f'locked sv {e.svid} with phase {e.phase_rad} +- {e.phase_std_rad}, '
                           f'frequency {e.frequency_hz} +- {e.frequency_std_hz}')
    elif topic == '/fusion/odometry':
        p = msg.pose.pose.position
        v = msg.twist.twist.linear
        if not _finite(p.x, p.y, p.z, v.x, v.y, v.z):
            bad.append('non-finite odometry')
        cov = np.asarray(msg.pose.covariance).reshape(6, 6)
        if not np.isfinite(cov).all() or (np.diag(cov)[:3] <= 0).any():
            bad.append('odometry covariance not finite or not positive')
    elif topic == '/gnss/integrity':
        if not (msg.spoofing_state in (0, 1, 2, 3) and msg.jamming_state in (0, 1, 2, 3)
                and msg.spoofing_scope in (0, 1, 2, 3)):
            bad.append(f'states {msg.spoofing_state}, {msg.jamming_state}, scope {msg.spoofing_scope}')
        if len(msg.affected_svids) != len(msg.affected_satellite_constellations):
            bad.append('affected satellites malformed')
        if math.isinf(msg.jammer_to_signal_db):
            bad.append(f'J/S {msg.jammer_to_signal_db}')
        for test in msg.tests:
            if test.decision not in (0, 1, 2, 3) or (test.decision != 0 and math.isnan(test.statistic)):
                bad.append(f'test {test.name}: decision {test.decision} on statistic {test.statistic}')
    elif topic == '/fusion/fix':
        if not (_finite(msg.latitude, msg.longitude, msg.altitude) and abs(msg.latitude) <= 90):
            bad.append('non-finite fix')
        if not np.isfinite(np.asarray(msg.position_covariance)).all():
            bad.append('fix covariance not finite')
    return bad


# ---------------------------------------------------------------------------------- the rig
class NodeProcess:
    """One node executable as its own process, with a test node publishing its inputs and
    collecting its outputs and diagnostics."""

    def __init__(self, name: str, *, reliable_inputs: bool, extra_args: tuple[str, ...] = ()) -> None:
        package, self.inputs, self.outputs, _ = NODES[name]
        self.name = name
        args = ['-p', 'input_timeout_s:=1.0']
        if reliable_inputs:  # reliable and keep-all: the publisher waits for the node, nothing is dropped
            for t in self.inputs:
                args += ['-p', f'qos_overrides.{t}.subscription.reliability:=reliable',
                         '-p', f'qos_overrides.{t}.subscription.history:=keep_all']
        params = ['--params-file', str(ROOT / 'bags' / 'default.params.yaml')]
        # stderr to a file, not a pipe: a node that logs faster than a pipe is read would block on it
        self._log = tempfile.TemporaryFile(mode='w+')
        self.proc = subprocess.Popen([executable(package, name), '--ros-args', *params, *args, *extra_args],
                                     stdout=subprocess.DEVNULL, stderr=self._log, text=True)
        self.context = make_context()
        self.node = rclpy.create_node('fuzzer', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.out: dict[str, list] = defaultdict(list)
        self.diagnostics: list[DiagnosticStatus] = []
        for topic in self.outputs:
            cls = message_class(_TYPES[topic])
            self.node.create_subscription(cls, topic, lambda raw, t=topic, c=cls: self.out[t].append(
                deserialize_message(raw, c)), DATA_QOS, raw=True)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, DATA_QOS)
        deadline = time.monotonic() + 120.0
        while f'{name} ready' not in self.stderr:
            if time.monotonic() > deadline or self.proc.poll() is not None:
                text = self.close()  # what it wrote (the log is closed with it)
                raise AssertionError(f'{name} did not start:\n{text[-3000:]}')
            time.sleep(0.05)

    @property
    def stderr(self) -> str:
        """What the node has written to stderr so far."""
        self._log.flush()
        self._log.seek(0)
        return self._log.read()

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        self.diagnostics.extend(s for s in msg.status if s.name and self._mine(s))

    def _mine(self, status: DiagnosticStatus) -> bool:
        return {'rfi_monitor_node': 'rfi_monitor', 'imm_carrier_node': 'imm_carrier',
                'fusion_node': 'uwb_gnss_fusion', 'gnss_integrity_node': 'gnss_integrity',
                'gnss_correlator_node': 'gnss_correlator'}[self.name] in status.name

    def publishers(self, qos=PLAYER_QOS) -> dict:
        pubs = {t: self.node.create_publisher(message_class(_TYPES[t]), t, qos) for t in self.inputs}
        deadline = time.monotonic() + 20.0
        while not all(p.get_subscription_count() > 0 for p in pubs.values()):
            assert time.monotonic() < deadline, f'{self.name} did not subscribe to {self.inputs}'
            self.executor.spin_once(timeout_sec=0.05)
        self.spin(0.5)  # the subscriber's side of discovery
        return pubs

    def publish(self, pub, payload, timeout_s: float = SETTLE_S) -> None:
        """Publish, waiting while the keep-all writer's history is full (the node is behind)."""
        end = time.monotonic() + timeout_s
        while True:
            try:
                pub.publish(payload)
                return
            except _rclpy.RCLError:
                assert time.monotonic() < end, f'{self.name} stopped taking messages'
                self.spin(0.05)

    def spin(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.02)

    def settle(self, pubs: dict, timeout_s: float = 30.0) -> None:
        """Wait until every publisher's messages are acknowledged (reliable subscribers) and spin."""
        for pub in pubs.values():
            end = time.monotonic() + timeout_s
            while not pub.wait_for_all_acked(rclpy.duration.Duration(seconds=0.05)):
                self.executor.spin_once(timeout_sec=0.01)
                assert time.monotonic() < end, f'{self.name} stopped taking messages'
        self.spin(0.05)

    def latest_values(self, after: float, *, level: bytes | None = None, timeout_s: float = 20.0) -> dict:
        """Key/values of the first diagnostics status (of ``level``) received after ``after`` (monotonic)."""
        seen = len(self.diagnostics)
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.05)
            fresh = [s for s in self.diagnostics[seen:] if level is None or s.level == level]
            if fresh and time.monotonic() > after:
                return {kv.key: kv.value for kv in fresh[-1].values}
        raise AssertionError(f'no {self.name} diagnostics (level {level!r}) within {timeout_s} s '
                             f'(process {"alive" if self.alive() else "exited"})')

    def alive(self) -> bool:
        return self.proc.poll() is None

    def close(self) -> str:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        try:
            self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        text = self.stderr
        self._log.close()
        self.executor.remove_node(self.node)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        return text


ANSWERS = {'rfi_monitor_node': ('/rfi/if_samples', '/rfi/jammer_state'),
           'imm_carrier_node': ('/gnss/correlators', '/carrier/estimates'),
           'fusion_node': ('/gnss/measurements', '/fusion/status'),
           'gnss_integrity_node': ('/gnss/measurements', '/gnss/integrity')}
"""node -> (input, output): every valid input message on it after the fuzz gets an output with its stamp."""


def _stamp(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


_TYPES = {
    '/rfi/if_samples': 'rfi_msgs/msg/IfSamples', '/gnss/correlators': 'rfi_msgs/msg/CorrelatorArray',
    '/gnss/measurements': 'rfi_msgs/msg/GnssMeasurementArray', '/uwb/ranges': 'rfi_msgs/msg/UwbRange',
    '/rfi/jammer_state': 'rfi_msgs/msg/JammerState', '/carrier/estimates': 'rfi_msgs/msg/CarrierPhaseArray',
    '/fusion/odometry': 'nav_msgs/msg/Odometry', '/fusion/fix': 'sensor_msgs/msg/NavSatFix',
    '/fusion/status': 'rfi_msgs/msg/FusionStatus', '/gnss/integrity': 'rfi_msgs/msg/GnssIntegrity',
}


# ---------------------------------------------------------------------------------- tests
@pytest.mark.slow
@pytest.mark.parametrize('name', list(NODES))
def test_node_survives_hostile_input_and_accounts_for_every_message(name):
    package, inputs, outputs, seconds = NODES[name]
    rng = np.random.default_rng([SEED, list(NODES).index(name)])
    valid = valid_messages(inputs, seconds)
    prime_count = len(valid) // 3
    # the monitor sheds whole blocks (counted) when its CPU time exceeds max_cpu_load of the stream time
    # (issue 14 item 6): thousands of hostile blocks on a few ms of stream put it in debt, and it would
    # then shed the valid tail this test wants answered; shedding has tests of its own
    extra = ('-p', 'max_cpu_load:=0.0') if name == 'rfi_monitor_node' else ()
    rig = NodeProcess(name, reliable_inputs=True, extra_args=extra)
    try:
        pubs = rig.publishers()
        sent: dict[str, int] = dict.fromkeys(inputs, 0)
        latest: dict[str, object] = {}

        def send(topic: str, payload) -> None:
            rig.publish(pubs[topic], payload)
            sent[topic] += 1

        for topic, msg in valid[:prime_count]:
            send(topic, msg)
            latest[topic] = msg
            rig.spin(0.001)
        rig.settle(pubs, timeout_s=SETTLE_S)
        streams = {}
        for topic in inputs:
            templates = [m for t, m in valid if t == topic]
            faults = issue_faults(topic, latest.get(topic, templates[0]))
            streams[topic] = HostileStream(templates, rng, faults).messages(
                FUZZ_COUNT, lambda t=topic: latest.get(t))
        hostile = dict.fromkeys(inputs, 0)
        rest = iter(valid[prime_count:2 * prime_count])  # interleaved; the last third is the tail
        done = False
        while not done:
            done = True
            for topic in inputs:
                for _ in range(20):
                    item = next(streams[topic], None)
                    if item is None:
                        break
                    done = False
                    send(topic, item[1])
                    hostile[topic] += 1
            nxt = next(rest, None)
            if nxt is not None:
                send(nxt[0], nxt[1])
                latest[nxt[0]] = nxt[1]
            rig.spin(0.005)  # take the outputs as they come
        rig.settle(pubs, timeout_s=SETTLE_S)
        # the correlator answers a continuous stream only (ANSWERS): its counts before the valid tail
        before = (None if name in ANSWERS else
                  rig.latest_values(time.monotonic() + 1.0, level=DiagnosticStatus.STALE, timeout_s=SETTLE_S))
        valid_tail = [*rest, *valid[2 * prime_count:]]
        for topic, msg in valid_tail:
            send(topic, msg)
            rig.spin(0.001)
        rig.settle(pubs, timeout_s=SETTLE_S)
        values = rig.latest_values(time.monotonic() + 1.0, level=DiagnosticStatus.STALE, timeout_s=SETTLE_S)
        # the fusion node's re-ordering buffer holds the last messages until it has been idle for
        # idle_flush_s (1 s), the same silence that makes it STALE (input_timeout_s 1 s): the STALE
        # report may come first, so the tail's last outputs are awaited here (the CI run of session 9
        # failed on this race)
        answer_in, answer_out = ANSWERS.get(name, (inputs[0], outputs[0]))
        tail = [_stamp(m) for t, m in valid[2 * prime_count:] if t == answer_in and name in ANSWERS]
        end = time.monotonic() + 10.0
        while time.monotonic() < end and not set(tail) <= {_stamp(m) for m in rig.out[answer_out]}:
            rig.spin(0.1)
        alive = rig.alive()
    finally:
        stderr = rig.close()
    assert alive and 'Traceback' not in stderr, stderr[-3000:]
    assert all(n >= FUZZ_COUNT for n in hostile.values()), hostile
    for topic in inputs:
        assert int(values[f'input.{topic}.received']) == sent[topic], (topic, values)
        assert int(values[f'input.{topic}.callback_errors']) == 0, (topic, values)
        assert int(values[f'input.{topic}.lost']) == 0, (topic, values)
    assert values['accounting_ok'] == 'True', values
    # a corrupt field is a named, counted rejection, never a core exception: at RFI_FUZZ_COUNT=20000 gnss_integrity's
    # monitor kept a range of 1e300 m (or a 1-sigma of 1e300, a range of 5e-324) as its anchor's newest and raised on
    # every epoch until the anchor was heard again: 3 of the 10 valid tail epochs unanswered (issue 27)
    assert int(values.get('core_exceptions', 0)) == 0, {k: v for k, v in values.items() if 'exception' in k}
    invalid = [(t, why) for t in outputs for m in rig.out[t] for why in invalid_outputs(t, m)]
    assert not invalid, invalid[:20]
    if before is not None:  # every valid block after the fuzz reached the receiver
        assert int(values['blocks_processed']) - int(before['blocks_processed']) == len(valid_tail), (before, values)
        return
    answered = {_stamp(m) for m in rig.out[answer_out]}
    missing = [stamp for stamp in tail if stamp not in answered]
    assert tail and not missing, (
        f'{len(missing)} of the {len(tail)} valid messages after the fuzz were not answered '
        f'(first {missing[:5]}; answered up to {max(answered, default=None)})',
        ' '.join(f'{k}={v}' for k, v in values.items() if 'reject' in k or 'late' in k or 'buffer' in k
                 or 'flush' in k or 'window' in k or 'restart' in k))


@pytest.mark.parametrize('name', list(NODES))
def test_silent_node_reports_stale_and_a_best_effort_publisher_is_accepted(name):
    package, inputs, outputs, seconds = NODES[name]
    rig = NodeProcess(name, reliable_inputs=False)
    try:
        stale = rig.latest_values(time.monotonic(), level=DiagnosticStatus.STALE)
        pubs = rig.publishers(qos_profile_sensor_data)
        valid = valid_messages(inputs, min(seconds, 2.0))
        for topic, msg in valid:
            pubs[topic].publish(msg)
            rig.spin(0.002)
        rig.spin(1.0)
        values = rig.latest_values(time.monotonic() + 1.0, level=DiagnosticStatus.STALE)
    finally:
        stderr = rig.close()
    assert 'Traceback' not in stderr, stderr[-3000:]
    assert all(int(stale[f'input.{t}.received']) == 0 for t in inputs), stale
    for topic in inputs:
        n = sum(1 for t, _ in valid if t == topic)
        received, lost = int(values[f'input.{topic}.received']), int(values[f'input.{topic}.lost'])
        assert received > 0 and received + lost == n, (topic, n, values)
    if name in ANSWERS:
        assert rig.out[outputs[0]], f'{name} published nothing for best-effort input'
    else:  # the correlator answers only a continuous stream (1 ms intervals once tracking): the blocks are taken
        assert int(values['blocks_processed']) > 0, values


@pytest.mark.slow
def test_messages_lost_at_a_high_rate_are_counted():
    """5,000 ranges as fast as possible into a subscription with a 10-message queue: those the node
    could not take are lost in the middleware; the node must count every one of them."""
    rig = NodeProcess('fusion_node', reliable_inputs=False,
                      extra_args=('-p', 'qos_overrides./uwb/ranges.subscription.depth:=10'))
    try:
        pubs = rig.publishers(qos_profile_sensor_data)
        ranges = [m for t, m in valid_messages(['/uwb/ranges'], 120.0) if t == '/uwb/ranges'][:5000]
        pubs['/uwb/ranges'].publish(ranges[0])  # taken before the burst: the stream's first number
        rig.spin(1.0)
        for msg in ranges[1:-1]:
            pubs['/uwb/ranges'].publish(msg)
        rig.spin(2.0)
        pubs['/uwb/ranges'].publish(ranges[-1])  # after a pause: a loss just before it is seen too
        rig.spin(0.5)
        values = rig.latest_values(time.monotonic() + 1.0, level=DiagnosticStatus.STALE)
    finally:
        stderr = rig.close()
    received = int(values['input./uwb/ranges.received'])
    lost = int(values['input./uwb/ranges.lost'])
    assert received + lost == len(ranges), values
    assert lost > 0, 'the burst was expected to overflow a 10-message queue'
    assert 'messages lost' in stderr
