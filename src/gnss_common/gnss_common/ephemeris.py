"""Keplerian broadcast ephemerides (GPS LNAV, Galileo I/NAV and F/NAV, BeiDou D1/D2, QZSS LNAV):
satellite position, velocity, clock; selection; transmit time; Sagnac.

Everything is vectorised over satellites: :func:`pack_ephemerides` turns a sequence of
:class:`GpsEphemeris` into column arrays once, and :func:`satellite_states` evaluates all of them at
their own epochs in one pass.

Time arguments are split as (continuous GPS week, time of week in s) so that t - t_oe keeps full
float64 resolution (a single "seconds since 1980" float would lose ~0.2 us, about 1 mm of orbit).

Notes
-----
IS-GPS-200 (rev. N), 20.3.3.3.3.1 (satellite clock correction, relativistic term, T_GD for the
L1 C/A single-frequency user), 20.3.3.4.3 and Table 20-IV (user algorithm for the ephemeris).
The velocity is the analytic time derivative of Table 20-IV (as added to IS-GPS-200 in its
Table 20-IV velocity extension and in Remondi, "Computing satellite velocity using the broadcast
ephemeris", GPS Solutions 8, 2004). Cao et al., eq. 5-6 use these satellite states (p_G, v_G,
dt^(i), its drift) in the pseudorange and Doppler models.

The other Keplerian systems use the same algorithm with their own constants and time scale
(``GpsEphemeris.system``):

- Galileo (OS SIS ICD 2.0, 5.1.1-5.1.5): mu = 3.986004418e14, Omega_e = 7.2921151467e-5; GST is
  aligned to GPST (the GGTO of a few ns is neglected; RINEX 3 numbers Galileo weeks as GPS weeks).
  ``tgd_s`` holds the BGD of the record's clock (E1/E5b for I/NAV, E1/E5a for F/NAV), so the clock
  is that of an E1 single-frequency user (ICD 5.1.5).
- BeiDou (BDS-SIS-ICD-B1I-3.0, 5.2.4.12): CGCS2000 mu = 3.986004418e14, Omega_e = 7.2921150e-5;
  times of the record (t_oe, t_oc, week) are BDT = GPST - 14 s, so a GPS epoch is shifted by
  -14 s before t_k is formed. GEO satellites (C01-C05, C59-C63) are computed in the
  ICD's inclined frame and rotated: x_GK = R_Z(Omega_e t_k) R_X(-5 deg) x_GK' (ICD Table 5-11).
  ``tgd_s`` holds TGD1 (B1I user).
- QZSS (IS-QZSS-PNT-004, 4.1.2): the GPS algorithm and constants on GPS time.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np

from gnss_common.constants import (
    BEIDOU_EARTH_ROTATION_RATE_RADPS,
    BEIDOU_GM_M3PS2,
    BEIDOU_MINUS_GPS_TIME_S,
    EARTH_GM_M3PS2,
    EARTH_ROTATION_RATE_RADPS,
    GALILEO_EARTH_ROTATION_RATE_RADPS,
    GALILEO_GM_M3PS2,
    RELATIVISTIC_F_GALILEO_BEIDOU_S_PER_SQRT_M,
    RELATIVISTIC_F_S_PER_SQRT_M,
    SECONDS_PER_WEEK,
    SPEED_OF_LIGHT_MPS,
)
from gnss_common.earth_rotation import (  # noqa: F401 (sagnac_range_correction_m re-exported)
    rotate_about_z,
    sagnac_range_correction_m,
    sagnac_rotate,
)
from gnss_common.gps_time import wrap_week_crossover_s

KEPLER_MAX_ITERATIONS = 30
"""Maximum Newton iterations for Kepler's equation (converges in < 6 for e < 0.03)."""

KEPLER_TOLERANCE_RAD = 1.0e-13
"""Convergence threshold on the eccentric anomaly, rad."""

DEFAULT_FIT_INTERVAL_H = 4.0
"""LNAV curve-fit interval when the fit flag is 0 or absent, h (IS-GPS-200, 20.3.3.4.3.1)."""

KEPLER_SYSTEMS = ("G", "E", "C", "J")
"""RINEX system letters whose broadcast orbit is Keplerian (GPS, Galileo, BeiDou, QZSS)."""

_MAX_SVID = {"G": 63, "E": 36, "C": 63, "J": 10}
"""Largest satellite number per system (RINEX 3.05, 3.5: Gnn, Enn, Cnn, Jnn = PRN - 192)."""

