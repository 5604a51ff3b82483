"""gnss_correlator_node in process: the real 4 MHz capture as IfSamples blocks in, CorrelatorArrays out;
bad blocks counted, gaps and format changes restart the receiver, nothing crashes."""

from __future__ import annotations

import math
import threading
from dataclasses import replace
from pathlib import Path
from typing import cast

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.context import Context
from rclpy.parameter import Parameter

from gnss_correlator import receiver as receiver_module
from gnss_correlator.correlator_cdr import correlator_array
from gnss_correlator.gnss_correlator_node import GnssCorrelatorNode
from gnss_correlator.node_params import CorrelatorNodeParams
from gnss_correlator.receiver import IfBlock, Receiver
from rfi_msgs.msg import Correlator, CorrelatorArray, IfSamples
from rfi_node_common.qos import DATA_QOS
from rfi_node_common.stamps import NS_PER_S, ns_to_stamp
from rfi_node_common.testing import NodeRig

DATA = Path(__file__).resolve().parent / 'data'
FS = 4e6
BLOCK = 40_000  # 10 ms
T0_NS = 1_700_000_000 * NS_PER_S


class CorrelatorRig(NodeRig):
    def __init__(self, params: dict | None = None) -> None:
        def make(context: Context, overrides: list[Parameter]) -> GnssCorrelatorNode:
            return GnssCorrelatorNode(context=context, parameter_overrides=overrides)
        super().__init__(make, inputs={'/rfi/if_samples': (IfSamples, DATA_QOS)},
                         outputs={'/gnss/correlators': CorrelatorArray, '/diagnostics': DiagnosticArray},
                         params={'spectrum_inverted': True, **(params or {})})
        self.sent = 0

    @property
    def cn(self) -> GnssCorrelatorNode:
        """The node under test, typed."""
        return cast(GnssCorrelatorNode, self.node)

    def send(self, msg: IfSamples) -> None:
        self.pubs['/rfi/if_samples'].publish(msg)
        self.sent += 1
        self.settle_until(lambda: self.cn.counts['blocks_received'] == self.sent)


def block(raw: np.ndarray, first: int, n: int = BLOCK, **fields) -> IfSamples:
    """IfSamples of complex int8 samples [first, first + n) of the capture."""
    m = IfSamples()
    m.header.stamp = ns_to_stamp(T0_NS + round(first / FS * NS_PER_S))
    m.header.frame_id = 'front_end'
    m.sample_rate_hz = FS
    m.intermediate_frequency_hz = 0.0
    m.center_frequency_hz = 1575.42e6
    m.is_complex = True
    m.first_sample_index = first
    m.scale = 1.0
    m.bits_per_sample = 2
    m.sample_format = IfSamples.INT8
    m.samples = raw[2 * first:2 * (first + n)].tobytes()
    for k, v in fields.items():
        setattr(m, k, v)
    return m


@pytest.fixture(scope='module')
def capture() -> np.ndarray:
    return np.fromfile(DATA / 'pocketsdr_L1_4MHz_IQ_150ms.bin', dtype=np.int8)


def test_real_capture_gives_one_array_per_ms_with_the_satellites(capture):
    rig = CorrelatorRig()
    try:
        n_blocks = capture.size // 2 // BLOCK
        for k in range(n_blocks):
            rig.send(block(capture, k * BLOCK))
        rig.spin_until(lambda: not rig.cn.receiver.acquiring and rig.outputs_arrived(), 'the first acquisition')
        arrays = rig.out['/gnss/correlators']
        assert rig.cn.counts['blocks_processed'] == n_blocks
        assert rig.cn.receiver.counts['acquisitions'] == 1
        stamps = np.array([a.header.stamp.sec * NS_PER_S + a.header.stamp.nanosec for a in arrays])
        # one array per 1-ms interval, from the first channel's first C/N0 (50 ms) to the end of the stream
        assert np.all(np.diff(stamps) == 1_000_000)
        assert len(arrays) >= 95 and stamps[-1] == T0_NS + 150 * 1_000_000
        assert {a.header.frame_id for a in arrays} == {'gnss_receiver'}
        last = {c.svid: c for c in arrays[-1].correlators}
        assert {16, 18, 26, 29, 31, 32} <= set(last)
        for a in arrays[-20:]:
            for c in a.correlators:
                if c.svid == 24:  # the acquisition's likely false alarm (tracking shows it: C/N0 < 30)
                    continue
                assert 35.0 < c.cn0_dbhz < 50.0 and abs(c.integration_time_s - 1e-3) < 1e-6
        # unit amplitude: the magnitude of a locked satellite's I/Q is about 1
        mags = [math.hypot(c.in_phase, c.quadrature) for a in arrays[-50:] for c in a.correlators if c.svid == 26]
        assert 0.8 < float(np.median(mags)) < 1.2
        # the NCO's phase change over 1 ms: 2 pi x Doppler x 1 ms (PRN 26 at +648 Hz)
        assert last[26].predicted_phase_change_rad == pytest.approx(2 * np.pi * 648.0e-3, abs=0.02)
        # carrier_lock: UNKNOWN until the lock rule's 100-ms window is full, then HELD for the six satellites and
        # LOST for PRN 24, the likely false alarm (measured: the window is full at 101 ms of the stream)
        assert {c.carrier_lock for a in arrays[:40] for c in a.correlators} == {Correlator.CARRIER_LOCK_UNKNOWN}
        assert {s: c.carrier_lock for s, c in last.items() if s != 24} == dict.fromkeys(
            (16, 18, 26, 29, 31, 32), Correlator.CARRIER_LOCK_HELD)
        assert 24 not in last or last[24].carrier_lock == Correlator.CARRIER_LOCK_LOST
        rig.spin_until(lambda: len(rig.out['/diagnostics']) >= 1, 'diagnostics')
        status = rig.out['/diagnostics'][-1].status[0]
        assert status.name == 'gnss_correlator' and status.level == DiagnosticStatus.OK, status.message
    finally:
        rig.close()


