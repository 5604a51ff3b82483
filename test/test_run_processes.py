"""`run --transport processes`: the three node executables as separate processes fed by `play`.

A 3 s window of bags/default around the CW onset (every input type; jammer states reach the
fusion) is replayed by `run` as a user runs it, once with the node processes and once with the
direct transport, each writing what the nodes published (--record-outputs). The two must agree
field for field on every output topic: the processes see the same inputs in the same order per
node (a single publisher per input topic; the fusion re-orders its inputs by stamp), so no float
tolerance is needed. Every input is accounted for: played, and counted by the node that takes it.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path

import pytest

from rfi_experiments.bag_io import BagReader
from rfi_node_common import testing

pytestmark = pytest.mark.usefixtures('warm_kernels')   # the nodes load their kernels from the cache (conftest.py)

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / 'bags' / 'default'
PARAMS = ROOT / 'bags' / 'default.params.yaml'
WINDOW = ('--start', '28', '--duration', '3')
INPUTS = {'/gnss/correlators': 'imm_carrier', '/gnss/measurements': 'uwb_gnss_fusion',
          '/rfi/if_samples': 'rfi_monitor', '/uwb/ranges': 'uwb_gnss_fusion'}
RECEIVED_KEY = {'/gnss/correlators': 'arrays_received', '/gnss/measurements': 'gnss_received',
                '/rfi/if_samples': 'blocks_received', '/uwb/ranges': 'uwb_received'}


def run(tmp: Path, transport: str) -> tuple[subprocess.CompletedProcess, Path]:
    out = tmp / transport
    proc = subprocess.Popen(
        [sys.executable, '-m', 'rfi_experiments.run', str(BAG), '--out', str(out), '--params-file', str(PARAMS),
         '--transport', transport, *WINDOW, '--no-progress', '--record-outputs', str(out / 'outputs')],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # bounded by progress (run and its nodes spend CPU), not by a fixed 120 s; on a stall, interrupt, not kill: run
    # stops its node processes on Ctrl-C (test_ctrl_c_stops_every_process), a killed run would leave them running
    stdout, stderr = testing.communicate(proc, f'run --transport {transport} did not end (interrupted, nodes stopped)',
                                         stop_signal=signal.SIGINT)
    done = subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)
    assert done.returncode == 0, done.stderr
    assert 'Traceback' not in done.stderr
    return done, out


def fields(msg):
    """A message as nested tuples, NaN-safe (compares deserialised fields, not CDR padding)."""
    if hasattr(msg, 'get_fields_and_field_types'):
        return tuple((name, fields(getattr(msg, name))) for name in msg.get_fields_and_field_types())
    if isinstance(msg, (list, tuple)) or type(msg).__name__ == 'array' or hasattr(msg, 'tolist'):
        return tuple(fields(v) for v in (msg.tolist() if hasattr(msg, 'tolist') else msg))
    if isinstance(msg, float) and math.isnan(msg):
        return 'nan'
    return msg


def outputs(bag: Path) -> dict[str, list]:
    """Topic -> fields of each message in receive order; /diagnostics split per reporting node
    (the nodes' reports interleave differently across processes, each node's are in order), the
    STALE reports apart: a node process publishes one, stamped on the wall clock, while it waits for
    input (before play starts, after it ends); the stamp-timed reports are what the nodes compute."""
    from diagnostic_msgs.msg import DiagnosticStatus

    got: dict[str, list] = defaultdict(list)
    with BagReader(bag) as reader:
        for message in reader.messages():
            msg = message.decode()
            if message.topic == '/diagnostics':
                for status in msg.status:
                    stale = status.level == DiagnosticStatus.STALE
                    got[f'/diagnostics[{status.name}]{" STALE" if stale else ""}'].append(
                        (fields(msg.header), fields(status)))
            else:
                got[message.topic].append(fields(msg))
    return dict(got)


def without(names):
    """Message fields (as from fields()) without the named top-level fields."""
    return lambda msg: tuple(item for item in msg if item[0] not in names)


FUSION_REPORT = '/diagnostics[uwb_gnss_fusion]'
FUSION_KINDS = ('gnss', 'uwb', 'jammer', 'integrity')
"""The fusion's inputs, as its counters name them."""


