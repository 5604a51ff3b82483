"""Earth rotation during signal flight (the Sagnac correction): the one implementation.

A satellite position computed at transmit time is expressed in the ECEF frame of that instant;
the receiver sits in the ECEF frame of reception, which has turned by ``omega_e tau`` about the
z axis meanwhile (tau the signal travel time). Two forms are used:

* :func:`sagnac_rotate`: the exact rotation ``R3(omega_e tau) p_s``, with tau from the range and
  optionally iterated (SPP, the measurement builder, the simulators); its angle is
  :func:`flight_rotation`, which a light-time iteration of its own (a satellite that moves during
  the flight, ``rfi_sim.gnss_uwb``) calls directly;
* :func:`sagnac_range_correction_m` and :func:`sagnac_range_rate_correction_mps`: its first-order
  expansion in ``omega_e tau`` added to the straight-line range (and its time derivative), which
  broadcasts over batches of receiver states (the filter's measurement models evaluate it on all
  cubature points at once).

Notes
-----
IS-GPS-200, 20.3.3.4.3.3.2 (Earth rotation correction); Kaplan & Hegarty 3rd ed., sec. 11.2 and
eq. 11.18 (first-order form). Cao et al., eq. 5 writes the geometric range as
``D_Ecd(R3(w tau) p_G, p_r)``; eq. 6 uses the rotated satellite velocity likewise.
"""

from __future__ import annotations

import numpy as np

from gnss_common.constants import EARTH_ROTATION_RATE_RADPS, SPEED_OF_LIGHT_MPS

OMEGA_E_OVER_C = EARTH_ROTATION_RATE_RADPS / SPEED_OF_LIGHT_MPS
"""Earth rotation rate over the speed of light, rad/m (the factor of the first-order form)."""


def rotate_about_z(vectors: np.ndarray, cos_a: np.ndarray, sin_a: np.ndarray) -> np.ndarray:
    """Apply ``R3(a) = [[cos a, sin a, 0], [-sin a, cos a, 0], [0, 0, 1]]`` row by row.

    Args:
        vectors: ECEF vectors (positions or velocities), shape (N, 3).
        cos_a: cos of each rotation angle, shape (N,).
        sin_a: sin of each rotation angle, shape (N,).

    Returns:
        The rotated vectors, shape (N, 3) (a new array).
    """
    out = np.empty_like(vectors)
    out[:, 0] = cos_a * vectors[:, 0] + sin_a * vectors[:, 1]
    out[:, 1] = -sin_a * vectors[:, 0] + cos_a * vectors[:, 1]
    out[:, 2] = vectors[:, 2]
    return out


