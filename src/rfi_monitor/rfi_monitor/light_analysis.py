"""The light analysis of a block, for a node behind its live stream (pure module, no ROS).

``RfiMonitor.process(light=True)`` asks for it; the "stft" estimator answers with :func:`light_estimate` when the
last full analysis is recent (``LIGHT_MAX_AGE_S``, ``LIGHT_MAX_AGE_QUIET_S``) and the block's Welch spectrum agrees
with it, else analyses the block in full (counted as ``light_escalations``). Replays never get it (load_policy
module): it is a safety net of live streams only.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from rfi_monitor import classifier as cl
from rfi_monitor import estimate as es
from rfi_monitor.estimate import MIN_BLOCK_POWER, REF_IN_BLOCK, Block, BlockCounters, JammerEstimate
from rfi_monitor.noise_reference import NoiseReference
from rfi_monitor.params import RfiMonitorParams

LIGHT_MAX_AGE_S = 0.01
"""A light analysis (``RfiMonitor.process(light=True)``) carries the last full analysis of a jammer only if that block
is stamped at most this long before, s: a jammer's type, sweep period, band and shape do not change within 10 ms, and
a node behind its stream analyses a block in full at least this often while it reports one (the light path
escalates itself when the last full analysis is older)."""
LIGHT_MAX_AGE_QUIET_S = 0.05
"""... and of a block without a jammer (NONE), s. A quiet block's full analysis costs most (the evidence over blocks
decides with it: 3-5 ms at 38.192 MS/s on a 2-vCPU AMD EPYC, against 1 ms for a tracked chirp's), so one in 10 would
keep a node behind its stream behind (measured in live_stream.md); a jammer that appears is seen by the light
analysis itself from ``detect_jn_db`` - ``LIGHT_NONE_MARGIN_DB``, a weaker one by the next full analysis, at most
this much later."""
LIGHT_JN_TOLERANCE_DB = 3.0
"""A light analysis of a block whose jammer's power J/N moved more than this from the last full analysis's escalates
to a full analysis, dB (a jammer switching on, off, or changing: twice the 1-sigma scatter of a weak jammer's block
J/N at the common front ends)."""
LIGHT_NONE_MARGIN_DB = 3.0
"""... and a block after a NONE answer escalates from ``detect_jn_db`` minus this (power or spectral J/N), dB: what the
light path cannot see (a sweep the ridge analysis finds below the detection J/N) is left to the next full block."""


@dataclass(frozen=True)
class LastFull:
    """What a light analysis carries (light_estimate): the last fully analysed block's estimate, its block
    power, the noise power its J/N was measured against, its power J/N (dB) and the digital frequency of its spectral
    peak (cycles per sample), whether the estimate came from the evidence over blocks, and the stream it was on."""

    est: JammerEstimate
    power: float
    noise: float
    jn_power_db: float
    peak: float
    integrated: bool
    fs: float
    cplx: bool


def light_estimate(block: Block, lf: LastFull | None, params: RfiMonitorParams, noise_ref: NoiseReference,
                   counters: BlockCounters) -> JammerEstimate | None:
    """The light analysis of a block (``process(light=True)``), or None when the block needs the full one.

    The block's Welch PSD gives its power, its J/N against the reference of the last full analysis and its
    spectral features (the first steps of the full analysis, docs/rfi_monitor/stft_estimator.md). The answer
    keeps the last full analysis's type when the block agrees with it:

    * NONE (or a jammer found only by the evidence over blocks): neither the power J/N (against the floor, or
      before one is learned against the last full analysis's in-block noise level) nor the spectral J/N reaches
      ``detect_jn_db`` - ``LIGHT_NONE_MARGIN_DB``;
    * CW: the block still shows a narrow line (the full analysis's CW rule) within two bins of the last one's;
      its frequency is this block's spectral peak, as in the full analysis;
    * CHIRP, WIDEBAND: the block power's J/N against the last full analysis's noise power is within
      ``LIGHT_JN_TOLERANCE_DB`` of that analysis's own; the J/N published is the last one moved by the change.

    The sweep period, band, rate, start, shape and in-band fraction (and a wideband jammer's band) are the last
    full analysis's; a chirp's frequency is NaN (the ridge, which tracks it, does not run). J/S, the clipped
    fraction and the lower-bound flag are this block's."""
    xs, cplx, fs, fif, stamp_ns, first = (block.samples, block.cplx, block.fs, block.fif, block.stamp_ns,
                                          block.first)
    clipped, full_scale, coarse = block.clipped, block.full_scale, block.coarse
    p = params
    cp = p.classifier
    if lf is None or lf.fs != fs or lf.cplx != cplx or lf.est.type == cl.UNKNOWN:
        return None
    max_age_s = LIGHT_MAX_AGE_QUIET_S if lf.est.type == cl.NONE and not lf.integrated else LIGHT_MAX_AGE_S
    if not 0 < stamp_ns - lf.est.stamp_ns <= max_age_s * 1e9:
        return None
    psd, frames = cl.welch_psd(xs, cp.nfft, cp.max_frames)
    power = float(psd.sum())
    if not (math.isfinite(power) and power >= MIN_BLOCK_POWER):
        return None                               # the full analysis rejects it, counted
    floor, ref = noise_ref.reference(fs, cplx, full_scale, math.nan)
    if ref != REF_IN_BLOCK and es.off_floor(power, floor) is not None:
        return None
    norm = psd / power
    tpl = noise_ref.template if noise_ref.template is not None else cl.smooth_template(norm, cp.template_smooth_bins)
    feat = cl.features_from_psd(psd, frames, tpl, cp, cplx)
    thr = cp.detect_jn_db
    last = lf.est
    jtype = last.type
    conf = last.confidence
    freq, fstd = last.frequency_hz, last.frequency_std_hz
    if jtype == cl.NONE or lf.integrated:
        if ref == REF_IN_BLOCK:
            floor = lf.noise                      # no floor yet: the last full analysis's in-block noise level
            if not (math.isfinite(floor) and floor > 0):
                return None
        jn_ref = 10 * math.log10(power / floor - 1.0) if power > floor else -math.inf
        jn = max(jn_ref, feat.jn_spectral_db)
        if not jn < thr - LIGHT_NONE_MARGIN_DB:
            return None
        if jtype == cl.NONE:
            conf = 1.0 - cl.logistic(jn - thr, cp.confidence_slope_db)
        jn = max(jn, 5.0 * math.log10((1.0 if cplx else 2.0) / (frames * cp.nfft)))   # the resolution
    elif jtype == cl.CW:
        narrow = feat.jn_spectral_db >= thr
        cw = narrow and (feat.occupancy <= cp.cw_max_occupancy or feat.line_fraction >= cl.CW_MIN_LINE_FRACTION)
        if not cw or not abs(feat.peak_frequency - lf.peak) <= 2.0 / cp.nfft:
            return None
        noise = floor if ref != REF_IN_BLOCK else lf.noise
        jn_ref = 10 * math.log10(power / noise - 1.0) if power > noise else -math.inf
        jn = max(jn_ref, feat.jn_spectral_db)
        if not abs(jn - last.jammer_to_noise_db) <= LIGHT_JN_TOLERANCE_DB:
            return None
        conf = cl.logistic(feat.jn_spectral_db - thr, cp.confidence_slope_db)
        freq = es.relative_frequency_hz(feat.peak_frequency, fs, fif, cplx)
    else:
        jn_pow = 10 * math.log10(power / lf.noise - 1.0) if power > lf.noise > 0 else -math.inf
        delta = jn_pow - lf.jn_power_db
        if not abs(delta) <= LIGHT_JN_TOLERANCE_DB:
            return None
        jn = last.jammer_to_noise_db + delta
        if jtype == cl.CHIRP:
            freq = fstd = math.nan
    js = es.jammer_to_signal_db(jtype, jn, fs, cplx, p)
    lower = (clipped > p.clip_lower_bound_fraction or coarse) and jtype != cl.NONE
    counters["light_blocks"] += 1
    return dataclasses.replace(
        last, stamp_ns=int(stamp_ns), confidence=float(conf), jammer_to_noise_db=float(jn),
        jammer_to_signal_db=float(js), frequency_hz=float(freq), frequency_std_hz=float(fstd),
        first_sample_index=int(first), n_samples=int(xs.size), counters=counters.snapshot(), traces=None,
        jammer_to_noise_is_lower_bound=bool(lower or lf.integrated), clipped_fraction=float(clipped), light=True)