def is_arrival_counter(key: str) -> bool:
    """Whether a value of the fusion's /diagnostics counts the inputs *received so far* (on arrival, before its
    re-ordering buffer) rather than what it processed in stamp order: ``<kind>_received`` / ``_rejected`` /
    ``_buffered``, the satellites of the epochs received, the subscriptions' ``input.<topic>.*``, the reasons of
    rejections on arrival (``rejected.*``) and the window fractions computed from them."""
    kind, _, what = key.partition('_')
    return ((kind in FUSION_KINDS and what in ('received', 'rejected', 'buffered'))
            or key in ('satellites_received', 'satellites_without_state')
            or key.startswith(('input.', 'rejected.'))
            or (key.startswith('window.') and key != 'window.satellites_rejected_fraction'))


def report_values(entry) -> dict[str, str]:
    """key -> value of a /diagnostics entry (header, status) as outputs() gives it."""
    _, status = entry
    return {kv[0][1]: kv[1][1] for kv in dict(status)['values']}


def fusion_report_without_arrivals(entry):
    """A fusion /diagnostics entry (header, status) without its level, message and arrival counters."""
    header, status = entry
    kept = tuple(kv for kv in dict(status)['values'] if not is_arrival_counter(kv[0][1]))
    return header, tuple(item for item in status if item[0] not in ('level', 'message', 'values')), kept


ARRIVAL_TIMED = {
    '/fusion/status': without({'rejection_reasons', 'rejection_counts'}),
    FUSION_REPORT: fusion_report_without_arrivals,
}
"""Outputs that carry counters of the inputs *received so far* rather than of the inputs processed. The fusion
counts an input when it arrives, before its re-ordering buffer, and publishes /diagnostics when the first input
stamped a period after the last report arrives, so a report's arrival counters are a snapshot of the order in
which its inputs arrived across topics. In one process that order is the bag's, with each node's outputs right
after the input that caused them (the direct transport queues them). Across processes it is the machine's: a
/gnss/integrity verdict of epoch t is computed by another process from the same GNSS message, and reaches the
fusion before that message does whenever ``play`` is descheduled between its sends to its two subscribers
(gnss_integrity, then the fusion) for longer than gnss_integrity takes; the verdict, stamped t, then triggers the
report at t itself (``integrity_received`` 11 and ``gnss_received`` 10 in the report at 30 s, where the direct
replay has 10 and 11: a failure seen once under heavy load). Likewise a jammer state rejected on arrival (NaN J/S
while the monitor calibrates), a message held in a reliable retransmission, and the executor's one message per
subscription per turn after the node was descheduled. The last report is no final tally either (the last one here
is at 30 s of a window that ends at 31 s). So these counters are left out of the comparison of every report and
checked instead by what holds in any arrival order (:func:`assert_arrivals_bounded`); what the fusion computes in
stamp order (processed counts, filter, exclusions, every estimate) is compared field for field in every report.
The last /fusion/status is published after every input (the end-of-input flush) and is compared in full."""


def without_idle_flushes(entry):
    """A fusion /diagnostics entry (header, status) without its ``idle_flushes`` counter: the fusion
    processes its re-ordering buffer when no input has come for ``idle_flush_s`` of wall time, so how
    often that happens during a run depends on the machine's load (two suites on two shared cores:
    play waits longer for the monitor), not on the data; what the flushed messages give is compared."""
    header, status = entry
    return header, tuple((name, tuple(kv for kv in value if kv[0][1] != 'idle_flushes')) if name == 'values'
                         else (name, value) for name, value in status)


def stamp_ns_of(fields_of_header) -> int:
    stamp = dict(dict(fields_of_header)['stamp'])
    return stamp['sec'] * 1_000_000_000 + stamp['nanosec']


