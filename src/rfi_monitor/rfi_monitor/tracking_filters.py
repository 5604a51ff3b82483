"""Kalman trackers of the jammer's instantaneous frequency: KF, AKF and the adaptive fading KF.

One implementation serves the three filters of Kang et al., Sec. 3.1 and 4, on the state
``x = [f_n, df_n]`` (digital frequency, cycles/sample, and its change per sample):

    x_{n+1} = [[1, 1], [0, 1]] x_n + [w_n, w'_n],   z_n = [1, 0] x_n + v_n        (eq. 19-20)

with ``w ~ N(0, q_f)``. Eq. 19 has no noise on df (``q_df = 0``); the default here is a small
``q_df`` (process_rate_std 1e-6 cycles/sample^2): with q_df = 0, P(2,2) collapses during the
samples before the sweep period locks (the filter then averages the saw-tooth to df ~ 0) and the
rate never recovers once resets start (measured at J/N 11 dB: frequency RMSE 0.023 with q_df = 0
against 0.012 with 1e-6). Set it to 0 to run eq. 19 verbatim.

The gain is scaled by a factor from the innovation window of length M (eq. 11-13):

    C_n = H P_n^- H^T + R,   C^_n = 1/(M-1) sum_{i=n-M+1..n} nu_i^2,   a_n = max(1, C^_n / C_n)

* ``MODE_KF``   : K_n = P^- H^T C^-1                      (conventional KF)
* ``MODE_AKF``  : K_n = a_n P^- H^T C^-1                  (Kang et al. Sec. 4, after Kim et al. 2009),
  with a_n capped so that K(1) <= 1 (an uncapped a_n K overshoots the measurement and, with a
  small R, diverges to inf/NaN within a few hundred samples)
* ``MODE_AFKF`` : K_n = (1 / a_n) P^- H^T C^-1            (proposed, eq. 14)

The covariance update uses the Joseph form ``(I - K H) P (I - K H)^T + K R K^T``, which equals
eq. 17 for the optimal gain (a_n = 1) and stays positive semi-definite for a scaled gain (eq. 17
with a_n K can turn P(1,1) negative when a_n P11 / C > 1).

The sweep reset (eq. 21-22): at an estimated sweep start, after m = T - 1 samples of the last
sweep, ``f^_0 = f^_{T-1} - (T - 1) df^_{T-1}`` and ``P(1,1) = P11 + (T - 1)^2 P22``; as in the
paper, f~ and df~ are taken as uncorrelated, so P(1,2) is set to 0 and P(2,2) kept.

For a complex (signed) measurement the innovation is wrapped to [-0.5, 0.5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

MODE_KF = 0
MODE_AKF = 1
MODE_AFKF = 2

# layout of the float state vector of one filter
F_F, F_DF, F_P11, F_P12, F_P22, F_WSUM = 0, 1, 2, 3, 4, 5
N_FSTATE = 6
# layout of the int state vector of one filter
I_WCOUNT, I_WPOS = 0, 1
N_ISTATE = 2


@dataclass(frozen=True)
class TrackingFilterParams:
    """Parameters of the frequency tracker (all frequencies digital, cycles/sample).

    Attributes:
        mode: MODE_KF, MODE_AKF or MODE_AFKF.
        measurement_std: sigma_v of eq. 20, cycles/sample, > 0.
        process_std: sigma_w on f of eq. 19, cycles/sample, >= 0.
        process_rate_std: noise on df per sample, cycles/sample^2, >= 0 (eq. 19: 0).
        window: innovation window M of eq. 12, >= 2.
        initial_frequency: f at start, cycles/sample.
        initial_frequency_std: 1-sigma of f at start, cycles/sample, > 0.
        initial_rate_std: 1-sigma of df at start, cycles/sample^2, > 0.
    """

    mode: int = MODE_AFKF
    measurement_std: float = 0.08
    process_std: float = 1e-4
    process_rate_std: float = 1e-6
    window: int = 16
    initial_frequency: float = 0.25
    initial_frequency_std: float = 0.15
    initial_rate_std: float = 2e-3

    def __post_init__(self) -> None:
        if self.mode not in (MODE_KF, MODE_AKF, MODE_AFKF):
            raise ValueError(f"mode must be MODE_KF, MODE_AKF or MODE_AFKF, got {self.mode}")
        if not (math.isfinite(self.measurement_std) and self.measurement_std > 0):
            raise ValueError("measurement_std must be finite and > 0")
        for name in ("process_std", "process_rate_std"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be finite and >= 0")
        for name in ("initial_frequency_std", "initial_rate_std"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be finite and > 0")
        if not math.isfinite(self.initial_frequency):
            raise ValueError("initial_frequency must be finite")
        if int(self.window) < 2:
            raise ValueError("window must be >= 2")

    def as_array(self) -> np.ndarray:
        """Packed float parameters for the compiled kernels: [mode, R, q_f, q_df, M]."""
        return np.array([self.mode, self.measurement_std ** 2, self.process_std ** 2,
                         self.process_rate_std ** 2, self.window], dtype=np.float64)

    def initial_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(float state, int state, innovation ring buffer) at start."""
        fst = np.zeros(N_FSTATE)
        fst[F_F] = self.initial_frequency
        fst[F_P11] = self.initial_frequency_std ** 2
        fst[F_P22] = self.initial_rate_std ** 2
        return fst, np.zeros(N_ISTATE, dtype=np.int64), np.zeros(int(self.window))


