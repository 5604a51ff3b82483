"""ROS node of the GNSS/UWB fusion: /gnss/measurements, /uwb/ranges, /rfi/jammer_state -> odometry.

Skeleton of the foundation issue: it validates and counts its inputs and reports them on
/diagnostics. The cubature Kalman filter (Cao et al.) plugs in with its own issue; until then no
position is published, because nothing unvalidated is published as valid.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import NavSatFix

from rfi_msgs.msg import FusionStatus, GnssMeasurementArray, JammerState, UwbRange
from rfi_node_common.diagnostics import OK, StampTimer, diagnostic_array
from rfi_node_common.main import run_node
from rfi_node_common.params import declare, parameter
from rfi_node_common.qos import DATA_QOS
from rfi_node_common.stamps import stamp_to_ns

TOPICS = """topics:
  subscribes /gnss/measurements (rfi_msgs/GnssMeasurementArray), /uwb/ranges (rfi_msgs/UwbRange),
             /rfi/jammer_state (rfi_msgs/JammerState)
  publishes  /fusion/odometry (nav_msgs/Odometry), /fusion/fix (sensor_msgs/NavSatFix),
             /fusion/status (rfi_msgs/FusionStatus), /diagnostics (diagnostic_msgs/DiagnosticArray)"""


@dataclass(frozen=True)
class FusionNodeParams:
    diagnostics_period_s: float = parameter(
        1.0, 'Period of /diagnostics in message (stamp) time, s.', minimum=0.01, maximum=3600.0)


class FusionNode(Node):
    """Thin node around the fusion filter core (see module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__('uwb_gnss_fusion', **kwargs)
        self.params = declare(self, FusionNodeParams)
        self.counts: Counter[str] = Counter()
        self._diag_timer = StampTimer(self.params.diagnostics_period_s)
        self.odom_pub = self.create_publisher(Odometry, '/fusion/odometry', DATA_QOS)
        self.fix_pub = self.create_publisher(NavSatFix, '/fusion/fix', DATA_QOS)
        self.status_pub = self.create_publisher(FusionStatus, '/fusion/status', DATA_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', DATA_QOS)
        self.create_subscription(GnssMeasurementArray, '/gnss/measurements', self.on_gnss, DATA_QOS)
        self.create_subscription(UwbRange, '/uwb/ranges', self.on_uwb, DATA_QOS)
        self.create_subscription(JammerState, '/rfi/jammer_state', self.on_jammer, DATA_QOS)

    def _received(self, kind: str, stamp_ns: int) -> None:
        self.counts[f'{kind}_received'] += 1
        if self._diag_timer.due(stamp_ns):
            self.diag_pub.publish(diagnostic_array(
                stamp_ns, 'uwb_gnss_fusion', self.get_name(), OK,
                'fusion filter not installed: inputs counted only', dict(sorted(self.counts.items()))))

    def on_gnss(self, msg: GnssMeasurementArray) -> None:
        self._received('gnss_epochs', stamp_to_ns(msg.header.stamp))

    def on_uwb(self, msg: UwbRange) -> None:
        self._received('uwb_ranges', stamp_to_ns(msg.header.stamp))

    def on_jammer(self, msg: JammerState) -> None:
        self._received('jammer_states', stamp_to_ns(msg.header.stamp))


def main(argv=None) -> int:
    return run_node(FusionNode, executable='fusion_node', params_cls=FusionNodeParams, topics=TOPICS,
                    summary='Tightly-coupled GNSS/UWB cubature Kalman filter that survives jamming.', argv=argv)