BEIDOU_GEO_INCLINATION_RAD = math.radians(-5.0)
"""Rotation about X of the BeiDou GEO orbit frame, rad (BDS-SIS-ICD-B1I-3.0, Table 5-11)."""


def is_beidou_geo(prn: int) -> bool:
    """True for the BeiDou GEO satellites C01-C05 and C59-C63 (BDS-SIS-ICD-B1I-3.0, 5.2.4.12)."""
    return 1 <= prn <= 5 or 59 <= prn <= 63


@dataclass(frozen=True)
class GpsEphemeris:
    """One Keplerian broadcast ephemeris record (RINEX 2/3 navigation message fields).

    The name is historical: ``system`` says whose record it is ("G" GPS, the default, "E" Galileo,
    "C" BeiDou, "J" QZSS), and the evaluation uses that system's constants and time scale.

    Times: ``toc_week``/``toc_s`` is the clock reference epoch (week, time of week, s);
    ``week`` is the continuous week of ``toe_s``, numbered as GPS weeks for every system (BeiDou:
    BDT week + 1356). ``toe_s``, ``toc_s`` are seconds of week in the system's own time scale
    (GPST, GST = GPST, BDT = GPST - 14 s). Angles are radians (RINEX stores radians), angular
    rates rad/s, ``sqrt_a`` is sqrt(m), harmonic corrections m or rad as in IS-GPS-200.
    ``tgd_s``: GPS/QZSS T_GD, Galileo BGD of the record's clock, BeiDou TGD1; ``health``: 0 is
    usable (for Galileo: the E1-B bits DVS and HS only, see :mod:`gnss_common.rinex`).
    """

    prn: int
    toc_week: int
    toc_s: float
    af0_s: float
    af1_s_per_s: float
    af2_s_per_s2: float
    iode: int
    crs_m: float
    delta_n_radps: float
    m0_rad: float
    cuc_rad: float
    e: float
    cus_rad: float
    sqrt_a_sqrt_m: float
    toe_s: float
    cic_rad: float
    omega0_rad: float
    cis_rad: float
    i0_rad: float
    crc_m: float
    omega_rad: float
    omega_dot_radps: float
    idot_radps: float
    week: int
    sv_accuracy_m: float = 0.0
    health: int = 0
    tgd_s: float = 0.0
    iodc: int = 0
    transmission_time_s: float = math.nan
    fit_interval_h: float = DEFAULT_FIT_INTERVAL_H
    system: str = "G"

    def __post_init__(self) -> None:
        if self.system not in _MAX_SVID:
            raise ValueError(f"system must be one of {KEPLER_SYSTEMS}, got {self.system!r}")
        if self.system == "G" and not 1 <= self.prn <= 63:
            raise ValueError(f"GPS PRN must be in [1, 63], got {self.prn}")
        if not 1 <= self.prn <= _MAX_SVID[self.system]:
            raise ValueError(f"{self.system} satellite number must be in [1, {_MAX_SVID[self.system]}], got {self.prn}")
        if not 0.0 <= self.e < 1.0:
            raise ValueError(f"PRN {self.prn}: eccentricity must be in [0, 1), got {self.e}")
        if not self.sqrt_a_sqrt_m > 1000.0:
            raise ValueError(f"PRN {self.prn}: sqrt(A) = {self.sqrt_a_sqrt_m} sqrt(m) is not an orbit")
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name != "transmission_time_s" and isinstance(v, float) and not math.isfinite(v):
                raise ValueError(f"PRN {self.prn}: field {f.name} is not finite ({v})")


@dataclass(frozen=True)
class EphemerisArrays:
    """Column arrays of N ephemerides (one per row of a vectorised evaluation)."""

    prn: np.ndarray
    toc_week: np.ndarray
    toc_s: np.ndarray
    af0_s: np.ndarray
    af1_s_per_s: np.ndarray
    af2_s_per_s2: np.ndarray
    crs_m: np.ndarray
    delta_n_radps: np.ndarray
    m0_rad: np.ndarray
    cuc_rad: np.ndarray
    e: np.ndarray
    cus_rad: np.ndarray
    sqrt_a_sqrt_m: np.ndarray
    toe_s: np.ndarray
    cic_rad: np.ndarray
    omega0_rad: np.ndarray
    cis_rad: np.ndarray
    i0_rad: np.ndarray
    crc_m: np.ndarray
    omega_rad: np.ndarray
    omega_dot_radps: np.ndarray
    idot_radps: np.ndarray
    week: np.ndarray
    tgd_s: np.ndarray
    gm_m3ps2: np.ndarray
    earth_rotation_radps: np.ndarray
    relativistic_f_s_per_sqrt_m: np.ndarray
    system_minus_gps_s: np.ndarray
    beidou_geo: np.ndarray