def test_bad_blocks_are_counted_and_gaps_restart(capture):
    rig = CorrelatorRig({'acquisition_ms': 2})
    try:
        rig.send(block(capture, 0, sample_format=7))
        rig.send(block(capture, 0, sample_rate_hz=1.0e6))
        blank = block(capture, 0)
        blank.samples = bytes(len(blank.samples))
        rig.send(blank)
        rig.send(block(capture, 0, bits_per_sample=1))  # values +-3 do not fit 1 bit
        rig.send(block(capture, 0, intermediate_frequency_hz=1.998e6))  # IF + 5 kHz beyond fs / 2
        rig.send(block(capture, 0, n=1001))
        rig.send(block(capture, 0, n=1001))  # same stamp again
        c = rig.cn.counts
        assert c['rejected_unknown_sample_format'] == 1 and c['rejected_rate_below_2mhz'] == 1
        assert c['rejected_blank_block'] == 1 and c['rejected_values_exceed_bits'] == 1
        assert c['rejected_band_outside_nyquist'] == 1 and c['rejected_stamp_not_increasing'] == 1
        rig.send(block(capture, 1001, n=BLOCK))
        rig.send(block(capture, 1001 + BLOCK + 500, n=BLOCK))  # 500 samples missing
        assert rig.cn.receiver.counts['restarts_gap'] == 1
        m = block(capture, 100_000, n=BLOCK)
        m.is_complex = False  # the same bytes as 80 000 real samples: a format change
        m.intermediate_frequency_hz = 1.0e6
        rig.send(m)
        assert rig.cn.receiver.counts['restarts_format'] == 1
        assert c['blocks_processed'] == 4 and c['core_errors'] == 0
    finally:
        rig.close()


def test_settable_diagnostics_parameters_are_applied_between_blocks(capture):
    """hardware_id and diagnostics_window_s are declared settable (the shared NodeDiagnosticsParams): a change is
    applied before the next block, not accepted and ignored; a read-only one (the stamp gate's) is refused."""
    rig = CorrelatorRig({'acquisition_ms': 2})
    try:
        rig.send(block(capture, 0, n=2000))
        ok = rig.cn.set_parameters([Parameter('hardware_id', value='rx_42'),
                                    Parameter('diagnostics_window_s', value=3.0)])
        assert all(r.successful for r in ok)
        refused = rig.cn.set_parameters([Parameter('max_stamp_jump_s', value=1.0)])
        assert not refused[0].successful
        rig.send(block(capture, 2000, n=2000))
        assert rig.cn.params.hardware_id == 'rx_42' and rig.cn.params.diagnostics_window_s == 3.0
        assert rig.cn._window.window_ns == 3 * NS_PER_S and rig.cn.params.max_stamp_jump_s == 120.0
    finally:
        rig.close()


def _core_intervals_and_held_search(capture, monkeypatch):
    """(block length, blocks, the core's intervals for the capture in 1-ms blocks with the search in the caller's
    thread, an Event): the node's first search made to wait until the test sets the Event."""
    n = BLOCK // 2
    n_blocks = capture.size // 2 // n
    counts = capture[:2 * n * n_blocks].astype(np.float64)
    x = counts[0::2] + 1j * counts[1::2]
    core = Receiver(replace(CorrelatorNodeParams(spectrum_inverted=True).receiver(), acquisition_hold_s=0.0))
    expected = []
    for k in range(0, n_blocks, 2):  # the node's batch_ms: 10 ms
        expected += core.process(IfBlock(T0_NS + round(k * n / FS * NS_PER_S), FS, 0.0, True, k * n,
                                         x[k * n:(k + 2) * n]))
    core.close()
    release = threading.Event()
    original = receiver_module.acquire

    def held(*args, **kwargs):
        assert release.wait(timeout=120), 'the test never released the search'
        return original(*args, **kwargs)

    monkeypatch.setattr(receiver_module, 'acquire', held)
    return n, n_blocks, expected, release


