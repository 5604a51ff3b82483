"""One epoch's C/N0 per satellite as the C/N0 tests take it, its clean references, the signal bands.

Pure (no rclpy, no rfi_msgs). :class:`Cn0Epoch` is built by the node from a GnssMeasurementArray
(constellation, svid, cn0_dbhz, carrier_frequency_hz per measurement; elevations from the satellite
states and the receiver position, NaN when either is missing) or, in tests, from a
:class:`gnss_common.observations.GnssEpoch`. :class:`Cn0Reference` is what
:meth:`gnss_integrity.cn0_model.Cn0Models.reference` returns for it and every C/N0 test reads.
"""

from __future__ import annotations

from dataclasses import dataclass
from operator import attrgetter

import numpy as np

from gnss_common.constants import (
    BEIDOU_B1I_FREQUENCY_HZ,
    GALILEO_E5B_FREQUENCY_HZ,
    GLONASS_G1_BASE_FREQUENCY_HZ,
    GLONASS_G2_BASE_FREQUENCY_HZ,
    GPS_L1_FREQUENCY_HZ,
    GPS_L2_FREQUENCY_HZ,
    GPS_L5_FREQUENCY_HZ,
)
from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic_scalar
from gnss_common.observations import BEIDOU, GLONASS, GnssEpoch

BANDS = (
    ("L1", GPS_L1_FREQUENCY_HZ), ("B1I", BEIDOU_B1I_FREQUENCY_HZ), ("G1", GLONASS_G1_BASE_FREQUENCY_HZ),
    ("L2", GPS_L2_FREQUENCY_HZ), ("G2", GLONASS_G2_BASE_FREQUENCY_HZ), ("L5", GPS_L5_FREQUENCY_HZ),
    ("E5b", GALILEO_E5B_FREQUENCY_HZ), ("E6", 1_278.75e6), ("B3I", 1_268.52e6), ("E5", 1_191.795e6),
)
"""Signal bands (name, centre Hz) the models key on; GLONASS FDMA channels (+-4 MHz) share G1 / G2,
E1 / B1C / L1 share L1, E5a / B2a share L5. Any other carrier is band ``other``."""
BAND_NAMES = tuple(b[0] for b in BANDS) + ("other",)
N_BANDS = len(BAND_NAMES)
BAND_TOLERANCE_HZ = 5.0e6
N_CONSTELLATION_CODES = 8  # rfi_msgs/GnssMeasurement codes 0..7
_BAND_CENTRES_HZ = np.array([b[1] for b in BANDS])
_DEFAULT_BAND = np.zeros(N_CONSTELLATION_CODES, dtype=np.int64)  # NaN carrier: GPS L1 assumed (message)
_DEFAULT_BAND[GLONASS] = 2
_DEFAULT_BAND[BEIDOU] = 1  # B1I, the signal gnss_common.measurements builds
_FIELDS = attrgetter("constellation", "svid", "cn0_dbhz", "carrier_frequency_hz")

def signal_band(constellation: np.ndarray, carrier_frequency_hz: np.ndarray) -> np.ndarray:
    """Band index (into :data:`BAND_NAMES`) of each signal; a NaN carrier is the constellation's
    primary signal (GPS/Galileo/QZSS/SBAS L1, GLONASS G1, BeiDou B1I)."""
    const = np.clip(np.asarray(constellation, dtype=np.int64), 0, N_CONSTELLATION_CODES - 1)
    f = np.asarray(carrier_frequency_hz, dtype=float)
    dist = np.abs(f[:, None] - _BAND_CENTRES_HZ[None, :])
    nearest = np.argmin(np.where(np.isnan(dist), np.inf, dist), axis=1)
    near = np.take_along_axis(dist, nearest[:, None], axis=1)[:, 0] <= BAND_TOLERANCE_HZ
    band = np.where(near, nearest, N_BANDS - 1)
    return np.where(np.isnan(f), _DEFAULT_BAND[const], band)


