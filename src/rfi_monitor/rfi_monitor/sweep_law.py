"""Stage 6 of the ridge analysis (orchestrated by ``rfi_monitor.ridge.analyse``), for a saw-tooth: its sweep law
(ours).

The flyback is the largest step between consecutive in-band bins of the folded profile
(``rfi_monitor.sweep_shape``); a quadratic in the elapsed sweep fraction (a rate that changes along the sweep) is
fitted to the bins away from it (``_sawtooth_law``). The law gives the swept band's ends, the mean rate and the
frequency at the block's last sample (read at that sample's phase of the period: ``read_law``), its 1-sigma from the
fit's residual.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from rfi_monitor.numpy_kernels import pairwise_sum, polyfit, polyval


def _sawtooth_law(prof: np.ndarray, inband: np.ndarray, period_samples: float, L: int, span: float
                  ) -> tuple[float, np.ndarray, float, np.ndarray] | None:
    """(flyback phase, polynomial in the elapsed sweep fraction, RMS residual of the fit, the elapsed fractions of the
    bins fitted) of a saw-tooth's folded profile, or None.

    The flyback is the largest step between consecutive in-band bins. Bins within half a frame (plus one
    bin) of it are left out: their frames straddle the flyback. A quadratic (a rate that changes along the
    sweep; linear with fewer than 8 bins) is fitted to the others against the elapsed fraction of the
    sweep since the flyback; None when fewer than 4 bins remain or the fit leaves an RMS residual above a
    tenth of the span. Compiled (``_sawtooth_law_kernel``: np.polyfit's scaled least squares)."""
    ok, phi_j, coef, rms, ee = _sawtooth_law_kernel(np.ascontiguousarray(prof, dtype=np.float64),
                                                    np.ascontiguousarray(inband, dtype=np.bool_),
                                                    float(period_samples), int(L), float(span))
    return (phi_j, coef, rms, ee) if ok else None


@njit(cache=True)
def _sawtooth_law_kernel(prof: np.ndarray, inband: np.ndarray, period_samples: float, L: int, span: float
                         ) -> tuple[bool, float, np.ndarray, float, np.ndarray]:
    """_sawtooth_law, compiled: (found, flyback phase, coefficients, RMS, elapsed fractions fitted)."""
    K = prof.size
    none = (False, np.nan, np.zeros(3), np.nan, np.zeros(0))
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
    m = 0
    for k in range(K):
        c = (k + 0.5) / K
        e = (c - phi_j) % 1.0                # Python's float % is np.mod: into [0, 1)
        if inband[k] and np.isfinite(prof[k]) and e > guard and e < 1.0 - guard:
            ee[m] = e
            pp[m] = prof[k]
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
    return True, phi_j, coef, rms, ee[:m].copy()


def prediction_std(ee: np.ndarray, deg: int, e: float, rms: float) -> float:
    """1-sigma of what a least-squares polynomial (degree deg, fitted at abscissae ee with residual RMS rms) predicts
    at e for a new point: ``rms sqrt(1 + x^T (A^T A)^-1 x)``, A the fit's Vandermonde matrix and x that of e (the
    residual scatter, which a smooth law does not follow, plus the law's own standard error at e: its leverage)."""
    A = np.vander(ee, deg + 1)
    xv = np.vander(np.asarray([e]), deg + 1)[0]
    try:
        lev = float(xv @ np.linalg.solve(A.T @ A, xv))
    except np.linalg.LinAlgError:
        return math.inf
    return rms * math.sqrt(1.0 + max(lev, 0.0))


def read_law(law: tuple[float, np.ndarray, float, np.ndarray], inband: np.ndarray, period_frames: float, L: int,
             t_end: float) -> tuple[float, float, float, float, float, float]:
    """What a saw-tooth's law (``_sawtooth_law`` of the fine profile whose in-band bins are inband, fitted away from
    the flyback, where frames straddle it) gives: (low, high: the swept band; the frequency at the sweep start; the
    mean rate, cycles/sample^2; the frequency at the block's last sample, NaN when the jammer is out of band there; its
    1-sigma), cycles/sample. period_frames: the period in frames of L samples at hop L / 2; t_end: the block's last
    sample in frame units.

    The 1-sigma is the law's prediction interval at the block end's phase (``prediction_std``: the residual RMS of
    the profile around the law, which the sweep at that moment may deviate by as any profile bin does, with the law's
    own standard error there). Issue 26 item 3: twice the RMS, before, covered 89 % of the errors over the rows of
    docs/rfi_monitor/real_jammers.md (median |error| / std 0.14 on the simulated ones); the law's standard error
    alone covered 52 % (0-17 % on the 2-bit real captures, whose sweeps deviate from a smooth law); that document
    gives the coverage now."""
    phi_j, coef, rms, ee = law
    hop = L // 2
    f0, f1 = polyval(coef, 0.0), polyval(coef, 1.0)
    rate = (f1 - f0) / (period_frames * hop)
    ph_end = float(np.mod(t_end / period_frames, 1.0))
    e_end = (ph_end - phi_j) % 1.0
    fstd = max(prediction_std(ee, coef.size - 1, e_end, rms), 1e-4 / L)
    freq = math.nan
    if inband[min(int(ph_end * inband.size), inband.size - 1)]:
        freq = polyval(coef, e_end)
    return min(f0, f1), max(f0, f1), f0, rate, freq, fstd
