"""The receiver core on simulated IF (rfi_sim truth): the 1-ms output grid, imm_carrier's convention (the angle of
I + jQ is the carrier's Doppler phase, the predicted change the NCO's), the I/Q scalings, restarts."""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest

from gnss_correlator import receiver as receiver_module
from gnss_correlator.receiver import CorrelatorInterval, IfBlock, Receiver, ReceiverConfig
from rfi_sim.if_signal import FrontEndConfig, GpsSatellite, IfSimulator

FS = 4e6
T0_NS = 1_800_000_000 * 1_000_000_000
SATS = (GpsSatellite(prn=7, doppler_hz=1234.0, code_phase_chips=300.2, carrier_phase_rad=0.4, power_dbm=-127.0),
        GpsSatellite(prn=21, doppler_hz=-2210.0, code_phase_chips=12.7, carrier_phase_rad=2.0, power_dbm=-127.0))
CN0_DBHZ = -127.0 + 174.0  # the front end's -114 dBm/MHz noise density


@pytest.fixture(scope='module')
def samples() -> np.ndarray:
    fe = FrontEndConfig(sample_rate_hz=FS, intermediate_frequency_hz=0.0, is_complex=True, bits=4)
    v = IfSimulator(fe, satellites=SATS, seed=11).generate(int(FS * 0.4)).counts.astype(np.float64)
    return v[0::2] + 1j * v[1::2]


def run(x: np.ndarray, config: ReceiverConfig, block: int = 28_001) -> tuple[Receiver, list[CorrelatorInterval]]:
    rx = Receiver(config)
    out: list[CorrelatorInterval] = []
    for i in range(0, x.size, block):
        out += rx.process(IfBlock(T0_NS + round(i / FS * 1e9), FS, 0.0, True, i, x[i:i + block]))
    out += rx.poll(wait=True)  # the end of the stream: the blocks held for a first acquisition still running
    return rx, out


def per_prn(out: list[CorrelatorInterval], prn: int) -> dict[str, np.ndarray]:
    rows = [(iv.stamp_ns, iv.in_phase[k], iv.quadrature[k], iv.predicted_phase_change_rad[k], iv.cn0_dbhz[k])
            for iv in out for k in np.flatnonzero(iv.svid == prn)]
    a = np.array(rows)
    return {'t': (a[:, 0] - T0_NS) / 1e9, 'iq': a[:, 1] + 1j * a[:, 2], 'dphi': a[:, 3], 'cn0': a[:, 4]}


def test_grid_convention_and_unit_amplitude(samples):
    rx, out = run(samples, ReceiverConfig(prns=(3, 7, 21)))
    assert set(rx.tracked_prns) == {7, 21} and rx.counts['acquisitions'] == 1
    stamps = np.array([iv.stamp_ns for iv in out])
    assert np.all((stamps - T0_NS) % 1_000_000 == 0) and np.all(np.diff(stamps) == 1_000_000)
    assert all(len(set(iv.svid.tolist())) == iv.svid.size for iv in out)  # one correlator per channel per array
    for sat in SATS:
        r = per_prn(out, sat.prn)
        settled = r['t'] > 0.2
        # the predicted change is the NCO's: 2 pi f_d T with the tracked Doppler, close to the truth
        assert np.median(r['dphi'][settled]) == pytest.approx(2 * np.pi * sat.doppler_hz * 1e-3, abs=0.01)
        # the angle of I + jQ is the carrier's Doppler phase (modulo pi, the data bit), up to a constant: the
        # period ends up to 1 ms before the stamp, at an offset that drifts by < 1 us over the run
        d = np.angle(r['iq'][settled]) - 2 * np.pi * sat.doppler_hz * r['t'][settled]
        z = np.exp(2j * d)
        d = np.angle(z * np.conj(np.mean(z))) / 2
        sigma = 1.0 / math.sqrt(2 * 1e-3 * 10 ** (CN0_DBHZ / 10))  # the prompt's phase noise, rad
        assert np.sqrt(np.mean(d ** 2)) < 1.5 * sigma + 0.03
        # unit amplitude: |I + jQ| about 1 (noise std sigma per component around it)
        assert np.median(np.abs(r['iq'][settled])) == pytest.approx(1.0, abs=0.1)
        assert np.median(r['cn0'][settled]) == pytest.approx(CN0_DBHZ, abs=1.5)


