"""ubx_to_bag end to end on a UBX stream generated from the simulator: the measurements and the
fused positions equal those of the same scenario taken the direct way (simulator -> fusion), within
the tolerances stated here (epochs before the ephemerides: NaN satellite states, rejected by the
fusion); on the real pyubx2 logs (no RXM-SFRBX): measurements with NaN satellite states, the
interference reports and the MON-SPAN spectra; and the tool's refusals of bad input."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from gnss_common.ephemeris import EphemerisStore
from gnss_common.gps_time import gps_to_ros_stamp_ns
from gnss_common.lnav import LnavAssembler, encode_iono_subframe
from gnss_common.rinex import read_rinex_nav
from rfi_experiments import ubx_to_bag
from rfi_experiments.bag_io import BagReader
from rfi_experiments.ubx_synth import ephemeris_frames, klobuchar_frame, mon_hw_frame, rawx_frame
from rfi_node_common.conversions import msg_to_epoch
from rfi_sim.gnss_uwb import BroadcastGeometry, GnssUwbScenario, simulate
from uwb_gnss_fusion.fusion_filter import FusionFilter
from uwb_gnss_fusion.fusion_params import FusionParams

NAV = Path(__file__).parents[1] / "data" / "arlm2000.15n"
EPOCHS_BEFORE_EPHEMERIS = 3
"""RAWX epochs sent before the first SFRBX subframes: written with NaN satellite states."""
REAL = Path(__file__).parent / "data" / "ubx"

# Tolerances (UBX path - direct path), each with its cause:
SAT_POSITION_TOL_M = 0.05
"""The builder evaluates the orbit at t_rx - P/c - dt_sat, P holding the receiver clock offset (up
to ~1.5 km here: 5 us, 2 cm of orbit); the simulator at the true transmit time."""
SAT_VELOCITY_TOL_MPS = 0.01
"""The simulator reports the velocity at t_rx - 75 ms, the builder at the transmit time (up to
10 ms apart: 6 mm/s at 0.6 m/s^2)."""
RATE_TOL_MPS = 1.0e-3
"""Doppler travels as float32 in RAWX (4000 Hz: 2e-4 Hz, 5e-5 m/s)."""
CLOCK_TOL_M = 1.0e-5
DELAY_TOL_M = 1.0e-6
"""Klobuchar / troposphere: same functions, same reference position, same coefficients."""
EQUALISED_POSITION_TOL_M = 0.01
"""Fused positions, UBX path vs direct path once the direct path is given the two inputs a RAWX
stream cannot carry identically (C/N0 rounded to 1 dB-Hz; the satellite velocity at the transmit
time, see SAT_VELOCITY_TOL_MPS): everything else (decoding, SFRBX ephemerides, satellite position
and clock, Klobuchar, troposphere, Doppler) is then tested. Measured 0.004 m max."""
POSITION_TOL_M = 0.25
"""Raw comparison (no equalising): median position difference and difference of the RMS errors
against the truth. Measured 0.11 m median difference (0.92 m at one epoch of the filter's first
seconds, 0.13 m max after 30 s) and RMS errors 0.78 m direct / 0.88 m via UBX: the C/N0 rounding
changes the weights, and the filter integrates the velocity difference."""


def _equalise(direct, via_ubx):
    """The direct epochs with C/N0 and satellite velocity taken from the UBX epochs."""
    out = []
    for d, u in zip(direct, via_ubx, strict=True):
        obs = tuple(dataclasses.replace(o, cn0_dbhz=p.cn0_dbhz,
                                        satellite_velocity_ecef_mps=p.satellite_velocity_ecef_mps)
                    for o, p in zip(d.observations, u.observations, strict=True))
        out.append(dataclasses.replace(d, observations=obs))
    return out


@pytest.fixture(scope="module")
def scenario(tmp_path_factory):
    nav = read_rinex_nav(NAV)
    kb = LnavAssembler().add(1, encode_iono_subframe(nav.header.iono_alpha, nav.header.iono_beta, 0.0), 1854)
    sc = GnssUwbScenario(duration_s=120.0, gnss_rate_hz=1.0, seed=3)
    run = simulate(sc, BroadcastGeometry(NAV), kb.alpha, kb.beta)  # broadcast-representable coefficients
    store = EphemerisStore(nav.ephemerides)
    first = run.gnss_epochs[0]
    prns = sorted({o.svid for e in run.gnss_epochs for o in e.observations})
    used = [store.select(p, first.gps_week, first.gps_time_of_week_s)[0] for p in prns]
    stream = bytearray()
    for k, epoch in enumerate(run.gnss_epochs):
        if k == EPOCHS_BEFORE_EPHEMERIS:
            stream += ephemeris_frames(used, epoch.gps_week, epoch.gps_time_of_week_s)
            stream += klobuchar_frame(prns[0], kb.alpha, kb.beta, epoch.gps_time_of_week_s)
        stream += rawx_frame(epoch, leap_seconds=17)
        stream += mon_hw_frame(1 if k < 60 else 3, 10 if k < 60 else 200, 1400 if k < 60 else 600, 90)
    path = tmp_path_factory.mktemp("ubx") / "sim.ubx"
    path.write_bytes(bytes(stream))
    return sc, run, path


def _bag(tmp_path, path, *extra):
    out = tmp_path / "bag"
    rc = ubx_to_bag.main(["ubx_to_bag", str(path), str(out), *extra])
    assert rc == 0
    with BagReader(out) as reader:
        msgs = [(m.topic, m.stamp_ns, m.decode()) for m in reader.messages()]
    return msgs


def _fuse(epochs):
    f = FusionFilter(FusionParams(use_uwb=False))
    out = {}
    for e in epochs:
        o = f.process(e)
        if o.initialized:
            out[round(e.gps_time_of_week_s, 3)] = o.position_m.copy()
    return out


def test_ubx_to_bag_then_fusion_equals_the_direct_way(scenario, tmp_path, capsys):
    sc, run, path = scenario
    truth = np.asarray(sc.receiver_ecef_m)
    ref = ",".join(str(v) for v in sc.receiver_ecef_m)
    msgs = _bag(tmp_path, path, f"--reference-position={ref}", "--no-receiver-std")  # "=": X may be negative
    printed = capsys.readouterr().out
    assert "epochs_waiting_for_ephemeris" in printed
    assert "leap_seconds_disagree          0" in printed  # 2015: 17 s, as the stream says
    arrays = [(t, m) for topic, t, m in msgs if topic == ubx_to_bag.MEASUREMENTS_TOPIC]
    reports = [m for topic, _, m in msgs if topic == ubx_to_bag.INTERFERENCE_TOPIC]
    n = len(run.gnss_epochs)
    assert len(arrays) == n
    assert len(reports) == n
    assert [r.jamming_state for r in reports].count(3) == 60 and reports[-1].agc_count == 600.0
    direct = {round(e.gps_time_of_week_s, 3): e for e in run.gnss_epochs}
    before = [msg_to_epoch(m) for _, m in arrays[:EPOCHS_BEFORE_EPHEMERIS]]
    arrays = arrays[EPOCHS_BEFORE_EPHEMERIS:]
    n_nan = 0
    for e in before:  # no ephemeris yet: the measurements with NaN satellite states
        d = direct[round(e.gps_time_of_week_s, 3)]
        assert [o.svid for o in e.observations] == [o.svid for o in d.observations]
        for a, b in zip(e.observations, d.observations, strict=True):
            assert a.pseudorange_m == b.pseudorange_m and abs(a.cn0_dbhz - b.cn0_dbhz) <= 0.5
            assert abs(a.pseudorange_rate_mps - b.pseudorange_rate_mps) < RATE_TOL_MPS
            assert np.isnan(a.satellite_position_ecef_m).all() and math.isnan(a.satellite_clock_bias_m)
            assert math.isnan(a.ionosphere_delay_m) and math.isnan(a.troposphere_delay_m)
            n_nan += 1
    assert f"satellites_without_ephemeris   {n_nan}" in printed
    ubx_epochs = []
    for log_t, msg in arrays:
        e = msg_to_epoch(msg)
        assert log_t == e.stamp_ns == gps_to_ros_stamp_ns(e.gps_week, e.gps_time_of_week_s)  # ROS (UTC) time
        d = direct[round(e.gps_time_of_week_s, 3)]
        assert [o.svid for o in e.observations] == [o.svid for o in d.observations]
        for a, b in zip(e.observations, d.observations, strict=True):
            assert a.pseudorange_m == b.pseudorange_m  # float64 end to end
            assert abs(a.cn0_dbhz - b.cn0_dbhz) <= 0.5
            assert abs(a.pseudorange_rate_mps - b.pseudorange_rate_mps) < RATE_TOL_MPS
            assert np.abs(a.satellite_position_ecef_m - b.satellite_position_ecef_m).max() < SAT_POSITION_TOL_M
            assert np.abs(a.satellite_velocity_ecef_mps - b.satellite_velocity_ecef_mps).max() < SAT_VELOCITY_TOL_MPS
            assert abs(a.satellite_clock_bias_m - b.satellite_clock_bias_m) < CLOCK_TOL_M
            assert abs(a.ionosphere_delay_m - b.ionosphere_delay_m) < DELAY_TOL_M
            assert abs(a.troposphere_delay_m - b.troposphere_delay_m) < DELAY_TOL_M
            assert math.isnan(a.pseudorange_std_m)
        ubx_epochs.append(e)
    direct_epochs = run.gnss_epochs[EPOCHS_BEFORE_EPHEMERIS:]
    via_ubx = _fuse(ubx_epochs)
    with_nan = _fuse(before + ubx_epochs)  # the NaN states rejected, nothing else changes
    assert sorted(with_nan) == sorted(via_ubx)
    assert max(np.abs(with_nan[k] - via_ubx[k]).max() for k in via_ubx) == 0.0
    common = sorted(via_ubx)
    assert len(common) >= len(ubx_epochs) - 1
    equalised = _fuse(_equalise(direct_epochs, ubx_epochs))
    diff = np.array([np.linalg.norm(via_ubx[k] - equalised[k]) for k in common])
    assert diff.max() < EQUALISED_POSITION_TOL_M
    via_direct = _fuse(direct_epochs)
    diff = np.array([np.linalg.norm(via_ubx[k] - via_direct[k]) for k in common])
    assert np.median(diff) < POSITION_TOL_M
    rms_ubx = np.sqrt(np.mean([np.sum((via_ubx[k] - truth) ** 2) for k in common]))
    rms_direct = np.sqrt(np.mean([np.sum((via_direct[k] - truth) ** 2) for k in common]))
    assert abs(rms_ubx - rms_direct) < POSITION_TOL_M
    assert rms_ubx < 5.0  # a GNSS-only fix of this scenario, not a diverged filter


def test_coarse_fix_reference_and_receiver_std(scenario, tmp_path):
    _, run, path = scenario
    msgs = _bag(tmp_path, path)
    arrays = [msg_to_epoch(m) for topic, _, m in msgs if topic == ubx_to_bag.MEASUREMENTS_TOPIC]
    assert len(arrays) == len(run.gnss_epochs)
    obs = arrays[10].observations[0]
    assert obs.pseudorange_std_m in [0.01 * 2.0**k for k in range(16)]  # the receiver's prStdev
    assert obs.pseudorange_rate_std_mps > 0.0
    direct = next(e for e in run.gnss_epochs if e.gps_time_of_week_s == arrays[10].gps_time_of_week_s)
    # the troposphere seen from a per-epoch coarse fix (tens of metres off) instead of the truth: cm
    assert abs(obs.troposphere_delay_m - direct.observations[0].troposphere_delay_m) < 0.1


def test_nav_file_instead_of_sfrbx(scenario, tmp_path):
    _, run, path = scenario
    msgs = _bag(tmp_path, path, "--no-sfrbx", "--nav", str(NAV))
    arrays = [m for topic, _, m in msgs if topic == ubx_to_bag.MEASUREMENTS_TOPIC]
    assert len(arrays) == len(run.gnss_epochs)  # ephemerides from the first epoch on


def test_refusals(scenario, tmp_path, capsys):
    _, _, path = scenario
    assert ubx_to_bag.main(["ubx_to_bag", str(tmp_path / "missing.ubx"), str(tmp_path / "o")]) == 2
    assert "missing.ubx" in capsys.readouterr().err
    rawx_only = tmp_path / "rawx.ubx"
    rawx_only.write_bytes((REAL / "pygpsdata-RXMRAWX.log").read_bytes())
    assert ubx_to_bag.main(["ubx_to_bag", str(rawx_only), str(tmp_path / "o"), "--skip-without-ephemeris"]) == 2
    err = capsys.readouterr().err
    assert "nothing to write" in err and "14 epochs waiting for ephemeris" in err
    garbage = tmp_path / "garbage.ubx"
    garbage.write_bytes(np.random.default_rng(1).integers(0, 256, 20000, dtype=np.uint8).tobytes())
    assert ubx_to_bag.main(["ubx_to_bag", str(garbage), str(tmp_path / "o")]) == 2
    assert "0 valid UBX frames" in capsys.readouterr().err
    (tmp_path / "exists").mkdir()
    assert ubx_to_bag.main(["ubx_to_bag", str(path), str(tmp_path / "exists")]) == 2
    assert ubx_to_bag.main(["ubx_to_bag", str(path), str(tmp_path / "o"), "--reference-position", "1,2"]) == 2


def test_real_logs_without_sfrbx_give_nan_states_and_the_receiver_spectra(tmp_path, capsys):
    # pyubx2's real captures, one after the other: 14 RXM-RAWX epochs (no navigation data), then the
    # MON log and the ALL log (MON-HW, MON-RF, MON-SPAN; one GPS subframe 4 in ALL: no ephemeris)
    log = tmp_path / "real.ubx"
    log.write_bytes(b"".join((REAL / f"pygpsdata-{k}.log").read_bytes() for k in ("RXMRAWX", "MON", "ALL")))
    msgs = _bag(tmp_path, log)
    assert "satellites_without_ephemeris" in capsys.readouterr().out
    arrays = [m for topic, _, m in msgs if topic == ubx_to_bag.MEASUREMENTS_TOPIC]
    reports = [m for topic, _, m in msgs if topic == ubx_to_bag.INTERFERENCE_TOPIC]
    spectra = [(t, m) for topic, t, m in msgs if topic == ubx_to_bag.SPECTRUM_TOPIC]
    assert (len(arrays), len(reports), len(spectra)) == (14, 5, 2)
    fusion = FusionFilter(FusionParams(use_uwb=False))
    for msg in arrays:
        epoch = msg_to_epoch(msg)
        assert len(epoch.observations) >= 20
        for o in epoch.observations:  # real pseudorange and C/N0, NaN satellite states
            assert 1.9e7 < o.pseudorange_m < 4.8e7 and 0.0 < o.cn0_dbhz < 60.0  # BeiDou GEO: 41 000 km
            assert np.isnan(o.satellite_position_ecef_m).all() and np.isnan(o.satellite_velocity_ecef_mps).all()
            assert math.isnan(o.satellite_clock_bias_m) and math.isnan(o.troposphere_delay_m)
        assert not fusion.process(epoch).initialized  # the fusion rejects every such satellite ...
    rejected = sum(len(msg_to_epoch(m).observations) for m in arrays)
    assert fusion.rejection_counts["nonfinite_pseudorange"] == rejected  # ... and counts it under this name
    last = gps_to_ros_stamp_ns(2327, 223806.0)  # the latest RAWX epoch before the reports
    for t, sp in spectra:
        assert t == last and sp.header.frame_id == "gnss" and (sp.gps_week, sp.gps_time_of_week_s) == (2327, 223806.0)
        assert (sp.rf_block_id, sp.center_frequency_hz, sp.span_hz, sp.resolution_hz, sp.pga_gain_db) == (
            0, 1583.4e6, 128e6, 0.5e6, 12.0)
        assert len(sp.power_db) == 256 and all(v % 0.25 == 0.0 for v in sp.power_db)
    assert spectra[0][1].power_db[32] == 16.25 and spectra[1][1].power_db[127] == 35.0  # as pyubx2 parses them
    out = tmp_path / "skip"
    assert ubx_to_bag.main(["ubx_to_bag", str(log), str(out), "--skip-without-ephemeris"]) == 0
    with BagReader(out) as reader:
        topics = {m.topic for m in reader.messages()}
    assert topics == {ubx_to_bag.INTERFERENCE_TOPIC, ubx_to_bag.SPECTRUM_TOPIC}
