"""Where a block's full analysis spends its time, stage by stage (issue 26 item 2), against a bare STFT.

Run as a child process by ``rfi_monitor_speed.py`` (one per version of the rfi_monitor package, so that each is
imported on its own): ``python rfi_monitor_stages.py CASE N_BLOCKS`` prints one JSON line. CASE is
``<front end>:<phase>``: front ends ``real38`` (38.192 MS/s 8-bit real, IF 9.548 MHz, Kang et al.'s),
``cplx10`` (10 MS/s complex 8-bit), ``real24`` (24 MS/s real 8-bit, IF 6 MHz); phases ``acquisition`` (noise
only), ``tracking`` (the paper's saw-tooth chirp, 1e12 Hz/s, at J/S 40 dB with the noise counted over 2 MHz:
J/N 21 dB, from the first block) and ``switch`` (noise, then the chirp switched on half way).

The monitor is fed as the node feeds it (``NodeLikeMonitor``: counts times scale, the full-scale rule, shipped
settings) with consecutive stamps: a replay, every block analysed in full. Each block's CPU time
(``time.thread_time``) is split into the stages below by wrapping the module functions the monitor calls (the
time of a stage excludes the stages it calls; the rest is "other": the monitor's own code, the decision,
numpy glue). The reference, measured in the same process between blocks: a Hann-windowed 256-point STFT of the
same block with numpy (non-overlapping frames, ``np.fft.rfft`` real / ``np.fft.fft`` complex, |X|^2), the
physical cost of looking at the block once.
"""

from __future__ import annotations

import json
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

FRONT_ENDS = {
    "real38": dict(sample_rate_hz=38.192e6, intermediate_frequency_hz=9.548e6, is_complex=False),
    "cplx10": dict(sample_rate_hz=10.0e6, intermediate_frequency_hz=0.0, is_complex=True),
    "real24": dict(sample_rate_hz=24.0e6, intermediate_frequency_hz=6.0e6, is_complex=False),
}
"""The front ends of issue 26 item 2 (8 bits each)."""

STAGES = (
    ("decode", None, None),                                        # counts * scale (the node's decode)
    ("bad samples", "rfi_monitor.monitor", "_count_bad_samples"),
    ("welch + features", "rfi_monitor.classifier", "welch_psd"),
    ("welch + features", "rfi_monitor.classifier", "features_from_psd"),
    ("welch + features", "rfi_monitor.classifier", "smooth_template"),
    ("frame length choice", "rfi_monitor.ridge", "choose_frame_length"),
    ("ridge analysis", "rfi_monitor.ridge", "analyse"),
    ("integration", "rfi_monitor.integration", "Integrator.add"),
    ("spectral step", "rfi_monitor.spectral_step", "SpectralStep.test"),
    ("envelope J/N", "rfi_monitor.constant_envelope", "constant_envelope_jn_db"),
    ("folded shape", "rfi_monitor.ridge", "folded_shape"),
)
"""(stage, module, attribute) wrapped; an attribute missing in a version is skipped."""
CALLERS = ("rfi_monitor.monitor", "rfi_monitor.stft_estimator", "rfi_monitor.light_analysis",
           "rfi_monitor.kalman_estimator")
"""The monitor's modules that may have imported a stage's function by name (each version has some of them): wrapped
there too (not the stages' own modules: the integration's Welch PSD is the integration's time)."""


class StageClock:
    """Exclusive CPU time per stage: a stage called inside another is charged to itself only."""

    def __init__(self) -> None:
        self.totals: dict[str, float] = defaultdict(float)
        self._stack: list[list] = []

    def wrap(self, name: str, fn):
        def timed(*args, **kwargs):
            frame = [name, time.thread_time(), 0.0]
            self._stack.append(frame)
            try:
                return fn(*args, **kwargs)
            finally:
                self._stack.pop()
                dt = time.thread_time() - frame[1]
                self.totals[name] += dt - frame[2]
                if self._stack:
                    self._stack[-1][2] += dt
        timed.__wrapped__ = fn
        return timed