@dataclass(frozen=True)
class Cn0Epoch:
    """One epoch's C/N0 per satellite (rows = signals).

    Attributes:
        stamp_ns: receive time, ns (ROS time of the epoch's header; never the wall clock).
        constellation: rfi_msgs/GnssMeasurement constellation codes, int, shape (n,).
        svid: satellite numbers, int, shape (n,).
        cn0_dbhz: C/N0, dB-Hz, shape (n,) (NaN: not reported).
        elevation_rad: elevation, rad, shape (n,) (NaN: unknown, e.g. no ephemeris).
        carrier_frequency_hz: carrier of each signal, Hz, shape (n,) (NaN: the primary signal).
    """

    stamp_ns: int
    constellation: np.ndarray
    svid: np.ndarray
    cn0_dbhz: np.ndarray
    elevation_rad: np.ndarray
    carrier_frequency_hz: np.ndarray

    @classmethod
    def from_arrays(cls, stamp_ns: int, constellation, svid, cn0_dbhz, elevation_rad=None,
                    carrier_frequency_hz=None) -> Cn0Epoch:
        """Validated epoch; missing elevations / carriers are NaN."""
        c = np.asarray(constellation, dtype=np.int64).ravel()
        n = c.size
        el = np.full(n, np.nan) if elevation_rad is None else np.asarray(elevation_rad, float).ravel()
        fc = np.full(n, np.nan) if carrier_frequency_hz is None else np.asarray(carrier_frequency_hz, float).ravel()
        out = cls(int(stamp_ns), c, np.asarray(svid, dtype=np.int64).ravel(),
                  np.asarray(cn0_dbhz, dtype=float).ravel(), el, fc)
        if not (out.svid.size == out.cn0_dbhz.size == el.size == fc.size == n):
            raise ValueError("constellation, svid, cn0_dbhz, elevation_rad, carrier_frequency_hz: equal lengths")
        return out

    @classmethod
    def from_gnss_epoch(cls, epoch: GnssEpoch, receiver_ecef_m: np.ndarray | None) -> Cn0Epoch:
        """From a :class:`GnssEpoch`; elevations from ``receiver_ecef_m`` (None or NaN: unknown), those of
        ``coordinates.azimuth_elevation`` (line of sight rotated to ENU at the receiver)."""
        obs = epoch.observations
        n = len(obs)
        el = np.full(n, np.nan)
        rx = None if receiver_ecef_m is None else np.asarray(receiver_ecef_m, dtype=float).reshape(3)
        if obs and rx is not None and np.all(np.isfinite(rx)):
            sats = np.array([o.satellite_position_ecef_m for o in obs], dtype=float).reshape(-1, 3)
            ok = np.all(np.isfinite(sats), axis=1)
            if ok.any():
                lat, lon, _ = ecef_to_geodetic_scalar(*rx.tolist())
                enu = (sats[ok] - rx) @ ecef_to_enu_rotation(lat, lon).T
                el[ok] = np.arctan2(enu[:, 2], np.hypot(enu[:, 0], enu[:, 1]))
        fields = list(map(_FIELDS, obs))
        return cls(int(epoch.stamp_ns), np.array([f[0] for f in fields], dtype=np.int64),
                   np.array([f[1] for f in fields], dtype=np.int64), np.array([f[2] for f in fields], dtype=float),
                   el, np.array([f[3] for f in fields], dtype=float))


@dataclass(frozen=True)
class Cn0Reference:
    """The clean references of one epoch's satellites (from ``Cn0Models.reference``).

    Attributes:
        epoch: the epoch.
        slots: satellite-signal slot of each row (internal index), shape (n,).
        valid: rows with a usable C/N0, shape (n,).
        elevation_expected_dbhz, elevation_std_db: elevation model + satellite offset and the
            residual 1-sigma, per row (NaN: elevation unknown or model not learned there).
        level_expected_dbhz, level_std_db: the satellite's recent clean level and its 1-sigma (NaN:
            none usable).
        elevation_model_in_use: the elevation model judges this epoch (else the satellite levels).
        expected_dbhz, std_db: the reference in use, per row (NaN: none).
        lost_constellation, lost_svid, lost_cn0_dbhz, lost_elevation_rad: satellites tracked in the
            last clean epochs but missing now, with their last clean C/N0 and elevation.
        model_state: ``cn0_model.MODEL_*``.
        node_index: internal (lower node, upper node, upper node's tent weight) of each row.
    """

    epoch: Cn0Epoch
    slots: np.ndarray
    valid: np.ndarray
    elevation_expected_dbhz: np.ndarray
    elevation_std_db: np.ndarray
    level_expected_dbhz: np.ndarray
    level_std_db: np.ndarray
    elevation_model_in_use: bool
    expected_dbhz: np.ndarray
    std_db: np.ndarray
    lost_constellation: np.ndarray
    lost_svid: np.ndarray
    lost_cn0_dbhz: np.ndarray
    lost_elevation_rad: np.ndarray
    model_state: int
    node_index: tuple[np.ndarray, np.ndarray, np.ndarray]
