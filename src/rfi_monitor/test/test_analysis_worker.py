"""The ridge analysis on a second core (analysis_worker): the same results as in the calling process, and a worker
that fails changes nothing but speed.

Exact comparisons: the child is the same interpreter and libraries on the same machine as this process."""

import dataclasses
import math

import numpy as np
import pytest

from rfi_monitor import ridge as rg
from rfi_monitor.analysis_worker import AnalysisWorker
from rfi_monitor.monitor import RfiMonitor, RfiMonitorParams
from rfi_sim.if_signal import ChirpJammer, CwJammer, FrontEndConfig, IfSimulator

FE = FrontEndConfig(noise_bandwidth_hz=2e6)
BLOCK = int(round(FE.sample_rate_hz * 1e-3))


@pytest.fixture(scope="module")
def worker():
    w = AnalysisWorker()
    yield w
    w.close()


def _same(a, b) -> bool:
    """Two dataclasses equal field by field (NaN equal to NaN)."""
    for f in dataclasses.fields(a):
        va, vb = getattr(a, f.name), getattr(b, f.name)
        if isinstance(va, float) and math.isnan(va):
            if not (isinstance(vb, float) and math.isnan(vb)):
                return False
        elif va != vb:
            return False
    return True


def test_worker_gives_the_local_ridge_analysis_to_the_bit(worker):
    rng = np.random.default_rng(11)
    t = np.arange(BLOCK)
    chirp = 3.0 * np.cos(2 * np.pi * (0.1 * t + 2e-6 * (t % 2000) ** 2))
    z = rng.standard_normal(8192) + 1j * rng.standard_normal(8192)
    cases = [(rng.standard_normal(BLOCK), False, 128), (rng.standard_normal(BLOCK) + chirp, False, 64),
             ((rng.standard_normal(BLOCK) + chirp)[-16384:], False, 32), (z, True, 64)]
    par = rg.RidgeParams()
    for x, cplx, L in cases:
        assert worker.submit(x, cplx, FE.sample_rate_hz, par, L)
        got = worker.collect()
        assert got is not None
        assert _same(got, rg.analyse(x, cplx, FE.sample_rate_hz, par, L))
    assert worker.jobs == len(cases) and worker.failures == 0


def test_worker_chooses_the_frame_length_and_takes_the_tail_as_the_monitor_does(worker):
    rng = np.random.default_rng(14)
    t = np.arange(BLOCK)
    x = rng.standard_normal(BLOCK) + 3.0 * np.cos(2 * np.pi * (0.1 * t + 2e-6 * (t % 2000) ** 2))
    par = rg.RidgeParams()
    L = rg.choose_frame_length(x, False, par)
    for tail in (0, 16384):
        assert worker.submit(x, False, FE.sample_rate_hz, par, 0, tail)
        got = worker.collect()
        assert got is not None and got.frame_length == L
        assert _same(got, rg.analyse(x[-tail:] if tail else x, False, FE.sample_rate_hz, par, L))


def test_changed_parameters_reach_the_worker(worker):
    x = np.random.default_rng(15).standard_normal(BLOCK)
    for par in (rg.RidgeParams(presence_nats=3.0, detect_sigma=5.0), rg.RidgeParams()):
        assert worker.submit(x, False, FE.sample_rate_hz, par, 64)
        got = worker.collect()
        assert got is not None and _same(got, rg.analyse(x, False, FE.sample_rate_hz, par, 64))
    a = rg.analyse(x, False, FE.sample_rate_hz, rg.RidgeParams(presence_nats=3.0, detect_sigma=5.0), 64)
    assert not _same(a, rg.analyse(x, False, FE.sample_rate_hz, rg.RidgeParams(), 64))   # the change matters