@njit(cache=True, inline="always")
def kf_predict(f: float, df: float, p11: float, p12: float, p22: float, q_f: float,
               q_df: float) -> tuple[float, float, float, float, float]:
    """Time update (eq. 15-16) with F = [[1, 1], [0, 1]]; returns (f, df, P11, P12, P22)."""
    return f + df, df, p11 + 2.0 * p12 + p22 + q_f, p12 + p22, p22 + q_df


@njit(cache=True, inline="always")
def kf_gain_scale(mode: int, c: float, c_hat: float, p11: float) -> float:
    """Gain factor g of K = g P^- H^T C^-1 (eq. 13-14 and the AKF of Sec. 4).

    Args:
        mode: MODE_KF / MODE_AKF / MODE_AFKF.
        c: computed innovation variance H P^- H^T + R (eq. 11).
        c_hat: windowed innovation variance (eq. 12); < 0 while the window is not yet full (g = 1).
        p11: P^-(1,1).
    """
    if mode == MODE_KF or c_hat < 0.0:
        return 1.0
    alpha = max(1.0, c_hat / c)                          # eq. 13
    if mode == MODE_AKF:
        return min(alpha, c / p11)                       # AKF, capped so that K(1) <= 1
    return 1.0 / alpha                                   # eq. 14


@njit(cache=True, inline="always")
def kf_update(f: float, df: float, p11: float, p12: float, p22: float, nu: float, r: float,
              g: float) -> tuple[float, float, float, float, float]:
    """Measurement update with the scaled gain (eq. 14, 17-18; Joseph form); returns the state.

    Args:
        f, df, p11, p12, p22: prior state and covariance.
        nu: innovation z - f, cycles/sample (already wrapped for signed measurements).
        r: measurement variance R, (cycles/sample)^2.
        g: gain factor from ``kf_gain_scale``.
    """
    c = p11 + r
    k1 = g * p11 / c
    k2 = g * p12 / c
    a11 = (1.0 - k1) * p11                               # Joseph form of eq. 17
    a12 = (1.0 - k1) * p12
    a21 = p12 - k2 * p11
    a22 = p22 - k2 * p12
    return (f + k1 * nu, df + k2 * nu, a11 * (1.0 - k1) + k1 * k1 * r, -a11 * k2 + a12 + k1 * k2 * r,
            -a21 * k2 + a22 + k2 * k2 * r)


