"""Tests of the RfiMonitor core: stream invariance, identification, conversions, bad input, real data."""

import math
from pathlib import Path

import numpy as np
import pytest

from rfi_monitor.classifier import CHIRP, CW, NONE, UNKNOWN, WIDEBAND
from rfi_monitor.monitor import RfiMonitor, RfiMonitorParams, jammer_to_signal_db
from rfi_sim.if_signal import ChirpJammer, CwJammer, FrontEndConfig, IfSimulator, NoiseJammer

DATA = Path(__file__).parent / "data"
BLOCK = 38192  # 1 ms at the paper's 38.192 MHz


def _kalman(**kw):
    """Parameters of the per-sample (Kang et al.) estimator, which most tests here exercise; the default
    "stft" estimator has its own tests (test_stft_estimator.py)."""
    return RfiMonitorParams(estimator="kalman", **kw)


def _feed(mon, x, fe, block, first=0, traces=False):
    out = []
    for k in range(0, x.size - block + 1, block):
        out.append(mon.process(x[k:k + block], fe.sample_rate_hz, fe.intermediate_frequency_hz,
                               first + k, stamp_ns=1000 * (first + k), return_traces=traces))
    return out


def _calibrated(fe, seed=50, **kw):
    mon = RfiMonitor(_kalman(**kw))
    clean = IfSimulator(fe, (), seed=seed).generate(5 * BLOCK).values()
    _feed(mon, clean, fe, BLOCK)
    assert mon.calibrated
    mon.reset()          # calibration kept, per-sample state fresh
    return mon


def test_one_block_equals_many_blocks():
    fe = FrontEndConfig(noise_density_dbm_per_mhz=-124.0)
    x = IfSimulator(fe, (ChirpJammer(),), seed=1).generate(3 * BLOCK).values()
    par = _kalman(noise_floor_power=fe.noise_power_mw, calibration_blocks=1)
    a = RfiMonitor(par)
    ta = a.process(x, fe.sample_rate_hz, fe.intermediate_frequency_hz, 0, 0, return_traces=True).traces
    b = RfiMonitor(par)
    fs, fif = fe.sample_rate_hz, fe.intermediate_frequency_hz
    parts = [b.process(x[i:j], fs, fif, i, 0, return_traces=True).traces
             for i, j in ((0, 5000), (5000, 40001), (40001, 3 * BLOCK))]
    for name in ("sample_index", "z", "f", "df", "p11", "z_ar", "reset"):
        np.testing.assert_array_equal(np.concatenate([getattr(p, name) for p in parts]), getattr(ta, name))
    assert a.state_summary == b.state_summary
    assert ta is not None and ta.reset.sum() > 100  # the chirp was tracked with sweep resets


def test_chirp_identified_and_tracked_at_11db():
    fe = FrontEndConfig(noise_density_dbm_per_mhz=-124.0)  # J/S 30 dB, J/N 11.2 dB
    mon = _calibrated(fe, noise_density_dbm_per_mhz=-124.0)  # nominal N for J/S
    jam = ChirpJammer()
    sim = IfSimulator(fe, (jam,), seed=2)
    ests = _feed(mon, sim.generate(6 * BLOCK).values(), fe, BLOCK)
    e = ests[-1]
    assert [x.type for x in ests[1:]] == [CHIRP] * 5
    assert e.sweep_period_s == pytest.approx(jam.sweep_period_s, rel=0.01)
    assert e.jammer_to_noise_db == pytest.approx(sim.jn_db(jam), abs=0.5)
    assert e.jammer_to_signal_db == pytest.approx(30.0, abs=0.5)
    assert 5e11 < e.sweep_rate_hz_per_s < 1.2e12
    assert abs(e.sweep_start_frequency_hz - jam.start_frequency_hz) < 1e6
    assert e.confidence > 0.9 and e.valid


