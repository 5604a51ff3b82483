"""UWB range ambiguities (issue 15 item 2): the mirror of coplanar anchors resolved by the GNSS
likelihood ratio (:mod:`uwb_gnss_fusion.mirror_test`), and the reinitialisation when one anchor is
persistently gated while a fix explains every anchor (``uwb_gated_anchor_reinit``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gnss_common.observations import UwbRangeMeasurement
from uwb_gnss_fusion.fusion_filter import FusionFilter, FusionParams
from uwb_gnss_fusion.mirror_test import (
    MirrorTest,
    anchor_plane,
    clock_free_chi2,
    householder,
    is_range_ambiguous,
    reflect,
)

# the benchmark's anchors (fusion_never_worse.py): the paper's three and a fourth, in a local
# east/north/up frame around the tag at the origin
_RANGES = (11.71, 13.00, 11.26, 12.0)
_AZ = (20.0, 140.0, 260.0, 80.0)
_UP = (1.5, -0.5, 0.8, 2.5)


def _local_anchors() -> np.ndarray:
    out = []
    for r, az, up in zip(_RANGES, _AZ, _UP, strict=True):
        h = math.sqrt(r * r - up * up)
        out.append([h * math.sin(math.radians(az)), h * math.cos(math.radians(az)), up])
    return np.array(out)


# ------------------------------------------------------------------ geometry and the statistic
def test_reflection_keeps_every_range_to_three_anchors() -> None:
    a = _local_anchors()[:3]
    c, n = anchor_plane(a)
    tag = np.zeros(3)
    m = reflect(tag, c, n)
    assert np.allclose(np.linalg.norm(a - tag, axis=1), np.linalg.norm(a - m, axis=1), atol=1e-12)
    assert np.linalg.norm(m - tag) > 1.0  # the tag is about 0.6 m off the anchors' plane
    assert is_range_ambiguous(tag, m, a, 0.1)
    # the fourth anchor (2.5 m up) tells them apart
    assert not is_range_ambiguous(tag, m, _local_anchors(), 0.1)
    # reflect is affine with linear part householder(n); twice is the identity
    x = np.array([[1.0, -2.0, 3.0], [0.5, 0.2, -0.1]])
    assert np.allclose(reflect(x, c, n) - reflect(np.zeros(3), c, n), x @ householder(n).T)
    assert np.allclose(reflect(reflect(x, c, n), c, n), x)


def test_collinear_or_too_few_anchors_have_no_plane() -> None:
    assert anchor_plane(np.zeros((2, 3))) is None
    assert anchor_plane(np.array([[0.0, 0, 0], [1, 0, 0], [5, 0, 0]])) is None


def test_clock_free_chi2_ignores_a_common_offset() -> None:
    rng = np.random.default_rng(1)
    r = rng.normal(size=(2, 7))
    s = rng.uniform(0.5, 2.0, 7)
    w = 1.0 / s**2
    c = (r * w).sum(axis=1, keepdims=True) / w.sum()
    assert np.allclose(clock_free_chi2(r, s), ((r - c) ** 2 * w).sum(axis=1))
    assert np.allclose(clock_free_chi2(r + 12.3, s), clock_free_chi2(r, s))


def test_mirror_statistic_scales_to_independent_samples_and_swaps() -> None:
    tau = 60.0
    t = MirrorTest(tau_s=tau, switch_log_lr=1.0)
    # chi2 current 4 over 8 satellites: variance factor 1 (floor); increment 0.5 * (4 - 2.3) * dt / (2 tau)
    dt = 0.2
    per_epoch = 0.5 * 1.7 * dt / (2.0 * tau)
    n_needed = math.floor(1.0 / per_epoch) + 1  # 706 (1 / per_epoch = 705.9)
    fired = [t.add(np.array([4.0, 2.3]), 8, dt) for _ in range(n_needed)]
    assert fired[-1] and not any(fired[:-1])
    assert t.log_lr == pytest.approx(-n_needed * per_epoch)
    # a variance factor of 4 (chi2 / dof) divides the evidence by 4
    t2 = MirrorTest(tau_s=tau, switch_log_lr=100.0)
    t2.add(np.array([16.0, 8.0]), 8, 0.0)  # first epoch: sets the factor, dt 0 adds nothing
    assert t2.variance_factor == pytest.approx(4.0) and t2.log_lr == 0.0
    t2.add(np.array([16.0, 8.0]), 8, dt)
    assert t2.log_lr == pytest.approx(0.5 * 8.0 * dt / (2.0 * tau) / 4.0)
    # fewer than four satellites carry no evidence
    assert not t2.add(np.array([100.0, 0.0]), 3, dt)


# ------------------------------------------------------------------ the filter on the simulator
@pytest.fixture(scope="module")
def clean_run():
    """120 s, no jamming, pseudorange errors white (jitter only), the benchmark's four anchors."""
    from pathlib import Path

    from rfi_sim.gnss_uwb import PAPER_ANCHOR_RANGES_M, BroadcastGeometry, GnssUwbScenario, simulate

    nav = Path(__file__).resolve().parents[2] / "gnss_common" / "test" / "data" / "arlm2000.15n"
    geo = BroadcastGeometry(nav)
    sc = GnssUwbScenario(
        jsr_db=None, duration_s=120.0, seed=7, correlated_error_std_m=0.0,
        anchor_ranges_m=(*PAPER_ANCHOR_RANGES_M, 12.0), anchor_azimuths_deg=_AZ, anchor_up_m=_UP,
    )
    return simulate(sc, geo, geo.iono_alpha, geo.iono_beta)