def assert_arrivals_bounded(got: dict[str, list], inputs: dict[str, list[int]]) -> None:
    """The arrival counters of every fusion report (header stamp S) bounded by what any arrival order allows:
    ``<kind>_processed <= <kind>_received <= `` the inputs of that kind stamped at or before S (a report is
    published on the first input stamped S, so nothing newer has arrived), inputs' stamps from ``inputs``
    (kind -> stamps of the messages fed to the fusion); the accounting adds up and nothing is lost."""
    for entry in got[FUSION_REPORT]:
        stamp = stamp_ns_of(entry[0])
        values = report_values(entry)
        assert values['accounting_ok'] == 'True', values
        for kind, stamps in inputs.items():
            processed, received = int(values[f'{kind}_processed']), int(values[f'{kind}_received'])
            assert processed <= received <= sum(1 for t in stamps if t <= stamp), (kind, stamp, values)
        assert not any(int(v) for k, v in values.items() if k.endswith(('.lost', '.middleware_lost'))), values
        assert 'rejected.late_beyond_reorder_window' not in values, values


def fusion_inputs(outs: dict[str, list]) -> dict[str, list[int]]:
    """kind -> stamps of the fusion's inputs in the replayed window: GNSS and UWB from the bag, the jammer states
    and integrity verdicts the nodes published (recorded in ``outs``)."""
    with BagReader(BAG) as reader:
        start = reader.start_ns + round(float(WINDOW[1]) * 1e9)
        stop = start + round(float(WINDOW[3]) * 1e9)
        stamps: dict[str, list[int]] = defaultdict(list)
        for message in reader.messages(['/gnss/measurements', '/uwb/ranges'], start_ns=start, stop_ns=stop):
            header = message.decode().header.stamp
            stamps['gnss' if message.topic == '/gnss/measurements' else 'uwb'].append(
                header.sec * 1_000_000_000 + header.nanosec)
    for kind, topic in (('jammer', '/rfi/jammer_state'), ('integrity', '/gnss/integrity')):
        stamps[kind] = [stamp_ns_of(dict(m)['header']) for m in outs.get(topic, [])]
    return dict(stamps)


def assert_outputs_equal(got: dict[str, list], expected: dict[str, list]) -> None:
    """What a replay through node processes published (``got``, without the wall-clock STALE reports) equals the
    direct replay's (``expected``), field for field, but for the arrival counters (ARRIVAL_TIMED), which are
    bounded instead, and the fusion's wall-time ``idle_flushes``."""
    got, expected = dict(got), dict(expected)
    for outs in (got, expected):
        if FUSION_REPORT in outs:
            outs[FUSION_REPORT] = [without_idle_flushes(m) for m in outs[FUSION_REPORT]]
    assert set(got) == set(expected)
    assert {'/rfi/jammer_state', '/fusion/odometry', '/fusion/status', '/carrier/estimates',
            '/diagnostics[rfi_monitor]', FUSION_REPORT, '/diagnostics[imm_carrier]'} <= set(got)
    for topic in expected:
        assert len(got[topic]) == len(expected[topic]), topic
        if topic in ARRIVAL_TIMED:
            if topic != FUSION_REPORT:  # published after every input: see ARRIVAL_TIMED
                assert got[topic][-1] == expected[topic][-1], topic
            assert [ARRIVAL_TIMED[topic](m) for m in got[topic]] == [ARRIVAL_TIMED[topic](m) for m in expected[topic]]
        else:
            assert got[topic] == expected[topic], topic
    assert_arrivals_bounded(got, fusion_inputs(got))
    assert_arrivals_bounded(expected, fusion_inputs(expected))


@pytest.fixture(scope='module')
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('run')
    # direct first: it compiles the nodes' numba code into the install tree's cache, which the node
    # processes then load; a cold compile inside three processes on two cores (15-30 s each) makes the
    # fusion lag past its re-ordering window (run warns about it), which is not what this compares
    direct = run(tmp, 'direct')
    return run(tmp, 'processes'), direct


def test_processes_outputs_equal_direct_field_for_field(runs):
    (_, processes), (_, direct) = runs
    got, expected = outputs(processes / 'outputs'), outputs(direct / 'outputs')
    got = {t: v for t, v in got.items() if not t.endswith(' STALE')}
    # field for field but for the arrival counters, which are bounded (and no message reached the fusion after its
    # re-ordering window): see ARRIVAL_TIMED
    assert_outputs_equal(got, expected)
    # the same report figures
    assert json.loads((processes / 'summary.json').read_text()) == json.loads((direct / 'summary.json').read_text())


