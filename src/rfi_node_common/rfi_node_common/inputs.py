"""Input subscriptions of the nodes: any publisher accepted, a replay received reliably, every loss counted once,
no callback fatal.

:func:`subscribe_input` creates a node's input subscription with :data:`rfi_node_common.qos.INPUT_QOS`
(best available: reliable while every publisher on the topic is reliable, so a ``play`` or another node
loses nothing; best effort once a best-effort sensor driver is there, REP 2003, so it is still matched)
and rclpy's QoS overriding (``-p qos_overrides./rfi/if_samples.subscription.reliability:=reliable`` or
``best_effort`` fixes one input's reliability). Around the node's callback it

* counts every message that reaches the subscription (``<topic>.received``);
* counts the messages that never reached it, from gaps in the publishers' sequence numbers
  (``<topic>.lost``, :class:`rfi_node_common.input_checks.SequenceLossCounter`), and records the
  middleware's own lost-message event where it reports one (``<topic>.middleware_lost``), with one
  throttled warning. The two see the same losses (Fast DDS reports a sample lost when it sees the same
  gap in the writer's sequence numbers), so the node's total (:meth:`InputHealth.lost_total`, the
  ``lost`` of its diagnostics) takes per topic the larger of the two, never their sum;
* catches any exception the callback lets out (a malformed payload that rclpy cannot deserialise, a
  bug): it is counted (``<topic>.callback_errors``), logged as an error and the node keeps running.

A loss after the last received message shows no gap: a best-effort input cannot count it (``play``
says so in its summary, with how many messages it sent); a reliable one does not lose it.

:class:`InputHealth` holds these counters for all inputs of a node and the wall-clock (steady) time
of the last activity; :class:`StaleInputWatch` publishes a STALE diagnostics status when no input
has arrived for ``input_timeout_s`` of wall time (also when none ever arrived), so an operator sees
a silent node. The wall clock is used only there: no estimate depends on it.
"""

from __future__ import annotations

import copy
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

from rfi_node_common.input_checks import SequenceLossCounter
from rfi_node_common.qos import INPUT_QOS, best_available_reliability

STALE_REASON = 'no input'


class InputHealth:
    """Per-topic arrival, loss and callback-error counters of one node, and its last activity time.

    Args:
        clock: monotonic seconds (injected for tests), default :func:`time.monotonic`.
    """

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self.topics: list[str] = []
        self.counts: Counter[str] = Counter()
        self._loss: dict[str, SequenceLossCounter] = {}
        self.publishers: dict[str, int] = {}
        self.started_s = clock()
        self.last_activity_s: float | None = None
        self.last_received_ns = 0
        """When the middleware received the message being handled (rmw ``received_timestamp``, ns of the system
        clock; 0 when the middleware does not report it): :meth:`queued_s` (resource accounting only)."""

    def add_topic(self, topic: str) -> None:
        if topic not in self._loss:
            self.topics.append(topic)
            self._loss[topic] = SequenceLossCounter()
            self.publishers[topic] = 1
            for key in ('received', 'lost', 'middleware_lost', 'callback_errors'):
                self.counts[f'{topic}.{key}'] += 0

    def arrived(self, topic: str, sequence_number: int) -> int:
        """One message reached the subscription of ``topic``; returns the messages newly found lost."""
        self.counts[f'{topic}.received'] += 1
        self.touch()
        lost = self._loss[topic].observe(sequence_number, self.publishers[topic])
        if lost:
            self.counts[f'{topic}.lost'] += lost
        return lost

    def queued_s(self) -> float | None:
        """How long the message being handled waited between its reception by the middleware and now, s (its time in
        the subscription's queue: a node behind its input); None when the middleware does not report receptions."""
        if self.last_received_ns <= 0:
            return None
        return (time.time_ns() - self.last_received_ns) * 1e-9

    def matched(self, topic: str, publishers: int) -> None:
        """The middleware now matches ``publishers`` publishers with the subscription of ``topic``."""
        self.publishers[topic] = max(1, int(publishers))
        self._loss[topic].forget_beyond(self.publishers[topic])

    def middleware_lost(self, topic: str, count: int) -> None:
        self.counts[f'{topic}.middleware_lost'] += int(count)

    def callback_error(self, topic: str) -> None:
        self.counts[f'{topic}.callback_errors'] += 1

    def touch(self) -> None:
        """Mark activity now (on arrival and when a callback ends, so a long first call is not silence)."""
        self.last_activity_s = self._clock()

    def lost(self, topic: str) -> int:
        """Messages of ``topic`` lost before the node: the larger of the sequence-gap count and the middleware's
        count (they see the same losses; see the module docstring)."""
        return max(self.counts[f'{topic}.lost'], self.counts[f'{topic}.middleware_lost'])

    def lost_total(self) -> int:
        """Messages lost before the node, all inputs (:meth:`lost` summed over the topics)."""
        return sum(self.lost(t) for t in self.topics)

    def callback_errors_total(self) -> int:
        return sum(self.counts[f'{t}.callback_errors'] for t in self.topics)

    def silent_for_s(self) -> float:
        """Wall seconds since the last activity (since start if nothing ever arrived)."""
        last = self.started_s if self.last_activity_s is None else self.last_activity_s
        return self._clock() - last

    def values(self) -> dict[str, object]:
        """Diagnostics key/values: ``input.<topic>.<counter>``."""
        return {f'input.{k}': v for k, v in sorted(self.counts.items())}


