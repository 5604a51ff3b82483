"""Receiver clock steps (``receiver_clock_steps``, :func:`uwb_gnss_fusion.clock_steps.receiver_clock_step`).

Receivers that let their clock drift step it by whole milliseconds: every pseudorange of the
epoch jumps by 299,792.458 m at once. Checked on the real ESBC00DNK multi-GNSS hour (the
gnss_common test data, 30 s epochs) with steps injected into the pseudoranges: a whole-millisecond
step is repaired exactly (the outputs are those of the unstepped run), another step re-solves the
clock, and independent outliers are never taken for a step.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gnss_common.constants import SPEED_OF_LIGHT_MPS
from gnss_common.coordinates import azimuth_elevation
from gnss_common.observations import GnssEpoch
from uwb_gnss_fusion.clock_steps import MS_OF_LIGHT_M
from uwb_gnss_fusion.fusion_filter import FusionFilter, FusionParams

DATA = Path(__file__).resolve().parents[2] / "gnss_common" / "test" / "data"
TRUTH = np.array([3582105.2910, 532589.7313, 5232754.8054])


@pytest.fixture(scope="module")
def esbc_epochs() -> list[GnssEpoch]:
    from gnss_common.measurements import GnssEpochBuilder
    from gnss_common.rinex import read_rinex_nav, read_rinex_obs

    obs = read_rinex_obs(DATA / "ESBC00DNK_R_20201770000_01H_30S_MO.crx.gz")
    nav = read_rinex_nav(DATA / "ESBC00DNK_R_20201770000_01H_MN.rnx.gz")
    builder = GnssEpochBuilder.from_rinex(obs, nav)
    return [builder.build(e).epoch for e in obs.epochs]


def _shift(epoch: GnssEpoch, metres: float, only: set[int] | None = None) -> GnssEpoch:
    """The epoch with ``metres`` added to every pseudorange (or to those of the indices ``only``)."""
    obs = tuple(replace(o, pseudorange_m=o.pseudorange_m + metres) if only is None or i in only else o
                for i, o in enumerate(epoch.observations))
    return replace(epoch, observations=obs)


def _run(epochs, **kw) -> tuple[FusionFilter, np.ndarray]:
    f = FusionFilter(FusionParams(use_uwb=False, **kw))
    pos = np.array([o.position_m if o.initialized else np.full(3, np.nan) for o in map(f.process_gnss, epochs)])
    return f, pos


def _stepped(epochs, steps_m: dict[int, float]) -> list[GnssEpoch]:
    """The receiver clock stepped by ``steps_m[k]`` at epoch k and kept there (steps add up)."""
    out, total = [], 0.0
    for k, e in enumerate(epochs):
        total += steps_m.get(k, 0.0)
        out.append(_shift(e, total) if total else e)
    return out


def test_whole_millisecond_steps_are_repaired_exactly(esbc_epochs):
    _, clean = _run(esbc_epochs)
    f, stepped = _run(_stepped(esbc_epochs, {40: MS_OF_LIGHT_M, 80: -3.0 * MS_OF_LIGHT_M}))
    assert f.rejection_counts.get("receiver_clock_step_ms") == 2
    assert "divergence" not in f.rejection_counts and "receiver_clock_step" not in f.rejection_counts
    ok = np.isfinite(clean[:, 0])
    assert ok.sum() == len(esbc_epochs) - 1 and np.array_equal(ok, np.isfinite(stepped[:, 0]))
    # the same filter on the same measurements up to a known clock offset: equal to rounding
    np.testing.assert_allclose(stepped[ok], clean[ok], rtol=0, atol=1e-3)
    assert MS_OF_LIGHT_M == pytest.approx(SPEED_OF_LIGHT_MPS * 1e-3)


def test_without_the_repair_a_millisecond_step_costs_the_position(esbc_epochs):
    """What the option prevents: every pseudorange gated, divergence, metres of error. With the moving
    model (motion_detection off): once the detector has found the antenna static, the static model holds
    the position through the divergence and hides the cost (max error 2.9 m against 1.4 m, divergence still
    declared)."""
    _, clean = _run(esbc_epochs, motion_detection=False)
    f, stepped = _run(_stepped(esbc_epochs, {40: MS_OF_LIGHT_M}), receiver_clock_steps=False, motion_detection=False)
    assert f.rejection_counts.get("divergence", 0) >= 1
    err_clean = np.linalg.norm(clean[40:60] - TRUTH, axis=1)
    err = np.linalg.norm(stepped[40:60] - TRUTH, axis=1)
    assert np.nanmax(err) > np.nanmax(err_clean) + 2.0 or np.isnan(err).any()


@pytest.mark.parametrize("step_m", [90.0, -5_000.0, 0.4 * MS_OF_LIGHT_M])
def test_other_steps_re_solve_the_clock(esbc_epochs, step_m):
    _, clean = _run(esbc_epochs)
    f, stepped = _run(_stepped(esbc_epochs, {40: step_m}))
    assert f.rejection_counts.get("receiver_clock_step") == 1
    assert "divergence" not in f.rejection_counts and "receiver_clock_step_ms" not in f.rejection_counts
    # the position is kept through the step: within 0.5 m of the unstepped run's at every epoch after it
    assert np.all(np.linalg.norm(stepped[40:] - clean[40:], axis=1) < 0.5)


def test_no_step_on_the_real_hour_nor_for_independent_outliers(esbc_epochs):
    f, _ = _run(esbc_epochs)
    assert not {"receiver_clock_step", "receiver_clock_step_ms"} & set(f.rejection_counts)
    # two satellites of an epoch off by the same 1 ms (a decoding error, not the clock): not a step,
    # the screen drops them
    epochs = list(esbc_epochs)
    high = [i for i, o in enumerate(epochs[50].observations)
            if azimuth_elevation(TRUTH, o.satellite_position_ecef_m)[1] > np.radians(30.0)]
    epochs[50] = _shift(epochs[50], MS_OF_LIGHT_M, only=set(high[:2]))
    g, pos = _run(epochs)
    assert not {"receiver_clock_step", "receiver_clock_step_ms"} & set(g.rejection_counts)
    assert g.rejection_counts.get("common_mode_pseudorange", 0) == 2
    assert np.linalg.norm(pos[50] - TRUTH) < 5.0
    # half of the satellites shifted together is not a majority: no step taken
    n = len(epochs[60].observations)
    epochs[60] = _shift(epochs[60], MS_OF_LIGHT_M, only=set(range(n // 2)))
    h, _ = _run(epochs)
    assert not {"receiver_clock_step", "receiver_clock_step_ms"} & set(h.rejection_counts)


@pytest.mark.parametrize("n_satellites", [4, 5])
def test_a_step_needs_five_agreeing_satellites(esbc_epochs, n_satellites):
    """Four satellites fit any position and clock, and under 30 dB J/S four coincident outliers were
    taken for steps (CLOCK_STEP_MIN_SATELLITES): from epoch 30 on only ``n_satellites`` high
    satellites are kept, and the clock steps by 1 ms at epoch 40."""
    def high(e: GnssEpoch) -> GnssEpoch:
        keep = [o for o in e.observations
                if azimuth_elevation(TRUTH, o.satellite_position_ecef_m)[1] > np.radians(35.0)]
        return replace(e, observations=tuple(keep[:n_satellites]))

    epochs = [e if k < 30 else high(e) for k, e in enumerate(esbc_epochs)]
    assert all(len(e.observations) == n_satellites for e in epochs[30:])
    f, _ = _run(_stepped(epochs, {40: MS_OF_LIGHT_M}))
    found = f.rejection_counts.get("receiver_clock_step_ms", 0)
    assert found == (1 if n_satellites >= 5 else 0)
