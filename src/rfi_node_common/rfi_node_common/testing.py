"""Test support (not used at run time): the in-process rig of the node tests.

One node under test runs in a :class:`rclpy.context.Context` of its own with a test node that
publishes its inputs and collects its outputs, both in one ``SingleThreadedExecutor``. Every
publish of the node on an output topic is counted, so a test spins (bounded, never sleeps) until
the node has taken its inputs and every message it published has arrived::

    rig = NodeRig(lambda context, overrides: MyNode(context=context, parameter_overrides=overrides),
                  inputs={'/in': (In, DATA_QOS)}, outputs={'/out': Out, '/diagnostics': DiagnosticArray})
    rig.pubs['/in'].publish(msg)
    rig.settle_until(lambda: rig.node.counts['received'] == 1)
    rig.close()

Each node package's test module subclasses :class:`NodeRig` with its topics and a ``send``.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from typing import Any, TypeVar

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile

from rfi_node_common.qos import DATA_QOS

SPIN_DEADLINE_S = 10.0
"""Longest a rig spins for one condition before the test fails, s (wall clock)."""

NodeFactory = Callable[[Context, list[Parameter]], Node]
"""Builds the node under test in the given context with the given parameter overrides."""

Output = type | tuple[type, Callable[[Any], bool]]
"""An output topic's message type, or (type, accept): only messages that ``accept`` are collected
(e.g. those of this node when another process of the same ROS domain publishes on the topic)."""

R = TypeVar('R', bound='NodeRig')


class NodeRig:
    """The node under test plus a test node that publishes its inputs and collects its outputs.

    Args:
        make_node: builds the node under test (``make_node(context, parameter_overrides)``).
        params: parameter overrides of the node, by name.
        args: command-line arguments of ``rclpy.init`` (e.g. ``--ros-args --params-file ...``).
        inputs: input topic -> (message type, QoS of the test's publisher).
        outputs: output topic -> message type, or (type, accept).
        name: name of the test node.
        spin_deadline_s: bound of each :meth:`spin_until`, s.

    Attributes:
        node: the node under test; ``io``: the test node; ``pubs``: input topic -> publisher;
        ``out``: output topic -> messages received, in arrival order; ``published``: output topic
        -> messages the node published.
    """

    def __init__(self, make_node: NodeFactory, *, inputs: Mapping[str, tuple[type, QoSProfile]],
                 outputs: Mapping[str, Output], params: Mapping[str, Any] | None = None,
                 args: list[str] | None = None, name: str = 'node_test_io',
                 spin_deadline_s: float = SPIN_DEADLINE_S) -> None:
        self.spin_deadline_s = spin_deadline_s
        self.context = Context()
        rclpy.init(args=args, context=self.context)
        overrides = [Parameter(k, value=v) for k, v in (params or {}).items()]
        try:
            self.node = make_node(self.context, overrides)
        except Exception:
            rclpy.shutdown(context=self.context)
            raise
        self.io = Node(name, context=self.context)
        self.pubs = {topic: self.io.create_publisher(cls, topic, qos) for topic, (cls, qos) in inputs.items()}
        self.out: dict[str, list] = {}
        for topic, spec in outputs.items():
            cls, accept = spec if isinstance(spec, tuple) else (spec, None)
            self.out[topic] = []
            self.io.create_subscription(cls, topic, self._collector(self.out[topic], accept), DATA_QOS)
        self.published: Counter[str] = Counter()
        self._node_pubs = [p for p in self.node.publishers if p.topic_name in self.out]
        missing = set(self.out) - {p.topic_name for p in self._node_pubs}
        assert not missing, f'the node does not publish {sorted(missing)}'
        for pub in self._node_pubs:
            pub.publish = self._counting(pub.publish, pub.topic_name)  # type: ignore[method-assign,assignment]
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.io)
        self.spin_until(lambda: all(p.get_subscription_count() >= 1 for p in self.pubs.values())
                        and all(p.get_subscription_count() >= 1 for p in self._node_pubs), 'discovery')

    @staticmethod
    def _collector(into: list, accept: Callable[[Any], bool] | None) -> Callable[[Any], None]:
        if accept is None:
            return into.append

        def collect(msg: Any) -> None:
            if accept(msg):
                into.append(msg)
        return collect

    def _counting(self, publish: Callable[[Any], None], topic: str) -> Callable[[Any], None]:
        def counted(msg: Any) -> None:
            self.published[topic] += 1
            publish(msg)
        return counted

    def spin_until(self, done: Callable[[], bool], what: str = 'the graph') -> None:
        """Spin the executor until ``done()``; fail the test after ``spin_deadline_s``."""
        deadline = time.monotonic() + self.spin_deadline_s
        while not done():
            assert time.monotonic() < deadline, f'{what} did not settle within {self.spin_deadline_s} s'
            self.executor.spin_once(timeout_sec=0.05)

    def outputs_arrived(self) -> bool:
        """Every message the node published on an output topic has been collected."""
        return all(len(msgs) == self.published[topic] for topic, msgs in self.out.items())

    def settle_until(self, taken: Callable[[], bool], what: str = 'delivery') -> None:
        """Spin until ``taken()`` (the node has received what was sent) and every output has arrived."""
        self.spin_until(lambda: taken() and self.outputs_arrived(), what)

    def close(self) -> None:
        """Stop the executor, destroy both nodes and shut the context down (idempotent: a test may close a rig
        before building the next, so that the first node no longer receives the second one's inputs)."""
        if getattr(self, "_closed", False):
            return
        self._closed = True
        self.executor.shutdown()
        self.node.destroy_node()
        self.io.destroy_node()
        rclpy.shutdown(context=self.context)


@contextmanager
def rig_factory(make: Callable[..., R]) -> Iterator[Callable[..., R]]:
    """``make`` wrapped so that every rig it built is closed at the end (the body of a pytest fixture).

    ::

        @pytest.fixture
        def rig_factory():
            with testing.rig_factory(Rig) as make:
                yield make
    """
    rigs: list[R] = []

    def build(*args: Any, **kwargs: Any) -> R:
        rig = make(*args, **kwargs)
        rigs.append(rig)
        return rig

    try:
        yield build
    finally:
        for rig in rigs:
            rig.close()