def test_every_input_played_and_counted_by_its_node(runs):
    (done, processes), _ = runs
    with BagReader(BAG) as reader:
        start = reader.start_ns + 28_000_000_000
        stop = reader.start_ns + 31_000_000_000
        stamps = defaultdict(list)
        for message in reader.messages(list(INPUTS), start_ns=start, stop_ns=stop):
            header = message.decode().header.stamp
            stamps[message.topic].append(header.sec * 1_000_000_000 + header.nanosec)
    replay = (processes / 'replay.md').read_text()
    for topic, values in stamps.items():
        assert f'| {topic} | in | {len(values)} |' in replay
    played = [line.split()[1:] for line in (processes / 'logs' / 'play.log').read_text().splitlines()
              if line.startswith('total ')]
    assert played == [[str(sum(len(v) for v in stamps.values())), '0']]  # published, to nobody
    # play paced itself on the monitor and on gnss_integrity: every IF block was answered by a jammer state, every
    # GNSS epoch by a verdict (processes.SYNCED)
    play_log = (processes / 'logs' / 'play.log').read_text()
    assert f'sync /rfi/if_samples -> /rfi/jammer_state: {len(stamps["/rfi/if_samples"])} answered, 0 not within' \
        in play_log
    assert (f'sync /gnss/measurements -> /gnss/integrity: {len(stamps["/gnss/measurements"])} answered, '
            '0 not within') in play_log
    # each node's last report counts every input stamped before it (an input with that very stamp
    # may come just after the one that triggered the report) and its accounting adds up
    last: dict[str, tuple[int, dict[str, str]]] = {}
    with BagReader(processes / 'outputs') as reader:
        for message in reader.messages(['/diagnostics']):
            msg = message.decode()
            for status in msg.status:
                stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
                last[status.name] = (stamp, {kv.key: kv.value for kv in status.values})
    for topic, node in INPUTS.items():
        stamp, values = last[node]
        assert values['accounting_ok'] == 'True', node
        before = sum(1 for t in stamps[topic] if t < stamp)
        up_to = sum(1 for t in stamps[topic] if t <= stamp)
        assert 0 < before <= int(values[RECEIVED_KEY[topic]]) <= up_to, (topic, values)
    assert 'rfi_monitor 0, gnss_integrity 0, uwb_gnss_fusion 0, imm_carrier 0, play 0' in replay


def test_replay_through_processes_is_reliable_end_to_end_and_loses_nothing(runs):
    """The nodes' inputs are best effort by default (sensor drivers); `run` makes them reliable, play
    waits for them, and every input is answered: the first IF block too (lost every time before)."""
    (done, processes), _ = runs
    logs = processes / 'logs'
    for name, topics in (('rfi_monitor', ['/rfi/if_samples']), ('imm_carrier', ['/gnss/correlators']),
                         ('uwb_gnss_fusion', ['/gnss/measurements', '/uwb/ranges', '/rfi/jammer_state']),
                         ('gnss_integrity', ['/gnss/measurements', '/uwb/ranges', '/rfi/jammer_state'])):
        command = (logs / f'{name}.log').read_text().splitlines()[0]
        for topic in topics:
            assert f'-p qos_overrides.{topic}.subscription.reliability:=reliable' in command, (name, command)
    play_log = (logs / 'play.log').read_text()
    assert 'best-effort subscriber' not in play_log and 'to nobody' in play_log
    rows = {line.split()[0]: line.split()[2:] for line in play_log.splitlines() if line.startswith('/')}
    with BagReader(BAG) as reader:
        start = reader.start_ns + 28_000_000_000
        inputs = {t: [m.decode().header.stamp for m in reader.messages([t], start_ns=start,
                                                                         stop_ns=start + 3_000_000_000)]
                  for t in INPUTS}
    for topic, stamps in inputs.items():
        subscribers = '2' if topic in ('/gnss/measurements', '/uwb/ranges') else '1'  # + gnss_integrity
        assert rows[topic] == [str(len(stamps)), subscribers, '0'], play_log  # published, subscribers, to nobody
    got = outputs(processes / 'outputs')
    # the first IF block and the first correlator array are answered
    for inp, out in (('/rfi/if_samples', '/rfi/jammer_state'), ('/gnss/correlators', '/carrier/estimates')):
        first = inputs[inp][0]
        assert dict(dict(got[out][0])['header'])['stamp'] == (('sec', first.sec), ('nanosec', first.nanosec)), out
    # every GNSS epoch and UWB range was processed (one status each; the last ones at the end of input)
    assert len(got['/fusion/status']) == len(inputs['/gnss/measurements']) + len(inputs['/uwb/ranges'])
    assert len(got['/carrier/estimates']) == len(inputs['/gnss/correlators'])
    # no node counted an input message lost
    for name in ('rfi_monitor', 'uwb_gnss_fusion', 'imm_carrier'):
        _, status = got[f'/diagnostics[{name}]'][-1]
        lost = {kv[0][1]: kv[1][1] for kv in dict(status)['values'] if kv[0][1].endswith(('.lost', '.middleware_lost'))}
        assert not any(int(v) for v in lost.values()), (name, lost)
    assert 'warning' not in done.stdout and 'lost' not in done.stderr



