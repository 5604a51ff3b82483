"""Oracle tests of the real-jammer waveforms and front-end effects of the IF simulator (issue 14)."""

import math

import numpy as np
import pytest

from rfi_sim.if_signal import (
    CHIRP,
    CW,
    NONE,
    ChirpJammer,
    CwJammer,
    FrontEndConfig,
    IfSimulator,
    NoiseJammer,
    js_for_jn_db,
)
from rfi_sim.jammer_waveforms import SHAPES, SweepJammer, sweep_law

FS = 10e6
QUIET = -250.0  # dBm/MHz: no thermal noise to speak of


def _cplx_fe(**kw):
    base = dict(sample_rate_hz=FS, intermediate_frequency_hz=0.0, is_complex=True, bits=16,
                noise_density_dbm_per_mhz=QUIET)
    base.update(kw)
    return FrontEndConfig(**base)


def _closed_form_saw_up(tau, lo, hi, T, q):
    r0 = 2 * (hi - lo) / (T * (1 + q))
    return lo + r0 * tau + 0.5 * (q - 1) * r0 / T * tau ** 2


def test_nonlinear_saw_frequency_and_rate_follow_the_law():
    # the first recording's sweep: rate 1.35e12 -> 1.54e12 Hz/s over a sweep of 8.972 us
    T, r0, r1 = 8.972e-6, 1.35e12, 1.54e12
    lo = -6.4e6
    hi = lo + 0.5 * (r0 + r1) * T
    j = SweepJammer(shape="saw_up", low_frequency_hz=lo, high_frequency_hz=hi, sweep_period_s=T,
                    rate_ratio=r1 / r0, time_offset_s=2.1e-6)
    blk = IfSimulator(_cplx_fe(), (j,), satellites=(), seed=1).generate(4000)
    t = np.arange(4000) / FS
    tau = np.mod(t + j.time_offset_s, T)
    np.testing.assert_allclose(blk.truth.frequency_hz[0], _closed_form_saw_up(tau, lo, hi, T, r1 / r0),
                               rtol=0, atol=1e-3)
    law = sweep_law(j)
    rates = law.rate_hz_per_s(np.linspace(0, T * 0.999999, 1000))
    assert rates.min() == pytest.approx(r0, rel=1e-9) and rates.max() == pytest.approx(r1, rel=1e-6)
    # the generated phase: increment per sample = frequency at the interval's midpoint
    x = blk.values()
    dphi = np.angle(x[1:] * np.conj(x[:-1])) / (2 * np.pi) * FS
    mid = np.mod(t[:-1] + 0.5 / FS + j.time_offset_s, T)
    inside = np.diff(np.floor((t + j.time_offset_s) / T)) == 0
    err = np.mod(dphi - _closed_form_saw_up(mid, lo, hi, T, r1 / r0) + FS / 2, FS) - FS / 2  # aliased above fs/2
    assert np.max(np.abs(err[inside])) < 2e3
    np.testing.assert_array_equal(blk.truth.sweep_start_indices[0], np.flatnonzero(np.diff(tau) < 0) + 1)
    assert blk.truth.shape == ("saw_up",) and blk.truth.jammer_type == CHIRP
    assert blk.truth.sweep_period_s[0] == T


def _shape_jammer(shape):
    return SweepJammer(shape=shape, low_frequency_hz=-3e6, high_frequency_hz=3.5e6, sweep_period_s=12e-6,
                       rate_ratio=1.2, up_fraction=0.6, hook_fraction=0.2, hook_overshoot_hz=0.5e6,
                       time_offset_s=1e-6)


