"""Geometry of the fusion's topics made to be drawn (issue 30): covariance ellipse, anchors, satellites on a map.

Pure (numpy; no rclpy, no message types). :mod:`uwb_gnss_fusion.view_topics` turns these into ``nav_msgs/Path`` and
``visualization_msgs/MarkerArray`` in the ``map`` frame (local ENU, REP 105).

* :func:`covariance_ellipse`: the horizontal confidence ellipse of a position (east, north) covariance: semi-axes
  ``k sqrt(lambda_i)`` with ``k = sqrt(-2 ln(1 - p))`` (the chi-square quantile of 2 degrees of freedom at
  probability p: 2.448 at 95 %) and the major axis's angle from east.
* :func:`sky_directions`: unit line-of-sight vectors, ENU at the receiver, from a receiver to satellites (ECEF):
  a satellite is drawn ``satellite_marker_distance_m`` from the antenna along it, a sky plot around the robot.
* :func:`satellite_label`: ``G05``, ``E11``, ... (RINEX system letters) of a key ``constellation * 1000 + svid``.

Example
-------
>>> import numpy as np
>>> a, b, yaw = covariance_ellipse(np.diag([4.0, 1.0]), 0.95)
>>> round(a, 3), round(b, 3), round(yaw, 3)
(4.895, 2.448, 0.0)
>>> satellite_label(1005), satellite_label(3011)
('G05', 'E11')
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gnss_common.coordinates import ecef_to_enu
from gnss_common.observations import BEIDOU, GALILEO, GLONASS, GPS, QZSS, SBAS
from rfi_node_common.params import parameter

SYSTEM_LETTERS = {GPS: 'G', GLONASS: 'R', GALILEO: 'E', BEIDOU: 'C', QZSS: 'J', SBAS: 'S'}
"""RINEX 3 system letter of each constellation code (gnss_common.observations)."""


@dataclass(frozen=True)
class FusionViewParams:
    """Parameters of the fusion's drawn topics (defined here once; FusionNodeParams takes them over)."""

    view_rate_hz: float = parameter(
        5.0, 'Rate of the topics made to be drawn, per second of stamp time: fusion/path (nav_msgs/Path in '
        'map_frame_id, one pose added per update), fusion/markers (visualization_msgs/MarkerArray: UWB anchors, '
        'position covariance ellipse) and fusion/satellites (MarkerArray: satellites used and rejected), Hz. '
        'Published only while someone subscribes; the subscriptions are looked at once per period.',
        minimum=0.01, maximum=1000.0)
    path_max_poses: int = parameter(
        3000, 'Poses kept in fusion/path (the oldest dropped): path_max_poses / view_rate_hz s of track.',
        minimum=2, maximum=1000000)
    covariance_probability: float = parameter(
        0.95, 'Probability of the horizontal position confidence ellipse drawn on fusion/markers (chi-square, 2 '
        'degrees of freedom: semi-axes 2.45 sigma at 0.95).', minimum=0.01, maximum=0.9999)
    satellite_marker_distance_m: float = parameter(
        20.0, 'Distance from the antenna at which fusion/satellites draws each satellite along its line of sight '
        '(a sky plot around the robot), m.', minimum=0.1, maximum=1e6)


def covariance_ellipse(cov_en_m2: np.ndarray, probability: float) -> tuple[float, float, float]:
    """The confidence ellipse of a horizontal position covariance.

    Args:
        cov_en_m2: covariance of (east, north), m^2, shape (2, 2) (the top-left of a 3x3 ENU covariance).
        probability: of the ellipse, 0 < p < 1.

    Returns:
        (semi-major axis m, semi-minor axis m, angle of the major axis from east, counter-clockwise, rad). NaN
        axes for a covariance that is not finite; negative eigenvalues (round-off) are taken as 0.
    """
    c = np.asarray(cov_en_m2, dtype=np.float64)[:2, :2]
    if not np.isfinite(c).all():
        return math.nan, math.nan, 0.0
    k = math.sqrt(-2.0 * math.log(1.0 - probability))
    w, v = np.linalg.eigh(0.5 * (c + c.T))
    w = np.maximum(w, 0.0)
    yaw = math.atan2(float(v[1, 1]), float(v[0, 1]))
    if yaw > math.pi / 2:
        yaw -= math.pi
    elif yaw <= -math.pi / 2:
        yaw += math.pi
    return k * math.sqrt(float(w[1])), k * math.sqrt(float(w[0])), yaw


def sky_directions(receiver_ecef_m: np.ndarray, satellites_ecef_m: np.ndarray) -> np.ndarray:
    """Unit lines of sight, ENU at the receiver, shape (N, 3) (NaN rows for satellites without a position)."""
    sats = np.asarray(satellites_ecef_m, dtype=np.float64).reshape(-1, 3)
    out = np.full(sats.shape, np.nan)
    ok = np.isfinite(sats).all(axis=1)
    if ok.any():
        enu = ecef_to_enu(sats[ok], np.asarray(receiver_ecef_m, dtype=np.float64).reshape(3))
        norm = np.linalg.norm(enu, axis=1, keepdims=True)
        out[ok] = enu / np.where(norm > 0, norm, np.nan)
    return out


def satellite_label(key: int) -> str:
    """``G05`` for key 1005 (``constellation * 1000 + svid``; ``?`` for an unknown constellation)."""
    system, svid = divmod(int(key), 1000)
    return f'{SYSTEM_LETTERS.get(system, "?")}{svid:02d}'


def yaw_quaternion(yaw_rad: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by yaw about the up axis."""
    return 0.0, 0.0, math.sin(yaw_rad / 2.0), math.cos(yaw_rad / 2.0)
