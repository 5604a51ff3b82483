"""Broadcast ionosphere (Klobuchar) and a standard-atmosphere Saastamoinen troposphere.

These give the I and T terms of the pseudorange model (Cao et al., eq. 5) for a single-frequency
user: the Klobuchar delay is an L1 delay, scaled to another carrier (Galileo E1, BeiDou B1I,
GLONASS G1 of channel k) by :func:`ionosphere_frequency_scale`. Both are vectorised over satellites.

Notes
-----
- Ionosphere: IS-GPS-200 (rev. N), 20.3.3.5.2.5 and Figure 20-4 (Klobuchar 1987).
- Troposphere: zenith hydrostatic delay of Saastamoinen (1972) in the form of Davis et al.
  (1985), zenith wet delay of Saastamoinen (1972), surface meteorology from a standard
  atmosphere (Berg 1948, as used by RTKLIB's ``tropmodel``), slant mapping with the Black &
  Eisner (1984) function m(E) = 1.001 / sqrt(0.002001 + sin^2 E) (RTCA DO-229, A.4.2.4).
"""

from __future__ import annotations

import math

import numpy as np

from gnss_common.constants import GPS_L1_FREQUENCY_HZ

KLOBUCHAR_NIGHT_DELAY_S = 5.0e-9
"""Klobuchar constant night-time vertical delay DC term, s (IS-GPS-200, Figure 20-4)."""

KLOBUCHAR_MIN_PERIOD_S = 72_000.0
"""Klobuchar minimum period of the cosine, s (IS-GPS-200, Figure 20-4)."""

KLOBUCHAR_PEAK_LOCAL_TIME_S = 50_400.0
"""Local time of the Klobuchar daily maximum (14:00), s (IS-GPS-200, Figure 20-4)."""

STANDARD_RELATIVE_HUMIDITY = 0.7
"""Default relative humidity for the standard atmosphere, fraction (RTKLIB default)."""


def _check_coeffs(name: str, coeffs: np.ndarray) -> np.ndarray:
    arr = np.asarray(coeffs, dtype=float).reshape(-1)
    if arr.shape != (4,):
        raise ValueError(f"{name} must have 4 coefficients, got shape {np.shape(coeffs)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains non-finite values: {arr}")
    return arr


def klobuchar_delay_s(
    alpha: np.ndarray,
    beta: np.ndarray,
    lat_rad: float,
    lon_rad: float,
    azimuth_rad: np.ndarray | float,
    elevation_rad: np.ndarray | float,
    gps_tow_s: float,
) -> np.ndarray:
    """GPS L1 ionospheric group delay from the broadcast Klobuchar model.

    Args:
        alpha: alpha_0..3 from the nav message (s, s/sc, s/sc^2, s/sc^3), shape (4,).
        beta: beta_0..3 (s, s/sc, s/sc^2, s/sc^3), shape (4,).
        lat_rad: receiver geodetic latitude, rad.
        lon_rad: receiver longitude, rad.
        azimuth_rad: satellite azimuth(s), rad, scalar or (N,).
        elevation_rad: satellite elevation(s), rad, same shape; values below 0 are clipped to 0.
        gps_tow_s: GPS time of week of the measurement (receive time), s.

    Returns:
        Slant L1 delay, s, shape of ``azimuth_rad`` broadcast with ``elevation_rad``; always >= 0.

    Raises:
        ValueError: coefficients not 4 finite values, or non-finite geometry/time.

    Notes
    -----
    IS-GPS-200, Figure 20-4, in semicircles (sc): psi = 0.0137/(E + 0.11) - 0.022,
    phi_i = phi_u + psi cos A (clipped to +-0.416), lambda_i = lambda_u + psi sin A / cos(phi_i),
    phi_m = phi_i + 0.064 cos(lambda_i - 1.617), t = 4.32e4 lambda_i + t_GPS (mod 86400),
    F = 1 + 16 (0.53 - E)^3, AMP = sum alpha_n phi_m^n (>= 0), PER = sum beta_n phi_m^n (>= 72000),
    x = 2 pi (t - 50400)/PER, T = F [5e-9 + AMP (1 - x^2/2 + x^4/24)] for |x| < 1.57, else F 5e-9.
    """
    a = _check_coeffs("alpha", alpha)
    b = _check_coeffs("beta", beta)
    az = np.asarray(azimuth_rad, dtype=float)
    el = np.clip(np.asarray(elevation_rad, dtype=float), 0.0, None)
    if not (
        np.all(np.isfinite(az))
        and np.all(np.isfinite(el))
        and math.isfinite(lat_rad)
        and math.isfinite(lon_rad)
        and math.isfinite(gps_tow_s)
    ):
        raise ValueError("klobuchar_delay_s: non-finite latitude, longitude, azimuth, elevation or time")
    e_sc = el / math.pi
    psi = 0.0137 / (e_sc + 0.11) - 0.022
    phi_i = np.clip(lat_rad / math.pi + psi * np.cos(az), -0.416, 0.416)
    lam_i = lon_rad / math.pi + psi * np.sin(az) / np.cos(phi_i * math.pi)
    phi_m = phi_i + 0.064 * np.cos((lam_i - 1.617) * math.pi)
    t = np.mod(4.32e4 * lam_i + gps_tow_s, 86400.0)
    f = 1.0 + 16.0 * (0.53 - e_sc) ** 3
    amp = np.maximum(a[0] + phi_m * (a[1] + phi_m * (a[2] + phi_m * a[3])), 0.0)
    per = np.maximum(b[0] + phi_m * (b[1] + phi_m * (b[2] + phi_m * b[3])), KLOBUCHAR_MIN_PERIOD_S)
    x = 2.0 * math.pi * (t - KLOBUCHAR_PEAK_LOCAL_TIME_S) / per
    day = amp * (1.0 - x * x / 2.0 + x**4 / 24.0)
    return f * (KLOBUCHAR_NIGHT_DELAY_S + np.where(np.abs(x) < 1.57, day, 0.0))