@pytest.mark.parametrize("shape", SHAPES)
def test_every_shape_phase_matches_its_truth_frequency(shape):
    j = _shape_jammer(shape)
    fs = 16.368e6
    blk = IfSimulator(_cplx_fe(sample_rate_hz=fs), (j,), satellites=(), seed=2).generate(6000)
    f = blk.truth.frequency_hz[0]
    lo, hi = blk.truth.swept_band_hz[0]
    assert f.min() >= lo - 1.0 and f.max() <= hi + 1.0
    assert f.max() > hi - 0.1e6 and f.min() < lo + 0.1e6
    x = blk.values()
    dphi = np.angle(x[1:] * np.conj(x[:-1])) / (2 * np.pi) * fs
    # exclude the saw-tooth jumps (the phase is continuous there) and the corners of the triangle and
    # the hook, where an interval's mean frequency is not the mean of its ends
    d2 = np.abs(np.diff(f, 2))
    corner = np.zeros(f.size - 1, dtype=bool)
    corner[:-1] |= d2 > 5e3
    corner[1:] |= d2 > 5e3
    smooth = (np.abs(np.diff(f)) < 0.2e6) & ~corner
    f_mid = 0.5 * (f[1:] + f[:-1])        # a sample interval's mean frequency, to O(rate change)
    assert np.max(np.abs(dphi - f_mid)[smooth]) < 5e3
    law = sweep_law(j)
    if shape == "triangle":  # the top is reached at up_fraction of the period
        assert float(law.frequency_hz(np.array([0.6 * 12e-6]))[0]) == pytest.approx(3.5e6, abs=1.0)
    if shape == "hooked_saw":  # the hook bottoms out at low - overshoot, 90 % into the period
        assert float(law.frequency_hz(np.array([0.9 * 12e-6]))[0]) == pytest.approx(-3.5e6, abs=1.0)
    if shape == "saw_down":
        assert np.median(np.diff(f)[smooth]) < 0


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("fif", [4.092e6, -4.092e6])
def test_real_if_is_the_real_part_of_the_shifted_baseband(shape, fif):
    # x_real[n] = sqrt(2) Re(z[n] exp(+-j 2 pi |IF| n / fs)), conjugate for spectral inversion
    fs = 16.368e6
    j = _shape_jammer(shape)
    z = IfSimulator(_cplx_fe(sample_rate_hz=fs), (j,), satellites=(), seed=2).generate(6000)
    r = IfSimulator(FrontEndConfig(sample_rate_hz=fs, intermediate_frequency_hz=fif, bits=16,
                                   noise_density_dbm_per_mhz=QUIET), (j,), satellites=(), seed=2).generate(6000)
    zz = z.values() if fif > 0 else np.conj(z.values())
    expect = math.sqrt(2.0) * np.real(zz * np.exp(2j * np.pi * abs(fif) / fs * np.arange(6000)))
    amp = float(np.max(np.abs(expect)))
    assert np.max(np.abs(r.values() - expect)) < 1e-3 * amp
    np.testing.assert_array_equal(r.truth.frequency_hz, z.truth.frequency_hz)


def test_linear_saw_up_equals_the_paper_chirp():
    fe = FrontEndConfig(sample_rate_hz=38.192e6, bits=16, noise_density_dbm_per_mhz=QUIET)
    ch = ChirpJammer(start_frequency_hz=-2e6, sweep_rate_hz_per_s=1e12, sweep_period_s=4e-6, time_offset_s=1.3e-6)
    sw = SweepJammer(shape="saw_up", low_frequency_hz=-2e6, high_frequency_hz=2e6, sweep_period_s=4e-6,
                     time_offset_s=1.3e-6, js_db=ch.js_db)
    a = IfSimulator(fe, (ch,), satellites=(), seed=3).generate(20_000)
    b = IfSimulator(fe, (sw,), satellites=(), seed=3).generate(20_000)
    np.testing.assert_allclose(b.truth.frequency_hz, a.truth.frequency_hz, atol=1e-3)
    np.testing.assert_array_equal(b.truth.sweep_start_indices[0], a.truth.sweep_start_indices[0])
    assert np.max(np.abs(b.counts.astype(int) - a.counts.astype(int))) <= 1


