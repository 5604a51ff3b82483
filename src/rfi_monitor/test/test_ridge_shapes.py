"""Oracle tests of the sweep-shape label of the "stft" estimator (ridge.py, module docstring step 5; issue 14 item 3).

The jammers are rfi_sim's frequency laws (``jammer_waveforms.sweep_law``: exact phase, the hook as rfi_sim makes it:
a return that overshoots below the sweep's start and relaxes back), plus unit-power Gaussian noise, at common SDR
rates (4 and 10 MS/s complex, 12, 16.368 and 38.192 MS/s real) and J/N 10-20 dB. What is asserted is the decision
rule, not a tuned number: a hooked saw-tooth whose return lasts at least two profile bins is HOOKED; a plain
saw-tooth (linear or not) is never HOOKED; triangles (symmetric, 70/30, wider than the band) are TRIANGLE; a ridge
that is only scatter gives UNKNOWN; a periodic ridge moving over only 2-4 bins is a sweep when its direction is
significant and a pulsed tone (periodic, not moving) is not.
"""

import math

import numpy as np
import pytest

from rfi_monitor import ridge as rg
from rfi_monitor import sweep_shape
from rfi_sim.jammer_waveforms import SweepJammer, sweep_law


def _swept(n: int, fs: float, cplx: bool, jam: SweepJammer, jn_db: float, seed: int, fif: float = 0.0,
           band_hz: float | None = None) -> np.ndarray:
    """n samples of unit-power noise plus ``jam`` at J/N jn_db (in band); band_hz: the tone only where |f| <= it."""
    rng = np.random.default_rng(seed)
    law = sweep_law(jam)
    t = np.arange(n) / fs + 0.37 * jam.sweep_period_s
    k = np.floor(t / law.period_s)
    tau = t - k * law.period_s
    cyc = k * law.cycles_per_period + law.cycles(tau) + fif * t
    a = math.sqrt(10 ** (jn_db / 10))
    gate = 1.0 if band_hz is None else (np.abs(law.frequency_hz(tau)) <= band_hz).astype(float)
    ph = 2 * np.pi * np.mod(cyc, 1.0)
    if cplx:
        return a * gate * np.exp(1j * ph) + (rng.standard_normal(n) + 1j * rng.standard_normal(n)) / math.sqrt(2)
    return a * math.sqrt(2) * gate * np.cos(ph) + rng.standard_normal(n)


FRONT_ENDS = {  # name: (fs, complex, IF, usable half band Hz)
    "4 MS/s complex": (4e6, True, 0.0, 1.4e6),
    "10 MS/s complex": (10e6, True, 0.0, 3.5e6),
    "16.368 MS/s real": (16.368e6, False, 4.092e6, 3.0e6),
    "38.192 MS/s real": (38.192e6, False, 9.548e6, 5.0e6),
}


def _shape_of(fe: str, jam_of_band, jn_db: float, seed: int, frame_length: int = 0, **kw) -> rg.RidgeResult:
    fs, cplx, fif, half = FRONT_ENDS[fe]
    x = _swept(int(1e-3 * fs), fs, cplx, jam_of_band(half), jn_db, seed, fif, **kw)
    return rg.analyse(x, cplx, fs, rg.RidgeParams(), frame_length)


HOOKED = [  # (front end, period s, hook fraction, overshoot as a share of the swept band): returns of 2+ profile bins
    ("10 MS/s complex", 30e-6, 0.25, 0.2),
    ("10 MS/s complex", 100e-6, 0.2, 0.15),
    ("4 MS/s complex", 100e-6, 0.3, 0.25),
    ("16.368 MS/s real", 10e-6, 0.3, 0.25),
    ("16.368 MS/s real", 30e-6, 0.25, 0.2),
    ("38.192 MS/s real", 30e-6, 0.25, 0.2),
    ("38.192 MS/s real", 100e-6, 0.15, 0.1),
]


