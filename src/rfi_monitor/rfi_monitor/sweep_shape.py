"""Stage 5 of the ridge analysis (orchestrated by ``rfi_monitor.ridge.analyse``): the folded sweep profile and the
sweep shape (ours; issue 14 item 3).

Sweep profile (``_profile``, ``phase_profiles``): the ridge frequencies of the present frames folded on the period
into ``phase_bins`` bins (median of each bin) and the share of present frames per bin. Bins with at least half of the
largest share are "in band"; ``in_band_fraction`` is their share of the period (< 1: a sweep that leaves the sampled
band, or a pulsed one). Complex input: a ridge in the first or last bin (the +-0.5 cycles/sample edge, where the
circular spectrum joins) is present but its frequency stays out of the medians (it may be either edge). The shape is
read from a coarser profile of at most ``SHAPE_BINS`` bins (steps well above the ridge's scatter). Steps between
consecutive in-band bins larger than ``JUMP_SPAN`` of the swept span are flybacks; the others are swept steps, up or
down.

Shape (``_shape``), a statistic of the profile's slope sequence with this decision rule: a swept step *counts* when it
exceeds ``STEP_SIGMA`` (3) standard errors of the two bin medians it joins (each from its bin's interquartile range /
sqrt(frames)): a ridge that is only scatter gives no counted steps. Fewer than 3 counted steps: unknown. Of the
counted steps, up in a share of 30-70 %, or a way back from the sweep's end (``_return_bins``) lasting >= 30 % of the
period (``TRIANGLE_SIDE``): triangle (at least 2 counted steps each way, else unknown). Otherwise the main direction's
saw-tooth when its sign test (``_sign_tail``, Binomial(n, 1/2)) is <= ``SAW_P`` (0.01), or all counted steps go its
way and a flyback is seen between two in-band bins (a triangle seen only in pieces also goes one way within each
piece); steps against it in 15-30 % of the counted ones, or the direction unproven: unknown. It is hooked when its way
back from the sweep's end is swept (``MIN_RETURN_BINS`` = 2 bins of the profile strictly inside the span, 10 % from its
ends: an instantaneous flyback gives at most one such bin) or when the two steps after its flyback both exceed
``hook_rate_ratio`` times the median step (an overshoot relaxing back fast). The return is also looked for in the
finer ``phase_bins`` profile, and then at the resolution of a sample (``rfi_monitor.fine_hook``). Rate: the median
counted step of the main direction; swept band: the extremes of the profile (of its in-band part: a lower bound of a
sweep wider than the band), then the 2 % and 98 % points of the in-band ridge frequencies (``_fold_residuals``, which
also gives the ridge's scatter about the profile: the 1-sigma of the block-end frequency).

A periodic ridge is a sweep when it moves over >= 4 bins, or over >= 2 bins with a saw-tooth direction whose sign test
is <= ``SAW_P`` (a narrow saw-tooth seen with short frames); a pulsed tone is periodic but does not move.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from rfi_monitor.numpy_kernels import median_sorted, pairwise_sum, quantile_pair

SHAPE_UNKNOWN, SAWTOOTH_UP, SAWTOOTH_DOWN, TRIANGLE, HOOKED_SAWTOOTH = 0, 1, 2, 3, 4
"""Sweep shape codes, identical to rfi_msgs/JammerState.SHAPE_*."""
SHAPE_NAMES = {SHAPE_UNKNOWN: "unknown", SAWTOOTH_UP: "sawtooth_up", SAWTOOTH_DOWN: "sawtooth_down",
               TRIANGLE: "triangle", HOOKED_SAWTOOTH: "hooked_sawtooth"}


JUMP_SPAN = 0.6
"""A step between consecutive in-band profile bins larger than this share of the swept span is a flyback
(a saw-tooth's is ~1; a sweep that crosses the band in two or three bins, as a triangle wider than the
band does, steps by a half or a third of the span and is still a sweep)."""
SHAPE_BINS = 16
"""Phase bins of the profile the sweep shape and rate are read from (the finer ``phase_bins`` profile gives
the frequency at the block end)."""
RETURN_MARGIN = 0.1
"""_return_bins: a bin on a saw-tooth's way back counts when it lies more than this share of the swept span inside
either end of it."""
MIN_RETURN_BINS = 2
"""A saw-tooth with at least this many profile bins on a swept way back is hooked (an instantaneous flyback
gives none, or one where the frames around it are mixed)."""
TRIANGLE_SIDE = 0.3
"""_shape: a triangle's shorter side takes at least this share of the period (of the counted steps, or of the
profile's bins on the way back from the sweep's end); a swept return shorter than that is a hook."""
STEP_SIGMA = 3.0
"""_shape: a swept step of the folded profile counts for the shape when it exceeds this many standard errors of
the two medians it joins (a ridge that is only scatter gives few such steps, and no runs of them)."""
SAW_P = 0.01
"""_shape: a saw-tooth whose counted steps do not all go one way needs a sign test (``_sign_tail``) of at most this
(6 of 7 steps up: 0.06, unknown; 13 of 15: 0.004, a saw-tooth). analyse: a periodic ridge that moves over only 2-4
bins is a sweep when its saw-tooth direction has a sign test of at most this (7 of 7 steps: 0.008)."""


def _profile(f: np.ndarray, present: np.ndarray, period_frames: float, K: int, fuse: np.ndarray | None = None,
             resolution: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Folded sweep profile: median ridge frequency, present share and the median's standard error per phase
    bin (K bins). fuse: the present frames whose frequency enters the medians (default all present ones).
    Standard error: 1.2533 x the interquartile range / 1.349 / sqrt(n) (a median's, from the bin's own spread),
    at least ``resolution`` / sqrt(12 n); infinite with fewer than 4 frames in the bin. Frame t falls in phase
    bin floor(K (t / period_frames mod 1)). Compiled (``_profile_kernel``: the same medians as np.median per bin of
    a np.lexsort by (bin, frequency), the numpy version it replaced)."""
    use = present if fuse is None else fuse
    return _profile_kernel(np.ascontiguousarray(f, dtype=np.float64), np.ascontiguousarray(present, dtype=np.bool_),
                           np.ascontiguousarray(use, dtype=np.bool_), float(period_frames), int(K), float(resolution))