def test_clipped_fraction_matches_the_tone_arcsine_law():
    # real IF, fixed gain set for noise only, a CW 10 dB above it: the fraction of samples at the
    # extreme codes is P(A cos(phi) >= top) + P(A cos(phi) <= bottom) = (acos(top/A) + acos(-bottom/A)) / pi,
    # phi uniform
    fe = FrontEndConfig(sample_rate_hz=16.368e6, intermediate_frequency_hz=4.092e6, bits=8,
                        gain_mode="fixed", clip_sigma=4.0)
    jam = CwJammer(frequency_hz=0.3137e6, js_db=js_for_jn_db(fe, 10.0))
    sim = IfSimulator(fe, (jam,), satellites=(), seed=4)
    blk = sim.generate(200_000)
    amp = math.sqrt(2 * sim.jammer_power_mw(jam)) / sim.step
    tone_only = (math.acos(126.5 / amp) + math.acos(127.5 / amp)) / math.pi
    # with the thermal noise (sigma in steps) blurring the threshold: average over the tone's phase
    from scipy.stats import norm
    sig = math.sqrt(fe.noise_power_mw) / sim.step
    a_cos = amp * np.cos(np.linspace(0, 2 * np.pi, 20_000, endpoint=False))
    expect = float(np.mean(norm.sf((126.5 - a_cos) / sig) + norm.sf((a_cos + 127.5) / sig)))
    assert 0.2 < expect < 0.5 and abs(expect - tone_only) < 0.05
    assert blk.truth.clipped_fraction == pytest.approx(expect, abs=0.005)
    assert blk.truth.clipped_fraction == pytest.approx(np.mean((blk.counts == 127) | (blk.counts == -128)))


def test_switch_on_leaves_the_earlier_samples_untouched():
    fe = _cplx_fe(noise_density_dbm_per_mhz=-114.0, bits=8, gain_mode="fixed")
    on_s = 6e-3 + 0.37e-3
    jam = SweepJammer(shape="saw_up", low_frequency_hz=-4e6, high_frequency_hz=4e6, sweep_period_s=20e-6,
                      js_db=js_for_jn_db(fe, 10.0), on_time_s=on_s)
    sim = IfSimulator(fe, (jam,), satellites=(), seed=5)
    clean = IfSimulator(fe, (), satellites=(), seed=5)
    k_on = math.ceil(on_s * FS)
    for b in range(8):
        blk, ref = sim.generate(10_000), clean.generate(10_000)
        first = b * 10_000
        n_off = min(max(k_on - first, 0), 10_000)
        np.testing.assert_array_equal(blk.counts[:2 * n_off], ref.counts[:2 * n_off])
        assert blk.truth.active[0] == (n_off < 10_000)
        assert blk.truth.jammer_type == (CHIRP if n_off < 10_000 else NONE)
        if n_off == 0:
            assert blk.truth.jn_block_db[0] == pytest.approx(10.0, abs=1e-9)
        if n_off == 10_000:
            assert blk.truth.jn_block_db[0] == -np.inf and blk.truth.in_band_fraction[0] == 0.0


def test_sweep_wider_than_the_filter_is_in_band_for_the_right_fraction():
    # linear triangle over -12..+12 MHz, filter pass band -5..+5 MHz: in band (gain >= -3 dB) for
    # 10 / 24 of the time; J/N over the block = in-band J/N + 10 log10(fraction) + the filter skirts
    fe = _cplx_fe(noise_density_dbm_per_mhz=-114.0, bits=8, filter_low_hz=-4.5e6, filter_high_hz=4.5e6,
                  clip_sigma=6.0)
    jam = SweepJammer(shape="triangle", low_frequency_hz=-12e6, high_frequency_hz=12e6, sweep_period_s=9.09e-6,
                      js_db=js_for_jn_db(fe, 17.0))
    blk = IfSimulator(fe, (jam,), satellites=(), seed=6).generate(50_000)
    tr = blk.truth
    assert tr.in_band_fraction[0] == pytest.approx(9.0 / 24.0, abs=0.005)
    assert tr.jn_in_band_db[0] == pytest.approx(17.0 - 0.6, abs=0.6)  # mean |H|^2 over the pass band
    assert tr.jn_block_db[0] == pytest.approx(tr.jn_in_band_db[0] + 10 * math.log10(9 / 24), abs=0.5)
    # the samples agree: the jammer power in the block from the data, over N
    x = blk.values()
    jn_meas = 10 * math.log10(np.mean(np.abs(x) ** 2) / fe.noise_power_mw - 1.0)
    assert jn_meas == pytest.approx(tr.jn_block_db[0], abs=0.3)
    assert tr.swept_band_hz[0].tolist() == [-12e6, 12e6]


