"""if_source -> rfi_monitor_node in one process over DDS, on the real captures: the blocks on /rfi/if_samples are
those of the direct read (np.fromfile, compared exactly) and every /rfi/jammer_state is byte for byte what the
monitor core gives on the directly read blocks. Bounded spins, no sleeps."""

from __future__ import annotations

import math
import re
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message

from rfi_experiments.if_source import IfSourceNode, IfSourceParams
from rfi_monitor.monitor import RfiMonitor
from rfi_monitor.rfi_monitor_node import (
    MonitorNodeParams,
    RfiMonitorNode,
    decode_counts,
    decode_samples,
    full_scale,
    jammer_state_msg,
)
from rfi_msgs.msg import IfSamples, JammerState
from rfi_node_common import testing
from rfi_node_common.qos import DATA_QOS
from rfi_node_common.stamps import ns_to_stamp, stamp_to_ns

DATA = Path(__file__).resolve().parents[2] / 'rfi_monitor' / 'test' / 'data'
SHARED_12MHZ = Path(__file__).resolve().parents[4] / 'shared' / 'data' / 'iq_clean_pocketsdr' / \
    'L1_20211125_004000_12MHz_I.bin'
CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'if_source.yaml'
FRAME_ID = 'if_source_node_test'
START_NS = 1_638_434_820_000_000_000

# file, source parameters, direct read dtype, block samples, complex, fs, IF, bits
CASES = [
    ('pocketsdr_L1_12MHz_I_10ms.bin', {'item_type': 'byte', 'sampling_frequency_hz': 12e6,
                                       'intermediate_frequency_hz': 3e6, 'bits_per_sample': 2},
     np.int8, 12000, False, 12e6, 3e6, 2),
    ('pocketsdr_L1_4MHz_IQ_10ms.bin', {'item_type': 'ibyte', 'sampling_frequency_hz': 4e6, 'bits_per_sample': 2},
     np.int8, 4000, True, 4e6, 0.0, 2),
    ('gnsssdr_cttc_4Msps_4ms.dat', {'item_type': 'gr_complex', 'sampling_frequency_hz': 4e6,
                                    'block_duration_s': 0.0005},
     np.float32, 2000, True, 4e6, 0.0, 16),
]
IDS = [c[0] for c in CASES]


def message_fields(msg, wire: bool = True) -> tuple:
    """Every field of a message as it arrives (after a CDR round trip: float32 fields rounded), nested messages
    expanded, NaN made comparable. Serialised bytes cannot be compared: rclpy leaves the CDR padding bytes
    uninitialised."""
    if wire:
        msg = deserialize_message(serialize_message(msg), type(msg))
    out = []
    for name in msg.get_fields_and_field_types():
        v = getattr(msg, name)
        if hasattr(v, 'get_fields_and_field_types'):
            out.append(message_fields(v, wire=False))
        elif isinstance(v, float) and math.isnan(v):
            out.append('nan')
        elif isinstance(v, (bytes, bytearray, list, np.ndarray)) or type(v).__name__ == 'array':
            out.append(bytes(np.asarray(v).tobytes()) if not isinstance(v, (bytes, bytearray)) else bytes(v))
        else:
            out.append(v)
    return tuple(out)