@pytest.mark.parametrize("fe,period,hook,over", HOOKED, ids=[f"{c[0]} {c[1] * 1e6:.0f}us hook {c[2]}" for c in HOOKED])
@pytest.mark.parametrize("jn", [10.0, 20.0])
def test_hooked_sawtooth_with_a_resolved_return_is_hooked(fe, period, hook, over, jn):
    for seed in (1, 2):
        r = _shape_of(fe, lambda h: SweepJammer("hooked_saw", -h, h, period, hook_fraction=hook,
                                                hook_overshoot_hz=over * 2 * h), jn, seed)
        assert r.periodic and r.period_samples == pytest.approx(period * FRONT_ENDS[fe][0], rel=0.01)
        assert r.shape == rg.HOOKED_SAWTOOTH, (fe, period, hook, jn, seed, rg.SHAPE_NAMES[r.shape])


SAWS = [(fe, shape, period, ratio) for fe in FRONT_ENDS for shape, period, ratio in
        (("saw_up", 10e-6, 1.0), ("saw_down", 30e-6, 1.3), ("saw_up", 100e-6, 1.5))]


@pytest.mark.parametrize("fe,shape,period,ratio", SAWS, ids=[f"{c[0]} {c[1]} {c[2] * 1e6:.0f}us x{c[3]}" for c in SAWS])
def test_plain_sawtooth_is_never_hooked(fe, shape, period, ratio):
    """An instantaneous flyback (linear or non-linear rate) gives the saw-tooth's direction, or UNKNOWN; never a hook,
    a triangle or the other direction."""
    want = rg.SAWTOOTH_UP if shape == "saw_up" else rg.SAWTOOTH_DOWN
    got = []
    for seed in (1, 2, 3):
        for jn in (10.0, 20.0):
            r = _shape_of(fe, lambda h: SweepJammer(shape, -h, h, period, rate_ratio=ratio), jn, seed)
            assert r.periodic and r.sweeping
            got.append(r.shape)
    assert set(got) <= {want, rg.SHAPE_UNKNOWN}, [rg.SHAPE_NAMES[s] for s in got]
    assert got.count(want) >= 5, [rg.SHAPE_NAMES[s] for s in got]


TRIANGLES = [(fe, period, up) for fe in FRONT_ENDS for period, up in ((20e-6, 0.5), (60e-6, 0.7))]


@pytest.mark.parametrize("fe,period,up", TRIANGLES, ids=[f"{c[0]} {c[1] * 1e6:.0f}us up {c[2]}" for c in TRIANGLES])
def test_triangle_is_triangle(fe, period, up):
    for seed in (1, 2):
        r = _shape_of(fe, lambda h: SweepJammer("triangle", -h, h, period, up_fraction=up, rate_ratio=1.2), 10.0,
                      seed)
        assert r.shape == rg.TRIANGLE, (fe, period, up, seed, rg.SHAPE_NAMES[r.shape])


@pytest.mark.parametrize("fs,cplx,fif", [(10e6, True, 0.0), (12e6, False, 3e6)],
                         ids=["10 MS/s complex", "12 MS/s real"])
def test_triangle_wider_than_the_band_in_pieces(fs, cplx, fif):
    """A triangle over 4x the sampled band (in band ~25 % of each 9.09 us period: the in-band pieces alternate up
    and down). Complex input: the pieces cross the +-fs/2 edge, where a ridge in the first or last bin is ambiguous
    (left out of the profile's medians)."""
    half = fs / 2 if cplx else fs / 4
    jam = SweepJammer("triangle", -4 * half, 4 * half, 9.09e-6)
    shapes = []
    for seed in range(1, 6):
        x = _swept(int(1e-3 * fs), fs, cplx, jam, 15.0, seed, fif, band_hz=0.95 * half)
        r = rg.analyse(x, cplx, fs, rg.RidgeParams(), 8)
        assert r.periodic and r.period_samples == pytest.approx(9.09e-6 * fs, rel=0.01)
        assert r.in_band_fraction < 0.6
        shapes.append(r.shape)
    assert shapes == [rg.TRIANGLE] * 5, [rg.SHAPE_NAMES[s] for s in shapes]


