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
"""/diagnostics publishers: reliable, volatile, keep last 100.

What the ROS 2 diagnostics stack uses (ros/diagnostics, Jazzy): ``diagnostic_updater::Updater`` publishes
``/diagnostics`` with ``rclcpp::create_publisher(..., "/diagnostics", 1)``, i.e. the default profile with
depth 1 (reliable, volatile, keep last); ``diagnostic_aggregator`` subscribes with
``rclcpp::SystemDefaultsQoS().keep_last(history_depth)`` (reliable, volatile with the shipped
middlewares). Reliability and durability are the ones that decide compatibility: a reliable, volatile
publisher matches both that subscription and a best-effort one (``test_qos.py`` checks this with rclpy's
own compatibility check). The depth is 100 rather than the updater's 1 because a fast replay publishes
one report per second of stamp time, many per wall-clock second."""

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

LATCHED_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
"""A value set once that a late subscriber must still get (REP 2003 latched status; the fusion node's
datum): reliable, transient local, depth 1. A subscriber asks for TRANSIENT_LOCAL to receive it on joining."""