def direct_blocks(path: Path, dtype, block: int, cplx: bool, fs: float, fif: float, bits: int) -> list[IfSamples]:
    """IfSamples built by hand from np.fromfile (not with rfi_experiments.if_formats)."""
    x = np.fromfile(path, dtype=dtype)
    per = block * (2 if cplx else 1)
    out = []
    for k in range(x.size // per):
        m = IfSamples()
        m.header.stamp = ns_to_stamp(START_NS + round(k * block * 1e9 / fs))
        m.header.frame_id = FRAME_ID
        m.sample_rate_hz, m.intermediate_frequency_hz, m.center_frequency_hz = fs, fif, 1575.42e6
        m.is_complex, m.first_sample_index, m.scale = cplx, k * block, 1.0
        m.bits_per_sample = bits
        m.sample_format = IfSamples.INT8 if dtype == np.int8 else IfSamples.INT16
        m.samples = x[k * per:(k + 1) * per].astype(np.int8 if dtype == np.int8 else '<i2').tobytes()
        out.append(m)
    return out


def core_states(blocks: list[IfSamples]) -> list[JammerState]:
    """The monitor core (the node's defaults and arguments) on each block, as the node would publish it."""
    mon = RfiMonitor(MonitorNodeParams().monitor_params())
    out = []
    for m in blocks:
        est = mon.process(decode_samples(m), m.sample_rate_hz, m.intermediate_frequency_hz, m.first_sample_index,
                          stamp_to_ns(m.header.stamp), is_complex=bool(m.is_complex), full_scale=full_scale(m))
        if est.valid:
            out.append(jammer_state_msg(est, m))
    return out


class Chain:
    """if_source and rfi_monitor_node in one context and executor, with a probe collecting their outputs."""

    def __init__(self, source_params: dict) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.monitor = RfiMonitorNode(context=self.context, parameter_overrides=[
            Parameter('input_timeout_s', value=0.0),
            Parameter('max_cpu_load', value=0.0),   # no load shedding: every block analysed, as by the core
            Parameter('qos_overrides./rfi/if_samples.subscription.reliability', value='reliable')])
        self.probe = Node('if_source_probe', context=self.context)
        self.blocks: list[IfSamples] = []
        self.states: list[JammerState] = []
        self.diagnostics: list[DiagnosticArray] = []
        self.probe.create_subscription(IfSamples, '/rfi/if_samples', self._own(self.blocks), DATA_QOS)
        self.probe.create_subscription(JammerState, '/rfi/jammer_state', self._own(self.states), DATA_QOS)
        self.probe.create_subscription(DiagnosticArray, '/diagnostics', self._diag, DATA_QOS)
        params = {'start_time': str(START_NS / 1e9), 'frame_id': FRAME_ID, 'pace': 'max', 'exit_at_end': False,
                  'wait_for_subscribers': 2, 'wait_timeout_s': 20.0, **source_params}
        self.source = IfSourceNode(context=self.context,
                                   parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
        self.executor = testing.CountingExecutor(context=self.context)
        for node in (self.monitor, self.probe, self.source):
            self.executor.add_node(node)

    @staticmethod
    def _own(into: list):
        return lambda msg: into.append(msg) if msg.header.frame_id == FRAME_ID else None

    def _diag(self, msg: DiagnosticArray) -> None:
        status = msg.status[0] if msg.status else None
        if status is not None and status.name == 'if_source' and status.hardware_id == self.source.params.hardware_id:
            self.diagnostics.append(msg)

    def final_values(self) -> dict[str, str]:
        final = [d for d in self.diagnostics if d.status[0].message.startswith('end of input')]
        assert len(final) == 1
        return {kv.key: kv.value for kv in final[0].status[0].values}

    def spin_until(self, done, what: str) -> None:
        # bounded by progress (a message taken by the monitor or the probe; if_source's reader is a thread, so a
        # block it publishes is one), not by a fixed total: a cold numba cache compiles the monitor's kernels on the
        # first block
        testing.wait_until(done, lambda: self.executor.spin_once(timeout_sec=0.05),
                           lambda: self.executor.messages_taken, f'{what}: not done')

    def close(self) -> None:
        self.executor.shutdown()
        for node in (self.source, self.monitor, self.probe):
            node.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def chains():
    made: list[Chain] = []

    def make(params: dict) -> Chain:
        made.append(Chain(params))
        return made[-1]
    yield make
    for c in made:
        c.close()


@pytest.mark.parametrize('name,params,dtype,block,cplx,fs,fif,bits', CASES, ids=IDS)
def test_source_to_monitor_equals_direct_read(chains, name, params, dtype, block, cplx, fs, fif, bits):
    check_chain_against_direct_read(chains, DATA / name, params, dtype, block, cplx, fs, fif, bits)


@pytest.mark.skipif(not SHARED_12MHZ.is_file(), reason='../shared/data is not here (a clone has the cuts only)')
def test_whole_12mhz_capture_through_source_and_monitor(chains):
    """The whole 0.1 s PocketSDR 12 MHz real capture of ../shared/data: 100 blocks, as above."""
    check_chain_against_direct_read(chains, SHARED_12MHZ, *CASES[0][1:])


def check_chain_against_direct_read(chains, path, params, dtype, block, cplx, fs, fif, bits):
    direct = direct_blocks(path, dtype, block, cplx, fs, fif, bits)
    expected_states = core_states(direct)
    assert len(expected_states) == len(direct)  # every block analysed
    chain = chains({'input': str(path), **params})
    chain.spin_until(lambda: chain.source.done.is_set() and len(chain.states) >= len(direct)
                     and any(d.status[0].message.startswith('end of input') for d in chain.diagnostics),
                     'every block through the monitor')
    assert len(chain.blocks) == len(direct)
    for got, want in zip(chain.blocks, direct, strict=True):
        assert np.array_equal(decode_counts(got), decode_counts(want))  # exact: integers
        assert message_fields(got) == message_fields(want)       # and every other field
    for k, (a, b) in enumerate(zip(chain.states, expected_states, strict=True)):
        assert message_fields(a) == message_fields(b), (k, a, b, chain.monitor.accounting())
    values = chain.final_values()
    assert values['blocks_published'] == str(len(direct)) and values['gaps'] == '0'
    assert values['final_partial_block_samples'] == '0' and values['trailing_bytes'] == '0'
    monitor = chain.monitor.accounting()
    assert monitor['blocks_processed'] == len(direct) and monitor['gaps'] == 0 and monitor['accounting_ok']


def test_real_time_pace_keeps_the_sample_rate(chains):
    """pace real_time: 10 blocks of 1 ms are not out before 10 ms of steady time (the only timing asserted is a
    lower bound, which load cannot break)."""
    chain = chains({'input': str(DATA / CASES[1][0]), **CASES[1][1], 'pace': 'real_time'})
    t0 = time.monotonic()
    chain.spin_until(lambda: chain.source.done.is_set() and len(chain.blocks) == 10, 'ten blocks')
    assert time.monotonic() - t0 >= 0.010
    assert [b.first_sample_index for b in chain.blocks] == [4000 * k for k in range(10)]


@pytest.mark.parametrize('overrides,needle', [
    ({'item_type': 'ishort', 'input': str(DATA / 'pocketsdr_L1_12MHz_I_10ms.bin'), 'sampling_frequency_hz': 4e6,
      'intermediate_frequency_hz': 3e6}, 'fs/2'),
    ({'item_type': 'gr_complex', 'input': '{odd}'}, 'not a whole number of gr_complex items'),
    ({'input': '/no/such/capture.bin'}, 'No such file'),
    ({'start_time': 'teatime'}, 'start time'),
    ({'sample_type': 'iq'}, 'packed item types only'),
    ({'block_duration_s': 2.0e-7}, 'block_duration_s'),
])
def test_bad_parameters_are_refused(tmp_path, overrides, needle):
    odd = tmp_path / 'odd.dat'
    odd.write_bytes(bytes(8 * 5000 + 3))
    overrides = {k: (str(odd) if v == '{odd}' else v) for k, v in overrides.items()}
    error = testing.start_error(lambda context, params: IfSourceNode(context=context, parameter_overrides=params),
                                overrides)
    assert re.search(needle, error), error


def test_parameters_are_documented():
    import dataclasses
    assert 'if_to_bag' in (IfSourceParams.__doc__ or '')
    for f in dataclasses.fields(IfSourceParams):
        assert f.metadata['rfi_doc']['description'], f.name


def test_config_file_lists_every_parameter_with_its_default():
    import dataclasses

    import yaml
    values = yaml.safe_load(CONFIG.read_text())['if_source']['ros__parameters']
    defaults = {f.name: f.default for f in dataclasses.fields(IfSourceParams)}
    assert values == defaults
    assert all(type(values[k]) is type(v) for k, v in defaults.items())  # 0.0 stays a float, 0 an int


def test_pipe_backlog_and_capacity_are_seen():
    """What the live reader uses to see that it fell behind: the bytes waiting in the pipe and its capacity."""
    import os

    from rfi_experiments.if_source import bytes_waiting, pipe_capacity
    r, w = os.pipe()
    try:
        capacity = pipe_capacity(r)
        assert capacity is not None and capacity >= 4096
        os.set_blocking(w, False)
        written = 0
        try:
            while True:
                written += os.write(w, bytes(4096))
        except BlockingIOError:
            pass
        assert written == capacity and bytes_waiting(r) == capacity   # a full pipe: the writer is blocked
        os.read(r, 1000)
        assert bytes_waiting(r) == capacity - 1000
    finally:
        os.close(r)
        os.close(w)


@pytest.mark.parametrize('reliability,policy', [('reliable', 'RELIABLE'), ('best_effort', 'BEST_EFFORT')])
def test_reliability_parameter_sets_the_publisher_qos(reliability, policy):
    context = Context()
    rclpy.init(context=context)
    node = None
    try:
        node = IfSourceNode(context=context, parameter_overrides=[
            Parameter('input', value=str(DATA / CASES[1][0])), Parameter('reliability', value=reliability)])
        assert node.pub.qos_profile.reliability.name == policy
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