class InputSubscription:
    """The input subscription of one topic, made by :func:`subscribe_input`; attributes not defined here are those
    of the current rclpy Subscription (``qos_profile``, ``topic_name``, ...).

    With the default best-available reliability (:data:`rfi_node_common.qos.INPUT_QOS`) the subscription starts
    with :func:`rfi_node_common.qos.best_available_reliability` of the publishers in the graph, and a reliable one
    is made again best effort when the middleware reports a publisher with incompatible QoS (a best-effort sensor
    driver that appeared later): ``switches`` counts these. With an overridden reliability nothing changes.
    """

    def __init__(self, node: Any, create: Callable[[Any, bool], Any], qos: Any) -> None:
        self._node = node
        self._create = create
        self.adaptive = False
        """Whether the reliability follows the publishers (not overridden by a parameter)."""
        self.switches = 0
        self.subscription = create(qos, True)

    def __getattr__(self, name: str) -> Any:
        if name == 'subscription':  # not yet made (__init__)
            raise AttributeError(name)
        return getattr(self.subscription, name)

    def take_pending(self, limit: int = 10_000) -> int:
        """Handle now the messages that have reached the subscription but wait for the executor; returns how many.

        Each goes through the subscription's callback (counted, guarded, as if the executor had taken it). A node
        calls this from another input's callback when what it computes there must not depend on the order in
        which the executor serves its subscriptions: a ``SingleThreadedExecutor`` takes one message per ready
        subscription per wait, in the order the subscriptions were created, so under load a message that came
        later on one topic can be handled before those that came earlier on another. The executor's own take of
        a subscription emptied here finds nothing and calls nothing. ``limit`` bounds one call (a publisher that
        floods the topic cannot keep the caller here for ever).
        """
        from rclpy.exceptions import InvalidHandle

        sub = self.subscription
        taken = 0
        while taken < limit:
            try:
                with sub.handle:
                    msg_info = sub.handle.take_message(sub.msg_type, sub.raw)
            except InvalidHandle:  # destroyed (shutdown, or a switch to best effort): nothing to take
                return taken
            if msg_info is None:
                return taken
            taken += 1
            if sub._callback_type.name == 'MessageOnly':  # as rclpy's executor calls it
                sub.callback(msg_info[0])
            else:
                sub.callback(*msg_info)
        return taken

    def to_best_effort(self) -> bool:
        """Make the subscription best effort (it was reliable and adaptive); returns whether it changed."""
        from rclpy.qos import ReliabilityPolicy

        if not self.adaptive or self.subscription.qos_profile.reliability != ReliabilityPolicy.RELIABLE:
            return False
        qos = copy.copy(self.subscription.qos_profile)
        qos.reliability = ReliabilityPolicy.BEST_EFFORT
        old = self.subscription
        self._node.destroy_subscription(old)  # first: two readers would take one writer's samples twice
        self.subscription = self._create(qos, False)
        self.subscription.callback = old.callback  # with whatever wraps it (a replay harness counts through it)
        self.switches += 1
        return True


