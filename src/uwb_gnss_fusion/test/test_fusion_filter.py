"""Behaviour tests of the GNSS/UWB fusion filter on small synthetic scenarios (seeded, fast)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic, enu_to_ecef
from gnss_common.jamming_weights import dll_jitter_m
from gnss_common.observations import GnssEpoch, SatelliteObservation, UwbRangeMeasurement
from uwb_gnss_fusion.fusion_filter import (
    MODE_GNSS,
    MODE_GNSS_UWB,
    FusionFilter,
    FusionOutput,
    FusionParams,
    ReorderBuffer,
)
from uwb_gnss_fusion.input_checks import validate_satellites

RX = np.array([-740289.918, -5457071.734, 3207245.542])
LAT, LON, _ = ecef_to_geodetic(RX)
R_ENU = ecef_to_enu_rotation(LAT, LON)
NS = 1_000_000_000
T0 = 1_000 * NS
# Satellites at fixed azimuth/elevation, 20200 km altitude-ish, expressed in ECEF (static geometry
# is enough for the filter logic; the orbits come in with the simulator).
AZ_EL_DEG = [(0, 75), (60, 35), (130, 50), (200, 25), (250, 60), (310, 30), (100, 15), (170, 80)]


def _sat_positions():
    out = []
    for az, el in AZ_EL_DEG:
        a, e = math.radians(az), math.radians(el)
        u = np.array([math.cos(e) * math.sin(a), math.cos(e) * math.cos(a), math.sin(e)])
        out.append(enu_to_ecef(u * 2.2e7, RX))
    return np.array(out)


SATS = _sat_positions()
ANCHORS = RX + np.array([[8.0, 9.0, 1.0], [-11.0, 4.0, -0.5], [2.0, -11.0, 0.8]]) @ R_ENU


def _epoch(stamp_ns, clock_m=150.0, drift_mps=0.0, rng=None, sigma=0.5, bias=None, svids=None, cn0=45.0):
    obs = []
    for i, sp in enumerate(SATS):
        rho = np.linalg.norm(sp - RX) + 7.2921151467e-5 / 299792458.0 * (sp[0] * RX[1] - sp[1] * RX[0])
        noise = 0.0 if rng is None else sigma * rng.standard_normal()
        extra = 0.0 if bias is None else bias.get(i + 1, 0.0)
        los = (sp - RX) / np.linalg.norm(sp - RX)
        vs = np.zeros(3)
        obs.append(
            SatelliteObservation(
                constellation=1,
                svid=(i + 1) if svids is None else svids[i],
                pseudorange_m=float(rho + clock_m + noise + extra),
                pseudorange_rate_mps=float(drift_mps + los @ vs),
                cn0_dbhz=cn0,
                satellite_position_ecef_m=sp.copy(),
                satellite_velocity_ecef_mps=vs,
                satellite_clock_bias_m=0.0,
                satellite_clock_drift_mps=0.0,
            )
        )
    return GnssEpoch(
        stamp_ns=int(stamp_ns), gps_week=2000, gps_time_of_week_s=stamp_ns / NS, observations=tuple(obs)
    )


def _uwb(stamp_ns, j, rng=None, sigma=0.03, frame="earth", anchors=ANCHORS, truth=RX, anchor_id=None):
    r = float(np.linalg.norm(anchors[j] - truth)) + (0.0 if rng is None else sigma * rng.standard_normal())
    return UwbRangeMeasurement(
        stamp_ns=int(stamp_ns),
        anchor_id=anchor_id or f"A{j + 1}",
        anchor_position_m=anchors[j].copy(),
        frame_id=frame,
        range_m=r,
    )


def _horizontal_error(out: FusionOutput) -> float:
    e = R_ENU @ (out.position_m - RX)
    return float(math.hypot(e[0], e[1]))


def _run_gnss(f, n, rng, start=T0, dt_ns=NS // 5, **kw):
    out = None
    for k in range(n):
        out = f.process_gnss(_epoch(start + k * dt_ns, rng=rng, **kw))
    return out


# ----------------------------------------------------------------------------- params
@pytest.mark.parametrize(
    "kwargs",
    [
        dict(accel_psd_m2ps3=-1.0),
        dict(accel_psd_m2ps3=float("nan")),
        dict(gate_probability=0.0),
        dict(uwb_range_std_m=0.0),
        dict(min_satellites_init=3),
        dict(use_gnss=False, use_uwb=False),
        dict(anchors=(("a", 0.0, 0.0, 0.0), ("a", 1.0, 0.0, 0.0))),
        dict(uwb_lever_arm_m=(0.0, 0.0)),
        dict(clock_h_minus2_hz=-1.0),
        dict(uwb_latency_s=-0.1),
        dict(max_update_iterations=-1),
        dict(nonlinearity_threshold=0.0),
        dict(uwb_huber_k=0.0),
        dict(uwb_huber_k_positive=float("nan")),
        dict(divergence_uwb_gated_fraction=0.0),
        dict(divergence_uwb_gated_fraction=1.5),
    ],
)
def test_params_validation(kwargs):
    with pytest.raises(ValueError):
        FusionParams(**kwargs)


def test_gate_threshold_is_chi2_quantile():
    assert FusionParams(gate_probability=0.9999).gate_nis == pytest.approx(15.1367, abs=1e-3)
    assert math.isinf(FusionParams(gate_probability=1.0).gate_nis)


# ----------------------------------------------------------------------------- GNSS only
def test_gnss_only_noise_free_converges_to_truth_and_clock():
    f = FusionFilter(FusionParams(use_uwb=False))
    out = _run_gnss(f, 50, None, clock_m=1234.5, drift_mps=0.0)
    assert out.initialized and out.frame_id == "earth" and out.mode == MODE_GNSS
    np.testing.assert_allclose(out.position_m, RX, atol=1e-3)
    assert out.clock_bias_m == pytest.approx(1234.5, abs=1e-3)
    assert out.satellites_used == len(SATS)
    lat, lon, h = out.geodetic
    assert lat == pytest.approx(math.degrees(LAT), abs=1e-8) and lon == pytest.approx(
        math.degrees(LON), abs=1e-8
    )
    cov = out.position_covariance_enu_m2
    np.testing.assert_allclose(cov, cov.T, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        out.stamp_ns = 0  # type: ignore[misc]


def test_before_initialisation_output_is_flagged_and_nan():
    f = FusionFilter()
    out = f.process_gnss(GnssEpoch(stamp_ns=T0, gps_week=2000, gps_time_of_week_s=0.0))
    assert not out.initialized
    assert np.all(np.isnan(out.position_m))
    assert dict(out.rejection_counts)["no_satellites"] == 1


def test_nis_is_consistent_with_noise_model():
    rng = np.random.default_rng(5)
    f = FusionFilter(FusionParams(use_uwb=False, use_doppler=False, accel_psd_m2ps3=1e-4))
    nis = []
    for k in range(300):
        out = f.process_gnss(_epoch(T0 + k * NS // 5, rng=rng, sigma=0.5, cn0=45.0))
        if k > 20:
            nis.append(out.normalized_innovation_squared)
    # the weights come from the DLL model at 45 dB-Hz with its 0.5 m floor; the noise is 0.5 m
    sig = math.hypot(f.params.loop.code_floor_m, float(dll_jitter_m(45.0, f.params.loop)))
    expected = (0.5 / sig) ** 2
    assert np.mean(nis) == pytest.approx(expected, rel=0.2)


# ----------------------------------------------------------------------------- robustness
def test_outlier_burst_recovery_within_5_s():
    rng = np.random.default_rng(7)
    f = FusionFilter(FusionParams(use_uwb=False, accel_psd_m2ps3=0.01))
    errors = []
    for k in range(400):  # 80 s at 5 Hz; bursts on sat 2 (+150 m) at 30-32 s and sats 3,5 (-60 m) at 50-51 s
        t = k / 5
        bias = {}
        if 30 <= t < 32:
            bias = {2: 150.0}
        if 50 <= t < 51:
            bias = {3: -60.0, 5: -60.0}
        out = f.process_gnss(_epoch(T0 + k * NS // 5, rng=rng, bias=bias))
        errors.append(np.linalg.norm(out.position_m - RX))
    errors = np.array(errors)
    counts = dict(out.rejection_counts)
    # every outlier is caught, by the common-mode screen (default) or by the CKF gate
    caught = counts.get("common_mode_pseudorange", 0) + counts.get("innovation_gate_pseudorange", 0)
    assert caught >= 10 + 2 * 5
    for start in (30, 50):
        pre = np.sqrt(np.mean(errors[(start - 5) * 5 : start * 5] ** 2))
        post = errors[(start + 2 + 5) * 5]
        assert post <= 2 * pre, (start, pre, post)
        assert errors[start * 5 : (start + 2) * 5].max() <= 2 * pre + 0.5


def test_bad_inputs_are_counted_never_crash_never_nan():
    rng = np.random.default_rng(9)
    f = FusionFilter(FusionParams(anchors=(("A1", *ANCHORS[0]), ("A2", *ANCHORS[1]), ("A3", *ANCHORS[2])),
                                  divergence_fix_confirm_s=0.0))   # started by the first epoch
    _run_gnss(f, 10, rng)
    t = T0 + 2 * NS
    good = _epoch(t, rng=rng)
    o = list(good.observations)
    o[0] = dataclasses.replace(o[0], pseudorange_m=float("nan"))
    o[1] = dataclasses.replace(o[1], satellite_position_ecef_m=np.array([np.inf, 0.0, 0.0]))
    o[2] = dataclasses.replace(o[2], svid=o[3].svid)  # duplicate
    below = dataclasses.replace(
        o[4], svid=30, satellite_position_ecef_m=enu_to_ecef(np.array([2.2e7, 0.0, -1e6]), RX)
    )
    o.append(below)
    o[5] = dataclasses.replace(o[5], pseudorange_m=-5.0)
    outs = [f.process_gnss(dataclasses.replace(good, observations=tuple(o)))]
    outs.append(f.process_gnss(GnssEpoch(stamp_ns=t + NS // 5, gps_week=2000, gps_time_of_week_s=0.0)))
    three = _epoch(t + 2 * NS // 5, rng=rng)
    outs.append(f.process_gnss(dataclasses.replace(three, observations=three.observations[:3])))
    outs.append(f.process_uwb(dataclasses.replace(_uwb(t + 3 * NS // 5, 0), range_m=-1.0)))
    outs.append(f.process_uwb(dataclasses.replace(_uwb(t + 3 * NS // 5, 0), range_m=float("nan"))))
    outs.append(f.process_uwb(_uwb(t + 3 * NS // 5, 0, anchor_id="ghost")))
    outs.append(
        f.process_uwb(dataclasses.replace(_uwb(t + 3 * NS // 5, 0), anchor_position_m=np.array([1.0, 2.0])))
    )
    outs.append(f.process_gnss(_epoch(t - NS, rng=rng)))  # in the past
    outs.append(f.process_uwb(_uwb(-5, 1)))
    counts = dict(outs[-1].rejection_counts)
    for reason in (
        "nonfinite_pseudorange",
        "duplicate_svid",
        "below_elevation_mask",
        "nonphysical_pseudorange",
        "no_satellites",
        "fewer_than_4_satellites",
        "negative_range",
        "nonfinite_range",
        "unknown_anchor",
        "out_of_order",
        "invalid_stamp",
    ):
        assert counts.get(reason, 0) >= 1, reason
    assert counts["duplicate_svid"] == 2
    for out in outs:
        assert out.initialized and np.all(np.isfinite(out.position_m))
    assert outs[0].satellites_used == len(SATS) + 1 - 6  # 9 given: NaN, inf, 2 duplicates, negative, below
    assert outs[2].satellites_used == 3  # tightly coupled: fewer than 4 satellites still update
    # a stamp far in the future resets and re-initialises from that epoch
    out = f.process_gnss(_epoch(t + int((f.params.max_prediction_s + 10.0) * NS), rng=rng))
    assert dict(out.rejection_counts)["time_gap_reset"] == 1 and out.initialized
    with pytest.raises(TypeError):
        f.process_gnss(dataclasses.replace(good, stamp_ns=1.5))
    with pytest.raises(TypeError):
        f.process("not a measurement")


def test_jammer_information_inflates_pseudorange_variance():
    rng1, rng2 = np.random.default_rng(11), np.random.default_rng(11)
    a = FusionFilter(FusionParams(use_uwb=False))
    b = FusionFilter(FusionParams(use_uwb=False))
    _run_gnss(a, 5, rng1)
    _run_gnss(b, 5, rng2)
    a.set_jammer_to_signal(T0 + NS, 35.0)
    oa = _run_gnss(a, 5, rng1, start=T0 + NS)
    ob = _run_gnss(b, 5, rng2, start=T0 + NS)
    assert oa.jammer_to_signal_db == 35.0 and math.isnan(ob.jammer_to_signal_db)
    assert np.trace(oa.covariance_pv[:3, :3]) > 1.5 * np.trace(ob.covariance_pv[:3, :3])
    # stale J/S is ignored
    oc = _run_gnss(a, 1, rng1, start=T0 + 10 * NS)
    assert math.isnan(oc.jammer_to_signal_db)


# ----------------------------------------------------------------------------- UWB
def test_gnss_plus_uwb_beats_gnss_only_horizontally():
    rng_a, rng_b = np.random.default_rng(13), np.random.default_rng(13)
    urng = np.random.default_rng(14)
    g = FusionFilter(FusionParams(use_uwb=False, accel_psd_m2ps3=0.01))
    gu = FusionFilter(FusionParams(accel_psd_m2ps3=0.01))
    err_g, err_gu = [], []
    for k in range(300):
        t = T0 + k * NS // 5
        og = g.process_gnss(_epoch(t, rng=rng_a))
        ogu = gu.process_gnss(_epoch(t, rng=rng_b))
        for j in range(3):
            ogu = gu.process_uwb(_uwb(t + (j + 1) * NS // 20, j, rng=urng))
        g.process_uwb(_uwb(t + NS // 20, 0))  # ignored by the GNSS-only baseline
        if k > 50:
            err_g.append(_horizontal_error(og))
            err_gu.append(_horizontal_error(ogu))
    assert ogu.mode == MODE_GNSS_UWB and ogu.uwb_used == 1
    assert dict(g.rejection_counts)["uwb_disabled"] == 300
    assert np.sqrt(np.mean(np.square(err_gu))) < 0.1
    assert np.sqrt(np.mean(np.square(err_gu))) < 0.5 * np.sqrt(np.mean(np.square(err_g)))


def test_uwb_only_local_frame_with_four_anchors():
    anchors = np.array([[0.0, 0.0, 2.0], [10.0, 0.0, 0.5], [10.0, 10.0, 2.5], [0.0, 10.0, 0.3]])
    truth = np.array([4.0, 6.0, 1.0])
    rng = np.random.default_rng(17)
    f = FusionFilter(FusionParams(use_gnss=False, accel_psd_m2ps3=0.01))
    out = None
    for k in range(400):
        out = f.process_uwb(
            _uwb(T0 + k * NS // 40, k % 4, rng=rng, frame="map", anchors=anchors, truth=truth)
        )
    assert out.initialized and out.frame_id == "map" and math.isnan(out.clock_bias_m)
    err = out.position_m - truth
    assert math.hypot(err[0], err[1]) < 0.03
    # the height is weakly observed by near-coplanar anchors: the estimate must be consistent
    assert np.all(np.abs(err) < 3.0 * np.sqrt(np.diag(out.covariance_pv)[:3]))
    assert all(math.isnan(v) for v in out.geodetic)
    # a GNSS epoch cannot be used in the local frame: counted, not crashed
    out = f.process_gnss(_epoch(T0 + 11 * NS))
    assert dict(out.rejection_counts)["gnss_disabled"] == 1


@pytest.mark.parametrize("fraction", [1.0, 0.5])
def test_divergence_when_most_anchors_disagree_even_if_one_agrees(fraction):
    # The tag jumps to a point at the same distance from anchor 1: anchor 1 keeps agreeing with the
    # stale estimate, the other three are gated. The original rule (consecutive gated ranges,
    # fraction 1) never fires; the windowed rule declares divergence and multilaterates.
    anchors = np.array([[0.0, 0.0, 2.0], [10.0, 0.0, 0.5], [10.0, 10.0, 2.5], [0.0, 10.0, 0.3]])
    truth = np.array([4.0, 6.0, 1.0])
    rel = truth - anchors[0]
    c, s_ = math.cos(0.6), math.sin(0.6)
    jumped = anchors[0] + np.array([c * rel[0] - s_ * rel[1], s_ * rel[0] + c * rel[1], rel[2]])
    # the window rule alone (the per-anchor rule, uwb_gated_anchor_reinit, would also recover the
    # state here: test_mirror_ambiguity.py)
    f = FusionFilter(FusionParams(use_gnss=False, accel_psd_m2ps3=0.01, divergence_uwb_gated_fraction=fraction,
                                  uwb_gated_anchor_reinit=False))
    out = None
    for k in range(400):
        pos = truth if k < 200 else jumped
        out = f.process_uwb(_uwb(T0 + k * NS // 40, k % 4, frame="map", anchors=anchors, truth=pos))
    counts = dict(out.rejection_counts)
    if fraction == 1.0:
        assert "divergence" not in counts and out.reinitializations == 0
        assert np.linalg.norm(out.position_m - jumped) > 0.5  # lost, and not saying so
    else:
        assert counts["divergence"] >= 1 and out.reinitializations >= 1
        assert np.linalg.norm(out.position_m - jumped) < 0.05


def test_map_frame_uwb_rejected_by_earth_filter():
    f = FusionFilter(FusionParams(divergence_fix_confirm_s=0.0))
    _run_gnss(f, 3, None)
    out = f.process_uwb(_uwb(T0 + NS, 0, frame="map"))
    assert dict(out.rejection_counts)["uwb_frame_mismatch"] == 1


def test_uwb_initialises_then_gnss_sets_clock_switching_modes():
    f = FusionFilter(FusionParams(accel_psd_m2ps3=0.01))
    rng = np.random.default_rng(19)
    for k in range(90):
        out = f.process_uwb(_uwb(T0 + k * NS // 60, k % 3, rng=rng))
        # three anchors: two mirror solutions, so the filter waits a whole uwb_init_window_s
        assert out.initialized == (k >= 60)
    assert out.initialized and math.isnan(out.clock_bias_m)
    out = _run_gnss(f, 20, None, start=T0 + 3 * NS // 2, clock_m=777.0)
    assert out.clock_bias_m == pytest.approx(777.0, abs=0.5)
    assert np.linalg.norm(out.position_m - RX) < 0.5


def test_uwb_multilateration_finds_the_tag_all_around_the_anchors():
    # Four non-coplanar anchors of a compact cluster (like the Hanyang set-up); noise-free ranges
    # from tags all around it, near and far: the initial fix is the unique solution. A single
    # Gauss-Newton start from the centroid can stop in a local minimum; the multi-start cannot.
    anchors = np.array([[2.58, -0.87, 1.97], [-0.05, -0.9, 0.6], [2.5, 0.85, 1.2], [0.0, 0.8, 2.4]])
    for radius in (4.0, 15.0, 50.0):
        for ang in np.radians(np.arange(0.0, 360.0, 30.0)):
            truth = np.array([radius * math.cos(ang), radius * math.sin(ang), 0.1])
            f = FusionFilter(FusionParams(use_gnss=False))
            outs = [
                f.process_uwb(_uwb(T0 + j * NS // 40, j, frame="map", anchors=anchors, truth=truth))
                for j in range(4)
            ]
            # fewer than four anchors in the window: wait (three leave two mirror solutions)
            assert [o.initialized for o in outs] == [False, False, False, True]
            np.testing.assert_allclose(outs[-1].position_m, truth, atol=1e-4)


def test_snapshot_fix_inconsistent_with_uwb_ranges_is_refused():
    # A GNSS snapshot fix must agree with the recent UWB ranges (within the chi-square gate, with
    # the fix's init_position_std_m as its 1-sigma); a jammed epoch whose outliers could not be
    # excluded must not replace a state the UWB supports. Here the range says the tag is 100 m
    # further from anchor 1 than the fix: refused, until the range is older than the window.
    for offset_m, expect_init in ((100.0, False), (0.0, True)):
        f = FusionFilter(FusionParams(divergence_fix_confirm_s=0.0))   # a fix may start the filter at once
        r = _uwb(T0, 0)
        f.process_uwb(dataclasses.replace(r, range_m=r.range_m + offset_m))  # one anchor: no multilateration
        out = f.process_gnss(_epoch(T0 + NS // 10))
        assert out.initialized == expect_init
        assert dict(out.rejection_counts).get("gnss_fix_inconsistent_with_uwb", 0) == (0 if expect_init else 1)
    out = f.process_gnss(_epoch(T0 + 2 * NS))
    assert out.initialized


@pytest.mark.parametrize("clock_steps", [False, True])
def test_gnss_divergence_while_uwb_agrees_resets_the_clock_not_the_position(clock_steps):
    # A receiver clock step of 3 km. Without the clock-step rule every pseudorange is gated for
    # divergence_gnss_epochs epochs and GNSS declares divergence; the UWB ranges still agree with the
    # state, so the position is kept and only the clock is re-solved (no snapshot reinitialisation, no
    # reset). With it (the default) the step is found at its first epoch and the clock moved by it.
    rng = np.random.default_rng(31)
    f = FusionFilter(FusionParams(accel_psd_m2ps3=0.01, receiver_clock_steps=clock_steps))
    out = None
    errors = []
    for k in range(5 * 30):  # 30 s of GNSS at 5 Hz, 3 anchors at 20 Hz each in between
        t = T0 + k * NS // 5
        clock = 150.0 if k < 5 * 15 else 3150.0
        out = f.process_gnss(_epoch(t, clock_m=clock, rng=rng))
        for j in range(12):
            out = f.process_uwb(_uwb(t + (j + 1) * NS // 65, j % 3, rng=rng))
        if k >= 5 * 5:
            errors.append(_horizontal_error(out))
    counts = dict(out.rejection_counts)
    if clock_steps:
        assert counts["receiver_clock_step"] == 1 and "divergence" not in counts and out.reinitializations == 0
        assert "innovation_gate_pseudorange" not in counts
    else:
        assert counts["clock_reset_uwb_consistent"] >= 1 and "receiver_clock_step" not in counts
        assert "reset_uninitialized" not in counts and out.reinitializations == counts["clock_reset_uwb_consistent"]
    assert max(errors) < 0.1
    assert out.clock_bias_m == pytest.approx(3150.0, abs=1.0)


def test_clock_drift_unobserved_without_doppler_and_kept_on_reinitialisation():
    # No Doppler, 30 s epochs (a RINEX station), receiver clock drifting at +400 m/s: the first fix
    # cannot observe the drift; with init_clock_drift_unobserved_std_mps (1000 m/s) the second
    # epoch solves it. With a 1 m/s prior the 12 km clock error gates every pseudorange.
    def run(unobserved_std):
        rng = np.random.default_rng(37)
        # receiver_clock_steps off: this is the drift prior's test (the clock-step rule would take the 12 km
        # of an unsolved drift for steps and move the clock epoch after epoch)
        f = FusionFilter(FusionParams(use_uwb=False, use_doppler=False, receiver_clock_steps=False,
                                      init_clock_drift_unobserved_std_mps=unobserved_std))
        out = None
        for k in range(8):
            out = f.process_gnss(_epoch(T0 + 30 * k * NS, clock_m=150.0 + 400.0 * 30 * k, rng=rng))
        return f, out

    f, out = run(1000.0)
    counts = dict(out.rejection_counts)
    assert "innovation_gate_pseudorange" not in counts and "divergence" not in counts
    assert out.clock_drift_mps == pytest.approx(400.0, abs=0.5)
    assert _horizontal_error(out) < 1.0
    _, bad = run(1.0)
    assert dict(bad.rejection_counts)["innovation_gate_pseudorange"] >= 8
    # a reinitialisation without a drift keeps the drift of the lost state (same oscillator)
    again = f.initialize(out.stamp_ns, RX + 5.0, clock_bias_m=out.clock_bias_m)
    assert again.clock_drift_mps == pytest.approx(out.clock_drift_mps)
    fresh = FusionFilter().initialize(T0, RX, clock_bias_m=0.0)
    assert fresh.clock_drift_mps == 0.0


# ----------------------------------------------------------------------------- divergence
def test_divergence_detected_and_reinitialised_from_snapshot():
    rng = np.random.default_rng(23)
    f = FusionFilter(FusionParams(use_uwb=False))
    f.initialize(T0, RX + np.array([400.0, -300.0, 200.0]), clock_bias_m=150.0, position_std_m=0.5)
    diverged = []
    out = None
    for k in range(1, 40):
        out = f.process_gnss(_epoch(T0 + k * NS // 5, rng=rng))
        diverged.append(out.diverged)
    assert any(diverged) and out.reinitializations >= 1
    assert dict(out.rejection_counts)["divergence"] >= 1
    assert np.linalg.norm(out.position_m - RX) < 3.0


def test_divergence_reinitialises_from_supplied_reference():
    f = FusionFilter(FusionParams(use_uwb=False, min_satellites_init=8, divergence_gnss_epochs=2))
    f.initialize(T0, RX + np.array([400.0, 0.0, 0.0]), clock_bias_m=150.0, position_std_m=0.5)
    f.supply_reference_solution(T0, RX + np.array([1.0, 0.0, 0.0]), 2.0, clock_bias_m=150.0)
    # only 7 satellites: the internal snapshot needs 8, so the reference must be used
    outs = [
        f.process_gnss(dataclasses.replace(e, observations=e.observations[:7]))
        for e in (_epoch(T0 + k * NS // 5) for k in range(1, 4))
    ]
    first = next(o for o in outs if o.diverged)
    np.testing.assert_allclose(first.position_m, RX + np.array([1.0, 0.0, 0.0]), atol=1e-6)


def test_divergence_asks_the_reference_provider_only_then():
    asked = []

    def provider(stamp_ns):
        asked.append(stamp_ns)
        return T0, RX + np.array([1.0, 0.0, 0.0]), 2.0, 150.0

    f = FusionFilter(FusionParams(use_uwb=False, min_satellites_init=8, divergence_gnss_epochs=2),
                     reference_provider=provider)
    f.initialize(T0, RX + np.array([400.0, 0.0, 0.0]), clock_bias_m=150.0, position_std_m=0.5)
    outs = [
        f.process_gnss(dataclasses.replace(e, observations=e.observations[:7]))
        for e in (_epoch(T0 + k * NS // 5) for k in range(1, 4))
    ]
    first = next(o for o in outs if o.diverged)
    assert asked == [first.stamp_ns]  # asked once, at the divergence, not on every epoch
    np.testing.assert_allclose(first.position_m, RX + np.array([1.0, 0.0, 0.0]), atol=1e-6)


# ----------------------------------------------------------------------------- time handling
def test_asynchronous_stream_is_deterministic_and_time_ordered():
    def run():
        rng = np.random.default_rng(29)
        f = FusionFilter()
        res = []
        for k in range(30):
            t = T0 + k * NS // 5
            res.append(f.process_gnss(_epoch(t, rng=rng)))
            res.append(f.process_uwb(_uwb(t, 0, rng=rng)))  # same stamp as the epoch: dt = 0 is fine
            res.append(f.process_uwb(_uwb(t + NS // 10, 1, rng=rng)))
        return res

    a, b = run(), run()
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.position_m, y.position_m)
        np.testing.assert_array_equal(x.covariance_pv, y.covariance_pv)
    assert all(x.stamp_ns <= y.stamp_ns for x, y in zip(a, a[1:], strict=False))


def test_reorder_buffer_releases_in_stamp_order_and_counts_late():
    buf = ReorderBuffer(window_ns=100)
    msgs = [_uwb(s, 0) for s in (300, 100, 200, 250)]
    for m in msgs:
        assert buf.push(m)
    ready = buf.pop_ready(now_ns=360)
    assert [m.stamp_ns for m in ready] == [100, 200, 250]
    assert not buf.push(_uwb(150, 0)) and buf.late == 1
    assert [m.stamp_ns for m in buf.flush()] == [300]
    with pytest.raises(ValueError):
        ReorderBuffer(-1)


def test_common_mode_screen_catches_an_outlier_the_clock_variance_hides():
    # With a TCXO-class clock (h_-2 = 2e-18 /s) the clock-drift variance enters every rate's
    # innovation variance, so a 1 m/s error on one pseudorange rate passes the per-measurement
    # CKF gate and shifts the velocity by ~0.5 m/s; the common-mode screen removes the clock from
    # the test and drops it.
    vel_err = {}
    for screen in (True, False):
        rng = np.random.default_rng(21)
        f = FusionFilter(FusionParams(use_uwb=False, accel_psd_m2ps3=0.01, clock_h_minus2_hz=2e-18,
                                      common_mode_screen=screen))
        _run_gnss(f, 50, rng)
        ep = _epoch(T0 + 50 * NS // 5, rng=rng)
        obs = list(ep.observations)
        obs[3] = dataclasses.replace(obs[3], pseudorange_rate_mps=obs[3].pseudorange_rate_mps + 1.0)
        out = f.process_gnss(dataclasses.replace(ep, observations=tuple(obs)))
        counts = dict(out.rejection_counts)
        vel_err[screen] = float(np.linalg.norm(out.velocity_mps))
        if screen:
            assert counts.get("common_mode_doppler", 0) == 1
        else:
            assert counts.get("innovation_gate_doppler", 0) == 0
    assert vel_err[True] < 0.01 < 0.3 < vel_err[False]


def _validate_satellites_reference(obs, params, count):
    """Test oracle: the per-satellite checks of input_checks.validate_satellites, one observation at a time."""
    rows = []
    for o in obs:
        try:
            sp = np.asarray(o.satellite_position_ecef_m, dtype=float).reshape(3)
            sv = np.asarray(o.satellite_velocity_ecef_mps, dtype=float).reshape(3)
        except (ValueError, TypeError):
            count("malformed_observation", 1)
            continue
        scalars = (o.pseudorange_m, o.satellite_clock_bias_m, o.ionosphere_delay_m, o.troposphere_delay_m)
        if not (np.isfinite(sp).all() and all(math.isfinite(float(v)) for v in scalars)):
            count("nonfinite_pseudorange", 1)
            continue
        if not (1.0e7 < float(np.linalg.norm(sp)) < 5.0e7):
            count("nonphysical_satellite_position", 1)
            continue
        if not (1.0e6 < o.pseudorange_m < 1.0e8) or o.ionosphere_delay_m < 0.0 or o.troposphere_delay_m < 0.0:
            count("nonphysical_pseudorange", 1)
            continue
        if math.isfinite(o.cn0_dbhz) and o.cn0_dbhz < params.min_cn0_dbhz:
            count("low_cn0", 1)
            continue
        rate_ok = (
            params.use_doppler
            and math.isfinite(o.pseudorange_rate_mps)
            and np.isfinite(sv).all()
            and math.isfinite(o.satellite_clock_drift_mps)
            and abs(o.pseudorange_rate_mps) < 2.0e4
        )
        if params.use_doppler and not rate_ok:
            count("invalid_doppler", 1)
        rows.append((o, sp, sv, bool(rate_ok)))
    return rows


def _counter():
    counts: dict[str, int] = {}

    def count(reason: str, n: int = 1) -> None:
        if n > 0:
            counts[reason] = counts.get(reason, 0) + n

    return counts, count


def test_vectorised_satellite_checks_equal_the_per_observation_loop():
    # every rejection reason, alone and mixed, in random epochs: same rows, same counts
    rng = np.random.default_rng(33)
    base = list(_epoch(T0, rng=rng).observations)
    spoil = [
        lambda o: dataclasses.replace(o, pseudorange_m=math.nan),
        lambda o: dataclasses.replace(o, satellite_clock_bias_m=math.inf),
        lambda o: dataclasses.replace(o, satellite_position_ecef_m=np.array([1.0, 2.0, 3.0])),
        lambda o: dataclasses.replace(o, satellite_position_ecef_m=np.array([math.nan, 0.0, 0.0])),
        lambda o: dataclasses.replace(o, pseudorange_m=5.0e5),
        lambda o: dataclasses.replace(o, ionosphere_delay_m=-1.0),
        lambda o: dataclasses.replace(o, cn0_dbhz=10.0),
        lambda o: dataclasses.replace(o, cn0_dbhz=math.nan),
        lambda o: dataclasses.replace(o, pseudorange_rate_mps=math.nan),
        lambda o: dataclasses.replace(o, pseudorange_rate_mps=3.0e4),
        lambda o: dataclasses.replace(o, satellite_velocity_ecef_mps=np.array([math.nan, 0.0, 0.0])),
        lambda o: dataclasses.replace(o, satellite_position_ecef_m=np.zeros(2)),
        lambda o: dataclasses.replace(o, satellite_velocity_ecef_mps=np.zeros((1, 3))),
        lambda o: o,
    ]
    for use_doppler in (True, False):
        for _ in range(50):
            obs = [spoil[int(rng.integers(len(spoil)))](o) for o in base]
            params = FusionParams(use_doppler=use_doppler)
            (counts_a, a), (counts_b, b) = _counter(), _counter()
            fast = validate_satellites(obs, params, a)
            slow = _validate_satellites_reference(obs, params, b)
            assert [(r[0].svid, r[3]) for r in fast] == [(r[0].svid, r[3]) for r in slow]
            for rf, rs in zip(fast, slow, strict=True):
                np.testing.assert_array_equal(rf[1], rs[1])
                np.testing.assert_array_equal(rf[2], rs[2])
            assert counts_a == counts_b
    # a position that is not a 3-vector is counted as malformed, the others still checked
    bad = [dataclasses.replace(base[0], satellite_position_ecef_m=np.zeros(2))] + base[1:]
    counts, count = _counter()
    assert len(validate_satellites(bad, FusionParams(), count)) == len(base) - 1
    assert counts == {"malformed_observation": 1}


def test_reanchor_on_uwb_drops_a_dragged_state():
    """GNSS found spoofed (issue 25): the state a spoofer dragged is replaced by UWB multilateration."""
    f = FusionFilter(FusionParams())
    t = 1_437_263_983 * NS
    assert not f.reanchor_on_uwb(t)  # nothing to re-anchor before a start
    for k in range(20):
        f.process_gnss(_epoch(t + k * NS // 5))
        for j in range(3):
            f.process_uwb(_uwb(t + k * NS // 5 + (j + 1) * NS // 20, j))
    assert f.initialized
    dragged = RX + R_ENU.T @ np.array([30.0, 0.0, 0.0])  # what a spoofer's re-initialisation could leave
    f.initialize(t + 4 * NS, dragged, velocity_mps=R_ENU.T @ np.array([1.0, 0.0, 0.0]))
    assert f.reanchor_on_uwb(t + 4 * NS)
    out = None
    for k in range(20, 40):  # UWB only afterwards (GNSS excluded)
        for j in range(3):
            out = f.process_uwb(_uwb(t + k * NS // 5 + (j + 1) * NS // 20, j))
    assert out is not None and np.linalg.norm((out.position_m - RX) @ R_ENU.T[:, :2]) < 0.3
    assert f.rejection_counts.get('reanchor_on_uwb') == 1
    g = FusionFilter(FusionParams(use_uwb=False))
    g.process_gnss(_epoch(t))
    g.process_gnss(_epoch(t + NS))
    if g.initialized:
        assert not g.reanchor_on_uwb(t + NS) and g.rejection_counts.get('reanchor_without_uwb') == 1
