"""The fusion solution in a local ENU frame (REP 105 ``map``) at the robot's ``base_link``.

Pure core (no rclpy). :class:`LocalFrame` holds the origin of the local frame (a datum given as
WGS 84 latitude / longitude / ellipsoidal altitude, or the first good fix) and expresses an ECEF
estimate of the GNSS antenna in it; :func:`base_link_solution` moves the antenna estimate to the
robot's ``base_link`` with the antenna's position in ``base_link`` (the lever arm).

Frames. The local frame is east-north-up at the origin (x east, y north, z up, REP 103/105), the
tangent frame of :func:`gnss_common.coordinates.ecef_to_enu` (its rotation, computed once per
origin by :func:`gnss_common.coordinates.ecef_to_enu_rotation`). ``base_link`` is the robot's body
frame (x forward, y left, z up, REP 103). An estimate already in the anchors' local frame (UWB-only
mode of the filter, ``frame_id`` map) is used as it is: its axes are taken as ENU, as the filter does.

Attitude. The filter estimates position and velocity of the antenna, not attitude. The robot is
assumed level (roll = pitch = 0), so the lever arm's vertical part always applies. Its horizontal
part needs the yaw, which is known only under an assumption the integrator chooses
(``heading_source``):

* ``none``: the yaw is unknown. The base_link position is the antenna's minus the vertical lever
  arm, and the horizontal position covariance grows by r^2 / 2 per axis (r: horizontal lever arm
  length; base_link lies on a circle of radius r around the antenna, and r^2 / 2 is the variance
  per axis of a point uniform on it). The horizontal velocity in base_link axes has mean 0 and
  variance (|v_h|^2 + trace of the horizontal velocity covariance) / 2 per axis (the same reasoning
  for the velocity vector): tight when the robot stands still, weak when it moves.
* ``velocity``: the robot moves forward without side slip (a car-like robot, not reversing): its
  yaw is the course over ground atan2(v_n, v_e) whenever the horizontal speed is at least
  ``min_speed_mps``; below it the yaw is unknown as with ``none``. The lever arm is rotated by this
  yaw, the base_link position covariance includes the yaw error (linearised: var(yaw) from the
  velocity covariance across the course divided by speed^2), and the velocity is rotated into
  base_link axes (forward = speed, left = 0 with the across-course velocity variance).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic_scalar, geodetic_to_ecef

HEADING_SOURCES = ('none', 'velocity')
"""Values of ``heading_source`` (module docstring)."""


@dataclass(frozen=True)
class LocalSolution:
    """The solution at base_link in the local ENU frame.

    Attributes:
        stamp_ns: stamp of the estimate, ns.
        position_m: base_link position, ENU, m, shape (3,).
        position_covariance_m2: its covariance, ENU, m^2, shape (3, 3).
        velocity_body_mps: base_link velocity in base_link axes (forward, left, up), m/s, shape (3,).
        velocity_covariance_m2ps2: its covariance, m^2/s^2, shape (3, 3).
        yaw_rad: yaw of base_link x from east, counter-clockwise, rad (NaN: unknown).
        yaw_variance_rad2: its variance, rad^2 (NaN: unknown).
    """

    stamp_ns: int
    position_m: np.ndarray
    position_covariance_m2: np.ndarray
    velocity_body_mps: np.ndarray
    velocity_covariance_m2ps2: np.ndarray
    yaw_rad: float
    yaw_variance_rad2: float


class LocalFrame:
    """Origin and axes of the local ENU frame.

    Args:
        datum: (latitude_deg, longitude_deg, ellipsoidal altitude_m) of the origin, or None: the origin
            is set by :meth:`set_origin_ecef` (the node uses the first good fix).
    """

    def __init__(self, datum: tuple[float, float, float] | None = None) -> None:
        self.origin_ecef_m: np.ndarray | None = None
        self.origin_geodetic: tuple[float, float, float] | None = None
        self._rotation = np.eye(3)
        if datum is not None:
            lat_deg, lon_deg, alt_m = (float(v) for v in datum)
            self._set(np.asarray(geodetic_to_ecef(math.radians(lat_deg), math.radians(lon_deg), alt_m), dtype=float),
                      (lat_deg, lon_deg, alt_m))

    @property
    def defined(self) -> bool:
        """The origin is known."""
        return self.origin_ecef_m is not None

    def set_origin_ecef(self, position_ecef_m: np.ndarray) -> None:
        """Put the origin at an ECEF point, m, shape (3,) (the first good fix)."""
        p = np.asarray(position_ecef_m, dtype=float).reshape(3)
        lat, lon, h = ecef_to_geodetic_scalar(*p.tolist())
        self._set(p, (math.degrees(lat), math.degrees(lon), h))

    def _set(self, origin_ecef_m: np.ndarray, geodetic: tuple[float, float, float]) -> None:
        self.origin_ecef_m = origin_ecef_m
        self.origin_geodetic = geodetic
        self._rotation = ecef_to_enu_rotation(math.radians(geodetic[0]), math.radians(geodetic[1]))

    def from_ecef(self, position_m: np.ndarray, velocity_mps: np.ndarray,
                  covariance_pv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """An ECEF estimate in the local frame: (position, m; velocity, m/s; 6x6 covariance of [p, v]).

        ``R @ (p - origin)``, as :func:`gnss_common.coordinates.ecef_to_enu` (R from
        :func:`gnss_common.coordinates.ecef_to_enu_rotation` at the origin, computed once).

        Raises:
            RuntimeError: the origin is not defined yet.
        """
        if self.origin_ecef_m is None:
            raise RuntimeError('the local frame has no origin yet')
        r = self._rotation
        rr = np.zeros((6, 6))
        rr[:3, :3] = r
        rr[3:, 3:] = r
        return r @ (np.asarray(position_m) - self.origin_ecef_m), r @ np.asarray(velocity_mps), \
            rr @ covariance_pv @ rr.T


def _yaw_rotation(yaw_rad: float) -> np.ndarray:
    """base_link axes -> ENU for a level robot with this yaw."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def base_link_solution(stamp_ns: int, position_m: np.ndarray, velocity_mps: np.ndarray, covariance_pv: np.ndarray,
                       antenna_position_m: np.ndarray, heading_source: str, min_speed_mps: float) -> LocalSolution:
    """The antenna's local ENU estimate moved to base_link (module docstring: assumptions).

    Args:
        stamp_ns: stamp, ns.
        position_m: antenna position, ENU, m, shape (3,).
        velocity_mps: antenna velocity, ENU, m/s, shape (3,) (that of base_link too: no rotation rate
            is estimated, so the lever arm adds no velocity).
        covariance_pv: covariance of [position, velocity], ENU, shape (6, 6).
        antenna_position_m: antenna position in base_link (forward, left, up), m, shape (3,).
        heading_source: one of :data:`HEADING_SOURCES`.
        min_speed_mps: with ``velocity``: the horizontal speed from which the course is the yaw, m/s.
    """
    if heading_source not in HEADING_SOURCES:
        raise ValueError(f'heading_source {heading_source!r} is not one of {", ".join(HEADING_SOURCES)}')
    p = np.asarray(position_m, dtype=float)
    v = np.asarray(velocity_mps, dtype=float)
    cov = np.asarray(covariance_pv, dtype=float)
    lever = np.asarray(antenna_position_m, dtype=float)
    cov_p, cov_v = cov[:3, :3], cov[3:, 3:]
    speed = math.hypot(v[0], v[1])
    if heading_source == 'velocity' and speed >= min_speed_mps and speed > 0.0:
        yaw = math.atan2(v[1], v[0])
        rot = _yaw_rotation(yaw)
        # d(rot @ lever)/dyaw and dyaw/dv: base = p - rot(yaw(v)) lever, linearised in [p, v]
        c, s = math.cos(yaw), math.sin(yaw)
        g = np.array([-s * lever[0] - c * lever[1], c * lever[0] - s * lever[1], 0.0])
        h = np.array([-v[1], v[0], 0.0]) / (speed * speed)
        jac = np.hstack([np.eye(3), -np.outer(g, h)])
        return LocalSolution(
            stamp_ns=stamp_ns, position_m=p - rot @ lever, position_covariance_m2=jac @ cov @ jac.T,
            velocity_body_mps=rot.T @ v, velocity_covariance_m2ps2=rot.T @ cov_v @ rot,
            yaw_rad=yaw, yaw_variance_rad2=float(h @ cov_v @ h))
    # yaw unknown (uniform): horizontal lever arm and horizontal velocity direction unknown
    radius2 = float(lever[0] ** 2 + lever[1] ** 2)
    pos_cov = cov_p.copy()
    pos_cov[0, 0] += radius2 / 2.0
    pos_cov[1, 1] += radius2 / 2.0
    vel_cov = np.zeros((3, 3))
    horizontal = (v[0] ** 2 + v[1] ** 2 + cov_v[0, 0] + cov_v[1, 1]) / 2.0
    vel_cov[0, 0] = vel_cov[1, 1] = horizontal
    vel_cov[2, 2] = cov_v[2, 2]
    return LocalSolution(
        stamp_ns=stamp_ns, position_m=p - np.array([0.0, 0.0, lever[2]]), position_covariance_m2=pos_cov,
        velocity_body_mps=np.array([0.0, 0.0, v[2]]), velocity_covariance_m2ps2=vel_cov,
        yaw_rad=math.nan, yaw_variance_rad2=math.nan)
