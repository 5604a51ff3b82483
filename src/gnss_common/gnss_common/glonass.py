"""GLONASS broadcast ephemeris: orbit integration in PZ-90, clock, frequency channel; selection.

A GLONASS navigation message does not carry Keplerian elements: it gives the satellite's state
(position, velocity, luni-solar acceleration) in the Earth-fixed PZ-90 frame at the reference
time t_b, and the user integrates the equations of motion from t_b to the wanted epoch. This
module does that, vectorised over satellites, on the GPS time scale used by the rest of
:mod:`gnss_common`.

Times: RINEX gives the epoch t_b of a GLONASS record in UTC; :mod:`gnss_common.rinex` converts it
to GPS time with the leap seconds of the file header (GLONASS time = UTC(SU) + 3 h, so the
3 h and the leap seconds are the only offsets between the scales; the tau_c / tau_GPS offsets of
a few ns are neglected).

Frames: PZ-90.11 and WGS 84 (G1762) agree to a few cm (IERS Technical Note 36 / GLONASS ICD
2016 edition); no transformation is applied.

Notes
-----
GLONASS ICD edition 5.1 (2008), Appendix A.3.1.2 "Simplify algorithm for re-calculation of
ephemeris to current time": fourth-order Runge-Kutta integration of

    dx/dt = v_x,  dv_x/dt = -mu/r^3 x - 3/2 J2 mu a_e^2 / r^5 x (1 - 5 z^2/r^2) + w^2 x + 2 w v_y + a_x
    dy/dt = v_y,  dv_y/dt = -mu/r^3 y - 3/2 J2 mu a_e^2 / r^5 y (1 - 5 z^2/r^2) + w^2 y - 2 w v_x + a_y
    dz/dt = v_z,  dv_z/dt = -mu/r^3 z - 3/2 J2 mu a_e^2 / r^5 z (3 - 5 z^2/r^2) + a_z

with the broadcast luni-solar accelerations (a_x, a_y, a_z) held constant over the interval
(ICD A.3.1.2, they are the projections of the Moon's and Sun's accelerations at t_b).
Clock (ICD 3.3.3, RINEX 3.05 Table A10): dt_sv(t) = -tau_n + gamma_n (t - t_b), RINEX storing
-tau_n and +gamma_n; the relativistic effects are already in tau_n, gamma_n.
Carrier: f_G1 = 1602 MHz + k 0.5625 MHz, k the frequency channel of the satellite (ICD 3.3.1.4).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np

from gnss_common.constants import (
    GLONASS_EARTH_ROTATION_RATE_RADPS,
    GLONASS_G1_BASE_FREQUENCY_HZ,
    GLONASS_G1_CHANNEL_SPACING_HZ,
    GLONASS_GM_M3PS2,
    GLONASS_J2,
    GLONASS_MAX_CHANNEL,
    GLONASS_MIN_CHANNEL,
    GLONASS_SEMI_MAJOR_AXIS_M,
    SECONDS_PER_WEEK,
    SPEED_OF_LIGHT_MPS,
)
from gnss_common.ephemeris import SatelliteStates

INTEGRATION_STEP_S = 60.0
"""Largest Runge-Kutta step, s (ICD A.3.1.2 allows up to a few minutes; 60 s keeps the
truncation error below 1 mm over 15 min)."""

DEFAULT_MAX_AGE_S = 1800.0
"""Largest |t - t_b| for which a record is used, s: records come every 30 min, so the nearest one
is at most 15 min away; 30 min covers one missed record (RTKLIB MAXDTOE_GLO)."""


@dataclass(frozen=True)
class GlonassEphemeris:
    """One GLONASS broadcast record (RINEX 3 navigation message fields, SI units).

    Attributes:
        slot: orbital slot number n (RINEX ``Rnn``), 1..63.
        tb_week: continuous GPS week of the reference time t_b (converted from UTC).
        tb_s: GPS time of week of t_b, s.
        minus_tau_n_s: -tau_n, the clock bias term as RINEX stores it, s.
        gamma_n: relative frequency bias +gamma_n, dimensionless (s/s).
        frame_time_s: message frame time t_k + nd 86400, s of the UTC week (kept for reference).
        position_m: PZ-90 position at t_b, m, shape (3,).
        velocity_mps: PZ-90 velocity at t_b, m/s, shape (3,).
        acceleration_mps2: luni-solar acceleration at t_b, m/s^2, shape (3,).
        health: 0 healthy (RINEX: MSB of B_n), nonzero unusable.
        frequency_channel: FDMA channel k, -7..13.
        age_days: age of the operational information E_n, days.
    """

    slot: int
    tb_week: int
    tb_s: float
    minus_tau_n_s: float
    gamma_n: float
    frame_time_s: float
    position_m: np.ndarray
    velocity_mps: np.ndarray
    acceleration_mps2: np.ndarray
    health: int
    frequency_channel: int
    age_days: float = 0.0

    def __post_init__(self) -> None:
        if not 1 <= self.slot <= 63:
            raise ValueError(f"GLONASS slot must be in [1, 63], got {self.slot}")
        if not GLONASS_MIN_CHANNEL <= self.frequency_channel <= GLONASS_MAX_CHANNEL:
            raise ValueError(
                f"R{self.slot:02d}: frequency channel must be in [{GLONASS_MIN_CHANNEL}, {GLONASS_MAX_CHANNEL}],"
                f" got {self.frequency_channel}"
            )
        for f in fields(self):
            v = getattr(self, f.name)
            arr = np.asarray(v, dtype=float) if not isinstance(v, str) else None
            if arr is not None and not np.all(np.isfinite(arr)):
                raise ValueError(f"R{self.slot:02d}: field {f.name} is not finite ({v})")
        for name in ("position_m", "velocity_mps", "acceleration_mps2"):
            if np.asarray(getattr(self, name)).shape != (3,):
                raise ValueError(f"R{self.slot:02d}: {name} must have shape (3,)")
        r = float(np.linalg.norm(self.position_m))
        if not 2.0e7 < r < 3.0e7:
            raise ValueError(f"R{self.slot:02d}: geocentric radius {r:.0f} m is not a GLONASS orbit")

    @property
    def carrier_frequency_hz(self) -> float:
        """G1 carrier of this satellite's channel, Hz."""
        return glonass_g1_frequency_hz(self.frequency_channel)