@njit(cache=True)
def _phase_bins(nfr: int, period_frames: float, K: int) -> np.ndarray:
    """Phase bin of frames 0..nfr-1 on a period of period_frames frames, K bins: floor(K (t / period mod 1)),
    at most K - 1 (np.minimum((np.mod(t / p, 1.0) * K).astype(np.int64), K - 1); Python's float % is np.mod)."""
    kb = np.empty(nfr, dtype=np.int64)
    for t in range(nfr):
        j = int(((t / period_frames) % 1.0) * K)
        kb[t] = j if j < K - 1 else K - 1
    return kb


@njit(cache=True)
def _sort_run(buf: np.ndarray, s: int, c: int, tmp: np.ndarray) -> None:
    """Sort buf[s:s + c] in place (as np.sort). A phase bin's few frames: up to 16 values by counting each value's
    rank (ties by place) and placing it there, with no branch that depends on the values; up to 64 by insertion; more,
    or with a NaN, by numba's sort. Timed on the blocks of a stream (its branches on the values mispredict, unlike
    on one block timed again and again: 34 vs 21 us a profile at 38.192 MS/s tracking), per run of random values:
    8 values 49 / 96 / - ns (ranks / insertion / sort), 16 230 / 235 / -, 32 958 / 618 / 970, 64 3550 / 1902 / 2055."""
    nan = False
    for i in range(c):
        nan |= buf[s + i] != buf[s + i]
    if c > 64 or nan:
        buf[s:s + c] = np.sort(buf[s:s + c])
    elif c > 16:
        for i in range(1, c):
            x = buf[s + i]
            j = i
            while j > 0 and buf[s + j - 1] > x:
                buf[s + j] = buf[s + j - 1]
                j -= 1
            buf[s + j] = x
    else:
        for i in range(c):
            vi = buf[s + i]
            r = 0
            for j in range(i):
                r += buf[s + j] <= vi
            for j in range(i + 1, c):
                r += buf[s + j] < vi
            tmp[r] = vi
        for i in range(c):
            buf[s + i] = tmp[i]


