"""Diagnostics helpers: windowed counts, degraded-input texts, hardware_id, and the /diagnostics QoS
against the profiles the ROS 2 diagnostics stack uses."""

from __future__ import annotations

import copy

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSCompatibility,
    QoSProfile,
    ReliabilityPolicy,
    qos_check_compatible,
    qos_profile_system_default,
)

from rfi_node_common.diagnostics import (
    ERROR,
    OK,
    WARN,
    CountWindow,
    counted_level,
    degraded_inputs,
    diagnostic_array,
    fraction,
    publish_status,
)
from rfi_node_common.qos import DIAGNOSTICS_QOS, LATCHED_QOS
from rfi_node_common.testing import CountingExecutor, wait_until

S = 1_000_000_000


def test_count_window_gives_the_increase_over_the_last_window_of_stamp_time():
    window = CountWindow(10.0)
    # one rejection per second, 60 ranges per second
    deltas = [window.update(t * S, {'rejected': t, 'received': 60 * t}) for t in range(0, 31)]
    assert deltas[0] == {'rejected': 0, 'received': 0}
    assert deltas[5] == {'rejected': 5, 'received': 300}          # since start while filling
    assert deltas[10] == {'rejected': 10, 'received': 600}
    assert deltas[30] == {'rejected': 10, 'received': 600}        # the last 10 s only
    assert fraction(deltas[30]['rejected'], deltas[30]['received']) == pytest.approx(1 / 60)
    # a burst leaves the window 10 s later
    window = CountWindow(10.0)
    totals = [0] * 5 + [50] * 30
    out = [window.update(t * S, {'n': n}) for t, n in enumerate(totals)]
    assert out[5]['n'] == 50 and out[14]['n'] == 50 and out[15]['n'] == 0
    # a stamp older than the last one (time line restarted) starts again from zero
    assert window.update(3 * S, {'n': 60}) == {'n': 60}
    assert window.update(4 * S, {'n': 61}) == {'n': 61}


def test_count_window_rejects_a_non_positive_window():
    with pytest.raises(ValueError):
        CountWindow(0.0)


def test_degraded_inputs_names_only_the_fractions_above_the_threshold():
    checks = [('UWB ranges rejected', 10, 600), ('satellites rejected', 51, 450), ('nothing', 0, 0)]
    assert degraded_inputs(checks, 0.1) == ['satellites rejected 51/450 (11%)']
    assert degraded_inputs(checks, 1.0) == []
    assert degraded_inputs(checks, 0.0) == ['UWB ranges rejected 10/600 (2%)', 'satellites rejected 51/450 (11%)']
    assert fraction(3, 0) == 0.0


def test_status_carries_the_hardware_id_given():
    array = diagnostic_array(5 * S, 'uwb_gnss_fusion', 'ublox-f9p#123', WARN, 'x', {'a': 1})
    status = array.status[0]
    assert status.hardware_id == 'ublox-f9p#123' and status.name == 'uwb_gnss_fusion' and status.level == WARN
    assert array.header.stamp.sec == 5 and status.values[0].key == 'a' and status.values[0].value == '1'
    assert diagnostic_array(S, 'n', 'h', OK, '', {}).status[0].level == OK


# Profiles of the ROS 2 diagnostics stack (ros/diagnostics, Jazzy). SYSTEM_DEFAULT policies resolved as
# the shipped middlewares (Fast DDS, Cyclone DDS) resolve them: reliable, volatile, automatic liveliness.
# diagnostic_aggregator's subscription: rclcpp::SystemDefaultsQoS().keep_last(history_depth) (aggregator.cpp)
AGGREGATOR = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE, liveliness=LivelinessPolicy.AUTOMATIC)
BEST_EFFORT_MONITOR = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.BEST_EFFORT,
                                 durability=DurabilityPolicy.VOLATILE, liveliness=LivelinessPolicy.AUTOMATIC)
# diagnostic_updater's own publisher: create_publisher(..., "/diagnostics", 1) (default profile, depth 1)
UPDATER = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE, liveliness=LivelinessPolicy.AUTOMATIC)


def resolved(profile: QoSProfile) -> QoSProfile:
    """``profile`` with a SYSTEM_DEFAULT liveliness resolved to AUTOMATIC, as the middlewares do."""
    out = copy.copy(profile)
    if out.liveliness == LivelinessPolicy.SYSTEM_DEFAULT:
        out.liveliness = LivelinessPolicy.AUTOMATIC
    return out


