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