def test_agc_settles_on_the_total_power():
    fe = _cplx_fe(noise_density_dbm_per_mhz=-114.0, bits=8, gain_mode="agc", agc_time_constant_s=50e-6)
    jn = 20.0
    jam = CwJammer(frequency_hz=1.1e6, js_db=js_for_jn_db(fe, jn), on_time_s=1e-3)
    sim = IfSimulator(fe, (jam,), satellites=(), seed=7)
    first = sim.generate(10_000)  # 1 ms clean: gain stays near nominal
    assert abs(first.truth.agc_gain_db) < 0.3
    sim.generate(10_000)  # 20 time constants
    settled = sim.generate(10_000)
    expect = -10 * math.log10(1 + 10 ** (jn / 10))
    assert settled.truth.agc_gain_db == pytest.approx(expect, abs=0.3)
    assert settled.truth.jn_block_db[0] == pytest.approx(jn, abs=1e-6)  # J/N does not depend on the gain
    assert settled.truth.jammer_type == CW and first.truth.jammer_type == NONE
    # counts: the total power per real value is back at the nominal level
    p = np.mean(settled.counts.astype(float) ** 2) * settled.scale ** 2
    assert 10 * math.log10(p / (fe.noise_power_mw / 2)) == pytest.approx(0.0, abs=0.3)


def test_new_features_are_split_invariant(check_split_invariant):
    fe = _cplx_fe(noise_density_dbm_per_mhz=-114.0, bits=8, gain_mode="agc", filter_low_hz=-4e6,
                  filter_high_hz=4e6, agc_update_samples=50)
    jams = (SweepJammer(shape="hooked_saw", low_frequency_hz=-7e6, high_frequency_hz=6e6, sweep_period_s=9e-6,
                        rate_ratio=0.8, js_db=js_for_jn_db(fe, 15.0), on_time_s=1.23e-3),
            NoiseJammer(bandwidth_hz=1e6, js_db=js_for_jn_db(fe, 0.0), on_time_s=0.5e-3),
            CwJammer(frequency_hz=3.9e6, js_db=js_for_jn_db(fe, 5.0), on_time_s=2e-3))
    check_split_invariant(lambda: IfSimulator(fe, jams, seed=8), (1, 12_345, 7, 49, 17_598))


def test_low_bit_clipped_fraction_counts_the_outer_level():
    fe = FrontEndConfig(bits=2)
    blk = IfSimulator(fe, (), seed=0).generate(100_000)
    assert blk.truth.clipped_fraction == pytest.approx(np.mean(np.abs(blk.counts) == 3))


def test_invalid_sweeps_and_front_ends():
    with pytest.raises(ValueError):
        SweepJammer(shape="sine")
    with pytest.raises(ValueError):
        SweepJammer(low_frequency_hz=1e6, high_frequency_hz=1e6)
    with pytest.raises(ValueError):
        SweepJammer(rate_ratio=0.0)
    with pytest.raises(ValueError):
        SweepJammer(sweep_period_s=math.nan)
    with pytest.raises(ValueError):
        FrontEndConfig(filter_low_hz=-1e6)
    with pytest.raises(ValueError):
        FrontEndConfig(filter_low_hz=1e6, filter_high_hz=-1e6)
    with pytest.raises(ValueError):
        FrontEndConfig(gain_mode="auto")
    with pytest.raises(ValueError):
        FrontEndConfig(agc_update_samples=0)
    with pytest.raises(ValueError):
        IfSimulator(FrontEndConfig(), (CwJammer(on_time_s=math.inf),))
