"""Input subscriptions (rfi_node_common.inputs) in-process: any publisher accepted, a raising handler
counted, the QoS override honoured, silence reported."""

from __future__ import annotations

import time

import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import ReliabilityPolicy, qos_profile_sensor_data
from std_msgs.msg import String

from rfi_node_common.inputs import InputHealth, StaleInputWatch, subscribe_input
from rfi_node_common.qos import DATA_QOS, INPUT_QOS

TOPIC = '/test_inputs/chatter'


@pytest.fixture
def context():
    ctx = Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def spin_until(executor, done, timeout_s=10.0):
    end = time.monotonic() + timeout_s
    while not done():
        assert time.monotonic() < end, 'timed out'
        executor.spin_once(timeout_sec=0.05)


def test_best_effort_and_reliable_publishers_are_both_received_and_a_raising_handler_is_counted(context):
    node = rclpy.create_node('inputs_under_test', context=context)
    got = []

    def handler(msg):
        if msg.data == 'bad':
            raise ValueError('a handler bug')
        got.append(msg.data)

    health = InputHealth()
    sub = subscribe_input(node, String, TOPIC, handler, health)
    assert sub.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
    assert INPUT_QOS.reliability == ReliabilityPolicy.BEST_EFFORT  # the shared profile is not modified
    io = rclpy.create_node('io', context=context)
    sensor = io.create_publisher(String, TOPIC, qos_profile_sensor_data)
    reliable = io.create_publisher(String, TOPIC, DATA_QOS)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(io)
    spin_until(executor, lambda: sensor.get_subscription_count() and reliable.get_subscription_count())
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
    assert sub.qos_profile.reliability == ReliabilityPolicy.RELIABLE
    assert INPUT_QOS.reliability == ReliabilityPolicy.BEST_EFFORT


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
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(io)
    spin_until(executor, lambda: pub.get_subscription_count() and health.publishers[TOPIC + '_queue'] >= 1)
    pub.publish(String(data='now'))
    spin_until(executor, lambda: len(seen) == 1)
    pub.publish(String(data='later'))
    time.sleep(0.05)                                # the message waits in the subscription's queue
    spin_until(executor, lambda: len(seen) == 2)
    assert seen[0] is not None and seen[1] is not None   # this middleware reports reception times
    assert 0.0 <= seen[0] < seen[1] and seen[1] >= 0.05
