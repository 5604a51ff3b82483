"""Physical and system constants, each with its unit and source.

This is the one place constants live; every package imports them from here.
"""

SPEED_OF_LIGHT_MPS = 299_792_458.0
"""Speed of light in vacuum, m/s (IS-GPS-200, 20.3.4.3)."""

GPS_L1_FREQUENCY_HZ = 1_575.42e6
"""GPS L1 carrier frequency, Hz (IS-GPS-200, 3.3.1.1)."""

GPS_L2_FREQUENCY_HZ = 1_227.60e6
"""GPS L2 carrier frequency, Hz (IS-GPS-200, 3.3.1.1)."""

GPS_L1_WAVELENGTH_M = SPEED_OF_LIGHT_MPS / GPS_L1_FREQUENCY_HZ
"""GPS L1 carrier wavelength, m."""

GPS_CA_CHIP_RATE_HZ = 1.023e6
"""GPS C/A code chipping rate, chip/s (IS-GPS-200, 3.3.2.3)."""

GPS_CA_CODE_LENGTH_CHIPS = 1023
"""GPS C/A code length, chips (IS-GPS-200, 3.3.2.3)."""

GPS_NAV_BIT_RATE_HZ = 50.0
"""GPS LNAV navigation data rate, bit/s (IS-GPS-200, 20.3.2)."""

EARTH_ROTATION_RATE_RADPS = 7.2921151467e-5
"""WGS 84 value of the Earth's rotation rate, rad/s (IS-GPS-200, 20.3.3.4.3.3)."""

EARTH_GM_M3PS2 = 3.986005e14
"""WGS 84 value of the Earth's gravitational constant for GPS user, m^3/s^2 (IS-GPS-200, 20.3.3.4.3.3)."""

RELATIVISTIC_F_S_PER_SQRT_M = -4.442807633e-10
"""Relativistic clock correction constant F = -2 sqrt(mu)/c^2, s/m^(1/2) (IS-GPS-200, 20.3.3.3.3.1)."""

WGS84_SEMI_MAJOR_AXIS_M = 6_378_137.0
"""WGS 84 ellipsoid semi-major axis a, m (NIMA TR8350.2)."""

WGS84_FLATTENING = 1.0 / 298.257223563
"""WGS 84 ellipsoid flattening f, dimensionless (NIMA TR8350.2)."""

WGS84_ECCENTRICITY_SQUARED = WGS84_FLATTENING * (2.0 - WGS84_FLATTENING)
"""WGS 84 first eccentricity squared e^2 = f (2 - f), dimensionless."""

BOLTZMANN_DBW_PER_K_HZ = -228.6
"""Boltzmann's constant, dBW/(K Hz) (Kaplan & Hegarty, 3rd ed.)."""

THERMAL_NOISE_DENSITY_DBM_PER_HZ = -174.0
"""Thermal noise density kT at 290 K, dBm/Hz (Kaplan & Hegarty, 3rd ed.)."""

SECONDS_PER_WEEK = 604_800.0
"""Seconds in a GPS week, s."""

GPS_EPOCH_UNIX_S = 315_964_800
"""The GPS epoch 1980-01-06 00:00:00 UTC as a Unix time, s (IS-GPS-200, 3.3.4)."""

# GPS - UTC leap seconds are not a constant: the one table, with its source and validity, is
# gnss_common.gps_time.LEAP_SECONDS (leap_seconds_at_gps, gps_to_ros_stamp_ns).