def _run_from_mirror(run, **params) -> tuple[FusionFilter, float, float]:
    """Start the filter on the mirror of the truth across anchors A1-A3 and run GNSS + A1-A3.
    Returns (filter, final distance to the truth, to the mirror), m."""
    truth = np.asarray(run.truth.receiver_ecef_m, dtype=float)
    c, n = anchor_plane(run.truth.anchor_ecef_m[:3])
    mirror = reflect(truth, c, n)
    f = FusionFilter(FusionParams(accel_psd_m2ps3=0.01, **params))
    f.initialize(run.gnss_epochs[0].stamp_ns, mirror, position_std_m=0.05)
    out = None
    for m in run.messages(anchor_ids=("A1", "A2", "A3"), gnss=True):
        if m.stamp_ns > run.gnss_epochs[0].stamp_ns:
            out = f.process(m)
    assert out is not None and out.initialized
    return f, float(np.linalg.norm(out.position_m - truth)), float(np.linalg.norm(out.position_m - mirror))


def test_mirror_test_moves_the_filter_to_the_side_gnss_favours(clean_run) -> None:
    f_off, to_truth_off, to_mirror_off = _run_from_mirror(clean_run, uwb_mirror_test=False)
    # without the test the ranges hold the filter on the mirror (the GNSS pull is too weak)
    assert to_mirror_off < 0.3 < 1.0 < to_truth_off
    assert "uwb_mirror_switch" not in f_off.rejection_counts
    f_on, to_truth_on, _ = _run_from_mirror(clean_run, uwb_mirror_test=True)
    assert f_on.rejection_counts.get("uwb_mirror_switch", 0) >= 1
    assert to_truth_on < 0.3


