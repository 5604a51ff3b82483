"""The clean C/N0 models: the simulator's elevation law learned, a jammed start refused, the
down-slowly rate limit, satellite levels without elevations, lost satellites, save / load."""

from __future__ import annotations

import json
import math
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from gnss_common.observations import BEIDOU, GALILEO, GLONASS, GPS
from gnss_integrity.cn0_epoch import BAND_NAMES, Cn0Epoch, signal_band
from gnss_integrity.cn0_model import MODEL_BLOCKED, MODEL_EMPTY, MODEL_READY, Cn0ModelParams, Cn0Models
from rfi_sim.gnss_uwb import BroadcastGeometry, GnssUwbScenario, simulate

NAV = Path(__file__).resolve().parents[2] / "gnss_common" / "test" / "data" / "arlm2000.15n"


@cache
def sim_epochs(jsr_db: float | None, duration_s: float, elevations: bool = True, seed: int = 1) -> tuple:
    """The simulator's C/N0 (5 Hz, GPS, ARL1 sky) as Cn0Epochs, with or without elevations."""
    run = simulate(GnssUwbScenario(duration_s=duration_s, seed=seed, jsr_db=jsr_db), BroadcastGeometry(NAV))
    rx = run.truth.receiver_ecef_m if elevations else None
    return tuple(Cn0Epoch.from_gnss_epoch(e, rx) for e in run.gnss_epochs), run.scenario


def learn_all(models: Cn0Models, epochs) -> list:
    refs = []
    for ep in epochs:
        ref = models.reference(ep)
        models.learn(ref, clean=True)
        refs.append(ref)
    return refs


def test_signal_band():
    const = np.array([GPS, GLONASS, GLONASS, BEIDOU, GALILEO, GPS, GALILEO])
    carrier = np.array([math.nan, 1_598.0625e6, math.nan, math.nan, 1_207.14e6, 1_575.42e6, 1.0e9])
    names = [BAND_NAMES[b] for b in signal_band(const, carrier)]
    assert names == ["L1", "G1", "G1", "B1I", "E5b", "L1", "other"]


def test_learns_the_simulator_elevation_law():
    epochs, sc = sim_epochs(None, 300.0)
    models = Cn0Models()
    refs = learn_all(models, epochs)
    assert models.epochs_learned == len(epochs)
    ref = refs[-1]
    el = ref.epoch.elevation_rad
    law = sc.cn0_horizon_dbhz + (sc.cn0_zenith_dbhz - sc.cn0_horizon_dbhz) * np.sin(el)
    ok = np.isfinite(ref.elevation_expected_dbhz)
    assert ok.sum() >= 7  # every satellite but possibly one that just rose
    err = ref.elevation_expected_dbhz[ok] - law[ok]
    assert np.max(np.abs(err)) < 0.6, err  # noise 0.7 dB per sample, >= 20 effective samples per node
    # Residual 1-sigma: the simulator's C/N0 estimate noise (0.7 dB).
    assert np.all((ref.elevation_std_db[ok] > 0.45) & (ref.elevation_std_db[ok] < 1.0))
    assert ref.elevation_model_in_use and ref.model_state == MODEL_READY


@pytest.mark.parametrize("elevations", [True, False])
def test_refuses_a_start_jammed_at_20_db(elevations):
    epochs, _ = sim_epochs(20.0, 60.0, elevations)
    models = Cn0Models()
    refs = learn_all(models, epochs)
    assert models.epochs_learned == 0 and models.epochs_blocked == len(epochs)
    assert refs[0].model_state == MODEL_EMPTY
    assert all(r.model_state == MODEL_BLOCKED for r in refs[1:])
    assert all(np.isnan(r.expected_dbhz).all() for r in refs)
    # The same sky without the jammer passes the ceiling.
    clean, _ = sim_epochs(None, 60.0, elevations)
    fresh = Cn0Models()
    assert fresh.learn(fresh.reference(clean[0]), True)


def synthetic_epoch(stamp_s: float, cn0, el_deg) -> Cn0Epoch:
    n = len(cn0)
    return Cn0Epoch.from_arrays(int(stamp_s * 1e9), [GPS] * n, list(range(1, n + 1)), cn0, np.radians(el_deg))


def test_falls_slowly_when_a_jammer_slips_through_the_gates():
    # A quickly adapting learner (short memory, no clipping), so that only the rate limit holds it.
    params = Cn0ModelParams(memory_samples=30.0, min_node_weight=5.0, huber_k=20.0)
    el = np.array([35.0, 45.0, 55.0, 65.0, 75.0, 85.0])
    clean_cn0 = 34.0 + 15.0 * np.sin(np.radians(el))
    models = Cn0Models(params)
    rng = np.random.default_rng(0)
    t = 0.0
    for _ in range(600):  # 120 s clean at 5 Hz
        models.learn(models.reference(synthetic_epoch(t, clean_cn0 + 0.5 * rng.standard_normal(6), el)), True)
        t += 0.2
    before = models.reference(synthetic_epoch(t, clean_cn0, el)).elevation_expected_dbhz
    for _ in range(300):  # 60 s, 4 dB down (above the physical ceiling), wrongly called clean
        assert models.learn(models.reference(synthetic_epoch(t, clean_cn0 - 4.0, el)), True)
        t += 0.2
    after = models.reference(synthetic_epoch(t, clean_cn0, el)).elevation_expected_dbhz
    fall = before - after
    limit = 60.0 * params.max_fall_db_per_s  # 1 dB per minute
    assert np.all((fall > 0.9 * limit) & (fall <= limit + 0.05)), fall  # the running mean fell 4 dB
    for _ in range(600):  # 120 s clean again: the published level follows the running mean back up
        models.learn(models.reference(synthetic_epoch(t, clean_cn0, el)), True)
        t += 0.2
    back = models.reference(synthetic_epoch(t, clean_cn0, el)).elevation_expected_dbhz
    assert np.all(np.abs(back - clean_cn0) < 0.3), back - clean_cn0