def test_unit_noise_scaling(samples):
    _, out = run(samples, ReceiverConfig(prns=(7,), iq_scaling='unit_noise'))
    r = per_prn(out, 7)
    settled = r['t'] > 0.2
    # the NCO's accumulated phase removed (imm_carrier's residual), the signal sits on one axis (+- the bits)
    iq = (r['iq'] * np.exp(-1j * np.cumsum(r['dphi'])))[settled]
    # the component across that axis is noise of std 1
    z = iq ** 2
    axis = np.angle(np.mean(z)) / 2
    across = (iq * np.exp(-1j * axis)).imag
    assert np.std(across) == pytest.approx(1.0, abs=0.15)
    amp = math.sqrt(2 * 1e-3 * 10 ** (CN0_DBHZ / 10))
    assert np.median(np.abs(iq)) == pytest.approx(amp, rel=0.15)


def test_gap_and_format_change_restart(samples):
    rx = Receiver(ReceiverConfig(prns=(7, 21), acquisition_ms=4, acquisition_hold_s=0.0))  # synchronous
    n = 40_000
    assert rx.process(IfBlock(T0_NS, FS, 0.0, True, 0, samples[:n])) == []
    assert set(rx.tracked_prns) == {7, 21}
    rx.process(IfBlock(T0_NS + 10_000_000, FS, 0.0, True, n, samples[n:2 * n]))
    rx.process(IfBlock(T0_NS + 20_250_000, FS, 0.0, True, 2 * n + 1000, samples[2 * n + 1000:3 * n]))
    assert rx.counts['restarts_gap'] == 1
    rx.process(IfBlock(T0_NS + 30_000_000, FS, 1.0e6, False, 3 * n, samples[3 * n:4 * n].real.copy()))
    assert rx.counts['restarts_format'] == 1 and rx.tracked_prns == ()
    with pytest.raises(ValueError, match='complex iff'):
        rx.process(IfBlock(T0_NS + 40_000_000, FS, 1.0e6, False, 4 * n, samples[4 * n:5 * n]))
    with pytest.raises(ValueError, match='iq_scaling'):
        ReceiverConfig(iq_scaling='volts')


def test_reacquisition_runs_in_the_worker_and_outputs_do_not_depend_on_it(samples, monkeypatch):
    """A channel lost (dropped here by hand) is found again by the periodic search, which runs in the worker
    thread and starts its channel at the block the lag says: two runs give the same outputs."""
    threads: list[str] = []
    original = receiver_module.acquire

    def recording_acquire(*args, **kwargs):
        threads.append(threading.current_thread().name)
        return original(*args, **kwargs)

    monkeypatch.setattr(receiver_module, 'acquire', recording_acquire)
    config = ReceiverConfig(prns=(7, 21), acquisition_ms=4, reacquisition_period_s=0.05, reacquisition_lag_s=0.02,
                            acquisition_hold_s=0.0)  # the first acquisition synchronous (its own test below)
    runs = []
    for _ in range(2):
        rx = Receiver(config)
        out: list[CorrelatorInterval] = []
        started_at = None
        block = 20_000
        for i in range(0, samples.size, block):
            out += rx.process(IfBlock(T0_NS + round(i / FS * 1e9), FS, 0.0, True, i, samples[i:i + block]))
            if i == 2 * block:
                assert rx.tracker is not None
                rx.tracker.drop_channel(21)
            if started_at is None and i > 2 * block and 21 in rx.tracked_prns:
                started_at = i
        rx.close()
        assert 21 in rx.tracked_prns and rx.counts['channels_started'] == 3
        # searched on the 4 ms before the period's end, started 20 ms of stream later, at a block boundary
        assert started_at is not None and started_at / FS >= 0.05 + 0.02
        runs.append((started_at, [(iv.stamp_ns, iv.svid.tolist(), iv.in_phase.tolist()) for iv in out]))
    assert runs[0] == runs[1]
    # per run: the first acquisition in the caller's thread, the reacquisitions in the worker
    assert threads.count('MainThread') == 2 and len(threads) > 2
    assert all(t.startswith('gnss_correlator_acquisition') for t in threads if t != 'MainThread')