def glonass_g1_frequency_hz(channel: int) -> float:
    """G1 FDMA carrier, Hz: 1602 MHz + k 0.5625 MHz (GLONASS ICD 5.1, 3.3.1.4)."""
    return GLONASS_G1_BASE_FREQUENCY_HZ + int(channel) * GLONASS_G1_CHANNEL_SPACING_HZ


@dataclass(frozen=True)
class GlonassArrays:
    """Column arrays of N GLONASS records (row i = record i)."""

    slot: np.ndarray
    tb_week: np.ndarray
    tb_s: np.ndarray
    minus_tau_n_s: np.ndarray
    gamma_n: np.ndarray
    position_m: np.ndarray  # (N, 3)
    velocity_mps: np.ndarray  # (N, 3)
    acceleration_mps2: np.ndarray  # (N, 3)
    frequency_channel: np.ndarray


def pack_glonass(ephemerides: Sequence[GlonassEphemeris]) -> GlonassArrays:
    """Pack N GLONASS records into column arrays for :func:`glonass_states`."""
    return GlonassArrays(
        slot=np.array([e.slot for e in ephemerides], dtype=float),
        tb_week=np.array([e.tb_week for e in ephemerides], dtype=float),
        tb_s=np.array([e.tb_s for e in ephemerides], dtype=float),
        minus_tau_n_s=np.array([e.minus_tau_n_s for e in ephemerides], dtype=float),
        gamma_n=np.array([e.gamma_n for e in ephemerides], dtype=float),
        position_m=np.array([e.position_m for e in ephemerides], dtype=float).reshape(-1, 3),
        velocity_mps=np.array([e.velocity_mps for e in ephemerides], dtype=float).reshape(-1, 3),
        acceleration_mps2=np.array([e.acceleration_mps2 for e in ephemerides], dtype=float).reshape(-1, 3),
        frequency_channel=np.array([e.frequency_channel for e in ephemerides], dtype=float),
    )