def test_gated_anchor_reinitialises_from_a_fix_that_explains_every_anchor() -> None:
    """The benchmark's failure (fusion_never_worse.py, +22 dB, seed 165): the GNSS start is metres
    off in height, the first ranges pull the state near the mirror of A1-A3 and the gate then keeps
    A4 out for the whole run. With ``uwb_gated_anchor_reinit`` the filter restarts from the
    four-anchor fix after ``divergence_uwb_ranges`` gated ranges of A4. The trap needs a start at the first
    epoch and ranges taken without their curvature variance (``divergence_fix_confirm_s`` 0 and
    ``uwb_range_curvature_noise`` false, the defaults until session 7); with the curvature term the first ranges
    no longer pull the state there."""
    from pathlib import Path

    from rfi_sim.gnss_uwb import PAPER_ANCHOR_RANGES_M, BroadcastGeometry, GnssUwbScenario, simulate

    nav = Path(__file__).resolve().parents[2] / "gnss_common" / "test" / "data" / "arlm2000.15n"
    geo = BroadcastGeometry(nav)
    sc = GnssUwbScenario(
        jsr_db=22.0, duration_s=30.0, seed=165,
        anchor_ranges_m=(*PAPER_ANCHOR_RANGES_M, 12.0), anchor_azimuths_deg=_AZ, anchor_up_m=_UP,
    )
    run = simulate(sc, geo, geo.iono_alpha, geo.iono_beta)
    truth = np.asarray(run.truth.receiver_ecef_m, dtype=float)

    def final_error(**params) -> tuple[FusionFilter, float]:
        f = FusionFilter(FusionParams(accel_psd_m2ps3=0.01, **params))
        errs = [np.linalg.norm(f.process(m).position_m - truth) for m in run.messages(gnss=True)]
        return f, float(np.sqrt(np.mean(np.square(errs[-2000:]))))  # the last 5 s

    old = dict(uwb_range_curvature_noise=False, divergence_fix_confirm_s=0.0)
    f_off, err_off = final_error(uwb_gated_anchor_reinit=False, **old)
    assert err_off > 1.0 and f_off.rejection_counts["innovation_gate_uwb"] > 500  # A4: 600 ranges in 30 s
    f_on, err_on = final_error(**old)
    assert f_on.rejection_counts.get("uwb_anchor_gated_reinit", 0) >= 1
    assert err_on < 0.2
    f_curv, err_curv = final_error(uwb_gated_anchor_reinit=False, divergence_fix_confirm_s=0.0)
    assert err_curv < 0.2 and f_curv.rejection_counts.get("innovation_gate_uwb", 0) < 100


@pytest.mark.parametrize("bias_m", [2.0, 1.0])
def test_a_biased_anchor_is_gated_without_cycling(bias_m: float) -> None:
    """UWB alone (map frame), started at the tag, A4 reads long (NLOS-like). 2 m: no fix explains
    every anchor within 4 sigma, so A4 stays gated and the filter is never restarted. 1 m: A4 is the
    anchor that carries the height, a fix 1.7 m low explains all four ranges and the filter restarts
    there once; it returns to the tag and is not restarted again (once per anchor id)."""
    anchors = _local_anchors()
    tag = np.zeros(3)
    rng = np.random.default_rng(3)
    f = FusionFilter(FusionParams(use_gnss=False, accel_psd_m2ps3=0.01))
    f.initialize(0, tag, frame_id="map", position_std_m=0.02)
    out = None
    for k in range(1, 20 * 10 + 1):  # 10 s at 20 Hz per anchor
        for j, a in enumerate(anchors):
            r = float(np.linalg.norm(a - tag)) + 0.03 * rng.standard_normal() + (bias_m if j == 3 else 0.0)
            out = f.process(UwbRangeMeasurement(stamp_ns=k * 50_000_000 + j * 10_000_000, anchor_id=f"A{j + 1}",
                                                anchor_position_m=a, range_m=r, frame_id="map"))
    assert out is not None
    counts = f.rejection_counts
    assert counts.get("uwb_anchor_gated_reinit", 0) == (0 if bias_m == 2.0 else 1)
    assert counts["innovation_gate_uwb"] >= 150
    # the three unbiased anchors hold the horizontal tightly and the height weakly (the tag is
    # 0.6 m from their plane: UWB alone with three anchors, 0.09 m 3D RMS in the benchmark)
    err = out.position_m - tag
    assert float(np.linalg.norm(err[:2])) < 0.05 and abs(float(err[2])) < 0.3