def test_replay_equals_the_core_while_the_first_acquisition_runs_in_the_worker(capture, monkeypatch):
    """Blocks replayed into the node (5 ms each, gathered to 10 ms) while its first acquisition runs in the worker
    thread, held there until every block has been taken: the node takes them all meanwhile, and its arrays are,
    value for value, those of the core run in this process on the same blocks with the search in the caller's
    thread (the synchronous path)."""
    n, n_blocks, expected, release = _core_intervals_and_held_search(capture, monkeypatch)
    rig = CorrelatorRig()
    try:
        for k in range(n_blocks):
            rig.send(block(capture, k * n, n=n))
        assert rig.cn.receiver.acquiring and rig.out['/gnss/correlators'] == []
        assert rig.cn.counts['blocks_received'] == n_blocks and rig.cn.receiver.blocks_held > 0
        release.set()
        rig.spin_until(lambda: not rig.cn.receiver.acquiring and not rig.cn._pending and rig.outputs_arrived(),
                       'the blocks held')
        got = rig.out['/gnss/correlators']
        assert len(expected) >= 95 and got == [correlator_array(iv, 'gnss_receiver') for iv in expected]
        assert rig.cn.counts['blocks_processed'] == n_blocks and rig.cn._values()['accounting_ok']
    finally:
        release.set()
        rig.close()


def test_after_the_search_the_input_is_taken_before_the_held_blocks_are_answered(capture, monkeypatch):
    """Once the first search is done, blocks handed in are held, not answered (the receiver's replay_per_block 0),
    and each replay callback first takes every block waiting in the subscription (blocks_taken_before_replay), then
    answers REPLAY_BLOCKS_PER_CALLBACK held ones: the replay no longer starves the input (one message taken per
    executor turn against 100 ms of stream replayed lost 1-ms blocks, docs/gnss_correlator/live_stream.md). The
    arrays are those of the core with the search in the caller's thread."""
    n, n_blocks, expected, release = _core_intervals_and_held_search(capture, monkeypatch)
    rig = CorrelatorRig()
    try:
        first = 6
        for k in range(first):
            rig.send(block(capture, k * n, n=n))
        release.set()
        assert rig.cn.receiver._first is not None
        rig.cn.receiver._first.future.result(timeout=120)  # done; its guard condition not served yet
        before = rig.cn.receiver.blocks_held
        for k in range(first, first + 4):  # handed in directly, as the executor would: held, none answered
            rig.cn.on_raw_block(block(capture, k * n, n=n))
        assert rig.cn.receiver.blocks_held == before + 2 and rig.cn.counts['arrays_published'] == 0
        events: list[tuple[str, int]] = []
        take, poll = rig.cn.subscription.take_pending, rig.cn.receiver.poll

        def spy_take(*args, **kwargs) -> int:
            taken = take(*args, **kwargs)
            if 'limit' not in kwargs:  # the replay's take (the one after each block has a limit: DRAIN_BLOCKS)
                events.append(('take', taken))
            return taken

        def spy_poll(*args, **kwargs):
            events.append(('poll', kwargs['max_blocks']))
            return poll(*args, **kwargs)

        monkeypatch.setattr(rig.cn.subscription, 'take_pending', spy_take)
        monkeypatch.setattr(rig.cn.receiver, 'poll', spy_poll)
        for k in range(first + 4, n_blocks):  # the rest published at once, served with the replay
            rig.pubs['/rfi/if_samples'].publish(block(capture, k * n, n=n))
        rig.spin_until(lambda: rig.cn.counts['blocks_received'] == n_blocks and not rig.cn.receiver.acquiring
                       and not rig.cn._pending and rig.outputs_arrived(), 'the blocks held')
        assert events and all(e == 'take' for e, _ in events[0::2]) and all(e == 'poll' for e, _ in events[1::2])
        assert all(v == 10 for e, v in events if e == 'poll')
        assert rig.cn.counts['blocks_taken_before_replay'] == sum(v for e, v in events if e == 'take')
        assert rig.cn.counts['blocks_processed'] == n_blocks and rig.cn.counts['core_errors'] == 0
        got = rig.out['/gnss/correlators']
        assert len(expected) >= 95 and got == [correlator_array(iv, 'gnss_receiver') for iv in expected]
    finally:
        release.set()
        rig.close()
