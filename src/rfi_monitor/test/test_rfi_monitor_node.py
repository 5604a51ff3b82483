"""In-process tests of rfi_monitor_node: one Context per test, a SingleThreadedExecutor, bounded spins.

Blocks are simulated with rfi_experiments.sim.if_signal (seeded) and sent over DDS to the node; a
probe node collects /rfi/jammer_state and /diagnostics. With diagnostics_period_s = 1 ms and block
stamps at least 1 ms apart every block gives exactly one /diagnostics message, so the probe knows how
many outputs to wait for (no sleeps: ``spin_once`` until the counts are reached, with a deadline).

Jammers are at J/S 40 dB with the noise counted over 2 MHz (J/N 21.2 dB), where the monitor finds the
sweep within a 1 ms block (test/test_rfi_monitor_replay.py explains the choice). The chirp bars come
from direct core runs of the same stream, seeds 0-39 step 3 (core at the time of writing): 8 of 8
blocks CHIRP, frequency RMSE 65-133 kHz, period error <= 0.02 %, sweep rate 0.94-1.01e12 Hz/s.
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
import yaml
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message

from rfi_experiments.sim.if_signal import ChirpJammer, CwJammer, FrontEndConfig, IfBlock, IfSimulator
from rfi_monitor.monitor import RfiMonitorParams
from rfi_monitor.rfi_monitor_node import NESTED, MonitorNodeParams, RfiMonitorNode, decode_samples
from rfi_msgs.msg import IfSamples, JammerState
from rfi_node_common.qos import DATA_QOS
from rfi_node_common.stamps import ns_to_stamp, stamp_to_ns

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'rfi_monitor.yaml'
START_NS = 1_700_000_000_000_000_000
FRAME_ID = 'rfi_monitor_node_test_front_end'
L1_HZ = 1575.42e6
NOISE_BW_HZ = 2.0e6
JS_DB = 40.0
JN_DB = JS_DB - 130.0 + 114.0 - 10 * math.log10(NOISE_BW_HZ / 1e6)  # 21.0 dB
CALIBRATION = 5
SPIN_DEADLINE_S = 30.0


def _parameters(**overrides) -> list[Parameter]:
    base = {'diagnostics_period_s': 0.001, 'noise_bandwidth_hz': NOISE_BW_HZ}
    base.update(overrides)
    return [Parameter(k, value=v) for k, v in base.items()]


class Probe:
    """The node under test, a publisher of IF blocks and collectors of its outputs, in one executor."""

    def __init__(self, **overrides) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = RfiMonitorNode(context=self.context, parameter_overrides=_parameters(**overrides))
        self.probe = Node('rfi_monitor_probe', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.probe)
        self.diagnostics_published = 0
        publish = self.node.diag_pub.publish

        def counted(msg: DiagnosticArray) -> None:
            self.diagnostics_published += 1
            publish(msg)
        self.node.diag_pub.publish = counted
        self.states: list[JammerState] = []
        self.diagnostics: list[DiagnosticArray] = []
        self.pub = self.probe.create_publisher(IfSamples, '/rfi/if_samples', DATA_QOS)
        # keep only this node's outputs: another process on the same ROS domain may publish on these topics
        self.probe.create_subscription(JammerState, '/rfi/jammer_state', self._on_state, DATA_QOS)
        self.probe.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, DATA_QOS)
        self._spin_until(lambda: self.pub.get_subscription_count() >= 1
                         and self.node.state_pub.get_subscription_count() >= 1
                         and self.node.diag_pub.get_subscription_count() >= 1, 'discovery')

    def _on_state(self, msg: JammerState) -> None:
        if msg.header.frame_id == FRAME_ID:
            self.states.append(msg)

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        if msg.status and msg.status[0].name == 'rfi_monitor' and msg.status[0].hardware_id == self.node.get_name():
            self.diagnostics.append(msg)

    def _spin_until(self, done, what: str) -> None:
        deadline = time.monotonic() + SPIN_DEADLINE_S
        while not done():
            self.executor.spin_once(timeout_sec=0.05)
            if time.monotonic() > deadline:
                raise AssertionError(f'{what} did not complete within {SPIN_DEADLINE_S} s')

    def send(self, msg: IfSamples) -> JammerState | None:
        """Publish one block; return the JammerState it produced (None if it produced none)."""
        received = self.node.counts['blocks_received']
        before = len(self.states)
        self.pub.publish(msg)
        self._spin_until(lambda: self.node.counts['blocks_received'] == received + 1, 'block delivery')
        self._spin_until(lambda: len(self.states) == self.node.counts['states_published']
                         and len(self.diagnostics) == self.diagnostics_published, 'output delivery')
        assert len(self.states) - before in (0, 1)
        if len(self.states) == before:
            return None
        assert self.states[-1].header.stamp == msg.header.stamp
        return self.states[-1]

    def send_all(self, msgs: list[IfSamples]) -> list[JammerState | None]:
        return [self.send(m) for m in msgs]

    def values(self) -> dict[str, str]:
        return {kv.key: kv.value for kv in self.diagnostics[-1].status[0].values}

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.probe.destroy_node()
        rclpy.shutdown(context=self.context)


@pytest.fixture
def probe_factory():
    probes: list[Probe] = []

    def make(**overrides) -> Probe:
        p = Probe(**overrides)
        probes.append(p)
        return p
    yield make
    for p in probes:
        p.close()


def block_msg(blk: IfBlock, first_index: int, stamp_ns: int, *, bits: int | None = None) -> IfSamples:
    """IfSamples of a simulated block (INT8 for <= 8 bits, else INT16 little-endian)."""
    bits = blk.bits if bits is None else bits
    fmt, dtype = (IfSamples.INT8, '<i1') if bits <= 8 else (IfSamples.INT16, '<i2')
    m = IfSamples(sample_rate_hz=blk.sample_rate_hz, intermediate_frequency_hz=blk.intermediate_frequency_hz,
                  center_frequency_hz=L1_HZ, is_complex=blk.is_complex, first_sample_index=first_index,
                  scale=float(blk.scale), bits_per_sample=bits, sample_format=fmt)
    m.header.stamp = ns_to_stamp(stamp_ns)
    m.header.frame_id = FRAME_ID
    m.samples = blk.counts.astype(dtype).tobytes()
    return m


def stream(fe: FrontEndConfig, jammers: tuple, n_clean: int, n_jammed: int, seed: int, block_s: float = 1e-3):
    """A continuous stream: n_clean noise-only blocks, then n_jammed blocks with the jammers (the jammer
    switches on at a block boundary). Returns (messages, truth blocks)."""
    n = round(block_s * fe.sample_rate_hz)
    clean = IfSimulator(fe, (), seed=seed)
    jammed = IfSimulator(fe, jammers, seed=seed + 1)
    msgs, blocks = [], []
    for k in range(n_clean + n_jammed):
        blk = clean.generate(n) if k < n_clean else jammed.generate(n)
        msgs.append(block_msg(blk, k * n, START_NS + round(k * block_s * 1e9)))
        blocks.append(blk)
    return msgs, blocks


def wrapped(err_hz: np.ndarray, band_hz: float) -> np.ndarray:
    """Frequency error folded into +-band/2: at a saw-tooth's reset an estimate a few samples late is one
    whole swept band off, which is a timing error of the reset, not a frequency error."""
    return (err_hz + band_hz / 2) % band_hz - band_hz / 2


# --------------------------------------------------------------------------------------------------
def test_chirp_stream_gives_chirp_with_the_right_frequency_track(probe_factory):
    fe = FrontEndConfig(noise_bandwidth_hz=NOISE_BW_HZ)
    jammer = ChirpJammer(js_db=JS_DB)
    msgs, blocks = stream(fe, (jammer,), CALIBRATION, 8, seed=3)
    p = probe_factory()
    states = p.send_all(msgs)
    assert all(s is not None for s in states)
    assert [s.type for s in states[:CALIBRATION]] == [JammerState.UNKNOWN] * CALIBRATION
    chirp = states[CALIBRATION:]
    types = [s.type for s in chirp]
    assert types.count(JammerState.CHIRP) >= 7 and set(types) <= {JammerState.CHIRP, JammerState.WIDEBAND}, types
    est = np.array([s.frequency_hz for s in chirp if s.type == JammerState.CHIRP])
    true = np.array([b.truth.frequency_hz[0, -1] for b, s in zip(blocks[CALIBRATION:], chirp, strict=True)
                     if s.type == JammerState.CHIRP])
    rmse_hz = float(np.sqrt(np.mean(wrapped(est - true, jammer.bandwidth_hz) ** 2)))
    assert rmse_hz < 250e3, rmse_hz  # a tone anywhere in the 5.1 MHz sweep: 1.47 MHz
    for s in chirp:
        assert s.header.frame_id == FRAME_ID and s.center_frequency_hz == L1_HZ
        assert s.sample_rate_hz == fe.sample_rate_hz
        assert abs(s.jammer_to_noise_db - JN_DB) < 1.5
        assert abs(s.jammer_to_signal_db - JS_DB) < 1.5
        if s.type == JammerState.CHIRP and math.isfinite(s.sweep_period_s):
            assert abs(s.sweep_period_s / jammer.sweep_period_s - 1) < 0.01
            assert abs(s.sweep_rate_hz_per_s / jammer.sweep_rate_hz_per_s - 1) < 0.10
    # continuous stream: no gaps; all blocks analysed
    v = p.values()
    assert v['gaps'] == '0' and v['rate_changes'] == '0'
    assert int(v['blocks_processed']) == len(msgs) and v['accounting_ok'] == 'True'


@pytest.mark.parametrize('is_complex, bits', [(False, 8), (False, 12), (True, 8), (True, 12)],
                         ids=['real-int8', 'real-int16', 'complex-int8', 'complex-int16'])
def test_cw_in_every_format(probe_factory, is_complex, bits):
    if is_complex:
        fe = FrontEndConfig(sample_rate_hz=19.096e6, intermediate_frequency_hz=0.0, is_complex=True, bits=bits,
                            noise_bandwidth_hz=NOISE_BW_HZ)
    else:
        fe = FrontEndConfig(bits=bits, noise_bandwidth_hz=NOISE_BW_HZ)
    f_hz = -1.3e6
    msgs, _ = stream(fe, (CwJammer(frequency_hz=f_hz, js_db=JS_DB),), CALIBRATION, 3, seed=5)
    assert msgs[0].sample_format == (IfSamples.INT8 if bits <= 8 else IfSamples.INT16)
    p = probe_factory()
    states = p.send_all(msgs)
    for s in states[CALIBRATION:]:
        assert s.type == JammerState.CW
        assert abs(s.frequency_hz - f_hz) < 10e3  # Welch bin 149 kHz (real) / 75 kHz (complex)
        assert abs(s.jammer_to_noise_db - JN_DB) < 1.5
        assert s.sweep_rate_hz_per_s == 0.0 and math.isnan(s.sweep_period_s)
    assert p.values()['accounting_ok'] == 'True'


def test_decode_is_little_endian_and_scaled():
    values = np.array([1, -2, 300, -32768, 32767, 0], dtype='<i2')
    m = IfSamples(sample_format=IfSamples.INT16, scale=0.5, samples=values.tobytes())
    np.testing.assert_array_equal(decode_samples(m), values.astype(float) * 0.5)
    m8 = IfSamples(sample_format=IfSamples.INT8, scale=2.0, samples=bytes([0x01, 0xff, 0x80, 0x7f]))
    np.testing.assert_array_equal(decode_samples(m8), [2.0, -2.0, -256.0, 254.0])


def test_gaps_and_rate_changes_are_counted_and_reset_the_monitor(probe_factory):
    fe = FrontEndConfig(noise_bandwidth_hz=NOISE_BW_HZ)
    msgs, _ = stream(fe, (CwJammer(frequency_hz=1e6, js_db=JS_DB),), CALIBRATION, 4, seed=7)
    n = len(msgs[0].samples)
    msgs[6].first_sample_index += 10 * n          # gap before block 6 ...
    for m in msgs[7:]:
        m.first_sample_index += 10 * n            # ... and continuous after it
    fe2 = FrontEndConfig(sample_rate_hz=16.368e6, intermediate_frequency_hz=4.092e6,
                         noise_bandwidth_hz=NOISE_BW_HZ)
    other = IfSimulator(fe2, (), seed=8).generate(16368)
    msgs.append(block_msg(other, 0, START_NS + 20_000_000))   # new rate: restarts the calibration
    p = probe_factory()
    states = p.send_all(msgs)
    v = p.values()
    assert v['gaps'] == '1'
    assert v['rate_changes'] == '1'
    assert [s.type for s in states[CALIBRATION:-1]] == [JammerState.CW] * 4   # a gap keeps the calibration
    assert states[-1].type == JammerState.UNKNOWN and states[-1].sample_rate_hz == 16.368e6
    assert v['calibrated'] == 'False'
    assert int(v['blocks_processed']) == len(msgs) and v['accounting_ok'] == 'True'


def _bad_blocks(good: IfSamples) -> dict[str, IfSamples]:
    """One malformed variant of ``good`` per rejection reason; stamps after the good block's."""
    bad = {}

    def variant(reason: str, k: int, **fields) -> IfSamples:
        m = deserialize_message(serialize_message(good), IfSamples)   # a deep copy
        m.header.stamp = ns_to_stamp(stamp_to_ns(good.header.stamp) + k * 1_000_000)
        for key, value in fields.items():
            setattr(m, key, value)
        bad[reason] = m
        return m

    counts = np.frombuffer(good.samples, dtype='<i1').copy()
    saturated = counts.copy()
    saturated[::10] = 127                                             # 10 % at full scale
    variant('empty_block', 1, samples=b'')
    variant('saturated', 2, samples=saturated.tobytes())
    variant('bad_sample_rate', 3, sample_rate_hz=0.0)
    variant('bad_sample_rate_negative', 4, sample_rate_hz=-38.192e6)
    variant('odd_length_iq', 5, is_complex=True, intermediate_frequency_hz=0.0, samples=counts[:-1].tobytes())
    variant('unknown_sample_format', 6, sample_format=7)
    variant('truncated_sample', 7, sample_format=IfSamples.INT16, bits_per_sample=12,
            samples=counts[:-1].tobytes())
    variant('bad_scale', 8, scale=0.0)
    variant('bad_bits_per_sample', 9, bits_per_sample=12)                # 12 bits cannot be stored as INT8
    variant('bad_intermediate_frequency', 10, intermediate_frequency_hz=20e6)  # above fs/2
    variant('short_block', 11, samples=counts[:1000].tobytes())
    variant('stamp_not_increasing', -1)                                  # before the good block
    return bad