def ionosphere_frequency_scale(carrier_frequency_hz: np.ndarray | float) -> np.ndarray:
    """Ratio of the ionospheric group delay on a carrier to that on GPS L1: (f_L1 / f)^2.

    Args:
        carrier_frequency_hz: carrier(s), Hz, > 0 (e.g. Galileo E1 1575.42e6: 1.0; BeiDou B1I
            1561.098e6: 1.018; GLONASS G1 channel k: 1602e6 + k 0.5625e6: about 0.97).

    Notes
    -----
    First-order ionosphere: the group delay is 40.3 TEC / f^2 (Hofmann-Wellenhof et al. 2008,
    eq. 5.79), so a delay known on L1 (the Klobuchar model) scales by (f_L1 / f)^2. The broadcast
    GPS Klobuchar model is used for every system here (as RTKLIB does for single-frequency
    multi-GNSS); Galileo's NeQuick-G and BeiDou's own Klobuchar set are not implemented.
    """
    f = np.asarray(carrier_frequency_hz, dtype=float)
    if not np.all(np.isfinite(f) & (f > 0.0)):
        raise ValueError(f"carrier_frequency_hz must be finite and > 0, got {carrier_frequency_hz}")
    return (GPS_L1_FREQUENCY_HZ / f) ** 2


def ionosphere_free_pseudorange_m(
    pr1_m: np.ndarray | float, pr2_m: np.ndarray | float, f1_hz: float, f2_hz: float
) -> np.ndarray:
    """Ionosphere-free combination of two code pseudoranges, m: (f1^2 PR1 - f2^2 PR2) / (f1^2 - f2^2).

    Args:
        pr1_m: pseudorange(s) on the carrier ``f1_hz``, m, scalar or (N,).
        pr2_m: pseudorange(s) on the carrier ``f2_hz``, m, same shape.
        f1_hz, f2_hz: the two carriers, Hz, finite, > 0, different (GPS L1 1575.42e6, L2 1227.60e6).

    Returns:
        The combination, m, shape of the inputs: free of the first-order ionospheric delay
        (40.3 TEC / f^2), with the code noise and multipath of the two signals amplified
        (GPS L1/L2: weights 2.546 and -1.546, noise about 3x that of one signal).

    Notes
    -----
    IS-GPS-200, 20.3.3.3.3.3: ``PR = (PR_L2 - gamma PR_L1) / (1 - gamma)`` with
    ``gamma = (f1 / f2)^2``, the same combination; the dual-frequency P(Y) user applies the
    broadcast clock polynomial without T_GD (20.3.3.3.3.2), whose reference this combination is.
    """
    f1, f2 = float(f1_hz), float(f2_hz)
    if not (math.isfinite(f1) and math.isfinite(f2) and f1 > 0.0 and f2 > 0.0 and f1 != f2):
        raise ValueError(f"need two different finite carriers > 0, got {f1_hz}, {f2_hz}")
    g1 = f1 * f1 / (f1 * f1 - f2 * f2)
    g2 = f2 * f2 / (f1 * f1 - f2 * f2)
    return g1 * np.asarray(pr1_m, dtype=float) - g2 * np.asarray(pr2_m, dtype=float)


