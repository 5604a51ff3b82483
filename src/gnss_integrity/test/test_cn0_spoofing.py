"""The C/N0 spoofing tests: a +3 dB takeover with a common fluctuation detected within seconds, one
constellation spoofed on a real multi-GNSS hour implicated by name, a jammer not taken for a
spoofer, the common-fluctuation statistic's clean-data model."""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from gnss_common.measurements import build_epochs
from gnss_common.observations import GALILEO, GPS
from gnss_common.rinex import read_rinex_nav, read_rinex_obs
from gnss_integrity.cn0_epoch import Cn0Epoch
from gnss_integrity.cn0_jamming import Cn0JammingDetector
from gnss_integrity.cn0_model import Cn0Models
from gnss_integrity.cn0_spoofing import (
    COMMON_FLUCTUATION,
    ELEVATION_DEPENDENCE,
    TEST_NAMES,
    TOO_HIGH,
    Cn0SpoofingParams,
    Cn0SpoofingTests,
)
from gnss_integrity.outcome import (
    CATEGORY_CN0,
    DECISION_ALARM,
    DECISION_PASS,
    DECISION_SUSPECT,
    DECISION_UNKNOWN,
    SCOPE_ALL,
    SCOPE_CONSTELLATIONS,
)
from rfi_sim.gnss_uwb import BroadcastGeometry, GnssUwbScenario, simulate

DATA = Path(__file__).resolve().parents[2] / "gnss_common" / "test" / "data"
RATE_HZ = 5.0
CLEAN_S = 180.0


@cache
def sim_epochs(jsr_db: float | None, duration_s: float = 240.0) -> tuple[Cn0Epoch, ...]:
    geometry = BroadcastGeometry(DATA / "arlm2000.15n")
    run = simulate(GnssUwbScenario(duration_s=duration_s, seed=4, jsr_db=jsr_db), geometry)
    return tuple(Cn0Epoch.from_gnss_epoch(e, run.truth.receiver_ecef_m) for e in run.gnss_epochs)


@cache
def esbc_epochs() -> tuple[Cn0Epoch, ...]:
    obs = read_rinex_obs(DATA / "ESBC00DNK_R_20201770000_01H_30S_MO.crx.gz")
    nav = read_rinex_nav(DATA / "ESBC00DNK_R_20201770000_01H_MN.rnx.gz")
    rx = obs.header.approx_position_ecef_m
    return tuple(Cn0Epoch.from_gnss_epoch(r.epoch, rx) for r in build_epochs(obs, nav))


def run_chain(epochs, params: Cn0SpoofingParams | None = None) -> list:
    """The node's per-epoch sequence: reference, jamming, spoofing, learning gated by both."""
    models, jam, spoof = Cn0Models(), Cn0JammingDetector(), Cn0SpoofingTests(params)
    out = []
    for ep in epochs:
        ref = models.reference(ep)
        j = jam.evaluate(ref)
        s = spoof.evaluate(ref, j)
        models.learn(ref, j.epoch_clean and s.epoch_clean)
        out.append((j, s))
    return out


def takeover(epochs, k0: int, select=None, seed: int = 0, period_epochs: float = 20.0) -> list[Cn0Epoch]:
    """From epoch k0 the selected satellites (default all) get one C/N0: their median at k0 + 3 dB,
    with a common 1.5 dB sinusoid (one transmitter, a moving antenna) and 0.5 dB independent noise."""
    rng = np.random.default_rng(seed)
    out = list(epochs[:k0])
    level = None
    for k, e in enumerate(epochs[k0:]):
        sel = np.ones(e.svid.size, bool) if select is None else select(e)
        if level is None:
            level = float(np.median(e.cn0_dbhz[sel])) + 3.0
        c = e.cn0_dbhz.copy()
        c[sel] = level + 1.5 * math.sin(2 * math.pi * k / period_epochs) + 0.5 * rng.standard_normal(sel.sum())
        out.append(Cn0Epoch.from_arrays(e.stamp_ns, e.constellation, e.svid, c, e.elevation_rad,
                                        e.carrier_frequency_hz))
    return out


def first_s(results, k0: int, index: int, decision: int, rate_hz: float = RATE_HZ) -> float:
    return next((i / rate_hz for i, (_, s) in enumerate(results[k0:]) if s.outcomes[index].decision >= decision),
                math.inf)


@pytest.mark.slow
def test_a_takeover_is_detected_within_seconds():
    k0 = int(CLEAN_S * RATE_HZ)
    res = run_chain(takeover(sim_epochs(None), k0))
    for _, s in res[:k0]:
        assert all(o.decision <= DECISION_PASS for o in s.outcomes)
        assert [o.name for o in s.outcomes] == list(TEST_NAMES) and all(o.category == CATEGORY_CN0 for o in s.outcomes)
    # One transmitter: the elevation dependence is gone within 2 s, the power is high at once, the
    # common fluctuation needs a few of its periods (4 s).
    assert first_s(res, k0, 1, DECISION_ALARM) <= 3.0
    assert first_s(res, k0, 0, DECISION_SUSPECT) <= 3.0
    assert first_s(res, k0, 2, DECISION_SUSPECT) <= 5.0 and first_s(res, k0, 2, DECISION_ALARM) <= 10.0
    j, s = res[k0 + 25]
    alarm = [o for o in s.outcomes if o.decision == DECISION_ALARM]
    assert alarm and all(o.scope == SCOPE_ALL and o.constellations == (GPS,) for o in alarm)
    assert s.fraction_lost > 0.7 and not s.epoch_clean
    assert j.outcome.decision == DECISION_PASS  # stronger, not weaker: no jamming