def test_each_bad_input_is_counted_and_gives_no_state(probe_factory):
    fe = FrontEndConfig(noise_bandwidth_hz=NOISE_BW_HZ)
    msgs, _ = stream(fe, (CwJammer(frequency_hz=1e6, js_db=JS_DB),), CALIBRATION, 2, seed=9)
    p = probe_factory()
    p.send_all(msgs[:CALIBRATION + 1])
    good = msgs[CALIBRATION]
    bad = _bad_blocks(good)
    for reason, msg in bad.items():
        published = p.node.counts['states_published']
        state = p.send(msg)
        assert state is None and p.node.counts['states_published'] == published, reason
        v = p.values()
        key = 'rejected_' + reason.removesuffix('_negative')
        assert int(v[key]) >= 1, (reason, v)
        assert v['accounting_ok'] == 'True'
        assert p.diagnostics[-1].status[0].level == b'\x01', reason  # WARN: a block was rejected
    v = p.values()
    assert int(v['rejected_bad_sample_rate']) == 2
    rejected = sum(int(x) for k, x in v.items() if k.startswith('rejected_'))
    assert rejected == len(bad)
    assert int(v['blocks_received']) == CALIBRATION + 1 + len(bad)
    assert int(v['blocks_processed']) == CALIBRATION + 1
    # the node is still alive and analyses the next good block. Only the saturated block reached the core
    # (with the good block's first_sample_index: a gap); the next block continues it
    last = msgs[CALIBRATION + 1]
    last.header.stamp = ns_to_stamp(stamp_to_ns(good.header.stamp) + 100_000_000)
    state = p.send(last)
    assert state is not None and state.type == JammerState.CW
    assert p.diagnostics[-1].status[0].level == b'\x00'  # OK again: nothing rejected since the last report
    assert p.values()['gaps'] == '1'


