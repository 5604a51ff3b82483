"""Named QoS profiles of the suite (REP 2003 roles).

Replay and tests must count every message, so the data path is reliable with a deep queue; a
player keeps all samples until they are acknowledged so that a slow subscriber is not skipped.
"""

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

DATA_QOS_DEPTH = 1000
"""Queue depth of the data path, messages (enough for every burst the tests and replays send)."""

DATA_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=DATA_QOS_DEPTH,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
"""Inputs and outputs of the nodes: reliable, volatile, depth 1000."""

PLAYER_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_ALL,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
"""Publishers of ``play``: reliable and keep-all, so nothing is dropped when a reader lags."""

RECORDER_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_ALL,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
"""Subscriptions of ``record``: reliable and keep-all."""

STATUS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
"""Latched status: the last value is delivered to late joiners."""
