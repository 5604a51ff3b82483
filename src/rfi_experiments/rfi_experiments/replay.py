"""In-process bag replay through real rclpy nodes, one executor, deterministic at any speed.

:class:`ReplayHarness` takes node instances (already constructed in one rclpy ``Context``),
publishes a bag's messages on their topics and collects what the nodes publish. After each input
message it spins the executor until the graph is *quiescent*: every subscription of every node
has taken every message published on its topic so far (inputs and the nodes' own outputs, so a
chain monitor -> fusion settles too). It knows this because it counts: each subscription's
callback and each publisher's ``publish`` of the given nodes is wrapped with a counter. The order
in which callbacks see messages is therefore the bag's order whatever the replay speed, and the
outputs of a replay at 1x and at maximum rate are identical. Nothing is dropped silently: the
harness never lets more than one input message be in flight, and a message that a subscription
never takes stops the replay (:class:`ReplayStalled`) instead of going missing. (The nodes'
inputs are best effort by default; ``run`` makes them reliable with the
``qos_overrides.<topic>.subscription.reliability`` parameter; the tests' replays over DDS in one
process have lost nothing either way.)

Two transports:

- ``dds`` (default): real publishers and subscriptions over the middleware, one
  SingleThreadedExecutor, settled by counting as above. This is how the nodes run on a robot.
- ``direct``: the same node objects and callbacks, but messages are handed from publisher to
  subscriptions in this process without the middleware, first in first out: a published
  message object goes to typed subscriptions as it is (one object shared by all of them, so a
  callback must not modify its message, which ROS callbacks should not do anyway), and is
  serialised only for raw subscriptions; bag bytes are deserialised once per message. It gives
  the same per-node message order and is 10-100x faster, because a middleware round trip costs
  about a millisecond here; use it for long replays and benchmarks. Nothing goes out on the
  network in this mode.

Timers are not fired by the harness: nodes in this suite compute (and report diagnostics) from
message stamps, never from the wall clock.

End of input: after the last message, :meth:`ReplayHarness.run` tells every node that has it that
the input has ended (:func:`end_input`: ``node.end_of_input()``, or ``node.flush()`` for a node
that only has that), so a node that holds messages back (the fusion node's 0.1 s re-ordering
buffer) processes them, and settles the graph again so that what they produce is collected. A
replay of N GNSS and UWB messages therefore gives N fusion outputs, not those of all but the last
0.1 s.
"""

from __future__ import annotations

import itertools
import os
import time
from collections import defaultdict, deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.serialization import deserialize_message

from rfi_experiments.bag_io import BagMessage, BagReader, deserialize, message_class, msgtype_of, serialize
from rfi_node_common.qos import DATA_QOS, VIEW_QOS

IGNORED_TOPICS = frozenset({'/rosout', '/parameter_events'})
"""Infrastructure topics the harness neither waits for nor collects."""


def collected(pub: Any) -> bool:
    """Whether the harness collects (and, over DDS, waits for) a node's publisher: not the infrastructure topics,
    and not the topics made to be drawn (published with ``VIEW_QOS`` and only while a viewer subscribes, issue 30):
    a replay records what the nodes estimate, and its own subscription would make them draw; a viewer connected to
    the replay still gets them."""
    return pub.topic_name not in IGNORED_TOPICS and pub.qos_profile != VIEW_QOS

TRANSPORTS = ('dds', 'direct')
"""Ways the harness moves messages between publishers and subscriptions (module docstring)."""


END_OF_INPUT_METHODS = ('end_of_input', 'flush')
"""Methods a node may offer to be told that its input has ended, in order of preference."""


def end_input(node: Any) -> str | None:
    """Tell ``node`` that its input has ended: call its ``end_of_input()``, or ``flush()`` if it has
    only that; return the name of the method called (None: the node has neither)."""
    for name in END_OF_INPUT_METHODS:
        method = getattr(node, name, None)
        if callable(method):
            method()
            return name
    return None


class ReplayStalled(RuntimeError):
    """The graph did not settle after an input message (a node lost or never took a message)."""


