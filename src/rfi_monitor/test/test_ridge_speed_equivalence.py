"""The faster ridge.py (issue 14 item 6) reports what the one before it did.

ridge_reference.py beside this file is ridge.py as of efa776e, before the speed work (numpy noise levels with
scipy.ndimage filters; the new one computes them in one compiled pass, reuses the excess array and writes
the STFT power in place), with the later sweep-shape step of issue 14 item 3 ported into it (not speed work: its
rules are checked by test_ridge_shapes.py, the compiled versions against the reference's numpy ones there too;
here they only keep the two analyses comparable field by field). Both run on the same inputs here: the
swept-jammer shape cases of test_stft_estimator.py (CASES) and the real clean captures in data/, block by
block, the whole block and the tail analysed while tracking (RidgeParams.tracking_samples), and through the
whole monitor.

Tolerances: integers, flags and shape codes exactly; floats within 1e-6 relative (plus 1e-15 absolute
near zero), NaN where the reference has NaN. The arithmetic was kept in the same precision and order
(float32 quantile, medians and threshold; float64 masked sums in frame order; the float32 phasor sums and
the float64 period sum in numpy's pairwise order), so on the development machine the results are
bit-identical; the tolerance allows for a numpy or CPU that sums float32 in another order (~1e-7
relative on the phasor, less on what is derived from it). Monitor outputs: type and shape exactly, J/N
within 1e-6 dB, frequency, rate, period, band within 1e-6 relative.
"""

import dataclasses
import importlib.util
import math
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from rfi_monitor import frame_length, ridge_periodicity
from rfi_monitor import monitor as monitor_module
from rfi_monitor import ridge as new

HERE = Path(__file__).parent


