"""Input checks of the fusion filter: which satellites and UWB ranges it may apply.

Pure core (no rclpy). Each check counts a rejected input under its first failing reason through
the ``count(reason, n)`` callable it is given (the filter's cumulative rejection counts), so that
nothing is dropped unseen. The node's own message checks (:mod:`rfi_node_common.message_checks`) run before these.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from gnss_common.observations import (
    BEIDOU,
    GALILEO,
    GLONASS,
    GPS,
    QZSS,
    SBAS,
    SatelliteObservation,
    UwbRangeMeasurement,
)

from .fusion_params import FRAME_EARTH, FRAME_MAP, FusionParams

Count = Callable[[str, int], None]
"""count(reason, n): add n to the cumulative count of ``reason``."""

SatelliteRow = tuple[SatelliteObservation, np.ndarray, np.ndarray, bool]
"""(observation, position (3,) m, velocity (3,) m/s, pseudorange rate usable)."""


@dataclass
class PreparedEpoch:
    """The validated satellites of one epoch with their 1-sigmas, as arrays (k satellites).

    Attributes:
        sat_pos: satellite positions at transmission, ECEF, m, (k, 3).
        sat_vel: satellite velocities, ECEF, m/s, (k, 3) (zero where the rate is unusable).
        sat_clk: c * satellite clock offset, m, (k,).
        sat_drift: c * satellite clock drift, m/s, (k,) (zero where the rate is unusable).
        iono: ionospheric delay, m, (k,).
        tropo: tropospheric delay, m, (k,).
        pr: pseudoranges, m, (k,).
        rate: pseudorange rates, m/s, (k,) (NaN: not applied).
        sigma_pr: pseudorange 1-sigmas, m, (k,).
        sigma_rate: pseudorange-rate 1-sigmas, m/s, (k,).
        system: constellation code of each satellite (``gnss_common.observations`` GPS, GALILEO,
            ...), int, (k,); None: all GPS.
        sat_id: key of each satellite, ``constellation * 1000 + svid``, int, (k,) (the
            correlated-error slots of the fusion filter); None: not given.
    """

    sat_pos: np.ndarray
    sat_vel: np.ndarray
    sat_clk: np.ndarray
    sat_drift: np.ndarray
    iono: np.ndarray
    tropo: np.ndarray
    pr: np.ndarray
    rate: np.ndarray
    sigma_pr: np.ndarray
    sigma_rate: np.ndarray
    system: np.ndarray | None = None
    sat_id: np.ndarray | None = None

    def subset(self, keep: np.ndarray, rate: np.ndarray | None = None) -> PreparedEpoch:
        """The satellites selected by ``keep`` (bool or index array), with ``rate`` if given."""
        r = self.rate if rate is None else rate
        return PreparedEpoch(
            sat_pos=self.sat_pos[keep], sat_vel=self.sat_vel[keep], sat_clk=self.sat_clk[keep],
            sat_drift=self.sat_drift[keep], iono=self.iono[keep], tropo=self.tropo[keep], pr=self.pr[keep],
            rate=r[keep], sigma_pr=self.sigma_pr[keep], sigma_rate=self.sigma_rate[keep],
            system=None if self.system is None else self.system[keep],
            sat_id=None if self.sat_id is None else self.sat_id[keep],
        )


CONSTELLATION_NAMES = {
    GPS: "gps", GLONASS: "glonass", GALILEO: "galileo", BEIDOU: "beidou", QZSS: "qzss", SBAS: "sbas"
}
"""Constellation code -> name (``skipped_constellation.<name>`` counters, bias names)."""

MULTI_GNSS_CONSTELLATIONS = frozenset((GPS, GALILEO, BEIDOU, GLONASS, QZSS))
"""Constellations the filter applies with ``FusionParams.multi_gnss`` (each one other than GPS
with its inter-system clock bias); SBAS is always skipped (no broadcast orbit in the input)."""


def used_constellations(multi_gnss: bool) -> frozenset[int]:
    """The constellation codes the filter applies (GPS alone, or :data:`MULTI_GNSS_CONSTELLATIONS`)."""
    return MULTI_GNSS_CONSTELLATIONS if multi_gnss else _GPS_ONLY


_GPS_ONLY = frozenset((GPS,))


def skipped_constellations(observations: Sequence[object], multi_gnss: bool) -> int:
    """How many observations belong to a constellation the filter does not use.

    They are skipped by design, not rejected: the filter leaves them out of its rejected-satellite
    count."""
    used = used_constellations(multi_gnss)
    return sum(1 for o in observations if isinstance(o, SatelliteObservation) and o.constellation not in used)


def usable_observations(observations: Sequence[object], count: Count, multi_gnss: bool) -> list[SatelliteObservation]:
    """The observations of the constellations in use, without satellites that appear more than once.

    Counted: ``malformed_observation`` (not a SatelliteObservation), ``unsupported_constellation``
    with ``skipped_constellation.<name>`` (``glonass``, ``galileo``, ``beidou``, ``qzss``,
    ``sbas``, or ``code_<n>``) for each satellite of a constellation not in use
    (:func:`used_constellations`), ``duplicate_svid`` (every copy of a duplicated
    (constellation, satellite number)).
    """
    used = used_constellations(multi_gnss)
    obs: list[SatelliteObservation] = []
    seen: dict[tuple[int, int], int] = {}
    for o in observations:
        if not isinstance(o, SatelliteObservation):
            count("malformed_observation", 1)
            continue
        if o.constellation not in used:
            count("unsupported_constellation", 1)
            count(f"skipped_constellation.{CONSTELLATION_NAMES.get(o.constellation, f'code_{o.constellation}')}", 1)
            continue
        key = (o.constellation, o.svid)
        seen[key] = seen.get(key, 0) + 1
        obs.append(o)
    dup = {s for s, n in seen.items() if n > 1}
    if dup:
        count("duplicate_svid", sum(seen[s] for s in dup))
        obs = [o for o in obs if (o.constellation, o.svid) not in dup]
    return obs


def _scalars(obs: list[SatelliteObservation]) -> np.ndarray:
    return np.array(
        [
            (o.pseudorange_m, o.satellite_clock_bias_m, o.ionosphere_delay_m, o.troposphere_delay_m,
             o.cn0_dbhz, o.pseudorange_rate_mps, o.satellite_clock_drift_mps)
            for o in obs
        ],
        dtype=float,
    ).reshape(len(obs), 7)


def _vectors_one_by_one(
    obs: list[SatelliteObservation], count: Count
) -> tuple[list[SatelliteObservation], np.ndarray, np.ndarray]:
    """Observations whose position and velocity reshape to 3-vectors, with those vectors; the
    others counted ``malformed_observation``."""
    good, sps, svs = [], [], []
    for o in obs:
        try:
            sp = np.asarray(o.satellite_position_ecef_m, dtype=float).reshape(3)
            sv = np.asarray(o.satellite_velocity_ecef_mps, dtype=float).reshape(3)
        except (ValueError, TypeError):
            count("malformed_observation", 1)
            continue
        good.append(o)
        sps.append(sp)
        svs.append(sv)
    return good, np.array(sps).reshape(-1, 3), np.array(svs).reshape(-1, 3)


def validate_satellites(obs: list[SatelliteObservation], params: FusionParams, count: Count) -> list[SatelliteRow]:
    """The per-satellite checks, on arrays; each rejected satellite counted under its first failing reason.

    Args:
        obs: observations of the constellations in use (:func:`usable_observations`).
        params: filter parameters (``min_cn0_dbhz``, ``use_doppler``).
        count: the rejection counter.

    Returns:
        The rows of the satellites kept, in input order.

    Notes:
        Reasons, in order: ``malformed_observation`` (a position or velocity that is not a
        3-vector), ``nonfinite_pseudorange``,
        ``nonphysical_satellite_position`` (geocentric radius outside 10 000-50 000 km),
        ``nonphysical_pseudorange`` (outside 1 000-100 000 km, negative delays), ``low_cn0``; a kept
        satellite whose rate cannot be used counts ``invalid_doppler`` (with ``use_doppler``).
    """
    if not obs:
        return []
    try:
        sp = np.array([o.satellite_position_ecef_m for o in obs], dtype=float)
        sv = np.array([o.satellite_velocity_ecef_mps for o in obs], dtype=float)
        shaped = sp.shape == (len(obs), 3) and sv.shape == (len(obs), 3)
    except (ValueError, TypeError):
        shaped = False
    if not shaped:  # rare: vectors of other shapes or types, checked one by one
        obs, sp, sv = _vectors_one_by_one(obs, count)
    n = len(obs)
    sc = _scalars(obs)
    pr, clk, iono, tropo, cn0, rate, sdrift = sc.T
    finite = np.isfinite(sp).all(axis=1) & np.isfinite(pr) & np.isfinite(clk)
    finite &= np.isfinite(iono) & np.isfinite(tropo)
    with np.errstate(invalid="ignore"):
        radius = np.sqrt((sp * sp).sum(axis=1))
        pos_ok = finite & (radius > 1.0e7) & (radius < 5.0e7)
        pr_ok = pos_ok & (pr > 1.0e6) & (pr < 1.0e8) & (iono >= 0.0) & (tropo >= 0.0)
        keep = pr_ok & ~(np.isfinite(cn0) & (cn0 < params.min_cn0_dbhz))
        rate_ok = (
            np.isfinite(rate) & np.isfinite(sv).all(axis=1) & np.isfinite(sdrift) & (np.abs(rate) < 2.0e4)
            if params.use_doppler
            else np.zeros(n, dtype=bool)
        )
    for reason, k in (
        ("nonfinite_pseudorange", n - int(finite.sum())),
        ("nonphysical_satellite_position", int(finite.sum() - pos_ok.sum())),
        ("nonphysical_pseudorange", int(pos_ok.sum() - pr_ok.sum())),
        ("low_cn0", int(pr_ok.sum() - keep.sum())),
        ("invalid_doppler", int((keep & ~rate_ok).sum()) if params.use_doppler else 0),
    ):
        if k:
            count(reason, k)
    return [(obs[i], sp[i], sv[i], bool(rate_ok[i])) for i in np.flatnonzero(keep)]


def validate_uwb_range(
    meas: UwbRangeMeasurement, params: FusionParams, anchors: Mapping[str, np.ndarray], count: Count
) -> np.ndarray | None:
    """The anchor position of a usable UWB range, or None after counting why it is not.

    Args:
        meas: the range.
        params: filter parameters (``uwb_max_range_m``).
        anchors: the anchor registry (id -> position, m); empty: the message's position is used.
        count: the rejection counter.

    Notes:
        Reasons: ``unknown_uwb_frame``, ``unknown_anchor``, ``malformed_anchor_position``,
        ``nonfinite_anchor_position``, ``nonfinite_range``, ``negative_range``,
        ``nonphysical_range`` (beyond ``uwb_max_range_m``), ``nonphysical_range_std`` (<= 0).
    """
    if meas.frame_id not in (FRAME_EARTH, FRAME_MAP):
        count("unknown_uwb_frame", 1)
        return None
    if not isinstance(meas.anchor_id, str) or not meas.anchor_id:
        count("unknown_anchor", 1)
        return None
    if anchors:
        anchor = anchors.get(meas.anchor_id)
        if anchor is None:
            count("unknown_anchor", 1)
            return None
    else:
        try:
            anchor = np.asarray(meas.anchor_position_m, dtype=float).reshape(3)
        except (ValueError, TypeError):
            count("malformed_anchor_position", 1)
            return None
        if not np.isfinite(anchor).all():
            count("nonfinite_anchor_position", 1)
            return None
    rng = meas.range_m
    if not (isinstance(rng, (int, float, np.floating)) and math.isfinite(rng)):
        count("nonfinite_range", 1)
        return None
    if rng < 0.0:
        count("negative_range", 1)
        return None
    if rng > params.uwb_max_range_m:
        count("nonphysical_range", 1)
        return None
    std = meas.range_std_m
    if math.isfinite(std) and std <= 0.0:
        count("nonphysical_range_std", 1)
        return None
    return anchor