@dataclass
class ReplayResult:
    """What a replay produced.

    Attributes:
        outputs: topic -> list of (receive index, message) of every message the nodes published;
            the message is CDR bytes (dds transport) or the published object (direct transport,
            or bytes where the node published bytes); :meth:`messages` gives objects either way.
        output_types: topic -> message type name.
        inputs: topic -> number of bag messages published.
        ended: node name -> the end-of-input method called on it after the last input
            (``end_of_input`` or ``flush``; nodes with neither are not listed).
        wall_time_s: wall-clock duration of the replay, s (end of input included).
        bag_duration_s: span of the replayed messages' log times, s.
    """

    outputs: dict[str, list[tuple[int, Any]]] = field(default_factory=dict)
    output_types: dict[str, str] = field(default_factory=dict)
    inputs: dict[str, int] = field(default_factory=dict)
    ended: dict[str, str] = field(default_factory=dict)
    wall_time_s: float = 0.0
    bag_duration_s: float = 0.0

    def messages(self, topic: str) -> list[Any]:
        """The messages published on ``topic``, deserialised, in order."""
        return [deserialize(m, self.output_types[topic]) if isinstance(m, bytes) else m
                for _, m in self.outputs.get(topic, [])]

    @property
    def real_time_factor(self) -> float:
        """Bag time replayed per wall-clock second (inf for an instantaneous replay)."""
        return self.bag_duration_s / self.wall_time_s if self.wall_time_s > 0 else float('inf')