_SYSTEM_COLUMNS = ("gm_m3ps2", "earth_rotation_radps", "relativistic_f_s_per_sqrt_m", "system_minus_gps_s")
_ARRAY_FIELDS = tuple(f.name for f in fields(EphemerisArrays) if f.name not in (*_SYSTEM_COLUMNS, "beidou_geo"))
_SYSTEM_CONSTANTS = {
    "G": (EARTH_GM_M3PS2, EARTH_ROTATION_RATE_RADPS, RELATIVISTIC_F_S_PER_SQRT_M, 0.0),
    "J": (EARTH_GM_M3PS2, EARTH_ROTATION_RATE_RADPS, RELATIVISTIC_F_S_PER_SQRT_M, 0.0),
    "E": (GALILEO_GM_M3PS2, GALILEO_EARTH_ROTATION_RATE_RADPS, RELATIVISTIC_F_GALILEO_BEIDOU_S_PER_SQRT_M, 0.0),
    "C": (BEIDOU_GM_M3PS2, BEIDOU_EARTH_ROTATION_RATE_RADPS, RELATIVISTIC_F_GALILEO_BEIDOU_S_PER_SQRT_M,
          BEIDOU_MINUS_GPS_TIME_S),
}
"""system -> (mu m^3/s^2, Omega_e rad/s, F s/sqrt(m), system time - GPST s) of its ephemeris."""


def pack_ephemerides(ephemerides: Sequence[GpsEphemeris]) -> EphemerisArrays:
    """Pack N ephemerides (any mix of Keplerian systems) into column arrays (each shape (N,)) for
    :func:`satellite_states`, with each row's system constants."""
    cols = {name: np.array([getattr(e, name) for e in ephemerides], dtype=float) for name in _ARRAY_FIELDS}
    consts = np.array([_SYSTEM_CONSTANTS[e.system] for e in ephemerides], dtype=float).reshape(-1, 4)
    for k, name in enumerate(_SYSTEM_COLUMNS):
        cols[name] = consts[:, k].copy()
    cols["beidou_geo"] = np.array([e.system == "C" and is_beidou_geo(e.prn) for e in ephemerides], dtype=bool)
    return EphemerisArrays(**cols)


@dataclass(frozen=True)
class SatelliteStates:
    """Satellite states at the requested epochs (row i belongs to ephemeris i).

    Attributes:
        position_ecef_m: (N, 3) antenna phase centre (broadcast: APC), ECEF at the epoch, m.
        velocity_ecef_mps: (N, 3) velocity in the rotating ECEF frame, m/s.
        clock_bias_s: (N,) satellite clock offset incl. relativistic term and minus T_GD, s.
        clock_drift_s_per_s: (N,) its time derivative (incl. relativistic-term rate), s/s.
        relativistic_s: (N,) the relativistic term alone, s.
    """

    position_ecef_m: np.ndarray
    velocity_ecef_mps: np.ndarray
    clock_bias_s: np.ndarray
    clock_drift_s_per_s: np.ndarray
    relativistic_s: np.ndarray


def _solve_kepler(mean_anomaly_rad: np.ndarray, e: np.ndarray) -> np.ndarray:
    ecc = mean_anomaly_rad.copy()
    for _ in range(KEPLER_MAX_ITERATIONS):
        step = (ecc - e * np.sin(ecc) - mean_anomaly_rad) / (1.0 - e * np.cos(ecc))
        ecc = ecc - step
        if np.all(np.abs(step) < KEPLER_TOLERANCE_RAD):
            break
    return ecc