def test_scatter_profile_is_unknown():
    """Ridge points that are only noise (uniform over the band, any period) folded as analyse folds them: no shape."""
    rng = np.random.default_rng(5)
    shapes = []
    for _ in range(300):
        nfr = int(rng.integers(200, 2000))
        L = int(rng.choice([8, 16, 32, 64]))
        f = rng.uniform(-0.5, 0.5, nfr)
        present = rng.uniform(size=nfr) < rng.uniform(0.05, 1.0)
        per = float(rng.uniform(4.0, 60.0))
        K = 32 if per > 16 else max(4, int(per))
        prof, share, se = sweep_shape._profile(f, present, per, K, None, 1.0 / L)
        if not np.any(share > 0):
            continue
        inband = (share >= 0.5 * float(np.max(share))) & np.isfinite(prof)
        shapes.append(sweep_shape._shape(prof, inband, 2.0, se)[0])
    assert len(shapes) > 250
    assert shapes.count(rg.SHAPE_UNKNOWN) == len(shapes), {rg.SHAPE_NAMES[s]: shapes.count(s) for s in set(shapes)}


def test_narrow_sawtooth_is_a_sweep_and_pulsed_tone_is_not():
    """A saw-tooth over 2.5 MHz in 12 us at 12 MS/s real seen with 16-sample frames moves over only ~3.4 bins: a sweep
    (its counted profile steps all go up: sign test <= SAW_P). A tone pulsed on and off with the same period is
    periodic but does not move: not a sweep, no shape."""
    fs, fif = 12e6, 3e6
    n = 12000
    for seed in (1, 2, 3):
        x = _swept(n, fs, False, SweepJammer("saw_up", -1.26e6, 1.26e6, 12e-6), 25.0, seed, fif)
        r = rg.analyse(x, False, fs, rg.RidgeParams(), 16)
        assert r.periodic and r.sweeping and r.shape == rg.SAWTOOTH_UP, rg.SHAPE_NAMES[r.shape]
        rng = np.random.default_rng(seed)
        t = np.arange(n) / fs
        gate = (np.mod(t, 12e-6) < 6e-6).astype(float)
        x = math.sqrt(2 * 10 ** 2.5) * gate * np.cos(2 * np.pi * (fif + 0.4e6) * t) + rng.standard_normal(n)
        r = rg.analyse(x, False, fs, rg.RidgeParams(), 16)
        assert not r.sweeping and r.shape == rg.SHAPE_UNKNOWN, (r.periodic, rg.SHAPE_NAMES[r.shape])


def test_sign_tail():
    assert sweep_shape._sign_tail(3, 3) == pytest.approx(1 / 8)
    assert sweep_shape._sign_tail(15, 15) == pytest.approx(2.0 ** -15)
    assert sweep_shape._sign_tail(6, 7) == pytest.approx(8 / 128)
    assert sweep_shape._sign_tail(0, 5) == 1.0 and sweep_shape._sign_tail(1, 0) == 1.0


def test_return_bins():
    up = np.array([0.0, 0.1, 0.2, 0.3, 0.4, -0.4, -0.3, -0.2, -0.1])          # instantaneous flyback
    hook = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.15, -0.15, -0.45, -0.35, -0.2, -0.1])   # swept, overshooting
    ok_u, ok_h = np.ones(up.size, bool), np.ones(hook.size, bool)
    assert sweep_shape._return_bins(up, ok_u, True) == (0, 1)
    assert sweep_shape._return_bins(hook, ok_h, True) == (2, 3)
    assert sweep_shape._return_bins(-hook, ok_h, False) == (2, 3)


# ----- folded_shape: a sweep of known period (from the evidence over blocks) below the per-frame ridge -----

