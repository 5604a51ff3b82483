"""Plausibility checks of fusion_node's inputs, made before its re-ordering buffer (no rclpy here).

They are :mod:`rfi_node_common.message_checks` (moved there so that gnss_integrity_node applies the same ones:
one implementation), re-exported here under their old names; the reasons are documented there.
"""

from __future__ import annotations

from rfi_node_common.message_checks import (
    ANCHOR_ECEF_RADIUS_M,
    ANCHOR_MAP_MAX_ABS_M,
    ATMOSPHERE_DELAY_MAX_M,
    CN0_MAX_DBHZ,
    PSEUDORANGE_RATE_STD_MAX_MPS,
    PSEUDORANGE_RATE_STD_MIN_MPS,
    PSEUDORANGE_STD_MAX_M,
    PSEUDORANGE_STD_MIN_M,
    SATELLITE_CLOCK_BIAS_MAX_M,
    SATELLITE_CLOCK_DRIFT_MAX_MPS,
    SATELLITE_REASONS,
    SATELLITE_SPEED_MAX_MPS,
    UWB_RANGE_STD_MAX_M,
    UWB_RANGE_STD_MIN_M,
    UWB_REASONS,
    checked_satellites,
    satellite_reason,
    uwb_range_reason,
)

__all__ = ['ANCHOR_ECEF_RADIUS_M', 'ANCHOR_MAP_MAX_ABS_M', 'ATMOSPHERE_DELAY_MAX_M', 'CN0_MAX_DBHZ',
           'PSEUDORANGE_RATE_STD_MAX_MPS', 'PSEUDORANGE_RATE_STD_MIN_MPS', 'PSEUDORANGE_STD_MAX_M',
           'PSEUDORANGE_STD_MIN_M', 'SATELLITE_CLOCK_BIAS_MAX_M', 'SATELLITE_CLOCK_DRIFT_MAX_MPS', 'SATELLITE_REASONS',
           'SATELLITE_SPEED_MAX_MPS', 'UWB_RANGE_STD_MAX_M', 'UWB_RANGE_STD_MIN_M', 'UWB_REASONS', 'checked_satellites',
           'satellite_reason', 'uwb_range_reason']
