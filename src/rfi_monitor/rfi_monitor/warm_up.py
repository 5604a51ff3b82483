"""Compiled functions compiled (or loaded from numba's cache) before a node subscribes (pure: no rclpy)."""

from __future__ import annotations

import numpy as np

from rfi_monitor.constant_envelope import constant_envelope_noise
from rfi_monitor.monitor import RfiMonitor, RfiMonitorParams
from rfi_monitor.spectral_step import warm_up as spectral_step_warm_up


def warm_up(params: RfiMonitorParams) -> None:
    """Run a throw-away monitor on real and complex blocks of noise, then of noise with a saw-tooth chirp, so that
    the compiled (numba) functions of both the quiet and the tracking paths (the sweep profile, law and shape) are
    compiled or loaded from the cache at start-up, not on the first blocks of a live stream (seconds of CPU on a
    fresh install, which the load shedding would otherwise pay for by shedding the first blocks, or the input queue
    by dropping them)."""
    rng = np.random.default_rng(0)
    n = max(params.min_block_samples, 8192)
    fs = 4.0e6
    t = np.arange(n) / fs
    tau = np.mod(t, 64 / fs)                               # a 64-sample saw-tooth over 1 MHz
    for cplx in (False, True):
        mon = RfiMonitor(params)
        fif = 0.0 if cplx else 1.0e6
        phase = 2 * np.pi * (fif * t - 0.5e6 * tau + 0.5 * (1e6 / (64 / fs)) * tau ** 2)
        for k, jam in enumerate((0.0, 4.0, 4.0)):
            if cplx:
                z = (rng.standard_normal(n) + 1j * rng.standard_normal(n)) / np.sqrt(2) + jam * np.exp(1j * phase)
                x = np.empty(2 * n)
                x[0::2], x[1::2] = z.real, z.imag
            else:
                x = rng.standard_normal(n) + jam * np.cos(phase)
            mon.process(x, fs, fif, k * n, 1 + k * int(n / fs * 1e9), is_complex=cplx, full_scale=64.0)
    # the constant-envelope J/N runs only on a strong CW or chirp at >= 4 bits, which the blocks above are not
    # (test_warm_up.py found its real-sample kernels compiled on the first such block of a live stream)
    constant_envelope_noise(rng.standard_normal(n), False)
    constant_envelope_noise(rng.standard_normal(n) + 1j * rng.standard_normal(n), True)
    if params.spectral_step.enabled:
        spectral_step_warm_up(params.classifier.nfft)
