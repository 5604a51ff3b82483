"""Physical and system constants, each with its unit and source.

This is the one place constants live; every package imports them from here.
"""

import math

NS_PER_S = 1_000_000_000
"""Nanoseconds per second (ROS stamps are integer ns)."""

TWO_PI = 2.0 * math.pi
"""One cycle, rad."""

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

# ----------------------------------------------------------------------------------------------
# Multi-GNSS: carrier frequencies, the constants each system's broadcast ephemeris is defined
# with, and the offsets between the system time scales.

GALILEO_E1_FREQUENCY_HZ = 1_575.42e6
"""Galileo E1 carrier frequency, Hz (Galileo OS SIS ICD 2.0, 2.2.1)."""

GALILEO_E5A_FREQUENCY_HZ = 1_176.45e6
"""Galileo E5a carrier frequency, Hz (Galileo OS SIS ICD 2.0, 2.2.1)."""

GALILEO_E5B_FREQUENCY_HZ = 1_207.14e6
"""Galileo E5b carrier frequency, Hz (Galileo OS SIS ICD 2.0, 2.2.1)."""

BEIDOU_B1I_FREQUENCY_HZ = 1_561.098e6
"""BeiDou B1I carrier frequency, Hz (BDS-SIS-ICD-B1I-3.0, 4.2)."""

GPS_L5_FREQUENCY_HZ = 1_176.45e6
"""GPS (and QZSS) L5 carrier frequency, Hz (IS-GPS-705, 3.3.1.1)."""

GLONASS_G1_BASE_FREQUENCY_HZ = 1_602.0e6
"""GLONASS G1 FDMA carrier of channel k = 0, Hz (GLONASS ICD 5.1, 3.3.1.4)."""

GLONASS_G1_CHANNEL_SPACING_HZ = 0.5625e6
"""GLONASS G1 FDMA channel spacing, Hz: f = 1602 MHz + k 0.5625 MHz (GLONASS ICD 5.1, 3.3.1.4)."""

GLONASS_G2_BASE_FREQUENCY_HZ = 1_246.0e6
"""GLONASS G2 FDMA carrier of channel k = 0, Hz (GLONASS ICD 5.1, 3.3.1.4)."""

GLONASS_G2_CHANNEL_SPACING_HZ = 0.4375e6
"""GLONASS G2 FDMA channel spacing, Hz: f = 1246 MHz + k 0.4375 MHz (GLONASS ICD 5.1, 3.3.1.4)."""

GLONASS_MIN_CHANNEL = -7
"""Lowest GLONASS FDMA frequency channel number k (GLONASS ICD 5.1, 3.3.1.4)."""

GLONASS_MAX_CHANNEL = 13
"""Highest GLONASS FDMA frequency channel number k (ICD 5.1 allows up to +13; +7 in use since 2005)."""

GALILEO_GM_M3PS2 = 3.986004418e14
"""Earth's gravitational constant of the Galileo ephemeris, m^3/s^2 (Galileo OS SIS ICD 2.0, 5.1.1)."""

GALILEO_EARTH_ROTATION_RATE_RADPS = 7.2921151467e-5
"""Earth's rotation rate of the Galileo ephemeris, rad/s (Galileo OS SIS ICD 2.0, 5.1.1)."""

BEIDOU_GM_M3PS2 = 3.986004418e14
"""Earth's gravitational constant of CGCS2000 for the BeiDou ephemeris, m^3/s^2 (BDS-SIS-ICD-B1I-3.0, 5.2.4.10)."""

BEIDOU_EARTH_ROTATION_RATE_RADPS = 7.2921150e-5
"""Earth's rotation rate of CGCS2000 for the BeiDou ephemeris, rad/s (BDS-SIS-ICD-B1I-3.0, 5.2.4.10)."""

RELATIVISTIC_F_GALILEO_BEIDOU_S_PER_SQRT_M = -4.442807309e-10
"""F = -2 sqrt(mu)/c^2 with mu = 3.986004418e14, s/m^(1/2) (Galileo OS SIS ICD 2.0, 5.1.4)."""

GLONASS_GM_M3PS2 = 3.9860044e14
"""Earth's gravitational constant of PZ-90 for the GLONASS orbit, m^3/s^2 (GLONASS ICD 5.1, 3.1.3)."""

GLONASS_EARTH_ROTATION_RATE_RADPS = 7.292115e-5
"""Earth's rotation rate of PZ-90, rad/s (GLONASS ICD 5.1, 3.1.3)."""

GLONASS_SEMI_MAJOR_AXIS_M = 6_378_136.0
"""Semi-major axis of the PZ-90 ellipsoid, m (GLONASS ICD 5.1, 3.1.3)."""

GLONASS_J2 = 1.08262575e-3
"""Second zonal harmonic J2^0 of the PZ-90 geopotential, dimensionless (GLONASS ICD 5.1, 3.1.3)."""

BEIDOU_MINUS_GPS_TIME_S = -14.0
"""BDT - GPST, s: BDT started 2006-01-01 00:00:00 UTC, when GPST - UTC was 14 s (BDS-SIS-ICD-B1I-3.0, 4.3)."""

BEIDOU_WEEK_OFFSET = 1356
"""GPS week of the BDT week 0 start (2006-01-01): GPS week = BDT week + 1356 (BDS-SIS-ICD-B1I-3.0, 4.3)."""

GLONASS_MINUS_UTC_S = 10_800.0
"""GLONASS time - UTC, s: Moscow time UTC(SU) + 3 h (GLONASS ICD 5.1, 3.3.3)."""