def install(clock: StageClock) -> list[str]:
    """Wrap the stages' functions (where the monitor looks them up); returns the stages found."""
    import importlib
    found = []
    for stage, module, attr in STAGES:
        if module is None:
            continue
        mod = importlib.import_module(module)
        owner, name = (mod, attr) if "." not in attr else (getattr(mod, attr.split(".")[0], None), attr.split(".")[1])
        fn = getattr(owner, name, None) if owner is not None else None
        if fn is None:
            continue
        setattr(owner, name, clock.wrap(stage, fn))
        found.append(stage)
        if owner is mod:
            for caller in CALLERS:                # also where the monitor's modules imported it by name
                try:
                    cm = importlib.import_module(caller)
                except ImportError:
                    continue
                if cm is not mod and getattr(cm, name, None) is fn:
                    setattr(cm, name, getattr(owner, name))
    return found


def blocks(front_end: str, phase: str, n_blocks: int):
    from rfi_sim.if_signal import ChirpJammer, FrontEndConfig, IfSimulator
    fe = FrontEndConfig(noise_bandwidth_hz=2e6, **FRONT_ENDS[front_end])
    n = int(round(fe.sample_rate_hz * 1e-3))
    clean = IfSimulator(fe, (), seed=3)
    jammed = IfSimulator(fe, (ChirpJammer(js_db=40.0),), seed=4)
    out = []
    for k in range(n_blocks):
        sim = clean if phase == "acquisition" or (phase == "switch" and k < n_blocks // 2) else jammed
        blk = sim.generate(n)
        out.append((blk.counts.copy(), float(blk.scale)))
    return fe, n, out


def bare_stft(x: np.ndarray, cplx: bool, w: np.ndarray) -> np.ndarray:
    """The reference: Hann-windowed 256-point STFT of the block with numpy, |X|^2."""
    L = w.size
    fr = x[: (x.size // L) * L].reshape(-1, L) * w
    s = np.fft.fft(fr, axis=1) if cplx else np.fft.rfft(fr, axis=1)
    return s.real ** 2 + s.imag ** 2


def main() -> None:
    case, n_blocks = sys.argv[1], int(sys.argv[2])
    front_end, phase = case.split(":")
    from rfi_monitor_real_jammers import NodeLikeMonitor
    fe, n, data = blocks(front_end, phase, n_blocks)
    clock = StageClock()
    mon = NodeLikeMonitor(None)
    try:                                   # as the node does before it subscribes: compiled functions loaded
        from rfi_monitor.warm_up import warm_up
    except ImportError:                    # the package before issue 26 had it in the node module
        from rfi_monitor.rfi_monitor_node import warm_up
    warm_up(mon.params)
    install(clock)
    cplx = bool(fe.is_complex)
    w = np.hanning(256)
    per_block, stft, stage_rows, types, freqs = [], [], [], [], []
    for k, (counts, scale) in enumerate(data):
        before = dict(clock.totals)
        t0 = time.thread_time()
        e = mon.process(counts, scale, fe.sample_rate_hz, fe.intermediate_frequency_hz, cplx, 8, k * n,
                        10**9 + k * 10**6)
        per_block.append(time.thread_time() - t0)
        stage_rows.append({s: clock.totals[s] - before.get(s, 0.0) for s in clock.totals})
        types.append(int(e.type))
        freqs.append(float(e.frequency_hz))
        x = counts.astype(np.float64) * scale
        if cplx:
            x = x[0::2] + 1j * x[1::2]
        t0 = time.thread_time()
        bare_stft(x, cplx, w)
        stft.append(time.thread_time() - t0)
    print(json.dumps({"t": per_block, "stft": stft, "stages": stage_rows, "n": n, "types": types,
                      "freqs": freqs}))


if __name__ == "__main__":
    main()
