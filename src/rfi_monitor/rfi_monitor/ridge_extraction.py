"""Stage 3 of the ridge analysis (orchestrated by ``rfi_monitor.ridge.analyse``): the ridge of each frame (ours).

In every frame of the short-time spectrum a swept tone is one ridge a few bins wide, wherever it is and however it
moves. Per frame (``frame_ridges``, one compiled pass ``_excess_kernel`` over |STFT|^2): the strongest bin of the
excess over the noise level (``rfi_monitor.stft.noise_levels``), its frequency interpolated (parabola on log power,
``_ridge``), present when its excess exceeds ``ln(B) + presence_nats`` (a false alarm in ``exp(-presence_nats)`` of
the noise frames). A real IF's DC and Nyquist bins hold no ridge. The same pass sums the spectral phasor
``u_t = sum_b max(S_tb / N_b - 1, 0) exp(2 pi i b / B)`` whose periodicity over frames is stage 4
(``rfi_monitor.ridge_periodicity``). ``joined_span``: the span a ridge without a period covers as a track.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from rfi_monitor.numpy_kernels import pairwise_sum
from rfi_monitor.stft import _f32


@njit(cache=True)
def _excess_kernel(S: np.ndarray, div: np.ndarray, cos32: np.ndarray, sin32: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One pass over |STFT|^2 (module docstring): per frame the strongest bin of the excess
    E = S / div (float32; the first one, as np.argmax), E there, and the two float32 sums of the spectral
    phasor, sum_b max(E - 1, 0) cos / sin(2 pi b / B)."""
    nfr, B = S.shape
    k = np.empty(nfr, dtype=np.int64)
    pk = np.empty(nfr, dtype=np.float32)
    uc = np.empty(nfr, dtype=np.float32)
    us = np.empty(nfr, dtype=np.float32)
    e = np.empty(B, dtype=np.float32)
    tc = np.empty(B, dtype=np.float32)
    ts = np.empty(B, dtype=np.float32)
    one = np.float32(1.0)
    zero = np.float32(0.0)
    for t in range(nfr):
        for b in range(B):
            e[b] = S[t, b] / div[b]
        kb = 0
        best = e[0]
        for b in range(1, B):
            v = e[b]
            if v > best or (v != v and best == best):
                best = v
                kb = b
        k[t] = kb
        pk[t] = best
        for b in range(B):
            v = e[b] - one
            if v < zero:
                v = zero
            tc[b] = v * cos32[b]
            ts[b] = v * sin32[b]
        uc[t] = pairwise_sum(tc, np.float32(0.0))
        us[t] = pairwise_sum(ts, np.float32(0.0))
    return k, pk, uc, us


def _ridge(S: np.ndarray, k: np.ndarray, pk: np.ndarray, freqs: np.ndarray, presence: float
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame: interpolated ridge frequency (cycles/sample), peak excess, present flag. k, pk: the
    strongest bin of each frame's excess and the excess there (``_excess_kernel``)."""
    nfr, B = S.shape
    rows = np.arange(nfr)
    km, kp = np.clip(k - 1, 0, B - 1), np.clip(k + 1, 0, B - 1)
    a = np.log(S[rows, km] + 1e-30)
    b = np.log(S[rows, k] + 1e-30)
    c = np.log(S[rows, kp] + 1e-30)
    den = a - 2 * b + c
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where((den < 0) & (k > 0) & (k < B - 1), 0.5 * (a - c) / den, 0.0)
    d = np.clip(d, -0.5, 0.5)
    df = freqs[1] - freqs[0]
    f = freqs[k] + d * df
    present = pk > (math.log(B) + presence)
    return f, pk, present


def joined_span(f: np.ndarray, present: np.ndarray, max_step: float) -> float:
    """The 5-95 % span of the ridge frequencies of the frames joined to a present neighbour by a step of at most
    max_step (analyse, a sweep without a period; 0 when fewer than 8 such frames): the span the track itself covers.
    A tone held in one bin with a few isolated frames elsewhere (front-end spurs, noise) spans nothing; a sweep's
    frames are all joined. (The span of all present frames made such blocks of real captures look like sweeps.)"""
    pair = present[1:] & present[:-1] & (np.abs(np.diff(f)) <= max_step)
    joined = np.zeros(f.size, dtype=bool)
    joined[1:] |= pair
    joined[:-1] |= pair
    fj = f[joined]
    return float(np.percentile(fj, 95) - np.percentile(fj, 5)) if fj.size >= 8 else 0.0


@dataclass(frozen=True)
class FrameRidges:
    """The ridge of every frame of one block (module docstring; ``frame_ridges``).

    Attributes:
        frequency: interpolated ridge frequency per frame, cycles/sample; shape (frames,).
        excess: the strongest bin's excess over the noise level per frame (float32); shape (frames,).
        present: the ridge stands above the presence threshold; shape (frames,) bool.
        bin: the strongest bin per frame; shape (frames,) int64.
        phasor: the spectral phasor u_t per frame (stage 4's input); shape (frames,) complex.
        peak_excess: mean frame peak excess minus H_B (the noise-only expectation).
        present_fraction: share of the frames with a ridge present.
    """

    frequency: np.ndarray
    excess: np.ndarray
    present: np.ndarray
    bin: np.ndarray
    phasor: np.ndarray
    peak_excess: float
    present_fraction: float


def frame_ridges(S: np.ndarray, freqs: np.ndarray, lvl: np.ndarray, cplx: bool, presence_nats: float) -> FrameRidges:
    """The ridge of each frame of |STFT|^2 S (frames, bins; float32, ``rfi_monitor.stft.stft_power``) over the noise
    levels lvl (``noise_levels``), and the spectral phasor, in one pass (module docstring)."""
    B = S.shape[1]
    ang = 2.0 * np.pi * np.arange(B) / B
    div = _f32(lvl)
    if not cplx and B > 3:
        # a real IF's DC and Nyquist bins: outside any front end's pass band, one degree of freedom (heavier
        # tails), and where a quantiser's offset and fs/2 products sit: no ridge there (the front-end spurs there
        # made noise blocks of the 2-bit 12 MS/s capture look like sweeps)
        div[0] = div[-1] = np.float32(np.inf)
    kmax, pk32, uc, us = _excess_kernel(S, div, np.cos(ang).astype(np.float32),
                                        np.sin(ang).astype(np.float32))
    f, pk, present = _ridge(S, kmax, pk32, freqs, presence_nats)
    h = float(np.sum(1.0 / np.arange(1, B + 1)))
    return FrameRidges(f, pk, present, kmax, uc + 1j * us, float(np.mean(pk)) - h, float(np.mean(present)))
