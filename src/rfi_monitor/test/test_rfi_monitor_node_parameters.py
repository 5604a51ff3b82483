"""rfi_monitor_node's hooks for issue 11: hardware_id from a parameter, node-level parameters settable while
running (as `ros2 param set` does, through the SetParameters service), the core's parameters read-only."""

from __future__ import annotations

import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from rfi_monitor.rfi_monitor_node import MonitorNodeParams, RfiMonitorNode
from rfi_node_common.params import runtime_parameter_names, set_parameters_remotely


@pytest.fixture
def setup():
    context = Context()
    rclpy.init(context=context)
    node = RfiMonitorNode(context=context, parameter_overrides=[Parameter('input_timeout_s', value=0.0),
                                                                Parameter('hardware_id', value='usrp-b210#31')])
    client = Node('monitor_param_client', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(client)
    yield node, client, executor
    executor.shutdown()
    node.destroy_node()
    client.destroy_node()
    rclpy.shutdown(context=context)


def test_settable_parameters_are_the_node_level_ones():
    assert set(runtime_parameter_names(MonitorNodeParams)) == {
        'warning_throttle_s', 'hardware_id', 'diagnostics_window_s', 'warn_rejected_fraction', 'warn_lost_fraction'}


def test_hardware_id_is_the_parameter_and_can_be_set_while_running(setup):
    node, client, executor = setup
    status = node.diagnostics(1_000_000_000).status[0]
    assert status.hardware_id == 'usrp-b210#31' and status.name == 'rfi_monitor'
    results = set_parameters_remotely(client, executor, '/rfi_monitor',
                                      {'hardware_id': 'usrp-b210#32', 'warn_rejected_fraction': 0.3})
    assert all(r.successful for r in results)
    assert node.runtime.apply_pending(node._apply_parameters)   # what the next block does first
    assert node.diagnostics(2_000_000_000).status[0].hardware_id == 'usrp-b210#32'
    assert node.params.warn_rejected_fraction == 0.3
    (result,) = set_parameters_remotely(client, executor, '/rfi_monitor', {'noise_bandwidth_hz': 4.0e6})
    assert not result.successful and 'read-only' in result.reason
    (result,) = set_parameters_remotely(client, executor, '/rfi_monitor', {'diagnostics_window_s': -1.0})
    assert not result.successful and 'out of range' in result.reason
