"""The replay harness cancels the nodes' wall-clock timers, so a dds replay equals a direct one even
when one node's first call (a cold numba compile) leaves the others silent for seconds."""

from __future__ import annotations

import rclpy
from rclpy.clock import ClockType
from ros_fixtures import make_context

from imm_carrier.imm_carrier_node import ImmCarrierNode
from rfi_experiments.replay import ReplayHarness
from rfi_monitor.rfi_monitor_node import RfiMonitorNode
from uwb_gnss_fusion.fusion_node import FusionNode


def test_steady_clock_timers_are_cancelled_and_stamp_timers_kept():
    context = make_context()
    try:
        nodes = [RfiMonitorNode(context=context), FusionNode(context=context), ImmCarrierNode(context=context)]
        steady = [t for n in nodes for t in n.timers if t.clock.clock_type == ClockType.STEADY_TIME]
        assert len(steady) == 4  # three stale watches and the fusion node's idle flush
        harness = ReplayHarness(nodes, context=context, transport='dds')
        assert harness.wall_clock_timers_cancelled == 4
        assert all(t.is_canceled() for t in steady)
        assert nodes[1].idle_flush_timer.is_canceled() and nodes[0].stale_watch.timer.is_canceled()
        harness.destroy()
        for n in nodes:
            n.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
