"""Oracle tests of the spoofing injector (rfi_sim.spoofing): every attack against an independent model
(a receiver really at the spoofed position, the derivative of the pseudorange change, a snapshot
solver), constellation limits, the C/N0 of one transmitter, meaconing, the attack dict parser,
determinism, and real station days (ARL1 GPS, ESBC multi-GNSS)."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gnss_common.constants import SPEED_OF_LIGHT_MPS
from gnss_common.coordinates import azimuth_elevation, ecef_to_enu_rotation, ecef_to_geodetic
from gnss_common.earth_rotation import sagnac_rotate
from gnss_common.measurements import build_epochs
from gnss_common.observations import BEIDOU, GALILEO, GLONASS, GPS
from gnss_common.rinex import read_rinex_nav, read_rinex_obs
from gnss_common.spp import SinglePointPositioner, SppParams
from gnss_common.synthetic_sky import (
    CLOCK_BIAS_M,
    ORBIT_RADIUS_M,
    RECEIVER_ECEF_M,
    SKY_AZ_EL_DEG,
    synthetic_epoch,
)
from rfi_sim.gnss_uwb import BroadcastGeometry, GnssUwbScenario, simulate
from rfi_sim.spoofing import AttackInjector, SpoofingAttack, apply_attack, attack_from_dict

DATA = Path(__file__).resolve().parents[2] / "gnss_common" / "test" / "data"
RX = RECEIVER_ECEF_M
LAT, LON, _ = ecef_to_geodetic(RX)
R_ENU = ecef_to_enu_rotation(LAT, LON)
S = 1_000_000_000  # ns per s


def _at(epoch, t_s):
    """The same epoch stamped t_s later."""
    return replace(epoch, stamp_ns=epoch.stamp_ns + round(t_s * S))


def _pr(epoch):
    return np.array([o.pseudorange_m for o in epoch.observations])


def _rates(epoch):
    return np.array([o.pseudorange_rate_mps for o in epoch.observations])


def _cn0(epoch):
    return np.array([o.cn0_dbhz for o in epoch.observations])


def _receive_frame_satellites(rx):
    """The receive-frame satellite positions synthetic_epoch places for SKY_AZ_EL_DEG around rx."""
    out = []
    for az, el in SKY_AZ_EL_DEG:
        a, e = math.radians(az), math.radians(el)
        u = R_ENU.T @ np.array([math.sin(a) * math.cos(e), math.cos(a) * math.cos(e), math.sin(e)])
        b = rx @ u
        out.append(rx + (-b + math.sqrt(b * b - rx @ rx + ORBIT_RADIUS_M**2)) * u)
    return np.array(out)


def _spp(epoch, **kw):
    return SinglePointPositioner(SppParams(elevation_mask_deg=5.0, **kw)).process(epoch)


# ---- position push ------------------------------------------------------------------------------

def test_position_push_gives_the_pseudoranges_of_a_receiver_at_the_pushed_position():
    """Oracle: synthetic_epoch of a receiver really at p + d, seeing the same satellites."""
    v_enu = np.array([1.0, 0.5, 0.2])
    clean = synthetic_epoch()
    tau_s = 40.0
    attack = SpoofingAttack("position_push", start_s=10.0, push_velocity_enu_mps=tuple(v_enu))
    out, truth = apply_attack([clean, _at(clean, 10.0 + tau_s)], attack, RX)
    assert out[0] is clean and not truth.attacked[0] and truth.attacked[1]
    d_ecef = R_ENU.T @ (v_enu * tau_s)
    q = RX + d_ecef
    sky_q = [tuple(np.degrees(azimuth_elevation(q, s))) for s in _receive_frame_satellites(RX)]
    oracle = synthetic_epoch(sky=sky_q, receiver_ecef_m=q)
    tropo = np.array([o.troposphere_delay_m for o in clean.observations])
    tropo_q = np.array([o.troposphere_delay_m for o in oracle.observations])
    np.testing.assert_allclose(_pr(out[1]) - tropo, _pr(oracle) - tropo_q, rtol=0, atol=1e-3)
    np.testing.assert_allclose(truth.position_offset_enu_m[1], v_enu * tau_s, atol=1e-9)
    np.testing.assert_allclose(truth.spoofed_position_ecef_m[1], q, atol=1e-9)
    assert truth.time_offset_s[1] == 0.0
    assert truth.affected[1] == {(GPS, k + 1) for k in range(len(SKY_AZ_EL_DEG))} and truth.affected[0] == set()
    for a, b in zip(out[1].observations, clean.observations, strict=True):  # satellite states untouched
        assert np.array_equal(a.satellite_position_ecef_m, b.satellite_position_ecef_m)


def test_snapshot_solution_is_dragged_exactly_by_the_push():
    clean = synthetic_epoch()
    attack = SpoofingAttack("position_push", start_s=0.0, push_velocity_enu_mps=(1.0, 0.0, 0.0))
    out, truth = apply_attack([clean, _at(clean, 60.0)], attack, RX)
    res = _spp(out[1])
    assert res.valid
    np.testing.assert_allclose(R_ENU @ (res.position_ecef_m - RX), [60.0, 0.0, 0.0], atol=1e-3)
    assert res.clock_bias_m == pytest.approx(CLOCK_BIAS_M, abs=1e-3)


def _moving_sky(n, dt_s, receiver_velocity_ecef_mps=None):
    """n epochs dt_s apart: the synthetic sky's satellites moving on straight lines at their velocity,
    the receiver static or moving; the clean measurements do not matter (only the changes are tested)."""
    base = synthetic_epoch()
    epochs, positions = [], []
    v_r = np.zeros(3) if receiver_velocity_ecef_mps is None else np.asarray(receiver_velocity_ecef_mps)
    for k in range(n):
        t = k * dt_s
        obs = tuple(replace(o, satellite_position_ecef_m=o.satellite_position_ecef_m
                            + o.satellite_velocity_ecef_mps * t) for o in base.observations)
        epochs.append(replace(_at(base, t), observations=obs))
        positions.append(RX + v_r * t)
    return epochs, np.array(positions)


@pytest.mark.parametrize("receiver_velocity", [None, np.array([4.0, -3.0, 1.0])])
def test_consistent_rates_are_the_derivative_of_the_pseudorange_change(receiver_velocity):
    dt = 0.2
    epochs, positions = _moving_sky(11, dt, receiver_velocity)
    attack = SpoofingAttack("position_push", start_s=0.0, push_velocity_enu_mps=(2.0, -1.0, 0.5))
    out, _ = apply_attack(epochs, attack, positions)  # (n, 3) positions: velocity by finite difference
    dpr = np.array([_pr(o) - _pr(e) for o, e in zip(out, epochs, strict=True)])
    drate = np.array([_rates(o) - _rates(e) for o, e in zip(out, epochs, strict=True)])
    central = (dpr[2:] - dpr[:-2]) / (2 * dt)
    np.testing.assert_allclose(drate[1:-1], central, rtol=0, atol=1e-4)
    # the geometry matters: the rate change is not simply the push along the line of sight
    assert np.ptp(drate[5]) > 0.5


def test_inconsistent_push_leaves_the_authentic_rates():
    epochs, _ = _moving_sky(5, 1.0)
    attack = SpoofingAttack("position_push", start_s=1.0, push_velocity_enu_mps=(5.0, 0.0, 0.0),
                            doppler_consistent=False)
    out, _ = apply_attack(epochs, attack, RX)
    for o, e in zip(out, epochs, strict=True):
        assert [a.pseudorange_rate_mps for a in o.observations] == [b.pseudorange_rate_mps for b in e.observations]
    assert np.linalg.norm(_pr(out[-1]) - _pr(epochs[-1])) > 10.0  # the code is pushed (15 m east)


# ---- time push ----------------------------------------------------------------------------------

@pytest.mark.parametrize("consistent", [True, False])
def test_time_push_adds_c_rate_t_to_every_pseudorange(consistent):
    rate_ns_per_s = 100.0
    clean = synthetic_epoch()
    epochs = [_at(clean, t) for t in (0.0, 5.0, 12.5, 30.0)]
    attack = SpoofingAttack("time_push", start_s=5.0, time_push_ns_per_s=rate_ns_per_s, doppler_consistent=consistent)
    out, truth = apply_attack(epochs, attack, RX)
    for o, e, t in zip(out, epochs, (0.0, 5.0, 12.5, 30.0), strict=True):
        tau = max(t - 5.0, 0.0)
        np.testing.assert_allclose(_pr(o) - _pr(e), SPEED_OF_LIGHT_MPS * rate_ns_per_s * 1e-9 * tau, rtol=0, atol=1e-7)
        expected_rate = SPEED_OF_LIGHT_MPS * rate_ns_per_s * 1e-9 if consistent and t >= 5.0 else 0.0
        np.testing.assert_allclose(_rates(o) - _rates(e), expected_rate, rtol=0, atol=1e-9)
    np.testing.assert_allclose(truth.time_offset_s, [0.0, 0.0, 750e-9, 2500e-9], rtol=1e-12)
    res = _spp(out[-1])  # the clock moves, the position does not
    assert np.linalg.norm(res.position_ecef_m - RX) < 1e-3
    assert res.clock_bias_m - CLOCK_BIAS_M == pytest.approx(SPEED_OF_LIGHT_MPS * 2500e-9, abs=1e-3)


def test_attack_ends_and_the_epochs_pass_through():
    clean = synthetic_epoch()
    epochs = [_at(clean, t) for t in (0.0, 10.0, 20.0, 30.0)]
    attack = SpoofingAttack("time_push", start_s=10.0, end_s=20.0, time_push_ns_per_s=50.0)
    out, truth = apply_attack(epochs, attack, RX)
    assert truth.attacked.tolist() == [False, True, False, False]
    assert out[0] is epochs[0] and out[2] is epochs[2] and out[3] is epochs[3]


# ---- constellations -----------------------------------------------------------------------------

def test_one_constellation_spoofed_leaves_the_others_bit_identical():
    systems = [GPS, GALILEO, GPS, GALILEO, BEIDOU, GPS, GALILEO, GLONASS, GPS]
    clean = synthetic_epoch(constellations=systems)
    attack = SpoofingAttack("takeover", start_s=0.0, constellations=(GALILEO,), push_velocity_enu_mps=(3.0, 0.0, 0.0),
                            time_push_ns_per_s=20.0)
    out, truth = apply_attack([clean, _at(clean, 10.0)], attack, RX)
    for a, b in zip(out[1].observations, clean.observations, strict=True):
        if b.constellation == GALILEO:
            assert a.pseudorange_m != b.pseudorange_m and a.cn0_dbhz != b.cn0_dbhz
        else:
            assert a is b
    assert truth.affected[1] == {(GALILEO, k + 1) for k, c in enumerate(systems) if c == GALILEO}


def test_real_multi_gnss_day_only_galileo_spoofed():
    obs = read_rinex_obs(DATA / "ESBC00DNK_R_20201770000_01H_30S_MO.crx.gz")
    nav = read_rinex_nav(DATA / "ESBC00DNK_R_20201770000_01H_MN.rnx.gz")
    epochs = [r.epoch for r in build_epochs(obs, nav)][:40]
    rx = obs.header.approx_position_ecef_m
    attack = SpoofingAttack("position_push", start_s=300.0, constellations=(GALILEO,),
                            push_velocity_enu_mps=(0.5, 0.0, 0.0))
    out, truth = apply_attack(epochs, attack, rx, seed=3)
    assert truth.attacked.sum() == 30
    changed = 0
    for o, e in zip(out, epochs, strict=True):
        assert o.stamp_ns == e.stamp_ns and len(o.observations) == len(e.observations)
        for a, b in zip(o.observations, e.observations, strict=True):
            if b.constellation != GALILEO or not truth.attacked[epochs.index(e)]:
                assert a is b
            else:
                changed += 1
    assert changed > 100


# ---- C/N0 ---------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def arl1_sim():
    """60 s of the GNSS/UWB simulator on the ARL1 broadcast ephemeris, no jamming."""
    geometry = BroadcastGeometry(DATA / "arlm2000.15n")
    return simulate(GnssUwbScenario(duration_s=60.0, seed=11), geometry, geometry.iono_alpha, geometry.iono_beta)


def _cn0_table(epochs, rx):
    """(epoch, satellite) tables of C/N0 and sin(elevation) over the satellites seen throughout."""
    common = set.intersection(*({o.svid for o in e.observations} for e in epochs))
    cn0 = np.array([[o.cn0_dbhz for o in e.observations if o.svid in common] for e in epochs])
    sin_el = np.array([[math.sin(azimuth_elevation(rx, o.satellite_position_ecef_m)[1])
                        for o in e.observations if o.svid in common] for e in epochs])
    return cn0, sin_el


def test_single_transmitter_cn0_loses_the_elevation_dependence_and_moves_together(arl1_sim):
    rx = arl1_sim.truth.receiver_ecef_m
    epochs = list(arl1_sim.gnss_epochs)
    clean_cn0, sin_el = _cn0_table(epochs[50:], rx)
    assert np.corrcoef(clean_cn0.ravel(), sin_el.ravel())[0, 1] > 0.9
    pooled_cn0, pooled_el, pair_corr, levels = [], [], [], []
    for seed in range(5):
        attack = SpoofingAttack("takeover", start_s=10.0, power_advantage_db=3.0)
        out, truth = apply_attack(epochs, attack, rx, seed=seed)
        cn0, _ = _cn0_table(list(out[50:]), rx)
        pooled_cn0.append(cn0.ravel())
        pooled_el.append(sin_el.ravel())
        dev = cn0 - cn0.mean(axis=0)  # each satellite's fluctuation about its own level
        corr = np.corrcoef(dev.T)
        pair_corr.append(corr[np.triu_indices_from(corr, 1)].mean())
        levels.append(np.median(cn0) - truth.reference_cn0_dbhz)
        clean_median = np.median([o.cn0_dbhz for o in epochs[49].observations])
        assert truth.reference_cn0_dbhz == pytest.approx(clean_median)  # the last epoch before 10 s
    assert abs(np.corrcoef(np.concatenate(pooled_cn0), np.concatenate(pooled_el))[0, 1]) < 0.3
    slope = np.polyfit(np.concatenate(pooled_el), np.concatenate(pooled_cn0), 1)[0]
    assert abs(slope) < 3.0  # clean: ~15 dB from horizon to zenith
    assert min(pair_corr) > 0.7  # one transmitter: the satellites rise and fall together
    clean_dev = clean_cn0 - clean_cn0.mean(axis=0)
    clean_corr = np.corrcoef(clean_dev.T)
    assert abs(clean_corr[np.triu_indices_from(clean_corr, 1)].mean()) < 0.2
    assert abs(np.mean(levels) - 3.0) < 1.0


def test_matched_power_keeps_the_pattern_plus_the_advantage_and_a_common_fluctuation(arl1_sim):
    rx = arl1_sim.truth.receiver_ecef_m
    epochs = list(arl1_sim.gnss_epochs)
    attack = SpoofingAttack("takeover", start_s=0.0, cn0_mode="matched", power_advantage_db=3.0)
    out, _ = apply_attack(epochs, attack, rx, seed=2)
    diff = np.array([np.mean(_cn0(o) - _cn0(e)) for o, e in zip(out, epochs, strict=True)])
    spread = max(np.ptp(_cn0(o) - _cn0(e)) for o, e in zip(out, epochs, strict=True))
    assert spread < 1e-9  # the same change for every satellite of an epoch
    assert abs(diff.mean() - 3.0) < 1.0 and 0.3 < diff.std() < 2.0
    lag1 = np.corrcoef(diff[:-1], diff[1:])[0, 1]
    assert lag1 == pytest.approx(math.exp(-0.2 / attack.cn0_common_tau_s), abs=0.1)
    assert all(_pr(o).tolist() == _pr(e).tolist() for o, e in zip(out, epochs, strict=True))  # power only


def test_missing_cn0_stays_missing():
    clean = synthetic_epoch(cn0=math.nan)
    out, truth = apply_attack([clean], SpoofingAttack("takeover", start_s=0.0), RX)
    assert np.all(np.isnan(_cn0(out[0]))) and math.isnan(truth.reference_cn0_dbhz)


# ---- meaconing ----------------------------------------------------------------------------------

def test_meaconing_is_a_common_delay_plus_the_meacon_geometry():
    v_r = np.array([3.0, -2.0, 0.5])
    clean = synthetic_epoch(receiver_velocity_ecef_mps=v_r)
    offset = np.array([40.0, -25.0, 8.0])
    attack = SpoofingAttack("meaconing", start_s=0.0, meaconing_delay_s=2e-6, meacon_offset_enu_m=tuple(offset))
    out, truth = apply_attack([clean], attack, RX, receiver_velocity_ecef_mps=v_r)
    m = RX + R_ENU.T @ offset
    sats = np.array([o.satellite_position_ecef_m for o in clean.observations])
    rho = [np.linalg.norm(sagnac_rotate(sats, x, iterations=3)[0] - x, axis=1) for x in (RX, m)]
    common = _pr(out[0]) - _pr(clean) - (rho[1] - rho[0])
    expected = SPEED_OF_LIGHT_MPS * 2e-6 + np.linalg.norm(offset)
    np.testing.assert_allclose(common, expected, rtol=0, atol=1e-6)
    assert truth.time_offset_s[0] == pytest.approx(expected / SPEED_OF_LIGHT_MPS, rel=1e-12)
    np.testing.assert_allclose(truth.position_offset_enu_m[0], offset, atol=1e-9)
    # a snapshot solver finds the meacon antenna, static, and the clock delayed by the whole replay path
    res = _spp(out[0])
    np.testing.assert_allclose(res.position_ecef_m, m, atol=1e-3)
    assert res.clock_bias_m - CLOCK_BIAS_M == pytest.approx(expected, abs=1e-3)
    assert np.linalg.norm(res.velocity_ecef_mps) < 1e-3
    clean_drift = _spp(clean).clock_drift_mps
    assert res.clock_drift_mps - clean_drift == pytest.approx(float((RX - m) @ v_r) / np.linalg.norm(m - RX), abs=1e-3)


# ---- dicts, validation, determinism -------------------------------------------------------------

def test_attack_from_dict_reads_names_lists_and_defaults():
    a = attack_from_dict({"kind": "position_push", "start_s": 60, "push_velocity_enu_mps": [1, 0, 0],
                          "constellations": ["Galileo", 1], "doppler_consistent": False, "end_s": None})
    assert a.constellations == (GALILEO, GPS) and a.push_velocity_enu_mps == (1.0, 0.0, 0.0)
    assert a.start_s == 60.0 and a.end_s is None and a.power_advantage_db == 3.0
    m = attack_from_dict({"kind": "meaconing", "start_s": 0.0})
    assert m.meaconing_delay_s == 2e-6 and m.meacon_offset_enu_m == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("value,key", [
    ([1, 2], "mapping"),
    ({"kind": "jam", "start_s": 0.0}, "kind"),
    ({"start_s": 0.0}, "kind"),
    ({"kind": "takeover"}, "start_s"),
    ({"kind": "takeover", "start_s": -1.0}, "start_s"),
    ({"kind": "takeover", "start_s": "soon"}, "start_s"),
    ({"kind": "takeover", "start_s": 5.0, "end_s": 5.0}, "end_s"),
    ({"kind": "takeover", "start_s": 0.0, "speed": 1.0}, "speed"),
    ({"kind": "position_push", "start_s": 0.0}, "push_velocity_enu_mps"),
    ({"kind": "position_push", "start_s": 0.0, "push_velocity_enu_mps": [1, 0]}, "push_velocity_enu_mps"),
    ({"kind": "position_push", "start_s": 0.0, "push_velocity_enu_mps": [1, 0, 0], "time_push_ns_per_s": 5},
     "push_velocity_enu_mps"),
    ({"kind": "time_push", "start_s": 0.0}, "time_push_ns_per_s"),
    ({"kind": "time_push", "start_s": 0.0, "time_push_ns_per_s": 1e6}, "time_push_ns_per_s"),
    ({"kind": "takeover", "start_s": 0.0, "doppler_consistent": "yes"}, "doppler_consistent"),
    ({"kind": "takeover", "start_s": 0.0, "constellations": ["galilei"]}, "constellations"),
    ({"kind": "takeover", "start_s": 0.0, "constellations": []}, "constellations"),
    ({"kind": "takeover", "start_s": 0.0, "cn0_mode": "loud"}, "cn0_mode"),
    ({"kind": "takeover", "start_s": 0.0, "power_advantage_db": 99.0}, "power_advantage_db"),
    ({"kind": "takeover", "start_s": 0.0, "cn0_common_tau_s": 0.0}, "cn0_common_tau_s"),
    ({"kind": "takeover", "start_s": 0.0, "meaconing_delay_s": 1e-6}, "meaconing_delay_s"),
    ({"kind": "meaconing", "start_s": 0.0, "doppler_consistent": False}, "doppler_consistent"),
    ({"kind": "meaconing", "start_s": 0.0, "meaconing_delay_s": 0.0}, "meaconing_delay_s"),
    ({"kind": "meaconing", "start_s": 0.0, "time_push_ns_per_s": 10.0}, "time_push_ns_per_s"),
])
def test_bad_attack_dicts_raise_naming_the_key(value, key):
    with pytest.raises(ValueError, match=key):
        attack_from_dict(value)


def test_seeded_and_deterministic(arl1_sim):
    epochs = list(arl1_sim.gnss_epochs)[:100]
    rx = arl1_sim.truth.receiver_ecef_m
    attack = SpoofingAttack("position_push", start_s=5.0, push_velocity_enu_mps=(0.0, 2.0, 0.0))
    a, ta = apply_attack(epochs, attack, rx, seed=4)
    b, tb = apply_attack(epochs, attack, rx, seed=4)
    c, _ = apply_attack(epochs, attack, rx, seed=5)
    assert [_cn0(x).tolist() for x in a] == [_cn0(x).tolist() for x in b]
    assert [_cn0(x).tolist() for x in a] != [_cn0(x).tolist() for x in c]
    assert [_pr(x).tolist() for x in a] == [_pr(x).tolist() for x in c]  # the seed draws C/N0 only
    assert np.array_equal(ta.position_offset_enu_m, tb.position_offset_enu_m)


def test_out_of_order_stamps_and_missing_satellite_states_raise():
    clean = synthetic_epoch()
    injector = AttackInjector(SpoofingAttack("takeover", start_s=0.0), clean.stamp_ns)
    injector.apply(_at(clean, 1.0), RX)
    with pytest.raises(ValueError, match="earlier"):
        injector.apply(clean, RX)
    no_states = replace(clean, observations=tuple(replace(o, satellite_position_ecef_m=np.full(3, np.nan))
                                                  for o in clean.observations))
    push = SpoofingAttack("position_push", start_s=0.0, push_velocity_enu_mps=(1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="satellite positions"):
        apply_attack([no_states, _at(no_states, 1.0)], push, RX)
    # a time push needs no geometry
    out, _ = apply_attack([no_states], SpoofingAttack("time_push", start_s=0.0, time_push_ns_per_s=10.0), RX)
    assert len(out[0].observations) == len(clean.observations)
    with pytest.raises(ValueError, match="shape"):
        apply_attack([clean], push, np.zeros((2, 3)))


# ---- simulated and real runs: the position is really dragged ------------------------------------

def test_simulated_run_snapshot_solution_follows_the_push(arl1_sim):
    epochs = list(arl1_sim.gnss_epochs)
    rx = arl1_sim.truth.receiver_ecef_m
    attack = SpoofingAttack("position_push", start_s=20.0, push_velocity_enu_mps=(1.0, 0.0, 0.0))
    out, truth = apply_attack(epochs, attack, rx, seed=1)
    lat, lon, _ = ecef_to_geodetic(rx)
    rot = ecef_to_enu_rotation(lat, lon)
    spp_clean, spp_spoofed = SinglePointPositioner(), SinglePointPositioner()
    moved = []
    for o, e in zip(out, epochs, strict=True):
        a, b = spp_spoofed.process(o), spp_clean.process(e)
        assert a.valid and b.valid
        moved.append(rot @ (a.position_ecef_m - b.position_ecef_m))
    moved = np.array(moved)
    err = moved - truth.position_offset_enu_m
    assert np.all(moved[:100] == 0.0)  # before the attack: the same epochs
    # the C/N0 weights change with the spoofed C/N0, so the noise maps a little differently
    assert np.sqrt(np.mean(np.sum(err[100:] ** 2, axis=1))) < 1.0
    assert moved[-1, 0] > 35.0  # 40 m east at the end


def test_real_station_day_is_dragged_by_the_push_and_pushed_clock():
    obs = read_rinex_obs(DATA / "arlm200a.15o")
    nav = read_rinex_nav(DATA / "arlm2000.15n")
    epochs = [r.epoch for r in build_epochs(obs, nav)]
    rx = obs.header.approx_position_ecef_m
    # matched power without fluctuation: the solver's C/N0 weights are those of the clean day
    attack = SpoofingAttack("takeover", start_s=600.0, push_velocity_enu_mps=(0.0, 0.1, 0.0),
                            time_push_ns_per_s=10.0, cn0_mode="matched", power_advantage_db=0.0,
                            cn0_common_std_db=0.0)
    out, truth = apply_attack(epochs, attack, rx)
    lat, lon, _ = ecef_to_geodetic(rx)
    rot = ecef_to_enu_rotation(lat, lon)
    for o, e, off, dt in zip(out, epochs, truth.position_offset_enu_m, truth.time_offset_s, strict=True):
        a, b = SinglePointPositioner().process(o), SinglePointPositioner().process(e)
        np.testing.assert_allclose(rot @ (a.position_ecef_m - b.position_ecef_m), off, atol=0.01)
        assert a.clock_bias_m - b.clock_bias_m == pytest.approx(SPEED_OF_LIGHT_MPS * dt, abs=0.01)
        if a.velocity_valid and truth.attacked[epochs.index(e)]:
            np.testing.assert_allclose(rot @ (a.velocity_ecef_mps - b.velocity_ecef_mps), [0.0, 0.1, 0.0], atol=1e-3)
    assert truth.position_offset_enu_m[-1, 1] == pytest.approx(0.1 * (119 * 30.0 - 600.0))