def test_cw_identified_with_frequency():
    fe = FrontEndConfig()
    mon = _calibrated(fe)
    jam = CwJammer(frequency_hz=1.3e6)
    ests = _feed(mon, IfSimulator(fe, (jam,), seed=3).generate(3 * BLOCK).values(), fe, BLOCK)
    e = ests[-1]
    assert e.type == CW
    assert abs(e.frequency_hz - 1.3e6) < 3 * e.frequency_std_hz
    assert e.sweep_rate_hz_per_s == 0.0 and math.isnan(e.sweep_period_s)


def test_cw_through_a_two_bit_quantiser_is_cw():
    # a 2-bit front end turns a strong CW into a near square wave: harmonic lines widen its
    # occupancy and its three-sample track becomes periodic (the quantised waveform repeats with the
    # tone's phase); it must stay CW (7/50 such cases were CHIRP in the confusion matrix)
    fe = FrontEndConfig(bits=2, noise_density_dbm_per_mhz=-128.8)     # J/S 30 dB, J/N 16 dB
    mon = _calibrated(fe)
    for f_dig in (0.0524, 0.3506):
        mon.reset()
        f_hz = f_dig * fe.sample_rate_hz - fe.intermediate_frequency_hz
        x = IfSimulator(fe, (CwJammer(frequency_hz=f_hz, phase_rad=1.0),), seed=11).generate(3 * BLOCK).values()
        ests = _feed(mon, x, fe, BLOCK)
        assert [e.type for e in ests] == [CW] * 3
        assert abs(ests[-1].frequency_hz - f_hz) < 3 * ests[-1].frequency_std_hz


def test_line_fraction_separates_cw_from_chirp():
    from rfi_monitor.classifier import CW_MIN_LINE_FRACTION, ClassifierParams, block_features
    fe = FrontEndConfig(bits=2, noise_density_dbm_per_mhz=-120.0)
    cw = IfSimulator(fe, (CwJammer(frequency_hz=2.1e6),), seed=12).generate(BLOCK).values()
    ch = IfSimulator(fe, (ChirpJammer(start_frequency_hz=-1e6, sweep_rate_hz_per_s=4e11, sweep_period_s=5e-6),),
                     seed=12).generate(BLOCK).values()
    a = block_features(cw, None, ClassifierParams())
    b = block_features(ch, None, ClassifierParams())
    assert a.line_fraction >= 0.9 > CW_MIN_LINE_FRACTION > 0.5 > b.line_fraction


def test_strong_cw_is_still_cw():
    fe = FrontEndConfig()
    mon = _calibrated(fe)
    x = IfSimulator(fe, (CwJammer(frequency_hz=-2e6, js_db=50.0),), seed=3).generate(BLOCK).values()
    e = _feed(mon, x, fe, BLOCK)[-1]
    assert e.type == CW


@pytest.mark.parametrize("jam", [NoiseJammer(bandwidth_hz=30e6), NoiseJammer(bandwidth_hz=2e6)])
def test_noise_jammer_is_wideband(jam):
    fe = FrontEndConfig()
    mon = _calibrated(fe)
    ests = _feed(mon, IfSimulator(fe, (jam,), seed=4).generate(4 * BLOCK).values(), fe, BLOCK)
    assert all(e.type == WIDEBAND for e in ests)
    assert all(math.isnan(e.frequency_hz) for e in ests)


def test_clean_is_none_and_calibration_is_unknown():
    fe = FrontEndConfig()
    mon = RfiMonitor(_kalman())
    ests = _feed(mon, IfSimulator(fe, (), seed=5).generate(10 * BLOCK).values(), fe, BLOCK)
    assert [e.type for e in ests[:5]] == [UNKNOWN] * 5
    assert [e.type for e in ests[5:]] == [NONE] * 5


