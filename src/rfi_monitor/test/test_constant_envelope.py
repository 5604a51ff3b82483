"""The noise under a constant-envelope jammer from the block's moments (rfi_monitor.constant_envelope), and the
monitor's J/N with it for a strong fast chirp that is on from the first block (no clean start)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rfi_monitor.constant_envelope import constant_envelope_jn_db
from rfi_monitor.monitor import RfiMonitor, RfiMonitorParams
from rfi_sim.jammer_waveforms import SweepJammer, sweep_law


def _tone(n: int, fs: float, f_hz: float, cplx: bool, power: float, rng: np.random.Generator) -> np.ndarray:
    ph = 2 * np.pi * f_hz * np.arange(n) / fs + rng.uniform(0, 2 * np.pi)
    if cplx:
        return math.sqrt(power) * np.exp(1j * ph)
    return math.sqrt(2 * power) * np.cos(ph)


def _noise(n: int, cplx: bool, rng: np.random.Generator) -> np.ndarray:
    if cplx:
        return (rng.standard_normal(n) + 1j * rng.standard_normal(n)) / math.sqrt(2)
    return rng.standard_normal(n)


@pytest.mark.parametrize("cplx", [True, False])
@pytest.mark.parametrize("jn_db", [10.0, 20.0, 30.0, 40.0])
def test_tone_in_noise_reads_its_jn(cplx, jn_db):
    """A tone in white Gaussian noise, at frequencies that include the trap of real moments (fs / 4):
    within 0.5 dB of the truth from J/N 10 dB, where the monitor needs it (below, the moments of 8192 samples
    scatter by several tenths of a dB, and the spectral estimate, kept when larger, is good there anyway)."""
    rng = np.random.default_rng(int(jn_db) + 7 * cplx)
    fs = 16.368e6
    # real input: tones inside a front end's pass band (a real tone within a few bins of DC or fs / 2 leaks across it
    # in the FFT's analytic signal, whose magnitude then ripples: that errs low, test_noise_alone_...)
    freqs = (fs / 4, 0.01 * fs, 0.31 * fs, -0.2 * fs) if cplx else (fs / 4, 0.1 * fs, 0.31 * fs, 0.4 * fs)
    for f in freqs:
        x = _tone(16368, fs, f, cplx, 10 ** (jn_db / 10), rng) + _noise(16368, cplx, rng)
        got = constant_envelope_jn_db(x, cplx)
        assert abs(got - jn_db) < 0.5, (cplx, jn_db, f, got)


@pytest.mark.parametrize("cplx", [True, False])
def test_noise_alone_and_modulated_jammers_read_low(cplx):
    """Noise alone reads far below any detection threshold; a jammer whose magnitude is not constant (pulsed, two
    tones beating) reads below its true J/N: the estimate errs low, never high."""
    rng = np.random.default_rng(3 + cplx)
    fs, n = 10e6, 16384
    for _ in range(20):
        assert constant_envelope_jn_db(_noise(n, cplx, rng), cplx) < -5.0
    on = (np.arange(n) // 500) % 2 == 0                 # pulsed: on half the time
    for jn_db in (10.0, 25.0):
        p = 10 ** (jn_db / 10)
        pulsed = _tone(n, fs, 1.3e6, cplx, 2 * p, rng) * on + _noise(n, cplx, rng)
        two = _tone(n, fs, 1.3e6, cplx, p / 2, rng) + _tone(n, fs, 2.1e6, cplx, p / 2, rng) + _noise(n, cplx, rng)
        for x in (pulsed, two):
            assert constant_envelope_jn_db(x, cplx) < jn_db + 0.3, (cplx, jn_db)


def _chirp_block(k: int, n: int, fs: float, jam: SweepJammer, jn_db: float, rng: np.random.Generator) -> np.ndarray:
    law = sweep_law(jam)
    t = (k * n + np.arange(n)) / fs
    m = np.floor(t / law.period_s)
    cyc = m * law.cycles_per_period + law.cycles(t - m * law.period_s)
    return math.sqrt(10 ** (jn_db / 10)) * np.exp(2j * np.pi * np.mod(cyc, 1.0)) + _noise(n, True, rng)


def test_monitor_jn_of_a_strong_fast_chirp_on_from_the_start():
    """A saw-tooth over 60 % of a 4 MS/s I/Q band in 12 us at J/N 30 dB, on from the first block: the noise beside it
    in the short-time spectrum reads high (its leakage fills every bin of every frame: 23 dB before), the moments
    give the J/N within 1 dB."""
    fs, n = 4e6, 4000
    jam = SweepJammer("saw_up", -1.08e6, 1.08e6, 12e-6)
    rng = np.random.default_rng(11)
    mon = RfiMonitor(RfiMonitorParams())
    jns, e = [], None
    for k in range(6):
        e = mon.process(_chirp_block(k, n, fs, jam, 30.0, rng), fs, 0.0, k * n, 10**9 + k * 10**6)
        assert e.valid and e.type == 2
        jns.append(e.jammer_to_noise_db)
    assert all(abs(j - 30.0) < 1.0 for j in jns), jns
    assert e is not None and e.counters["jn_from_envelope"] == 6


@pytest.mark.parametrize("n", [8192, 8191, 1000, 1125])
def test_hilbert_transform_is_the_analytic_signals_imaginary_part(n):
    """The envelope's real-FFT Hilbert transform equals the imaginary part of ridge.analytic_signal (the complex
    inverse FFT it replaced) to rounding, odd lengths included; the real part there is the samples themselves."""
    from rfi_monitor.constant_envelope import hilbert_transform
    from rfi_monitor.ridge import analytic_signal
    x = np.random.default_rng(n).standard_normal(n) + 3 * np.cos(0.7 * np.arange(n))
    a = analytic_signal(x)
    h = hilbert_transform(x)
    assert h.shape == x.shape
    np.testing.assert_allclose(h, a.imag, rtol=0, atol=1e-12 * np.abs(a).max())
    np.testing.assert_allclose(x, a.real, rtol=0, atol=1e-12 * np.abs(a).max())