def test_folded_shape_noise_is_unknown():
    rng = np.random.default_rng(11)
    par = rg.RidgeParams()
    for trial in range(40):
        cplx = bool(trial % 2)
        n = int(rng.integers(4000, 40000))
        x = rng.standard_normal(n) + (1j * rng.standard_normal(n) if cplx else 0.0)
        period = float(rng.uniform(20.0, 500.0))
        shape, inb, lo, hi = rg.folded_shape(x, cplx, period, par)
        assert shape == rg.SHAPE_UNKNOWN, (trial, period, rg.SHAPE_NAMES[shape], inb)


@pytest.mark.parametrize("fe,shape,jn", [("38.192 MS/s real", "saw_up", -5.0), ("38.192 MS/s real", "saw_down", -5.0),
                                         ("10 MS/s complex", "triangle", -8.0), ("16.368 MS/s real", "saw_up", -8.0)])
def test_folded_shape_weak_sweep(fe, shape, jn):
    """A sweep at J/N -5..-8 dB, where the per-frame ridge finds no period in most blocks (23 of 24 here): folded on
    its true period, the shape is right or unknown in each block (never another label), right in most."""
    fs, cplx, fif, half = FRONT_ENDS[fe]
    period = 5.1e-6 if fe.startswith("38") else 20e-6
    want = {"saw_up": rg.SAWTOOTH_UP, "saw_down": rg.SAWTOOTH_DOWN, "triangle": rg.TRIANGLE}[shape]
    got = []
    for seed in range(1, 7):
        x = _swept(int(1e-3 * fs), fs, cplx, SweepJammer(shape, -0.5 * half, 0.5 * half, period), jn, seed, fif)
        got.append(rg.folded_shape(x, cplx, period * fs, rg.RidgeParams())[0])
    assert set(got) <= {want, rg.SHAPE_UNKNOWN}, [rg.SHAPE_NAMES[s] for s in got]
    assert got.count(want) >= 4, [rg.SHAPE_NAMES[s] for s in got]


def test_folded_shape_triangle_wider_than_the_band_two_bit():
    """The triangle over 4x the band at 4 MS/s complex through a 2-bit quantiser (the chosen frame holds many of its
    36-sample periods, so the ridge finds none): folded on the period, a triangle."""
    fs, half = 4e6, 1.25e6
    got = []
    for seed in range(1, 6):
        x = _swept(4000, fs, True, SweepJammer("triangle", -4 * half, 4 * half, 9.09e-6), 13.0, seed,
                   band_hz=half)
        q = np.sign(x.real) * np.where(np.abs(x.real) > 1.0, 3, 1) + 1j * np.sign(x.imag) * np.where(
            np.abs(x.imag) > 1.0, 3, 1)
        got.append(rg.folded_shape(q, True, 9.09e-6 * fs, rg.RidgeParams())[0])
    assert set(got) <= {rg.TRIANGLE, rg.SHAPE_UNKNOWN}, [rg.SHAPE_NAMES[s] for s in got]
    assert got.count(rg.TRIANGLE) >= 4, [rg.SHAPE_NAMES[s] for s in got]