def test_per_anchor_rule_recovers_a_jump_the_consecutive_window_rule_misses() -> None:
    """test_fusion_filter's jump (the tag moves to a point at the same distance from anchor 1):
    with ``divergence_uwb_gated_fraction = 1`` the window rule never fires; the per-anchor rule
    restarts from the four-anchor fix."""
    anchors = np.array([[0.0, 0.0, 2.0], [10.0, 0.0, 0.5], [10.0, 10.0, 2.5], [0.0, 10.0, 0.3]])
    truth = np.array([4.0, 6.0, 1.0])
    rel = truth - anchors[0]
    c, s_ = math.cos(0.6), math.sin(0.6)
    jumped = anchors[0] + np.array([c * rel[0] - s_ * rel[1], s_ * rel[0] + c * rel[1], rel[2]])
    f = FusionFilter(FusionParams(use_gnss=False, accel_psd_m2ps3=0.01, divergence_uwb_gated_fraction=1.0))
    out = None
    for k in range(400):
        pos = truth if k < 200 else jumped
        a = anchors[k % 4]
        out = f.process_uwb(UwbRangeMeasurement(stamp_ns=k * 25_000_000, anchor_id=f"A{k % 4}", anchor_position_m=a,
                                                range_m=float(np.linalg.norm(a - pos)), frame_id="map"))
    assert out is not None
    counts = dict(out.rejection_counts)
    assert "divergence" not in counts
    assert counts.get("uwb_anchor_gated_reinit", 0) >= 1
    assert np.linalg.norm(out.position_m - jumped) < 0.05


def test_side_prior_puts_the_filter_on_the_side_the_installer_gives(clean_run) -> None:
    """uwb_tag_side_of_anchor_plane: the tag of the benchmark lies below the plane of A1-A3 (the mirror about
    1.2 m above it). Started on the mirror, the prior -1 (below) moves the filter to the truth; the prior +1
    (a wrong installation entry) keeps it on the mirror; the prior 0 is the filter without it."""
    truth = np.asarray(clean_run.truth.receiver_ecef_m, dtype=float)
    c, n = anchor_plane(clean_run.truth.anchor_ecef_m[:3])
    up = truth / np.linalg.norm(truth)
    assert float((truth - c) @ (n if float(n @ up) >= 0 else -n)) < -0.3       # the tag is below the plane
    f_below, to_truth, _ = _run_from_mirror(clean_run, uwb_tag_side_of_anchor_plane=-1)
    assert f_below.rejection_counts.get("uwb_side_prior_flip", 0) >= 1
    assert to_truth < 0.3
    f_above, to_truth_above, to_mirror_above = _run_from_mirror(clean_run, uwb_tag_side_of_anchor_plane=1)
    assert "uwb_side_prior_flip" not in f_above.rejection_counts
    assert to_mirror_above < 0.3 < 1.0 < to_truth_above
    with pytest.raises(ValueError):
        FusionParams(uwb_tag_side_of_anchor_plane=2)


@pytest.mark.parametrize("side", [-1, 0])
def test_side_prior_acts_without_gnss(side: int) -> None:
    """UWB alone in the map frame (+z up), A1-A3 only, the filter started on the mirror of the tag
    (about 1.2 m above it). With the prior -1 it moves to the truth within a few seconds of ranges
    (counted as uwb_side_prior_flip); without a prior it stays where the start put it. (Before,
    the prior was applied at GNSS epochs only, so a UWB-only filter kept the side its
    multilateration start happened to pick.)"""
    anchors = _local_anchors()[:3]
    tag = np.zeros(3)
    mirror = reflect(tag, *anchor_plane(anchors))
    assert mirror[2] > 1.0
    f = FusionFilter(FusionParams(use_gnss=False, accel_psd_m2ps3=0.01, uwb_tag_side_of_anchor_plane=side))
    f.initialize(0, mirror, frame_id="map", position_std_m=0.1)
    rng = np.random.default_rng(4)
    out = None
    for k in range(1, 101):  # 5 s at 20 Hz per anchor
        for i, a in enumerate(anchors):
            r = float(np.linalg.norm(tag - a)) + 0.03 * rng.standard_normal()
            out = f.process(UwbRangeMeasurement(k * 50_000_000 + i * 1_000_000, f"A{i + 1}", a, "map", r))
    assert out is not None
    if side:
        assert f.rejection_counts.get("uwb_side_prior_flip", 0) >= 1
        assert np.linalg.norm(out.position_m - tag) < 0.3
    else:
        assert "uwb_side_prior_flip" not in f.rejection_counts
        assert np.linalg.norm(out.position_m - mirror) < 0.3