def test_one_spoofed_constellation_is_named():
    epochs = esbc_epochs()
    k0 = 60  # 30 min clean, then Galileo flat and 3 dB up (30 s epochs)
    res = run_chain(takeover(epochs, k0, lambda e: e.constellation == GALILEO, period_epochs=6.0))
    for _, s in res[:k0]:
        assert all(o.decision <= DECISION_PASS for o in s.outcomes)
    assert first_s(res, k0, 0, DECISION_ALARM, 1 / 30) <= 120.0  # three 30 s epochs of persistence
    assert first_s(res, k0, 1, DECISION_ALARM, 1 / 30) <= 300.0
    assert first_s(res, k0, 2, DECISION_ALARM, 1 / 30) <= 900.0  # a 25-sample window of 30 s epochs
    flagged = [o for _, s in res[k0:] for o in s.outcomes if o.decision >= DECISION_SUSPECT]
    assert flagged
    assert all(o.scope == SCOPE_CONSTELLATIONS and o.constellations == (GALILEO,) for o in flagged)
    implicated = {sat for o in flagged for sat in o.satellites}
    assert implicated and all(c == GALILEO for c, _ in implicated)
    assert all(j.outcome.decision <= DECISION_PASS for j, _ in res)


@pytest.mark.slow
def test_a_jammer_is_not_taken_for_a_spoofer():
    k0 = int(CLEAN_S * RATE_HZ)
    epochs = list(sim_epochs(None)[:k0]) + list(sim_epochs(25.0)[k0:])
    res = run_chain(epochs)
    assert any(j.outcome.decision == DECISION_ALARM for j, _ in res[k0:])
    for _, s in res:
        assert all(o.decision <= DECISION_PASS for o in s.outcomes)


def test_common_fluctuation_meets_its_clean_data_model():
    """Independent C/N0 noise on 10 satellites for 3,000 evaluations: the suspect threshold at
    p = 1e-2 (one group) is reached at most at that rate; a common 2 dB sinusoid is found within a
    window."""
    rng = np.random.default_rng(11)
    params = Cn0SpoofingParams(false_alarm_probability=1e-2, alarm_false_alarm_probability=1e-3,
                               persistence_epochs=1, persistence_s=0.0)
    tests = Cn0SpoofingTests(params)
    models = Cn0Models()
    el = np.radians(np.linspace(20.0, 80.0, 10))
    base = 34.0 + 15.0 * np.sin(el)
    z = []
    for k in range(3000):
        ep = Cn0Epoch.from_arrays(k * 200_000_000, [GPS] * 10, range(1, 11), base + rng.standard_normal(10), el)
        o = tests.evaluate(models.reference(ep)).outcomes[2]
        if o.decision != DECISION_UNKNOWN:
            z.append(o.statistic >= o.suspect_threshold)
    assert len(z) > 2900 and np.mean(z) <= 1e-2
    hits = []
    for k in range(3000, 3200):
        common = 2.0 * math.sin(2 * math.pi * k / 20.0)
        ep = Cn0Epoch.from_arrays(k * 200_000_000, [GPS] * 10, range(1, 11),
                                  base + common + rng.standard_normal(10), el)
        hits.append(tests.evaluate(models.reference(ep)).outcomes[2].decision)
    assert np.mean(np.array(hits[50:]) == DECISION_ALARM) > 0.9


def test_unknown_without_references_never_pass():
    tests = Cn0SpoofingTests()
    models = Cn0Models()
    for k, ep in enumerate(sim_epochs(None)[:20]):
        res = tests.evaluate(models.reference(ep))
        names = {o.name: o for o in res.outcomes}
        assert names[TOO_HIGH].decision == DECISION_UNKNOWN and math.isnan(names[TOO_HIGH].statistic)
        assert names[ELEVATION_DEPENDENCE].decision == DECISION_UNKNOWN
        assert names[COMMON_FLUCTUATION].decision == (DECISION_UNKNOWN if k < 49 else DECISION_PASS)
        assert res.epoch_clean and math.isnan(res.fraction_lost)


def test_evaluation_interval_returns_the_last_result_in_between():
    tests = Cn0SpoofingTests(Cn0SpoofingParams(evaluation_interval_s=0.2))
    models = Cn0Models()
    ep = sim_epochs(None)[0]
    first = tests.evaluate(models.reference(ep))
    again = Cn0Epoch.from_arrays(ep.stamp_ns + 50_000_000, ep.constellation, ep.svid, ep.cn0_dbhz, ep.elevation_rad)
    assert tests.evaluate(models.reference(again)) is first
    with pytest.raises(ValueError):
        Cn0SpoofingParams(min_group_satellites=2)
