"""Covariance analysis of the carrier filter: P before and after each update (Zhao et al., Fig. 9)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_discrete_are

from gnss_common.clock_model import ClockHCoefficients, clock_process_noise_phase
from gnss_common.constants import GPS_L1_FREQUENCY_HZ


@dataclass(frozen=True)
class CovarianceHistory:
    """Output of :func:`covariance_analysis`.

    Attributes:
        time_s: time of each update, s, shape (n,).
        prior: P-bar before each update, shape (n, 2, 2), [[rad^2, rad^2/s], [., (rad/s)^2]].
        posterior: P-hat after each update, same shape and units.
    """

    time_s: np.ndarray
    prior: np.ndarray
    posterior: np.ndarray

    @property
    def posterior_frequency_std_hz(self) -> np.ndarray:
        """sqrt(P-hat[1, 1]) / 2 pi, Hz, shape (n,)."""
        return np.sqrt(self.posterior[:, 1, 1]) / (2.0 * math.pi)

    @property
    def prior_frequency_std_hz(self) -> np.ndarray:
        """sqrt(P-bar[1, 1]) / 2 pi, Hz, shape (n,)."""
        return np.sqrt(self.prior[:, 1, 1]) / (2.0 * math.pi)

    @property
    def posterior_phase_std_rad(self) -> np.ndarray:
        """sqrt(P-hat[0, 0]), rad, shape (n,)."""
        return np.sqrt(self.posterior[:, 0, 0])


def phase_measurement_variance_rad2(cn0_dbhz: float, integration_time_s: float) -> float:
    """Variance of the phase information in one correlator, sigma_v^2 / A^2 = 1 / (2 T C/N0), rad^2.

    The EKF update of measurement_model's I/Q model reduces to a scalar phase measurement with
    H = [1, 0] and this variance, whatever the phase and the data bit (u^T S u = A^2 P11 + sigma^2).

    Notes:
        Zhao et al., eq. 2-5.
    """
    if not (math.isfinite(integration_time_s) and integration_time_s > 0 and math.isfinite(cn0_dbhz)):
        raise ValueError("integration_time_s must be > 0 and cn0_dbhz finite")
    return 1.0 / (2.0 * integration_time_s * 10.0 ** (cn0_dbhz / 10.0))


def covariance_analysis(
    clock: ClockHCoefficients,
    cn0_dbhz: float | np.ndarray,
    integration_time_s: float,
    n_steps: int,
    initial_covariance: np.ndarray,
    carrier_hz: float = GPS_L1_FREQUENCY_HZ,
    form: str = "brown_hwang",
    process_noise_scale: float = 1.0,
) -> CovarianceHistory:
    """Riccati recursion of the mode-matched EKF (identical for both modes) over n_steps.

    Args:
        clock: clock h-coefficients.
        cn0_dbhz: C/N0, dB-Hz, scalar or shape (n_steps,).
        integration_time_s: T, s, > 0.
        n_steps: number of updates, >= 1.
        initial_covariance: P at t = 0, shape (2, 2), rad and rad/s.
        carrier_hz: carrier frequency, Hz.
        form: process-noise form (gnss_common.clock_model).
        process_noise_scale: factor on W.

    Returns:
        CovarianceHistory.

    Notes:
        Zhao et al., Section IV and Fig. 9 (1 ms, 51 dB-Hz): P-bar = F P F^T + W (eq. 7-8),
        P-hat = P-bar - P-bar H^T (H P-bar H^T + R)^-1 H P-bar with H = [1, 0], R from
        :func:`phase_measurement_variance_rad2`.
    """
    if n_steps < 1:
        raise ValueError("n_steps must be >= 1")
    p = np.array(initial_covariance, dtype=float)
    if p.shape != (2, 2) or not np.all(np.isfinite(p)) or np.any(np.linalg.eigvalsh((p + p.T) / 2) < 0):
        raise ValueError("initial_covariance must be a finite symmetric PSD 2x2 matrix")
    cn0 = np.broadcast_to(np.asarray(cn0_dbhz, dtype=float), (n_steps,))
    f = np.array([[1.0, integration_time_s], [0.0, 1.0]])
    w = process_noise_scale * clock_process_noise_phase(clock, integration_time_s, carrier_hz, form)
    prior = np.empty((n_steps, 2, 2))
    post = np.empty((n_steps, 2, 2))
    for k in range(n_steps):
        p = f @ p @ f.T + w
        prior[k] = p
        r = phase_measurement_variance_rad2(float(cn0[k]), integration_time_s)
        gain = p[:, 0] / (p[0, 0] + r)
        p = p - np.outer(gain, p[0, :])
        p = 0.5 * (p + p.T)
        post[k] = p
    time_s = integration_time_s * np.arange(1, n_steps + 1)
    return CovarianceHistory(time_s=time_s, prior=prior, posterior=post)


def steady_state_covariance(
    clock: ClockHCoefficients,
    cn0_dbhz: float,
    integration_time_s: float,
    carrier_hz: float = GPS_L1_FREQUENCY_HZ,
    form: str = "brown_hwang",
    process_noise_scale: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state (P-bar, P-hat) from the discrete algebraic Riccati equation (scipy), rad and rad/s.

    Notes:
        P-bar solves P = F P F^T - F P H^T (H P H^T + R)^-1 H P F^T + W (the filtering DARE, dual
        form passed to scipy.linalg.solve_discrete_are with a = F^T, b = H^T).
    """
    f = np.array([[1.0, integration_time_s], [0.0, 1.0]])
    w = process_noise_scale * clock_process_noise_phase(clock, integration_time_s, carrier_hz, form)
    r = np.array([[phase_measurement_variance_rad2(cn0_dbhz, integration_time_s)]])
    h = np.array([[1.0, 0.0]])
    p_bar = solve_discrete_are(f.T, h.T, w, r)
    k = p_bar @ h.T @ np.linalg.inv(h @ p_bar @ h.T + r)
    p_hat = p_bar - k @ h @ p_bar
    return p_bar, p_hat


def convergence_time_s(
    history: CovarianceHistory, steady_posterior: np.ndarray, rel_tol: float = 0.1
) -> float:
    """First time after which the posterior frequency variance stays within rel_tol of steady state, s."""
    target = float(steady_posterior[1, 1])
    dev = np.abs(history.posterior[:, 1, 1] - target) / target
    outside = np.flatnonzero(dev > rel_tol)
    if outside.size == 0:
        return float(history.time_s[0])
    if outside[-1] == dev.size - 1:
        return math.inf
    return float(history.time_s[outside[-1] + 1])
