"""The input checks of single-point positioning (spp module): which measurements of an epoch are used, each rejected
one counted with its reason (``spp.REJECTION_REASONS``), and the corrected pseudoranges and rates of the others."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from gnss_common.observations import GPS, GnssEpoch


@dataclass(frozen=True)
class ScreenedEpoch:
    """The measurements of an epoch that passed the input checks (``_screen``), by increasing svid: corrected
    pseudoranges ``y_corr`` (clock, ionosphere and troposphere removed), corrected rates (NaN where unusable)."""

    n: int
    svids: np.ndarray
    sat_pos: np.ndarray
    sat_vel: np.ndarray
    y_corr: np.ndarray
    rate_corr: np.ndarray
    cn0: np.ndarray
    iono_m: np.ndarray
    pr_std: np.ndarray
    rate_std: np.ndarray
    missing_corrections: int


def screen_epoch(epoch: GnssEpoch, reject: Callable[[int, str], None]) -> ScreenedEpoch:
    """The input checks of ``spp.SinglePointPositioner.process`` (module docstring: rejection reasons): each rejected
    measurement handed to reject(svid, reason); the others corrected and sorted by svid."""
    obs = list(epoch.observations)
    svid_count: dict[int, int] = {}
    for o in obs:
        if o.constellation == GPS:
            svid_count[o.svid] = svid_count.get(o.svid, 0) + 1
    rows = []
    missing_corrections = 0
    for o in obs:
        if o.constellation != GPS:
            reject(o.svid, "unsupported_constellation")
            continue
        if svid_count[o.svid] > 1:
            reject(o.svid, "duplicate_svid")
            continue
        sat = np.asarray(o.satellite_position_ecef_m, dtype=float).reshape(-1)
        vel = np.asarray(o.satellite_velocity_ecef_mps, dtype=float).reshape(-1)
        if sat.shape != (3,) or vel.shape != (3,):
            reject(o.svid, "invalid_input")
            continue
        core = (o.pseudorange_m, o.satellite_clock_bias_m, sat[0], sat[1], sat[2])
        if not all(math.isfinite(v) for v in core):
            reject(o.svid, "invalid_input")
            continue
        r_sat = math.sqrt(sat[0] ** 2 + sat[1] ** 2 + sat[2] ** 2)
        if not (
            1.0e7 <= o.pseudorange_m <= 4.0e7
            and 2.0e7 <= r_sat <= 5.0e7
            and abs(o.satellite_clock_bias_m) < 3.0e5
        ):
            reject(o.svid, "non_physical")
            continue
        iono = o.ionosphere_delay_m
        tropo = o.troposphere_delay_m
        if not (math.isfinite(iono) and math.isfinite(tropo)):
            missing_corrections += 1
            iono = iono if math.isfinite(iono) else 0.0
            tropo = tropo if math.isfinite(tropo) else 0.0
        if iono < 0.0 or tropo < 0.0 or iono > 200.0 or tropo > 100.0:
            reject(o.svid, "non_physical")
            continue
        rate_ok = (
            math.isfinite(o.pseudorange_rate_mps)
            and math.isfinite(o.satellite_clock_drift_mps)
            and bool(np.all(np.isfinite(vel)))
            and abs(o.pseudorange_rate_mps) < 1.0e5
        )
        rows.append(
            (
                o.svid,
                sat,
                vel,
                o.pseudorange_m + o.satellite_clock_bias_m - iono - tropo,
                (o.pseudorange_rate_mps + o.satellite_clock_drift_mps) if rate_ok else math.nan,
                o.cn0_dbhz if math.isfinite(o.cn0_dbhz) else math.nan,
                iono,
                o.pseudorange_std_m,
                o.pseudorange_rate_std_mps,
            )
        )
    rows.sort(key=lambda r: r[0])
    n = len(rows)
    return ScreenedEpoch(
        n,
        np.array([r[0] for r in rows], dtype=int),
        np.array([r[1] for r in rows], dtype=float).reshape(n, 3),
        np.array([r[2] for r in rows], dtype=float).reshape(n, 3),
        np.array([r[3] for r in rows], dtype=float),
        np.array([r[4] for r in rows], dtype=float),
        np.array([r[5] for r in rows], dtype=float),
        np.array([r[6] for r in rows], dtype=float),
        np.array([r[7] for r in rows], dtype=float),
        np.array([r[8] for r in rows], dtype=float),
        missing_corrections,
    )
