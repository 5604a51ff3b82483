"""Bag replay through a relay node: complete, in order and byte-identical, at 1x and max rate."""

from __future__ import annotations

import pytest
import rclpy
from ros_fixtures import HoldingRelay, RelayNode, make_context
from sample_bag import write_sample_bag

from rfi_experiments.bag_io import BagReader
from rfi_experiments.replay import ReplayHarness


@pytest.fixture(scope='module')
def sample_bag(tmp_path_factory):
    path = tmp_path_factory.mktemp('bags') / 'sample'
    counts = write_sample_bag(path, seconds=2.0)
    return path, counts


def replay(path, rate, transport='dds'):
    context = make_context()
    try:
        with BagReader(path) as reader:
            types = {t: info[0] for t, info in reader.topics.items()}
            expected = [(m.topic, m.raw) for m in reader.messages()]
        relay = RelayNode(types, context=context)
        harness = ReplayHarness([relay], context=context, transport=transport)
        result = harness.run(path, rate=rate)
        harness.destroy()
        relay.destroy_node()
        return expected, result
    finally:
        rclpy.shutdown(context=context)


def relayed_in_order(result):
    merged = sorted((index, topic[len('/relay'):], raw)
                    for topic, items in result.outputs.items() for index, raw in items)
    return [(topic, raw) for _, topic, raw in merged]


@pytest.mark.parametrize('transport', ['dds', 'direct'])
@pytest.mark.parametrize('rate', [None, 1.0], ids=['max', '1x'])
def test_relay_complete_in_order_and_byte_identical(sample_bag, rate, transport):
    path, counts = sample_bag
    expected, result = replay(path, rate, transport)
    assert result.inputs == counts
    assert len(expected) == sum(counts.values()) == 190  # 20 IF + 20 jammer + 10 GNSS + 40 UWB + 100 correlators
    assert relayed_in_order(result) == expected
    if rate is not None:
        # paced replay takes the bag's duration (1.95 s of log time) at least
        assert result.wall_time_s >= result.bag_duration_s * 0.99


def test_outputs_do_not_depend_on_replay_speed(sample_bag):
    path, _ = sample_bag
    _, fast = replay(path, None)
    _, paced = replay(path, 4.0)
    assert fast.outputs == paced.outputs


def test_direct_transport_gives_the_same_outputs_as_dds(sample_bag):
    path, _ = sample_bag
    _, dds = replay(path, None, 'dds')
    _, direct = replay(path, None, 'direct')
    assert direct.outputs == dds.outputs


def test_unknown_transport_is_refused():
    context = make_context()
    try:
        with pytest.raises(ValueError, match='transport'):
            ReplayHarness([], context=context, transport='carrier-pigeon')
    finally:
        rclpy.shutdown(context=context)


@pytest.mark.parametrize('transport', ['dds', 'direct'])
@pytest.mark.parametrize('end_method', ['end_of_input', 'flush', None])
def test_end_of_input_releases_what_a_node_holds_back(sample_bag, transport, end_method):
    """A node that holds messages back (the fusion's re-ordering buffer) gets end_of_input() (or
    flush(), or nothing if it has neither) after the last input, and its outputs are collected."""
    path, counts = sample_bag
    context = make_context()
    try:
        with BagReader(path) as reader:
            types = {t: info[0] for t, info in reader.topics.items()}
            topics = ['/uwb/ranges', '/gnss/measurements']
            expected = [(m.topic, m.raw) for m in reader.messages(topics)]
        node = HoldingRelay({t: types[t] for t in topics}, context=context, end_method=end_method)
        harness = ReplayHarness([node], context=context, transport=transport)
        held = harness.run(path, topics=topics, end_of_input=False)
        assert held.outputs == {'/relay/uwb/ranges': [], '/relay/gnss/measurements': []} and held.ended == {}
        assert len(node.held) == len(expected) and node.calls == []
        harness.destroy()
        node.destroy_node()
        node = HoldingRelay({t: types[t] for t in topics}, context=context, end_method=end_method)
        harness = ReplayHarness([node], context=context, transport=transport)
        result = harness.run(path, topics=topics)
        harness.destroy()
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    if end_method is None:
        assert result.ended == {} and sum(len(v) for v in result.outputs.values()) == 0
    else:
        assert result.ended == {'holding_relay': end_method} and node.calls == ['release']
        # per topic in order (a burst over DDS has no order across topics)
        for topic in topics:
            assert [raw for _, raw in result.outputs['/relay' + topic]] == [raw for t, raw in expected if t == topic]


@pytest.mark.parametrize('transport', ['dds', 'direct'])
def test_subscriptions_see_the_publishers_sequence_numbers(sample_bag, transport):
    """The nodes count lost input from gaps in the publisher's sequence numbers (MessageInfo): the
    direct hand-over numbers each publisher's messages 1, 2, ... as the middleware does."""
    from rclpy.node import Node

    from rfi_msgs.msg import UwbRange

    path, counts = sample_bag
    context = make_context()
    try:
        node = Node('sequence_recorder', context=context)
        seen = []
        node.create_subscription(UwbRange, '/uwb/ranges',
                                 lambda msg, info: seen.append(info['publication_sequence_number']), 10)
        harness = ReplayHarness([node], context=context, transport=transport)
        harness.run(path, topics=['/uwb/ranges'])
        harness.destroy()
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    assert seen == list(range(1, counts['/uwb/ranges'] + 1))
