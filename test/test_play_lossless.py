"""Issue 27 item 2: ``play --max`` into the nodes with their default input QoS delivers every message, or the
loss appears in the node's input counters and in play's summary.

Before: the nodes' inputs were best effort, so a fast replay of large IF blocks lost some that no counter showed
(a loss after the last received block leaves no sequence gap). Now an input takes its publishers' reliability
(best available, ``rfi_node_common.qos``): play is reliable, so the input is, and play waits for every message
to be acknowledged. The node runs in this process (default parameters), play in its own process, as a user
runs them. No wall-clock limit is asserted: the loops below wait for counted events, bounded only so that a
silent loss fails the test instead of hanging it.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest
import rclpy
from ament_index_python.packages import get_package_prefix
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from ros_fixtures import make_context

from rfi_experiments.bag_io import BagReader
from rfi_experiments.if_to_bag import main as if_to_bag
from rfi_node_common import testing
from rfi_node_common.qos import DATA_QOS_DEPTH

ROOT = Path(__file__).resolve().parents[1]
CAPTURE = ROOT / 'src' / 'rfi_monitor' / 'test' / 'data' / 'pocketsdr_L1_12MHz_I_10ms.bin'


def tool(name: str) -> str:
    return os.path.join(get_package_prefix('rfi_experiments'), 'lib', 'rfi_experiments', name)


def counts_in_window(bag: Path, topics: list[str], duration_s: float | None) -> dict[str, int]:
    """Messages of each topic that ``play --duration`` sends (the window starts at the bag's first message)."""
    with BagReader(bag) as reader:
        stop = None if duration_s is None else reader.start_ns + round(duration_s * 1e9)
        out = dict.fromkeys(topics, 0)
        for m in reader.messages(topics, stop_ns=stop):
            out[m.topic] += 1
    return out


def play_into(make_node, bag: Path, topics: list[str], duration_s: float | None = None,
              overrides: list[Parameter] | None = None):
    """Start the node, ``play --max`` the topics of ``bag`` into it, spin until the node has accounted for every
    message play sent (received + counted lost) or play's end plus :data:`BOUND_S`; return (the node's input
    counters, the count sent per topic, play's completed process)."""
    expected = counts_in_window(bag, topics, duration_s)
    context = make_context()
    node = make_node(context, overrides or [])
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    health = node.health
    window = [] if duration_s is None else ['--duration', str(duration_s)]
    player = subprocess.Popen([tool('play'), str(bag), '--max', '--no-progress', '--topics', *topics, *window,
                               '--wait-subscribers', '120', '--expect-subscribers', '1', '--ack-timeout', '300'],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        while player.poll() is None:
            executor.spin_once(timeout_sec=0.05)
        out, err = player.communicate()

        def accounted() -> bool:
            return all(health.counts[f'{t}.received'] + health.lost(t) >= n for t, n in expected.items())

        # until nothing more is taken for testing.STALL_S (a bound on a hang, not a measured limit): what was not
        # accounted for by then fails the assertions on the counters
        watch = testing.Stall(lambda: sum(health.counts[f'{t}.received'] + health.lost(t) for t in expected),
                              'the node taking what play sent')
        while not accounted():
            try:
                watch.check()
            except AssertionError:
                break
            executor.spin_once(timeout_sec=0.05)
        counters = {t: (health.counts[f'{t}.received'], health.lost(t)) for t in topics}
        reliability = {t: s.qos_profile.reliability.name for t, s in _subscriptions(node, topics).items()}
    finally:
        if player.poll() is None:
            player.kill()
            player.communicate()
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    return counters, expected, subprocess.CompletedProcess(player.args, player.returncode, out, err), reliability


def _subscriptions(node, topics):
    return {s.topic_name: s for s in node.subscriptions if s.topic_name in topics}


def monitor(context, overrides):
    from rfi_monitor.rfi_monitor_node import RfiMonitorNode
    return RfiMonitorNode(context=context, parameter_overrides=overrides)


def fusion(context, overrides):
    from uwb_gnss_fusion.fusion_node import FusionNode
    return FusionNode(context=context, parameter_overrides=overrides)


def imm(context, overrides):
    from imm_carrier.imm_carrier_node import ImmCarrierNode
    return ImmCarrierNode(context=context, parameter_overrides=overrides)


@pytest.fixture(scope='module')
def converted_capture(tmp_path_factory):
    """The real PocketSDR capture in the project (10 ms, 12 MS/s real), converted by if_to_bag in 0.5 ms blocks."""
    out = tmp_path_factory.mktemp('capture') / 'pocketsdr'
    assert if_to_bag(['if_to_bag', str(CAPTURE), str(out), '--item-type', 'byte', '--sampling-frequency-hz', '12e6',
                      '--intermediate-frequency-hz', '3e6', '--center-frequency-hz', '1575.42e6',
                      '--bits-per-sample', '2', '--start-time', '2021-11-25T00:40:00Z',
                      '--block-duration-s', '0.0005']) == 0
    return out


CASES = {
    # name: (node, bag, topics, --duration)
    'default_if_into_monitor': (monitor, ROOT / 'bags' / 'default', ['/rfi/if_samples'], None),
    'default_correlators_into_imm': (imm, ROOT / 'bags' / 'default', ['/gnss/correlators'], 10.0),
    'spoofed_into_fusion': (fusion, ROOT / 'bags' / 'spoofed', ['/gnss/measurements', '/uwb/ranges'], 10.0),
    # 1,800 UWB ranges in 300 s, more than the input's queue: a node that falls behind drops the oldest, counted
    'arl1_jammed_into_fusion': (fusion, ROOT / 'bags' / 'arl1_jammed', ['/gnss/measurements', '/uwb/ranges'], 300.0),
}


def assert_accounted(counters, expected, player, reliability):
    """Every message play sent was received by the node or counted lost by it; none lost while a topic sent no
    more than an input's queue depth (a reliable input then cannot drop any); play named what it sent."""
    assert player.returncode == 0, player.stderr
    for t, n in expected.items():
        assert n > 0
        assert reliability[t] == 'RELIABLE', reliability   # play is reliable, so the default input is
        received, lost = counters[t]
        assert received + lost == n, (t, counters[t], n)   # nothing lost unseen, nothing counted twice
        if n <= DATA_QOS_DEPTH:
            assert lost == 0, (t, counters[t], n)
        assert f'delivery {t}: {n} sent; reliable subscribers' in player.stdout, player.stdout
        assert 'every message acknowledged' in player.stdout
    assert 'best-effort subscriber' not in player.stderr


@pytest.mark.parametrize('case', sorted(CASES))
def test_play_max_of_the_bags_into_the_default_nodes_loses_nothing_unseen(case):
    make_node, bag, topics, duration_s = CASES[case]
    assert_accounted(*play_into(make_node, bag, topics, duration_s))


def test_play_max_of_a_converted_capture_into_the_monitor_loses_nothing(converted_capture):
    counters, expected, player, reliability = play_into(monitor, converted_capture, ['/rfi/if_samples'])
    assert expected == {'/rfi/if_samples': 20}
    assert_accounted(counters, expected, player, reliability)


def test_a_best_effort_input_is_named_in_plays_summary_with_what_was_sent(converted_capture):
    """Forced best effort (the parameter override): play cannot know what the node dropped, so it says how many
    it sent, that the subscriber is best effort, and how to make it reliable; what the node received plus what it
    counted lost never exceeds what was sent, and any loss it counted is not counted twice."""
    topic = '/rfi/if_samples'
    counters, expected, player, reliability = play_into(
        monitor, converted_capture, [topic],
        overrides=[Parameter(f'qos_overrides.{topic}.subscription.reliability', value='best_effort')])
    assert player.returncode == 0, player.stderr
    assert reliability[topic] == 'BEST_EFFORT'
    sent = f'delivery {topic}: {expected[topic]} sent; best-effort subscribers /rfi_monitor: not acknowledged'
    assert sent in player.stdout, player.stdout
    assert f'qos_overrides.{topic}.subscription.reliability:=reliable' in player.stderr
    received, lost = counters[topic]
    assert received + lost <= expected[topic]


def test_plays_summary_names_a_loss_that_a_subscriber_reports(capsys):
    """play reads the nodes' /diagnostics: a node's counted loss is named in the summary (the larger of the gap
    count and the middleware's, never their sum), and what it sent to whom is said per topic."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    from rfi_experiments.play import Delivery, print_receipts, read_input_reports

    topic = '/rfi/if_samples'
    values = {f'input.{topic}.received': '27', f'input.{topic}.lost': '23', f'input.{topic}.middleware_lost': '23',
              'input./other.received': '5'}
    msg = DiagnosticArray(status=[DiagnosticStatus(name='rfi_monitor', values=[
        KeyValue(key=k, value=v) for k, v in values.items()]), DiagnosticStatus(name='no_inputs')])
    reports: dict = {}
    read_input_reports(msg, [topic], reports)
    assert reports == {('rfi_monitor', topic): (27, 23)}
    delivery = {topic: Delivery(published=50, subscribers=1, best_effort={'/rfi_monitor'})}
    print_receipts(delivery, reports, [])
    out, err = capsys.readouterr()
    assert f'delivery {topic}: 50 sent; best-effort subscribers /rfi_monitor: not acknowledged' in out
    assert f'delivery {topic}: rfi_monitor reported (last /diagnostics) 27 received, 23 lost' in out
    assert f'play: warning: {topic}: rfi_monitor reports 23 messages lost' in err
    print_receipts({topic: Delivery(published=50, subscribers=1, reliable={'/rfi_monitor'})}, {}, [topic])
    out, err = capsys.readouterr()
    assert 'reliable subscribers /rfi_monitor: not every message acknowledged' in out and err == ''
