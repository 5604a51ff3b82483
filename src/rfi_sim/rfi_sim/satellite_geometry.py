"""Satellite geometry sources of the simulators: satellite states at a GPS time.

:class:`BroadcastGeometry` evaluates a real GPS broadcast ephemeris (RINEX nav, IS-GPS-200 orbits
via ``gnss_common.ephemeris``); any callable with the :data:`GeometrySource` signature may replace
it (the tests use ideal circular orbits).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gnss_common.ephemeris import EphemerisArrays, EphemerisStore, pack_ephemerides, satellite_states
from gnss_common.rinex import read_rinex_nav


@dataclass(frozen=True)
class SatelliteSnapshot:
    """Satellite states at one GPS time (rows = satellites).

    Attributes:
        prn: PRNs, shape (n,), int.
        position_ecef_m: ECEF at that time, m, shape (n, 3).
        velocity_ecef_mps: ECEF velocity, m/s, shape (n, 3).
        clock_bias_s: satellite clock offset (incl. relativistic term, minus T_GD), s, shape (n,).
        clock_drift_s_per_s: its rate, s/s, shape (n,).
    """

    prn: np.ndarray
    position_ecef_m: np.ndarray
    velocity_ecef_mps: np.ndarray
    clock_bias_s: np.ndarray
    clock_drift_s_per_s: np.ndarray


GeometrySource = Callable[[int, float], SatelliteSnapshot]
"""geometry(week, gps_tow_s) -> states of all satellites with a valid orbit at that GPS time."""


class BroadcastGeometry:
    """Geometry source from a RINEX GPS navigation file (IS-GPS-200 orbits via gnss_common).

    Args:
        nav_path: RINEX 2/3 GPS navigation file.

    Attributes:
        iono_alpha, iono_beta: Klobuchar coefficients of the file header (shape (4,)).
    """

    def __init__(self, nav_path: str | Path) -> None:
        nav = read_rinex_nav(nav_path)
        self.iono_alpha = nav.header.iono_alpha
        self.iono_beta = nav.header.iono_beta
        self._store = EphemerisStore(nav.ephemerides)
        self._cache: dict[tuple[int, ...], EphemerisArrays] = {}

    def __call__(self, week: int, tow_s: float) -> SatelliteSnapshot:
        chosen = []
        for prn in self._store.prns:
            eph, _ = self._store.select(prn, week, tow_s)
            if eph is not None:
                chosen.append(eph)
        key = tuple(id(e) for e in chosen)
        packed = self._cache.get(key)
        if packed is None:
            packed = pack_ephemerides(chosen)
            self._cache[key] = packed
        st = satellite_states(packed, week, tow_s)
        return SatelliteSnapshot(
            np.array([e.prn for e in chosen], dtype=int),
            st.position_ecef_m,
            st.velocity_ecef_mps,
            st.clock_bias_s,
            st.clock_drift_s_per_s,
        )
