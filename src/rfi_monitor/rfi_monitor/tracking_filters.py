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

Speed (``filter_step``, used by the stand-alone runner and the fused loop alike): the gain of the
fading filter is ``K = P^- H^T / max(C_n, C^_n)`` (one division), the update and the next
prediction are fused (``kf_update_predict``), and a rejected sample runs the same arithmetic with
K = 0 (selects, no branch), so that the per-sample serial chain is short.

The sweep reset (eq. 21-22): at an estimated sweep start, after m = T - 1 samples of the last
sweep, ``f^_0 = f^_{T-1} - (T - 1) df^_{T-1}`` and ``P(1,1) = P11 + (T - 1)^2 P22``; as in the
paper, f~ and df~ are taken as uncorrelated, so P(1,2) is set to 0 and P(2,2) kept. The monitor
can instead keep the exact covariance of that linear map (``kf_sweep_reset(cross_covariance=True)``,
beyond the paper; the stand-alone runner here uses eq. 22).

For a complex (signed) measurement the innovation is wrapped to [-0.5, 0.5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numba import njit

from rfi_node_common.params import parameter

MODE_KF = 0
MODE_AKF = 1
MODE_AFKF = 2

class FilterFloat(IntEnum):
    """Slots of the float state vector of one filter (cycles/sample, cycles/sample^2)."""

    F = 0
    DF = 1
    P11 = 2
    P12 = 3
    P22 = 4
    WSUM = 5


class FilterInt(IntEnum):
    """Slots of the int state vector of one filter (innovation window)."""

    WCOUNT = 0
    WPOS = 1


N_FSTATE = len(FilterFloat)
N_ISTATE = len(FilterInt)


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
    measurement_std: float = parameter(
        0.08, 'sigma_v of the IF measurement (eq. 20), cycles/sample. Raise it at low J/N.',
        minimum=1e-9, maximum=1.0)
    process_std: float = parameter(
        1e-4, 'sigma_w on the frequency (eq. 19), cycles/sample.', minimum=0.0, maximum=1.0)
    process_rate_std: float = parameter(
        1e-6,
        "Process noise on the sweep rate per sample, cycles/sample^2. The paper's eq. 19 has none; with 0 the rate "
        'variance collapses before the period locks and the rate estimate freezes.', minimum=0.0, maximum=1.0)
    window: int = parameter(
        16, 'Innovation window M of the adaptive filters (eq. 12), samples.', minimum=2, maximum=100000)
    initial_frequency: float = parameter(
        0.25,
        'Frequency of the tracking filter at start and after every reset (gaps between snapshots included), '
        "cycles/sample. 0.25 is the paper's IF at fs/4; set to the IF / fs of another front end.",
        minimum=-1.0, maximum=1.0)
    initial_frequency_std: float = parameter(
        0.15, '1-sigma of the initial frequency, cycles/sample.', minimum=1e-12, maximum=1.0)
    initial_rate_std: float = parameter(
        2e-3, '1-sigma of the initial sweep rate, cycles/sample^2 (1e12 Hz/s at 38.192 MHz is 6.9e-4).',
        minimum=1e-12, maximum=1.0)

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
        fst[FilterFloat.F] = self.initial_frequency
        fst[FilterFloat.P11] = self.initial_frequency_std ** 2
        fst[FilterFloat.P22] = self.initial_rate_std ** 2
        return fst, np.zeros(N_ISTATE, dtype=np.int64), np.zeros(int(self.window))


@njit(cache=True, inline="always")
def kf_predict(f: float, df: float, p11: float, p12: float, p22: float, q_f: float,
               q_df: float) -> tuple[float, float, float, float, float]:
    """Time update (eq. 15-16) with F = [[1, 1], [0, 1]]; returns (f, df, P11, P12, P22)."""
    return f + df, df, p11 + 2.0 * p12 + p22 + q_f, p12 + p22, p22 + q_df


@njit(cache=True, inline="always")
def kf_gain_inv(mode: int, c: float, c_hat: float, p11: float) -> float:
    """Gain factor over the innovation variance, g / C, of K = g P^- H^T / C (eq. 13-14, Sec. 4).

    Args:
        mode: MODE_KF / MODE_AKF / MODE_AFKF.
        c: computed innovation variance H P^- H^T + R (eq. 11).
        c_hat: windowed innovation variance (eq. 12); < 0 while the window is not yet full (g = 1).
        p11: P^-(1,1).

    Notes:
        For the fading filter ``g / C = 1 / (a_n C) = 1 / max(C, C^)`` (eq. 13-14): one division,
        and the same value while the window fills (c_hat < 0). The AKF's ``g = min(a_n, C / P11)``
        caps K(1) at 1 (module docstring).
    """
    if mode == MODE_AFKF:
        return 1.0 / max(c, c_hat)                       # eq. 13-14
    if mode == MODE_KF or c_hat < 0.0:
        return 1.0 / c
    alpha = max(1.0, c_hat / c)                          # eq. 13
    return min(alpha, c / p11) / c                       # AKF, capped so that K(1) <= 1


@njit(cache=True, inline="always")
def kf_update_predict(f: float, df: float, p11: float, p12: float, p22: float, nu: float, r: float,
                      kinv: float, q_f: float, q_df: float
                      ) -> tuple[float, float, float, float, float, float, float, float]:
    """Measurement update with the scaled gain (eq. 14, 17-18, Joseph form), then the time update
    to the next sample (eq. 15-16), in one step.

    Args:
        f, df, p11, p12, p22: prior state and covariance of this sample.
        nu: innovation z - f, cycles/sample (wrapped for signed measurements; 0 if no measurement).
        r: measurement variance R, (cycles/sample)^2.
        kinv: g / C from ``kf_gain_inv`` (K = kinv P^- H^T); 0 for a rejected sample (predict only).
        q_f, q_df: process noise variances of f and df.

    Returns:
        (f, df, P11) posterior of this sample, then (f, df, P11, P12, P22) prior of the next one.

    Notes:
        With ``k = kinv [P11, P12]`` and ``C = P11 + R`` the Joseph form is
        ``P+ = P - kinv (2 - C kinv) p p^T`` for ``p = [P11, P12]`` (it equals eq. 17 when kinv = 1/C);
        with F = [[1, 1], [0, 1]] the prediction of it is
        ``F P F^T + Q - t (F p)(F p)^T``, t = kinv (2 - C kinv), F p = [P11 + P12, P12].
        Written for a short serial chain (speed): kinv holds the one division of the sample and
        depends on the innovation (eq. 12-14), so everything that does not need it is formed
        first, and each output is one or two fused multiply-adds after it:
        ``f = (f + df) + ((P11 + P12) nu) kinv`` and, per element with ``b = (F p)_i (F p)_j``,
        ``(F P F^T + Q)_ij + kinv (b C kinv - 2 b)``. Same equations; the rounding differs from
        the textbook order by ~1 ulp.
    """
    c = p11 + r
    s1 = p11 + p12
    b11 = s1 * s1
    b12 = p12 * s1
    b22 = p12 * p12
    bp = p11 * p11
    g1 = p11 * nu
    g2 = p12 * nu
    g3 = s1 * nu
    f_post = f + g1 * kinv
    df_post = df + g2 * kinv
    p11_post = p11 + kinv * (bp * c * kinv - 2.0 * bp)
    return (f_post, df_post, p11_post, (f + df) + g3 * kinv, df_post,
            (p11 + 2.0 * p12 + p22 + q_f) + kinv * (b11 * c * kinv - 2.0 * b11),
            (p12 + p22) + kinv * (b12 * c * kinv - 2.0 * b12),
            (p22 + q_df) + kinv * (b22 * c * kinv - 2.0 * b22))


@njit(cache=True, inline="always")
def kf_sweep_reset(f: float, df: float, p11: float, p12: float, p22: float,
                   samples_since_start: float, cross_covariance: bool) -> tuple[float, float, float]:
    """Reset at a sweep start (eq. 21-22) from the posterior at T - 1; returns (f0, P11, P12).

    Args:
        f, df: state at T - 1 of the last sweep; p11, p12, p22: its covariance.
        samples_since_start: T - 1 of the last sweep.
        cross_covariance: False: the paper's eq. 22, f~ and df~ taken as uncorrelated (P12 of the
            reset state 0); True (beyond the paper): the exact covariance of the linear map
            ``[f0, df] = [[1, -m], [0, 1]] [f, df]``, ``P11 - 2 m P12 + m^2 P22`` and
            ``P12 - m P22``, which keeps the correlation that eq. 21 creates between f0~ and
            df~ (a too steep df~ gives a too low f0~), so that the first samples of the sweep
            correct both.

    Notes:
        Kang et al., eq. 21 (f0) and eq. 22 (P(1,1)); P(2,2) is kept.
    """
    m = samples_since_start
    if cross_covariance:
        return f - m * df, p11 - 2.0 * m * p12 + m * m * p22, p12 - m * p22
    return f - m * df, p11 + m * m * p22, 0.0


@njit(cache=True, inline="always")
def window_push(old: float, pos: int, count: int, m: int, wsum: float, nu2: float,
                valid: bool) -> tuple[float, int, int, float]:
    """Slide the innovation window of eq. 12 (a ring of m squared innovations) by one squared
    innovation if ``valid`` (else keep it).

    Args:
        old: ring[pos], the value the new one replaces once the window is full.
        pos, count, m: write position, values held (<= m) and length M of the window.
        wsum: sum of the values held.
        nu2: new squared innovation.
        valid: push (else leave the window unchanged).

    Returns:
        (value to store at ring[pos], new pos, new count, new sum). Scalars only and selects, no
        branches (rejections are random) and no array argument (the compiled loop would count
        references to it on every sample).
    """
    full = count >= m
    base = wsum - (old if full else 0.0)          # off the chain through nu2
    wsum = base + nu2 if valid else wsum
    store = nu2 if valid else old
    nxt = pos + 1
    pos = (nxt if nxt < m else 0) if valid else pos
    count = count + 1 if (valid and not full) else count
    return store, pos, count, wsum


@njit(cache=True, inline="always")
def filter_step(mode: int, f: float, df: float, p11: float, p12: float, p22: float, z: float, valid: bool,
                wrap: bool, old: float, wpos: int, wcount: int, m_win: int, wsum: float, r: float, q_f: float,
                q_df: float) -> tuple[float, float, float, float, float, float, float, float, float, int, int,
                                      float]:
    """One sample of KF / AKF / AFKF from the prior of this sample to the prior of the next.

    Args:
        mode: MODE_*.
        f, df, p11, p12, p22: prior state and covariance.
        z: measurement, cycles/sample (ignored unless valid).
        valid: the measurement is accepted (else prediction only, window unchanged).
        wrap: wrap the innovation to [-0.5, 0.5) (signed measurements).
        old, wpos, wcount, m_win, wsum: innovation window of eq. 12 (``window_push``).
        r, q_f, q_df: R and the process noise variances.

    Returns:
        (f, df, P11) posterior of this sample, (f, df, P11, P12, P22) prior of the next one,
        then (value to store at ring[wpos], wpos, wcount, wsum) of the window.
    """
    nu = z - f if valid else 0.0
    if wrap:
        nu = nu - math.floor(nu + 0.5)
    store, wpos, wcount, wsum = window_push(old, wpos, wcount, m_win, wsum, nu * nu, valid)
    c = p11 + r
    if mode == MODE_AKF:
        kinv = kf_gain_inv(mode, c, wsum / (m_win - 1) if wcount >= m_win else -1.0, p11)
    else:
        # KF: 1 / C; AFKF: 1 / max(C, C^) = (M - 1) / max((M - 1) C, sum nu^2)   (eq. 12-14)
        m1 = float(m_win - 1)
        weff = wsum if (mode == MODE_AFKF and wcount >= m_win) else -1.0
        kinv = m1 / max(c * m1, weff)
    kinv = kinv if valid else 0.0
    fp, dfp, p11p, f, df, p11, p12, p22 = kf_update_predict(f, df, p11, p12, p22, nu, r, kinv, q_f, q_df)
    return fp, dfp, p11p, f, df, p11, p12, p22, store, wpos, wcount, wsum


@njit(cache=True, error_model="numpy")
def _run(z: np.ndarray, valid: np.ndarray, reset: np.ndarray, par: np.ndarray, fst: np.ndarray,
         ist: np.ndarray, ring: np.ndarray, wrap: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = z.size
    mode = int(par[0])
    r, q_f, q_df = par[1], par[2], par[3]
    f, df, p11 = fst[FilterFloat.F], fst[FilterFloat.DF], fst[FilterFloat.P11]
    p12, p22, wsum = fst[FilterFloat.P12], fst[FilterFloat.P22], fst[FilterFloat.WSUM]
    count, pos = ist[FilterInt.WCOUNT], ist[FilterInt.WPOS]
    f_out = np.empty(n)
    df_out = np.empty(n)
    p11_out = np.empty(n)
    last_start = 0
    for k in range(n):
        if reset[k] and k > 0:
            # the state predicts sample k; eq. 21 uses the posterior at T - 1 = k - 1
            f, p11, p12 = kf_sweep_reset(f - df, df, p11, p12, p22, float(k - 1 - last_start), False)
            last_start = k
        p0 = pos
        (f_out[k], df_out[k], p11_out[k], f, df, p11, p12, p22, ring[p0], pos, count,
         wsum) = filter_step(mode, f, df, p11, p12, p22, z[k], valid[k], wrap, ring[pos], pos, count, ring.size,
                             wsum, r, q_f, q_df)
    fst[FilterFloat.F], fst[FilterFloat.DF], fst[FilterFloat.P11] = f, df, p11
    fst[FilterFloat.P12], fst[FilterFloat.P22], fst[FilterFloat.WSUM] = p12, p22, wsum
    ist[FilterInt.WCOUNT], ist[FilterInt.WPOS] = count, pos
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
