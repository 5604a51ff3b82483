"""The fusion filter on a run of the rfi_sim GNSS/UWB simulator (seeded, 30 s, no jamming)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rfi_sim.gnss_uwb import BroadcastGeometry, GnssUwbScenario, simulate
from uwb_gnss_fusion.fusion_filter import FusionFilter, FusionParams

NAV = Path(__file__).resolve().parents[2] / 'gnss_common' / 'test' / 'data' / 'arlm2000.15n'
"""ARL1 broadcast ephemeris, 2015-07-19 (the copy of the gnss_common tests)."""


def test_broadcast_geometry_run_and_fusion_filter_consume_it():
    geo = BroadcastGeometry(NAV)
    run = simulate(GnssUwbScenario(duration_s=30.0, seed=1), geo, geo.iono_alpha, geo.iono_beta)
    assert min(run.truth.satellites_tracked) >= 6
    f = FusionFilter(FusionParams(accel_psd_m2ps3=0.01))
    for m in run.messages():
        out = f.process(m)
    assert out.initialized
    assert np.linalg.norm(out.position_m - run.truth.receiver_ecef_m) < 2.0