def test_weak_sweeps_right_or_unknown():
    """J/N -5 and -8 dB at the four front ends (saw-tooth up and down, triangle): where analyse finds the period, the
    shape is the right one or unknown, never another label (the ridge profile's rule, then the folded spectrum's
    when the profile shows none); at -5 dB most periodic blocks are labelled."""
    want_of = {"saw_up": rg.SAWTOOTH_UP, "saw_down": rg.SAWTOOTH_DOWN, "triangle": rg.TRIANGLE}
    right = {-5.0: 0, -8.0: 0}
    periodic = {-5.0: 0, -8.0: 0}
    for fe, (fs, cplx, fif, half) in FRONT_ENDS.items():
        for shape, period in (("saw_up", 10e-6), ("saw_down", 30e-6), ("triangle", 20e-6)):
            for jn in (-5.0, -8.0):
                for seed in range(1, 4):
                    x = _swept(int(1e-3 * fs), fs, cplx, SweepJammer(shape, -half, half, period), jn, seed, fif)
                    r = rg.analyse(x, cplx, fs, rg.RidgeParams())
                    if not r.periodic:
                        continue
                    periodic[jn] += 1
                    assert r.shape in (want_of[shape], rg.SHAPE_UNKNOWN), (fe, shape, jn, seed, rg.SHAPE_NAMES[r.shape])
                    right[jn] += r.shape == want_of[shape]
    assert periodic[-5.0] >= 24 and right[-5.0] >= 0.7 * periodic[-5.0], (periodic, right)


# ----- fine_profile: the sample-resolution profile of lag products (a hook shorter than a frame) -----

def test_fine_profile_frequency_is_the_closed_form():
    """A clean linear chirp: the fine profile's frequency per phase bin is the sweep law at the bin's phase (the lag
    product's mean frequency over one sample), within a few standard errors."""
    fs, T = 10e6, 200
    jam = SweepJammer("saw_up", -3e6, 3e6, T / fs)
    law = sweep_law(jam)
    x = _swept(20000, fs, True, jam, 20.0, 1)
    fp = rg.fine_profile(x, True, float(T))
    assert fp is not None and fp.present.all() and fp.bin_samples == pytest.approx(1.0)
    tau = (np.mod((np.arange(T) + 0.5) / fs + 0.37 * T / fs, T / fs))       # the generator starts at 0.37 T
    f_true = law.frequency_hz(tau) / fs
    inner = np.abs(f_true) < 0.28                                              # away from the flyback
    err = (fp.frequency - f_true)[inner]
    assert np.sqrt(np.mean(err ** 2)) < 0.003, np.sqrt(np.mean(err ** 2))


@pytest.mark.parametrize("seed", range(1, 7))
def test_short_hook_like_real_jammers_row_s_is_hooked(seed):
    """real_jammers.md row S: a hooked saw-tooth -3.5..+4 MHz in 12 us at 10 MS/s complex whose hook (15 % of the
    period, 0.8 MHz below the start) lasts 18 samples: shorter than two profile bins and a frame, so the STFT
    profile sees a plain saw-tooth; the sample-resolution profile sees the return."""
    fs = 10e6
    jam = SweepJammer("hooked_saw", -3.5e6, 4e6, 12e-6, hook_fraction=0.15, hook_overshoot_hz=0.8e6)
    x = _swept(int(1e-3 * fs), fs, True, jam, 10.0, seed)
    r = rg.analyse(x, True, fs, rg.RidgeParams())
    assert r.periodic and r.period_samples == pytest.approx(120.0, rel=1e-3)
    assert r.shape == rg.HOOKED_SAWTOOTH, rg.SHAPE_NAMES[r.shape]


def test_hooks_of_a_few_samples_across_front_ends():
    """Hooks whose swept return crosses the band in 5-20 samples (too short for the STFT profile), at the four front
    ends and J/N 10-20 dB: hooked in most blocks, a saw-tooth of the right direction otherwise, never anything
    else."""
    got = []
    for fe, period in (("4 MS/s complex", 30e-6), ("10 MS/s complex", 12e-6), ("16.368 MS/s real", 9e-6),
                       ("38.192 MS/s real", 5e-6)):
        for seed, jn in ((1, 10.0), (2, 20.0)):
            r = _shape_of(fe, lambda h, p=period: SweepJammer("hooked_saw", -0.8 * h, 0.8 * h, p, hook_fraction=0.15,
                                                              hook_overshoot_hz=0.15 * 1.6 * h), jn, seed)
            got.append(r.shape)
    assert set(got) <= {rg.HOOKED_SAWTOOTH, rg.SAWTOOTH_UP}, [rg.SHAPE_NAMES[s] for s in got]
    assert got.count(rg.HOOKED_SAWTOOTH) >= 6, [rg.SHAPE_NAMES[s] for s in got]


