"""The Hanyang dataset authors' scoring, reproduced on their own LS / ESKF solutions of the full
LOS/Trajectory_A/Case_1 case (shipped in test/data/uwb_hanyang_los_a1 with its RMSD_results.txt).

Oracle: the authors' figures, printed by their script; ours must equal them to 1e-12 relative
(float sums may differ in the last bits between CPUs, not more).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from rfi_sim.evaluation import HANYANG_WINDOWS, hanyang_authors_rmse

CASE = Path(__file__).resolve().parent / "data" / "uwb_hanyang_los_a1"


def _reported() -> dict[str, tuple[float, float]]:
    nums = [float(w) for w in (CASE / "RMSD_results.txt").read_text().split() if w[:1].isdigit()]
    assert len(nums) == 4
    return {"LS": (nums[0], nums[1]), "ESKF": (nums[2], nums[3])}


@pytest.mark.parametrize("solution", ["LS", "ESKF"])
def test_reproduces_rmsd_results(solution):
    truth = np.genfromtxt(CASE / "trajectory.csv", delimiter=",", skip_header=1)
    est = np.genfromtxt(CASE / f"{solution}.csv", delimiter=",", skip_header=1, usecols=(0, 1, 2, 3))
    r3, r2, n = hanyang_authors_rmse(truth, est[:, 0], est[:, 1:4], HANYANG_WINDOWS["Trajectory_A"])
    want = _reported()[solution]
    assert math.isclose(r3, want[0], rel_tol=1e-12), (r3, want)
    assert math.isclose(r2, want[1], rel_tol=1e-12), (r2, want)
    assert 1000 < n < est.shape[0]  # a window, not the whole run


def test_plain_metric_differs_from_the_authors():
    """The point of the issue: without window and tag height the same LS.csv scores differently."""
    truth = np.genfromtxt(CASE / "trajectory.csv", delimiter=",", skip_header=1)
    est = np.genfromtxt(CASE / "LS.csv", delimiter=",", skip_header=1, usecols=(0, 1, 2, 3))
    m = (est[:, 0] >= truth[0, 0]) & (est[:, 0] <= truth[-1, 0])
    ref = np.stack([np.interp(est[m, 0], truth[:, 0], truth[:, i]) for i in (1, 2, 3)], axis=1)
    plain_3d = float(np.sqrt(np.mean(((est[m, 1:4] - ref) ** 2).sum(1))))
    assert abs(plain_3d - _reported()["LS"][0]) > 0.01