def _load(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod          # dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


old = _load("rfi_monitor_ridge_reference", HERE / "ridge_reference.py")
shapes = _load("rfi_monitor_stft_cases", HERE / "test_stft_estimator.py")

REL = 1e-6


def _close(a: float, b: float, rel: float = REL) -> bool:
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return a == b or abs(a - b) <= rel * max(abs(a), abs(b)) + 1e-15


def _same_result(a, b) -> list[str]:
    """Fields of two RidgeResults that differ beyond the tolerances."""
    bad = []
    for fld in dataclasses.fields(a):
        if fld.name == "hook_checked":      # the sample-resolution hook test is newer than the reference
            continue
        va, vb = getattr(a, fld.name), getattr(b, fld.name)
        if isinstance(va, (bool, int, np.bool_)) and not isinstance(va, float):
            if va != vb:
                bad.append(f"{fld.name}: {va} != {vb}")
        elif not _close(float(va), float(vb)):
            bad.append(f"{fld.name}: {va!r} != {vb!r}")
    return bad


def _blocks():
    """(name, block, fs, complex) of 1 ms blocks: the shape cases (3 blocks each) and the real captures."""
    out = []
    for c in shapes.CASES:
        name, fs, cplx, fif, shape, lo, hi, period, jn, ratio, _ = c
        x, _f = shapes.jammed(int(3e-3 * fs), fs, cplx, shape, lo, hi, period, jn, seed=1, fif=fif, rate_ratio=ratio)
        n = int(round(1e-3 * fs))
        out += [(f"{name} #{k}", x[k * n:(k + 1) * n], fs, cplx) for k in range(3)]
    for name, x, fs, _fif, cplx, block in shapes._real_captures():
        if cplx is None:                      # complex64 file
            x, cplx = x.astype(np.complex128), True
        elif cplx:                            # interleaved int8 I, Q
            x = x[0::2].astype(np.float64) + 1j * x[1::2].astype(np.float64)
        else:
            x = x.astype(np.float64)
        out += [(f"{name} #{k}", x[k * block:(k + 1) * block], fs, cplx) for k in range(3)]
    return out


BLOCKS = _blocks()


def _best_select_score(x, cplx, par) -> float:
    """The best frame-length score of choose_frame_length's slice (reference arithmetic)."""
    n = min(x.size, int(par.select_samples)) if par.select_samples > 0 else x.size
    best = -math.inf
    for L in par.frame_lengths:
        if 8 * L > n:
            break
        S, _ = old.stft_power(x[:n], L, cplx)
        sc = old._peak_excess(S, old.noise_levels(S, par.noise_smooth_bins, cplx), cplx)
        if math.isfinite(sc):
            best = max(best, sc)
    return best


def test_frame_length_on_noise():
    """On noise (white, and band-limited by a smooth pass band as a front end's) no frame-length score is significant
    over noise, and the longest frame is taken: the cheapest analysis, not the random (often the shortest) frame the
    raw scores took."""
    par = new.RidgeParams()
    rng = np.random.default_rng(3)
    for cplx in (False, True):
        for bw in (None, 0.6):
            w = rng.standard_normal(8192) + (1j * rng.standard_normal(8192) if cplx else 0)
            if bw is not None:
                # a Gaussian pass band around the band's middle, 1-sigma bw of half the band
                X = np.fft.fft(w)
                f = np.fft.fftfreq(8192) if cplx else np.abs(np.fft.fftfreq(8192))
                mid, half = (0.0, 0.5) if cplx else (0.25, 0.25)
                X *= np.exp(-0.5 * ((f - mid) / (bw * half)) ** 2)
                w = np.fft.ifft(X) if cplx else np.fft.ifft(X).real
            z = []
            for L in par.frame_lengths:
                S, _ = new.stft_power(w, L, cplx)
                mu, sd = new.null_peak_excess(L, cplx, 8192, par.noise_smooth_bins)
                lvl = new.noise_levels(S, par.noise_smooth_bins, cplx)
                z.append((frame_length._peak_excess(S, lvl, cplx) - mu) / sd)
            assert max(z) < new.SELECT_Z, (cplx, bw, z)
            assert new.choose_frame_length(w, cplx, par) == max(par.frame_lengths), (cplx, bw, z)


def test_frame_length_null_is_deterministic():
    a = new.null_peak_excess(32, False, 4096, 5)
    frame_length._NULL_EXCESS.clear()
    assert new.null_peak_excess(32, False, 4096, 5) == a
    assert 0.0 < a[1] < 1.0


@pytest.mark.parametrize("name,x,fs,cplx", BLOCKS, ids=[b[0] for b in BLOCKS])
def test_analyse_same_as_reference(name, x, fs, cplx):
    par = new.RidgeParams()
    L_old = old.choose_frame_length(x, cplx, old.RidgeParams())
    if _best_select_score(x, cplx, par) >= new.MIN_SELECT_EXCESS:
        # where nothing is concentrated (noise) the choice changed on purpose after the speed work: no score
        # significant over noise (ridge.null_peak_excess) takes the longest frame (test_frame_length_on_noise);
        # the scores themselves are compared below
        assert new.choose_frame_length(x, cplx, par) == L_old, name
    parts = [x]
    if x.size > par.tracking_samples:
        parts.append(x[-par.tracking_samples:])
    for part in parts:
        for L in sorted({L_old, 16, 64}):
            a = old.analyse(part, cplx, fs, old.RidgeParams(), L)
            b = new.analyse(part, cplx, fs, par, L)
            assert not _same_result(a, b), (name, part.size, L, _same_result(a, b))
    # the noise levels themselves, at every frame length
    for L in par.frame_lengths:
        S, _ = old.stft_power(x, L, cplx)
        S2, _ = new.stft_power(x, L, cplx)
        np.testing.assert_allclose(S2, S, rtol=0, atol=0)
        lvl = old.noise_levels(S, par.noise_smooth_bins, cplx)
        np.testing.assert_allclose(new.noise_levels(S, par.noise_smooth_bins, cplx), lvl, rtol=REL, atol=0)
        # the frame-length score (choose_frame_length)
        assert _close(frame_length._peak_excess(S, lvl, cplx), old._peak_excess(S, lvl, cplx)), (name, L)


def test_noise_levels_same_as_reference_on_random_spectra():
    """Random shapes, heavy-tailed cells, plateaus, tiny and huge scales, float64 input (converted)."""
    rng = np.random.default_rng(7)
    for trial in range(60):
        nfr = int(rng.integers(8, 400))
        B = int(rng.integers(5, 70))
        cplx = bool(trial % 2)
        S = (rng.exponential(1.0, (nfr, B)) * rng.uniform(0.5, 2.0, B) * 10.0 ** rng.uniform(-20, 20))
        if trial % 3 == 0:
            S[:, B // 3:B // 2] *= 30.0                           # a plateau
            S[rng.integers(0, nfr, nfr // 4), rng.integers(0, B, nfr // 4)] *= 1e3   # a sweep's cells
        S32 = S.astype(np.float32)
        for w in (3, 5, 7):
            np.testing.assert_allclose(new.noise_levels(S32, w, cplx), old.noise_levels(S32, w, cplx),
                                       rtol=REL, atol=0)


def _as_called_today(ridge_module):
    """The reference module as the monitor calls it today: its analyse takes ``fine_hook`` (the reference has no
    sample-resolution hook test) and returns today's RidgeResult (``hook_checked`` False)."""
    shim = types.ModuleType("rfi_monitor_ridge_reference_as_called_today")
    shim.__dict__.update(ridge_module.__dict__)

    def analyse(x, cplx, fs, par, frame_length=0, fine_hook=True):
        return new.RidgeResult(**dataclasses.asdict(ridge_module.analyse(x, cplx, fs, par, frame_length)))
    shim.analyse = analyse
    return shim


def _run_monitor(x, fs, cplx, fif, ridge_module):
    """The monitor's outputs with the given ridge module; the frame length is always chosen by the current
    choose_frame_length (its choice on noise changed on purpose: test_frame_length_on_noise), so that the
    comparison is of the analysis."""
    saved = monitor_module.rg
    saved_choose = ridge_module.choose_frame_length
    ridge_module.choose_frame_length = new.choose_frame_length
    monitor_module.rg = ridge_module if ridge_module is new else _as_called_today(ridge_module)
    try:
        return shapes.run(x, fs, cplx, fif)
    finally:
        monitor_module.rg = saved
        ridge_module.choose_frame_length = saved_choose


@pytest.mark.parametrize("case", shapes.CASES[:5], ids=[c[0] for c in shapes.CASES[:5]])
def test_monitor_outputs_same_as_reference(case):
    """The whole stft estimator (acquisition, then tracking with the tail analysed) with either ridge."""
    name, fs, cplx, fif, shape, lo, hi, period, jn, ratio, _ = case
    x, _f = shapes.jammed(int(4e-3 * fs), fs, cplx, shape, lo, hi, period, jn, seed=4, fif=fif, rate_ratio=ratio)
    ea = _run_monitor(x, fs, cplx, fif, old)
    eb = _run_monitor(x, fs, cplx, fif, new)
    assert len(ea) == len(eb) == 4
    for a, b in zip(ea, eb, strict=True):
        assert (a.type, a.sweep_shape, a.valid, a.noise_reference) == (b.type, b.sweep_shape, b.valid,
                                                                      b.noise_reference), name
        assert abs(a.jammer_to_noise_db - b.jammer_to_noise_db) <= 1e-6, name
        for fld in ("frequency_hz", "frequency_std_hz", "sweep_rate_hz_per_s", "sweep_period_s",
                    "sweep_start_frequency_hz", "sweep_bandwidth_hz", "in_band_fraction"):
            assert _close(getattr(a, fld), getattr(b, fld)), (name, fld, getattr(a, fld), getattr(b, fld))


def test_monitor_on_real_clean_capture_same_as_reference():
    name, x, fs, fif, cplx, block = shapes._real_captures()[1]        # pocketsdr 12 MHz real
    a = _run_monitor(x.astype(np.float64), fs, cplx, fif, old)
    b = _run_monitor(x.astype(np.float64), fs, cplx, fif, new)
    assert [e.type for e in a] == [e.type for e in b]
    assert all(abs(p.jammer_to_noise_db - q.jammer_to_noise_db) <= 1e-6 for p, q in zip(a, b, strict=True))


def test_periodicity_same_as_reference_on_random_phasors():
    """The compiled period search against the reference on phasor sequences: noise only, periodic sweeps of
    2.3 to 60 frames (sub-harmonic check, refinement on multiples), weak and strong, pulsed."""
    rng = np.random.default_rng(11)
    par = new.RidgeParams()
    n_periodic = 0
    for trial in range(300):
        T = int(rng.integers(40, 2500))
        per = float(rng.uniform(2.3, 60.0))
        t = np.arange(T)
        amp = float(rng.choice([0.0, 0.3, 1.0, 5.0]))
        gate = (np.mod(t / per, 1.0) < rng.uniform(0.3, 1.0)) if trial % 4 == 0 else 1.0
        u = amp * gate * np.exp(2j * np.pi * np.mod(t / per, 1.0)) + (rng.standard_normal(T)
                                                                       + 1j * rng.standard_normal(T))
        lmin, lmax = int(par.min_period_frames), int(rng.integers(5, max(6, T // 4 + 1)))
        a = old._periodicity(u, lmin, lmax, old.RidgeParams())
        b = ridge_periodicity._periodicity(u, lmin, lmax, par)
        assert _close(a[0], b[0]) and _close(a[1], b[1]), (trial, a, b)
        n_periodic += math.isfinite(a[0])
    assert 50 < n_periodic < 300          # both outcomes exercised
