"""Stage 3 of the ridge analysis (orchestrated by ``rfi_monitor.ridge.analyse``): the ridge of each frame (ours).

In every frame of the short-time spectrum a swept tone is one ridge a few bins wide, wherever it is and however it
moves. Per frame (``frame_ridges``: a compiled pass ``_excess_kernel`` over |STFT|^2, then ``_ridge_kernel``): the
strongest bin of the excess over the noise level (``rfi_monitor.stft.noise_levels``), its frequency interpolated
(parabola on log power), present when its excess exceeds ``ln(B) + presence_nats`` (a false alarm in
``exp(-presence_nats)`` of the noise frames). A real IF's DC and Nyquist bins hold no ridge. The first pass also
sums the spectral phasor ``u_t = sum_b max(S_tb / N_b - 1, 0) exp(2 pi i b / B)`` whose periodicity over frames is
stage 4 (``rfi_monitor.ridge_periodicity``). ``joined_span``: the span a ridge without a period covers as a track.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from rfi_monitor.numpy_kernels import pairwise_sum, pairwise_sum_short


@njit(cache=True)
def _excess_kernel(S: np.ndarray, lvl: np.ndarray, edges_out: bool, cos32: np.ndarray, sin32: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One pass over |STFT|^2 (module docstring): per frame the strongest bin of the excess E = S / N (float32; N the
    noise levels lvl as float32 divisors, at least 1e-37, infinite at the first and last bins when edges_out; the
    first strongest bin, as np.argmax), E there, the spectral phasor sum_b max(E - 1, 0) exp(2 pi i b / B) (two float32
    sums, numpy's pairwise order), and the powers (+ 1e-30, float32) of the strongest bin and its two neighbours
    (clipped to the band), whose logarithms ``_ridge_kernel`` interpolates."""
    nfr, B = S.shape
    div = np.empty(B, dtype=np.float32)
    for b in range(B):
        v = lvl[b]
        if v < 1e-37:
            v = 1e-37
        div[b] = np.float32(v)
    if edges_out:
        div[0] = div[B - 1] = np.float32(np.inf)
    k = np.empty(nfr, dtype=np.int64)
    pk = np.empty(nfr, dtype=np.float32)
    u = np.empty(nfr, dtype=np.complex128)
    nb = np.empty((3, nfr), dtype=np.float32)
    e = np.empty(B, dtype=np.float32)
    tc = np.empty(B, dtype=np.float32)
    ts = np.empty(B, dtype=np.float32)
    one = np.float32(1.0)
    zero = np.float32(0.0)
    tiny = np.float32(1e-30)
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
        if B <= 128:
            u[t] = complex(np.float64(pairwise_sum_short(tc, zero)), np.float64(pairwise_sum_short(ts, zero)))
        else:
            u[t] = complex(np.float64(pairwise_sum(tc, zero)), np.float64(pairwise_sum(ts, zero)))
        nb[0, t] = S[t, max(kb - 1, 0)] + tiny
        nb[1, t] = S[t, kb] + tiny
        nb[2, t] = S[t, min(kb + 1, B - 1)] + tiny
    return k, pk, u, nb


@njit(cache=True)
def _ridge_kernel(lg: np.ndarray, k: np.ndarray, pk: np.ndarray, B: int, freqs: np.ndarray, thr: np.float32
                  ) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Per frame: the ridge frequency interpolated by a parabola through the log powers lg (np.log of
    ``_excess_kernel``'s last output) of the strongest bin k and its neighbours (cycles/sample; not at the band's first
    and last bins), and the present flag (peak excess pk > thr, float32); with the mean of pk (float32, numpy's
    pairwise order) and the present share. The float32 arithmetic of the numpy expressions it replaced, in their
    order."""
    nfr = k.size
    f = np.empty(nfr)
    present = np.empty(nfr, dtype=np.bool_)
    df = freqs[1] - freqs[0]
    two = np.float32(2.0)
    half = np.float32(0.5)
    n_present = 0
    for t in range(nfr):
        kb = k[t]
        a, b, c = lg[0, t], lg[1, t], lg[2, t]
        den = a - two * b + c
        d = np.float32(0.0)
        if den < 0 and kb > 0 and kb < B - 1:
            d = half * (a - c) / den
            if d < -half:
                d = -half
            elif d > half:
                d = half
        f[t] = freqs[kb] + np.float64(d) * df
        present[t] = pk[t] > thr
        n_present += 1 if present[t] else 0
    mean_pk = pairwise_sum(pk, np.float32(0.0)) / np.float32(nfr)
    return f, present, float(mean_pk), n_present / nfr


_TABLES: dict[int, tuple[np.ndarray, np.ndarray, float]] = {}


def _tables(B: int) -> tuple[np.ndarray, np.ndarray, float]:
    """cos and sin(2 pi b / B) in float32 and the harmonic number H_B (the noise-only mean peak excess), per B."""
    t = _TABLES.get(B)
    if t is None:
        ang = 2.0 * np.pi * np.arange(B) / B
        t = (np.cos(ang).astype(np.float32), np.sin(ang).astype(np.float32), float(np.sum(1.0 / np.arange(1, B + 1))))
        _TABLES[B] = t
    return t


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
        phasor: the spectral phasor u_t per frame (stage 4's input); shape (frames,) complex128.
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
    nfr, B = S.shape
    cos32, sin32, h = _tables(B)
    # a real IF's DC and Nyquist bins: outside any front end's pass band, one degree of freedom (heavier tails), and
    # where a quantiser's offset and fs/2 products sit: no ridge there (the front-end spurs there made noise blocks of
    # the 2-bit 12 MS/s capture look like sweeps)
    kmax, pk, u, nb = _excess_kernel(S, np.ascontiguousarray(lvl, dtype=np.float64), not cplx and B > 3, cos32, sin32)
    np.log(nb, out=nb)
    f, present, mean_pk, share = _ridge_kernel(nb, kmax, pk, B, freqs, np.float32(math.log(B) + presence_nats))
    return FrameRidges(f, pk, present, kmax, u, mean_pk - h, share)
