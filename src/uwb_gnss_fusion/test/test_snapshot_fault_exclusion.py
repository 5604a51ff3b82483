"""The snapshot fix's fault exclusion (initialisation._exclude_faults): several faulty satellites at once, as the
outlier bursts of strong jamming give (docs/uwb_gnss_fusion/fusion_never_worse.md, GNSS alone at +30 dB).

Oracle: exact pseudoranges from the filter's own model (eq. 5) at a known receiver, 1 m noise, gross errors added
to chosen satellites."""

from __future__ import annotations

import numpy as np

from uwb_gnss_fusion.initialisation import snapshot_fix
from uwb_gnss_fusion.input_checks import PreparedEpoch
from uwb_gnss_fusion.measurement_models import STATE_DIM, pseudorange_model

RX = np.array([-740289.9, -5457071.7, 3207245.5])
CLK_M = 1234.5


def _epoch(n: int, rng: np.random.Generator, faults: dict[int, float]) -> PreparedEpoch:
    up = RX / np.linalg.norm(RX)
    east = np.cross([0.0, 0.0, 1.0], up)
    east /= np.linalg.norm(east)
    north = np.cross(up, east)
    sats = []
    for k in range(n):            # spread in azimuth, elevations 20-75 deg, GPS orbit radius
        az = 2 * np.pi * k / n + 0.3
        el = np.radians(20 + 55 * ((k * 7) % n) / max(n - 1, 1))
        los = np.cos(el) * (np.sin(az) * east + np.cos(az) * north) + np.sin(el) * up
        b = float(RX @ los)
        r = -b + np.sqrt(b * b - (RX @ RX - 26.56e6 ** 2))
        sats.append(RX + r * los)
    sat_pos = np.array(sats)
    z = np.zeros(n)
    state = np.zeros(STATE_DIM)
    state[0:3], state[6] = RX, CLK_M
    pr = pseudorange_model(sat_pos, z, z, z)(state[None, :])[0] + rng.normal(0.0, 1.0, n)
    for k, e in faults.items():
        pr[k] += e
    return PreparedEpoch(sat_pos=sat_pos, sat_vel=np.zeros((n, 3)), sat_clk=z, sat_drift=z, iono=z, tropo=z,
                         pr=pr, rate=np.full(n, np.nan), sigma_pr=np.full(n, 1.0), sigma_rate=np.full(n, 0.1))


def test_clean_and_one_or_two_faults_give_the_true_position():
    rng = np.random.default_rng(4)
    for faults in ({}, {2: 150.0}, {1: 80.0, 5: -200.0}):
        for _ in range(10):
            fix = snapshot_fix(_epoch(9, rng, faults), 5)
            assert fix is not None, faults
            assert np.linalg.norm(fix[0] - RX) < 15.0, (faults, np.linalg.norm(fix[0] - RX))


def test_no_fix_rather_than_a_wrong_one():
    """Three gross faults among seven satellites (beyond the two excluded at most) or two among six (no subset of
    five is clean): no fix, or one near the truth; never a fix metres-to-hundreds of metres off passed as good."""
    rng = np.random.default_rng(5)
    for n, faults in ((7, {0: 120.0, 3: -90.0, 5: 250.0}), (6, {1: 100.0, 4: -150.0})):
        given = 0
        for _ in range(20):
            fix = snapshot_fix(_epoch(n, rng, faults), 5)
            if fix is not None:
                given += 1
                assert np.linalg.norm(fix[0] - RX) < 15.0, (n, faults, np.linalg.norm(fix[0] - RX))
        assert given < 20


def test_two_faults_that_the_one_at_a_time_exclusion_got_wrong():
    """Eight satellites, two gross faults: dropping the largest residual one at a time (the fix before) ended on a
    wrong consistent set, 113, 832 and 66 m off in these three cases (found by a seeded search over random fault
    pairs, kept as regression cases); the subset exclusion gives the true position."""
    for faults, seed in (({0: -76.534, 4: -210.347}, 884449), ({6: -103.055, 1: -251.691}, 9805),
                         ({0: -44.036, 4: -134.555}, 908325)):
        fix = snapshot_fix(_epoch(8, np.random.default_rng(seed), faults), 5)
        assert fix is not None
        assert np.linalg.norm(fix[0] - RX) < 10.0, (faults, np.linalg.norm(fix[0] - RX))


def test_fewer_wrong_fixes_over_random_faults():
    """Seeded Monte Carlo, 5-8 satellites, 1-3 faults of 20-300 m: fixes more than 30 m off are a small share of the
    fixes given (measured 63 of 817 given in 3,000 epochs; the exclusion one at a time: 115 of 597)."""
    rng = np.random.default_rng(1)
    bad = given = 0
    for _ in range(600):
        n = int(rng.integers(5, 9))
        ks = rng.choice(n, int(rng.integers(1, 4)), replace=False)
        faults = {int(k): float(rng.choice([-1, 1]) * rng.uniform(20, 300)) for k in ks}
        fix = snapshot_fix(_epoch(n, np.random.default_rng(int(rng.integers(1_000_000_000))), faults), 5)
        if fix is not None:
            given += 1
            bad += np.linalg.norm(fix[0] - RX) > 30.0
    assert given > 100
    assert bad / given < 0.12, (bad, given)