def _rotate_about_line(x: np.ndarray, a: np.ndarray, b: np.ndarray, angle_rad: float) -> np.ndarray:
    """``x`` rotated about the line through ``a`` and ``b`` (keeps its distances to both)."""
    k = (b - a) / np.linalg.norm(b - a)
    v = x - a
    v_rot = v * math.cos(angle_rad) + np.cross(k, v) * math.sin(angle_rad) + k * (k @ v) * (1 - math.cos(angle_rad))
    return a + v_rot


@pytest.mark.parametrize("side", [-1, 0])
def test_gated_anchor_restart_with_three_anchors_needs_the_side(side: int) -> None:
    """The benchmark's 3-anchor miss (fusion_never_worse.py, +22 dB, seed 145): the state sits in a
    wrong local minimum where the ranges of A1 and A2 agree and A3's are all gated (there 3.7 m
    below the truth for 55 s). Constructed: UWB alone, the filter started on the circle of points
    with A1's and A2's ranges (the tag rotated by 40 deg about the A1-A2 line). Three anchors fix
    two points, mirrors of each other, so the per-anchor restart needs the installer's side: with
    -1 it restarts from the fix below the plane (the truth); without it the state stays wrong."""
    anchors = _local_anchors()[:3]
    tag = np.zeros(3)
    start = _rotate_about_line(tag, anchors[0], anchors[1], math.radians(40.0))
    assert abs(np.linalg.norm(start - anchors[2]) - np.linalg.norm(tag - anchors[2])) > 1.0
    # a static tag whose velocity is known (in the benchmark: from the Doppler), so that the
    # position uncertainty along the A1-A2 circle stays small and A3 stays gated
    f = FusionFilter(FusionParams(use_gnss=False, accel_psd_m2ps3=0.01, init_velocity_std_mps=0.01,
                                  uwb_tag_side_of_anchor_plane=side))
    f.initialize(0, start, frame_id="map", position_std_m=0.05)
    rng = np.random.default_rng(6)
    out = None
    for k in range(1, 201):  # 10 s at 20 Hz per anchor
        for i, a in enumerate(anchors):
            r = float(np.linalg.norm(tag - a)) + 0.03 * rng.standard_normal()
            out = f.process(UwbRangeMeasurement(k * 50_000_000 + i * 1_000_000, f"A{i + 1}", a, "map", r))
    assert out is not None
    if side:
        assert f.rejection_counts.get("uwb_anchor_gated_reinit", 0) == 1
        assert np.linalg.norm(out.position_m - tag) < 0.2
    else:
        assert "uwb_anchor_gated_reinit" not in f.rejection_counts
        assert np.linalg.norm(out.position_m - tag) > 1.0


# ------------------------------------------------------------------ the ambiguity in the published covariance
def test_mirror_probability_oracle() -> None:
    from uwb_gnss_fusion.mirror_test import mirror_wrong_side_probability

    # Phi(-d / (2 sigma)): d = 2 sigma -> Phi(-1) = 0.15866
    assert mirror_wrong_side_probability(4.0, 2.0) == pytest.approx(0.158655, abs=1e-6)
    assert mirror_wrong_side_probability(0.0, 2.0) == pytest.approx(0.5)
    assert mirror_wrong_side_probability(1.28, None) == 0.5      # without GNSS nothing picks the side
    assert mirror_wrong_side_probability(50.0, 2.0) < 1e-10     # a mirror far away: GNSS tells


