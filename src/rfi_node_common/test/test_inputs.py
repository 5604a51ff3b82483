"""Input subscriptions (rfi_node_common.inputs) in-process: any publisher accepted, a raising handler
counted, the QoS override honoured, silence reported."""

from __future__ import annotations

import time

import pytest
import rclpy
from rclpy.context import Context
from rclpy.parameter import Parameter
from rclpy.qos import ReliabilityPolicy, qos_profile_sensor_data
from std_msgs.msg import String

from rfi_node_common.inputs import InputHealth, StaleInputWatch, subscribe_input
from rfi_node_common.qos import DATA_QOS, INPUT_QOS, best_available_reliability
from rfi_node_common.testing import CountingExecutor, wait_until

TOPIC = '/test_inputs/chatter'


@pytest.fixture
def context():
    ctx = Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def spin_until(executor, done):
    """Spin until ``done()``; fail once nothing progressed (no message taken, when the executor counts them:
    ``testing.CountingExecutor``) for ``testing.STALL_S``, not after a fixed 10 s."""
    wait_until(done, lambda: executor.spin_once(timeout_sec=0.05), lambda: getattr(executor, 'messages_taken', 0),
               'timed out')


def test_best_effort_and_reliable_publishers_are_both_received_and_a_raising_handler_is_counted(context):
    node = rclpy.create_node('inputs_under_test', context=context)
    got = []

    def handler(msg):
        if msg.data == 'bad':
            raise ValueError('a handler bug')
        got.append(msg.data)

    health = InputHealth()
    sub = subscribe_input(node, String, TOPIC, handler, health)
    assert sub.qos_profile.reliability == ReliabilityPolicy.RELIABLE and sub.adaptive  # no publisher yet
    assert INPUT_QOS.reliability == ReliabilityPolicy.BEST_AVAILABLE  # the shared profile is not modified
    io = rclpy.create_node('io', context=context)
    sensor = io.create_publisher(String, TOPIC, qos_profile_sensor_data)
    reliable = io.create_publisher(String, TOPIC, DATA_QOS)
    executor = CountingExecutor(context=context)
    executor.add_node(node)
    executor.add_node(io)
    # the driver that appeared later makes the input best effort (REP 2003: it is still received)
    spin_until(executor, lambda: sensor.get_subscription_count() and reliable.get_subscription_count())
    assert sub.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT and sub.switches == 1
    spin_until(executor, lambda: health.publishers[TOPIC] == 2)
    sensor.publish(String(data='from a driver'))
    spin_until(executor, lambda: len(got) == 1)
    reliable.publish(String(data='bad'))
    reliable.publish(String(data='from a node'))
    spin_until(executor, lambda: len(got) == 2)
    assert got == ['from a driver', 'from a node']
    assert health.counts[f'{TOPIC}.received'] == 3
    assert health.counts[f'{TOPIC}.callback_errors'] == 1
    assert health.lost_total() == 0
    assert health.values()[f'input.{TOPIC}.received'] == 3


def test_the_qos_override_parameter_makes_an_input_reliable(context):
    node = rclpy.create_node('inputs_under_test', context=context, parameter_overrides=[
        Parameter(f'qos_overrides.{TOPIC}.subscription.reliability', value='reliable')])
    sub = subscribe_input(node, String, TOPIC, lambda msg: None, InputHealth())
    assert sub.qos_profile.reliability == ReliabilityPolicy.RELIABLE and not sub.adaptive
    assert INPUT_QOS.reliability == ReliabilityPolicy.BEST_AVAILABLE


def test_a_best_effort_override_stays_best_effort_with_reliable_publishers(context):
    node = rclpy.create_node('inputs_under_test', context=context, parameter_overrides=[
        Parameter(f'qos_overrides.{TOPIC}.subscription.reliability', value='best_effort')])
    io = rclpy.create_node('io', context=context)
    io.create_publisher(String, TOPIC, DATA_QOS)
    sub = subscribe_input(node, String, TOPIC, lambda msg: None, InputHealth())
    assert sub.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT and not sub.adaptive


def test_best_available_follows_the_publishers_in_the_graph():
    """rmw_dds_common's rule: reliable iff every publisher is reliable (none: reliable)."""
    assert best_available_reliability([]) == ReliabilityPolicy.RELIABLE
    assert best_available_reliability([ReliabilityPolicy.RELIABLE] * 2) == ReliabilityPolicy.RELIABLE
    assert best_available_reliability([ReliabilityPolicy.RELIABLE,
                                       ReliabilityPolicy.BEST_EFFORT]) == ReliabilityPolicy.BEST_EFFORT


