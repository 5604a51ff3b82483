"""Issue 26 item 1: a replay is analysed in full on every block, and at any speed gives the same answers as at 1x.

A continuous stream of Kang et al.'s front end (38.192 MS/s, IF 9.548 MHz, 8-bit real), 1 ms blocks: 10 clean
blocks, then the paper's saw-tooth chirp at J/S 40 dB (J/N 21 dB) switched on for 30 blocks; stamped in 2023, so
a replay. At 38.192 MS/s a block's full analysis costs about as much CPU as the block lasts on this machine
(docs/rfi_monitor/speed.md), so before issue 26 the shipped CPU budget (max_cpu_load 0.9) gave a replay light
analyses (no chirp frequency) and shed blocks, depending on the machine's speed.

The node runs with its shipped parameters (only the noise bandwidth of the J/N reference given), in process, fed
three ways, the input made reliable each time (nothing is lost, so the comparison is of the analysis alone):

* ``max``: the replay harness as fast as the graph settles (``play --max`` without its queue);
* ``1x``: the harness paced at the recorded rate;
* ``burst``: every block published before the node spins once (``play --max`` into a node behind it: the blocks
  wait in its reliable input queue, depth 1000).

Each must answer every block with the full analysis (blocks_light 0, blocks_shed 0, every block counted as not
live), and the JammerStates must be equal field for field (floats bit for bit) across the three.
"""

from __future__ import annotations

import struct

import pytest
import rclpy
from rclpy.parameter import Parameter
from ros_fixtures import make_context

from rfi_experiments.bag_io import BagReader, BagWriter, deserialize
from rfi_experiments.replay import ReplayHarness
from rfi_monitor.rfi_monitor_node import RfiMonitorNode
from rfi_msgs.msg import IfSamples, JammerState
from rfi_node_common import testing
from rfi_node_common.qos import DATA_QOS
from rfi_node_common.stamps import ns_to_stamp
from rfi_sim.if_signal import ChirpJammer, FrontEndConfig, IfSimulator

START_NS = 1_700_000_000_000_000_000
FRAME_ID = 'rfi_monitor_replay_rate_test'
NOISE_BW_HZ = 2.0e6
N_CLEAN, N_JAMMED = 10, 30
N_BLOCKS = N_CLEAN + N_JAMMED


def _blocks() -> list[IfSamples]:
    fe = FrontEndConfig(noise_bandwidth_hz=NOISE_BW_HZ)
    n = round(fe.sample_rate_hz * 1e-3)
    clean = IfSimulator(fe, (), seed=31)
    jammed = IfSimulator(fe, (ChirpJammer(js_db=40.0),), seed=32)
    msgs = []
    for k in range(N_BLOCKS):
        blk = (clean if k < N_CLEAN else jammed).generate(n)
        m = IfSamples(sample_rate_hz=blk.sample_rate_hz, intermediate_frequency_hz=blk.intermediate_frequency_hz,
                      center_frequency_hz=1575.42e6, is_complex=blk.is_complex, first_sample_index=k * n,
                      scale=float(blk.scale), bits_per_sample=8, sample_format=IfSamples.INT8)
        m.header.stamp = ns_to_stamp(START_NS + k * 10**6)
        m.header.frame_id = FRAME_ID
        m.samples = blk.counts.astype('<i1').tobytes()
        msgs.append(m)
    return msgs


def _node(context) -> RfiMonitorNode:
    return RfiMonitorNode(context=context, parameter_overrides=[
        Parameter('noise_bandwidth_hz', value=NOISE_BW_HZ), Parameter('input_timeout_s', value=0.0),
        Parameter('qos_overrides./rfi/if_samples.subscription.reliability', value='reliable')])


