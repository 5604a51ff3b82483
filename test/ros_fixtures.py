"""Fixtures for tests that run rclpy nodes: one Context per test, a relay node."""

from __future__ import annotations

import rclpy
from rclpy.context import Context
from rclpy.node import Node

from rfi_experiments.bag_io import message_class
from rfi_node_common.qos import DATA_QOS


def make_context() -> Context:
    context = Context()
    rclpy.init(context=context)
    return context


class RelayNode(Node):
    """Republishes the serialized bytes of each input topic on '/relay' + topic, unchanged."""

    def __init__(self, topics: dict[str, str], *, context: Context) -> None:
        super().__init__('relay', context=context)
        for topic, msgtype in topics.items():
            cls = message_class(msgtype)
            pub = self.create_publisher(cls, '/relay' + topic, DATA_QOS)
            self.create_subscription(cls, topic, lambda raw, pub=pub: pub.publish(raw), DATA_QOS, raw=True)


class HoldingRelay(Node):
    """Like :class:`RelayNode`, but holds every message back until told that the input has ended,
    as a node with a re-ordering buffer does at the end of a bag; ``end_method`` names the method that
    releases them: 'end_of_input', 'flush' (the fusion node's older name) or None (no such method)."""

    def __init__(self, topics: dict[str, str], *, context: Context, end_method: str | None = 'end_of_input') -> None:
        super().__init__('holding_relay', context=context)
        self.held: list[tuple[object, bytes]] = []
        self.calls: list[str] = []
        for topic, msgtype in topics.items():
            cls = message_class(msgtype)
            pub = self.create_publisher(cls, '/relay' + topic, DATA_QOS)
            self.create_subscription(cls, topic, lambda raw, pub=pub: self.held.append((pub, raw)), DATA_QOS,
                                     raw=True)
        if end_method is not None:
            setattr(self, end_method, self._release)

    def _release(self) -> None:
        self.calls.append('release')
        for pub, raw in self.held:
            pub.publish(raw)
        self.held.clear()