def standard_atmosphere(
    height_m: float, relative_humidity: float = STANDARD_RELATIVE_HUMIDITY
) -> tuple[float, float, float]:
    """Standard-atmosphere surface pressure, temperature and water-vapour pressure.

    Args:
        height_m: ellipsoidal height used as altitude, m; clipped to [0, 11000] (the lapse rate
            holds in the troposphere only).
        relative_humidity: fraction in [0, 1].

    Returns:
        ``(pressure_hpa, temperature_k, water_vapour_hpa)``.

    Notes
    -----
    Berg (1948): P = 1013.25 (1 - 2.2557e-5 h)^5.2568, T = 15 - 6.5e-3 h + 273.16,
    e = 6.108 RH exp((17.15 T - 4684) / (T - 38.45)) (as in RTKLIB ``tropmodel``).
    """
    if not (0.0 <= relative_humidity <= 1.0):
        raise ValueError(f"relative_humidity must be in [0, 1], got {relative_humidity}")
    if not math.isfinite(height_m):
        raise ValueError(f"height_m must be finite, got {height_m}")
    h = min(max(height_m, 0.0), 11_000.0)
    p = 1013.25 * (1.0 - 2.2557e-5 * h) ** 5.2568
    t = 15.0 - 6.5e-3 * h + 273.16
    e = 6.108 * relative_humidity * math.exp((17.15 * t - 4684.0) / (t - 38.45))
    return p, t, e


def black_eisner_mapping(elevation_rad: np.ndarray | float) -> np.ndarray:
    """Black & Eisner (1984) tropospheric mapping function, dimensionless, 1.001 at zenith.

    Args:
        elevation_rad: elevation(s), rad; clipped to >= 0.

    Notes
    -----
    m(E) = 1.001 / sqrt(0.002001 + sin^2 E) (RTCA DO-229, A.4.2.4).
    """
    el = np.clip(np.asarray(elevation_rad, dtype=float), 0.0, None)
    return 1.001 / np.sqrt(0.002001 + np.sin(el) ** 2)


def saastamoinen_zenith_delays_m(
    lat_rad: float, height_m: float, relative_humidity: float = STANDARD_RELATIVE_HUMIDITY
) -> tuple[float, float]:
    """Zenith hydrostatic and wet delays from a standard atmosphere, m.

    Args:
        lat_rad: geodetic latitude, rad.
        height_m: ellipsoidal height, m (see :func:`standard_atmosphere`).
        relative_humidity: fraction in [0, 1].

    Returns:
        ``(zhd_m, zwd_m)``.

    Notes
    -----
    ZHD = 0.0022768 P / (1 - 0.00266 cos 2 phi - 0.00028 H_km) (Saastamoinen 1972; Davis et al.
    1985); ZWD = 0.002277 (1255 / T + 0.05) e (Saastamoinen 1972); P, e in hPa, T in K.
    """
    p, t, e = standard_atmosphere(height_m, relative_humidity)
    h_km = min(max(height_m, 0.0), 11_000.0) / 1000.0
    zhd = 0.0022768 * p / (1.0 - 0.00266 * math.cos(2.0 * lat_rad) - 0.00028 * h_km)
    zwd = 0.002277 * (1255.0 / t + 0.05) * e
    return zhd, zwd


def troposphere_delay_m(
    lat_rad: float,
    height_m: float,
    elevation_rad: np.ndarray | float,
    relative_humidity: float = STANDARD_RELATIVE_HUMIDITY,
) -> np.ndarray:
    """Slant tropospheric delay, m (>= 0): (ZHD + ZWD) m(E).

    Args:
        lat_rad: receiver geodetic latitude, rad.
        height_m: receiver ellipsoidal height, m.
        elevation_rad: satellite elevation(s), rad, scalar or (N,); clipped to >= 0.
        relative_humidity: fraction in [0, 1].

    Returns:
        Slant delay, m, shape of ``elevation_rad``.

    Notes
    -----
    See :func:`saastamoinen_zenith_delays_m` and :func:`black_eisner_mapping`; about 2.4 m at
    zenith at sea level, ~10x at 5 deg elevation.
    """
    zhd, zwd = saastamoinen_zenith_delays_m(lat_rad, height_m, relative_humidity)
    return (zhd + zwd) * black_eisner_mapping(elevation_rad)


