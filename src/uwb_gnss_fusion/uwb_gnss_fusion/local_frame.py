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
from typing import NamedTuple

import numpy as np
from numba import njit

from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic_scalar, geodetic_to_ecef

HEADING_SOURCES = ('none', 'velocity')
"""Values of ``heading_source`` (module docstring)."""


class LocalSolution(NamedTuple):
    """The solution at base_link in the local ENU frame (immutable; a NamedTuple: built for every published
    solution, at a third of a frozen dataclass's cost).

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
        :func:`gnss_common.coordinates.ecef_to_enu_rotation` at the origin, computed once); the covariance
        ``diag(R, R) P diag(R, R)^T`` (compiled: :func:`_to_local_kernel`).

        Raises:
            RuntimeError: the origin is not defined yet.
        """
        if self.origin_ecef_m is None:
            raise RuntimeError('the local frame has no origin yet')
        return _to_local_kernel(_f64(position_m, 3), _f64(velocity_mps, 3), _f64(covariance_pv, 6, 6),
                                self.origin_ecef_m, self._rotation)

    def base_link_solution(self, stamp_ns: int, position_m: np.ndarray, velocity_mps: np.ndarray,
                           covariance_pv: np.ndarray, frame_is_earth: bool, antenna_position_m: np.ndarray,
                           heading_source: str, min_speed_mps: float) -> LocalSolution:
        """:func:`base_link_solution` of an estimate in ECEF (``frame_is_earth``: first expressed in this frame,
        as :meth:`from_ecef`) or already in the local frame (the filter's map frame), in one compiled call
        (``fusion_node`` makes one per published solution).

        Raises:
            RuntimeError: an ECEF estimate and the origin is not defined yet.
            ValueError: ``heading_source`` is not one of :data:`HEADING_SOURCES`.
        """
        use_velocity = _heading_uses_velocity(heading_source)
        if frame_is_earth:
            if self.origin_ecef_m is None:
                raise RuntimeError('the local frame has no origin yet')
            origin, rotation = self.origin_ecef_m, self._rotation
        else:
            origin, rotation = _ZERO3, _EYE3
        return LocalSolution(stamp_ns, *_local_base_link_kernel(
            _f64(position_m, 3), _f64(velocity_mps, 3), _f64(covariance_pv, 6, 6), origin, rotation,
            _f64(antenna_position_m, 3), use_velocity, float(min_speed_mps)))


_ZERO3 = np.zeros(3)
_EYE3 = np.eye(3)


def _f64(a: np.ndarray, *shape: int) -> np.ndarray:
    """``a`` as a C-contiguous float64 array of ``shape`` (no copy when it is one already)."""
    return np.ascontiguousarray(a, dtype=np.float64).reshape(shape)


def _heading_uses_velocity(heading_source: str) -> bool:
    if heading_source not in HEADING_SOURCES:
        raise ValueError(f'heading_source {heading_source!r} is not one of {", ".join(HEADING_SOURCES)}')
    return heading_source == 'velocity'


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

    Compiled (:func:`_base_link_kernel`); :meth:`LocalFrame.base_link_solution` does the same from ECEF.
    """
    use_velocity = _heading_uses_velocity(heading_source)
    return LocalSolution(stamp_ns, *_base_link_kernel(
        _f64(position_m, 3), _f64(velocity_mps, 3), _f64(covariance_pv, 6, 6), _f64(antenna_position_m, 3),
        use_velocity, float(min_speed_mps)))


@njit(cache=True)
def _to_local_kernel(p: np.ndarray, v: np.ndarray, cov: np.ndarray, origin: np.ndarray, r: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(R (p - origin), R v, diag(R, R) cov diag(R, R)^T) with explicit loops (3 x 3 blocks)."""
    pos = np.zeros(3)
    vel = np.zeros(3)
    for i in range(3):
        for k in range(3):
            pos[i] += r[i, k] * (p[k] - origin[k])
            vel[i] += r[i, k] * v[k]
    tmp = np.zeros((6, 6))      # diag(R, R) cov
    for bi in range(2):
        for i in range(3):
            for j in range(6):
                acc = 0.0
                for k in range(3):
                    acc += r[i, k] * cov[3 * bi + k, j]
                tmp[3 * bi + i, j] = acc
    out = np.zeros((6, 6))      # (diag(R, R) cov) diag(R, R)^T
    for i in range(6):
        for bj in range(2):
            for j in range(3):
                acc = 0.0
                for k in range(3):
                    acc += tmp[i, 3 * bj + k] * r[j, k]
                out[i, 3 * bj + j] = acc
    return pos, vel, out