def test_20ms_correlators_after_bit_sync():
    """``coherent_ms`` 20 on 0.8 s of simulated IF: each satellite is bit-synchronised, then published once per data
    bit (T = 20 code periods, stamps 20 ms apart), each bit's correlator ending on a true bit edge (the period
    whose end the simulator's code phase puts at a multiple of 20 x 1023 chips) within the 1 ms of its stamp; the
    predicted change is 2 pi f_d x 20 ms; unit amplitude (median |I + jQ| 1 +- 0.1); and the angle of I + jQ minus
    the true Doppler phase is constant modulo pi to within the 20-ms prompt's phase noise (1 / sqrt(2 T C/N0),
    0.03 rad here) plus the PLL's jitter inside the bit (bound 0.1 rad rms)."""
    fe = FrontEndConfig(sample_rate_hz=FS, intermediate_frequency_hz=0.0, is_complex=True, bits=4)
    v = IfSimulator(fe, satellites=SATS, seed=11).generate(int(FS * 0.8)).counts.astype(np.float64)
    rx, out = run(v[0::2] + 1j * v[1::2], ReceiverConfig(prns=(3, 7, 21), coherent_ms=20))
    assert rx.counts['bit_syncs'] == 2 and rx.counts['correlators_20ms'] > 0
    for sat in SATS:
        rows = [(iv.stamp_ns, iv.in_phase[k], iv.quadrature[k], iv.predicted_phase_change_rad[k],
                 iv.integration_time_s[k]) for iv in out for k in np.flatnonzero(iv.svid == sat.prn)]
        a = np.array(rows)
        long = a[:, 4] > 0.015
        assert np.count_nonzero(long) >= 10, sat.prn
        first = np.flatnonzero(long)[0]
        assert np.all(long[first:]), 'once synchronised, every correlator spans a bit'
        t = (a[long, 0] - T0_NS) / 1e9
        assert np.allclose(np.diff(t), 0.02, atol=2e-6)
        assert np.allclose(a[long, 4], 0.02, atol=2e-5)
        # each bit's end: the true code phase (chips since a bit edge) at the stamp is 0 to 1 ms past an edge
        chip_rate = 1.023e6 * (1.0 + sat.doppler_hz / 1575.42e6)
        past = (sat.code_phase_chips + chip_rate * t) % (20 * 1023) / chip_rate
        assert np.all(past < 1e-3 + 1e-6), past
        assert np.median(a[long, 3]) == pytest.approx(2 * np.pi * sat.doppler_hz * 0.02, abs=0.2)
        iq = a[long, 1] + 1j * a[long, 2]
        assert np.median(np.abs(iq)) == pytest.approx(1.0, abs=0.1)
        d = np.angle(iq) - 2 * np.pi * sat.doppler_hz * t
        z = np.exp(2j * d)
        d = np.angle(z * np.conj(np.mean(z))) / 2
        assert np.sqrt(np.mean(d ** 2)) < 0.1, np.sqrt(np.mean(d ** 2))


