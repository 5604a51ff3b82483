"""The UWB range noise: the curvature (second-order) term and the per-anchor innovation-based
estimate (``FusionParams.uwb_range_curvature_noise``, ``uwb_range_noise_adaptive``; issue 15 item 2)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gnss_common.observations import UwbRangeMeasurement
from uwb_gnss_fusion.ckf_kernels import range_curvature_variance
from uwb_gnss_fusion.fusion_filter import FusionFilter, FusionParams
from uwb_gnss_fusion.uwb_update import (
    RangeNoiseEstimate,
    anchors_heard,
    range_curvature_variance_reference,
    range_std_with_shared_bias,
)

_ANCHORS = np.array([[12.0, 0.0, 1.5], [-6.0, 10.0, -0.5], [-5.0, -11.0, 0.8], [2.0, 12.0, 2.5]])


def _spd(rng: np.random.Generator, n: int) -> np.ndarray:
    a = rng.standard_normal((n, n))
    return a @ a.T + n * np.eye(n) * 0.1


@pytest.mark.parametrize("latency_s", [0.0, 0.15])
def test_compiled_curvature_variance_equals_the_hessian_formula(latency_s: float) -> None:
    """Oracle: 0.5 tr(A P_t A P_t), A the range Hessian, P_t the covariance of p + lever - lat v."""
    rng = np.random.default_rng(3)
    for _ in range(5):
        p = _spd(rng, 8)
        nominal = rng.standard_normal(8) * 3.0
        anchor, lever = rng.standard_normal(3) * 10.0, rng.standard_normal(3) * 0.2
        j = np.zeros((3, 8))
        j[:, 0:3] = np.eye(3)
        j[:, 3:6] = -latency_s * np.eye(3)
        p_tag = j @ p @ j.T
        los = nominal[0:3] + lever - latency_s * nominal[3:6] - anchor
        expected = range_curvature_variance_reference(p_tag, los)
        assert range_curvature_variance(p, nominal, anchor, lever, latency_s) == pytest.approx(expected, rel=1e-10)


def test_curvature_variance_is_zero_along_the_line_of_sight_and_s4_over_rho2_across() -> None:
    """Analytic: no variance across the line of sight, no term; an isotropic 1-sigma s across it at
    range rho: s^4 / rho^2 (the range error of a tangential offset is |d|^2 / (2 rho))."""
    nominal, lever = np.zeros(8), np.zeros(3)
    anchor = np.array([12.0, 0.0, 0.0])  # line of sight along x
    p = np.eye(8) * 1e-6
    p[0, 0] = 4.0
    assert range_curvature_variance(p, nominal, anchor, lever, 0.0) < 1e-12
    s = 1.3
    p = np.diag([1e-4, s * s, s * s, 1.0, 1.0, 1.0, 1.0, 1.0])
    assert range_curvature_variance(p, nominal, anchor, lever, 0.0) == pytest.approx(s**4 / 144.0, rel=1e-9)
    # Monte Carlo of the range's second-order part for the same covariance
    rng = np.random.default_rng(0)
    d = rng.standard_normal((200_000, 2)) * s
    second = (d**2).sum(axis=1) / (2 * 12.0)
    assert second.var() == pytest.approx(s**4 / 144.0, rel=0.03)


def test_noise_estimate_converges_to_the_true_variance_factor() -> None:
    """Innovations drawn with the state part S - R known: the estimate of alpha = R_true / sigma^2
    converges (stated 0.1 m, true 0.03 m: alpha 0.09)."""
    rng = np.random.default_rng(1)
    est = RangeNoiseEstimate(window=200, prior_weight=20, floor_m=0.01, ceiling_m=1.0)
    stated, true = 0.1, 0.03
    state_var = 0.02**2
    for _ in range(3000):
        used = est.std_m(stated)
        nu = rng.standard_normal() * math.sqrt(state_var + true**2)
        est.add(nu, state_var + used**2, used, stated)
    assert est.std_m(stated) == pytest.approx(true, rel=0.15)


def test_noise_estimate_ignores_samples_dominated_by_the_state_and_respects_its_bounds() -> None:
    """While S is a thousand times R a sample barely moves the estimate; the 1-sigma used stays in
    [floor, ceiling] (widened to the stated 1-sigma), and NaNs are ignored."""
    est = RangeNoiseEstimate(window=200, prior_weight=20, floor_m=0.01, ceiling_m=1.0)
    for _ in range(100):  # innovations of zero with S = 1000 R: samples of -999
        est.add(0.0, 1000.0 * 0.01, 0.1, 0.1)
    assert est.std_m(0.1) > 0.09
    est.add(math.nan, 0.02, 0.1, 0.1)
    assert math.isfinite(est.std_m(0.1))
    low = RangeNoiseEstimate(window=200, prior_weight=20, floor_m=0.01, ceiling_m=1.0)
    for _ in range(3000):
        low.add(0.0, 0.01, 0.1, 0.1)  # innovations of zero with S = R: alpha -> 0
    assert low.std_m(0.1) == pytest.approx(0.01)
    high = RangeNoiseEstimate(window=200, prior_weight=20, floor_m=0.01, ceiling_m=1.0)
    for _ in range(500):
        high.add(10.0, 0.01, 0.1, 0.1)
    assert high.std_m(0.1) == pytest.approx(1.0)
    assert high.std_m(3.0) == pytest.approx(3.0)  # the ceiling widened to a larger stated 1-sigma


def _uwb_run(noise_m: float, seconds: float, seed: int = 2, rate_hz: float = 20.0):
    """Static tag at (0.3, -0.4, 0.1) m in the map frame, four anchors, white range noise."""
    rng = np.random.default_rng(seed)
    tag = np.array([0.3, -0.4, 0.1])
    out = []
    for k in range(int(seconds * rate_hz)):
        for i, a in enumerate(_ANCHORS):
            stamp = int(k * 1e9 / rate_hz) + i * 1_000_000
            r = float(np.linalg.norm(tag - a)) + noise_m * rng.standard_normal()
            out.append(UwbRangeMeasurement(stamp, f"A{i + 1}", a, "map", r))
    return tag, out


def test_adaptive_noise_makes_the_uwb_filter_consistent() -> None:
    """The filter's range 1-sigma is its default 0.1 m, the ranges' noise 0.03 m. With the estimate
    every anchor's 1-sigma ends within 15 % of 0.03 m and the error / reported 1-sigma is near 1;
    without it the filter reports about three times its error (underconfident)."""
    tag, meas = _uwb_run(0.03, 120.0)

    def run(**kw):
        f = FusionFilter(FusionParams(use_gnss=False, accel_psd_m2ps3=0.01, **kw))
        z = []
        for i, m in enumerate(meas):
            out = f.process(m)
            if i >= len(meas) // 4 and out.initialized:
                z.append((out.position_m - tag) / np.sqrt(np.diag(out.covariance_pv[0:3, 0:3])))
        return f, float(np.sqrt(np.mean(np.square(z))))

    f_off, ratio_off = run(uwb_range_noise_adaptive=False)
    f_default, _ = run()    # without GNSS the estimate acts only when asked
    assert "uwb_noise_estimates" not in f_default.rejection_counts
    f_on, ratio_on = run(uwb_range_noise_adaptive_without_gnss=True)
    assert ratio_off < 0.6
    assert 0.6 < ratio_on < 1.6
    assert f_on.rejection_counts["uwb_noise_estimates"] == 4
    for est in f_on.uwb_noise.values():
        assert est.std_m(0.1) == pytest.approx(0.03, rel=0.15)


def test_curvature_term_enters_the_innovation_variance() -> None:
    """With the term on, the prior innovation variance of a range is larger by exactly the term
    at the prior (the filter started 2 m uncertain across the lines of sight)."""
    _, meas = _uwb_run(0.03, 1.0)
    f_on = FusionFilter(FusionParams(use_gnss=False, uwb_range_curvature_noise=True))
    f_off = FusionFilter(FusionParams(use_gnss=False, uwb_range_curvature_noise=False))
    for f in (f_on, f_off):
        f.initialize(0, np.array([0.3, -0.4, 0.1]), frame_id="map", position_std_m=2.0)
    m = meas[0]
    expected = range_curvature_variance(f_on.state.ckf.p, f_on.state.nominal, m.anchor_position_m, np.zeros(3), 0.0)
    assert expected > 1e-3  # (2 m)^2 across a 12 m line of sight: about (0.33 m)^2 per axis pair
    f_on.process(m)
    f_off.process(m)
    assert f_on.state.uwb_scratch[1] - f_off.state.uwb_scratch[1] == pytest.approx(expected, rel=1e-9)


def test_parameters_are_checked() -> None:
    with pytest.raises(ValueError):
        FusionParams(uwb_range_noise_window=5)
    with pytest.raises(ValueError):
        FusionParams(uwb_range_std_floor_m=2.0, uwb_range_std_ceiling_m=1.0)
    with pytest.raises(ValueError):
        FusionParams(uwb_range_std_floor_m=0.0)


def test_ranges_are_not_iterated_with_fewer_anchors_than_uwb_iterate_min_anchors() -> None:
    """uwb_iterate_min_anchors (issue 15 item 2): with GNSS in use, a range is refined (iterated update) only while
    at least that many anchors were heard within uwb_init_window_s; with 1-2 anchors the iterated point leaks
    information across the line of sight (docs/uwb_gnss_fusion/fusion_never_worse.md). Off (0; the default is 3):
    every range may be refined; the UWB-only filter (no GNSS) is never limited."""
    base = np.array([4_000_000.0, 1_000_000.0, 4_800_000.0])       # an Earth-frame (ECEF) tag position, m
    anchors = base + _ANCHORS

    def first_range_iterations(n_anchors: int, k: int, use_gnss: bool = True) -> float:
        f = FusionFilter(FusionParams(use_gnss=use_gnss, uwb_iterate_min_anchors=k))
        frame = "earth" if use_gnss else "map"
        a_set = anchors if use_gnss else _ANCHORS
        f.initialize(0, (base if use_gnss else np.zeros(3)) + np.array([1.5, -1.0, 1.2]), frame_id=frame,
                     position_std_m=2.0)
        for i in range(n_anchors):
            tag = base if use_gnss else np.zeros(3)
            f.process(UwbRangeMeasurement(1_000_000 * (i + 1), f"A{i + 1}", a_set[i], frame,
                                          float(np.linalg.norm(tag - a_set[i]))))
        return float(f.state.uwb_scratch[4])                      # refinement steps of the last range

    assert first_range_iterations(1, 0) > 0                  # 2 m off across the line of sight: refined
    assert first_range_iterations(1, 3) == 0
    assert first_range_iterations(2, 3) == 0
    assert first_range_iterations(3, 3) > 0
    assert first_range_iterations(1, 3, use_gnss=False) > 0
    with pytest.raises(ValueError):
        FusionParams(uwb_iterate_min_anchors=-1)


def test_ranges_of_one_anchor_share_a_bias_while_fewer_than_three_anchors_are_heard() -> None:
    """uwb_range_bias_std_m (issue 15 item 2): with GNSS in use and fewer than three anchors heard, the n-th
    range of an anchor within uwb_range_bias_time_s is applied with 1-sigma sqrt(std^2 + n sigma_b^2); with three
    anchors, without GNSS, or with the rule off, with std. Stamps older than the time drop out."""
    base = np.array([4_000_000.0, 1_000_000.0, 4_800_000.0])
    sigma_b, std = 0.05, 0.03

    def applied(n_anchors: int, use_gnss: bool = True, bias: float = sigma_b, dt_ns: int = 50_000_000,
                n_ranges: int = 6) -> list[float]:
        f = FusionFilter(FusionParams(use_gnss=use_gnss, uwb_range_bias_std_m=bias, uwb_range_bias_time_s=1.0))
        frame = "earth" if use_gnss else "map"
        tag = base if use_gnss else np.zeros(3)
        f.initialize(0, tag, frame_id=frame, position_std_m=0.5)
        out = []
        for k in range(n_ranges):
            stamp = dt_ns * (k + 1)
            for i in range(n_anchors):
                a = tag + _ANCHORS[i]
                f.state.recent_uwb[f"A{i + 1}"] = (stamp, a, 12.0, frame)
            out.append(range_std_with_shared_bias(f, stamp, "A1", std, anchors_heard(f, stamp)))
        return out

    one = applied(1)
    assert one[0] == std
    for n, value in enumerate(one[1:], start=2):
        assert value == pytest.approx(math.sqrt(std**2 + n * sigma_b**2), rel=1e-12)
    assert applied(2)[-1] == pytest.approx(math.sqrt(std**2 + 6 * sigma_b**2), rel=1e-12)
    assert applied(3) == [std] * 6
    assert applied(1, use_gnss=False) == [std] * 6
    assert applied(1, bias=0.0) == [std] * 6
    # 0.4 s apart with a 1 s time: at most three stamps (this one and the two before) share the bias
    assert applied(1, dt_ns=400_000_000)[-1] == pytest.approx(math.sqrt(std**2 + 3 * sigma_b**2), rel=1e-12)
    with pytest.raises(ValueError):
        FusionParams(uwb_range_bias_std_m=-0.1)
    with pytest.raises(ValueError):
        FusionParams(uwb_range_bias_time_s=0.0)


@pytest.mark.parametrize("seed", [116, 176])
def test_one_anchor_under_jamming_no_longer_collapses_the_height(seed: int) -> None:
    """The benchmark's +30 dB one-anchor cell (fusion_never_worse.py seeds 116 / 176, first 60 s): without the
    shared-bias rule a 20 Hz stream of one anchor's ranges, applied along a line of sight that turns as the estimate
    moves, made the filter metres off in height with a 1-sigma of decimetres (up error / 1-sigma 6-17); with it the
    height error is within a few of its 1-sigmas and the 3D error smaller."""
    from pathlib import Path

    from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic
    from gnss_common.observations import GnssEpoch
    from rfi_sim.gnss_uwb import PAPER_ANCHOR_RANGES_M, BroadcastGeometry, GnssUwbScenario, simulate

    nav = Path(__file__).resolve().parents[2] / "gnss_common" / "test" / "data" / "arlm2000.15n"
    geo = BroadcastGeometry(nav)
    sc = GnssUwbScenario(jsr_db=30.0, duration_s=60.0, seed=seed, anchor_ranges_m=(*PAPER_ANCHOR_RANGES_M, 12.0),
                         anchor_azimuths_deg=(20.0, 140.0, 260.0, 80.0), anchor_up_m=(1.5, -0.5, 0.8, 2.5))
    run = simulate(sc, geo, geo.iono_alpha, geo.iono_beta)
    truth = np.asarray(run.truth.receiver_ecef_m, dtype=float)
    lat, lon, _ = ecef_to_geodetic(truth)
    rot = ecef_to_enu_rotation(lat, lon)

    def score(**params) -> tuple[float, float]:
        f = FusionFilter(FusionParams(accel_psd_m2ps3=0.01, **params))
        t0 = run.gnss_epochs[0].stamp_ns
        errs, z_up = [], []
        for m in run.messages(anchor_ids=("A1",), gnss=True):
            out = f.process(m)
            if isinstance(m, GnssEpoch) and m.stamp_ns - t0 >= 20_000_000_000 and out.initialized:
                e = rot @ (out.position_m - truth)
                errs.append(e)
                z_up.append(e[2] / math.sqrt((rot @ out.covariance_pv[0:3, 0:3] @ rot.T)[2, 2]))
        assert len(errs) > 30
        return float(np.sqrt(np.mean(np.sum(np.square(errs), axis=1)))), float(np.sqrt(np.mean(np.square(z_up))))

    rms_on, z_on = score()
    rms_off, z_off = score(uwb_range_bias_std_m=0.0)
    assert z_off > 5.0 and z_on < 0.6 * z_off
    assert rms_on < rms_off


def test_a_stated_std_whose_square_underflows_is_not_a_sample():
    """A stated 1-sigma of 5e-324 (the fuzzer's subnormal) squares to 0: the sample divided by it raised
    ZeroDivisionError in the core (counted core exceptions); it is now ignored, and the estimate is unchanged."""
    est = RangeNoiseEstimate(window=100, prior_weight=20, floor_m=0.01, ceiling_m=1.0)
    est.add(0.1, 0.02, 0.1, 0.1)
    alpha, weight = est.alpha, est.weight
    est.add(0.1, 0.02, 0.1, 5e-324)
    assert (est.alpha, est.weight) == (alpha, weight)