@njit(cache=True)
def _base_link_kernel(p: np.ndarray, v: np.ndarray, cov: np.ndarray, lever: np.ndarray, use_velocity: bool,
                      min_speed_mps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, float]:
    """(position, its covariance, velocity in base_link axes, its covariance, yaw, yaw variance) of
    :func:`base_link_solution` (module docstring), ENU inputs."""
    speed = math.hypot(v[0], v[1])
    if use_velocity and speed >= min_speed_mps and speed > 0.0:
        yaw = math.atan2(v[1], v[0])
        c, s = math.cos(yaw), math.sin(yaw)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])     # base_link axes -> ENU
        # base = p - rot(yaw(v)) lever, linearised in [p, v]: jac = [I, -g h^T] with g = d(rot lever)/dyaw,
        # h = dyaw/dv
        g = np.array([-s * lever[0] - c * lever[1], c * lever[0] - s * lever[1], 0.0])
        h = np.array([-v[1], v[0], 0.0]) / (speed * speed)
        jac = np.zeros((3, 6))
        for i in range(3):
            jac[i, i] = 1.0
            for j in range(3):
                jac[i, 3 + j] = -g[i] * h[j]
        pos = np.zeros(3)
        vel = np.zeros(3)
        for i in range(3):
            acc = 0.0
            acc_v = 0.0
            for k in range(3):
                acc += rot[i, k] * lever[k]
                acc_v += rot[k, i] * v[k]
            pos[i] = p[i] - acc
            vel[i] = acc_v
        jc = np.zeros((3, 6))
        for i in range(3):
            for j in range(6):
                acc = 0.0
                for k in range(6):
                    acc += jac[i, k] * cov[k, j]
                jc[i, j] = acc
        pos_cov = np.zeros((3, 3))
        for i in range(3):
            for j in range(3):
                acc = 0.0
                for k in range(6):
                    acc += jc[i, k] * jac[j, k]
                pos_cov[i, j] = acc
        rc = np.zeros((3, 3))       # rot^T cov_v
        for i in range(3):
            for j in range(3):
                acc = 0.0
                for k in range(3):
                    acc += rot[k, i] * cov[3 + k, 3 + j]
                rc[i, j] = acc
        vel_cov = np.zeros((3, 3))  # rot^T cov_v rot
        for i in range(3):
            for j in range(3):
                acc = 0.0
                for k in range(3):
                    acc += rc[i, k] * rot[k, j]
                vel_cov[i, j] = acc
        yaw_var = 0.0
        for i in range(3):
            for j in range(3):
                yaw_var += h[i] * cov[3 + i, 3 + j] * h[j]
        return pos, pos_cov, vel, vel_cov, yaw, yaw_var
    # yaw unknown (uniform): horizontal lever arm and horizontal velocity direction unknown
    radius2 = lever[0] ** 2 + lever[1] ** 2
    pos_cov = cov[:3, :3].copy()
    pos_cov[0, 0] += radius2 / 2.0
    pos_cov[1, 1] += radius2 / 2.0
    vel_cov = np.zeros((3, 3))
    horizontal = (v[0] ** 2 + v[1] ** 2 + cov[3, 3] + cov[4, 4]) / 2.0
    vel_cov[0, 0] = horizontal
    vel_cov[1, 1] = horizontal
    vel_cov[2, 2] = cov[5, 5]
    pos = np.array([p[0], p[1], p[2] - lever[2]])
    vel = np.array([0.0, 0.0, v[2]])
    return pos, pos_cov, vel, vel_cov, math.nan, math.nan


@njit(cache=True)
def _local_base_link_kernel(p: np.ndarray, v: np.ndarray, cov: np.ndarray, origin: np.ndarray, r: np.ndarray,
                            lever: np.ndarray, use_velocity: bool, min_speed_mps: float
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, float]:
    """:func:`_to_local_kernel` then :func:`_base_link_kernel`, one call."""
    pos, vel, cl = _to_local_kernel(p, v, cov, origin, r)
    return _base_link_kernel(pos, vel, cl, lever, use_velocity, min_speed_mps)


def warm_up() -> None:
    """Compile (or load from numba's cache) this module's kernels and the geodetic one of the origin on a throwaway
    solution, as :func:`.ckf_kernels.warm_up` does for the filter's (a node calls it before it subscribes)."""
    frame = LocalFrame((45.0, 7.0, 100.0))
    assert frame.origin_ecef_m is not None
    frame.set_origin_ecef(frame.origin_ecef_m)
    p, v, cov, lever = frame.origin_ecef_m + 1.0, np.ones(3), np.eye(6), np.ones(3)
    frame.from_ecef(p, v, cov)
    for heading in HEADING_SOURCES:
        frame.base_link_solution(0, p, v, cov, True, lever, heading, 0.5)
        frame.base_link_solution(0, v, v, cov, False, lever, heading, 0.5)
        base_link_solution(0, v, v, cov, lever, heading, 0.5)