def test_cancel_keeps_answers_in_order(worker):
    rng = np.random.default_rng(12)
    par = rg.RidgeParams()
    a, b = rng.standard_normal(BLOCK), rng.standard_normal(BLOCK) * 2.0
    assert worker.submit(a, False, FE.sample_rate_hz, par, 128)
    assert not worker.submit(b, False, FE.sample_rate_hz, par, 128)      # one block at a time
    worker.cancel()
    assert worker.submit(b, False, FE.sample_rate_hz, par, 128)
    got = worker.collect()
    assert got is not None and _same(got, rg.analyse(b, False, FE.sample_rate_hz, par, 128))
    assert worker.collect() is None                                       # nothing pending


def test_a_larger_block_grows_the_shared_file(worker):
    x = np.random.default_rng(13).standard_normal(300_000)               # 2.4 MB > the first 1 MiB
    par = rg.RidgeParams()
    assert worker.submit(x, False, FE.sample_rate_hz, par, 128)
    got = worker.collect()
    assert got is not None and _same(got, rg.analyse(x, False, FE.sample_rate_hz, par, 128))


def _stream(jammers, n_blocks, seed):
    sim = IfSimulator(FE, jammers, seed=seed)
    out = []
    for _ in range(n_blocks):
        blk = sim.generate(BLOCK)
        out.append(np.clip(np.round(blk.values() / blk.scale), -127, 127) * blk.scale)
    return out


def _run(blocks, worker=None):
    mon = RfiMonitor(RfiMonitorParams(), worker=worker)
    return [mon.process(x, FE.sample_rate_hz, FE.intermediate_frequency_hz, k * BLOCK, 10**9 + k * 10**6,
                        full_scale=127.0) for k, x in enumerate(blocks)], mon


@pytest.mark.parametrize("jammers", [(), (ChirpJammer(js_db=40.0),), (CwJammer(js_db=40.0),)],
                         ids=["noise", "chirp", "cw"])
def test_monitor_estimates_do_not_depend_on_the_worker(worker, jammers):
    blocks = _stream(jammers, 40, seed=5)
    local, _ = _run(blocks)
    before = worker.jobs
    remote, mon = _run(blocks, worker)
    assert worker.jobs > before + 20                # most blocks were analysed on the worker
    for a, b in zip(local, remote, strict=True):
        assert (a.type, a.sweep_shape, a.noise_reference) == (b.type, b.sweep_shape, b.noise_reference)
        for f in ("jammer_to_noise_db", "frequency_hz", "frequency_std_hz", "sweep_rate_hz_per_s", "sweep_period_s",
                  "sweep_bandwidth_hz", "in_band_fraction"):
            va, vb = getattr(a, f), getattr(b, f)
            assert (math.isnan(va) and math.isnan(vb)) or va == vb, f
    assert remote[-1].counters["worker_blocks"] == worker.jobs - before


def test_a_dead_worker_is_counted_and_the_block_analysed_here():
    blocks = _stream((ChirpJammer(js_db=40.0),), 12, seed=6)
    local, _ = _run(blocks)
    w = AnalysisWorker(reply_timeout_s=2.0)
    try:
        mon = RfiMonitor(RfiMonitorParams(), worker=w)
        out = []
        for k, x in enumerate(blocks):
            if k == 6:
                w._proc.kill()                       # the child dies between blocks
                w._proc.wait(5.0)
            out.append(mon.process(x, FE.sample_rate_hz, FE.intermediate_frequency_hz, k * BLOCK,
                                   10**9 + k * 10**6, full_scale=127.0))
        assert w.failures == 1 and not w.alive
        assert out[-1].counters["worker_failures"] == 1
        assert [e.type for e in out] == [e.type for e in local]
        assert all((math.isnan(a.frequency_hz) and math.isnan(b.frequency_hz)) or a.frequency_hz == b.frequency_hz
                   for a, b in zip(local, out, strict=True))
    finally:
        w.close()


def test_close_is_idempotent_and_the_shared_file_leaves_no_name_behind():
    import os
    w = AnalysisWorker()
    assert not os.path.exists(w._path)           # unlinked once the child has it open (a killed node leaks nothing)
    w.close()
    w.close()
    assert not w.alive
    assert not w.submit(np.zeros(BLOCK), False, FE.sample_rate_hz, rg.RidgeParams(), 128)
