"""ROS node of the carrier tracker: /gnss/correlators -> /carrier/estimates, /diagnostics.

Skeleton of the foundation issue: it validates and counts correlator arrays and reports them on
/diagnostics. The IMM and PLL trackers (Zhao et al.) plug in with their own issue; until then no
estimate is published, because nothing unvalidated is published as valid.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node

from rfi_msgs.msg import CarrierPhaseArray, CorrelatorArray
from rfi_node_common.diagnostics import OK, WARN, StampTimer, diagnostic_array
from rfi_node_common.main import run_node
from rfi_node_common.params import declare, parameter
from rfi_node_common.qos import DATA_QOS
from rfi_node_common.stamps import stamp_to_ns

TOPICS = """topics:
  subscribes /gnss/correlators (rfi_msgs/CorrelatorArray)
  publishes  /carrier/estimates (rfi_msgs/CarrierPhaseArray), /diagnostics (diagnostic_msgs/DiagnosticArray)"""


@dataclass(frozen=True)
class CarrierNodeParams:
    method: str = parameter('imm', 'Tracker to run: imm, pll or both (side by side on the same input).',
                            choices=('imm', 'pll', 'both'))
    diagnostics_period_s: float = parameter(
        1.0, 'Period of /diagnostics in message (stamp) time, s.', minimum=0.01, maximum=3600.0)


class ImmCarrierNode(Node):
    """Thin node around the carrier trackers (see module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__('imm_carrier', **kwargs)
        self.params = declare(self, CarrierNodeParams)
        self.counts: Counter[str] = Counter()
        self._diag_timer = StampTimer(self.params.diagnostics_period_s)
        self.estimates_pub = self.create_publisher(CarrierPhaseArray, '/carrier/estimates', DATA_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', DATA_QOS)
        self.create_subscription(CorrelatorArray, '/gnss/correlators', self.on_correlators, DATA_QOS)

    def on_correlators(self, msg: CorrelatorArray) -> None:
        stamp_ns = stamp_to_ns(msg.header.stamp)
        self.counts['arrays_received'] += 1
        for c in msg.correlators:
            if not (math.isfinite(c.in_phase) and math.isfinite(c.quadrature)):
                self.counts['rejected_non_finite_iq'] += 1
            elif not c.integration_time_s > 0.0:
                self.counts['rejected_bad_integration_time'] += 1
            else:
                self.counts['correlators_valid'] += 1
        if self._diag_timer.due(stamp_ns):
            rejected = sum(v for k, v in self.counts.items() if k.startswith('rejected_'))
            self.diag_pub.publish(diagnostic_array(
                stamp_ns, 'imm_carrier', self.get_name(), WARN if rejected else OK,
                'trackers not installed: correlators validated and counted only', dict(sorted(self.counts.items()))))


def main(argv=None) -> int:
    return run_node(ImmCarrierNode, executable='imm_carrier_node', params_cls=CarrierNodeParams, topics=TOPICS,
                    summary='IMM carrier-phase tracking through interference, beside a Costas PLL.', argv=argv)
