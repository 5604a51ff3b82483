"""UWB-only mode of the fusion filter on real ranges (Hanyang outdoor dataset: the first 60 s of
LOS/Trajectory_B/Case_3 and the first 45 s of NLOS/Trajectory_A/Case_1).

The dataset authors' LS and ESKF solutions of the same ranges are the peers; all three are scored
with the same metric (truth linearly interpolated at each solution's stamp, 3D and 2D RMSE). The
NLOS excerpt covers the start-up, where a three-anchor multilateration once picked the mirror
solution 12 m away (the filter now waits for the fourth anchor or a whole init window).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gnss_common.observations import UwbRangeMeasurement
from uwb_gnss_fusion.fusion_filter import FusionFilter, FusionParams

DATA_DIR = Path(__file__).resolve().parent / "data"
CASES = ("hanyang_los_b_case3_60s", "hanyang_nlos_a_case1_45s")


def _load(case: str, name: str) -> np.ndarray:
    return np.genfromtxt(DATA_DIR / case / f"{name}.csv", delimiter=",", skip_header=1)


def _rmse(ts: np.ndarray, xyz: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    m = (ts >= truth[0, 0]) & (ts <= truth[-1, 0])
    ref = np.stack([np.interp(ts[m], truth[:, 0], truth[:, i]) for i in (1, 2, 3)], axis=1)
    e = xyz[m] - ref
    return float(np.sqrt(np.mean((e**2).sum(1)))), float(np.sqrt(np.mean((e[:, :2] ** 2).sum(1))))


@pytest.fixture(scope="module", params=CASES)
def run(request):
    case = request.param
    msgs = []
    for anchor in ("A3", "A5", "A9", "A12"):
        for r in _load(case, anchor):
            msgs.append(
                UwbRangeMeasurement(
                    stamp_ns=int(r[1]),
                    anchor_id=str(int(r[2])),
                    anchor_position_m=r[3:6].copy(),
                    frame_id="map",
                    range_m=float(r[6]),
                )
            )
    msgs.sort(key=lambda m: m.stamp_ns)
    f = FusionFilter(FusionParams(use_gnss=False, accel_psd_m2ps3=1.0))
    outs = [f.process_uwb(m) for m in msgs]
    return case, msgs, outs


def test_uwb_only_real_data_beats_authors_ls_and_eskf(run):
    case, msgs, outs = run
    truth = _load(case, "trajectory")
    valid = [o for o in outs if o.initialized]
    assert len(valid) >= len(msgs) - 5
    assert all(o.frame_id == "map" and np.all(np.isfinite(o.position_m)) for o in valid)
    ckf = _rmse(np.array([o.stamp_ns for o in valid], float), np.array([o.position_m for o in valid]), truth)
    for peer in ("LS", "ESKF"):
        d = _load(case, peer)
        ref = _rmse(d[:, 0], d[:, 1:4], truth)
        assert ckf[0] < ref[0], (peer, ckf, ref)
        assert ckf[1] < ref[1], (peer, ckf, ref)
    assert valid[-1].reinitializations == 0
