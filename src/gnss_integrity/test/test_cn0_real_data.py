"""Every C/N0 test on the recorded C/N0 of real clean station hours (src/gnss_common/test/data).

ARL1 (GPS, S1), ESBC00DNK (GPS, GLONASS, Galileo, BeiDou, S1C/S2I): no ALARM at all, SUSPECT in at
most 1 of 1,000 epochs per test (none in these 120-epoch hours), with the elevation model (header
position) and without elevations (a receiver stream with no ephemeris). GEONET 0759 / 3040 carry no
C/N0: every C/N0 test is UNKNOWN there, never PASS. The model learns from nothing on each hour.
The counts per station and test are printed (``pytest -s``).
"""

from __future__ import annotations

from collections import Counter
from functools import cache
from pathlib import Path

import pytest

from gnss_common.measurements import build_epochs
from gnss_common.rinex import read_rinex_nav, read_rinex_obs
from gnss_integrity.cn0_epoch import Cn0Epoch
from gnss_integrity.cn0_jamming import TEST_NAME, Cn0JammingDetector
from gnss_integrity.cn0_model import Cn0Models
from gnss_integrity.cn0_spoofing import TEST_NAMES, Cn0SpoofingTests
from gnss_integrity.outcome import DECISION_ALARM, DECISION_PASS, DECISION_SUSPECT, DECISION_UNKNOWN

DATA = Path(__file__).resolve().parents[2] / "gnss_common" / "test" / "data"
STATIONS = {
    "ARL1": ("arlm200a.15o", "arlm2000.15n"),
    "ESBC": ("ESBC00DNK_R_20201770000_01H_30S_MO.crx.gz", "ESBC00DNK_R_20201770000_01H_MN.rnx.gz"),
    "0759": ("07590920.05o", "07590920.05n"),
    "3040": ("30400920.05o", "30400920.05n"),
}
ALL_TESTS = (TEST_NAME, *TEST_NAMES)


@cache
def station_epochs(name: str, elevations: bool) -> tuple[Cn0Epoch, ...]:
    obs_f, nav_f = STATIONS[name]
    obs = read_rinex_obs(DATA / obs_f)
    nav = read_rinex_nav(DATA / nav_f)
    rx = obs.header.approx_position_ecef_m if elevations else None
    return tuple(Cn0Epoch.from_gnss_epoch(r.epoch, rx) for r in build_epochs(obs, nav))


@cache
def decisions(name: str, elevations: bool) -> tuple[Counter, int, bool]:
    """(test name, decision) -> epochs, epochs, elevation model used in some epoch."""
    models, jam, spoof = Cn0Models(), Cn0JammingDetector(), Cn0SpoofingTests()
    counts: Counter = Counter()
    used_elevation = False
    epochs = station_epochs(name, elevations)
    for ep in epochs:
        ref = models.reference(ep)
        j = jam.evaluate(ref)
        s = spoof.evaluate(ref, j)
        models.learn(ref, j.epoch_clean and s.epoch_clean)
        used_elevation |= j.elevation_model_in_use
        for o in (j.outcome, *s.outcomes):
            counts[(o.name, o.decision)] += 1
    labels = ("unknown", "pass", "suspect", "alarm")
    report = {t: {labels[d]: counts[(t, d)] for d in range(4) if counts[(t, d)]} for t in ALL_TESTS}
    print(f"\n{name} elevations={elevations} epochs={len(epochs)}: {report}")
    return counts, len(epochs), used_elevation


@pytest.mark.slow
@pytest.mark.parametrize("elevations", [True, False])
@pytest.mark.parametrize("name", ["ARL1", "ESBC"])
def test_clean_days_give_no_jamming_nor_spoofing(name, elevations):
    counts, n, used_elevation = decisions(name, elevations)
    assert used_elevation is elevations
    for test in ALL_TESTS:
        assert counts[(test, DECISION_ALARM)] == 0, test
        assert counts[(test, DECISION_SUSPECT)] <= n // 1000, test
    # The tests ran: learning from nothing takes a few 30 s epochs; the elevation test needs
    # elevations, the fluctuation test a 50-sample window.
    assert counts[(TEST_NAME, DECISION_PASS)] >= 0.9 * n
    assert counts[(TEST_NAMES[0], DECISION_PASS)] >= 0.9 * n
    assert counts[(TEST_NAMES[1], DECISION_PASS)] >= (0.7 * n if elevations else 0)
    assert counts[(TEST_NAMES[2], DECISION_PASS)] >= 0.5 * n


@pytest.mark.parametrize("name", ["0759", "3040"])
def test_no_cn0_in_the_file_is_unknown_never_none(name):
    counts, n, _ = decisions(name, True)
    for test in ALL_TESTS:
        assert counts[(test, DECISION_UNKNOWN)] == n, test
