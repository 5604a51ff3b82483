"""GPS ionospheric delays of RINEX epochs from the L1/L2 carriers, levelled per arc to the broadcast model.

The RINEX glue of :func:`gnss_common.corrections.carrier_levelled_ionosphere_m` (method, equations and
its limits there): used by ``rinex_to_bag --ionosphere carrier-levelled`` and by tests and
benchmarks that build epochs from RINEX directly. Non-causal (each arc as a whole): post-processing
of a file, not a live receiver's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from gnss_common.constants import GPS_L1_FREQUENCY_HZ, GPS_L2_FREQUENCY_HZ, SPEED_OF_LIGHT_MPS
from gnss_common.corrections import carrier_levelled_ionosphere_m
from gnss_common.measurements import CONSTELLATION_CODES
from gnss_common.observations import GnssEpoch
from gnss_common.rinex_obs import RinexObs

GPS_PHASE_CODES = (("L1", "L1C", "L1W", "L1P", "L1X"), ("L2", "L2W", "L2P", "L2L", "L2X", "L2S", "L2D", "L2C"))
"""GPS L1 and L2 carrier-phase observables, first present in the header used (RINEX 2, then 3/4)."""


def level_gps_ionosphere(obs: RinexObs, epochs: Sequence[GnssEpoch]) -> tuple[list[GnssEpoch], dict[str, int]]:
    """The GPS ``ionosphere_delay_m`` of ``epochs`` (one per ``obs.epochs``, in order, with the
    Klobuchar delays) replaced by the carrier-levelled delay where both carriers are there.

    Returns:
        (epochs, counts): ``levelled`` and ``model`` (kept Klobuchar) GPS measurements.
    """
    gps = CONSTELLATION_CODES["G"]
    header_codes = obs.header.obs_types.get("G", ())
    l1 = next((c for c in GPS_PHASE_CODES[0] if c in header_codes), None)
    l2 = next((c for c in GPS_PHASE_CODES[1] if c in header_codes), None)
    counts = {"levelled": 0, "model": 0}
    if l1 is None or l2 is None:
        counts["model"] = sum(o.constellation == gps for e in epochs for o in e.observations)
        return list(epochs), counts
    lam1, lam2 = SPEED_OF_LIGHT_MPS / GPS_L1_FREQUENCY_HZ, SPEED_OF_LIGHT_MPS / GPS_L2_FREQUENCY_HZ
    series: dict[int, list[tuple[int, float, float]]] = {}
    for k, (rinex_epoch, epoch) in enumerate(zip(obs.epochs, epochs, strict=True)):
        for o in epoch.observations:
            if o.constellation == gps:
                values = rinex_epoch.observations.get(f"G{o.svid:02d}", {})
                gf = lam1 * values.get(l1, math.nan) - lam2 * values.get(l2, math.nan)
                series.setdefault(o.svid, []).append((k, gf, o.ionosphere_delay_m))
    levelled: dict[tuple[int, int], float] = {}
    for svid, rows in series.items():
        arr = np.array(rows)
        delay = carrier_levelled_ionosphere_m(arr[:, 0].astype(np.int64), arr[:, 1], arr[:, 2],
                                              GPS_L1_FREQUENCY_HZ, GPS_L2_FREQUENCY_HZ)
        levelled.update({(int(k), svid): float(d) for k, d in zip(arr[:, 0], delay, strict=True) if math.isfinite(d)})
    out = []
    for k, epoch in enumerate(epochs):
        obs_out = []
        for o in epoch.observations:
            d = levelled.get((k, o.svid)) if o.constellation == gps else None
            if o.constellation == gps:
                counts["levelled" if d is not None else "model"] += 1
            obs_out.append(o if d is None else replace(o, ionosphere_delay_m=d))
        out.append(replace(epoch, observations=tuple(obs_out)))
    return out, counts