def test_plain_sawtooths_never_hooked_random():
    """Random plain saw-tooths (up or down, rate ratio 1-1.5, 30-100 % of the band, periods 5-100 us, J/N 0-30 dB)
    at the four front ends: never HOOKED (the fine profile's flyback gives at most two bins inside the span)."""
    rng = np.random.default_rng(21)
    shapes = []
    for t in range(48):
        fe = list(FRONT_ENDS)[t % 4]
        fs, cplx, fif, half = FRONT_ENDS[fe]
        frac = float(rng.uniform(0.3, 1.0))
        jam = SweepJammer(str(rng.choice(["saw_up", "saw_down"])), -frac * half, frac * half,
                          float(rng.choice([5e-6, 8.972e-6, 12e-6, 20e-6, 50e-6, 100e-6])),
                          rate_ratio=float(rng.uniform(1.0, 1.5)))
        x = _swept(int(1e-3 * fs), fs, cplx, jam, float(rng.choice([0.0, 5.0, 10.0, 20.0, 30.0])),
                   int(rng.integers(1, 1000)), fif)
        shapes.append(rg.analyse(x, cplx, fs, rg.RidgeParams()).shape)
    assert rg.HOOKED_SAWTOOTH not in shapes and rg.TRIANGLE not in shapes, [rg.SHAPE_NAMES[s] for s in shapes]


def _clean_captures():
    from pathlib import Path
    d = Path(__file__).parent / "data"
    iq = np.fromfile(d / "pocketsdr_L1_4MHz_IQ_10ms.bin", dtype=np.int8).astype(float)
    re_ = np.fromfile(d / "pocketsdr_L1_12MHz_I_10ms.bin", dtype=np.int8).astype(float)
    g = np.fromfile(d / "gnsssdr_cttc_4Msps_4ms.dat", dtype=np.float32).astype(float)
    return [(iq[0::2][:4000] + 1j * iq[1::2][:4000], True, 4e6), (re_[:12000], False, 12e6),
            (g[0::2][:4000] + 1j * g[1::2][:4000], True, 4e6)]


def test_fine_profile_noise_alone_shows_nothing():
    """White noise (real and complex) and the real clean captures (2-bit PocketSDR, 16-bit GNSS-SDR; coloured by their
    front ends, the noise's lag product removed from the in-block spectrum): folded on any period, no phase bin holds a
    jammer, so no way back either."""
    rng = np.random.default_rng(4)
    par = rg.RidgeParams()
    blocks = [(rng.standard_normal(n) + (1j * rng.standard_normal(n) if c else 0.0), c, 10e6)
              for n, c in ((10000, True), (16368, False), (38192, False), (4000, True))] + _clean_captures()
    for x, cplx, fs in blocks:
        S, freqs = rg.stft_power(np.asarray(x), 32, cplx)
        lvl = rg.noise_levels(S, par.noise_smooth_bins, cplx)
        r = rg.analyse(np.asarray(x), cplx, fs, par, 32)
        R = rg.noise_lag_product(lvl, freqs, r.noise_power, cplx)
        for period in (37.3, 90.0, 120.02, 250.7, 700.1):
            fp = rg.fine_profile(np.asarray(x), cplx, period, R, r.noise_power)
            if fp is None:
                continue
            assert not fp.present.any(), (cplx, fs, period, int(fp.present.sum()))
            assert rg.fine_return(fp, True) == (0, 0)


