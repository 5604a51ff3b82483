"""ubx_to_bag end to end on a UBX stream generated from the simulator: the measurements and the
fused positions equal those of the same scenario taken the direct way (simulator -> fusion), within
the tolerances stated here; and the tool's refusals of bad input."""

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
"""RAWX epochs sent before the first SFRBX subframes: withheld and counted."""

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
    assert len(arrays) == n - EPOCHS_BEFORE_EPHEMERIS
    assert len(reports) == n
    assert [r.jamming_state for r in reports].count(3) == 60 and reports[-1].agc_count == 600.0
    direct = {round(e.gps_time_of_week_s, 3): e for e in run.gnss_epochs}
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
    assert len(arrays) == len(run.gnss_epochs) - EPOCHS_BEFORE_EPHEMERIS
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
    rawx_only.write_bytes((Path(__file__).parent / "data" / "ubx" / "pygpsdata-RXMRAWX.log").read_bytes())
    assert ubx_to_bag.main(["ubx_to_bag", str(rawx_only), str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "nothing to write" in err and "14 epochs waiting for ephemeris" in err
    garbage = tmp_path / "garbage.ubx"
    garbage.write_bytes(np.random.default_rng(1).integers(0, 256, 20000, dtype=np.uint8).tobytes())
    assert ubx_to_bag.main(["ubx_to_bag", str(garbage), str(tmp_path / "o")]) == 2
    assert "0 valid UBX frames" in capsys.readouterr().err
    (tmp_path / "exists").mkdir()
    assert ubx_to_bag.main(["ubx_to_bag", str(path), str(tmp_path / "exists")]) == 2
    assert ubx_to_bag.main(["ubx_to_bag", str(path), str(tmp_path / "o"), "--reference-position", "1,2"]) == 2