def test_an_input_made_after_a_driver_started_is_best_effort_and_one_after_a_player_reliable(context):
    """A node started while a best-effort driver publishes matches it at once; one started while play (reliable)
    publishes is reliable, so nothing play sends is lost unseen."""
    io = rclpy.create_node('io', context=context)
    io.create_publisher(String, TOPIC + '_driver', qos_profile_sensor_data)
    io.create_publisher(String, TOPIC + '_play', DATA_QOS)
    node = rclpy.create_node('inputs_under_test', context=context)
    executor = CountingExecutor(context=context)
    executor.add_node(io)
    executor.add_node(node)
    spin_until(executor, lambda: node.get_publishers_info_by_topic(TOPIC + '_driver')
               and node.get_publishers_info_by_topic(TOPIC + '_play'))
    driver = subscribe_input(node, String, TOPIC + '_driver', lambda msg: None, InputHealth())
    player = subscribe_input(node, String, TOPIC + '_play', lambda msg: None, InputHealth())
    assert driver.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT and driver.switches == 0
    assert player.qos_profile.reliability == ReliabilityPolicy.RELIABLE and player.switches == 0


def test_a_loss_seen_by_the_sequence_gap_and_by_the_middleware_is_counted_once():
    """Issue 27: 27 of 50 blocks received, 46 counted lost: the gap count and the middleware's lost-message
    event saw the same 23 losses and were added."""
    health = InputHealth()
    health.add_topic(TOPIC)
    for seq in range(1, 28):
        health.arrived(TOPIC, seq if seq < 5 else seq + 23)   # 5..27 never arrived
    health.middleware_lost(TOPIC, 23)                         # what Fast DDS reports for the same gap
    assert health.counts[f'{TOPIC}.lost'] == 23 and health.counts[f'{TOPIC}.middleware_lost'] == 23
    assert health.lost(TOPIC) == 23 and health.lost_total() == 23
    health.middleware_lost(TOPIC, 2)                          # a loss only the middleware saw
    assert health.lost_total() == 25


def test_stale_watch_reports_silence_since_start_and_after_the_last_message():
    now = [100.0]
    health = InputHealth(clock=lambda: now[0])
    health.add_topic(TOPIC)
    reports = []

    class FakeNode:
        def create_timer(self, *args, **kwargs):
            return None

    watch = StaleInputWatch(FakeNode(), health, 5.0, reports.append)
    assert not watch.check()
    now[0] = 105.0
    assert watch.check() and reports == [5.0]
    health.arrived(TOPIC, 0)
    now[0] = 108.0
    assert not watch.check()
    now[0] = 110.5
    assert watch.check() and reports[-1] == pytest.approx(5.5)
    assert StaleInputWatch(FakeNode(), health, 0.0, reports.append).timer is None


def test_queued_s_is_the_time_a_message_waited_since_the_middleware_received_it(context):
    """The input records rmw's received_timestamp of the message being handled: a handler that runs 50 ms after the
    message arrived reads at least 50 ms of queueing (rfi_monitor_node's light analysis uses it); None before any."""
    node = rclpy.create_node('inputs_queue_under_test', context=context)
    health = InputHealth()
    assert health.queued_s() is None
    seen: list[float | None] = []
    subscribe_input(node, String, TOPIC + '_queue', lambda msg: seen.append(health.queued_s()), health)
    io = rclpy.create_node('io_queue', context=context)
    pub = io.create_publisher(String, TOPIC + '_queue', DATA_QOS)
    executor = CountingExecutor(context=context)
    executor.add_node(node)
    executor.add_node(io)
    spin_until(executor, lambda: pub.get_subscription_count() and health.publishers[TOPIC + '_queue'] >= 1)
    pub.publish(String(data='now'))
    spin_until(executor, lambda: len(seen) == 1)
    pub.publish(String(data='later'))
    time.sleep(0.05)                                # the message waits in the subscription's queue
    spin_until(executor, lambda: len(seen) == 2)
    assert seen[0] is not None and seen[1] is not None   # this middleware reports reception times
    # the second waited at least the sleep; the first as long as the spin took to take it (on a loaded machine that
    # can be longer than the second's wait: the two are not compared)
    assert seen[0] >= 0.0 and seen[1] >= 0.05
