"""The spectral-step test (rfi_monitor.spectral_step): a noise jammer in part of the band behind an AGC.

Pure tier: Gaussian noise with a band-limited noise jammer added, the block power normalised (an AGC) and
quantised to 2 bits, through the classifier's Welch PSD; and the monitor on rfi_sim's 2-bit AGC front end."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rfi_monitor.classifier import WIDEBAND, welch_psd
from rfi_monitor.monitor import REF_LEARNED, RfiMonitor, RfiMonitorParams
from rfi_monitor.spectral_step import (
    SpectralStep,
    SpectralStepParams,
    hann_bin_correlation,
    threshold_z,
)
from rfi_sim.if_signal import FrontEndConfig, IfSimulator, NoiseJammer, js_for_jn_db

NFFT = 256
N = 4096          # samples per block


def _block(rng: np.random.Generator, cplx: bool, jn_db: float | None, band: tuple[float, float],
           two_bit: bool = True) -> np.ndarray:
    """Noise (+ a noise jammer flat over ``band``, cycles/sample, J/N over the sampled band), power normalised
    to 1 (AGC), optionally quantised to 2 bits (levels +-1, +-3, threshold at 1 sigma)."""
    x = rng.standard_normal(N) + (1j * rng.standard_normal(N) if cplx else 0.0)
    if jn_db is not None:
        j = rng.standard_normal(N) + 1j * rng.standard_normal(N)
        f = np.fft.fftfreq(N)
        spec = np.fft.fft(j) * ((f >= band[0]) & (f < band[1]))
        j = np.fft.ifft(spec)
        if not cplx:
            j = j.real
        j *= math.sqrt(10 ** (jn_db / 10) * np.mean(np.abs(x) ** 2) / np.mean(np.abs(j) ** 2))
        x = x + j
    if cplx:
        x = x / math.sqrt(np.mean(np.abs(x) ** 2) / 2)
    else:
        x = x / math.sqrt(np.mean(x ** 2))
    if two_bit:
        q = lambda v: np.sign(v) * np.where(np.abs(v) > 1.0, 3.0, 1.0)   # noqa: E731
        x = q(x.real) + 1j * q(x.imag) if cplx else q(x)
    return x


def _feed(st: SpectralStep, x: np.ndarray, k: int, learn: bool = True):
    psd, frames = welch_psd(x, NFFT, 10 ** 6)
    d = st.test(psd / psd.sum(), frames, np.iscomplexobj(x), stamp_ns=k * 1_000_000)
    if learn and not d.detected:
        st.learn()
    return d


def test_hann_bin_correlation_is_the_windows():
    rho = hann_bin_correlation(256)
    assert rho[0] == pytest.approx(1.0)
    assert rho[1] == pytest.approx(4 / 9, rel=1e-9)
    assert rho[2] == pytest.approx(1 / 36, rel=1e-9)
    assert rho[3] == pytest.approx(0.0, abs=1e-12)


def test_threshold_is_bonferroni_over_bands_and_scales():
    # 64 groups, bands of 2..32 groups: sum_{L=2}^{32} (65 - L) = 1488 bands, 6 scales
    z = threshold_z(64, 0.5, 6, 1e-4)
    assert z == pytest.approx(5.584, abs=0.01)
    assert threshold_z(64, 0.5, 6, 1e-3) < z


@pytest.mark.parametrize("cplx", [True, False])
def test_no_false_alarm_on_noise(cplx):
    """2,000 blocks of 2-bit noise behind an AGC, decisions at every block: none reported (bound 1e-4 per block
    by construction; Bonferroni is conservative), and the variance model is not too tight: the largest z stays
    below the threshold by a margin."""
    rng = np.random.default_rng(11 if cplx else 12)
    st = SpectralStep(SpectralStepParams(decide_interval_s=0.0), NFFT)
    zs = []
    for k in range(2000):
        d = _feed(st, _block(rng, cplx, None, (0, 0)), k)
        assert not d.detected
        if d.tested:
            zs.append(d.z)
    assert len(zs) >= 1990
    assert max(zs) < threshold_z(64 if cplx else 63, 0.5, 6, 1e-4) - 0.3


@pytest.mark.parametrize("cplx", [True, False])
def test_partial_band_jammer_behind_an_agc_is_found_with_its_band(cplx):
    """J/N -5 dB over the sampled band, the jammer in 30 % of it, the block power normalised and quantised to 2
    bits: found within 30 blocks of 4,096 samples after a 100-block reference, its band within two groups, its
    J/N within 3 dB (the 2-bit quantiser compresses it)."""
    rng = np.random.default_rng(3)
    band = (0.05, 0.20) if cplx else (0.10, 0.25)        # cycles/sample
    st = SpectralStep(SpectralStepParams(), NFFT)
    for k in range(100):
        assert not _feed(st, _block(rng, cplx, None, band), k).detected
    found = None
    for k in range(100, 130):
        d = _feed(st, _block(rng, cplx, -5.0, band), k)
        if d.detected:
            found = (k, d)
            break
    assert found is not None
    k, d = found
    group = (4 if cplx else 2) / NFFT          # cycles/sample per group (4 bins of 256 / 2 bins of 129)
    assert abs(d.low - band[0]) <= 2 * group and abs(d.high - band[1]) <= 2 * group
    assert d.jn_db == pytest.approx(-5.0, abs=3.0)
    assert d.step_db >= SpectralStepParams().min_step_db and d.z > d.threshold


def test_a_jammer_never_becomes_the_reference():
    """While the step is seen the reference does not learn; once the jammer is gone nothing is reported."""
    rng = np.random.default_rng(5)
    band = (0.0, 0.2)
    st = SpectralStep(SpectralStepParams(decide_interval_s=0.0), NFFT)
    for k in range(50):
        _feed(st, _block(rng, True, None, band), k)
    before = st.reference_blocks
    hits = 0
    for k in range(50, 350):
        d = _feed(st, _block(rng, True, 0.0, band), k)
        hits += d.detected
        assert not st.learn()          # the block just tested showed the step: refused
    assert hits == 300
    assert st.reference_blocks == pytest.approx(before)
    st.restart()
    late = [_feed(st, _block(rng, True, None, band), k).detected for k in range(1350, 1400)]
    assert not any(late)


def test_a_jammer_in_the_reference_that_switches_off():
    """A jammer on while the reference was learned, then off (30 % or 70 % of the band, centred or at one edge):
    the block is flat again, y = P / R = c / R, which the line in x = 1 / R explains (step 2): never reported,
    and the clean blocks enter the reference at once (no run of z over learn_z, no relearn needed)."""
    rng = np.random.default_rng(6)
    for band in ((-0.15, 0.15), (-0.35, 0.35), (-0.5, 0.2), (-0.5, -0.2)):
        st = SpectralStep(SpectralStepParams(decide_interval_s=0.0, relearn_after_s=0.05), NFFT)
        for k in range(100):
            _feed(st, _block(rng, True, 3.0, band), k)
        before = st.reference_blocks
        ds = [_feed(st, _block(rng, True, None, band), k) for k in range(100, 200)]
        assert not any(d.detected for d in ds), band
        assert st.relearned == 0 and st.reference_blocks > before, band


def test_a_changed_front_end_is_relearned():
    """A shape that no band explains (here a wide tilt across the band, as a front end's filter changed) for
    relearn_after_s: the reference is learned again, and the reports (if any) stop."""
    rng = np.random.default_rng(9)
    st = SpectralStep(SpectralStepParams(decide_interval_s=0.0, relearn_after_s=0.05), NFFT)
    for k in range(100):
        _feed(st, _block(rng, True, None, (0, 0)), k)
    tilt = np.linspace(0.5, 2.0, N)

    def tilted(k: int) -> np.ndarray:
        x = _block(rng, True, None, (0, 0), two_bit=False)
        return np.fft.ifft(np.fft.fft(x) * np.sqrt(np.fft.ifftshift(tilt)))

    ds = [_feed(st, tilted(k), k) for k in range(100, 200)]
    assert st.relearned >= 1
    assert not any(d.detected for d in ds[60:])


def test_untested_until_the_reference_has_its_blocks_and_on_a_new_layout():
    rng = np.random.default_rng(7)
    st = SpectralStep(SpectralStepParams(min_reference_blocks=5, decide_interval_s=0.0), NFFT)
    ds = [_feed(st, _block(rng, True, None, (0, 0)), k) for k in range(7)]
    assert [d.tested for d in ds] == [False] * 5 + [True] * 2
    # real input: another layout, a new reference
    assert not _feed(st, _block(rng, False, None, (0, 0)), 8).tested
    assert st.reference_blocks == pytest.approx(1.0)


def test_decide_interval_reuses_the_last_decision():
    rng = np.random.default_rng(8)
    st = SpectralStep(SpectralStepParams(decide_interval_s=0.01), NFFT)
    ds = [_feed(st, _block(rng, True, None, (0, 0)), k) for k in range(30)]
    tested = [d for d in ds if d.tested]
    # one test per 10 ms of stamps (1 ms blocks) once the reference is ready: the same object in between
    assert len({id(d) for d in tested}) == 3


@pytest.mark.parametrize("kw", [dict(groups=4), dict(false_alarm_per_block=0.0), dict(min_step_db=0.0),
                                dict(max_band_fraction=0.6), dict(reference_blocks=0), dict(learn_z=-1.0),
                                dict(window_s=math.nan), dict(decide_interval_s=-1.0),
                                dict(relearn_after_s=-1.0)])
def test_bad_parameters_raise(kw):
    with pytest.raises(ValueError):
        SpectralStepParams(**kw)


def test_monitor_reports_the_band_of_a_noise_jammer_behind_a_2_bit_agc():
    """rfi_sim's 2-bit I/Q front end with an AGC, 4 MS/s, 1 ms blocks: 60 clean blocks, then a noise jammer of
    1 MHz at +0.75 MHz, J/N -3 dB over the sampled band. Before: NONE (the AGC hides the power); after: WIDEBAND
    within 30 blocks, frequency_hz at the band's centre (+-0.2 MHz), J/N against the learned shape; the clean
    blocks never reported."""
    fe = FrontEndConfig(sample_rate_hz=4e6, intermediate_frequency_hz=0.0, is_complex=True, bits=2,
                        gain_mode="agc", filter_low_hz=-1.8e6, filter_high_hz=1.8e6)
    jam = NoiseJammer(center_frequency_hz=0.75e6, bandwidth_hz=1.0e6, js_db=js_for_jn_db(fe, -3.0),
                      on_time_s=0.060)
    sim = IfSimulator(fe, (jam,), satellites=(), seed=4)
    mon = RfiMonitor(RfiMonitorParams())
    types, ests = [], []
    for k in range(90):
        b = sim.generate(4000)
        e = mon.process(b.counts[0::2] * b.scale + 1j * b.counts[1::2] * b.scale, 4e6, 0.0, b.first_sample_index,
                        stamp_ns=k * 1_000_000, is_complex=True, bits=2)
        types.append(int(e.type) if e.valid else -1)
        ests.append(e)
    assert all(t in (0, 4) for t in types[:60])
    hits = [k for k in range(60, 90) if types[k] == WIDEBAND]
    assert hits and hits[0] <= 75
    e = ests[hits[-1]]
    assert e.frequency_hz == pytest.approx(0.75e6, abs=0.2e6)
    assert e.noise_reference == REF_LEARNED
    assert e.counters["spectral_step_reports"] >= 1


def test_warm_up_compiles_the_kernels():
    """The node's warm-up reaches the kernels that only run once a reference exists (a cold first stream shed a
    block of the demo while they compiled)."""
    from rfi_monitor import spectral_step as ss
    ss.warm_up(NFFT)
    # the kernels called from Python (those they call are compiled into them, and have no signatures of their own
    # when loaded from numba's cache)
    for kernel in (ss._best_band, ss._add_block_kernel):
        assert kernel.signatures, kernel.__name__