GEOMETRY_FREE_SLIP_M = 0.15
"""Jump of the geometry-free carrier combination, m, beyond its extrapolation from the two epochs
before (beyond the epoch before, at an arc's second epoch), taken as a cycle slip (a new arc): one
L1 or L2 cycle moves the combination by 0.19 / 0.24 m, while the ionosphere's rate of change varies
by centimetres over 30 s (the usual geometry-free slip test, Hofmann-Wellenhof et al. 2008, sec.
7.2.1; a slip of 1 cycle on both carriers at once, 0.05 m, goes undetected)."""


def carrier_levelled_ionosphere_m(
    epoch_index: np.ndarray,
    geometry_free_phase_m: np.ndarray,
    model_delay_m: np.ndarray,
    f1_hz: float,
    f2_hz: float,
    slip_threshold_m: float = GEOMETRY_FREE_SLIP_M,
) -> np.ndarray:
    """One satellite's f1 ionospheric group delay: its changes measured by the dual-frequency carrier,
    its level per arc that of a model (the broadcast Klobuchar) averaged over the arc.

    Args:
        epoch_index: the satellite's epochs (index in the file, increasing), shape (N,); a missing
            index (a gap) starts a new arc.
        geometry_free_phase_m: ``lambda1 L1 - lambda2 L2`` at those epochs, m (carrier phases in
            cycles times their wavelengths), shape (N,); NaN where a carrier is missing.
        model_delay_m: the model's f1 delay at those epochs, m, shape (N,) (NaN: none).
        f1_hz / f2_hz: the two carrier frequencies, Hz.
        slip_threshold_m: geometry-free jump, m, beyond the extrapolation taken as a cycle slip (a
            new arc; :data:`GEOMETRY_FREE_SLIP_M`).

    Returns:
        f1 delay, m, shape (N,): NaN where the phase is missing or an arc has no model value.

    Notes:
        The carrier phases advance by the ionosphere, ``Phi_i = rho - I_i + lambda_i N_i`` with
        ``I_2 = gamma I_1``, ``gamma = (f1 / f2)^2``, so ``Phi_1 - Phi_2 = (gamma - 1) I_1 + const``
        over an arc without slips (Hofmann-Wellenhof et al. 2008, eqs. 5.57-5.59): the carrier
        measures the delay's changes to millimetres but not its level. Levelling the arc to the
        dual-frequency code (Ciraolo et al. 2007, J. Geodesy 81, eq. 3) needs the satellites' P1-C1
        code biases when the L1 code is C/A (receivers of the C1/P2 type), which no broadcast message
        carries; here the arc's level is the model's mean over the arc instead. The result keeps the
        model's error averaged over the arc (a constant per arc) and removes the part of it that
        varies within the arc. Non-causal: each value depends on the whole arc (a file converter's
        post-processing, not a live receiver's).
    """
    k = np.asarray(epoch_index, dtype=np.int64).reshape(-1)
    gf = np.asarray(geometry_free_phase_m, dtype=float).reshape(-1)
    model = np.asarray(model_delay_m, dtype=float).reshape(-1)
    if not (k.shape == gf.shape == model.shape):
        raise ValueError(f"epoch_index, geometry_free_phase_m and model_delay_m differ in shape: "
                         f"{k.shape}, {gf.shape}, {model.shape}")
    if not (math.isfinite(f1_hz) and math.isfinite(f2_hz) and f1_hz > f2_hz > 0.0):
        raise ValueError(f"need f1_hz > f2_hz > 0, got {f1_hz!r}, {f2_hz!r}")
    if np.any(np.diff(k) <= 0):
        raise ValueError("epoch_index must be strictly increasing")
    out = np.full(k.shape, math.nan)
    scale = 1.0 / ((f1_hz / f2_hz) ** 2 - 1.0)
    ok = np.isfinite(gf)
    # arcs: a missing phase, a gap in the epochs or a slip starts a new one
    arc = np.zeros(k.shape, dtype=np.int64)
    n_arc, length = 0, 0
    for i in range(k.size):
        if length and ok[i] and k[i] == k[i - 1] + 1:
            predicted = gf[i - 1] if length == 1 else 2.0 * gf[i - 1] - gf[i - 2]
            if abs(gf[i] - predicted) <= slip_threshold_m:
                arc[i], length = n_arc, length + 1
                continue
        n_arc += 1
        arc[i], length = n_arc, (1 if ok[i] else 0)
    for a in np.unique(arc[ok]):
        sel = ok & (arc == a)
        delay = gf[sel] * scale
        have = np.isfinite(model[sel])
        if have.any():
            out[sel] = delay + float(np.mean(model[sel][have] - delay[have]))
    return out