@njit(cache=True)
def _profile_kernel(f: np.ndarray, present: np.ndarray, use: np.ndarray, period_frames: float, K: int,
                    resolution: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """_profile, compiled: phase bins, frame counts and present shares, the used frequencies gathered per bin and
    sorted (a counting sort by bin, then each bin's values: the order np.lexsort((f, bin)) gives), then
    ``_bin_stats``."""
    nfr = f.size
    kb = _phase_bins(nfr, period_frames, K)
    n = np.zeros(K)
    npres = np.zeros(K)
    cnt = np.zeros(K, dtype=np.int64)
    m = 0
    for t in range(nfr):
        b = kb[t]
        n[b] += 1.0
        if present[t]:
            npres[b] += 1.0
        if use[t]:
            cnt[b] += 1
            m += 1
    share = np.zeros(K)
    for b in range(K):
        if n[b] > 0:
            share[b] = npres[b] / max(n[b], 1.0)
    if m == 0:
        return np.full(K, np.nan), share, np.full(K, np.inf)
    start = np.empty(K, dtype=np.int64)
    acc = 0
    for b in range(K):
        start[b] = acc
        acc += cnt[b]
    pos = start.copy()
    buf = np.empty(m)
    for t in range(nfr):
        if use[t]:
            b = kb[t]
            buf[pos[b]] = f[t]
            pos[b] += 1
    tmp = np.empty(m)
    for b in range(K):
        _sort_run(buf, start[b], cnt[b], tmp)
    prof, se = _bin_stats(buf, cnt, resolution)
    return prof, share, se


@njit(cache=True)
def _fold_residuals(f: np.ndarray, present: np.ndarray, inband: np.ndarray, prof: np.ndarray, period_frames: float,
                    q_lo: float, q_hi: float) -> tuple[float, int, float, float]:
    """The ridge against its folded profile (analyse, a periodic sweep): over the present frames whose phase bin is
    in band, (RMS of the finite differences from the profile, NaN when there are none; their number; the q_lo and
    q_hi quantiles (fractions) of their frequencies, NaN below 20 frames). Compiled: the mean in numpy's pairwise
    order, the quantiles as np.percentile's "linear"."""
    K = prof.size
    nfr = f.size
    kb = _phase_bins(nfr, period_frames, K)
    r2 = np.empty(nfr)
    fsel = np.empty(nfr)
    nres = 0
    nsel = 0
    for t in range(nfr):
        if present[t] and inband[kb[t]]:
            fsel[nsel] = f[t]
            nsel += 1
            r = f[t] - prof[kb[t]]
            if np.isfinite(r):
                r2[nres] = r * r
                nres += 1
    rms = math.sqrt(pairwise_sum(r2[:nres], 0.0) / nres) if nres else np.nan
    lo = hi = np.nan
    if nsel >= 20:
        lo, hi = quantile_pair(fsel, nsel, q_lo, q_hi)
    return rms, nsel, lo, hi


@njit(cache=True)
def _bin_stats(fs_sorted: np.ndarray, cnt: np.ndarray, resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """_profile's per-bin median and its standard error from the frequencies sorted by (bin, value) and the
    counts per bin (compiled; NaN / inf for an empty bin / fewer than 4 frames)."""
    K = cnt.size
    prof = np.full(K, np.nan)
    se = np.full(K, np.inf)
    start = 0
    floor = resolution / math.sqrt(12.0)
    for k in range(K):
        c = cnt[k]
        if c > 0:
            prof[k] = 0.5 * (fs_sorted[start + (c - 1) // 2] + fs_sorted[start + c // 2])
        if c >= 4:
            iqr = 1.2533 / 1.349 * (fs_sorted[start + (3 * (c - 1)) // 4] - fs_sorted[start + (c - 1) // 4])
            se[k] = max(iqr, floor) / math.sqrt(float(c))
        start += c
    return prof, se


@njit(cache=True)
def _sign_tail(k: int, n: int) -> float:
    """P(X >= k) for X ~ Binomial(n, 1/2): the chance that k or more of n steps go one way with no sweep."""
    if n <= 0:
        return 1.0
    tot = 0.0
    c = 1.0                                # C(n, i), exact in double for the n of a profile (<= 64)
    for i in range(n + 1):
        if i >= k:
            tot += c
        c = c * (n - i) / (i + 1)
    return tot / 2.0 ** n


@njit(cache=True)
def _return_bins(prof: np.ndarray, inband: np.ndarray, up: bool) -> tuple[int, int]:
    """Bins on a saw-tooth's return (module docstring): from the profile's extreme at the end of the
    sweep (its maximum for an up-sweep), the consecutive in-band bins that keep moving back (down for an
    up-sweep) and lie strictly inside the swept span (more than ``RETURN_MARGIN`` of it from either end).
    0 for an instantaneous flyback (the frames around it see one side or the other; at most one bin, the one
    where the two sides are mixed in equal numbers, can fall in between); >= ``MIN_RETURN_BINS``: a swept
    return (a hook's flyback, or an asymmetric triangle's short side). Returns (those bins, the steps the return
    takes: 1 for an instantaneous flyback). Compiled, O(bins)."""
    K = prof.size
    sgn = 1.0 if up else -1.0
    n_ok = 0
    lo, hi = np.inf, -np.inf
    j, best = -1, -np.inf
    for k in range(K):
        if inband[k] and np.isfinite(prof[k]):
            n_ok += 1
            lo = min(lo, prof[k])
            hi = max(hi, prof[k])
            if sgn * prof[k] > best:
                best, j = sgn * prof[k], k
    if n_ok < 4 or not hi - lo > 0:
        return 0, 0
    m = RETURN_MARGIN * (hi - lo)
    n = steps = 0
    prev = prof[j]
    for i in range(1, K):
        k = (j + i) % K
        if not (inband[k] and np.isfinite(prof[k])):
            break
        v = prof[k]
        if sgn * (v - prev) >= 0:          # moving with the sweep again: the return is over
            break
        steps += 1
        if lo + m < v < hi - m:
            n += 1
        prev = v
    return n, steps


def _shape(prof: np.ndarray, inband: np.ndarray, hook_ratio: float, se: np.ndarray | None = None
           ) -> tuple[int, float, float, float, float, float]:
    """(shape, low, high, start, rate per phase bin, direction p) of a folded profile (module docstring).

    se: standard error of each bin's median (``_profile``); a swept step counts for the shape only when it
    exceeds ``STEP_SIGMA`` times the standard error of the difference of the two medians it joins (None: every
    swept step counts). direction p: the sign-test probability (``_sign_tail``) of the saw-tooth's main
    direction among the counted steps (NaN for a triangle or an unknown shape). Compiled (``_shape_kernel``)."""
    has_se = se is not None
    out = _shape_kernel(np.ascontiguousarray(prof, dtype=np.float64), np.ascontiguousarray(inband, dtype=np.bool_),
                        float(hook_ratio), np.ascontiguousarray(se if has_se else prof, dtype=np.float64), has_se)
    return int(out[0]), float(out[1]), float(out[2]), float(out[3]), float(out[4]), float(out[5])


@njit(cache=True)
def _shape_kernel(prof: np.ndarray, inband: np.ndarray, hook_ratio: float, se: np.ndarray, has_se: bool
                  ) -> tuple[int, float, float, float, float, float]:
    """_shape, compiled."""
    K = prof.size
    nan = np.nan
    n_in = 0
    low, high = np.inf, -np.inf
    for k in range(K):
        if inband[k]:
            n_in += 1
            low = min(low, prof[k])
            high = max(high, prof[k])
    if n_in < 4:
        return SHAPE_UNKNOWN, nan, nan, nan, nan, nan
    span = high - low
    d = np.full(K, np.nan)
    jump = np.zeros(K, np.bool_)
    counted = np.zeros(K, np.bool_)
    n_c = n_up = n_dn = n_jump = 0
    for k in range(K):
        nx = (k + 1) % K
        if inband[k] and inband[nx]:
            d[k] = prof[nx] - prof[k]
            if abs(d[k]) > JUMP_SPAN * span:
                jump[k] = True
                n_jump += 1
            elif not has_se or abs(d[k]) > STEP_SIGMA * math.sqrt(se[k] * se[k] + se[nx] * se[nx]):
                counted[k] = True
                n_c += 1
                if d[k] > 0:
                    n_up += 1
                elif d[k] < 0:
                    n_dn += 1
    if n_c < 3 or not span > 0:
        return SHAPE_UNKNOWN, low, high, nan, nan, nan
    ups = np.empty(n_up)
    dns = np.empty(n_dn)
    iu = idn = 0
    for k in range(K):
        if counted[k]:
            if d[k] > 0:
                ups[iu] = d[k]
                iu += 1
            elif d[k] < 0:
                dns[idn] = d[k]
                idn += 1
    frac_up = n_up / max(n_up + n_dn, 1)
    med_up = median_sorted(ups) if n_up else 0.0
    med_dn = median_sorted(dns) if n_dn else 0.0
    up = frac_up > 0.5
    n_mid, n_ret = _return_bins(prof, inband, up)
    if TRIANGLE_SIDE <= frac_up <= 1 - TRIANGLE_SIDE or n_ret >= TRIANGLE_SIDE * K:
        # up and down alike (by counted steps, or by the time the way back takes): a triangle when each way has
        # at least two counted steps
        if min(n_up, n_dn) >= 2:
            return TRIANGLE, low, high, low, med_up, nan
        return SHAPE_UNKNOWN, low, high, nan, nan, nan
    med = med_up if up else med_dn
    p_dir = _sign_tail(max(n_up, n_dn), n_up + n_dn)
    start = low if up else high
    # hooked: a swept return (MIN_RETURN_BINS bins inside the span on the way back), or an overshoot that
    # relaxes back faster than the sweep over at least two counted steps after the flyback
    hooked = n_mid >= MIN_RETURN_BINS
    if not hooked:
        for j in range(K):
            if jump[j]:
                a, b = (j + 1) % K, (j + 2) % K
                if (counted[a] and counted[b] and np.sign(d[a]) == np.sign(med) and np.sign(d[b]) == np.sign(med)
                        and min(abs(d[a]), abs(d[b])) > hook_ratio * abs(med)):
                    hooked = True
                    break
    if hooked:
        return HOOKED_SAWTOOTH, low, high, start, med, p_dir
    if 0.15 < min(frac_up, 1 - frac_up) or (p_dir > SAW_P and (min(n_up, n_dn) > 0 or not n_jump > 0)):
        # steps going back but not as a return (scatter: a weak ridge), or a direction seen too few times with
        # no flyback between two in-band bins (a triangle's side seen in pieces looks the same): not a shape
        # that the profile shows
        return SHAPE_UNKNOWN, low, high, nan, med, nan
    return (SAWTOOTH_UP if up else SAWTOOTH_DOWN), low, high, start, med, p_dir


@dataclass(frozen=True)
class PhaseProfiles:
    """The folded profiles of a periodic ridge (``phase_profiles``).

    Attributes:
        prof, inband: the fine profile (K bins: ``phase_bins``, or one per frame of a period of nearly whole frames)
            and its in-band bins; shape (K,). The block-end frequency and the sweep law are read from it.
        se: the standard error of each of its bins (a median's, ``_profile``), shape (K,).
        prof_s, inband_s, se_s: the profile the shape is read from (Ks bins, at most ``SHAPE_BINS``; the fine one
            when the sweep is in band for less than 0.6 of the period), its in-band bins and standard errors.
        shape_bins: Ks.
        in_band_fraction: share of the coarse profile's bins in band.
    """

    prof: np.ndarray
    inband: np.ndarray
    se: np.ndarray
    prof_s: np.ndarray
    inband_s: np.ndarray
    se_s: np.ndarray
    shape_bins: int
    in_band_fraction: float


def phase_profiles(f: np.ndarray, present: np.ndarray, fuse: np.ndarray, period_frames: float, phase_bins: int,
                   resolution: float) -> PhaseProfiles:
    """The ridge (frequencies f of the frames, present flags, fuse: those whose frequency enters the medians) folded
    on a period of period_frames frames (module docstring): the fine profile and the coarser one for the shape.
    Compiled (``_phase_profiles_kernel``)."""
    prof, inband, se, prof_s, inband_s, se_s, Ks, inb = _phase_profiles_kernel(
        np.ascontiguousarray(f, dtype=np.float64), np.ascontiguousarray(present, dtype=np.bool_),
        np.ascontiguousarray(fuse, dtype=np.bool_), float(period_frames), int(phase_bins), float(resolution))
    return PhaseProfiles(prof, inband, se, prof_s, inband_s, se_s, int(Ks), float(inb))


@njit(cache=True)
def _in_band(prof: np.ndarray, share: np.ndarray, top: float) -> np.ndarray:
    """Bins with at least half the largest present share (top: the fine profile's) and a finite median;
    none when top is 0. The share is compared with half of this profile's own largest share."""
    K = prof.size
    mx = -np.inf
    for k in range(K):
        if share[k] > mx:
            mx = share[k]
    out = np.empty(K, dtype=np.bool_)
    for k in range(K):
        out[k] = share[k] >= 0.5 * mx and np.isfinite(prof[k]) and top > 0
    return out


@njit(cache=True)
def _phase_profiles_kernel(f: np.ndarray, present: np.ndarray, use: np.ndarray, period_frames: float, K: int,
                           resolution: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                       np.ndarray, int, float]:
    """phase_profiles, compiled: the same profiles (``_profile_kernel``) and the same tests as the numpy glue it
    replaced (shares of bins as count / bins, the largest share)."""
    # a period that is not a whole number of frames spreads the frames over all phases, so the profile
    # can be finer than a frame; where it is (nearly) whole, only per_fr phases are seen
    prof, share, se = _profile_kernel(f, present, use, period_frames, K, resolution)
    n_empty = 0
    for k in range(K):
        if np.isnan(prof[k]) and share[k] == 0:
            n_empty += 1
    if n_empty / K > 0.25:
        K = int(max(4, math.floor(period_frames)))
        prof, share, se = _profile_kernel(f, present, use, period_frames, K, resolution)
    top = -np.inf
    for k in range(K):
        if share[k] > top:
            top = share[k]
    inband = _in_band(prof, share, top)
    # the shape from a coarser profile (at most SHAPE_BINS bins: steps well above the ridge's scatter)
    Ks = min(K, SHAPE_BINS)
    if Ks == K:
        prof_s, share_s, se_s = prof, share, se
    else:
        prof_s, share_s, se_s = _profile_kernel(f, present, use, period_frames, Ks, resolution)
    inband_s = _in_band(prof_s, share_s, top)
    n_in = 0
    for k in range(Ks):
        n_in += 1 if inband_s[k] else 0
    inb = n_in / Ks
    if inb < 0.6 and Ks < K:
        # in band only part of the period: the finer profile has more bins in each in-band run
        Ks, prof_s, inband_s, se_s = K, prof, inband, se
    return prof, inband, se, prof_s, inband_s, se_s, Ks, inb
