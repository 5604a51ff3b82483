"""warm_up compiles every compiled function the first blocks of a stream use: on a fresh install (or after an edit:
docs/numba_cache.md) a kernel compiled on a live block costs seconds of CPU there (a second version of
_noise_levels_kernel once cost the 38.192 MS/s switch-on block 1.1-1.6 s). Checked in a fresh interpreter with an
empty numba cache: after warm_up, streams of several front ends (noise, a chirp switched on, a CW; 8-bit and 2-bit,
real and complex) must compile nothing (numba's "numba:compile" events; loading from a warm cache is not one)."""

from __future__ import annotations

import json
import os
import sys

from rfi_node_common import testing

SCRIPT = r'''
import json
from numba.core import event
from rfi_monitor.monitor import RfiMonitor, RfiMonitorParams
from rfi_monitor.warm_up import warm_up
from rfi_sim.if_signal import ChirpJammer, CwJammer, FrontEndConfig, IfSimulator

params = RfiMonitorParams()
warm_up(params)
new = {}
for fs, fif, cplx, bits in ((38.192e6, 9.548e6, False, 8), (10e6, 0.0, True, 8), (4e6, 0.0, True, 2)):
    fe = FrontEndConfig(sample_rate_hz=fs, intermediate_frequency_hz=fif, is_complex=cplx, bits=bits)
    half = fs / 2 if not cplx else fs
    chirp = ChirpJammer(start_frequency_hz=-0.3 * half, sweep_rate_hz_per_s=0.4 * half / 10e-6, sweep_period_s=10e-6,
                        js_db=40.0)
    cw = CwJammer(frequency_hz=0.1 * half, js_db=40.0)
    mon, blk, k = RfiMonitor(params), int(fs * 1e-3), 0
    with event.install_recorder('numba:compile') as compiles:
        for jammers, blocks, seed in (((), 12, 1), ((chirp,), 20, 2), ((cw,), 8, 3)):
            sim = IfSimulator(fe, jammers, seed=seed)
            for _ in range(blocks):
                mon.process(sim.generate(blk).counts, fs, fif, k * blk, k * 1_000_000, is_complex=cplx,
                            full_scale=float(2 ** (bits - 1)) if bits > 3 else None, bits=bits)
                k += 1
    for _, ev in compiles.buffer:
        if ev.is_start:
            f = ev.data['dispatcher'].py_func
            new.setdefault(f.__module__ + '.' + f.__qualname__, []).append(
                f'{fs / 1e6:g} MS/s {"complex" if cplx else "real"} {bits}-bit')
print(json.dumps(new))
'''


def test_the_first_blocks_compile_nothing_after_warm_up(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / 'numba_cache'))     # empty: every kernel compiles
    done = testing.run_process([sys.executable, '-c', SCRIPT], 'the warm-up check did not end', text=True, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    new = json.loads(done.stdout.strip().splitlines()[-1])
    assert new == {}, f'compiled after warm_up (function: front ends whose blocks compiled it): {new}'