def test_spectral_inversion_and_complex_frequency_sign():
    for fe in (FrontEndConfig(intermediate_frequency_hz=-9.548e6),
               FrontEndConfig(sample_rate_hz=16.368e6, intermediate_frequency_hz=0.0, is_complex=True)):
        mon = _calibrated(fe)
        n = int(fe.sample_rate_hz * 1e-3)
        x = IfSimulator(fe, (CwJammer(frequency_hz=1.1e6),), seed=6).generate(2 * n).values()
        e = _feed(mon, x, fe, n)[-1]
        assert e.type == CW
        assert e.frequency_hz == pytest.approx(1.1e6, abs=1e5)


def test_complex_chirp_tracked():
    fe = FrontEndConfig(sample_rate_hz=38.192e6, intermediate_frequency_hz=0.0, is_complex=True,
                        noise_density_dbm_per_mhz=-127.0)
    mon = _calibrated(fe)
    jam = ChirpJammer(start_frequency_hz=-4e6, sweep_period_s=8e-6)
    ests = _feed(mon, IfSimulator(fe, (jam,), seed=7).generate(5 * BLOCK).values(), fe, BLOCK)
    e = ests[-1]
    assert e.type == CHIRP
    assert e.sweep_period_s == pytest.approx(8e-6, rel=0.01)


def test_gap_and_rate_change_reset_state():
    fe = FrontEndConfig()
    x = IfSimulator(fe, (), seed=8).generate(3 * 4096).values()
    mon = RfiMonitor(_kalman(calibration_blocks=1))
    mon.process(x[:4096], fe.sample_rate_hz, fe.intermediate_frequency_hz, 0, 0)
    e = mon.process(x[4096:8192], fe.sample_rate_hz, fe.intermediate_frequency_hz, 9999, 0)
    assert e.counters["gaps"] == 1
    e = mon.process(x[8192:], 2 * fe.sample_rate_hz, fe.intermediate_frequency_hz, 0, 0)
    assert e.counters["rate_changes"] == 1 and e.type == UNKNOWN  # learning again


def test_bad_input_raises():
    mon = RfiMonitor(_kalman())
    x = np.zeros(4096)
    with pytest.raises(ValueError):
        mon.process(np.zeros(0), 4e6, 0.0, 0, 0)
    with pytest.raises(ValueError):
        mon.process(x, 0.0, 0.0, 0, 0)
    with pytest.raises(ValueError):
        mon.process(x, -4e6, 0.0, 0, 0)
    with pytest.raises(ValueError):
        mon.process(x, float("nan"), 0.0, 0, 0)
    with pytest.raises(ValueError):
        mon.process(np.zeros(4097, dtype=np.int8), 4e6, 0.0, 0, 0, is_complex=True)
    with pytest.raises(ValueError):
        mon.process(x, 4e6, 2.5e6, 0, 0)
    with pytest.raises(ValueError):
        mon.process(np.zeros((2, 2048)), 4e6, 0.0, 0, 0)
    with pytest.raises(ValueError):
        _kalman(phase_gain=0.0)
    with pytest.raises(ValueError):
        _kalman(noise_floor_power=-1.0)


def test_nan_blocks_are_rejected_clipped_blocks_analysed():
    fe = FrontEndConfig()
    mon = _calibrated(fe)
    x = IfSimulator(fe, (CwJammer(),), seed=9).generate(BLOCK).values()
    x[::10] = np.nan
    e = mon.process(x, fe.sample_rate_hz, fe.intermediate_frequency_hz, 0, 0)
    assert not e.valid and e.type == UNKNOWN and e.confidence == 0.0 and math.isnan(e.frequency_hz)
    assert e.counters["non_finite_samples"] == x[::10].size and e.counters["blocks_rejected"] == 1
    c = np.clip(np.round(IfSimulator(fe, (), seed=9).generate(BLOCK).values() / 1e-6), -3, 3)
    e = mon.process(c, fe.sample_rate_hz, fe.intermediate_frequency_hz, BLOCK, 0, full_scale=3.0)
    # issue 14 item 2: clipping is evidence, not a reason to drop the block (it was rejected before)
    n_clip = int(np.sum(np.abs(c) >= 3.0))
    assert e.valid and e.counters["saturated_samples"] == n_clip and e.counters["clipped_blocks"] == 1
    assert e.clipped_fraction == pytest.approx(n_clip / c.size)
    assert e.jammer_to_noise_is_lower_bound == (e.type != NONE)


