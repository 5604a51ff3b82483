"""rinex_to_bag on the real ARL1 RINEX 2 pair (gnss_common test data), read back from the bag."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from gnss_common.coordinates import azimuth_elevation
from gnss_common.ephemeris import earth_rotation_correction
from gnss_common.gps_time import gps_to_ros_stamp_ns
from gnss_common.measurements import GnssEpochBuilder
from gnss_common.rinex import read_rinex_nav, read_rinex_obs
from rfi_experiments.bag_io import BagReader
from rfi_experiments.rinex_to_bag import (
    IONOSPHERE_FREE_METADATA_KEY,
    IONOSPHERE_METADATA_KEY,
    MEASUREMENTS_TOPIC,
    TRUTH_TOPIC,
    convert_rinex,
    main,
)
from rfi_node_common.conversions import msg_to_epoch, msg_to_point

DATA = Path(__file__).resolve().parents[2] / "gnss_common" / "test" / "data"
OBS = DATA / "arlm200a.15o"
NAV = DATA / "arlm2000.15n"
ARL1_ECEF_M = np.array([-740289.918, -5457071.734, 3207245.542])  # header APPROX POSITION XYZ


def _run(*args: str) -> int:
    return main(["rinex_to_bag", *map(str, args)])


@pytest.fixture(scope="module")
def arl1_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("rinex") / "arl1"
    assert _run(OBS, NAV, out) == 0
    return out


@pytest.fixture(scope="module")
def bag_content(arl1_bag: Path) -> dict[str, list]:
    content: dict[str, list] = {MEASUREMENTS_TOPIC: [], TRUTH_TOPIC: []}
    with BagReader(arl1_bag) as reader:
        assert set(reader.topics) == {MEASUREMENTS_TOPIC, TRUTH_TOPIC}
        for m in reader.messages():
            content[m.topic].append((m.stamp_ns, m.decode()))
    return content


def test_counts_and_time_base(bag_content: dict[str, list]) -> None:
    obs = read_rinex_obs(OBS)
    arrays = bag_content[MEASUREMENTS_TOPIC]
    assert len(arrays) == len(obs.epochs) == 120
    stamps = [msg_to_epoch(msg).stamp_ns for _, msg in arrays]
    # bag log time equals the header stamp, stamps strictly increase at the 30 s interval
    assert [log for log, _ in arrays] == stamps
    assert np.all(np.diff(stamps) == 30 * 10**9)
    # first epoch 2015-07-19 00:00:00 GPST = GPS week 1854, tow 0 (a Sunday); the stamp is ROS
    # (UTC) time, 17 s behind GPS time in 2015: 2015-07-18 23:59:43 UTC
    assert stamps[0] == gps_to_ros_stamp_ns(1854, 0.0) == 1_437_263_983 * 10**9
    # every stamp is the ROS time of the message's own GPS week / time of week
    for _, msg in arrays:
        assert msg_to_epoch(msg).stamp_ns == gps_to_ros_stamp_ns(msg.gps_week, msg.gps_time_of_week_s)
    assert all(msg.header.frame_id == "earth" for _, msg in arrays)
    n_meas = sum(len(msg.measurements) for _, msg in arrays)
    assert n_meas > 6 * len(arrays)  # a monitor station tracks 7-11 GPS satellites


def test_one_epoch_equals_builder_output(bag_content: dict[str, list]) -> None:
    obs, nav = read_rinex_obs(OBS), read_rinex_nav(NAV)
    expected = GnssEpochBuilder.from_rinex(obs, nav).build(obs.epochs[57]).epoch
    got = msg_to_epoch(bag_content[MEASUREMENTS_TOPIC][57][1])
    assert got.stamp_ns == expected.stamp_ns and got.gps_week == expected.gps_week
    assert got.gps_time_of_week_s == expected.gps_time_of_week_s
    assert len(got.observations) == len(expected.observations) > 0
    for a, b in zip(got.observations, expected.observations, strict=True):
        assert (a.constellation, a.svid) == (b.constellation, b.svid)
        np.testing.assert_array_equal(a.satellite_position_ecef_m, b.satellite_position_ecef_m)
        np.testing.assert_array_equal(a.satellite_velocity_ecef_mps, b.satellite_velocity_ecef_mps)
        for name in ("pseudorange_m", "pseudorange_rate_mps", "cn0_dbhz", "satellite_clock_bias_m",
                     "satellite_clock_drift_mps", "ionosphere_delay_m", "troposphere_delay_m"):
            assert getattr(a, name) == getattr(b, name), name
        assert math.isnan(a.pseudorange_std_m) and math.isnan(a.pseudorange_rate_std_mps)


def test_truth_is_header_position_at_every_epoch(bag_content: dict[str, list]) -> None:
    truth = bag_content[TRUTH_TOPIC]
    arrays = bag_content[MEASUREMENTS_TOPIC]
    assert len(truth) == len(arrays)
    for (log_t, point), (_, array) in zip(truth, arrays, strict=True):
        stamp_ns, xyz, frame = msg_to_point(point)
        assert frame == "earth" and stamp_ns == log_t == msg_to_epoch(array).stamp_ns
        np.testing.assert_array_equal(xyz, ARL1_ECEF_M)


def test_elevation_mask_drops_exactly_the_low_satellites() -> None:
    open_sky = convert_rinex(OBS, NAV, elevation_mask_deg=-90.0)
    masked = convert_rinex(OBS, NAV, elevation_mask_deg=15.0)
    assert open_sky.skipped["below_elevation_mask"] == 0
    dropped = masked.skipped["below_elevation_mask"]
    assert dropped > 0
    assert open_sky.measurement_count - masked.measurement_count == dropped
    n_low = 0
    for full, kept in zip(open_sky.epochs, masked.epochs, strict=True):
        sats = np.array([o.satellite_position_ecef_m for o in full.observations])
        _, el = azimuth_elevation(ARL1_ECEF_M, earth_rotation_correction(sats, ARL1_ECEF_M)[0])
        high = {o.svid for o, e in zip(full.observations, el, strict=True) if e >= math.radians(15.0)}
        assert {o.svid for o in kept.observations} == high
        n_low += len(full.observations) - len(high)
    assert n_low == dropped


def test_rinex3_file_converts(tmp_path: Path) -> None:
    assert _run(DATA / "hand_rnx3.rnx", DATA / "hand_rnx3.nav", tmp_path / "b") == 0
    with BagReader(tmp_path / "b") as reader:
        assert reader.topics[MEASUREMENTS_TOPIC][1] == 3
        svids = [{m.svid for m in msg.decode().measurements} for msg in reader.messages([MEASUREMENTS_TOPIC])]
    # the invented GLONASS / Galileo satellites are skipped, GPS ones kept
    assert all(s and all(1 <= v <= 32 for v in s) for s in svids)


def _assert_one_line_error(capsys: pytest.CaptureFixture[str], fragment: str) -> None:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("rinex_to_bag: error: ") and fragment in err[0], err
    assert "Traceback" not in err[0]


def test_error_missing_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert _run(tmp_path / "nope.15o", NAV, tmp_path / "out") == 2
    _assert_one_line_error(capsys, "cannot read file")
    assert not (tmp_path / "out").exists()


def test_error_malformed_rinex(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.15o"
    lines = OBS.read_text().splitlines(keepends=True)
    end = next(i for i, line in enumerate(lines) if "END OF HEADER" in line)
    bad.write_text("".join(lines[: end + 1]) + " 15  7 19  0  0  0.0000000  0 xx\n")
    assert _run(bad, NAV, tmp_path / "out") == 2
    _assert_one_line_error(capsys, "bad.15o")
    # nav and obs swapped
    assert _run(NAV, OBS, tmp_path / "out") == 2
    _assert_one_line_error(capsys, "not an observation file")


def test_error_no_epochs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    header_only = tmp_path / "empty.15o"
    lines = OBS.read_text().splitlines(keepends=True)
    end = next(i for i, line in enumerate(lines) if "END OF HEADER" in line)
    header_only.write_text("".join(lines[: end + 1]))
    assert _run(header_only, NAV, tmp_path / "out") == 2
    _assert_one_line_error(capsys, "no observation epochs")
    assert not (tmp_path / "out").exists()


def test_error_output_exists_and_overwrite(arl1_bag: Path, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "copy"
    shutil.copytree(arl1_bag, out)
    before = sorted((p.name, p.stat().st_size) for p in out.iterdir())
    assert _run(OBS, NAV, out) == 2
    _assert_one_line_error(capsys, "exists already")
    assert sorted((p.name, p.stat().st_size) for p in out.iterdir()) == before
    assert _run(DATA / "hand_rnx3.rnx", DATA / "hand_rnx3.nav", out, "--overwrite") == 0
    with BagReader(out) as reader:
        assert reader.topics[MEASUREMENTS_TOPIC][1] == 3


def test_error_bad_mask(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert _run(OBS, NAV, tmp_path / "out", "--elevation-mask-deg", "95") == 2
    _assert_one_line_error(capsys, "elevation-mask-deg")
    assert _run(OBS, NAV, tmp_path / "out", "--elevation-mask-deg", "nan") == 2
    _assert_one_line_error(capsys, "elevation-mask-deg")


def test_help_says_truth_is_published_position(capsys: pytest.CaptureFixture[str]) -> None:
    assert _run("--help") == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "APPROX POSITION" in text and "published position" in text


def test_ionosphere_free_option(arl1_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--ionosphere-free: GPS P1/P2 combination without ionospheric delay, said in the summary and the metadata."""
    out = tmp_path / "arl1_if"
    assert _run(OBS, NAV, out, "--ionosphere-free") == 0
    assert "ionosphere-free L1/L2 P(Y) combination" in capsys.readouterr().out
    expected = convert_rinex(OBS, NAV, ionosphere_free=True)
    assert expected.codes_by_constellation == {"gps": {"P1+P2": expected.measurement_count}}
    with BagReader(out) as bag:
        assert bag.custom_data[IONOSPHERE_FREE_METADATA_KEY] == "true"
        msgs = [m.decode() for m in bag.messages([MEASUREMENTS_TOPIC])]
    assert len(msgs) == len(expected.epochs)
    for msg, epoch in zip(msgs, expected.epochs, strict=True):
        got = msg_to_epoch(msg)
        assert [o.pseudorange_m for o in got.observations] == [o.pseudorange_m for o in epoch.observations]
        assert all(o.ionosphere_delay_m == 0.0 for o in got.observations)
    with BagReader(arl1_bag) as bag:
        assert bag.custom_data[IONOSPHERE_FREE_METADATA_KEY] == "false"


