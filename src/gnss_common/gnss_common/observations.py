"""Plain data types for GNSS and UWB measurements, shared by simulators, converters and filters.

They mirror the rfi_msgs messages field by field (same names, same units) so that a node converts
a message into them in one line, and the pure cores never see ROS types.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

GPS = 1
GLONASS = 2
GALILEO = 3
BEIDOU = 4
QZSS = 5
SBAS = 6
"""Constellation codes, identical to rfi_msgs/GnssMeasurement constants."""


@dataclass(frozen=True)
class SatelliteObservation:
    """One satellite's measurements at one receive epoch (see rfi_msgs/GnssMeasurement.msg).

    Pseudorange model (Cao et al., eq. 5): ``pseudorange_m = rho + c dt_rx - satellite_clock_bias_m
    + ionosphere_delay_m + troposphere_delay_m + noise``, with rho the geometric range including the
    Earth-rotation correction. ``pseudorange_rate_mps = -wavelength * doppler_hz`` (positive when the
    range grows). Unknown floats are NaN.
    """

    constellation: int
    svid: int
    pseudorange_m: float
    pseudorange_rate_mps: float
    cn0_dbhz: float
    satellite_position_ecef_m: np.ndarray  # shape (3,), ECEF at transmission time
    satellite_velocity_ecef_mps: np.ndarray  # shape (3,)
    satellite_clock_bias_m: float
    satellite_clock_drift_mps: float
    ionosphere_delay_m: float = 0.0
    troposphere_delay_m: float = 0.0
    pseudorange_std_m: float = math.nan
    pseudorange_rate_std_mps: float = math.nan
    carrier_frequency_hz: float = math.nan  # carrier of the measured signal, Hz (NaN: unknown; GPS L1 assumed)


@dataclass(frozen=True)
class GnssEpoch:
    """All satellites measured at one receive epoch (see rfi_msgs/GnssMeasurementArray.msg)."""

    stamp_ns: int  # receive time, ROS (UTC) stamp, ns: gnss_common.gps_time.gps_to_ros_stamp_ns(week, tow)
    gps_week: int
    gps_time_of_week_s: float
    observations: tuple[SatelliteObservation, ...] = field(default_factory=tuple)


@dataclass(frozen=True)
class UwbRangeMeasurement:
    """One UWB two-way range (see rfi_msgs/UwbRange.msg; Cao et al., eq. 7)."""

    stamp_ns: int
    anchor_id: str
    anchor_position_m: np.ndarray  # shape (3,), in frame_id
    frame_id: str  # "earth" (ECEF) or "map" (local ENU)
    range_m: float
    range_std_m: float = math.nan