def _uwb_only_from(start: np.ndarray, anchors: np.ndarray, **params) -> tuple[FusionFilter, object]:
    """UWB alone in the map frame, the tag at the origin, started at ``start``; 2 s of ranges."""
    f = FusionFilter(FusionParams(use_gnss=False, accel_psd_m2ps3=0.01, **params))
    f.initialize(0, start, frame_id="map", position_std_m=0.1)
    rng = np.random.default_rng(5)
    out = None
    for k in range(1, 41):
        for i, a in enumerate(anchors):
            r = float(np.linalg.norm(a)) + 0.03 * rng.standard_normal()
            out = f.process(UwbRangeMeasurement(k * 50_000_000 + i * 1_000_000, f"A{i + 1}", a, "map", r))
    return f, out


def test_published_covariance_covers_the_mirror_of_three_anchors() -> None:
    """Three anchors, UWB alone, started on the mirror of the tag (0.64 m on the other side of the
    anchors' plane): the filter stays on that side. The published covariance is the filter's own plus
    p d^2 along the plane's normal, p = 0.5 without GNSS and d the distance from the estimate to its own
    mirror. The installer's side (the ambiguity resolved) or uwb_mirror_covariance false publish the
    filter's own covariance, and a fourth anchor off the plane removes the ambiguity and the term."""
    anchors = _local_anchors()
    c, n = anchor_plane(anchors[:3])
    assert float((np.zeros(3) - c) @ n) == pytest.approx(-0.639, abs=1e-3)
    mirror = reflect(np.zeros(3), c, n)
    f, out = _uwb_only_from(mirror, anchors[:3])
    side = float((out.position_m - c) @ n)
    assert side > 0.0                                           # on the mirror's side (the truth is the origin)
    own = f.state.ckf.p[0:3, 0:3]
    pub = out.covariance_pv[0:3, 0:3]
    # the filter's own covariance plus p d^2 n n^T (rank one, along the normal), p = 0.5 without GNSS
    np.testing.assert_allclose(pub - own, 0.5 * (2.0 * side) ** 2 * np.outer(n, n), rtol=1e-9, atol=1e-12)
    pub = float(n @ pub @ n)
    err_n = abs(float(out.position_m @ n))
    assert err_n < 2.0 * math.sqrt(pub)
    np.testing.assert_array_equal(out.covariance_pv[3:6, 3:6], f.state.ckf.p[3:6, 3:6])  # velocity untouched
    for params in ({"uwb_mirror_covariance": False}, {"uwb_tag_side_of_anchor_plane": 1}):
        g, o = _uwb_only_from(mirror, anchors[:3], **params)
        np.testing.assert_array_equal(o.covariance_pv, g.state.ckf.p[0:6, 0:6])
    g, o = _uwb_only_from(np.zeros(3), anchors)                 # four anchors, not coplanar
    np.testing.assert_array_equal(o.covariance_pv, g.state.ckf.p[0:6, 0:6])
    # four anchors in one plane: as ambiguous as three (the fourth moved into the plane of A1-A3)
    coplanar = anchors.copy()
    coplanar[3] -= ((coplanar[3] - c) @ n) * n
    g, o = _uwb_only_from(mirror, coplanar)
    side4 = float((o.position_m - c) @ n)
    np.testing.assert_allclose(o.covariance_pv[0:3, 0:3] - g.state.ckf.p[0:3, 0:3],
                               0.5 * (2.0 * side4) ** 2 * np.outer(n, n), rtol=1e-9, atol=1e-12)
    assert is_range_ambiguous(o.position_m, reflect(o.position_m, c, n), coplanar, 0.1)