def satellite_states(
    eph: EphemerisArrays, week: np.ndarray | int, tow_s: np.ndarray | float, include_tgd: bool = True
) -> SatelliteStates:
    """Evaluate broadcast orbits and clocks at GPS epochs (vectorised over satellites).

    Args:
        eph: packed ephemerides, N rows (:func:`pack_ephemerides`).
        week: continuous GPS week of each epoch, scalar or shape (N,).
        tow_s: GPS time of week of each epoch (GPS system time, i.e. after the satellite clock
            correction), s, scalar or shape (N,).
        include_tgd: subtract T_GD from the clock (the L1 C/A single-frequency user), default True.

    Returns:
        :class:`SatelliteStates` with N rows.

    Notes
    -----
    IS-GPS-200 Table 20-IV: A = sqrt_a^2, n = sqrt(mu/A^3) + delta_n, t_k = t - t_oe,
    M = M0 + n t_k, Kepler M = E - e sin E, nu from E, Phi = nu + omega, second-harmonic
    corrections, Omega = Omega0 + (Omega_dot - Omega_e) t_k - Omega_e t_oe.
    Clock (20.3.3.3.3.1): dt_sv = af0 + af1 (t - toc) + af2 (t - toc)^2 + dt_r - T_GD with
    dt_r = F e sqrt(A) sin E. Velocity: analytic derivative (Remondi 2004), using
    E_dot = n / (1 - e cos E) and nu_dot = E_dot sqrt(1 - e^2) / (1 - e cos E).
    """
    week_arr = np.asarray(week, dtype=float)
    tow = np.asarray(tow_s, dtype=float) + eph.system_minus_gps_s  # BDT = GPST - 14 s
    # Exact week arithmetic, then the IS-GPS-200 crossover rule guards against files whose week
    # field refers to the transmission rather than to t_oe.
    tk = wrap_week_crossover_s((week_arr - eph.week) * SECONDS_PER_WEEK + (tow - eph.toe_s))
    tc = wrap_week_crossover_s((week_arr - eph.toc_week) * SECONDS_PER_WEEK + (tow - eph.toc_s))

    a = eph.sqrt_a_sqrt_m**2
    e = eph.e
    n = np.sqrt(eph.gm_m3ps2 / a**3) + eph.delta_n_radps
    mean_anom = eph.m0_rad + n * tk
    ecc = _solve_kepler(mean_anom, e)
    sin_e, cos_e = np.sin(ecc), np.cos(ecc)
    one_minus = 1.0 - e * cos_e
    sq = np.sqrt(1.0 - e * e)
    nu = np.arctan2(sq * sin_e, cos_e - e)
    e_dot = n / one_minus
    nu_dot = e_dot * sq / one_minus

    phi = nu + eph.omega_rad
    s2, c2 = np.sin(2.0 * phi), np.cos(2.0 * phi)
    du = eph.cus_rad * s2 + eph.cuc_rad * c2
    dr = eph.crs_m * s2 + eph.crc_m * c2
    di = eph.cis_rad * s2 + eph.cic_rad * c2
    u = phi + du
    r = a * one_minus + dr
    inc = eph.i0_rad + eph.idot_radps * tk + di
    u_dot = nu_dot * (1.0 + 2.0 * (eph.cus_rad * c2 - eph.cuc_rad * s2))
    r_dot = a * e * sin_e * e_dot + 2.0 * nu_dot * (eph.crs_m * c2 - eph.crc_m * s2)
    i_dot = eph.idot_radps + 2.0 * nu_dot * (eph.cis_rad * c2 - eph.cic_rad * s2)

    xp, yp = r * np.cos(u), r * np.sin(u)
    xp_dot = r_dot * np.cos(u) - r * u_dot * np.sin(u)
    yp_dot = r_dot * np.sin(u) + r * u_dot * np.cos(u)

    w_e = eph.earth_rotation_radps
    geo = eph.beidou_geo
    # BeiDou GEO: Omega in the inertial-like frame of t_oe (no Omega_e t_k term), rotated below.
    om_dot = eph.omega_dot_radps - np.where(geo, 0.0, w_e)
    om = eph.omega0_rad + om_dot * tk - w_e * eph.toe_s
    so, co = np.sin(om), np.cos(om)
    si, ci = np.sin(inc), np.cos(inc)
    x = xp * co - yp * ci * so
    y = xp * so + yp * ci * co
    z = yp * si
    vx = xp_dot * co - yp_dot * ci * so + yp * si * so * i_dot - y * om_dot
    vy = xp_dot * so + yp_dot * ci * co - yp * si * co * i_dot + x * om_dot
    vz = yp_dot * si + yp * ci * i_dot
    if np.any(geo):
        x, y, z, vx, vy, vz = _beidou_geo_rotation(geo, w_e, np.asarray(tk), x, y, z, vx, vy, vz)

    rel = eph.relativistic_f_s_per_sqrt_m * e * eph.sqrt_a_sqrt_m * sin_e
    rel_dot = eph.relativistic_f_s_per_sqrt_m * e * eph.sqrt_a_sqrt_m * cos_e * e_dot
    clk = eph.af0_s + eph.af1_s_per_s * tc + eph.af2_s_per_s2 * tc * tc + rel
    if include_tgd:
        clk = clk - eph.tgd_s
    drift = eph.af1_s_per_s + 2.0 * eph.af2_s_per_s2 * tc + rel_dot
    return SatelliteStates(
        position_ecef_m=np.stack([x, y, z], axis=-1),
        velocity_ecef_mps=np.stack([vx, vy, vz], axis=-1),
        clock_bias_s=clk,
        clock_drift_s_per_s=drift,
        relativistic_s=rel,
    )