def table(out: list[CorrelatorInterval]) -> list[tuple]:
    """Every value of every interval, for exact comparison (NaN compared as a string)."""
    return [(iv.stamp_ns, iv.svid.tolist(), *(str(getattr(iv, f).tolist()) for f in (
        'in_phase', 'quadrature', 'cn0_dbhz', 'predicted_phase_change_rad', 'integration_time_s', 'locked',
        'phase_error_std_rad', 'half_cycle_wraps', 'pll_error_rad', 'cn0_m2m4_dbhz'))) for iv in out]


class HeldSearch:
    """``acquire`` replaced: the search runs only once ``release`` is set (so blocks are held meanwhile, whatever
    the machine's speed), and the threads it ran in are recorded."""

    def __init__(self, monkeypatch) -> None:
        self.release = threading.Event()
        self.threads: list[str] = []
        original = receiver_module.acquire

        def held(*args, **kwargs):
            self.threads.append(threading.current_thread().name)
            assert self.release.wait(timeout=60), 'the test never released the search'
            return original(*args, **kwargs)

        monkeypatch.setattr(receiver_module, 'acquire', held)


def test_first_acquisition_in_the_worker_holds_blocks_and_gives_the_synchronous_outputs(samples, monkeypatch):
    """While the first search runs in the worker, the blocks are taken and held (none answered); once it is done
    (the worker's notification), poll answers a few and the blocks handed in after it two each: the same
    intervals, value for value, as the search in the caller's thread."""
    _, sync = run(samples, ReceiverConfig(prns=(3, 7, 21), acquisition_ms=4, acquisition_hold_s=0.0), block=10_000)
    search = HeldSearch(monkeypatch)
    notified = threading.Event()
    rx = Receiver(ReceiverConfig(prns=(3, 7, 21), acquisition_ms=4), on_search_done=notified.set)
    out: list[CorrelatorInterval] = []
    block = 10_000
    for i in range(0, samples.size, block):
        out += rx.process(IfBlock(T0_NS + round(i / FS * 1e9), FS, 0.0, True, i, samples[i:i + block]))
        if i == 20 * block:
            # the 4-ms window was full at the second block (searched from there), the 19 blocks since are held
            assert rx.acquiring and out == [] and rx.tracked_prns == ()
            assert rx.blocks_held == 19 and rx.counts['blocks_held'] == 19
            search.release.set()
            assert notified.wait(timeout=60) and rx.poll_ready
            out += rx.poll(max_blocks=5)  # the window and 5 held blocks answered
            assert rx.acquiring and rx.blocks_held == 14 and set(rx.tracked_prns) == {7, 21}
        elif i > 20 * block:  # each block handed in now answers two held ones, in their order
            assert rx.blocks_held == max(14 - (i // block - 20), 0)
    out += rx.poll(wait=True)
    assert not rx.acquiring
    rx.close()
    assert rx.counts['acquisition_waits'] == 0 and rx.counts['acquisitions'] == 1
    assert search.threads == ['gnss_correlator_acquisition_0']
    assert len(out) > 300 and table(out) == table(sync)


def test_a_full_hold_waits_for_the_search_and_a_gap_drops_it(samples, monkeypatch):
    """Held blocks are bounded: at acquisition_hold_s of stream the caller waits for the search (counted) and two
    held blocks are answered (one more than came in, not the whole hold at once), with the synchronous outputs
    still; a gap while searching restarts the stream and drops what was held."""
    block = 10_000
    _, sync = run(samples[:12 * block], ReceiverConfig(prns=(7, 21), acquisition_ms=4, acquisition_hold_s=0.0),
                  block=block)
    search = HeldSearch(monkeypatch)
    rx = Receiver(ReceiverConfig(prns=(7, 21), acquisition_ms=4, acquisition_hold_s=0.02))  # 8 blocks

    def release_once_waiting() -> None:
        for _ in range(60_000):
            if rx.counts['acquisition_waits']:
                break
            time.sleep(0.001)
        search.release.set()

    helper = threading.Thread(target=release_once_waiting, daemon=True)
    helper.start()
    out: list[CorrelatorInterval] = []
    for i in range(0, 12 * block, block):
        out += rx.process(IfBlock(T0_NS + round(i / FS * 1e9), FS, 0.0, True, i, samples[i:i + block]))
        if i == 8 * block:
            assert rx.acquiring and rx.blocks_held == 7 and out == []
    helper.join(timeout=60)
    search.release.set()
    # blocks 2-9 held, the bound at block 9: the wait, blocks 2 and 3 answered; blocks 10 and 11 two each
    assert rx.counts['acquisition_waits'] == 1 and rx.counts['hold_bound_replays'] == 0
    assert rx.counts['blocks_held'] == 10 and rx.acquiring and rx.blocks_held == 4
    out += rx.poll(wait=True)
    assert not rx.acquiring and table(out) == table(sync)
    rx.close()

    search.release.clear()
    rx = Receiver(ReceiverConfig(prns=(7, 21), acquisition_ms=4))
    for i in (0, block, 2 * block, 3 * block + 500):  # the last one after a gap of 500 samples
        assert rx.process(IfBlock(T0_NS + round(i / FS * 1e9), FS, 0.0, True, i, samples[i:i + block])) == []
        if i == 2 * block:
            assert rx.acquiring and rx.blocks_held == 1
    assert rx.counts['restarts_gap'] == 1 and not rx.acquiring and rx.blocks_held == 0
    search.release.set()
    assert rx.poll(wait=True) == []
    rx.close()


def test_without_replay_per_block_the_hold_is_answered_by_poll_and_stays_bounded(samples, monkeypatch):
    """The node's mode (replay_per_block 0): once the search is done, blocks handed in are held, not answered
    (the caller takes its input first and polls when it has time); at the bound each block handed in answers two
    held ones (hold_bound_replays), so the hold never exceeds it; poll in slices gives the synchronous outputs."""
    block = 10_000
    n_blocks = 40  # 400 ms: past the first C/N0 window, so there are correlators to compare
    _, sync = run(samples[:n_blocks * block], ReceiverConfig(prns=(7, 21), acquisition_ms=4,
                                                             acquisition_hold_s=0.0), block=block)
    search = HeldSearch(monkeypatch)
    notified = threading.Event()
    bound = 8  # blocks of 10,000 samples in acquisition_hold_s 0.02 at 4 MS/s
    rx = Receiver(ReceiverConfig(prns=(7, 21), acquisition_ms=4, acquisition_hold_s=0.02),
                  on_search_done=notified.set, replay_per_block=0)
    out: list[CorrelatorInterval] = []
    held = []
    for k in range(n_blocks):
        i = k * block
        out += rx.process(IfBlock(T0_NS + round(i / FS * 1e9), FS, 0.0, True, i, samples[i:i + block]))
        held.append(rx.blocks_held)
        if k == 1:  # the window is full: the search runs; let it end at once
            search.release.set()
            assert notified.wait(timeout=60)
    # done from block 2 on, yet nothing answered until the bound (block 9); then 8 -> 6, 7, 8 -> 6, ...
    assert held == ([0, 0, 1, 2, 3, 4, 5, 6, 7] + [6, 7] * n_blocks)[:n_blocks] and max(held) < bound
    assert rx.counts['acquisition_waits'] == 0 and rx.counts['hold_bound_replays'] == held[9:].count(6)
    assert rx.counts['blocks_held'] == n_blocks - 2
    assert set(rx.tracked_prns) == {7, 21} and rx.acquiring and rx.poll_ready  # started at the bound
    out += rx.poll(max_blocks=4)
    assert rx.blocks_held == held[-1] - 4
    out += rx.poll(max_blocks=4)
    assert not rx.acquiring and not rx.poll_ready and rx.poll() == []
    assert len(sync) > 20 and table(out) == table(sync)
    rx.close()
    with pytest.raises(ValueError, match='replay_per_block'):
        Receiver(ReceiverConfig(), replay_per_block=-1)