def _derivatives(pos: np.ndarray, vel: np.ndarray, acc_ls: np.ndarray) -> np.ndarray:
    """Time derivative of the (N, 6) state [x, y, z, vx, vy, vz] (ICD A.3.1.2), m/s and m/s^2."""
    x, y, z = pos[:, 0], pos[:, 1], pos[:, 2]
    r2 = x * x + y * y + z * z
    r = np.sqrt(r2)
    mu_r3 = GLONASS_GM_M3PS2 / (r2 * r)
    j2 = 1.5 * GLONASS_J2 * GLONASS_GM_M3PS2 * GLONASS_SEMI_MAJOR_AXIS_M**2 / (r2 * r2 * r)
    z2r2 = 5.0 * z * z / r2
    w = GLONASS_EARTH_ROTATION_RATE_RADPS
    ax = -mu_r3 * x - j2 * x * (1.0 - z2r2) + w * w * x + 2.0 * w * vel[:, 1] + acc_ls[:, 0]
    ay = -mu_r3 * y - j2 * y * (1.0 - z2r2) + w * w * y - 2.0 * w * vel[:, 0] + acc_ls[:, 1]
    az = -mu_r3 * z - j2 * z * (3.0 - z2r2) + acc_ls[:, 2]
    return np.concatenate([vel, np.stack([ax, ay, az], axis=-1)], axis=1)


def integrate_orbit(
    position_m: np.ndarray,
    velocity_mps: np.ndarray,
    acceleration_mps2: np.ndarray,
    dt_s: np.ndarray,
    max_step_s: float = INTEGRATION_STEP_S,
) -> tuple[np.ndarray, np.ndarray]:
    """Propagate PZ-90 states by dt_s with fourth-order Runge-Kutta (GLONASS ICD 5.1, A.3.1.2).

    Args:
        position_m: (N, 3) positions at t_b, m.
        velocity_mps: (N, 3) velocities at t_b, m/s.
        acceleration_mps2: (N, 3) luni-solar accelerations (held constant), m/s^2.
        dt_s: (N,) t - t_b, s (either sign).
        max_step_s: largest step, s; every row takes the same number of equal steps
            ceil(max |dt| / max_step_s).

    Returns:
        ``(position_m, velocity_mps)`` at t, each (N, 3).
    """
    dt = np.asarray(dt_s, dtype=float).reshape(-1)
    state = np.concatenate([np.asarray(position_m, float), np.asarray(velocity_mps, float)], axis=1)
    acc = np.asarray(acceleration_mps2, dtype=float)
    if dt.size == 0:
        return state[:, :3], state[:, 3:]
    n_steps = max(1, int(math.ceil(float(np.max(np.abs(dt))) / max_step_s)))
    h = (dt / n_steps)[:, None]
    for _ in range(n_steps):
        k1 = _derivatives(state[:, :3], state[:, 3:], acc)
        s2 = state + 0.5 * h * k1
        k2 = _derivatives(s2[:, :3], s2[:, 3:], acc)
        s3 = state + 0.5 * h * k2
        k3 = _derivatives(s3[:, :3], s3[:, 3:], acc)
        s4 = state + h * k3
        k4 = _derivatives(s4[:, :3], s4[:, 3:], acc)
        state = state + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return state[:, :3].copy(), state[:, 3:].copy()


def glonass_clock_s(eph: GlonassArrays, week: np.ndarray | int, tow_s: np.ndarray | float) -> np.ndarray:
    """Satellite clock offset dt_sv = -tau_n + gamma_n (t - t_b), s (ICD 3.3.3), at GPS epochs."""
    dt = (np.asarray(week, dtype=float) - eph.tb_week) * SECONDS_PER_WEEK + (np.asarray(tow_s, float) - eph.tb_s)
    return eph.minus_tau_n_s + eph.gamma_n * dt


