"""Exact measurements of a fixed synthetic sky: the oracle input of positioning tests.

Pure, deterministic, no file: a receiver at a known ECEF position and velocity with a known clock
sees satellites at given (azimuth, elevation), each 26,560 km from the Earth's centre, and gets
noise-free pseudoranges and pseudorange rates by Cao et al., eq. 5 and 6, with the Earth's rotation
during the signal's flight (Sagnac) done exactly by light-time iteration. Tests of the single-point
solution (``gnss_common.spp``), the fusion's SPP reference and ``gnss_integrity`` use it: any solver
must recover the truth to numerical precision, and any injected error is the only error.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from gnss_common.constants import EARTH_ROTATION_RATE_RADPS, SPEED_OF_LIGHT_MPS
from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic
from gnss_common.earth_rotation import rotate_about_z
from gnss_common.observations import GPS, GnssEpoch, SatelliteObservation

RECEIVER_ECEF_M = np.array([-740289.918, -5457071.734, 3207245.542])
"""Default receiver: the ARL1 station's header position, ECEF, m."""
RECEIVER_VELOCITY_ECEF_MPS = np.array([3.0, -2.0, 0.5])
"""Default receiver velocity, ECEF, m/s."""
CLOCK_BIAS_M = 12345.678
"""Default receiver clock bias c dt_r, m."""
CLOCK_DRIFT_MPS = -45.6
"""Default receiver clock drift c ddt_r, m/s."""
SKY_AZ_EL_DEG = ((0, 80), (40, 35), (95, 60), (140, 20), (185, 45), (230, 15), (275, 55), (320, 25), (10, 12))
"""Default sky: (azimuth, elevation) of nine satellites, deg."""
STAMP_NS = 1_437_263_983_000_000_000
"""Default stamp: ROS (UTC) time of GPS week 1854, time of week 0, ns."""
ORBIT_RADIUS_M = 2.656e7
"""Distance of every synthetic satellite from the Earth's centre, m."""


def _r3(vector: np.ndarray, angle_rad: float) -> np.ndarray:
    """R3(angle) applied to one ECEF vector, shape (3,)."""
    return rotate_about_z(np.asarray(vector, dtype=float)[None, :], np.array([math.cos(angle_rad)]),
                          np.array([math.sin(angle_rad)]))[0]


def synthetic_epoch(
    sky: Sequence[tuple[float, float]] = SKY_AZ_EL_DEG,
    noise_m: Sequence[float] | None = None,
    svids: Sequence[int] | None = None,
    std_m: float = math.nan,
    cn0: float | Sequence[float] = 45.0,
    receiver_ecef_m: np.ndarray = RECEIVER_ECEF_M,
    receiver_velocity_ecef_mps: np.ndarray = RECEIVER_VELOCITY_ECEF_MPS,
    clock_bias_m: float = CLOCK_BIAS_M,
    clock_drift_mps: float = CLOCK_DRIFT_MPS,
    stamp_ns: int = STAMP_NS,
    gps_time_of_week_s: float = 0.0,
    constellations: Sequence[int] | None = None,
    clock_offsets_m: dict[int, float] | None = None,
) -> GnssEpoch:
    """One receive epoch of exact measurements.

    Args:
        sky: (azimuth deg from north, elevation deg) per satellite, seen from the receiver.
        noise_m: error added to each pseudorange, m (None: none).
        svids: satellite numbers (None: 1, 2, ...).
        std_m: ``pseudorange_std_m`` written into each measurement, m (NaN: unknown).
        cn0: C/N0 of every satellite, or one per satellite, dB-Hz.
        receiver_ecef_m, receiver_velocity_ecef_mps: receiver state, ECEF, m and m/s, shape (3,).
        clock_bias_m, clock_drift_mps: receiver clock c dt_r (m) and c ddt_r (m/s).
        stamp_ns, gps_time_of_week_s: the epoch's ROS stamp (ns) and GPS time of week (s),
            week 1854.
        constellations: constellation code per satellite (None: all GPS).
        clock_offsets_m: extra clock bias per constellation (an inter-system bias), m.

    Returns:
        :class:`GnssEpoch` whose pseudorange is ``|R3(w tau) p_s - p_r| + c dt_r (+ ISB) - c dt_s + I
        + T (+ noise)`` exactly (Cao et al., eq. 5; eq. 6 for the rate), satellite positions and
        velocities in the ECEF frame of transmission time.
    """
    rx = np.asarray(receiver_ecef_m, dtype=float)
    v_rx = np.asarray(receiver_velocity_ecef_mps, dtype=float)
    lat, lon, _ = ecef_to_geodetic(rx)
    r_enu = ecef_to_enu_rotation(lat, lon)
    cn0s = [float(cn0)] * len(sky) if np.isscalar(cn0) else [float(c) for c in cn0]  # type: ignore[union-attr, arg-type]
    obs = []
    for k, (az, el) in enumerate(sky):
        a, e = math.radians(az), math.radians(el)
        u = r_enu.T @ np.array([math.sin(a) * math.cos(e), math.cos(a) * math.cos(e), math.sin(e)])
        b = rx @ u
        d = -b + math.sqrt(b * b - rx @ rx + ORBIT_RADIUS_M**2)
        sat_rx = rx + d * u  # receive-time ECEF frame
        tau = d / SPEED_OF_LIGHT_MPS
        for _ in range(3):
            sat_tx = _r3(sat_rx, -EARTH_ROTATION_RATE_RADPS * tau)  # transmit-time ECEF frame
            back = _r3(sat_tx, EARTH_ROTATION_RATE_RADPS * tau)
            tau = float(np.linalg.norm(back - rx)) / SPEED_OF_LIGHT_MPS
        rng = float(np.linalg.norm(sat_rx - rx))
        v_sat_tx = np.cross(u, [0.0, 0.0, 1.0]) * 3000.0 + np.array([100.0, -50.0, 10.0]) * k
        v_sat_rx = _r3(v_sat_tx, EARTH_ROTATION_RATE_RADPS * tau)
        los = (sat_rx - rx) / rng
        sat_clock_m, sat_drift = 1000.0 * k, 0.01 * k
        iono, tropo = 3.0 + 0.1 * k, 2.5 / max(math.sin(e), 0.1)
        system = GPS if constellations is None else int(constellations[k])
        isb = 0.0 if clock_offsets_m is None else float(clock_offsets_m.get(system, 0.0))
        pr = rng + clock_bias_m + isb - sat_clock_m + iono + tropo
        if noise_m is not None:
            pr += float(noise_m[k])
        rate = float((v_sat_rx - v_rx) @ los) + clock_drift_mps - sat_drift
        obs.append(
            SatelliteObservation(
                constellation=system,
                svid=(int(svids[k]) if svids else k + 1),
                pseudorange_m=pr,
                pseudorange_rate_mps=rate,
                cn0_dbhz=cn0s[k],
                satellite_position_ecef_m=np.asarray(sat_tx, dtype=float),
                satellite_velocity_ecef_mps=v_sat_tx,
                satellite_clock_bias_m=sat_clock_m,
                satellite_clock_drift_mps=sat_drift,
                ionosphere_delay_m=iono,
                troposphere_delay_m=tropo,
                pseudorange_std_m=std_m,
            )
        )
    return GnssEpoch(stamp_ns=int(stamp_ns), gps_week=1854, gps_time_of_week_s=float(gps_time_of_week_s),
                     observations=tuple(obs))
