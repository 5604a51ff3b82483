"""Measurement models of the GNSS/UWB tightly-coupled filter, as callables (filterpy ``hx`` style).

Every model maps a batch of full navigation states ``X`` of shape (m, n) -- rows
``[x, y, z, vx, vy, vz, c*dt, c*ddt, b_1, ..., b_j]`` in m, m/s, m, m/s, m (ECEF, or the local frame
for UWB-only; ``b_i`` the inter-system clock biases of the systems other than GPS that the filter
has seen, none for a GPS-only stream: n = 8) -- to predicted measurements of shape (m, k). The CKF
evaluates a model on all 2n cubature points at once, so the models are vectorised over rows and
never branch on the measurement type: the fusion filter builds one callable per update with
:func:`stack_models`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from gnss_common.earth_rotation import sagnac_range_correction_m, sagnac_range_rate_correction_mps

MeasurementModel = Callable[[np.ndarray], np.ndarray]
"""hx(X): X (m, 8) states -> (m, k) predicted measurements."""

STATE_DIM = 8
"""Size of the navigation (and error) state [p(3), v(3), c*dt, c*ddt] without inter-system biases."""

_EYE8 = np.eye(STATE_DIM)
_PP = np.zeros((6, 6))
_PP[0:3, 0:3] = np.eye(3)
_PV = np.zeros((6, 6))
_PV[0:3, 3:6] = _PV[3:6, 0:3] = np.eye(3)
_VV = np.zeros((6, 6))
_VV[3:6, 3:6] = np.eye(3)


def pseudorange_model(
    sat_pos_ecef_m: np.ndarray,
    sat_clock_bias_m: np.ndarray,
    iono_delay_m: np.ndarray,
    tropo_delay_m: np.ndarray,
    bias_column: np.ndarray | None = None,
    error_column: np.ndarray | None = None,
) -> MeasurementModel:
    """Pseudorange model for k satellites.

    Args:
        sat_pos_ecef_m: satellite positions at transmission time, ECEF (frame of transmission
            time), m, shape (k, 3).
        sat_clock_bias_m: c * satellite clock offset, m, shape (k,).
        iono_delay_m: modelled ionospheric delay, m, shape (k,).
        tropo_delay_m: modelled tropospheric delay, m, shape (k,).
        bias_column: for each satellite the state column (>= 8) of its system's inter-system
            clock bias, or -1 for the reference system (GPS), int, shape (k,); None: all GPS.
        error_column: for each satellite the state column of its time-correlated pseudorange
            error (first-order Gauss-Markov or a constant code bias, added to the range), or -1
            for a satellite without one, int, shape (k,); None: none.

    Returns:
        hx mapping states (m, n) to pseudoranges (m, k), m.

    Notes:
        Cao et al., eq. 5: ``rho = |p_s - p_r| + T + I + c (dt_r - dt_s)``. The Earth-rotation
        (Sagnac) correction is the first-order closed form
        ``omega_e / c (x_s y_r - y_s x_r)`` of :func:`gnss_common.earth_rotation.sagnac_range_correction_m`
        (the neglected second-order term is below 1 mm for GNSS ranges). A satellite of another
        system sees the receiver clock in that system's time: ``c dt_r + b_sys`` with ``b_sys`` the
        inter-system bias (receiver hardware delay difference plus the residual offset between the
        system times; Hegarty 2017 / RTKLIB ``pntpos``), a state of its own. The time-correlated
        error of a satellite (residual orbit/clock, ionosphere and troposphere, multipath) is a
        first-order Gauss-Markov state of its own (Brown & Hwang, 4th ed., sec. 2.9 and 4.2).
    """
    ps = np.asarray(sat_pos_ecef_m, dtype=float)
    const = (
        np.asarray(iono_delay_m, float)
        + np.asarray(tropo_delay_m, float)
        - np.asarray(sat_clock_bias_m, float)
    )
    if error_column is not None:
        err = np.asarray(error_column, dtype=np.int64)
        if err.shape != const.shape or ((err < STATE_DIM) & (err != -1)).any():
            raise ValueError(f"error_column must be (k,) with -1 or columns >= {STATE_DIM}, got {error_column!r}")
        base = pseudorange_model(sat_pos_ecef_m, sat_clock_bias_m, iono_delay_m, tropo_delay_m, bias_column)
        if (err < 0).any():
            has_err = err >= 0
            take_err = np.where(has_err, err, 6)  # rows without a state read a column and are masked to zero

            def hx_some(states: np.ndarray) -> np.ndarray:
                return base(states) + np.where(has_err[None, :], states[:, take_err], 0.0)

            return hx_some

        def hx_err(states: np.ndarray) -> np.ndarray:
            return base(states) + states[:, err]

        return hx_err
    ps_b = ps[None, :, :]
    cols = None if bias_column is None else np.asarray(bias_column, dtype=np.int64)
    if cols is None or not (cols >= 0).any():

        def hx(states: np.ndarray) -> np.ndarray:
            p = states[:, None, 0:3]
            geom = np.sqrt(((ps_b - p) ** 2).sum(axis=2))
            return geom + sagnac_range_correction_m(ps_b, p) + states[:, 6:7] + const[None, :]

        return hx
    if cols.shape != const.shape or (cols[cols >= 0] < STATE_DIM).any():
        raise ValueError(f"bias_column must be (k,) with -1 or columns >= {STATE_DIM}, got {bias_column!r}")
    has_bias = cols >= 0
    take = np.where(has_bias, cols, 6)  # GPS rows read the clock column and are masked to zero
    mask = has_bias.astype(float)[None, :]

    def hx_multi(states: np.ndarray) -> np.ndarray:
        p = states[:, None, 0:3]
        geom = np.sqrt(((ps_b - p) ** 2).sum(axis=2))
        bias = states[:, take] * mask
        return geom + sagnac_range_correction_m(ps_b, p) + states[:, 6:7] + bias + const[None, :]

    return hx_multi


def pseudorange_rate_model(
    sat_pos_ecef_m: np.ndarray, sat_vel_ecef_mps: np.ndarray, sat_clock_drift_mps: np.ndarray
) -> MeasurementModel:
    """Pseudorange-rate (from Doppler) model for k satellites.

    Args:
        sat_pos_ecef_m: satellite positions, ECEF, m, shape (k, 3).
        sat_vel_ecef_mps: satellite velocities, ECEF, m/s, shape (k, 3).
        sat_clock_drift_mps: c * satellite clock drift, m/s, shape (k,).

    Returns:
        hx mapping states (m, 8) to pseudorange rates (m, k), m/s, positive when the range grows
        (``-lambda * doppler_hz``).

    Notes:
        Cao et al., eq. 6: ``rho_dot = (v_s - v_r)^T e + c (ddt_r - ddt_s)`` with ``e`` the unit
        line of sight from the receiver to the satellite, plus the time derivative of the Sagnac
        term of :func:`pseudorange_model` (a few mm/s) so that the two models are consistent.
    """
    ps = np.asarray(sat_pos_ecef_m, dtype=float)
    vs = np.asarray(sat_vel_ecef_mps, dtype=float)
    drift = np.asarray(sat_clock_drift_mps, dtype=float)

    def hx(states: np.ndarray) -> np.ndarray:
        d = ps[None, :, :] - states[:, None, 0:3]
        r = np.sqrt((d * d).sum(axis=2))
        dv = vs[None, :, :] - states[:, None, 3:6]
        rate = (d * dv).sum(axis=2) / r
        sagnac_rate = sagnac_range_rate_correction_mps(
            ps[None, :, :], vs[None, :, :], states[:, None, 0:3], states[:, None, 3:6]
        )
        return rate + sagnac_rate + states[:, 7:8] - drift[None, :]

    return hx


def uwb_range_model(
    anchor_pos_m: np.ndarray, lever_arm_m: np.ndarray | None = None, latency_s: float = 0.0
) -> MeasurementModel:
    """UWB two-way range model for k anchors.

    Args:
        anchor_pos_m: anchor positions in the state frame, m, shape (k, 3).
        lever_arm_m: tag position minus GNSS antenna position in the state frame, m, shape (3,)
            (zero: tag at the antenna, the paper's setting).
        latency_s: age of the range at its stamp, s (>= 0): the range measures the distance at
            ``stamp - latency_s``, when the tag was at ``p - v latency_s`` under the
            constant-velocity model (0: the paper's model).

    Returns:
        hx mapping states (m, 8) to ranges (m, k), m. The model depends on the position only
        (state components 0-2), or on position and velocity (0-5) if ``latency_s > 0``.

    Notes:
        Cao et al., eq. 7: ``rho_U = |p_anchor - p_tag|`` with ``p_tag = p_r + lever_arm``. Two-way
        ranging has no clock term. The latency term is beyond the paper (constant-velocity
        back-propagation, Cao et al. eq. 10, over ``latency_s``).
    """
    pa = np.asarray(anchor_pos_m, dtype=float)
    arm = np.zeros(3) if lever_arm_m is None else np.asarray(lever_arm_m, dtype=float)
    lat = float(latency_s)
    if not (math.isfinite(lat) and lat >= 0.0):
        raise ValueError(f"latency_s must be finite and >= 0, got {latency_s!r}")
    if pa.shape[0] == 1:
        a0 = pa[0] - arm

        if lat == 0.0:

            def hx1(states: np.ndarray) -> np.ndarray:
                d = states[:, 0:3] - a0
                return np.sqrt(np.einsum("ij,ij->i", d, d))[:, None]

            return hx1

        def hx1_lat(states: np.ndarray) -> np.ndarray:
            d = states[:, 0:3] - lat * states[:, 3:6] - a0
            return np.sqrt(np.einsum("ij,ij->i", d, d))[:, None]

        return hx1_lat

    def hx(states: np.ndarray) -> np.ndarray:
        pos = states[:, 0:3] if lat == 0.0 else states[:, 0:3] - lat * states[:, 3:6]
        tag = pos[:, None, :] + arm
        return np.sqrt(((pa[None, :, :] - tag) ** 2).sum(axis=2))

    return hx


def stack_models(models: list[MeasurementModel]) -> MeasurementModel:
    """Concatenate several models into one (columns in the given order).

    Args:
        models: list of hx callables, each (m, 8) -> (m, k_i).

    Returns:
        hx mapping (m, 8) to (m, sum k_i).
    """
    if len(models) == 1:
        return models[0]

    def hx(states: np.ndarray) -> np.ndarray:
        return np.concatenate([h(states) for h in models], axis=1)

    return hx


def constant_velocity_transition(
    dt_s: float, n_bias: int = 0, n_error: int = 0, error_tau_s: float = 1.0
) -> np.ndarray:
    """Discrete state transition of the 8-state constant-velocity / clock model.

    Args:
        dt_s: time step T_s, s (>= 0).
        n_bias: inter-system bias states appended after the clock (random walks: identity rows).
        n_error: first-order Gauss-Markov pseudorange-error states after the biases.
        error_tau_s: their correlation time, s (> 0).

    Returns:
        Phi, shape (8 + n_bias + n_error, 8 + n_bias + n_error).

    Notes:
        Cao et al., eq. 9 (continuous F) and eq. 10 (Phi = exp(F T_s)); a Gauss-Markov state
        decays by ``exp(-T_s / tau)`` (Brown & Hwang, 4th ed., eq. 4.2.11).
    """
    n = STATE_DIM + n_bias + n_error
    phi = _EYE8.copy() if n == STATE_DIM else np.eye(n)
    if n_error:
        idx = np.arange(STATE_DIM + n_bias, n)
        phi[idx, idx] = math.exp(-dt_s / error_tau_s)
    phi[0, 3] = phi[1, 4] = phi[2, 5] = dt_s
    phi[6, 7] = dt_s
    return phi


def white_acceleration_noise(accel_psd_m2ps3: float, dt_s: float) -> np.ndarray:
    """Process noise of position/velocity under white acceleration noise.

    Args:
        accel_psd_m2ps3: acceleration noise power spectral density q per axis, m^2/s^3.
        dt_s: time step, s.

    Returns:
        Q for [p, v], shape (6, 6), m^2, m^2/s, m^2/s^2.

    Notes:
        Integral of Phi G q G^T Phi^T over T_s for the constant-velocity model of Cao et al.,
        eq. 9-10 (Brown & Hwang, 4th ed., sec. 9.3): q [[T^3/3, T^2/2], [T^2/2, T]] per axis.
    """
    q = accel_psd_m2ps3
    return (q * dt_s**3 / 3.0) * _PP + (q * dt_s**2 / 2.0) * _PV + (q * dt_s) * _VV