def subscribe_input(node: Any, msg_type: Any, topic: str, callback: Callable[[Any], None], health: InputHealth,
                    *, raw: bool = False, warning_throttle_s: float = 5.0) -> InputSubscription:
    """Create the input subscription of ``node`` on ``topic`` (see the module docstring).

    Args:
        node: the rclpy node.
        msg_type: message class.
        topic: topic name; relative names resolve in the node's namespace, and the counters are keyed on
            the resolved name (``input./robot1/rfi/if_samples.received`` under ``__ns:=/robot1``).
        callback: the node's handler, called with the message (or its bytes with ``raw``).
        health: the node's :class:`InputHealth`; ``topic`` is added to it.
        raw: deliver the serialised bytes.
        warning_throttle_s: shortest interval between two warnings of one kind, s (wall time; logging only).

    Returns:
        the :class:`InputSubscription` (the rclpy Subscription's attributes, and its reliability switches).
    """
    from rclpy.event_handler import SubscriptionEventCallbacks
    from rclpy.qos import QoSPolicyKind, ReliabilityPolicy, qos_policy_name_from_kind
    from rclpy.qos_overriding_options import QosCallbackResult, QoSOverridingOptions

    topic = node.resolve_topic_name(topic)  # a relative name lands in the node's namespace (-r __ns:=...)
    health.add_topic(topic)
    logger = node.get_logger()
    holder: list[InputSubscription] = []

    def on_message(msg: Any, info: Any) -> None:
        health.last_received_ns = int(info.get('received_timestamp', 0) or 0) if info else 0
        lost = health.arrived(topic, info.get('publication_sequence_number', 0) if info else 0)
        if lost:
            logger.warn(f'{topic}: {lost} messages lost before this one (publisher sequence gap; '
                        f'{health.counts[f"{topic}.lost"]} in all)', throttle_duration_sec=warning_throttle_s)
        try:
            callback(msg)
        except Exception as err:  # noqa: BLE001 - one bad message must never end the node
            health.callback_error(topic)
            logger.error(f'{topic}: message dropped, its handler raised {type(err).__name__}: {err}',
                         throttle_duration_sec=warning_throttle_s)
        finally:
            health.touch()

    def on_lost(event: Any) -> None:
        health.middleware_lost(topic, event.total_count_change)
        logger.warn(f'{topic}: the middleware reports {event.total_count_change} messages lost',
                    throttle_duration_sec=warning_throttle_s)

    def on_matched(event: Any) -> None:
        health.matched(topic, event.current_count)

    def on_incompatible(event: Any) -> None:
        kind = getattr(event, 'last_policy_kind', None)
        reliability = kind is None or int(kind) == int(QoSPolicyKind.RELIABILITY)
        if reliability and holder and holder[0].to_best_effort():
            logger.info(f'{topic}: a best-effort publisher appeared: the input is now best effort '
                        '(losses are counted, not prevented)')
        else:
            logger.warn(f'{topic}: a publisher with incompatible QoS is not received '
                        f'(last policy: {qos_policy_name_from_kind(kind) if kind is not None else "?"})',
                        throttle_duration_sec=warning_throttle_s)

    from rclpy.exceptions import InvalidParameterValueException
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

    adaptive = [False]

    def resolve(qos: Any) -> Any:
        """Called by rclpy with the profile after the parameter overrides: best available -> the graph's."""
        if qos.reliability == ReliabilityPolicy.BEST_AVAILABLE:
            adaptive[0] = True
            qos.reliability = best_available_reliability(
                i.qos_profile.reliability for i in node.get_publishers_info_by_topic(topic))
        return QosCallbackResult(successful=True)

    overriding = [QoSOverridingOptions.with_default_policies(callback=resolve)]

    def create(qos: Any, first: bool) -> Any:
        events = (SubscriptionEventCallbacks(message_lost=on_lost, matched=on_matched,
                                             incompatible_qos=on_incompatible),
                  SubscriptionEventCallbacks(matched=on_matched, incompatible_qos=on_incompatible),
                  SubscriptionEventCallbacks(incompatible_qos=on_incompatible), None)
        for i, event_callbacks in enumerate(events):
            try:
                return node.create_subscription(msg_type, topic, on_message, qos, raw=raw,
                                                qos_overriding_options=overriding[0] if first else None,
                                                event_callbacks=event_callbacks)
            except InvalidParameterValueException:
                raise
            except (_rclpy.UnsupportedEventTypeError, NotImplementedError):  # a middleware without these events
                if i == len(events) - 1:
                    raise
                first = False  # the overrides are declared and already applied to qos
        raise AssertionError('unreachable')

    qos = copy.copy(INPUT_QOS)  # rclpy writes the overrides into the profile it is given
    holder.append(InputSubscription(node, create, qos))
    holder[0].adaptive = adaptive[0]  # known once rclpy has applied the overrides (resolve)
    return holder[0]


class StaleInputWatch:
    """Publishes a STALE diagnostics status while a node receives nothing (wall clock).

    Every ``timeout_s / 2`` of steady time it checks :meth:`InputHealth.silent_for_s`; while that is
    at least ``timeout_s`` it publishes ``make_status(silent_s)`` (the node builds the message, with
    level STALE, stamped with the node clock's now). Publishing resumes on the stamp timer once input
    arrives. ``timeout_s`` 0 disables the watch.

    Args:
        node: the rclpy node.
        health: the node's input health.
        timeout_s: silence that makes the node stale, s (wall time).
        publish_stale: called with the silent time, s, when stale.
    """

    def __init__(self, node: Any, health: InputHealth, timeout_s: float,
                 publish_stale: Callable[[float], None]) -> None:
        self.stale_reports = 0
        self._health = health
        self._timeout_s = float(timeout_s)
        self._publish_stale = publish_stale
        self.timer = None
        if self._timeout_s > 0:
            from rclpy.clock import Clock, ClockType
            self.timer = node.create_timer(self._timeout_s / 2.0, self.check,
                                           clock=Clock(clock_type=ClockType.STEADY_TIME))

    def check(self) -> bool:
        """Publish a stale report if the node has been silent for ``timeout_s``; return whether it did."""
        silent_s = self._health.silent_for_s()
        if silent_s < self._timeout_s:
            return False
        self.stale_reports += 1
        self._publish_stale(silent_s)
        return True
