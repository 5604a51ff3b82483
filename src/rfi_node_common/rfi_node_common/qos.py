"""Named QoS profiles of the suite (REP 2003 roles).

Inputs of the nodes take their publishers' reliability (:data:`INPUT_QOS`, Jazzy's best-available
reliability, resolved by :func:`best_available_reliability` and kept up to date by
:func:`rfi_node_common.inputs.subscribe_input`): reliable while every publisher on the topic is
reliable (the suite's own nodes, ``play``, or no publisher yet), so a replay is received reliably
and loses nothing, and best effort as soon as a best-effort publisher (a sensor driver with
``SensorDataQoS``, REP 2003) is there, so a live driver is still matched. The ``qos_overrides.<topic>.
subscription.reliability`` parameter (``reliable`` or ``best_effort``) fixes an input's reliability
instead. The nodes count what is lost either way (:mod:`rfi_node_common.inputs`). Outputs are
reliable (:data:`DATA_QOS`), which best-effort and reliable subscribers both accept; a player keeps
all samples until they are acknowledged so that a slow reliable subscriber is not skipped.
"""

from collections.abc import Iterable

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
    reliability=ReliabilityPolicy.BEST_AVAILABLE,
    durability=DurabilityPolicy.VOLATILE,
)
"""Input subscriptions of the nodes: the publishers' reliability (best available: see the module docstring and
:func:`best_available_reliability`), volatile, depth 1000; overridable per topic by the
``qos_overrides.<topic>.subscription.*`` parameters."""


def best_available_reliability(publishers: Iterable[ReliabilityPolicy]) -> ReliabilityPolicy:
    """The reliability a best-available subscription takes with these publishers on its topic.

    Reliable if every publisher is reliable (also with none: a replay started later is then received
    reliably), best effort as soon as one is not (a reliable subscription would refuse it). This is the
    rule of rmw_dds_common's ``qos_profile_get_best_available_for_subscription`` (Jazzy), which the
    middleware applies only once, when the subscription is created; the nodes apply it again when a
    best-effort publisher appears later (:func:`rfi_node_common.inputs.subscribe_input`).

    Args:
        publishers: the reliability of each publisher on the topic (from the ROS graph).
    """
    if all(p == ReliabilityPolicy.RELIABLE for p in publishers):
        return ReliabilityPolicy.RELIABLE
    return ReliabilityPolicy.BEST_EFFORT


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

VIEW_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=5,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
"""Topics made to be drawn (the monitor's waterfall, the fusion's path and markers; issue 30): reliable, volatile,
keep last 5. Reliable so that a bag recorder gets every one; rviz2 and Foxglove subscribe best effort or reliable,
both accepted. A shallow queue: a viewer that falls behind gets the newest picture, not a backlog (each message
replaces the last: a waterfall, a whole path, a whole marker set)."""
