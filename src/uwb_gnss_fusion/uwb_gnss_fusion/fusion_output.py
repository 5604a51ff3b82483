"""What the fusion filter returns after every input: :class:`FusionOutput`.

Pure core (no rclpy). The node maps it onto nav_msgs/Odometry, sensor_msgs/NavSatFix and
rfi_msgs/FusionStatus (:mod:`.output_messages`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from gnss_common.coordinates import geodetic_and_enu_covariance_scalar

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
        motion_static: the static model runs (:mod:`.motion_model`: the stationarity detector found the
            receiver static); False: the moving (constant-velocity) model.
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
    motion_static: bool = False

    def is_finite(self) -> bool:
        """Position, velocity and their covariance all finite (compiled test, :func:`all_finite`)."""
        return all_finite(self.position_m) and all_finite(self.velocity_mps) and all_finite(self.covariance_pv)

    def _earth_fix(self) -> tuple[float, float, float, np.ndarray]:
        """(lat_rad, lon_rad, height_m, ENU position covariance) of an ECEF estimate, computed once per output
        in one compiled call (:func:`gnss_common.coordinates.geodetic_and_enu_covariance_scalar`) and kept in
        the instance (a frozen dataclass: stored through ``__dict__``, as ``functools.cached_property`` does,
        without its per-instance lock)."""
        fix = self.__dict__.get('_earth_fix_cache')
        if fix is None:
            fix = self.__dict__['_earth_fix_cache'] = geodetic_and_enu_covariance_scalar(self.position_m,
                                                                                         self.covariance_pv)
        return fix

    @property
    def geodetic(self) -> tuple[float, float, float]:
        """(latitude_deg, longitude_deg, ellipsoidal altitude_m); NaN unless an ECEF estimate."""
        if not self.initialized or self.frame_id != FRAME_EARTH:
            return (math.nan, math.nan, math.nan)
        lat, lon, h, _ = self._earth_fix()
        return (math.degrees(lat), math.degrees(lon), h)

    @property
    def position_covariance_enu_m2(self) -> np.ndarray:
        """Position covariance in local ENU at the estimate, m^2, shape (3, 3) (NavSatFix order E, N, U).

        In "map" mode the map axes are taken as ENU and the covariance is returned unrotated.
        """
        if not self.initialized or self.frame_id != FRAME_EARTH:
            return self.covariance_pv[:3, :3].copy()
        return self._earth_fix()[3].copy()


@njit(cache=True)
def all_finite(a: np.ndarray) -> bool:
    """Every element of ``a`` (any shape, float) is finite; ``np.isfinite(a).all()`` at a tenth of its cost on the
    small arrays of one output (no temporary array, no reduction call)."""
    for v in a.flat:
        if not math.isfinite(v):
            return False
    return True


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernels of an output's fix and finiteness test (a node calls it
    before it subscribes, as :func:`.ckf_kernels.warm_up`)."""
    out = FusionOutput(stamp_ns=0, frame_id=FRAME_EARTH, initialized=True, diverged=False, mode=0,
                       position_m=np.array([6.4e6, 1.0e3, 1.0e3]), velocity_mps=np.zeros(3), covariance_pv=np.eye(6),
                       clock_bias_m=0.0, clock_drift_mps=0.0, satellites_used=0, satellites_rejected=0, uwb_used=0,
                       uwb_rejected=0, normalized_innovation_squared=math.nan, jammer_to_signal_db=math.nan,
                       rejection_counts=(), reinitializations=0)
    out.is_finite()
    all_finite(out.position_covariance_enu_m2.reshape(9))
    _ = out.geodetic
