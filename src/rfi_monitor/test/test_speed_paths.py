"""Compiled fast paths of the monitor: same results as the plain formulas."""

import math

import numpy as np

from rfi_monitor.classifier import ClassifierParams, block_features, welch_psd
from rfi_monitor.monitor import RfiMonitor, RfiMonitorParams, _count_bad_samples
from rfi_monitor.tracker_state import MonitorFloat


def test_count_bad_samples_matches_numpy():
    rng = np.random.default_rng(3)
    x = rng.integers(-8, 8, 1000).astype(float)
    x[[5, 17, 300]] = [np.nan, np.inf, -np.inf]
    fin = np.isfinite(x)
    assert _count_bad_samples(x, 1, 7.0) == (3, int(np.count_nonzero(np.abs(x[fin]) >= 7.0)))
    assert _count_bad_samples(x, 1, math.inf) == (3, 0)
    z = x[:500] + 1j * x[500:]
    zf = np.isfinite(z)
    mag = np.maximum(np.abs(z.real), np.abs(z.imag))
    assert _count_bad_samples(z.view(np.float64), 2, 7.0) == (int(np.count_nonzero(~zf)),
                                                              int(np.count_nonzero(mag[zf] >= 7.0)))


def test_block_features_match_the_numpy_formulas():
    rng = np.random.default_rng(4)
    n = 38192
    t = np.arange(n)
    cp = ClassifierParams()
    x = rng.standard_normal(n) + 2.0 * np.cos(2 * np.pi * (0.18 * t + 0.5e-5 * (t % 4000) ** 2))
    tpl = np.linspace(1.0, 2.0, cp.nfft // 2 + 1)
    tpl /= tpl.sum()
    feat = block_features(x, tpl, cp)
    psd, frames = welch_psd(x, cp.nfft, cp.max_frames)
    white = psd / tpl
    scale = float(np.median(white))
    excess = white / scale - 1.0
    occ = excess > max(max(cp.sig_sigma / math.sqrt(frames), cp.min_excess),
                       10 ** (-cp.sidelobe_db / 10) * float(np.max(excess)))
    exc_pow = np.where(occ, (white - scale) * tpl, 0.0)
    k = int(np.argmax(white))
    assert feat.peak_bin == k
    assert math.isclose(feat.power, float(psd.sum()), rel_tol=1e-12)
    assert math.isclose(feat.noise_scale, scale, rel_tol=1e-12)
    assert feat.occupancy == float(np.mean(occ)) and feat.occupancy > 0.05
    assert math.isclose(feat.jn_spectral_db, 10 * math.log10(exc_pow.sum() / scale), rel_tol=1e-9)
    assert math.isclose(feat.line_fraction, exc_pow[k - 2:k + 3].sum() / exc_pow.sum(), rel_tol=1e-9)


def test_windowed_running_power_follows_the_exponential_average():
    # the running power is updated once per aligned 16-sample window (tracker, "Speed"); at a
    # window end it equals the per-sample exponential average up to rounding
    rng = np.random.default_rng(5)
    n = 4096 + 16
    x = 3.0 * rng.standard_normal(n)
    mon = RfiMonitor(RfiMonitorParams(estimator="kalman", noise_floor_power=1.0, calibration_blocks=1))
    mon.process(x[:n - 1], 38.192e6, 9.548e6, 0, 0)   # middle samples 1 .. n - 3: ends window 255
    lam = 1.0 / mon.params.power_time_constant
    pw = x[1] ** 2                                     # the stream starts from the first power
    for m in range(2, 4096):
        pw += lam * (x[m] ** 2 - pw)
    assert math.isclose(float(mon.estimator._state.mst[MonitorFloat.POW]), pw, rel_tol=1e-9)


def test_tracker_state_fields_are_the_kernel_arguments():
    """track_block unpacks TrackerState and TraceBuffers into the compiled kernel's arguments in order."""
    import inspect

    from rfi_monitor.tracker import _track_block
    from rfi_monitor.tracker_state import TraceBuffers, TrackerState

    names = list(inspect.signature(_track_block.py_func).parameters)
    i = names.index(TrackerState._fields[0])
    assert names[i:i + len(TrackerState._fields)] == list(TrackerState._fields)
    assert names[-len(TraceBuffers._fields):] == ['o_' + f for f in TraceBuffers._fields]


def test_method_table_paper_and_ours():
    from rfi_monitor.params import Method

    assert RfiMonitorParams(estimator="kalman").method == Method.ours()
    assert RfiMonitorParams.paper_method().method == Method.paper()
    assert Method.ours().apply(RfiMonitorParams.paper_method()) == RfiMonitorParams(estimator="kalman")
