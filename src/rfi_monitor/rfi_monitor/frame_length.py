"""Stage 1 of the ridge analysis (orchestrated by ``rfi_monitor.ridge.analyse``): the frame length of a block (ours).

Frames of L samples (Hann, hop L/2) for each L in ``RidgeParams.frame_lengths``, tried on a slice of the block
(``RidgeParams.select_samples``): a tone sweeping ``k`` cycles/sample^2 spreads over ``k L^2`` bins of a frame, so its
peak excess over the noise grows with L up to ``L ~ 1 / sqrt(k)`` and falls after. The score of L is the mean frame
peak excess above what noise alone gives (the expectation of the largest of B exponential variables, the harmonic
number ``H_B``; ``_peak_excess``). The shortest L whose score is at least ``SHORT_FRAME_SCORE`` of the best is used
for the block; below ``MIN_SELECT_EXCESS`` (nothing clearly concentrated) the longest frame within noise's scatter of
the best, and the longest of all when no score stands ``SELECT_Z`` standard deviations over its noise-only mean
(``null_peak_excess``).
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
from numba import njit

from rfi_monitor.stft import _f32, noise_levels, stft_power


class FrameLengthParams(Protocol):
    """What the choice needs of ``rfi_monitor.ridge.RidgeParams`` (its attributes' meaning there)."""

    @property
    def frame_lengths(self) -> tuple[int, ...]: ...
    @property
    def select_samples(self) -> int: ...
    @property
    def min_frame_length(self) -> int: ...
    @property
    def noise_smooth_bins(self) -> int: ...


MIN_SELECT_EXCESS = 2.0
"""choose_frame_length: below this best mean peak excess (white noise: -0.1..1.3 over 8192 samples, real
input the higher) the longest frame within 0.5 of the best is taken instead of the best; and the longest frame of
all when no score stands ``SELECT_Z`` of its noise-only standard deviations above its noise-only mean
(``null_peak_excess``): nothing in the slice but noise."""
SELECT_Z = 3.0
"""choose_frame_length: significance of a frame-length score over noise, standard deviations of the score on white
Gaussian noise at that frame length."""
SHORT_FRAME_SCORE = 1.0
"""choose_frame_length takes the shortest frame whose peak excess is at least this share of the best one (1: the
best; 0.5 lost the 5.1 MHz sweep of the paper front end at J/N 10 dB, a 16-sample frame has 2.4 MHz bins)."""


_NULL_EXCESS: dict[tuple[int, bool, int, int], tuple[float, float]] = {}
NULL_SLICES = 24
"""Seeded white-noise slices that ``null_peak_excess`` measures its mean and standard deviation on."""


def null_peak_excess(L: int, cplx: bool, n: int, smooth_bins: int) -> tuple[float, float]:
    """(mean, standard deviation) of ``_peak_excess`` on white Gaussian noise for frames of L over n samples
    (choose_frame_length): measured once per (L, kind, n, smooth_bins) on ``NULL_SLICES`` seeded noise slices
    (deterministic) and cached. Neither is zero: the score's noise-only mean is 0.6-1.0 for real input (8192 samples)
    and its scatter 0.2-0.5."""
    key = (int(L), bool(cplx), int(n), int(smooth_bins))
    v = _NULL_EXCESS.get(key)
    if v is None:
        rng = np.random.default_rng(23456)
        vals = []
        for _ in range(NULL_SLICES):
            x = ((rng.standard_normal(n) + 1j * rng.standard_normal(n)) / math.sqrt(2.0) if cplx
                 else rng.standard_normal(n))
            S, _ = stft_power(x, L, cplx)
            vals.append(_peak_excess(S, noise_levels(S, smooth_bins, cplx), cplx))
        v = (float(np.mean(vals)), float(np.std(vals, ddof=1)))
        if len(_NULL_EXCESS) > 256:
            _NULL_EXCESS.clear()
        _NULL_EXCESS[key] = v
    return v


def _peak_excess(S: np.ndarray, lvl: np.ndarray, cplx: bool = True) -> float:
    """Mean over frames of the largest bin excess (power / noise level), minus the harmonic number H_B (the
    mean largest of B unit exponentials). Real input: without the DC and Nyquist bins (one degree of freedom:
    heavier tails, which made noise score above zero at short frames)."""
    b0, b1 = (1, S.shape[1] - 1) if (not cplx and S.shape[1] > 3) else (0, S.shape[1])
    B = b1 - b0
    h = float(np.sum(1.0 / np.arange(1, B + 1)))
    return float(np.mean(_row_max_excess(np.ascontiguousarray(S, dtype=np.float32), _f32(lvl), b0, b1))) - h


@njit(cache=True)
def _row_max_excess(S: np.ndarray, div: np.ndarray, b0: int, b1: int) -> np.ndarray:
    """Per frame the largest S / div (float32) over bins b0 .. b1 - 1 (NaN if any is NaN, as np.max)."""
    nfr = S.shape[0]
    out = np.empty(nfr, dtype=np.float32)
    for t in range(nfr):
        best = S[t, b0] / div[b0]
        for b in range(b0 + 1, b1):
            v = S[t, b] / div[b]
            if v > best or v != v:
                best = v
                if v != v:
                    break
        out[t] = best
    return out


def choose_frame_length(x: np.ndarray, cplx: bool, par: FrameLengthParams) -> int:
    """The frame length of the block (module docstring)."""
    n = x.size if par.select_samples <= 0 else min(x.size, int(par.select_samples))
    xs = x[:n]
    scores: list[tuple[int, float]] = []
    for L in par.frame_lengths:
        if 8 * L > n:
            break
        S, _ = stft_power(xs, L, cplx)
        lvl = noise_levels(S, par.noise_smooth_bins, cplx)
        scores.append((L, _peak_excess(S, lvl, cplx)))
    if not scores:
        return int(par.min_frame_length)
    scores = [(L, sc) for L, sc in scores if math.isfinite(sc)]
    if not scores:
        return int(par.min_frame_length)
    best = max(sc for _, sc in scores)
    if best < MIN_SELECT_EXCESS:
        # nothing clearly concentrated in the slice: the longest frame within noise's scatter of the best
        # (fewer frames, a cheaper analysis; a chirp that appears makes the monitor choose again at once), and
        # the longest of all when no score is significant over noise: the scores of a noise-only slice scatter
        # by about 0.5 around a mean of up to 1, so "the best" was a random frame length, often the shortest
        # and costliest (band-limited noise at 38.192 MS/s: L = 8, 9,547 frames per 1 ms block)
        z = []
        for L, sc in scores:
            mu, sd = null_peak_excess(L, cplx, n, par.noise_smooth_bins)
            z.append((sc - mu) / sd if sd > 0 else math.inf)
        if max(z) < SELECT_Z:
            return int(max(L for L, _ in scores))
        return int(max(L for L, sc in scores if sc >= best - 0.5))
    # the shortest frame within a factor SHORT_FRAME_SCORE of the best: time resolution (a sweep's ends,
    # short sweeps, the frequency at the block end) at little loss of peak excess
    return next(L for L, sc in scores if sc >= SHORT_FRAME_SCORE * best)
