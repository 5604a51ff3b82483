"""The ridge of the "stft" estimator ignores a real IF's DC and Nyquist bins, and an aperiodic "sweep" must span its
band with the track itself (issue 14 item 5, false alarms on the real clean captures).

Both were found on the 2-bit 12 MS/s real PocketSDR capture and the GNSS-SDR capture in 1024-sample blocks: a
quantiser's fs/2 and DC products, or a front-end spur held in one bin with a few noise frames elsewhere, made
noise blocks look like aperiodic sweeps (CHIRP in 3 of 3,139 blocks). The cases here are built from those
mechanisms, not from the capture's numbers.
"""

import math

import numpy as np

from rfi_monitor import ridge as rg


def _real_noise(rng, n):
    return rng.standard_normal(n)


def test_dc_and_nyquist_lines_of_a_real_if_make_no_ridge():
    """A strong DC offset and an fs/2 line (a quantiser's products), no jammer: no frame's ridge sits in the DC or
    Nyquist bin, and the block is no sweep, at every frame length."""
    rng = np.random.default_rng(21)
    n = 12000
    t = np.arange(n)
    x = _real_noise(rng, n) + 3.0 + 2.0 * np.cos(np.pi * t)        # DC and fs/2, each far above the noise per bin
    par = rg.RidgeParams()
    for L in par.frame_lengths:
        r = rg.analyse(x, False, 12e6, par, L)
        assert not r.sweeping and not r.periodic, L
        assert not (math.isfinite(r.frequency) and (r.frequency < 0.5 / L or r.frequency > 0.5 - 0.5 / L)), L


def test_joined_span_ignores_isolated_frames_and_follows_a_track():
    """joined_span (a sweep without a period must span 4 bins with its own track): a tone in one bin present in
    most frames, with isolated present frames far away flanked by absent ones (the real captures' case), spans
    ~0, while the span of all present frames (the rule before) is many bins; a ramp spans its range."""
    rng = np.random.default_rng(8)
    binw = 1.0 / 64
    fooled = 0
    for _ in range(50):
        nfr = 31
        f = np.full(nfr, 0.3) + rng.normal(0, 0.2 * binw, nfr)
        present = rng.random(nfr) < 0.8
        for k in rng.choice(np.arange(2, nfr - 2), 3, replace=False):   # three isolated outliers
            present[k - 1] = present[k + 1] = False
            present[k] = True
            f[k] = rng.uniform(-0.5, 0.5)
        fp = f[present]
        assert rg.joined_span(f, present, 2 * binw) < 2 * binw
        fooled += np.percentile(fp, 95) - np.percentile(fp, 5) >= 4 * binw
    assert fooled >= 10, fooled        # the old rule's span would have called many of these a sweep
    ramp = np.linspace(0.1, 0.3, 31)
    assert abs(rg.joined_span(ramp, np.ones(31, bool), 2 * binw) - 0.9 * 0.2) < 1e-9
    assert rg.joined_span(ramp, np.zeros(31, bool), 2 * binw) == 0.0
