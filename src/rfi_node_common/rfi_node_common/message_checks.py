"""Plausibility checks of the nodes' GNSS and UWB inputs, made before their cores (no rclpy here).

Shared by fusion_node and gnss_integrity_node: one implementation of what a corrupt or malicious field is. The
fusion's core validates what it applies and counts each rejection (``nonfinite_pseudorange``,
``nonphysical_satellite_position``, ``nonphysical_pseudorange``, ``low_cn0``, ``invalid_doppler``;
``nonfinite_anchor_position``, ``nonfinite_range``, ``negative_range``, ``nonphysical_range`` beyond its
``uwb_max_range_m``, ``nonphysical_range_std``). Some values it does not check would be applied as if valid, and the
integrity monitor checks none, so the nodes check them first and count them under their own reasons:

* A UWB range (:func:`uwb_range_reason`, every check of a range that needs no parameter, so that both nodes apply
  the same limits; the range is rejected):

  - ``range_std_m``: only NaN means "use the default" (the fusion's ``uwb_range_std_m``, the integrity
    monitor's ``uwb_std_m``); any other value must be finite, >= :data:`UWB_RANGE_STD_MIN_M` and at most
    :data:`UWB_RANGE_STD_MAX_M` (``invalid_range_std``). The cores took -inf (and +inf) as "use the default", and
    the integrity monitor squared 1e300 into an OverflowError.
  - the anchor position: not finite (``nonfinite_anchor_position``), or finite but off the Earth (ECEF) or beyond
    any local survey (map frame) (``nonphysical_anchor_position``): the cores would multilaterate from it.
  - ``range_m``: not finite (``nonfinite_range``), negative (``negative_range``), below :data:`UWB_RANGE_MIN_M`
    (``range_too_short``) or above :data:`UWB_RANGE_MAX_M` (``range_too_long``). The fusion's core took a range of
    5e-324 m as valid and counted 1e300 m only against its ``uwb_max_range_m``; the integrity monitor's residuals
    went infinite on both.

* Per satellite of a GNSS epoch (the satellite is dropped, the rest of the epoch is used):
  a C/N0 of +-inf or above :data:`CN0_MAX_DBHZ` (``nonphysical_cn0``; NaN = not reported, the core
  uses the nominal C/N0), a pseudorange or rate 1-sigma that is not NaN and not in (min, max]
  (``invalid_measurement_std``; the fusion took <= 0 and inf as "decide from C/N0", a 5e-324 squared to 0 made a
  noise matrix singular or divided by zero), a satellite
  velocity, clock bias or clock drift that is finite but physically impossible
  (``nonphysical_satellite_state``), a finite ionosphere or troposphere delay above
  :data:`ATMOSPHERE_DELAY_MAX_M` (``nonphysical_atmospheric_delay``).

The bounds are generous (10-1000x what GPS, GLONASS, Galileo and BeiDou produce) so that they only
catch corrupt or malicious values. Non-finite satellite values stay with the cores: in the fusion a non-finite
clock bias, delay, pseudorange or satellite position drops the satellite (``nonfinite_pseudorange``), a
non-finite velocity or clock drift drops its Doppler (``invalid_doppler``; NaN is "unknown" there).
"""

from __future__ import annotations

import math

from gnss_common.observations import SatelliteObservation, UwbRangeMeasurement

FRAME_EARTH = 'earth'
"""The core frame of ECEF anchors (REP 105 ``earth``; a node maps its ``earth_frame_id`` parameter to it)."""

UWB_RANGE_STD_MAX_M = 100.0
"""Largest UWB range 1-sigma accepted, m (the upper bound of the uwb_range_std_m parameter)."""
UWB_RANGE_STD_MIN_M = 1.0e-6
"""Smallest UWB range 1-sigma accepted, m: no ranging hardware knows a range to a micrometre (two-way UWB: a few
centimetres); a smaller stated 1-sigma is a corrupt field (the fuzzer's 5e-324 squared to 0 in the noise estimate)."""

ANCHOR_ECEF_RADIUS_M = (6.0e6, 7.0e6)
"""Geocentric distance of an anchor given in ECEF, m: from 370 km below the WGS 84 polar radius to
620 km above the equatorial radius (every surveyed point on Earth or in its atmosphere)."""

