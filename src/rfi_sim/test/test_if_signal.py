"""Oracle tests of the IF signal simulator (the C/A code generator's own tests: gnss_common/test/test_gps_ca.py)."""

import math

import numpy as np
import pytest

from gnss_common.gps_ca import ca_code
from rfi_sim.if_signal import (
    CHIRP,
    CW,
    ChirpJammer,
    CwJammer,
    FrontEndConfig,
    GpsSatellite,
    IfSimulator,
    NoiseJammer,
    simulate,
)


@pytest.mark.parametrize("cplx", [False, True])
def test_chirp_instantaneous_frequency_equals_closed_form(cplx):
    fs = 38.192e6
    fe = FrontEndConfig(sample_rate_hz=fs, intermediate_frequency_hz=0.0 if cplx else 9.548e6,
                        is_complex=cplx, bits=16, noise_density_dbm_per_mhz=-250.0)
    jam = ChirpJammer(start_frequency_hz=-2e6, sweep_rate_hz_per_s=1e12, sweep_period_s=4e-6,
                      time_offset_s=1.3e-6)
    sim = IfSimulator(fe, (jam,), satellites=(), seed=1)
    n = 2000
    blk = sim.generate(n)
    t = np.arange(n) / fs
    tau = np.mod(t + jam.time_offset_s, jam.sweep_period_s)
    np.testing.assert_allclose(blk.truth.frequency_hz[0], -2e6 + 1e12 * tau, rtol=0, atol=1e-3)
    if cplx:
        # phase increment between samples n, n+1 = 2 pi f(t_{n+1/2}) / fs for a linear chirp
        x = blk.values()
        dphi = np.angle(x[1:] * np.conj(x[:-1]))
        f_mid = -2e6 + 1e12 * np.mod(t[:-1] + 0.5 / fs + jam.time_offset_s, jam.sweep_period_s)
        inside = np.diff(np.floor((t + jam.time_offset_s) / jam.sweep_period_s)) == 0
        np.testing.assert_allclose(dphi[inside] / (2 * np.pi) * fs, f_mid[inside], atol=2e3)
    # sweep starts where tau wraps
    starts = blk.truth.sweep_start_indices[0]
    np.testing.assert_array_equal(starts, np.flatnonzero(np.diff(tau) < 0) + 1)


def test_paper_defaults():
    jam = ChirpJammer()
    fe = FrontEndConfig()
    assert fe.digital_frequency(jam.start_frequency_hz) == pytest.approx(0.1832)
    assert fe.digital_frequency(0.0) == pytest.approx(0.25)
    assert jam.sweep_rate_hz_per_s == 1e12 and jam.js_db == 30.0


@pytest.mark.parametrize("jam", [ChirpJammer(js_db=35.0), CwJammer(frequency_hz=1e6, js_db=35.0),
                                 NoiseJammer(bandwidth_hz=4e6, js_db=35.0)])
def test_measured_jn_matches_request(jam):
    fe = FrontEndConfig(bits=16)
    sim = IfSimulator(fe, (jam,), seed=3)
    x = sim.generate(200_000).values()
    n = fe.noise_power_mw
    jn_meas = 10 * math.log10(np.mean(x ** 2) / n - 1.0)
    assert jn_meas == pytest.approx(sim.jn_db(jam), abs=0.5)


def test_jn_complex_front_end():
    fe = FrontEndConfig(sample_rate_hz=4e6, intermediate_frequency_hz=0.0, is_complex=True, bits=16)
    jam = CwJammer(frequency_hz=3e5, js_db=25.0)
    sim = IfSimulator(fe, (jam,), seed=4)
    x = sim.generate(100_000).values()
    jn_meas = 10 * math.log10(np.mean(np.abs(x) ** 2) / fe.noise_power_mw - 1.0)
    assert jn_meas == pytest.approx(sim.jn_db(jam), abs=0.5)


@pytest.mark.parametrize("cplx,bits", [(False, 2), (True, 4), (False, 8), (True, 16)])
def test_chunked_equals_whole(cplx, bits, check_split_invariant):
    fe = FrontEndConfig(sample_rate_hz=16.368e6, intermediate_frequency_hz=0.0 if cplx else 4.092e6,
                        is_complex=cplx, bits=bits)
    jams = (ChirpJammer(start_frequency_hz=-3e6, sweep_period_s=6e-6), NoiseJammer(js_db=20.0),
            CwJammer(frequency_hz=5e5, js_db=10.0))
    sats = (GpsSatellite(prn=3, doppler_hz=-2500.0, code_phase_chips=100.5), GpsSatellite(prn=7))
    parts = check_split_invariant(lambda: IfSimulator(fe, jams, sats, seed=11), (1, 12_345, 7, 20_000, 17_647))
    assert parts[1].first_sample_index == 1


@pytest.mark.parametrize("bits,levels", [(1, {-1, 1}), (2, {-3, -1, 1, 3})])
def test_low_bit_quantiser_levels(bits, levels):
    blk = simulate(20_000, FrontEndConfig(bits=bits), seed=0)
    assert set(np.unique(blk.counts).tolist()) == levels
    assert blk.counts.dtype == np.int8


def test_two_bit_agc_threshold_at_one_sigma():
    blk = simulate(100_000, FrontEndConfig(bits=2), seed=0)
    frac_mag3 = np.mean(np.abs(blk.counts) == 3)
    assert frac_mag3 == pytest.approx(0.3173, abs=0.01)  # P(|x| > sigma) for Gaussian


def test_gps_signal_correlates_with_its_code():
    fs = 4.092e6
    fe = FrontEndConfig(sample_rate_hz=fs, intermediate_frequency_hz=0.0, is_complex=True, bits=16,
                        noise_density_dbm_per_mhz=-250.0)
    blk = simulate(4092, fe, satellites=(GpsSatellite(prn=5, doppler_hz=0.0, code_phase_chips=0.0),), seed=0)
    x = blk.values()
    chips = np.floor(np.arange(4092) * 1.023e6 / fs).astype(int) % 1023
    rep = ca_code(5)[chips].astype(float)
    wrong = ca_code(6)[chips].astype(float)
    assert abs(np.vdot(rep, x)) > 20 * abs(np.vdot(wrong, x))


def test_invalid_configs():
    with pytest.raises(ValueError):
        FrontEndConfig(sample_rate_hz=0.0)
    with pytest.raises(ValueError):
        FrontEndConfig(bits=17)
    with pytest.raises(ValueError):
        FrontEndConfig(sample_rate_hz=4e6, intermediate_frequency_hz=3e6)
    with pytest.raises(ValueError):
        IfSimulator(FrontEndConfig(), (ChirpJammer(sweep_period_s=0.0),))


def test_truth_types():
    assert simulate(1000, jammers=(CwJammer(),)).truth.jammer_type == CW
    assert simulate(1000, jammers=(ChirpJammer(), CwJammer(js_db=10.0))).truth.jammer_type == CHIRP