def _beidou_geo_rotation(
    geo: np.ndarray, w_e: np.ndarray, tk: np.ndarray, x: np.ndarray, y: np.ndarray, z: np.ndarray,
    vx: np.ndarray, vy: np.ndarray, vz: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """x_GK = R_Z(Omega_e t_k) R_X(-5 deg) x_GK' for the GEO rows (BDS-SIS-ICD-B1I-3.0, Table 5-11);
    velocity: the same rotation of v' plus the derivative of R_Z, i.e. minus Omega_e z_hat x x_GK."""
    cx, sx = math.cos(BEIDOU_GEO_INCLINATION_RAD), math.sin(BEIDOU_GEO_INCLINATION_RAD)
    # R_X(phi) = [[1, 0, 0], [0, cos, sin], [0, -sin, cos]] (passive rotation, as in the ICD).
    y1 = cx * y + sx * z
    z1 = -sx * y + cx * z
    vy1 = cx * vy + sx * vz
    vz1 = -sx * vy + cx * vz
    ang = w_e * tk
    cz, sz = np.cos(ang), np.sin(ang)
    # R_Z(phi) = [[cos, sin, 0], [-sin, cos, 0], [0, 0, 1]].
    x2 = cz * x + sz * y1
    y2 = -sz * x + cz * y1
    vx2 = cz * vx + sz * vy1 + w_e * y2
    vy2 = -sz * vx + cz * vy1 - w_e * x2
    return (
        np.where(geo, x2, x), np.where(geo, y2, y), np.where(geo, z1, z),
        np.where(geo, vx2, vx), np.where(geo, vy2, vy), np.where(geo, vz1, vz),
    )


def satellite_states_at_transmit(
    eph: EphemerisArrays,
    week_rx: int,
    tow_rx_s: float,
    pseudorange_m: np.ndarray,
    iterations: int = 2,
    include_tgd: bool = True,
) -> tuple[SatelliteStates, np.ndarray]:
    """Satellite states at signal transmission, from the receive epoch and the pseudoranges.

    Args:
        eph: packed ephemerides, N rows.
        week_rx: continuous GPS week of the receive epoch (receiver time tag).
        tow_rx_s: receive time of week (receiver time tag), s.
        pseudorange_m: measured code pseudoranges, m, shape (N,).
        iterations: fixed-point iterations on the satellite clock (2 reach < 1e-12 s).
        include_tgd: subtract T_GD (L1 C/A user), default True.

    Returns:
        ``(states, tow_tx_s)``: states at the GPS transmit time, and that time of week, s (N,),
        possibly negative (previous week) -- the week is handled internally via t_k.

    Notes
    -----
    t_sv = t_rx - P / c is the satellite's own clock reading at transmission, whatever the receiver
    clock offset (which P contains); GPS time is t = t_sv - dt_sv(t) (IS-GPS-200, 20.3.3.3.3.1,
    eq. for t), solved by fixed-point iteration. Cao et al., eq. 5 then uses p_G(t).
    """
    p = np.asarray(pseudorange_m, dtype=float)
    t_sv = tow_rx_s - p / SPEED_OF_LIGHT_MPS
    t = t_sv.copy()
    for _ in range(max(1, iterations)):
        dt = satellite_states(eph, week_rx, t, include_tgd=include_tgd).clock_bias_s
        t = t_sv - dt
    return satellite_states(eph, week_rx, t, include_tgd=include_tgd), t


def earth_rotation_correction(
    satellite_ecef_m: np.ndarray,
    receiver_ecef_m: np.ndarray,
    satellite_velocity_ecef_mps: np.ndarray | None = None,
    iterations: int = 2,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Rotate satellite state(s) from the transmit-time ECEF frame to the receive-time ECEF frame.

    Args:
        satellite_ecef_m: satellite position(s) at transmission in the ECEF frame of transmission,
            m, shape (N, 3) (or (3,)).
        receiver_ecef_m: receiver position at reception, m, shape (3,).
        satellite_velocity_ecef_mps: optional satellite velocities, m/s, same shape as positions.
        iterations: travel-time iterations (tau = |R3(w tau) x_s - x_r| / c); 2 give < 1 um.

    Returns:
        ``(position_m, velocity_mps_or_None, travel_time_s)`` in the receive-time ECEF frame,
        shapes (N, 3), (N, 3), (N,) (or (3,), (3,), scalar for a (3,) input).

    Notes
    -----
    The geometric range of Cao et al., eq. 5 is D_Ecd(R3(w tau) p_G, p_r)
    (:func:`gnss_common.earth_rotation.sagnac_rotate`). Velocities are rotated with the same
    matrix (the d tau / dt term is below 1e-9 of the velocity and is neglected).
    """
    sat = np.asarray(satellite_ecef_m, dtype=float)
    single = sat.ndim == 1
    rx = np.asarray(receiver_ecef_m, dtype=float).reshape(3)
    rotated, c, s, tau = sagnac_rotate(sat.reshape(-1, 3), rx, iterations)
    vel = None
    if satellite_velocity_ecef_mps is not None:
        vel = rotate_about_z(np.asarray(satellite_velocity_ecef_mps, dtype=float).reshape(-1, 3), c, s)
    if single:
        return rotated[0], (vel[0] if vel is not None else None), tau[0]
    return rotated, vel, tau


class EphemerisStore:
    """Holds Keplerian ephemerides (any systems) and picks the right one for a satellite and epoch.

    Selection rule: health == 0, |t - t_oe| <= max_age_s (default: half the record's fit
    interval, 2 h for the 4 h LNAV fit), and the smallest |t - t_oe|; ties go to the later
    transmission. Unhealthy records are never used.

    Notes
    -----
    IS-GPS-200, 20.3.3.4.3.1 (curve-fit interval) and 20.3.3.3.1.4 (SV health).
    """

    def __init__(self, ephemerides: Sequence[GpsEphemeris], max_age_s: float | None = None) -> None:
        """Index ephemerides by PRN.

        Args:
            ephemerides: records of any systems and satellites, any order.
            max_age_s: override of the validity half-window |t - t_oe|, s (> 0); None: half the fit interval.
        """
        if max_age_s is not None and not (math.isfinite(max_age_s) and max_age_s > 0.0):
            raise ValueError(f"max_age_s must be finite and > 0, got {max_age_s}")
        self._max_age_s = max_age_s
        self._by_sat: dict[tuple[str, int], list[GpsEphemeris]] = {}
        for eph in ephemerides:
            self._by_sat.setdefault((eph.system, eph.prn), []).append(eph)

    @property
    def prns(self) -> tuple[int, ...]:
        """GPS PRNs with at least one record."""
        return tuple(sorted(p for s, p in self._by_sat if s == "G"))

    @property
    def satellites(self) -> tuple[tuple[str, int], ...]:
        """(system letter, satellite number) with at least one record."""
        return tuple(sorted(self._by_sat))

    def select(self, prn: int, week: int, tow_s: float, system: str = "G") -> tuple[GpsEphemeris | None, str]:
        """Return ``(ephemeris, "ok")`` or ``(None, reason)`` with reason one of
        ``"no_ephemeris"``, ``"unhealthy"``, ``"stale_ephemeris"``.

        Args:
            prn: satellite number within its system (GPS: PRN).
            week: continuous GPS week of the epoch.
            tow_s: GPS time of week of the epoch, s.
            system: RINEX system letter ("G" default, "E", "C", "J").
        """
        candidates = self._by_sat.get((system, int(prn)))
        offset_s = _SYSTEM_CONSTANTS[system][3] if system in _SYSTEM_CONSTANTS else 0.0
        if not candidates:
            return None, "no_ephemeris"
        healthy = [e for e in candidates if e.health == 0]
        if not healthy:
            return None, "unhealthy"
        best: GpsEphemeris | None = None
        best_key: tuple[float, float] | None = None
        for e in healthy:
            age = abs((week - e.week) * SECONDS_PER_WEEK + (tow_s + offset_s - e.toe_s))
            limit = self._max_age_s if self._max_age_s is not None else 0.5 * e.fit_interval_h * 3600.0
            if age > limit:
                continue
            tt = e.transmission_time_s if math.isfinite(e.transmission_time_s) else 0.0
            key = (age, -tt)
            if best_key is None or key < best_key:
                best, best_key = e, key
        if best is None:
            return None, "stale_ephemeris"
        return best, "ok"