class ReplayHarness:
    """Feed bag messages through nodes in one SingleThreadedExecutor and collect their outputs.

    Args:
        nodes: the nodes under test, created in ``context``.
        context: the rclpy context of the nodes (one per test; the caller owns init/shutdown).
        collect: topics whose messages to collect (default: every topic the nodes publish on,
            except /rosout and /parameter_events).
        transport: 'dds' (middleware, executor) or 'direct' (in-process hand-over); see module doc.
        settle_timeout_s: longest wall time to wait for the graph to settle after one input, s.

    The nodes' steady-clock timers (stale-input reports, idle flush) are cancelled: a replay is driven
    by the stamps only (:meth:`_cancel_wall_clock_timers`).
    """

    def __init__(self, nodes: Sequence[Node], *, context: Context, collect: Iterable[str] | None = None,
                 transport: str = 'dds', settle_timeout_s: float = 10.0) -> None:
        if transport not in TRANSPORTS:
            raise ValueError(f'transport must be one of {", ".join(TRANSPORTS)}, got {transport!r}')
        self._direct = transport == 'direct'
        # topic -> (what the receiver takes: 'bytes', 'object' or 'as published', callback); the
        # callback of 'bytes' and 'object' also takes the publisher's sequence number
        self._routes: dict[str, list[tuple[str, Callable[..., None]]]] = defaultdict(list)
        self._queue: deque[tuple[str, Any, int]] = deque()  # (topic, message, publisher's sequence number)
        self._bag_sequence: dict[str, itertools.count] = {}  # the harness's own publisher per topic
        self._types: dict[str, type] = {}
        self._context = context
        self._nodes = list(nodes)
        self._settle_timeout_s = settle_timeout_s
        self._node = Node('rfi_replay_harness', context=context)
        self._executor = SingleThreadedExecutor(context=context)
        for node in self._nodes + [self._node]:
            self._executor.add_node(node)
        self.wall_clock_timers_cancelled = self._cancel_wall_clock_timers()
        self._published: dict[str, int] = defaultdict(int)
        self._taken: dict[int, int] = defaultdict(int)
        self._subscriptions: list[tuple[int, str, str]] = []  # (key, topic, node name)
        self._keys = itertools.count()
        if self._direct:
            self._wire_direct()
        else:
            self._instrument()
        self._publishers: dict[str, Any] = {}
        self._outputs: dict[str, list[tuple[int, Any]]] = defaultdict(list)
        self._output_types: dict[str, str] = {}
        self._received = 0
        topics = collect if collect is not None else self._node_output_topics()
        for topic, msgtype in topics.items() if isinstance(topics, dict) else self._typed(topics):
            self._collect(topic, msgtype)
        if not self._direct:
            for node in self._nodes:
                for pub in node.publishers:
                    if collected(pub):
                        self._wait_matched(pub, pub.topic_name)

    # -- direct transport --------------------------------------------------------------------
    def _cancel_wall_clock_timers(self) -> int:
        """Cancel the nodes' steady-clock timers (stale-input reports, the fusion node's idle flush).

        They measure the machine that replays, not the data: a long first call of one node (a cold numba
        compile) would make another node look silent, and the dds transport, which spins the executor,
        would then publish a STALE report or flush a re-ordering buffer early where the direct transport,
        which never spins timers, does not. Stamp-driven behaviour is untouched. Returns the count.
        """
        from rclpy.clock import ClockType

        cancelled = 0
        for node in self._nodes:
            for timer in list(node.timers):
                if timer.clock.clock_type == ClockType.STEADY_TIME and not timer.is_canceled():
                    timer.cancel()
                    cancelled += 1
        return cancelled

    def _wire_direct(self) -> None:
        for node in self._nodes:
            for sub in node.subscriptions:
                if sub.topic_name not in IGNORED_TOPICS:
                    self._types[sub.topic_name] = sub.msg_type
                    self._routes[sub.topic_name].append(('bytes' if sub.raw else 'object', self._direct_delivery(sub)))
            for pub in node.publishers:
                if pub.topic_name not in IGNORED_TOPICS:
                    self._types[pub.topic_name] = pub.msg_type
                    pub.publish = self._direct_publish(pub.topic_name)

    @staticmethod
    def _direct_delivery(sub: Any) -> Callable[[Any, int], None]:
        """The subscription's callback, given a MessageInfo as the middleware fills it: the
        publisher's sequence number (1, 2, ... per publisher), which the nodes count losses from."""
        callback, with_info = sub.callback, sub._callback_type.name != 'MessageOnly'

        def deliver(msg: Any, sequence_number: int) -> None:
            if with_info:
                callback(msg, {'source_timestamp': 0, 'received_timestamp': 0,
                               'publication_sequence_number': sequence_number, 'reception_sequence_number': 0})
            else:
                callback(msg)
        return deliver

    def _direct_publish(self, topic: str) -> Callable[[Any], None]:
        queue = self._queue
        sequence = itertools.count(1)

        def publish(msg: Any) -> None:
            queue.append((topic, msg, next(sequence)))
        return publish

    def _drain(self) -> None:
        """Hand every queued message to the subscriptions of its topic, first in first out."""
        while self._queue:
            topic, payload, sequence_number = self._queue.popleft()
            as_bytes = payload if isinstance(payload, bytes) else None
            as_object = None if isinstance(payload, bytes) else payload
            for takes, deliver in self._routes.get(topic, ()):
                if takes == 'bytes':
                    if as_bytes is None:
                        as_bytes = serialize(as_object)
                    deliver(as_bytes, sequence_number)
                elif takes == 'object':
                    if as_object is None:
                        as_object = deserialize_message(as_bytes, self._types[topic])
                    deliver(as_object, sequence_number)
                else:
                    deliver(payload)

    # -- instrumentation ---------------------------------------------------------------------
    def _instrument(self) -> None:
        for node in self._nodes:
            for sub in node.subscriptions:
                topic = sub.topic_name
                if topic in IGNORED_TOPICS:
                    continue
                key = next(self._keys)
                self._subscriptions.append((key, topic, node.get_name()))
                sub.callback = self._counting_callback(sub.callback, sub._callback_type, key)
            for pub in node.publishers:
                topic = pub.topic_name
                if topic not in IGNORED_TOPICS:
                    pub.publish = self._counting_publish(pub.publish, topic)

    def _counting_callback(self, callback: Callable[..., Any], callback_type: Any, key: int) -> Callable[..., Any]:
        taken = self._taken
        if callback_type.name == 'MessageOnly':
            def on_message(msg: Any) -> Any:
                taken[key] += 1
                return callback(msg)
            return on_message

        def on_message_with_info(msg: Any, info: Any) -> Any:
            taken[key] += 1
            return callback(msg, info)
        return on_message_with_info

    def _counting_publish(self, publish: Callable[[Any], None], topic: str) -> Callable[[Any], None]:
        published = self._published

        def counted(msg: Any) -> None:
            published[topic] += 1
            publish(msg)
        return counted

    def _node_output_topics(self) -> dict[str, str]:
        topics = {}
        for node in self._nodes:
            for pub in node.publishers:
                if collected(pub):
                    topics[pub.topic_name] = msgtype_of(pub.msg_type)
        return topics

    def _typed(self, topics: Iterable[str]) -> list[tuple[str, str]]:
        known = self._node_output_topics()
        missing = [t for t in topics if t not in known]
        if missing:
            raise ValueError(f'no node publishes {", ".join(missing)}: cannot collect it')
        return [(t, known[t]) for t in topics]

    def _collect(self, topic: str, msgtype: str) -> None:
        key = next(self._keys)
        self._subscriptions.append((key, topic, self._node.get_name()))
        outputs = self._outputs[topic]
        self._output_types[topic] = msgtype
        taken = self._taken

        def on_message(msg: Any) -> None:
            taken[key] += 1
            self._received += 1
            outputs.append((self._received, msg))

        if self._direct:
            self._types.setdefault(topic, message_class(msgtype))
            self._routes[topic].append(('as published', on_message))  # called with the message only
            return
        self._node.create_subscription(message_class(msgtype), topic, on_message, DATA_QOS, raw=True)

    # -- driving -----------------------------------------------------------------------------
    def _pending(self) -> list[str]:
        return [f'{name} on {topic} took {self._taken[key]} of {self._published[topic]}'
                for key, topic, name in self._subscriptions if self._taken[key] < self._published[topic]]

    def settle(self) -> None:
        """Spin until every subscription has taken every message published on its topic.

        Raises:
            ReplayStalled: not settled within ``settle_timeout_s`` (names the lagging subscriptions).
        """
        deadline = None
        while self._pending():
            self._executor.spin_once(timeout_sec=0.05)
            if deadline is None:
                deadline = time.monotonic() + self._settle_timeout_s
            elif time.monotonic() > deadline:
                raise ReplayStalled('graph did not settle: ' + '; '.join(self._pending()))

    def publish(self, message: BagMessage) -> None:
        """Publish one bag message on its topic and wait until the graph has settled."""
        if self._direct:
            sequence = self._bag_sequence.setdefault(message.topic, itertools.count(1))
            self._queue.append((message.topic, message.raw, next(sequence)))
            self._drain()
            return
        pub = self._publishers.get(message.topic)
        if pub is None:
            pub = self._node.create_publisher(message_class(message.msgtype), message.topic, DATA_QOS)
            pub.publish = self._counting_publish(pub.publish, message.topic)
            self._publishers[message.topic] = pub
            self._wait_matched(pub, message.topic)
        pub.publish(message.raw)
        self.settle()

    def _wait_matched(self, pub: Any, topic: str) -> None:
        """Wait until discovery has matched the new publisher with every subscription on topic."""
        expected = sum(1 for _, t, _ in self._subscriptions if t == topic)
        deadline = time.monotonic() + self._settle_timeout_s
        while pub.get_subscription_count() < expected:
            self._executor.spin_once(timeout_sec=0.01)
            if time.monotonic() > deadline:
                raise ReplayStalled(f'{topic}: {pub.get_subscription_count()} of {expected} subscriptions matched')

    def end_of_input(self) -> dict[str, str]:
        """Tell every node that its input has ended (:func:`end_input`), then deliver what they
        publish in response (direct) or settle the graph (dds). Returns node name -> method called.

        Raises:
            ReplayStalled: the graph did not settle afterwards.
        """
        ended = {}
        for node in self._nodes:
            method = end_input(node)
            if method is not None:
                ended[node.get_name()] = method
                if self._direct:
                    self._drain()  # a node's outputs may be another node's input: in node order
        if not self._direct:
            self.settle()
        return ended

    def run(self, bag: str | os.PathLike[str], *, topics: Iterable[str] | None = None,
            rate: float | None = None, progress: Callable[[int, int], None] | None = None,
            window_s: tuple[float, float] | None = None, end_of_input: bool = True) -> ReplayResult:
        """Replay ``bag`` (all topics, or ``topics``) through the nodes.

        Args:
            bag: bag directory.
            topics: input topics to publish (default: all topics of the bag).
            rate: pace as a multiple of the recorded pace; None replays as fast as the graph settles.
            progress: called as ``progress(done, total)`` after each message.
            window_s: replay only the messages whose log time lies in [start, stop) seconds after
                the bag's first message.
            end_of_input: after the last message, tell the nodes that the input has ended
                (:meth:`end_of_input`) and collect what they publish then (default); False leaves
                what the nodes hold back unprocessed (to inspect a node mid-stream).
        """
        if rate is not None and not rate > 0:
            raise ValueError(f'rate must be > 0 or None, got {rate}')
        result = ReplayResult()
        with BagReader(bag) as reader:
            selected = list(topics) if topics is not None else sorted(reader.topics)
            total = sum(reader.topics[t][1] for t in selected if t in reader.topics)
            start_ns = stop_ns = None
            if window_s is not None:
                start_ns = reader.start_ns + round(window_s[0] * 1e9)
                stop_ns = reader.start_ns + round(window_s[1] * 1e9)
            counts: dict[str, int] = defaultdict(int)
            wall_start = time.monotonic()
            first = last = None
            for i, message in enumerate(reader.messages(selected, start_ns=start_ns, stop_ns=stop_ns)):
                first = message.stamp_ns if first is None else first
                last = message.stamp_ns
                if rate is not None:
                    due = wall_start + (message.stamp_ns - first) * 1e-9 / rate
                    while time.monotonic() < due:
                        if self._direct:
                            time.sleep(due - time.monotonic())
                        else:
                            self._executor.spin_once(timeout_sec=max(0.0, min(0.05, due - time.monotonic())))
                self.publish(message)
                counts[message.topic] += 1
                if progress is not None:
                    progress(i + 1, total)
            if end_of_input:
                result.ended = self.end_of_input()
            result.wall_time_s = time.monotonic() - wall_start
            result.bag_duration_s = 0.0 if first is None else (last - first) * 1e-9
        result.inputs = dict(counts)
        result.outputs = {t: list(v) for t, v in self._outputs.items()}
        result.output_types = dict(self._output_types)
        return result

    def destroy(self) -> None:
        """Remove the nodes from the executor and destroy the harness node (not the nodes under test)."""
        for node in self._nodes + [self._node]:
            self._executor.remove_node(node)
        self._node.destroy_node()
        self._executor.shutdown()