def test_weak_chirp_with_known_period_right_or_unknown():
    """make demo's chirp at J/S +6 dB (38.192 MS/s real, J/N -13 dB, 5.1 MHz in 5.102 us), period known: the lag
    products are too weak for the fine profile (no phase bin present, so never hooked), and the folded spectrum
    gives the saw-tooth up or, honestly, unknown; never another label."""
    fs, cplx, fif, half = FRONT_ENDS["38.192 MS/s real"]
    jam = SweepJammer("saw_up", -2.55e6, 2.55e6, 5.102e-6)
    got = []
    par = rg.RidgeParams()
    for seed in range(1, 7):
        x = _swept(int(1e-3 * fs), fs, cplx, jam, -13.0, seed, fif)
        S, freqs = rg.stft_power(x, 32, cplx)
        r = rg.analyse(x, cplx, fs, par, 32)
        R = rg.noise_lag_product(rg.noise_levels(S, par.noise_smooth_bins, cplx), freqs, r.noise_power, cplx)
        fp = rg.fine_profile(x, cplx, 5.102e-6 * fs, R, r.noise_power)
        assert fp is not None and fp.present.mean() < 0.05 and rg.fine_return(fp, True)[0] < rg.FINE_MIN_RETURN
        got.append(rg.folded_shape(x, cplx, 5.102e-6 * fs, rg.RidgeParams())[0])
    assert set(got) <= {rg.SAWTOOTH_UP, rg.SHAPE_UNKNOWN}, [rg.SHAPE_NAMES[s] for s in got]


def test_monitor_tests_a_tracked_hook_once_per_recheck_interval(monkeypatch):
    """The monitor runs the sample-resolution hook test on the block that starts a track and then at most once per
    HOOK_RECHECK_S of stamps (it costs as much as the rest of a tracking block); the blocks in between report the
    tested verdict for a saw-tooth of the same period: row S's hooked saw-tooth is HOOKED in every block, a plain
    saw-tooth never."""
    from rfi_monitor import fine_hook
    from rfi_monitor import sweep_consistency as mon_module
    from rfi_monitor.monitor import RfiMonitor, RfiMonitorParams

    calls = []
    real_fine = fine_hook.fine_profile

    def counted(*args, **kwargs):
        calls.append(1)
        return real_fine(*args, **kwargs)
    monkeypatch.setattr(fine_hook, "fine_profile", counted)     # where fine_hook_shape looks it up
    fs, n = 10e6, 10_000
    for shape, want in (("hooked_saw", rg.HOOKED_SAWTOOTH), ("saw_up", rg.SAWTOOTH_UP)):
        jam = SweepJammer(shape, -3.5e6, 4e6, 12e-6, hook_fraction=0.15, hook_overshoot_hz=0.8e6)
        x = _swept(30 * n, fs, True, jam, 10.0, 5)
        mon = RfiMonitor(RfiMonitorParams())
        calls.clear()
        shapes = []
        for k in range(30):
            # 1 ms blocks over 0.06 s < HOOK_RECHECK_S, every third one missing (a node behind its stream sheds
            # blocks: a gap in the sample index must not make it test again)
            if k % 3 == 2:
                continue
            e = mon.process(x[k * n:(k + 1) * n], fs, 0.0, k * n, 10**9 + 2 * k * 10**6)
            shapes.append(e.sweep_shape)
        assert shapes == [want] * 20, (shape, [rg.SHAPE_NAMES[s] for s in shapes])
        assert 1 <= len(calls) <= 2, (shape, len(calls))     # the first block (and its whole-block retry, if any)
        # past the interval the test runs again
        calls.clear()
        k = 30
        later = 10**9 + 60 * 10**6 + int(mon_module.HOOK_RECHECK_S * 1e9)
        e = mon.process(x[:n], fs, 0.0, k * n, later)
        assert e.sweep_shape == want and len(calls) >= 1