def _harness_replay(bag, rate: float | None) -> tuple[list[JammerState], dict[str, object]]:
    context = make_context()
    try:
        node = _node(context)
        harness = ReplayHarness([node], context=context)
        result = harness.run(bag, topics=['/rfi/if_samples'], rate=rate)
        states = [deserialize(raw, result.output_types['/rfi/jammer_state'])
                  for _, raw in result.outputs.get('/rfi/jammer_state', [])]
        values = node.accounting()
        harness.destroy()
        node.destroy_node()
        return [s for s in states if s.header.frame_id == FRAME_ID], values
    finally:
        rclpy.shutdown(context=context)


def _burst_replay(msgs: list[IfSamples]) -> tuple[list[JammerState], dict[str, object]]:
    context = make_context()
    try:
        node = _node(context)
        io = rclpy.create_node('rfi_replay_rate_probe', context=context)
        states: list[JammerState] = []
        io.create_subscription(JammerState, '/rfi/jammer_state',
                               lambda m: states.append(m) if m.header.frame_id == FRAME_ID else None, DATA_QOS)
        pub = io.create_publisher(IfSamples, '/rfi/if_samples', DATA_QOS)
        executor = testing.CountingExecutor(context=context)
        executor.add_node(node)
        executor.add_node(io)

        def spin() -> None:
            executor.spin_once(timeout_sec=0.05)

        testing.wait_until(lambda: pub.get_subscription_count() >= 1 and node.subscription.get_publisher_count() >= 1,
                           spin, lambda: executor.messages_taken, 'no match')
        for m in msgs:                                  # all queued before the node takes the first
            pub.publish(m)
        # bounded by progress (a block or a state taken), not by a fixed total (a cold cache compiles in the callback)
        testing.wait_until(lambda: len(states) >= N_BLOCKS and node.counts['blocks_received'] >= N_BLOCKS, spin,
                           lambda: executor.messages_taken,
                           f'{N_BLOCKS} blocks and their states')
        values = node.accounting()
        executor.shutdown()
        io.destroy_node()
        node.destroy_node()
        return states, values
    finally:
        rclpy.shutdown(context=context)


def canonical(msg: JammerState) -> tuple:
    """Every field of a JammerState, floats as their IEEE bytes (NaN == NaN)."""
    fields = [f for f in msg.get_fields_and_field_types() if f != 'header']
    return ((msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id),
            tuple(struct.pack('<d', v) if isinstance(v, float) else v for v in (getattr(msg, f) for f in fields)))


@pytest.fixture(scope='module')
def replays(tmp_path_factory):
    msgs = _blocks()
    bag = tmp_path_factory.mktemp('replay_rate') / 'bag'
    with BagWriter(bag) as writer:
        for m in msgs:
            writer.write('/rfi/if_samples', m, START_NS + (m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
                                                           - START_NS))
    with BagReader(bag) as reader:
        assert sum(1 for _ in reader.messages(['/rfi/if_samples'])) == N_BLOCKS
    return {'max': _harness_replay(bag, None), '1x': _harness_replay(bag, 1.0), 'burst': _burst_replay(msgs)}


@pytest.mark.parametrize('pace', ['max', '1x', 'burst'])
def test_every_block_of_a_replay_gets_the_full_analysis(replays, pace):
    states, v = replays[pace]
    assert len(states) == N_BLOCKS
    assert v['blocks_processed'] == N_BLOCKS and v['blocks_light'] == 0 and v['blocks_shed'] == 0
    assert v['live_stream'] is False and v['load.not_live'] == N_BLOCKS and v['load.full'] == N_BLOCKS
    assert v['accounting_ok'] is True
    # the full analysis tracks the chirp: its frequency on the jammed blocks (a light analysis never gives one)
    chirp = [s for s in states[N_CLEAN + 1:] if s.type == JammerState.CHIRP]
    assert len(chirp) >= N_JAMMED - 3
    assert sum(s.frequency_hz == s.frequency_hz for s in chirp) >= len(chirp) - 3


def test_a_replay_at_any_speed_gives_the_answers_of_a_replay_at_1x(replays):
    reference = [canonical(s) for s in replays['1x'][0]]
    assert len(reference) == N_BLOCKS
    for pace in ('max', 'burst'):
        assert [canonical(s) for s in replays[pace][0]] == reference, pace