def flight_rotation(travel_time_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Earth's rotation during a signal's flight: cos and sin of ``omega_e tau``.

    Args:
        travel_time_s: signal travel times tau, s, any shape.

    Returns:
        ``(cos, sin)`` of the angle ``omega_e tau``, rad, each of the shape of ``travel_time_s``:
        the arguments of :func:`rotate_about_z` that take a transmit-time ECEF vector into the
        receive-time frame.

    Notes
    -----
    ``R3(omega_e tau)`` of IS-GPS-200, 20.3.3.4.3.3.2; Cao et al., eq. 5.
    """
    ang = EARTH_ROTATION_RATE_RADPS * travel_time_s
    return np.cos(ang), np.sin(ang)


def sagnac_rotate(
    satellite_ecef_m: np.ndarray, receiver_ecef_m: np.ndarray, iterations: int = 1
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rotate transmit-time satellite positions into the receive-time ECEF frame.

    Args:
        satellite_ecef_m: satellite positions in the ECEF frame of transmission, m, shape (N, 3).
        receiver_ecef_m: receiver position at reception, m, shape (3,).
        iterations: travel-time iterations, >= 1. The first uses the straight-line range
            ``tau = |p_s - p_r| / c``; each further one ``tau = |R3(w tau) p_s - p_r| / c``
            (2 give < 1 um).

    Returns:
        ``(rotated_m (N, 3), cos (N,), sin (N,), travel_time_s (N,))``: the rotated positions, the
        cos and sin of the angle used (to rotate velocities with :func:`rotate_about_z`), and the
        travel time recomputed from the rotated positions.

    Notes
    -----
    ``p_s' = R3(omega_e tau) p_s`` (IS-GPS-200, 20.3.3.4.3.3.2); Cao et al., eq. 5.
    """
    sat = np.asarray(satellite_ecef_m, dtype=float)
    rx = np.asarray(receiver_ecef_m, dtype=float)
    tau = np.sqrt(np.sum((sat - rx) ** 2, axis=1)) / SPEED_OF_LIGHT_MPS
    rotated = sat
    c = np.ones(sat.shape[0])
    s = np.zeros(sat.shape[0])
    for _ in range(max(1, iterations)):
        c, s = flight_rotation(tau)
        rotated = rotate_about_z(sat, c, s)
        tau = np.sqrt(np.sum((rotated - rx) ** 2, axis=1)) / SPEED_OF_LIGHT_MPS
    return rotated, c, s, tau


def sagnac_range_correction_m(satellite_ecef_m: np.ndarray, receiver_ecef_m: np.ndarray) -> np.ndarray:
    """First-order Sagnac range term ``omega_e (x_s y_r - y_s x_r) / c``, m.

    Args:
        satellite_ecef_m: satellite positions (transmit-time frame), m, shape (..., 3).
        receiver_ecef_m: receiver positions, m, shape (..., 3); the two broadcast against each
            other (e.g. (1, k, 3) satellites and (m, 1, 3) cubature points give (m, k)).

    Returns:
        The correction to add to the straight-line range, m, the broadcast shape without the last
        axis.

    Notes
    -----
    Kaplan & Hegarty 3rd ed., eq. 11.18: the first-order expansion of
    ``|R3(omega_e tau) p_s - p_r| - |p_s - p_r|``; the neglected terms are below 1 mm for GNSS
    ranges (test: against :func:`sagnac_rotate`).
    """
    s = np.asarray(satellite_ecef_m, dtype=float)
    r = np.asarray(receiver_ecef_m, dtype=float)
    return OMEGA_E_OVER_C * (s[..., 0] * r[..., 1] - s[..., 1] * r[..., 0])


def sagnac_range_rate_correction_mps(
    satellite_ecef_m: np.ndarray,
    satellite_velocity_ecef_mps: np.ndarray,
    receiver_ecef_m: np.ndarray,
    receiver_velocity_ecef_mps: np.ndarray,
) -> np.ndarray:
    """Time derivative of :func:`sagnac_range_correction_m`, m/s (same broadcasting).

    Args:
        satellite_ecef_m: satellite positions, m, shape (..., 3).
        satellite_velocity_ecef_mps: satellite velocities, m/s, shape (..., 3).
        receiver_ecef_m: receiver positions, m, shape (..., 3).
        receiver_velocity_ecef_mps: receiver velocities, m/s, shape (..., 3).

    Returns:
        ``omega_e / c (vx_s y_r - vy_s x_r + x_s vy_r - y_s vx_r)``, m/s.

    Notes
    -----
    Added to the range rate of Cao et al., eq. 6 so that the pseudorange and pseudorange-rate
    models stay consistent (a few mm/s).
    """
    ps = np.asarray(satellite_ecef_m, dtype=float)
    vs = np.asarray(satellite_velocity_ecef_mps, dtype=float)
    pr = np.asarray(receiver_ecef_m, dtype=float)
    vr = np.asarray(receiver_velocity_ecef_mps, dtype=float)
    return OMEGA_E_OVER_C * (vs[..., 0] * pr[..., 1] - vs[..., 1] * pr[..., 0] + ps[..., 0] * vr[..., 1]
                             - ps[..., 1] * vr[..., 0])
