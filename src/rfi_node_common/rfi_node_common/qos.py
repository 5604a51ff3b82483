"""Named QoS profiles of the suite (REP 2003 roles).

Inputs of the nodes are best effort (:data:`INPUT_QOS`), which accepts both best-effort publishers
(sensor drivers, ``SensorDataQoS``) and reliable ones (the suite's own nodes and ``play``); a
reliable subscription would refuse the former. Every input subscription is created with rclpy's
QoS overriding (``qos_overrides.<topic>.subscription.reliability`` and ``.depth`` parameters), so a
replay that must lose nothing (``run --transport processes``) makes them reliable end to end, and
the nodes count what is lost either way (:mod:`rfi_node_common.inputs`). Outputs are reliable
(:data:`DATA_QOS`), which best-effort and reliable subscribers both accept; a player keeps all
samples until they are acknowledged so that a slow reliable subscriber is not skipped.
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
"""Outputs of the nodes (and test publishers that must count every message): reliable, volatile, depth 1000."""

INPUT_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=DATA_QOS_DEPTH,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)
"""Input subscriptions of the nodes: best effort (accepts best-effort and reliable publishers, REP 2003),
volatile, depth 1000; overridable per topic by the ``qos_overrides.<topic>.subscription.*`` parameters."""

DIAGNOSTICS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
"""/diagnostics publishers: reliable, volatile (what diagnostic_updater and the aggregator use), depth 100."""

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