@njit(cache=True, inline="always")
def kf_sweep_reset(f: float, df: float, p11: float, p22: float,
                   samples_since_start: float) -> tuple[float, float, float]:
    """Reset at a sweep start (eq. 21-22) from the posterior at T - 1; returns (f0, P11, P12 = 0).

    ``samples_since_start`` = T - 1 of the last sweep. f~ and df~ are taken as uncorrelated (eq. 22).
    """
    m = samples_since_start
    return f - m * df, p11 + m * m * p22, 0.0


@njit(cache=True, inline="always")
def window_push(ring: np.ndarray, pos: int, count: int, wsum: float, nu2: float) -> tuple[int, int, float]:
    """Slide the innovation window of eq. 12 by one squared innovation; returns (pos, count, sum)."""
    m = ring.size
    if count >= m:
        wsum -= ring[pos]
    else:
        count += 1
    ring[pos] = nu2
    wsum += nu2
    pos = pos + 1 if pos + 1 < m else 0
    return pos, count, wsum


@njit(cache=True)
def _run(z: np.ndarray, valid: np.ndarray, reset: np.ndarray, par: np.ndarray, fst: np.ndarray,
         ist: np.ndarray, ring: np.ndarray, wrap: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = z.size
    mode = int(par[0])
    r, q_f, q_df = par[1], par[2], par[3]
    m_win = ring.size
    f, df, p11, p12, p22, wsum = fst[F_F], fst[F_DF], fst[F_P11], fst[F_P12], fst[F_P22], fst[F_WSUM]
    count, pos = ist[I_WCOUNT], ist[I_WPOS]
    f_out = np.empty(n)
    df_out = np.empty(n)
    p11_out = np.empty(n)
    last_start = 0
    for k in range(n):
        if k > 0:
            f, df, p11, p12, p22 = kf_predict(f, df, p11, p12, p22, q_f, q_df)
            if reset[k]:
                # the state predicts sample k; eq. 21 uses the posterior at T - 1 = k - 1
                f, p11, p12 = kf_sweep_reset(f - df, df, p11, p22, float(k - 1 - last_start))
                last_start = k
        if valid[k]:
            nu = z[k] - f
            if wrap:
                nu = nu - math.floor(nu + 0.5)
            pos, count, wsum = window_push(ring, pos, count, wsum, nu * nu)
            c_hat = max(wsum, 0.0) / (m_win - 1) if count >= m_win else -1.0
            g = kf_gain_scale(mode, p11 + r, c_hat, p11)
            f, df, p11, p12, p22 = kf_update(f, df, p11, p12, p22, nu, r, g)
        f_out[k] = f
        df_out[k] = df
        p11_out[k] = p11
    fst[F_F], fst[F_DF], fst[F_P11], fst[F_P12], fst[F_P22], fst[F_WSUM] = f, df, p11, p12, p22, wsum
    ist[I_WCOUNT], ist[I_WPOS] = count, pos
    return f_out, df_out, p11_out


def run_tracking_filter(z: np.ndarray, params: TrackingFilterParams = TrackingFilterParams(),
                        reset_mask: np.ndarray | None = None, signed: bool = False
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run one tracker over a measurement sequence (stand-alone; the monitor fuses it in its loop).

    Args:
        z: measurements, cycles/sample, shape (n,); NaN marks a rejected sample (prediction only).
        params: TrackingFilterParams.
        reset_mask: optional bool shape (n,): True at samples where a sweep starts (eq. 21-22).
        signed: complex (signed) measurements: wrap innovations.

    Returns:
        (f, df, p11): posterior frequency (cycles/sample), rate (cycles/sample^2) and P(1,1),
        each shape (n,).
    """
    z = np.ascontiguousarray(z, dtype=np.float64)
    if z.ndim != 1:
        raise ValueError("z must be 1-D")
    valid = np.isfinite(z)
    reset = np.zeros(z.size, dtype=np.bool_) if reset_mask is None else np.asarray(reset_mask, dtype=np.bool_)
    if reset.shape != z.shape:
        raise ValueError("reset_mask must have the shape of z")
    fst, ist, ring = params.initial_state()
    zz = np.where(valid, z, 0.0)
    return _run(zz, valid, reset, params.as_array(), fst, ist, ring, bool(signed))