# ---------------------------------------------------------------- real captures (no jammer)
def _real_captures():
    iq = np.fromfile(DATA / "pocketsdr_L1_4MHz_IQ_10ms.bin", dtype=np.int8)
    re = np.fromfile(DATA / "pocketsdr_L1_12MHz_I_10ms.bin", dtype=np.int8)
    gs = np.fromfile(DATA / "gnsssdr_cttc_4Msps_4ms.dat", dtype=np.complex64)
    return [("pocketsdr 4 MHz IQ", iq, 4e6, 0.0, True, 4000),
            ("pocketsdr 12 MHz I", re, 12e6, 3e6, False, 12000),
            ("gnss-sdr 4 MHz", gs, 4e6, 0.0, None, 2000)]


@pytest.mark.parametrize("name,x,fs,fif,cplx,block", _real_captures())
def test_real_capture_no_false_alarm(name, x, fs, fif, cplx, block):
    mon = RfiMonitor(_kalman())
    step = 2 * block if (cplx and not np.iscomplexobj(x)) else block
    types = []
    for k in range(0, x.size - step + 1, step):
        e = mon.process(x[k:k + step], fs, fif, k // (step // block), 0, is_complex=cplx)
        types.append(e.type)
    assert types[:5] == [UNKNOWN] * 5
    assert all(t == NONE for t in types[5:]), f"{name}: {types}"


def test_real_capture_plus_simulated_chirp_detected_and_tracked():
    raw = np.fromfile(DATA / "pocketsdr_L1_12MHz_I_10ms.bin", dtype=np.int8).astype(np.float64)
    fs, fif = 12e6, 3e6
    # scale: treat the 2-bit counts as the noise power reference (noise ~ mean(x^2) counts^2)
    n_pow = float(np.mean(raw ** 2))
    fe = FrontEndConfig(sample_rate_hz=fs, intermediate_frequency_hz=fif, bits=16,
                        noise_density_dbm_per_mhz=10 * math.log10(n_pow / 6.0))  # N over 6 MHz
    jam = ChirpJammer(start_frequency_hz=-1.5e6, sweep_rate_hz_per_s=2e11, sweep_period_s=15e-6,
                      js_db=10 * math.log10(n_pow / fe.signal_power_mw) + 10.0)  # J/N = 10 dB
    block = 12000
    mon = RfiMonitor(_kalman())
    for k in range(5):
        mon.process(raw[k * block:(k + 1) * block], fs, fif, k * block, 0)
    sim = IfSimulator(fe, (jam,), satellites=(), seed=0)
    sim.generate(5 * block, add_to=np.zeros(5 * block))   # advance to the same time
    x = sim.generate(5 * block, add_to=raw[5 * block:]).values()
    ests = [mon.process(x[k * block:(k + 1) * block], fs, fif, (5 + k) * block, 0) for k in range(5)]
    assert ests[-1].type == CHIRP
    assert ests[-1].sweep_period_s == pytest.approx(15e-6, rel=0.01)
    assert ests[-1].jammer_to_noise_db == pytest.approx(10.0, abs=1.0)


def test_fast_chirp_locked_by_the_periodicity_detector():
    # 1e13 Hz/s over 5.1 MHz: a 19.5-sample period, faster than the LPD's smoothing (ours)
    fe = FrontEndConfig(noise_density_dbm_per_mhz=-124.0)
    mon = _calibrated(fe, noise_density_dbm_per_mhz=-124.0)
    jam = ChirpJammer(sweep_rate_hz_per_s=1e13, sweep_period_s=ChirpJammer().bandwidth_hz / 1e13)
    e = _feed(mon, IfSimulator(fe, (jam,), seed=12).generate(3 * BLOCK).values(), fe, BLOCK)[-1]
    assert e.type == CHIRP
    assert e.sweep_period_s == pytest.approx(jam.sweep_period_s, rel=0.01)


def test_paper_method_parameters():
    p = RfiMonitorParams.paper_method(phase_gain=0.5)
    assert p.refine_window == 0 and not p.analysis.enabled and not p.sweep.lattice_voting
    assert p.sweep.decimation == 2              # its best setting (monitor.paper_method docstring)
    assert p.phase_gain == 0.5
    kal = _kalman()
    assert kal.sweep.lattice_voting and kal.analysis.enabled and RfiMonitorParams().estimator == "stft"
    with pytest.raises(ValueError):
        _kalman(refine_window=99)


@pytest.mark.parametrize("refine", [24, 0])
def test_resets_do_not_depend_on_unaligned_block_cuts(refine):
    # the LPD peaks act on the reset lattice at the end of aligned 16-sample windows, also when a
    # block ends inside one: resets and the filter track are those of one block
    fe = FrontEndConfig(noise_density_dbm_per_mhz=-124.0)
    fs, fif = fe.sample_rate_hz, fe.intermediate_frequency_hz
    x = IfSimulator(fe, (ChirpJammer(sweep_rate_hz_per_s=3e12),), seed=3).generate(2 * BLOCK).values()
    par = _kalman(noise_floor_power=fe.noise_power_mw, calibration_blocks=1, refine_window=refine)
    ta = RfiMonitor(par).process(x, fs, fif, 0, 0, return_traces=True).traces
    cuts = np.cumsum(np.random.default_rng(1).integers(1024, 3000, 60))
    cuts = np.r_[0, cuts[cuts < x.size - 1024], x.size]
    b = RfiMonitor(par)
    parts = [b.process(x[i:j], fs, fif, int(i), 0, return_traces=True).traces
             for i, j in zip(cuts[:-1], cuts[1:], strict=True)]
    assert ta is not None and ta.reset.sum() > 50
    tb = [p for p in parts if p is not None]
    assert len(tb) == len(parts)
    np.testing.assert_array_equal(np.concatenate([p.reset for p in tb]), ta.reset)
    np.testing.assert_allclose(np.concatenate([p.f for p in tb]), ta.f, rtol=0, atol=1e-9)


@pytest.mark.parametrize("cplx", [False, True])
def test_welch_psd_equals_the_direct_formula(cplx):
    from rfi_monitor.classifier import welch_psd
    rng = np.random.default_rng(4)
    x = rng.standard_normal(5000) + (1j * rng.standard_normal(5000) if cplx else 0.0)
    nfft = 256
    for max_frames in (8, 256):
        psd, frames = welch_psd(x, nfft, max_frames)
        nfr = x.size // nfft
        fr = x[:nfr * nfft].reshape(nfr, nfft)
        if nfr > max_frames:
            fr = fr[np.linspace(0, nfr - 1, max_frames).astype(np.int64)]
        spec = (np.fft.fft if cplx else np.fft.rfft)(fr * np.hanning(nfft), axis=1)
        p = np.mean(np.abs(spec) ** 2, axis=0)
        p = np.fft.fftshift(p) if cplx else p
        ref = p * np.mean(np.abs(fr) ** 2) / p.sum()
        assert frames == fr.shape[0]
        # the FFT runs in single precision (classifier.welch_psd): each bin to float32 accuracy
        # (measured 1.1e-7 relative), the total power exactly (it is computed in double)
        np.testing.assert_allclose(psd, ref, rtol=1e-6)
        assert math.isclose(psd.sum(), np.mean(np.abs(fr) ** 2), rel_tol=1e-12)


# ---------------------------------------------------------------- blocks that carry no information
def test_blank_blocks_are_rejected_and_never_enter_the_calibration():
    """All-zero samples, or non-zero samples only where the Hann window is zero, hold no power in the Welch
    frames: rejected as blank_block (before: NaN PSD, and a NaN noise template for good during calibration)."""
    fe = FrontEndConfig()
    mon = RfiMonitor(_kalman())
    fs, fif = fe.sample_rate_hz, fe.intermediate_frequency_hz
    x = IfSimulator(fe, (), seed=20).generate(8 * BLOCK).values()
    zero = np.zeros(BLOCK)
    on_window_zeros = np.zeros(BLOCK)
    on_window_zeros[::256] = 1.0          # the first sample of every 256-sample Welch frame: Hann weight 0
    for k, blank in enumerate((zero, on_window_zeros)):
        with np.errstate(all="raise"):    # no 0/0 on the way
            e = mon.process(blank, fs, fif, k * BLOCK, k)
        assert not e.valid and e.rejection == "blank_block" and e.type == UNKNOWN and e.confidence == 0.0
        assert math.isnan(e.jammer_to_noise_db)
    ests = _feed(mon, x, fe, BLOCK, first=2 * BLOCK)
    assert [e.type for e in ests[:5]] == [UNKNOWN] * 5 and mon.calibrated
    assert [e.type for e in ests[5:]] == [NONE] * 3
    assert ests[-1].counters["blocks_rejected"] == 2


def test_block_far_off_the_noise_floor_is_rejected_then_relearned():
    """A block 10 dB or more below the calibrated floor (gain or scale no longer as calibrated) says neither "no
    jammer" nor a J/N, and one 120 dB above it (scale 1e150 gave WIDEBAND with J/N 300 dB) measures the scale,
    not a jammer: both rejected; when it lasts calibration_blocks blocks the floor is learned again."""
    fe = FrontEndConfig()
    mon = _calibrated(fe)
    fs, fif = fe.sample_rate_hz, fe.intermediate_frequency_hz
    x = IfSimulator(fe, (), seed=21).generate(12 * BLOCK).values()
    e = mon.process(x[:BLOCK] * 1e-6, fs, fif, 0, 0)
    assert not e.valid and e.rejection == "below_noise_floor"
    e = mon.process(x[:BLOCK] * 1e7, fs, fif, 0, 0)                 # +140 dB
    assert not e.valid and e.rejection == "implausible_power" and math.isnan(e.jammer_to_noise_db)
    e = mon.process(x[:BLOCK] * 1e5, fs, fif, 0, 0)                 # +100 dB: a (very strong) wideband jammer
    assert e.valid and e.type == WIDEBAND and e.jammer_to_noise_db == pytest.approx(100.0, abs=0.5)
    e = mon.process(x[BLOCK:2 * BLOCK] * 0.5, fs, fif, BLOCK, 0)     # -6 dB: still a working front end
    assert e.valid and e.type == NONE
    quiet = _feed(mon, x[2 * BLOCK:] * 0.1, fe, BLOCK, first=2 * BLOCK)   # -20 dB for good
    assert [e.rejection for e in quiet[:5]] == ["below_noise_floor"] * 5
    assert quiet[4].counters["recalibrations"] == 1
    assert [e.type for e in quiet[5:]] == [UNKNOWN] * 5       # learning the new floor
    assert mon.calibrated
    # a fixed noise floor is never relearned
    fixed = RfiMonitor(_kalman(noise_floor_power=float(np.mean(x ** 2)), calibration_blocks=1))
    out = _feed(fixed, x * 0.01, fe, BLOCK)
    assert {e.rejection for e in out[1:]} == {"below_noise_floor"} and out[-1].counters["recalibrations"] == 0


def test_none_always_carries_a_finite_jn():
    """A clean block whose power is below the floor and that has no occupied bin used to give NONE with
    J/N = NaN (10 log10 of a negative excess); J/N is now at least the block power's resolution. Its J/S is NaN
    (issue 27 item 5: no jammer, no J/S)."""
    for fe in (FrontEndConfig(), FrontEndConfig(sample_rate_hz=16.368e6, intermediate_frequency_hz=0.0,
                                                is_complex=True)):
        n = 16384
        mon = RfiMonitor(_kalman())
        ests = _feed(mon, IfSimulator(fe, (), seed=22).generate(45 * n).values(), fe, n)
        none = [e for e in ests if e.type == NONE]
        assert len(none) == 40
        floor_db = 5 * math.log10((1.0 if fe.is_complex else 2.0) / n)
        assert all(math.isfinite(e.jammer_to_noise_db) and e.jammer_to_noise_db >= floor_db - 1e-9 for e in none)
        assert all(math.isnan(e.jammer_to_signal_db) for e in none)
        assert sum(e.jammer_to_noise_db == pytest.approx(floor_db) for e in none) >= 5   # the censored ones


@pytest.mark.parametrize("cplx", [False, True])
def test_none_carries_no_jammer_to_signal(cplx):
    """Issue 27 item 5: a block reported NONE published J/S = J/N + N - S of its J/N resolution (about -2 dB in the
    demo), which the report plotted as a measured J/S. Default ("stft") estimator, full and light analyses, and the
    J/S function itself: NaN for NONE; a jammer's J/S is J/N + N - S."""
    fe = (FrontEndConfig(sample_rate_hz=16.368e6, intermediate_frequency_hz=0.0, is_complex=True) if cplx
          else FrontEndConfig())
    n = 16384
    params = RfiMonitorParams(noise_bandwidth_hz=2e6)
    mon = RfiMonitor(params)
    x = IfSimulator(fe, (), seed=23).generate(30 * n).values()
    ests = [mon.process(x[k * n:(k + 1) * n], fe.sample_rate_hz, fe.intermediate_frequency_hz, k * n,
                        k * 1_000_000, is_complex=cplx, light=k >= 20) for k in range(30)]
    none = [e for e in ests if e.type == NONE]
    assert len(none) >= 20 and any(e.light for e in none) and any(not e.light for e in none)
    assert all(math.isfinite(e.jammer_to_noise_db) and math.isnan(e.jammer_to_signal_db) for e in none)
    # N = -114 dBm/MHz over 2 MHz = -110.99 dBm, S = -130 dBm: J/S = J/N + 19.01 dB for a jammer, NaN without one
    assert jammer_to_signal_db(CW, 3.0, fe.sample_rate_hz, cplx, params) == pytest.approx(3.0 + 19.0103, abs=1e-3)
    assert math.isnan(jammer_to_signal_db(NONE, 3.0, fe.sample_rate_hz, cplx, params))
    assert math.isnan(jammer_to_signal_db(CHIRP, math.nan, fe.sample_rate_hz, cplx, params))


def test_calibration_that_saw_no_noise_is_discarded():
    """A calibration whose learned floor is below MIN_BLOCK_POWER (blocks of pure narrowband excess: a tone with
    no noise leaves 1e-4 of its power outside its line) would later divide by ~0: it is discarded and learned
    again."""
    fe = FrontEndConfig()
    fs, fif = fe.sample_rate_hz, fe.intermediate_frequency_hz
    mon = RfiMonitor(_kalman(calibration_blocks=3))
    tone = 1e-29 * np.cos(2 * np.pi * 0.2 * np.arange(4 * BLOCK))    # power 5e-59 >= MIN_BLOCK_POWER 1e-60
    ests = _feed(mon, tone, fe, BLOCK)
    assert all(e.valid and e.type == UNKNOWN for e in ests)
    assert not mon.calibrated and ests[2].counters["calibrations_discarded"] == 1
    assert ests[3].counters["calibrations_discarded"] == 1     # the fourth block starts the new calibration
    mon = RfiMonitor(_kalman(calibration_blocks=3))   # the same tone at a real level calibrates
    _feed(mon, tone * 1e29, fe, BLOCK)
    assert mon.calibrated
    e = mon.process(tone[:BLOCK] * 1e29, fs, fif, 4 * BLOCK, 0)
    assert e.valid and math.isfinite(e.jammer_to_noise_db) and 0.0 <= e.confidence <= 1.0