def test_no_saturation_check_for_two_bit_front_ends():
    """A 2-bit front end puts about a third of its samples on its top level: that is not saturation."""
    from rfi_monitor.rfi_monitor_node import full_scale
    assert full_scale(IfSamples(bits_per_sample=2, scale=1.0)) is None
    assert full_scale(IfSamples(bits_per_sample=8, scale=0.5)) == 127 * 0.5
    assert full_scale(IfSamples(bits_per_sample=12, scale=1.0)) == 2047.0


# --------------------------------------------------------------------------------------------------
def _default(field: dataclasses.Field):
    return field.default if field.default is not dataclasses.MISSING else field.default_factory()  # type: ignore


def test_config_yaml_equals_defaults():
    doc = yaml.safe_load(CONFIG.read_text())
    assert list(doc) == ['rfi_monitor']
    values = doc['rfi_monitor']['ros__parameters']
    defaults = {f.name: _default(f) for f in dataclasses.fields(MonitorNodeParams)}
    assert list(values) == list(defaults)
    for name, default in defaults.items():
        assert type(values[name]) is type(default), name   # e.g. 1 in the file would be an int parameter
        assert values[name] == default, name


def test_config_yaml_loads_as_a_params_file():
    context = Context()
    rclpy.init(context=context, args=['--ros-args', '--params-file', str(CONFIG)])
    try:
        node = RfiMonitorNode(context=context)
        assert node.params == MonitorNodeParams()
        assert node.monitor.params == RfiMonitorParams()
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_every_core_parameter_is_a_node_parameter():
    names = {f.name for f in dataclasses.fields(MonitorNodeParams)}
    nested = {name for name, _, _ in NESTED}
    for f in dataclasses.fields(RfiMonitorParams):
        if f.name not in nested:
            assert f.name in names, f.name
    for _, prefix, cls in NESTED:
        for f in dataclasses.fields(cls):
            assert prefix + f.name in names, prefix + f.name
    assert MonitorNodeParams().monitor_params() == RfiMonitorParams()


def test_invalid_parameters_raise_a_clear_error(probe_factory):
    with pytest.raises(ValueError, match='min_block_samples'):
        MonitorNodeParams(min_block_samples=100)            # below classifier_nfft 256
    with pytest.raises(ValueError, match='tracker_mode'):
        MonitorNodeParams(tracker_mode='ekf')
    with pytest.raises(ValueError, match='sweep_tolerance'):
        MonitorNodeParams(sweep_tolerance=0.7)
    context = Context()
    rclpy.init(context=context)
    try:
        with pytest.raises(ValueError, match='diagnostics_period_s'):
            RfiMonitorNode(context=context, parameter_overrides=[Parameter('diagnostics_period_s', value=0.0)])
    finally:
        rclpy.shutdown(context=context)