def test_random_shapes_keep_their_label_across_front_ends():
    """Random triangles (up share 30-70 %), plain saw-tooths up and down (rate ratio 1-1.4) and hooked saw-tooths
    (hook 10-25 % of the period, overshoot 5-15 % of the span) at 4-20 MS/s, real and I/Q, J/N 3-30 dB: a
    triangle or a plain saw-tooth is never given another shape; a hooked one is hooked in most blocks, else the
    saw-tooth it is otherwise or unknown (session 8: 32 of 40 hooked, 8 of 40 before the sample-resolution test)."""
    rng = np.random.default_rng(8)
    hooked = 0
    for shape in ("triangle", "saw_up", "hooked_saw", "saw_down"):
        for _ in range(40):
            fs = float(rng.choice([4e6, 8e6, 10e6, 16.368e6, 20e6]))
            cplx = bool(rng.random() < 0.5)
            half = (0.45 if cplx else 0.2) * fs
            frac, per = float(rng.uniform(0.3, 0.9)), float(rng.uniform(5e-6, 50e-6))
            kw: dict = {"rate_ratio": float(rng.uniform(1.0, 1.4))}
            if shape == "triangle":
                kw["up_fraction"] = float(rng.uniform(0.3, 0.7))
            if shape == "hooked_saw":
                kw = {"hook_fraction": float(rng.uniform(0.1, 0.25)),
                      "hook_overshoot_hz": float(rng.uniform(0.05, 0.15)) * 2 * frac * half}
            jam = SweepJammer(shape, -frac * half, frac * half, per, **kw)
            x = _swept(int(1e-3 * fs), fs, cplx, jam, float(rng.uniform(3.0, 30.0)), int(rng.integers(1, 10**6)),
                       0.0 if cplx else fs / 4)
            got = rg.analyse(x, cplx, fs, rg.RidgeParams()).shape
            if shape == "triangle":
                assert got in (rg.TRIANGLE, rg.SHAPE_UNKNOWN), rg.SHAPE_NAMES[got]
            elif shape in ("saw_up", "saw_down"):
                want = rg.SAWTOOTH_UP if shape == "saw_up" else rg.SAWTOOTH_DOWN
                assert got in (want, rg.SHAPE_UNKNOWN), (shape, rg.SHAPE_NAMES[got])
            else:
                assert got in (rg.HOOKED_SAWTOOTH, rg.SAWTOOTH_UP, rg.SHAPE_UNKNOWN), rg.SHAPE_NAMES[got]
                hooked += got == rg.HOOKED_SAWTOOTH
    assert hooked >= 24, hooked


@pytest.mark.parametrize("shape,want", [("saw_up", rg.SAWTOOTH_UP), ("saw_down", rg.SAWTOOTH_DOWN),
                                        ("triangle", rg.TRIANGLE)])
def test_weak_sweep_shape_from_the_line_through_the_folded_map(shape, want):
    """The demo's weak chirp (5.1 MHz in 5.102 us at 38.192 MS/s real, J/N -13 dB over the block): too weak for any
    phase bin of the folded spectrum alone, its law is found from the line sum through all of them (_line_shape):
    the shape in most blocks, never another class; noise alone never gives one (below)."""
    fs = 38.192e6
    jam = SweepJammer(shape, -2.55e6, 2.55e6, 5.102e-6)
    T = sweep_law(jam).period_s * fs
    got = [rg.folded_shape(_swept(38192, fs, False, jam, -13.0, seed, 9.548e6), False, T, rg.RidgeParams())[0]
           for seed in range(6)]
    assert set(got) <= {want, rg.SHAPE_UNKNOWN}, [rg.SHAPE_NAMES[s] for s in got]
    assert got.count(want) >= 4, [rg.SHAPE_NAMES[s] for s in got]


def test_folded_shape_of_noise_is_unknown():
    rng = np.random.default_rng(5)
    for t in range(120):
        cplx = t % 2 == 0
        n = int(rng.choice([4000, 10000, 38192]))
        x = rng.standard_normal(n) + (1j * rng.standard_normal(n) if cplx else 0.0)
        assert rg.folded_shape(x, cplx, float(rng.uniform(30, 600)), rg.RidgeParams())[0] == rg.SHAPE_UNKNOWN
