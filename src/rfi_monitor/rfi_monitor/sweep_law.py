"""Stage 6 of the ridge analysis (orchestrated by ``rfi_monitor.ridge.analyse``), for a saw-tooth: its sweep law
(ours).

The flyback is the largest step between consecutive in-band bins of the folded profile
(``rfi_monitor.sweep_shape``); a quadratic in the elapsed sweep fraction (a rate that changes along the sweep) is
fitted to the bins away from it (``_sawtooth_law``), each bin placed at the mean phase of its frames
(``bin_mean_phase``). The law gives the swept band's ends, the mean rate and the frequency at the block's last sample
(read at that sample's phase of the period: ``read_law``), its 1-sigma from the fit's residual and the law's standard
error there. ``profile_abscissa_bias`` is the same correction for a frequency read off the profile itself.

The bins' abscissa (issue 26 item 3): a profile bin k stands for the centre of its phase interval,
``(k + 0.5) / K``, but the frames in it lie wherever the frame grid puts them. When the period is not close to a
whole number of frames their phases spread over the bin and average to its centre; when it is (a 12 us sweep at 4 or
12 MS/s with frames of 16 samples: 6 and 18 frames exactly), every frame of bin k sits at the same phase, k / K for a
whole number, and a law fitted (or a profile read) at the bins' centres reads the frequency half a bin late: the
sweep's rate times half a hop, 70 and 125 kHz on the rows of docs/rfi_monitor/real_jammers.md that showed it. Until
then that bias was added to the 1-sigma in quadrature; now the frequency is corrected (the law fitted, the profile
read, at the mean phase of each bin's frames), so the bias is 0 by construction where the frames tell the phase.
docs/rfi_monitor/frequency_std.md gives the errors and the coverage before and after.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from rfi_monitor.numpy_kernels import pairwise_sum, polyfit, polyval
from rfi_monitor.ridge_extraction import frame_ridges
from rfi_monitor.stft import stft_power


def _sawtooth_law(prof: np.ndarray, inband: np.ndarray, period_samples: float, L: int, span: float,
                  phase_mean: np.ndarray | None = None) -> tuple[float, np.ndarray, float, np.ndarray] | None:
    """(flyback phase, polynomial in the elapsed sweep fraction, RMS residual of the fit, the elapsed fractions of the
    bins fitted) of a saw-tooth's folded profile, or None.

    The flyback is the largest step between consecutive in-band bins. Bins within half a frame (plus one
    bin) of it are left out: their frames straddle the flyback. A quadratic (a rate that changes along the
    sweep; linear with fewer than 8 bins) is fitted to the others against the elapsed fraction of the
    sweep since the flyback; None when fewer than 4 bins remain or the fit leaves an RMS residual above a
    tenth of the span. Each bin is placed at the mean phase of its frames, phase_mean (``bin_mean_phase``; the bins'
    centres when None): the module docstring says why. Which bins are fitted is decided on their centres. Compiled
    (``_sawtooth_law_kernel``: np.polyfit's scaled least squares)."""
    K = prof.size
    pm = (np.arange(K) + 0.5) / K if phase_mean is None else np.ascontiguousarray(phase_mean, dtype=np.float64)
    if pm.shape != (K,):
        raise ValueError("phase_mean must have one phase per profile bin")
    ok, phi_j, coef, rms, ee, _ = _sawtooth_law_kernel(np.ascontiguousarray(prof, dtype=np.float64),
                                                    np.ascontiguousarray(inband, dtype=np.bool_),
                                                    float(period_samples), int(L), float(span), pm)
    return (phi_j, coef, rms, ee) if ok else None


@njit(cache=True)
def _sawtooth_law_kernel(prof: np.ndarray, inband: np.ndarray, period_samples: float, L: int, span: float,
                         phase_mean: np.ndarray) -> tuple[bool, float, np.ndarray, float, np.ndarray, np.ndarray]:
    """_sawtooth_law, compiled: (found, flyback phase, coefficients, RMS, elapsed fractions fitted, the bins fitted)."""
    K = prof.size
    none = (False, np.nan, np.zeros(3), np.nan, np.zeros(0), np.zeros(0, dtype=np.int64))
    j, best, any_both = 0, -np.inf, False
    for k in range(K):
        nx = (k + 1) % K
        v = -1.0
        if inband[k] and inband[nx] and np.isfinite(prof[k]) and np.isfinite(prof[nx]):
            any_both = True
            v = abs(prof[nx] - prof[k])
        if v > best:
            best, j = v, k
    if not any_both or not span > 0:
        return none
    if best < span / 3.0:
        return none
    phi_j = (j + 1) / K
    guard = 0.5 * L / period_samples + 1.0 / K
    ee = np.empty(K)
    pp = np.empty(K)
    kk = np.empty(K, dtype=np.int64)
    m = 0
    for k in range(K):
        c = (k + 0.5) / K
        e = (c - phi_j) % 1.0                # Python's float % is np.mod: into [0, 1)
        if inband[k] and np.isfinite(prof[k]) and e > guard and e < 1.0 - guard:
            ee[m] = (phase_mean[k] - phi_j) % 1.0    # the bin at its frames' mean phase, in the same bin as c
            pp[m] = prof[k]
            kk[m] = k
            m += 1
    if m < 4:
        return none
    deg = 2 if m >= 8 else 1
    coef = polyfit(ee[:m], pp[:m], deg)
    r2 = np.empty(m)
    for i in range(m):
        r = pp[i] - polyval(coef, ee[i])
        r2[i] = r * r
    rms = math.sqrt(pairwise_sum(r2, 0.0) / m * m / max(m - deg - 1, 1))
    if rms > 0.1 * span:
        return none
    return True, phi_j, coef, rms, ee[:m].copy(), kk[:m].copy()


INTERP_OFFSETS = 16
"""Sub-bin offsets (uniform over one bin) at which ``interpolation_error_rms`` evaluates the ridge's interpolation."""

_INTERP_CACHE: dict[tuple[int, float, bool], float] = {}


def interpolation_error_rms(L: int, rate: float, cplx: bool) -> float:
    """RMS error of the per-frame ridge frequency (``ridge_extraction.frame_ridges``: a parabola through the log powers
    of the strongest bin and its neighbours, Hann frames of L) for a noiseless linear chirp of ``rate``
    (cycles/sample^2) whose frequency at the frame's centre is uniform over one bin: INTERP_OFFSETS frames at offsets
    j / INTERP_OFFSETS of a bin, read by the monitor's own stft_power and frame_ridges; cycles/sample. Cached per
    (L, rate to 3 significant digits, cplx).

    Why (issue 26 item 3): this error is a function of where the chirp falls between the bins, so it is the same for
    every frame of a profile bin (those frames see the same segment of the sweep when the period is near a whole
    number of hops), and when the sweep moves nearly a whole number of bins from one profile bin to the next it is
    smooth along the sweep: the law follows it, its residual does not show it, and the law at the block end carries
    it (measured: 8 MHz / 20 us at 10 MS/s complex, 32-sample frames, 1.024 bins per phase step: the frames' error
    per phase from -4.9 to +5.3 kHz in sweep order; this function gives an RMS of 3.5 kHz, at most 4.8 kHz there)."""
    rate_key = float(f"{abs(rate):.3g}") if math.isfinite(rate) else 0.0
    key = (int(L), rate_key, bool(cplx))
    v = _INTERP_CACHE.get(key)
    if v is not None:
        return v
    u = np.arange(L) - (L - 1) / 2.0
    fc = (0.1 if cplx else 0.25) + np.arange(INTERP_OFFSETS) / INTERP_OFFSETS / L
    ph = 2.0 * np.pi * (fc[:, None] * u[None, :] + 0.5 * rate_key * u[None, :] ** 2)
    x = (np.exp(1j * ph) if cplx else np.cos(ph)).ravel()      # frame 2j of x is segment j exactly
    S, freqs = stft_power(x, L, cplx)
    rd = frame_ridges(S, freqs, np.ones(S.shape[1]), cplx, 0.0)
    e = rd.frequency[0::2][:INTERP_OFFSETS] - fc
    v = float(np.sqrt(np.mean(e * e)))
    _INTERP_CACHE[key] = v
    return v


def bin_mean_phase(used: np.ndarray, period_frames: float, K: int) -> np.ndarray:
    """The phase (fraction of the period, in [0, 1)) each of the K profile bins really stands for: the mean phase of
    its used frames (frame t at phase ``t / period_frames mod 1``, binned as ``sweep_shape._phase_bins`` bins it); the
    bin's centre ``(k + 0.5) / K`` where it has none. used: bool, shape (frames,): the frames whose ridge entered the
    profile. Compiled (``_bin_mean_phase_kernel``)."""
    return _bin_mean_phase_kernel(np.ascontiguousarray(used, dtype=np.bool_), float(period_frames), int(K))


@njit(cache=True)
def _bin_mean_phase_kernel(used: np.ndarray, period_frames: float, K: int) -> np.ndarray:
    """bin_mean_phase, compiled (the bin of a frame as ``sweep_shape._phase_bins`` computes it)."""
    n = np.zeros(K)
    s = np.zeros(K)
    for t in range(used.size):
        if used[t]:
            ph = (t / period_frames) % 1.0
            j = int(ph * K)
            j = j if j < K - 1 else K - 1
            n[j] += 1.0
            s[j] += ph
    out = np.empty(K)
    for k in range(K):
        out[k] = s[k] / n[k] if n[k] > 0 else (k + 0.5) / K
    return out


def profile_abscissa_bias(prof: np.ndarray, inband: np.ndarray, phase_mean: np.ndarray, periods: float,
                          span: float) -> float:
    """The correction ``ridge`` adds to a frequency read off the folded profile (module docstring), cycles/sample:
    the profile read at a phase (``periods``: the time in periods) on a line through its bins placed at the mean
    phases of their frames (``bin_mean_phase``), minus what ``ridge._profile_frequency`` reads there (the bins at
    their centres): between the two nearest bins when it interpolates them; when it reads the nearer bin alone (the
    other out of band or across the flyback, a step of half the span), on the line through that bin and its neighbour
    on the same side (the phase moved at most two bins from it). 0 where there is no such neighbour or two bins' mean
    phases are closer than a quarter bin (the line through them would not be defined well)."""
    K = prof.size
    x = float(np.mod(periods, 1.0))
    pos = x * K - 0.5
    k0u = int(math.floor(pos))               # -1 .. K - 1: the bin below the phase, unwrapped

    def at(ku: int) -> float:                # bin ku's mean phase, unwrapped as ku is
        return float(phase_mean[ku % K]) + (ku - ku % K) / K

    def joined(ku: int, mu: int) -> bool:    # both in band and not across the flyback
        k, m = ku % K, mu % K
        return bool(inband[k] and inband[m] and abs(prof[k] - prof[m]) < 0.5 * span)

    if joined(k0u, k0u + 1):
        a0, a1 = at(k0u), at(k0u + 1)
        if not a1 - a0 >= 0.25 / K:
            return 0.0
        w_a = min(max((x - a0) / (a1 - a0), -1.0), 2.0)
        return float((w_a - (pos - k0u)) * (prof[(k0u + 1) % K] - prof[k0u % K]))
    ku = k0u if pos - k0u < 0.5 else k0u + 1
    mu = ku - 1 if ku == k0u else ku + 1     # the neighbour away from the bin not read
    if not inband[ku % K] or not joined(ku, mu):
        return 0.0
    ak, am = at(ku), at(mu)
    if not abs(ak - am) >= 0.25 / K:
        return 0.0
    slope = (prof[ku % K] - prof[mu % K]) / (ak - am)
    return float(slope * min(max(x - ak, -2.0 / K), 2.0 / K))


def law_at_block_end(prof: np.ndarray, inband: np.ndarray, period_frames: float, L: int, span: float,
                     phase_mean: np.ndarray | None, f: np.ndarray, used: np.ndarray | None, t_end: float,
                     cplx: bool = True, se: np.ndarray | None = None
                     ) -> tuple[float, float, float, float, float, float] | None:
    """A saw-tooth's sweep law (``_sawtooth_law`` of its fine profile prof, whose in-band bins are inband, fitted
    away from the flyback, where frames straddle it, with each bin at the mean phase of its frames phase_mean) read
    at the block end, or None when no law fits: (low, high: the swept band; the frequency at the sweep start; the
    mean rate, cycles/sample^2; the frequency at the block's last sample, NaN when the jammer is out of band there;
    its 1-sigma), cycles/sample. period_frames: the period in frames of L samples at hop L / 2; span: the swept
    band's width; f: the frames' ridge, cycles/sample; used: the frames whose ridge entered the profile (None: no
    period-drift correction); t_end: the block's last sample in frame units; cplx: complex samples; se: the bins'
    standard errors (their medians' noise; None: 0).

    The 1-sigma is the error of the law at the block end, ``sqrt(model^2 + rms^2 x^T (A^T A)^-1 x)`` (A the fit's
    Vandermonde matrix, x that of the block end's elapsed fraction, rms the bins' residual RMS about the law): the
    law's own standard error there (its leverage), and what the law misses of the sweep (model). A bin's residual
    about the law is its median's noise (se, from its frames' spread: independent from bin to bin, and averaged
    out by the law) plus what the law misses; the law at the block end carries only the second, so the model term is
    the lack of fit, ``sqrt(rms^2 - mean se^2)`` over the bins fitted, and at least the ridge's interpolation error at
    the law's rate there (``interpolation_error_rms``): a profile whose bins carry that error coherently (smooth along
    the sweep) fits the law with a residual that does not show it, and the law carries it to the block end (issue 26
    item 3: the 8 MHz / 20 us rows at 10 MS/s complex, 0-7 % within 2 sigma before); at least 1e-4 / L. Until issue
    26 item 3's second round the whole residual RMS stood in the model term (``rms sqrt(1 + x^T (A^T A)^-1 x)``, a
    prediction interval for a new bin, not for the sweep): 85 % of the law's errors within 1 sigma. The period's own
    error moves the block end's phase (``_phase_drift``): the frequency is corrected and the correction's standard
    error added in quadrature. No abscissa bias is added: the law is fitted where the frames are (module docstring).
    docs/rfi_monitor/frequency_std.md gives the coverage.

    Compiled in one pass (``_law_at_block_end_kernel``: the fit, its read at the block end, the leverage with
    numba's np.linalg.solve, the LAPACK call numpy makes, and the period drift); the same floating-point operations
    as the numpy expressions it replaced."""
    K = prof.size
    pm = (np.arange(K) + 0.5) / K if phase_mean is None else np.ascontiguousarray(phase_mean, dtype=np.float64)
    se_k = np.zeros(K) if se is None else np.ascontiguousarray(se, dtype=np.float64)
    if se_k.shape != (K,):
        raise ValueError("se must have one standard error per profile bin")
    args = (np.ascontiguousarray(prof, dtype=np.float64), np.ascontiguousarray(inband, dtype=np.bool_),
            float(period_frames), int(L), float(span), pm, np.ascontiguousarray(f, dtype=np.float64),
            np.zeros(0, dtype=np.bool_) if used is None else np.ascontiguousarray(used, dtype=np.bool_),
            float(t_end), used is not None, se_k)
    try:
        ok, f0, f1, rate, freq, slope_rate, rms, lev, dfreq, dstd, lof2 = _law_at_block_end_kernel(*args, True)
    except np.linalg.LinAlgError:        # A^T A singular: no leverage, an infinite 1-sigma
        ok, f0, f1, rate, freq, slope_rate, rms, lev, dfreq, dstd, lof2 = _law_at_block_end_kernel(*args, False)
    if not ok:
        return None
    lack_of_fit = math.sqrt(lof2)
    interpolation = interpolation_error_rms(L, slope_rate, cplx)
    model = max(lack_of_fit, interpolation)
    scatter = max(rms, interpolation)        # a bin's error is at least the interpolation error its residual hides
    fstd = max(math.sqrt(model * model + scatter * scatter * max(lev, 0.0)), 1e-4 / L)
    if math.isfinite(freq) and used is not None:
        freq += dfreq
        fstd = math.hypot(fstd, dstd)
    return min(f0, f1), max(f0, f1), f0, rate, freq, fstd


@njit(cache=True)
def _law_at_block_end_kernel(prof: np.ndarray, inband: np.ndarray, period_frames: float, L: int, span: float,
                             phase_mean: np.ndarray, f: np.ndarray, used: np.ndarray, t_end: float, drift: bool,
                             se: np.ndarray, solve: bool) -> tuple[bool, float, float, float, float, float, float,
                                                                   float, float, float, float]:
    """law_at_block_end, compiled: (a law fitted, f0 = the law at the sweep start, f1 = at its end, the mean rate,
    the frequency at the block end (NaN out of band), the law's rate there (cycles/sample^2), the fit's residual
    RMS, the leverage x^T (A^T A)^-1 x (inf when not solve), the period drift's correction and its standard error
    (0, 0 when not drift or out of band), the law's lack of fit squared: rms^2 less the fitted bins' mean
    squared standard error se, at least 0)."""
    hop = L // 2
    ok, phi_j, coef, rms, ee, kk = _sawtooth_law_kernel(prof, inband, period_frames * hop, L, span, phase_mean)
    if not ok:
        return False, np.nan, np.nan, np.nan, np.nan, np.nan, np.nan, np.nan, 0.0, 0.0, 0.0

    f0, f1 = polyval(coef, 0.0), polyval(coef, 1.0)
    rate = (f1 - f0) / (period_frames * hop)
    ph_end = (t_end / period_frames) % 1.0
    e_end = (ph_end - phi_j) % 1.0
    deg = coef.size - 1
    slope = 0.0                              # d frequency / d e at the block end
    for i in range(deg):
        slope += (deg - i) * coef[i] * e_end ** (deg - i - 1)
    noise2 = 0.0                             # the fitted bins' mean squared standard error
    for k in kk:
        noise2 += se[k] * se[k]
    lof2 = max(rms * rms - noise2 / kk.size, 0.0)
    lev = np.inf
    if solve:
        A = np.vander(ee, deg + 1)
        xv = np.vander(np.array([e_end]), deg + 1)[0]
        lev = xv @ np.linalg.solve(A.T @ A, xv)
    freq = np.nan
    dfreq, dstd = 0.0, 0.0
    if inband[min(int(ph_end * inband.size), inband.size - 1)]:
        freq = polyval(coef, e_end)
        if drift:
            dfreq, dstd = _phase_drift(phi_j, coef, f, used, period_frames, L, prof.size, t_end)
    return True, f0, f1, rate, freq, slope / (period_frames * hop), rms, lev, dfreq, dstd, lof2


@njit(cache=True)
def _phase_drift(phi_j: float, coef: np.ndarray, f: np.ndarray, used: np.ndarray, period_frames: float, L: int,
                 K: int, t_end: float) -> tuple[float, float]:
    """The error of the law (flyback phase phi_j, polynomial coef in the elapsed sweep fraction) at the block end
    that an error in the period makes, and its 1-sigma, cycles/sample: (the correction to add to the law's frequency
    there, its standard error).

    The frames are folded at t / period_frames; a period off by a small relative error eps puts frame t at a phase off
    by eps t / period_frames. The law, fitted to frames spread over the block, absorbs the mean of that shift, so at a
    frame t it is off by slope(e_t) eps (t - t_mean) / period_frames (slope: d frequency / d elapsed fraction), and at
    the block end, half a block after the frames' mean, by the most (measured: 8 MHz / 20 us at 10 MS/s complex,
    12.5 frames per period, 50 periods per block: a period 0.0003 frames off, the estimate's own scatter there, moves
    the block end 4.5 kHz). eps is the least-squares slope of the frames' residuals about the law on
    slope(e_t) (t - t_mean) / period_frames over the frames the law was fitted on (their elapsed fraction outside the
    flyback guard; residuals beyond 5 scaled MADs left out); its standard error from their scatter. f: the frames'
    ridge, cycles/sample; used: the frames whose ridge entered the profile; K: the profile's bins; t_end: the block's
    last sample in frame units. (0, 0) when fewer than 8 frames remain. Compiled: the numpy expressions it replaced
    (np.mod, np.polyval, np.polyder, the mean in numpy's pairwise order, np.median, np.dot), operation for
    operation (numba's np.median selects the same element(s); its np.dot calls the same BLAS ddot)."""
    deg = coef.size - 1
    dcoef = np.zeros(max(deg, 1))            # np.polyder(coef)
    for i in range(deg):
        dcoef[i] = coef[i] * (deg - i)
    guard = 0.5 * L / (period_frames * (L // 2)) + 1.0 / K
    n = used.size
    t = np.empty(n)
    e = np.empty(n)
    m = 0
    for i in range(n):
        if used[i]:
            ei = (i / period_frames - phi_j) % 1.0
            if ei > guard and ei < 1.0 - guard:
                t[m] = i
                e[m] = ei
                m += 1
    if m < 8:
        return 0.0, 0.0
    tm = pairwise_sum(t[:m], 0.0) / m
    r = np.empty(m)
    x = np.empty(m)
    for i in range(m):
        r[i] = f[int(t[i])] - polyval(coef, e[i])
        x[i] = polyval(dcoef, e[i]) * (t[i] - tm) / period_frames
    med = np.median(r)
    ad = np.abs(r - med)
    mad = 1.4826 * np.median(ad)
    keep = ad <= 5.0 * mad if mad > 0 else np.ones(m, dtype=np.bool_)
    xk = x[keep]
    rk = r[keep] - med
    sxx = np.dot(xk, xk)
    if xk.size < 8 or not sxx > 0:
        return 0.0, 0.0
    eps = np.dot(xk, rk) / sxx
    res = rk - eps * xk
    se = math.sqrt(np.dot(res, res) / (xk.size - 2) / sxx)
    e_end = ((t_end / period_frames) % 1.0 - phi_j) % 1.0
    lever = polyval(dcoef, e_end) * (t_end - tm) / period_frames
    return eps * lever, abs(se * lever)

