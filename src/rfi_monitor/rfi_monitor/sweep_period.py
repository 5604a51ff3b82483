"""Sweep-period estimation of a saw-tooth chirp: LPD, AR pattern enhancement, peak detection.

Kang et al., Sec. 3.2:

1. Low-pass differentiator (Laguna et al. 1990), G(z) = 1 - z^-6, with forgetting factor gamma
   and normalisation beta (eq. 23):
   ``zG_n = gamma zG_{n-1} - (1 - gamma) (z_n - z_{n-6}) / (beta (f_max - f_min) / fs)``.
   At a sweep start z drops by the sweep bandwidth, so zG shows a positive peak (a down-chirp
   gives a negative one; we detect |zG| peaks of the sign that the rate estimate predicts, see
   ``sign``). A rejected measurement is replaced by the tracker's prediction.
2. AR(p) pattern enhancement (Oikonomou et al. 2006): zG is an AR(p) process whose coefficients
   Gamma follow ``Gamma_n = A Gamma_{n-1} + w`` (A = 0.2 I, eq. 25) and are estimated by a
   Kalman filter from ``zG_n = C_n^T Gamma_n + v`` (C_n = past p values, eq. 26); the enhanced
   pattern is ``zAR_n = C_n^T Gamma^_n`` (eq. 27). p = 10.
3. Peak: the maximum of zAR over an excursion above the threshold
   ``max(beta_en (f_max - f_min) / fs, kappa * noise level of zAR)`` (the paper's fixed threshold,
   plus a noise-relative floor so that the same parameters work at any J/N).
4. Period: from successive peak times. Interval d_i is consistent when d_i is within ``tol`` of
   an integer multiple q_i (1 or 2) of the median interval (a missed peak gives q = 2);
   ``T^ = sum d_i / sum q_i`` over the consistent intervals of the last 16 peaks; the estimate is
   locked when at least ``min_consistent`` intervals, and at least 60 % of them, agree (false
   peaks from noise give inconsistent intervals and so no lock).

Decimation (documented deviation, for speed): the LPD runs at the full rate; its output is
averaged over ``decimation`` samples and the AR Kalman filter (p x p covariance, O(p^2) per
step) and peak detector run at the decimated rate. A peak time is then known to +-D/2 samples,
and the period, averaged over up to 15 intervals, to about D / sum(q) samples.
The peak is late with respect to the sweep start by the LPD length (the 6-sample difference
reaches its full value 5 samples after the jump) plus the half decimation block; ``delay``
removes this deterministic group delay.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

LPD_LAG = 6
"""Lag of the low-pass differentiator G(z) = 1 - z^-6 (Kang et al., eq. 23)."""
AR_ORDER = 10
"""AR model order p (Kang et al., Sec. 3.2)."""
PEAK_RING = 16
"""Number of recent peak times kept for the period estimate."""

# float state layout
S_ZG, S_ACC, S_NOISE, S_PKMAX, S_PERIOD, S_ZAR = 0, 1, 2, 3, 4, 5
N_SFSTATE = 6
# int state layout
J_DEC, J_INPEAK, J_PKIDX, J_NPEAKS, J_RPOS, J_RCOUNT, J_LOCKED, J_ZPOS, J_ZCOUNT, J_NDEC = range(10)
N_SISTATE = 10


@dataclass(frozen=True)
class SweepPeriodParams:
    """Design parameters of the sweep-period estimator (Kang et al. give no values; these are ours).

    Attributes:
        forgetting: gamma of eq. 23, in [0, 1).
        beta: normalisation beta of eq. 23, > 0.
        beta_en: enhancement rate beta_en of the peak threshold, >= 0.
        kappa: noise-relative threshold factor (multiples of the mean |zAR| outside peaks), > 0.
        noise_time_constant: decimated steps of the EWMA of |zAR|, >= 1.
        decimation: D, samples averaged per AR step, >= 1.
        ar_process_var: diagonal of Q_AR (eq. 25), > 0.
        ar_measurement_var: sigma_AR^2 (eq. 26), > 0.
        ar_transition: diagonal of A (eq. 25; the paper: 0.2).
        delay: samples from a sweep start to its detected peak (group delay), >= 0.
        min_separation: minimum samples between two peaks (refractory), >= 1.
        tolerance: relative tolerance of an interval to a multiple of the median, in (0, 0.5).
        min_consistent: consistent intervals needed to lock, >= 1.
    """

    forgetting: float = 0.92
    beta: float = 1.0
    beta_en: float = 1e-4
    kappa: float = 8.0
    noise_time_constant: float = 256.0
    decimation: int = 2
    ar_process_var: float = 1.0
    ar_measurement_var: float = 1.0
    ar_transition: float = 0.2
    delay: float = 12.0
    min_separation: int = 24
    tolerance: float = 0.05
    min_consistent: int = 3

    def __post_init__(self) -> None:
        if not 0.0 <= self.forgetting < 1.0:
            raise ValueError("forgetting must be in [0, 1)")
        for name in ("beta", "kappa", "ar_process_var", "ar_measurement_var"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be finite and > 0")
        if not (math.isfinite(self.beta_en) and self.beta_en >= 0):
            raise ValueError("beta_en must be >= 0")
        if not self.noise_time_constant >= 1:
            raise ValueError("noise_time_constant must be >= 1")
        if int(self.decimation) < 1:
            raise ValueError("decimation must be >= 1")
        if not -1.0 < self.ar_transition < 1.0:
            raise ValueError("ar_transition must be in (-1, 1)")
        if not self.delay >= 0:
            raise ValueError("delay must be >= 0")
        if int(self.min_separation) < 1:
            raise ValueError("min_separation must be >= 1")
        if not 0.0 < self.tolerance < 0.5:
            raise ValueError("tolerance must be in (0, 0.5)")
        if int(self.min_consistent) < 1:
            raise ValueError("min_consistent must be >= 1")

    def as_array(self, band: float) -> np.ndarray:
        """Packed parameters for the kernels; ``band`` = (f_max - f_min) / fs, cycles/sample."""
        return np.array([self.forgetting, self.beta * band, self.beta_en * band, self.kappa,
                         1.0 / self.noise_time_constant, self.decimation, self.ar_process_var,
                         self.ar_measurement_var, self.ar_transition, self.delay, self.min_separation,
                         self.tolerance, self.min_consistent], dtype=np.float64)


def initial_state() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                             np.ndarray]:
    """(float state, int state, z history, AR Gamma, AR P, AR history, peak ring) at start."""
    sf = np.zeros(N_SFSTATE)
    sf[S_PERIOD] = math.nan
    return (sf, np.zeros(N_SISTATE, dtype=np.int64), np.zeros(LPD_LAG), np.zeros(AR_ORDER),
            np.vstack([np.eye(AR_ORDER), np.zeros((1, AR_ORDER))]), np.zeros(AR_ORDER),
            np.zeros(PEAK_RING, dtype=np.int64))


@njit(cache=True)
def _update_period(sf: np.ndarray, si: np.ndarray, peaks: np.ndarray, tol: float,
                   min_consistent: int) -> None:
    """Re-estimate the period from the stored peak times (step 4 of the module docstring)."""
    cnt = si[J_RCOUNT]
    if cnt < 2:
        return
    k = peaks.size
    start = (si[J_RPOS] - cnt) % k
    d = np.empty(cnt - 1)
    prev = peaks[start]
    for i in range(1, cnt):
        cur = peaks[(start + i) % k]
        d[i - 1] = cur - prev
        prev = cur
    med = np.median(d)
    if med <= 0:
        return
    sd = 0.0
    sq = 0.0
    nc = 0
    for i in range(d.size):
        q = math.floor(d[i] / med + 0.5)
        if 1 <= q <= 2 and abs(d[i] - q * med) <= tol * med * q:
            sd += d[i]
            sq += q
            nc += 1
    if nc >= min_consistent and 5 * nc >= 3 * d.size:
        sf[S_PERIOD] = sd / sq
        si[J_LOCKED] = 1
    else:
        si[J_LOCKED] = 0


@njit(cache=True, inline="always")
def sweep_step(n: int, z: float, sf: np.ndarray, si: np.ndarray, zhist: np.ndarray, gam: np.ndarray,
               pmat: np.ndarray, hist: np.ndarray, peaks: np.ndarray, par: np.ndarray, sign: float,
               wrap: bool) -> int:
    """Consume one measurement; return the estimated sweep-start sample index of a newly
    detected peak, or -1.

    Args:
        n: absolute sample index of z.
        z: measurement (or the tracker's prediction for a rejected sample), cycles/sample.
        sf, si, zhist, gam, pmat, hist, peaks: estimator state, updated in place (pmat has shape
            (p + 1, p): the AR covariance, upper triangle valid, and a scratch row).
        par: ``SweepPeriodParams.as_array(band)``.
        sign: +1 to detect sweep starts of an up-chirp (z drops), -1 for a down-chirp.
        wrap: wrap differences to [-0.5, 0.5) (signed complex measurements).
    """
    gamma = par[0]
    norm = par[1]
    # --- LPD (eq. 23) -----------------------------------------------------------------------
    pos = si[J_ZPOS]
    if si[J_ZCOUNT] >= zhist.size:
        dz = z - zhist[pos]
        if wrap:
            dz = dz - math.floor(dz + 0.5)
    else:
        dz = 0.0
        si[J_ZCOUNT] += 1
    zhist[pos] = z
    si[J_ZPOS] = pos + 1 if pos + 1 < zhist.size else 0
    zg = gamma * sf[S_ZG] - (1.0 - gamma) * dz / norm
    sf[S_ZG] = zg
    # --- decimation -----------------------------------------------------------------------
    sf[S_ACC] += zg * sign
    si[J_DEC] += 1
    dec = int(par[5])
    if si[J_DEC] < dec:
        return -1
    v = sf[S_ACC] / dec
    sf[S_ACC] = 0.0
    si[J_DEC] = 0
    si[J_NDEC] += 1
    # --- AR(p) Kalman filter (eq. 24-27) ------------------------------------------------------
    p = gam.size
    a = par[8]
    q_ar = par[6]
    r_ar = par[7]
    a2 = a * a
    pred = 0.0
    for i in range(p):
        gam[i] = a * gam[i]
        pred += hist[i] * gam[i]
    # P- = A P A^T + Q (A = a I), PC = P- C, s = C^T P- C + R; P is symmetric: the upper
    # triangle is updated and mirrored (halves the O(p^2) work); pc lives in pmat's extra row
    pc = pmat[p]
    for i in range(p):
        pmat[i, i] = a2 * pmat[i, i] + q_ar
        for j in range(i + 1, p):
            pmat[i, j] = a2 * pmat[i, j]
    for i in range(p):
        acc = 0.0
        for j in range(i):
            acc += pmat[j, i] * hist[j]
        for j in range(i, p):
            acc += pmat[i, j] * hist[j]
        pc[i] = acc
    s = r_ar
    for i in range(p):
        s += hist[i] * pc[i]
    innov = v - pred
    inv_s = 1.0 / s
    zar = 0.0
    for i in range(p):
        gam[i] += pc[i] * inv_s * innov
        zar += hist[i] * gam[i]
    for i in range(p):
        ki = pc[i] * inv_s
        for j in range(i, p):
            pmat[i, j] -= ki * pc[j]
    for i in range(p - 1, 0, -1):
        hist[i] = hist[i - 1]
    hist[0] = v
    sf[S_ZAR] = zar
    # --- peak detection -------------------------------------------------------------------------
    thr = max(par[2], par[3] * sf[S_NOISE])
    out = -1
    if zar > thr and si[J_NDEC] > 2 * p:
        if si[J_INPEAK] == 0:
            si[J_INPEAK] = 1
            sf[S_PKMAX] = zar
            si[J_PKIDX] = n - dec // 2
        elif zar > sf[S_PKMAX]:
            sf[S_PKMAX] = zar
            si[J_PKIDX] = n - dec // 2
    else:
        if si[J_INPEAK] == 1:
            si[J_INPEAK] = 0
            t_pk = si[J_PKIDX]
            last = peaks[(si[J_RPOS] - 1) % peaks.size]
            if si[J_RCOUNT] == 0 or t_pk - last >= int(par[10]):
                peaks[si[J_RPOS]] = t_pk
                si[J_RPOS] = (si[J_RPOS] + 1) % peaks.size
                if si[J_RCOUNT] < peaks.size:
                    si[J_RCOUNT] += 1
                si[J_NPEAKS] += 1
                _update_period(sf, si, peaks, par[11], int(par[12]))
                out = t_pk - int(par[9] + 0.5)
        # noise level: EWMA of |zAR| outside peaks
        lam = par[4]
        sf[S_NOISE] = (1.0 - lam) * sf[S_NOISE] + lam * abs(zar)
    return out


@njit(cache=True)
def _run(z: np.ndarray, par: np.ndarray, sign: float, wrap: bool) -> tuple[np.ndarray, np.ndarray,
                                                                           np.ndarray, float, int]:
    sf, si = np.zeros(N_SFSTATE), np.zeros(N_SISTATE, dtype=np.int64)
    sf[S_PERIOD] = math.nan
    zhist = np.zeros(LPD_LAG)
    gam = np.zeros(AR_ORDER)
    pmat = np.zeros((AR_ORDER + 1, AR_ORDER))
    for i in range(AR_ORDER):
        pmat[i, i] = 1.0
    hist = np.zeros(AR_ORDER)
    peaks = np.zeros(PEAK_RING, dtype=np.int64)
    zg = np.empty(z.size)
    zar = np.empty(z.size)
    starts = np.full(z.size, -1, dtype=np.int64)
    ns = 0
    for n in range(z.size):
        s = sweep_step(n, z[n], sf, si, zhist, gam, pmat, hist, peaks, par, sign, wrap)
        if s >= 0:
            starts[ns] = s
            ns += 1
        zg[n] = sf[S_ZG]
        zar[n] = sf[S_ZAR]
    return zg, zar, starts[:ns], sf[S_PERIOD], si[J_LOCKED]


def estimate_sweep_period(z: np.ndarray, params: SweepPeriodParams = SweepPeriodParams(), band: float = 0.5,
                          sign: float = 1.0, signed: bool = False
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, bool]:
    """Stand-alone sweep-period estimate from a measurement sequence (the monitor fuses this).

    Args:
        z: IF measurements, cycles/sample, shape (n,), finite.
        params: SweepPeriodParams.
        band: (f_max - f_min) / fs, observable band in cycles/sample (real: 0.5, complex: 1.0).
        sign: +1 up-chirp, -1 down-chirp.
        signed: wrap differences (complex measurements).

    Returns:
        (zG, zAR, sweep_starts, period_samples, locked): zG and zAR shape (n,) (zAR held between
        decimated steps); estimated sweep-start indices; period in samples (NaN if none).
    """
    z = np.ascontiguousarray(z, dtype=np.float64)
    if z.ndim != 1 or not np.all(np.isfinite(z)):
        raise ValueError("z must be 1-D and finite")
    if not band > 0:
        raise ValueError("band must be > 0")
    zg, zar, st, per, lock = _run(z, params.as_array(band), float(sign), bool(signed))
    return zg, zar, st, float(per), bool(lock)
