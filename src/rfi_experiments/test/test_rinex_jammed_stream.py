"""Unit and oracle tests of the ``rinex_jammed`` scenario stream (real RINEX + simulated jamming + UWB).

The real data are the ARL1 files shipped in src/rfi_experiments/data (with S1) and the GEONET 0759
pair of src/gnss_common/test/data (no S1, no Doppler); see the READMEs there.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gnss_common.gps_time import gps_to_ros_stamp_ns
from gnss_common.jamming_weights import dll_jitter_m, effective_cn0_dbhz
from rfi_experiments.rinex_to_bag import convert_rinex
from rfi_experiments.scenario import STREAMS, Scenario, ScenarioError, load_scenario
from rfi_experiments.streams import rinex_jammed
from rfi_sim.gnss_uwb import JammingEffect

PKG = Path(__file__).resolve().parents[1]
DATA = PKG / 'data'
GEONET = PKG.parents[0] / 'gnss_common' / 'test' / 'data'
NO_OUTLIERS = JammingEffect(outlier_onset_jsr_db=1000.0)


def scenario(duration_s: float = 600.0, **section) -> tuple[Scenario, dict]:
    return Scenario(name='t', description='', seed=1, duration_s=duration_s,
                    streams={'rinex_jammed': section}), section


@pytest.fixture(scope='module')
def arl1():
    conv = convert_rinex(DATA / 'arlm200a.15o', DATA / 'arlm2000.15n', 10.0)
    return conv.epochs, conv.truth_position_ecef_m


def section_with(phases, **kw) -> rinex_jammed.Section:
    sc, sec = scenario(duration_s=sum(d for _, d in phases), uwb_rate_hz=1.0,
                       jamming=[{'jsr_db': j, 'duration_s': d} for j, d in phases], **kw)
    return rinex_jammed.parse_section(sc, sec)


def test_stream_is_registered_and_the_shipped_scenario_parses():
    assert STREAMS['rinex_jammed'] == 'rfi_experiments.streams.rinex_jammed'
    sc = load_scenario(PKG / 'scenarios' / 'arl1_jammed.yaml')
    sec = rinex_jammed.parse_section(sc, sc.streams['rinex_jammed'])
    assert [j for j, _ in sec.phases] == [None, -10.0, -2.0, 6.0, 14.0, 22.0, 30.0]   # Cao et al., Table 1
    assert sum(d for _, d in sec.phases) == sc.duration_s
    assert sec.obs_file.name == 'arlm200a.15o' and sec.nav_file.name == 'arlm2000.15n'


def test_clean_phase_passes_the_real_observations_through(arl1):
    epochs, truth = arl1
    sec = section_with([(None, 300.0)])
    out = rinex_jammed.jam_epochs(epochs[:10], truth, epochs[0].stamp_ns, sec, np.random.default_rng(0))
    assert [j.epoch for j in out] == list(epochs[:10])
    assert all(j.jsr_db is None and not j.lost_lock and not j.outliers for j in out)


def test_reported_cn0_is_eq4_of_the_real_s1_and_loss_of_lock_follows_it(arl1):
    """Without C/N0 estimation noise the written C/N0 is exactly eq. 4 of the real S1, and a satellite
    is dropped exactly when that is below the loss-of-lock threshold (30 dB J/S: about 30 dB-Hz)."""
    epochs, truth = arl1
    jam = replace(NO_OUTLIERS, cn0_estimate_std_db=0.0)
    for jsr in (14.0, 30.0):
        sec = section_with([(jsr, 3600.0)])
        out = rinex_jammed.jam_epochs(epochs, truth, epochs[0].stamp_ns, sec, np.random.default_rng(1), jamming=jam)
        n_lost = 0
        for real, j in zip(epochs, out, strict=True):
            s1 = {o.svid: o.cn0_dbhz for o in real.observations}
            eff = {sv: float(effective_cn0_dbhz(c, jsr)) for sv, c in s1.items()}
            assert {o.svid: o.cn0_dbhz for o in j.epoch.observations} == pytest.approx(
                {sv: e for sv, e in eff.items() if e >= jam.loss_of_lock_dbhz})
            assert set(j.lost_lock) == {sv for sv, e in eff.items() if e < jam.loss_of_lock_dbhz}
            n_lost += len(j.lost_lock)
        if jsr == 14.0:
            assert n_lost == 0
        else:
            assert n_lost > 0.5 * sum(len(e.observations) for e in epochs)


def test_extra_code_jitter_has_the_dll_variance_difference(arl1):
    """At 22 dB J/S (no outliers) the pseudorange change divided by
    sqrt(sigma_DLL(C/N0_eff)^2 - sigma_DLL(S1)^2) is standard normal: mean 0, std 1 (~800 samples)."""
    epochs, truth = arl1
    jam = replace(NO_OUTLIERS, cn0_estimate_std_db=0.0)
    sec = section_with([(22.0, 3600.0)])
    out = rinex_jammed.jam_epochs(epochs, truth, epochs[0].stamp_ns, sec, np.random.default_rng(2), jamming=jam)
    loop = rinex_jammed._SIM.loop
    z = []
    for real, j in zip(epochs, out, strict=True):
        before = {o.svid: o for o in real.observations}
        for o in j.epoch.observations:
            clean = before[o.svid].cn0_dbhz
            extra = math.sqrt(dll_jitter_m(effective_cn0_dbhz(clean, 22.0), loop) ** 2 - dll_jitter_m(clean, loop) ** 2)
            z.append((o.pseudorange_m - before[o.svid].pseudorange_m) / extra)
            assert o.satellite_position_ecef_m is before[o.svid].satellite_position_ecef_m
    z = np.array(z)
    assert z.size > 500
    assert abs(z.mean()) < 4 / math.sqrt(z.size)
    assert abs(z.std() - 1.0) < 0.1


def test_burst_rate_law_and_time_fraction_in_bursts():
    jam = JammingEffect()
    assert rinex_jammed.burst_rate_per_s(jam, None) == 0.0
    assert rinex_jammed.burst_rate_per_s(jam, 5.9) == 0.0
    assert rinex_jammed.burst_rate_per_s(jam, 6.0) == jam.outlier_burst_rate_per_s
    assert rinex_jammed.burst_rate_per_s(jam, 16.0) == pytest.approx(10 * jam.outlier_burst_rate_per_s)
    # Fraction of time inside a burst = rate x mean duration (bursts rarely overlap at this rate).
    rate, span = 0.02, 200_000.0
    b = rinex_jammed.draw_bursts(np.random.default_rng(3), rate, 0.0, span, jam)
    mean_d = sum(jam.outlier_burst_duration_s) / 2
    assert b.shape[1] == 4 and abs(b.shape[0] - rate * span) < 4 * math.sqrt(rate * span)
    assert np.sum(b[:, 1] - b[:, 0]) / span == pytest.approx(rate * mean_d, rel=0.05)
    mags = np.abs(b[:, 2])
    assert mags.min() >= jam.outlier_magnitude_m[0] and mags.max() <= jam.outlier_magnitude_m[1]
    assert np.all(np.sign(b[:, 2]) == np.sign(b[:, 3]))
    assert rinex_jammed.draw_bursts(np.random.default_rng(3), 0.0, 0.0, span, jam).shape == (0, 4)


def test_outliers_appear_from_6_db_on_and_carry_the_burst_error(arl1):
    epochs, truth = arl1
    jam = replace(JammingEffect(), cn0_estimate_std_db=0.0, outlier_burst_rate_per_s=0.05)
    sec = section_with([(2.0, 1800.0), (22.0, 1800.0)])
    out = rinex_jammed.jam_epochs(epochs, truth, epochs[0].stamp_ns, sec, np.random.default_rng(4), jamming=jam)
    assert not any(j.outliers for j in out if j.jsr_db == 2.0)
    hits = [(real, j) for real, j in zip(epochs, out, strict=True) if j.outliers]
    assert hits
    for real, j in hits:
        before = {o.svid: o.pseudorange_m for o in real.observations}
        for o in j.epoch.observations:
            if o.svid in j.outliers:
                assert abs(o.pseudorange_m - before[o.svid]) > jam.outlier_magnitude_m[0] - 10.0


def test_file_without_s1_uses_the_elevation_model_and_keeps_nan_cn0():
    conv = convert_rinex(GEONET / '07590920.05o', GEONET / '07590920.05n', 10.0)
    truth = conv.truth_position_ecef_m
    epochs = conv.epochs[:5]
    assert all(math.isnan(o.cn0_dbhz) for e in epochs for o in e.observations)
    sec = section_with([(22.0, 150.0)])
    out = rinex_jammed.jam_epochs(epochs, truth, epochs[0].stamp_ns, sec, np.random.default_rng(5), jamming=NO_OUTLIERS)
    for e, j in zip(epochs, out, strict=True):
        el = rinex_jammed.elevations_rad(e, truth)
        model = sec.cn0_horizon_dbhz + (sec.cn0_zenith_dbhz - sec.cn0_horizon_dbhz) * np.sin(el)
        assert [j.cn0_clean_dbhz[o.svid] for o in e.observations] == pytest.approx(model)
        assert all(math.isnan(o.cn0_dbhz) and math.isnan(o.pseudorange_rate_mps) for o in j.epoch.observations)


def test_uwb_ranges_follow_the_anchor_geometry():
    truth = np.array([-740289.918, -5457071.734, 3207245.542])
    sec = section_with([(None, 10.0)], uwb_noise_std_m=0.0)
    anchors, ranges = rinex_jammed.uwb_ranges(truth, 1_000_000_000, 10.0, sec, np.random.default_rng(6))
    assert len(ranges) == 3 * 10
    assert np.linalg.norm(anchors - truth, axis=1) == pytest.approx([11.71, 13.00, 11.26])
    assert [r.range_m for r in ranges[:3]] == pytest.approx([11.71, 13.00, 11.26])
    stamps = [r.stamp_ns for r in ranges]
    assert stamps == sorted(stamps) and stamps[3] - stamps[0] == 1_000_000_000
    assert [r.anchor_id for r in ranges[:3]] == ['A1', 'A2', 'A3'] and all(r.frame_id == 'earth' for r in ranges)


def test_build_is_stamp_ordered_reproducible_and_keeps_the_real_epoch_times(arl1):
    epochs, _ = arl1
    sc, sec = scenario(duration_s=120.0, uwb_rate_hz=1.0, jamming=[{'jsr_db': None, 'duration_s': 60.0},
                                                                   {'jsr_db': 22.0}])
    items = list(rinex_jammed.build(sc, sec, seed=7))
    again = list(rinex_jammed.build(sc, sec, seed=7))
    assert [s for s, _, _ in items] == sorted(s for s, _, _ in items)
    gnss = [m for _, t, m in items if t == '/gnss/measurements']
    assert [s for s, t, _ in items if t == '/gnss/measurements'] == [e.stamp_ns for e in epochs[:4]]
    # stamps are ROS (UTC) time of each message's own GPS week / time of week (2015: GPS - UTC = 17 s)
    gnss_items = [(s, m) for s, t, m in items if t == '/gnss/measurements']
    assert all(s == m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
               == gps_to_ros_stamp_ns(m.gps_week, m.gps_time_of_week_s) for s, m in gnss_items)
    assert items[0][0] == 1_437_263_983 * 10**9   # 2015-07-19 00:00:00 GPST = 2015-07-18 23:59:43 UTC
    assert len(gnss) == 4 and sum(t == '/uwb/ranges' for _, t, _ in items) == 3 * 120
    assert sum(t == '/truth/jammer_state' for _, t, _ in items) == 120
    assert sum(t == '/truth/position' for _, t, _ in items) == 4
    ranges = [m.range_m for _, t, m in items if t == '/uwb/ranges']
    assert ranges == [m.range_m for _, t, m in again if t == '/uwb/ranges']
    jammed = [[x.pseudorange_m for x in m.measurements] for _, t, m in items if t == '/gnss/measurements']
    assert jammed == [[x.pseudorange_m for x in m.measurements] for _, t, m in again if t == '/gnss/measurements']


@pytest.mark.parametrize('section, duration_s, words', [
    ({'jamming_schedule': []}, 60.0, 'unknown key'),
    ({'jamming': [{'jsr_db': None, 'duration_s': 10.0}]}, 60.0, 'phases last 10.0 s'),
    ({'jamming': [{'jsr_db': 6.0}, {'jsr_db': 22.0}]}, 60.0, r'jamming\[0\].duration_s is required'),
    ({'uwb_rate_hz': 2.0, 'jamming': [{'jsr_db': 6.0, 'duration_s': 10.25}, {'jsr_db': 22.0}]}, 60.0, 'whole number'),
    ({'jamming': [{'jsr_db': 600.0}]}, 60.0, r'jamming\[0\].jsr_db'),
    ({'anchors': [{'range_m': 1.0, 'azimuth_deg': 0.0, 'up_m': 2.0}]}, 60.0, 'must exceed'),
    ({'obs_file': 'no_such_file.15o'}, 60.0, 'does not exist'),
    ({'uwb_reported_std_m': -1.0}, 60.0, 'uwb_reported_std_m'),
    ({}, 7200.0, 'exceeds'),
    ({'start_offset_s': 3000.0}, 1200.0, 'exceeds'),
])
def test_section_is_validated(section, duration_s, words):
    sc, sec = scenario(duration_s=duration_s, **section)
    with pytest.raises(ScenarioError, match=words):
        rinex_jammed.build(sc, sec, seed=0)