def test_satellite_levels_without_elevations_and_lost_satellites():
    epochs, _ = sim_epochs(None, 120.0, elevations=False)
    models = Cn0Models()
    refs = learn_all(models, epochs)
    ref = refs[-1]
    assert not ref.elevation_model_in_use and ref.model_state == MODEL_READY
    assert np.all(np.isnan(ref.elevation_expected_dbhz))
    recent = np.mean([r.epoch.cn0_dbhz for r in refs[-50:]], axis=0)
    assert np.all(np.abs(ref.level_expected_dbhz - recent) < 1.0)
    assert np.array_equal(ref.expected_dbhz, ref.level_expected_dbhz)
    # One satellite missing from the next epoch: lost, with its last clean C/N0.
    last = epochs[-1]
    nxt = Cn0Epoch.from_arrays(last.stamp_ns + 200_000_000, last.constellation[1:], last.svid[1:],
                               last.cn0_dbhz[1:])
    lost = models.reference(nxt)
    assert lost.lost_svid.tolist() == [int(last.svid[0])]
    assert lost.lost_cn0_dbhz[0] == pytest.approx(last.cn0_dbhz[0])


def test_not_learned_when_not_clean_or_too_soon():
    epochs, _ = sim_epochs(None, 60.0)
    models = Cn0Models()
    assert not models.learn(models.reference(epochs[0]), clean=False)
    assert models.learn(models.reference(epochs[0]), clean=True)
    assert not models.learn(models.reference(epochs[0]), clean=True)  # same stamp: within learn_interval_s
    assert models.learn(models.reference(epochs[1]), clean=True)


def test_save_load_round_trip_and_validation(tmp_path):
    epochs, _ = sim_epochs(None, 300.0)
    models = Cn0Models()
    learn_all(models, epochs[:1000])
    path = tmp_path / "cn0_model.json"
    models.save(path)
    loaded = Cn0Models.load(path)
    probe = epochs[1200]
    a, b = models.reference(probe), loaded.reference(probe)
    assert np.allclose(a.elevation_expected_dbhz, b.elevation_expected_dbhz, equal_nan=True, atol=1e-12)
    assert np.allclose(a.elevation_std_db, b.elevation_std_db, equal_nan=True, atol=1e-12)
    assert b.elevation_model_in_use  # a stored model judges at once (satellite levels are not stored)
    data = json.loads(path.read_text())
    for change, match in (
        (lambda d: d.update(version=99), "version"),
        (lambda d: d.update(format="other"), "format|not a"),
        (lambda d: d.update(bin_width_deg=10.0), "bin_width_deg"),
        (lambda d: next(iter(d["nodes"].values())).update(mean=[math.nan] * 19), "node field"),
        (lambda d: next(iter(d["nodes"].values())).update(w=[1.0] * 3), "node field"),
        (lambda d: d["nodes"].update({"9:L1": d["nodes"]["1:L1"]}), "bad key"),
        (lambda d: d["offsets"].update({"1:5:L1": [99.0, 1.0]}), "offset"),
    ):
        bad = json.loads(json.dumps(data))
        change(bad)
        with pytest.raises(ValueError, match=match):
            Cn0Models.from_json(bad)
    (tmp_path / "junk.json").write_text("{not json")
    with pytest.raises(ValueError, match="cannot read"):
        Cn0Models.load(tmp_path / "junk.json")


def test_params_are_validated():
    with pytest.raises(ValueError, match="bin_width_deg"):
        Cn0ModelParams(bin_width_deg=7.0)
    with pytest.raises(ValueError, match="min_node_weight"):
        Cn0ModelParams(min_node_weight=0.0)
    with pytest.raises(ValueError, match="min_node_weight must be <="):
        Cn0ModelParams(min_node_weight=1000.0)
    with pytest.raises(ValueError, match="equal lengths"):
        Cn0Epoch.from_arrays(0, [1, 1], [1, 2], [40.0])


def test_nan_cn0_is_never_learned_nor_judged():
    epochs, _ = sim_epochs(None, 60.0)
    models = Cn0Models()
    for ep in epochs:
        blind = Cn0Epoch.from_arrays(ep.stamp_ns, ep.constellation, ep.svid, np.full(ep.svid.size, np.nan),
                                     ep.elevation_rad)
        ref = models.reference(blind)
        assert not models.learn(ref, True)
        assert not ref.valid.any() and ref.model_state == MODEL_EMPTY