ANCHOR_MAP_MAX_ABS_M = 1.0e7
"""Largest coordinate of an anchor in the local (map) frame, m (larger than any local frame,
UTM-like offsets included)."""

CN0_MAX_DBHZ = 100.0
"""Largest C/N0 accepted, dB-Hz (open-sky GNSS signals reach about 55 dB-Hz)."""

PSEUDORANGE_STD_MAX_M = 1.0e4
"""Largest pseudorange 1-sigma accepted, m."""

PSEUDORANGE_RATE_STD_MAX_MPS = 1.0e3
"""Largest pseudorange-rate 1-sigma accepted, m/s."""

PSEUDORANGE_STD_MIN_M = 1.0e-3
"""Smallest pseudorange 1-sigma accepted, m: code ranging is not known to a millimetre (receivers report decimetres to
metres); a smaller one is a corrupt field (the fuzzer's 5e-324 squared to 0 and made the update's noise matrix
singular, a counted core exception)."""

PSEUDORANGE_RATE_STD_MIN_MPS = 1.0e-4
"""Smallest pseudorange-rate 1-sigma accepted, m/s (a tenth of a millimetre per second: below any receiver's Doppler
noise; a smaller one is a corrupt field, as above)."""

SATELLITE_SPEED_MAX_MPS = 1.0e4
"""Largest ECEF satellite speed accepted, m/s (MEO satellites move at about 3-4 km/s in ECEF)."""

SATELLITE_CLOCK_BIAS_MAX_M = 1.0e8
"""Largest |c * satellite clock offset| accepted, m: the broadcast a_f0 spans +-1.95 ms for GPS
(IS-GPS-200 Table 20-III) but +-62.5 ms = 1.9e7 m for Galileo (OS SIS ICD Table 52); real Galileo
satellites sit at several ms (E09 at 6.0 ms = 1.8e6 m on 2020-06-25)."""

SATELLITE_CLOCK_DRIFT_MAX_MPS = 1.0e3
"""Largest |c * satellite clock drift| accepted, m/s (broadcast drifts are below 0.01 m/s)."""

ATMOSPHERE_DELAY_MAX_M = 1.0e3
"""Largest modelled ionosphere or troposphere delay accepted, m (slant delays stay below ~150 m)."""

UWB_RANGE_MAX_M = 1.0e4
"""Longest UWB range accepted, m: two-way UWB reaches a few hundred metres; a longer finite range is a corrupt field
(the fuzzer's 1e300 made the integrity monitor's residuals infinite, a counted core exception on every epoch until the
anchor was heard again). The fusion's ``uwb_max_range_m`` (500 m by default) rejects shorter ones in its core; set
above this limit, it has no effect beyond it."""

UWB_RANGE_MIN_M = 1.0e-3
"""Shortest UWB range accepted, m: a tag is never within a millimetre of an anchor's antenna; the fuzzer's 5e-324
made the integrity monitor's second-order residual variance (|delta_perp|^2 / (2 r)) infinite, and the fusion's
core applied it as a valid range."""

UWB_REASONS = ('invalid_range_std', 'nonfinite_anchor_position', 'nonphysical_anchor_position', 'nonfinite_range',
               'negative_range', 'range_too_short', 'range_too_long')
"""Reasons of :func:`uwb_range_reason`, in the order it checks them."""

SATELLITE_REASONS = ('nonphysical_cn0', 'invalid_measurement_std', 'nonphysical_satellite_state',
                     'nonphysical_atmospheric_delay')
"""Reasons of :func:`satellite_reason`."""


def _std_ok(value: float, maximum: float, minimum: float = 0.0) -> bool:
    """NaN (unknown: the filter decides) or a finite value in (minimum, maximum] (minimum >= 0)."""
    return math.isnan(value) or minimum < value <= maximum


def _finite_above(value: float, maximum: float) -> bool:
    """A finite value with |value| > maximum (non-finite values are the core's to count)."""
    return math.isfinite(value) and abs(value) > maximum