def glonass_states(eph: GlonassArrays, week: np.ndarray | int, tow_s: np.ndarray | float) -> SatelliteStates:
    """GLONASS satellite states at GPS epochs (vectorised over records).

    Args:
        eph: packed records, N rows (:func:`pack_glonass`).
        week: continuous GPS week of each epoch, scalar or (N,).
        tow_s: GPS time of week of each epoch (system time, after the satellite clock correction), s.

    Returns:
        :class:`gnss_common.ephemeris.SatelliteStates`: PZ-90 (taken as ECEF) position and velocity,
        clock offset and drift (gamma_n); ``relativistic_s`` is zero (it is inside tau_n).
    """
    dt = (np.asarray(week, dtype=float) - eph.tb_week) * SECONDS_PER_WEEK + (np.asarray(tow_s, float) - eph.tb_s)
    dt = np.broadcast_to(dt, eph.tb_s.shape)
    pos, vel = integrate_orbit(eph.position_m, eph.velocity_mps, eph.acceleration_mps2, dt)
    return SatelliteStates(
        position_ecef_m=pos,
        velocity_ecef_mps=vel,
        clock_bias_s=eph.minus_tau_n_s + eph.gamma_n * dt,
        clock_drift_s_per_s=eph.gamma_n.copy(),
        relativistic_s=np.zeros_like(dt),
    )


def glonass_states_at_transmit(
    eph: GlonassArrays, week_rx: int, tow_rx_s: float, pseudorange_m: np.ndarray
) -> tuple[SatelliteStates, np.ndarray]:
    """GLONASS states at signal transmission from the receive epoch and the pseudoranges.

    Args:
        eph: packed records, N rows.
        week_rx: continuous GPS week of the receive epoch.
        tow_rx_s: receive GPS time of week (receiver time tag), s.
        pseudorange_m: (N,) code pseudoranges, m.

    Returns:
        ``(states, tow_tx_s)`` as :func:`gnss_common.ephemeris.satellite_states_at_transmit`.

    Notes
    -----
    t = t_sv - dt_sv(t) with t_sv = t_rx - P / c; the clock model is linear, so two fixed-point
    steps reach < 1e-15 s, and the orbit is integrated once.
    """
    p = np.asarray(pseudorange_m, dtype=float)
    t_sv = tow_rx_s - p / SPEED_OF_LIGHT_MPS
    t = t_sv.copy()
    for _ in range(2):
        t = t_sv - glonass_clock_s(eph, week_rx, t)
    return glonass_states(eph, week_rx, t), t


class GlonassStore:
    """Holds GLONASS records and picks the one nearest in time for a slot and epoch.

    Selection: health == 0, |t - t_b| <= max_age_s, smallest |t - t_b|.
    """

    def __init__(self, ephemerides: Sequence[GlonassEphemeris], max_age_s: float = DEFAULT_MAX_AGE_S) -> None:
        """Args:
        ephemerides: GLONASS records, any slots, any order.
        max_age_s: validity half-window |t - t_b|, s (> 0).
        """
        if not (math.isfinite(max_age_s) and max_age_s > 0.0):
            raise ValueError(f"max_age_s must be finite and > 0, got {max_age_s}")
        self._max_age_s = max_age_s
        self._by_slot: dict[int, list[GlonassEphemeris]] = {}
        for e in ephemerides:
            self._by_slot.setdefault(e.slot, []).append(e)

    @property
    def slots(self) -> tuple[int, ...]:
        """Slots with at least one record."""
        return tuple(sorted(self._by_slot))

    def select(self, slot: int, week: int, tow_s: float) -> tuple[GlonassEphemeris | None, str]:
        """``(record, "ok")`` or ``(None, reason)``, reason ``"no_ephemeris"``, ``"unhealthy"`` or
        ``"stale_ephemeris"`` (as :meth:`gnss_common.ephemeris.EphemerisStore.select`)."""
        cands = self._by_slot.get(int(slot))
        if not cands:
            return None, "no_ephemeris"
        healthy = [e for e in cands if e.health == 0]
        if not healthy:
            return None, "unhealthy"
        best, best_age = None, math.inf
        for e in healthy:
            age = abs((week - e.tb_week) * SECONDS_PER_WEEK + (tow_s - e.tb_s))
            if age <= self._max_age_s and age < best_age:
                best, best_age = e, age
        if best is None:
            return None, "stale_ephemeris"
        return best, "ok"
