"""What the fusion filter returns after every input: :class:`FusionOutput`.

Pure core (no rclpy). The node maps it onto nav_msgs/Odometry, sensor_msgs/NavSatFix and
rfi_msgs/FusionStatus (:mod:`.output_messages`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from gnss_common.coordinates import ecef_to_geodetic_scalar, rotate_covariance_ecef_to_enu_scalar

from .fusion_params import FRAME_EARTH


@dataclass(frozen=True)
class FusionOutput:
    """Everything the node maps onto nav_msgs/Odometry, sensor_msgs/NavSatFix and FusionStatus.

    Attributes:
        stamp_ns: filter time of this output, ns.
        frame_id: "earth" (ECEF) or "map" (anchors' local frame, UWB-only mode).
        initialized: False until the state exists; then position/velocity are NaN and invalid.
        diverged: divergence was declared at this call (the filter reinitialised or reset).
        mode: MODE_* of the recent updates (GNSS and/or UWB applied within the last second).
        position_m: position in frame_id, m, shape (3,).
        velocity_mps: velocity in frame_id, m/s, shape (3,).
        covariance_pv: covariance of [position, velocity], shape (6, 6), m^2, m^2/s, m^2/s^2
            (row-major order x, y, z, vx, vy, vz in frame_id).
        clock_bias_m: receiver c*dt, m (NaN in "map" mode or before the first GNSS epoch).
        clock_drift_mps: receiver c*ddt, m/s (NaN likewise).
        satellites_used / satellites_rejected / uwb_used / uwb_rejected: counts of this call.
        normalized_innovation_squared: NIS per applied measurement of this call (NaN if none).
        jammer_to_signal_db: J/S used for weighting, dB (NaN: none).
        rejection_counts: cumulative ``((reason, count), ...)`` sorted by reason.
        reinitializations: times the filter reinitialised since start.
    """

    stamp_ns: int
    frame_id: str
    initialized: bool
    diverged: bool
    mode: int
    position_m: np.ndarray
    velocity_mps: np.ndarray
    covariance_pv: np.ndarray
    clock_bias_m: float
    clock_drift_mps: float
    satellites_used: int
    satellites_rejected: int
    uwb_used: int
    uwb_rejected: int
    normalized_innovation_squared: float
    jammer_to_signal_db: float
    rejection_counts: tuple[tuple[str, int], ...]
    reinitializations: int

    @cached_property
    def _geodetic_rad(self) -> tuple[float, float, float]:
        """(lat_rad, lon_rad, height_m) of the ECEF estimate, computed once per output (scalar path)."""
        x, y, z = self.position_m.tolist()
        return ecef_to_geodetic_scalar(x, y, z)

    @cached_property
    def geodetic(self) -> tuple[float, float, float]:
        """(latitude_deg, longitude_deg, ellipsoidal altitude_m); NaN unless an ECEF estimate."""
        if not self.initialized or self.frame_id != FRAME_EARTH:
            return (math.nan, math.nan, math.nan)
        lat, lon, h = self._geodetic_rad
        return (math.degrees(lat), math.degrees(lon), h)

    @cached_property
    def position_covariance_enu_m2(self) -> np.ndarray:
        """Position covariance in local ENU at the estimate, m^2, shape (3, 3) (NavSatFix order E, N, U).

        In "map" mode the map axes are taken as ENU and the covariance is returned unrotated.
        """
        cov = self.covariance_pv[:3, :3]
        if not self.initialized or self.frame_id != FRAME_EARTH:
            return cov.copy()
        lat, lon, _ = self._geodetic_rad
        return rotate_covariance_ecef_to_enu_scalar(cov, lat, lon)

