"""ROS node of the RFI monitor: /rfi/if_samples -> /rfi/jammer_state, /diagnostics.

Skeleton of the foundation issue: it validates and counts IF blocks (format, gaps, stamp order)
and reports them on /diagnostics. The tracking core (Kang et al.) plugs in with its own issue;
until then no JammerState is published, because nothing unvalidated is published as valid.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node

from rfi_msgs.msg import IfSamples, JammerState
from rfi_node_common.diagnostics import OK, WARN, StampTimer, diagnostic_array
from rfi_node_common.main import run_node
from rfi_node_common.params import declare, parameter
from rfi_node_common.qos import DATA_QOS
from rfi_node_common.stamps import stamp_to_ns

TOPICS = """topics:
  subscribes /rfi/if_samples (rfi_msgs/IfSamples)
  publishes  /rfi/jammer_state (rfi_msgs/JammerState), /diagnostics (diagnostic_msgs/DiagnosticArray)"""


@dataclass(frozen=True)
class MonitorNodeParams:
    diagnostics_period_s: float = parameter(
        1.0, 'Period of /diagnostics in message (stamp) time, s.', minimum=0.01, maximum=3600.0)


def check_block(msg: IfSamples) -> str | None:
    """Return why an IF block is unusable, or None if it is well formed."""
    width = {IfSamples.INT8: 1, IfSamples.INT16: 2}.get(msg.sample_format)
    if width is None:
        return 'unknown_sample_format'
    if not msg.sample_rate_hz > 0.0:
        return 'bad_sample_rate'
    if len(msg.samples) == 0:
        return 'empty_block'
    if len(msg.samples) % width:
        return 'truncated_sample'
    values = len(msg.samples) // width
    if msg.is_complex and values % 2:
        return 'odd_length_iq'
    return None


class RfiMonitorNode(Node):
    """Thin node around the RFI monitor core (see module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__('rfi_monitor', **kwargs)
        self.params = declare(self, MonitorNodeParams)
        self.counts: Counter[str] = Counter()
        self._next_index: int | None = None
        self._last_stamp_ns: int | None = None
        self._diag_timer = StampTimer(self.params.diagnostics_period_s)
        self.state_pub = self.create_publisher(JammerState, '/rfi/jammer_state', DATA_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', DATA_QOS)
        self.create_subscription(IfSamples, '/rfi/if_samples', self.on_block, DATA_QOS)

    def on_block(self, msg: IfSamples) -> None:
        stamp_ns = stamp_to_ns(msg.header.stamp)
        self.counts['blocks_received'] += 1
        reason = check_block(msg)
        if reason is None and self._last_stamp_ns is not None and stamp_ns < self._last_stamp_ns:
            reason = 'stamp_backwards'
        if reason is not None:
            self.counts[f'rejected_{reason}'] += 1
            self.get_logger().warn(f'IF block rejected: {reason}', throttle_duration_sec=5.0)
        else:
            if self._next_index is not None and msg.first_sample_index != self._next_index:
                self.counts['gaps'] += 1
            width = 1 if msg.sample_format == IfSamples.INT8 else 2
            n = len(msg.samples) // width // (2 if msg.is_complex else 1)
            self._next_index = msg.first_sample_index + n
            self._last_stamp_ns = stamp_ns
            self.counts['blocks_processed'] += 1
        if self._diag_timer.due(stamp_ns):
            rejected = sum(v for k, v in self.counts.items() if k.startswith('rejected_'))
            level = WARN if rejected or self.counts['gaps'] else OK
            self.diag_pub.publish(diagnostic_array(
                stamp_ns, 'rfi_monitor', self.get_name(), level,
                'tracking core not installed: blocks validated and counted only', dict(sorted(self.counts.items()))))


def main(argv=None) -> int:
    return run_node(RfiMonitorNode, executable='rfi_monitor_node', params_cls=MonitorNodeParams, topics=TOPICS,
                    summary='Detect, classify and track GNSS jammers from IF sample blocks.', argv=argv)