def test_processes_report_is_complete(runs):
    (done, processes), _ = runs
    for name in ('index.md', 'summary.json', 'replay.md', 'jammer.png', 'carrier.png'):
        assert (processes / name).is_file(), name
    # 3 s: shorter than the positioning's convergence time, which the report says instead of scoring
    assert '| GNSS+UWB (fusion_node) | no sample after the first 10 s (convergence)' in (
        processes / 'index.md').read_text()
    assert 'processes transport' in done.stdout


def cmdline(pid: int) -> str | None:
    try:
        return Path(f'/proc/{pid}/cmdline').read_bytes().replace(b'\0', b' ').decode()
    except OSError:
        return None


def children_of(pid: int) -> dict[int, str]:
    """pid -> command line of the live child processes of ``pid`` (from /proc)."""
    kids = {}
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / 'stat').read_text().rsplit(')', 1)[1].split()[1])
            cmdline = (entry / 'cmdline').read_bytes().replace(b'\0', b' ').decode()
        except (OSError, IndexError, ValueError):
            continue
        if ppid == pid:
            kids[int(entry.name)] = cmdline
    return kids


def names(kids: dict[int, str]) -> set[str]:
    """Executable names of command lines (the script, for a Python entry point)."""
    out = set()
    for cmd in kids.values():
        words = cmd.split()
        out.add(Path(words[1] if 'python' in Path(words[0]).name and len(words) > 1 else words[0]).name)
    return out


def test_ctrl_c_stops_every_process(tmp_path):
    out = tmp_path / 'interrupted'
    proc = subprocess.Popen(
        [sys.executable, '-m', 'rfi_experiments.run', str(BAG), '--out', str(out), '--params-file', str(PARAMS),
         '--transport', 'processes', '--start', '28', '--duration', '60', '--no-progress'],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    kids: dict[int, str] = {}
    try:
        # the three nodes are up and play is running; bounded by progress: a new process, or CPU spent by run and
        # its nodes (a cold numba cache compiles for minutes beside a hog), not by a fixed 60 s
        watch = testing.Stall(lambda: (len(kids), testing.process_cpu_s(proc.pid)), 'run did not start the nodes '
                              'and play', look_every_s=0.5)
        while not {'rfi_monitor_node', 'gnss_integrity_node', 'fusion_node', 'imm_carrier_node', 'play'} <= names(kids):
            assert proc.poll() is None, proc.communicate()[1]
            try:
                watch.check()
            except AssertionError as e:
                raise AssertionError(f'{e}: {kids}') from None
            time.sleep(0.1)     # a poll of the process tree
            kids = children_of(proc.pid)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)   # kept on the wall clock: stopping promptly on Ctrl-C is what is tested
    finally:
        if proc.poll() is None:  # a failure above: stop run (and so its processes) as a user would
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
        left = [pid for pid, cmd in kids.items() if cmdline(pid) == cmd]
        for pid in left:  # never leave a node behind, even when the test fails
            os.kill(pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    assert 'interrupted' in err and 'Traceback' not in err
    assert not left, f'left running after Ctrl-C: {left}'