def uwb_range_reason(meas: UwbRangeMeasurement) -> str | None:
    """Why the node must reject this UWB range before the core, or None.

    Args:
        meas: the range; ``frame_id`` is the core's frame ("earth": ECEF anchor, "map": local),
            ``anchor_position_m`` m (3,), ``range_m`` m, ``range_std_m`` m.

    Returns:
        The first of :data:`UWB_REASONS` that applies, or None (the fusion's core checks its own
        ``uwb_max_range_m``).

    Examples:
        >>> import numpy as np
        >>> m = UwbRangeMeasurement(1, 'A1', np.array([1.0, 2.0, 3.0]), 'map', 5.0, -math.inf)
        >>> uwb_range_reason(m)
        'invalid_range_std'
        >>> uwb_range_reason(UwbRangeMeasurement(1, 'A1', np.array([1.0, 2.0, 3.0]), 'map', 1e300, math.nan))
        'range_too_long'
    """
    if not _std_ok(float(meas.range_std_m), UWB_RANGE_STD_MAX_M, UWB_RANGE_STD_MIN_M):
        return 'invalid_range_std'
    x, y, z = (float(v) for v in meas.anchor_position_m)
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return 'nonfinite_anchor_position'
    if meas.frame_id == FRAME_EARTH:
        lo, hi = ANCHOR_ECEF_RADIUS_M
        if not lo <= math.sqrt(x * x + y * y + z * z) <= hi:  # inf for a huge finite one
            return 'nonphysical_anchor_position'
    elif max(abs(x), abs(y), abs(z)) > ANCHOR_MAP_MAX_ABS_M:
        return 'nonphysical_anchor_position'
    range_m = float(meas.range_m)
    if not math.isfinite(range_m):
        return 'nonfinite_range'
    if range_m < 0.0:
        return 'negative_range'
    if range_m < UWB_RANGE_MIN_M:
        return 'range_too_short'
    if range_m > UWB_RANGE_MAX_M:
        return 'range_too_long'
    return None


def satellite_reason(obs: SatelliteObservation) -> str | None:
    """Why the node must drop this satellite before the core, or None.

    Args:
        obs: one satellite of an epoch (fields in the units of their names).

    Returns:
        One of :data:`SATELLITE_REASONS` (the first that applies, in that order), or None.
    """
    cn0 = float(obs.cn0_dbhz)
    if not (math.isnan(cn0) or (math.isfinite(cn0) and cn0 <= CN0_MAX_DBHZ)):
        return 'nonphysical_cn0'
    if not (_std_ok(float(obs.pseudorange_std_m), PSEUDORANGE_STD_MAX_M, PSEUDORANGE_STD_MIN_M)
            and _std_ok(float(obs.pseudorange_rate_std_mps), PSEUDORANGE_RATE_STD_MAX_MPS,
                        PSEUDORANGE_RATE_STD_MIN_MPS)):
        return 'invalid_measurement_std'
    vx, vy, vz = (float(v) for v in obs.satellite_velocity_ecef_mps)
    if math.isfinite(vx) and math.isfinite(vy) and math.isfinite(vz):
        if not math.sqrt(vx * vx + vy * vy + vz * vz) <= SATELLITE_SPEED_MAX_MPS:  # inf for a huge finite one
            return 'nonphysical_satellite_state'
    if _finite_above(float(obs.satellite_clock_bias_m), SATELLITE_CLOCK_BIAS_MAX_M) or _finite_above(
            float(obs.satellite_clock_drift_mps), SATELLITE_CLOCK_DRIFT_MAX_MPS):
        return 'nonphysical_satellite_state'
    if _finite_above(float(obs.ionosphere_delay_m), ATMOSPHERE_DELAY_MAX_M) or _finite_above(
            float(obs.troposphere_delay_m), ATMOSPHERE_DELAY_MAX_M):
        return 'nonphysical_atmospheric_delay'
    return None


def checked_satellites(observations: list[SatelliteObservation]
                       ) -> tuple[list[SatelliteObservation], dict[str, int], int]:
    """An epoch's satellites sorted out: those to apply, those dropped per reason (:func:`satellite_reason`),
    and how many have no state (no satellite position: no ephemeris yet, a receiver stream without
    navigation data; expected, not a degraded input, counted apart and never applied)."""
    kept = []
    dropped: dict[str, int] = {}
    stateless = 0
    for obs in observations:
        if not any(math.isfinite(float(v)) for v in obs.satellite_position_ecef_m):
            stateless += 1
            continue
        reason = satellite_reason(obs)
        if reason is None:
            kept.append(obs)
        else:
            dropped[reason] = dropped.get(reason, 0) + 1
    return kept, dropped, stateless