@pytest.mark.parametrize('subscriber', [AGGREGATOR, BEST_EFFORT_MONITOR, UPDATER],
                         ids=['aggregator', 'best_effort', 'updater'])
def test_diagnostics_qos_matches_what_the_diagnostics_stack_subscribes_with(subscriber):
    compatibility, reason = qos_check_compatible(resolved(DIAGNOSTICS_QOS), subscriber)
    assert compatibility == QoSCompatibility.OK, reason
    # the same reliability and durability as diagnostic_updater's publisher
    assert (DIAGNOSTICS_QOS.reliability, DIAGNOSTICS_QOS.durability) == (UPDATER.reliability, UPDATER.durability)


def test_diagnostics_reach_a_system_default_subscription_through_the_middleware():
    """What the aggregator does, live: a subscription with the system-default profile receives a report."""
    context = Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('diagnostics_qos_test', context=context)
        got = []
        node.create_subscription(DiagnosticArray, '/test_diagnostics_qos', got.append,
                                 QoSProfile(depth=1000, reliability=qos_profile_system_default.reliability,
                                            durability=qos_profile_system_default.durability))
        pub = node.create_publisher(DiagnosticArray, '/test_diagnostics_qos', DIAGNOSTICS_QOS)
        executor = CountingExecutor(context=context)
        executor.add_node(node)

        def spin() -> None:
            executor.spin_once(timeout_sec=0.05)

        # bounded by progress, not by a fixed 10 s (a match and one message: nothing to count before, so this is
        # testing.STALL_S in all)
        wait_until(lambda: pub.get_subscription_count() >= 1, spin, lambda: executor.messages_taken, 'no match')
        pub.publish(diagnostic_array(S, 'n', 'h', OK, 'x', {}))
        wait_until(lambda: bool(got), spin, lambda: executor.messages_taken, 'not received')
        assert got[0].status[0].hardware_id == 'h'
        executor.shutdown()
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_latched_qos_reaches_late_transient_local_and_volatile_subscribers():
    late = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                      liveliness=LivelinessPolicy.AUTOMATIC)
    assert qos_check_compatible(resolved(LATCHED_QOS), late)[0] == QoSCompatibility.OK
    assert qos_check_compatible(resolved(LATCHED_QOS), BEST_EFFORT_MONITOR)[0] == QoSCompatibility.OK
    assert LATCHED_QOS.durability == DurabilityPolicy.TRANSIENT_LOCAL and LATCHED_QOS.depth == 1


def test_counted_level_of_a_source_node():
    values = {'gaps': 2, 'trailing_bytes': 0, 'clipped_values': 5, 'read_errors': 0}
    assert counted_level(values, ('gaps', 'trailing_bytes', 'clipped_values')) == \
        (WARN, 'counted: gaps 2, clipped_values 5')
    assert counted_level({'gaps': 0}, ('gaps', 'not_counted_yet')) == (OK, 'publishing')
    assert counted_level(values, ('gaps',), 'the input failed') == (ERROR, 'the input failed')


def test_publish_status_never_raises_and_marks_the_last_report():
    class Pub:
        def __init__(self, fail):
            self.fail, self.sent = fail, []

        def publish(self, msg):
            if self.fail:
                raise RuntimeError('context shut down')
            self.sent.append(msg)

    class Node:
        def __init__(self):
            self.errors = []

        def get_logger(self):
            return self

        def error(self, text):
            self.errors.append(text)

    node, ok, broken = Node(), Pub(False), Pub(True)
    publish_status(node, ok, 0, 'if_source', 'rf_front_end', WARN, 'counted: gaps 2', {'gaps': 2}, final=True)
    status = ok.sent[0].status[0]
    assert (status.name, status.hardware_id, status.level, status.message) == \
        ('if_source', 'rf_front_end', WARN, 'end of input; counted: gaps 2')
    assert ok.sent[0].header.stamp.nanosec == 1  # never stamped 0
    publish_status(node, broken, 5, 'if_source', 'rf_front_end', OK, 'publishing', {}, final=False)
    assert node.errors == ['/diagnostics not published: RuntimeError: context shut down']