GEONET = DATA / "07590920.05o", DATA / "07590920.05n"


def test_ionosphere_carrier_levelled_option(arl1_bag: Path, tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    """--ionosphere carrier-levelled (GEONET 0759, C1/P2 with L1/L2 carriers): GPS delays from the
    carrier, Klobuchar where a carrier is missing, counted in the summary and the metadata; the
    pseudoranges and every other field are unchanged."""
    out = tmp_path / "geonet_lev"
    assert _run(*GEONET, out, "--ionosphere", "carrier-levelled") == 0
    summary = capsys.readouterr().out
    levelled = convert_rinex(*GEONET, ionosphere="carrier-levelled")
    plain = convert_rinex(*GEONET)
    counts = levelled.ionosphere_counts
    assert counts["levelled"] + counts["model"] == plain.measurement_count
    assert counts["levelled"] > 0.9 * plain.measurement_count
    assert f"carrier-levelled: GPS {counts['levelled']} levelled" in summary
    with BagReader(out) as bag:
        assert json.loads(bag.custom_data[IONOSPHERE_METADATA_KEY]) == {"source": "carrier-levelled", **counts}
        msgs = [msg_to_epoch(m.decode()) for m in bag.messages([MEASUREMENTS_TOPIC])]
    with BagReader(arl1_bag) as bag:
        assert json.loads(bag.custom_data[IONOSPHERE_METADATA_KEY]) == {"source": "klobuchar"}
    changed = 0
    for got, lev, ref in zip(msgs, levelled.epochs, plain.epochs, strict=True):
        assert [o.ionosphere_delay_m for o in got.observations] == [o.ionosphere_delay_m for o in lev.observations]
        for a, b in zip(lev.observations, ref.observations, strict=True):
            assert a.pseudorange_m == b.pseudorange_m and a.svid == b.svid
            changed += a.ionosphere_delay_m != b.ionosphere_delay_m
    assert changed == counts["levelled"]
    # the per-arc level is Klobuchar's: over the file the two agree on average
    d = np.array([a.ionosphere_delay_m - b.ionosphere_delay_m
                  for e, r in zip(levelled.epochs, plain.epochs, strict=True)
                  for a, b in zip(e.observations, r.observations, strict=True)])
    assert abs(d.mean()) < 0.1


def test_ionosphere_options_exclude_each_other(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    assert _run(OBS, NAV, tmp_path / "x", "--ionosphere", "carrier-levelled", "--ionosphere-free") == 2
    assert "exclude each other" in capsys.readouterr().err
