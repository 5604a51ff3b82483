"""uwb_dataset_to_bag on the real Hanyang LOS/Trajectory_A/Case_1 files (test/data/uwb_hanyang_los_a1)."""

from __future__ import annotations

import csv
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from rfi_experiments.bag_io import BagReader
from rfi_experiments.uwb_dataset_to_bag import (
    ESKF_TOPIC,
    LS_TOPIC,
    TRUTH_TOPIC,
    UWB_TOPIC,
    check_time_bases,
    main,
    read_case,
    read_position_csv,
)
from rfi_node_common.conversions import msg_to_point, msg_to_uwb

CASE = Path(__file__).resolve().parent / "data" / "uwb_hanyang_los_a1"
ANCHORS = ("A3", "A5", "A9", "A12")


def _run(*args: object) -> int:
    return main(["uwb_dataset_to_bag", *map(str, args)])


def _csv_rows(name: str) -> list[list[str]]:
    with open(CASE / name, newline="") as fh:
        return list(csv.reader(fh))[1:]


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list]:
    out = tmp_path_factory.mktemp("uwb") / "los_a1"
    assert _run(CASE, out) == 0
    content: dict[str, list] = {}
    with BagReader(out) as reader:
        for m in reader.messages():
            content.setdefault(m.topic, []).append((m.stamp_ns, m.decode()))
    return content


def test_every_row_becomes_one_message(bag: dict[str, list]) -> None:
    assert set(bag) == {UWB_TOPIC, TRUTH_TOPIC, LS_TOPIC, ESKF_TOPIC}
    assert len(bag[UWB_TOPIC]) == sum(len(_csv_rows(f"{a}.csv")) for a in ANCHORS)
    assert len(bag[TRUTH_TOPIC]) == len(_csv_rows("trajectory.csv"))
    assert len(bag[LS_TOPIC]) == len(_csv_rows("LS.csv"))
    assert len(bag[ESKF_TOPIC]) == len(_csv_rows("ESKF.csv"))
    for topic, msgs in bag.items():
        assert all(m.header.frame_id == "map" for _, m in msgs), topic
        log = [t for t, _ in msgs]
        assert all(b >= a for a, b in zip(log, log[1:], strict=False)), topic
        assert log == [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in msgs], topic


def test_uwb_fields_equal_the_csv_exactly(bag: dict[str, list]) -> None:
    by_anchor: dict[str, list] = {}
    for _, msg in bag[UWB_TOPIC]:
        by_anchor.setdefault(msg.anchor_id, []).append(msg)
    assert set(by_anchor) == {"3", "5", "9", "12"}
    for anchor in ANCHORS:
        rows = _csv_rows(f"{anchor}.csv")
        msgs = by_anchor[anchor[1:]]
        assert len(msgs) == len(rows)
        for row, msg in zip(rows, msgs, strict=True):
            meas = msg_to_uwb(msg)
            assert meas.stamp_ns == int(row[1])  # header stamp, not the record time row[0]
            assert meas.range_m == float(row[6]) and msg.rssi_dbm == float(row[7])
            np.testing.assert_array_equal(meas.anchor_position_m, [float(v) for v in row[3:6]])
            assert math.isnan(meas.range_std_m) and meas.frame_id == "map"


def test_truth_stamps_are_the_exact_gnss_stamps(bag: dict[str, list]) -> None:
    gnss_stamps = {int(r[2]) for r in _csv_rows("gnss.csv")}
    traj = _csv_rows("trajectory.csv")
    for (_, msg), row in zip(bag[TRUTH_TOPIC], traj, strict=True):
        stamp_ns, xyz, _ = msg_to_point(msg)
        assert stamp_ns in gnss_stamps and float(stamp_ns) == float(row[0])
        np.testing.assert_array_equal(xyz, [float(v) for v in row[1:4]])
    for (_, msg), row in zip(bag[LS_TOPIC], _csv_rows("LS.csv"), strict=True):
        stamp_ns, xyz, _ = msg_to_point(msg)
        assert stamp_ns == int(row[0])
        np.testing.assert_array_equal(xyz, [float(v) for v in row[1:4]])


def test_ranges_agree_with_truth_geometry(bag: dict[str, list]) -> None:
    """Frames and time bases line up: range - |truth - anchor| is small, and breaks if time is shifted."""
    truth = np.array([[msg_to_point(m)[0], *msg_to_point(m)[1]] for _, m in bag[TRUTH_TOPIC]])
    meas = [msg_to_uwb(m) for _, m in bag[UWB_TOPIC]]
    t = np.array([m.stamp_ns for m in meas], dtype=float)
    anchor = np.array([m.anchor_position_m for m in meas])
    rng = np.array([m.range_m for m in meas])

    def robust_residual_m(shift_s: float) -> float:
        ts = t + shift_s * 1e9
        ok = (ts > truth[0, 0]) & (ts < truth[-1, 0])
        pos = np.stack([np.interp(ts[ok], truth[:, 0], truth[:, k]) for k in (1, 2, 3)], axis=1)
        return float(np.median(np.abs(rng[ok] - np.linalg.norm(pos - anchor[ok], axis=1))))

    aligned = robust_residual_m(0.0)
    assert aligned < 0.25
    assert robust_residual_m(-2.0) > 2.0 * aligned and robust_residual_m(2.0) > 2.0 * aligned


def test_time_base_report_matches_independent_counts() -> None:
    case = read_case(CASE)
    report = check_time_bases(case)
    rec_minus_stamp = np.concatenate(
        [[int(r[0]) - int(r[1]) for r in _csv_rows(f"{a}.csv")] for a in ANCHORS]) / 1e6
    assert report.uwb_record_minus_stamp_ms == pytest.approx(
        (rec_minus_stamp.min(), np.median(rec_minus_stamp), rec_minus_stamp.max()))
    assert 0.0 < report.uwb_record_minus_stamp_ms[0] and report.uwb_record_minus_stamp_ms[2] < 10.0
    assert report.truth_stamps_restored == len(_csv_rows("trajectory.csv"))
    assert report.truth_stamps_rounded == 0
    eskf = np.array([int(r[0]) for r in _csv_rows("ESKF.csv")])
    last_uwb = max(int(r[1]) for a in ANCHORS for r in _csv_rows(f"{a}.csv"))
    assert report.reference_repeated_stamps[ESKF_TOPIC] == int(np.sum(eskf[1:] == eskf[:-1])) > 0
    assert report.reference_rows_after_uwb[ESKF_TOPIC] == int(np.sum(eskf > last_uwb))
    for topic in (LS_TOPIC, ESKF_TOPIC):
        p5, p50, p95 = report.reference_delay_ms[topic]
        assert 0.0 <= p5 <= p50 <= p95 < 100.0  # solver outputs follow the ranges on the same clock


def test_float_stamps_are_rounded_without_gnss(tmp_path: Path) -> None:
    (tmp_path / "t.csv").write_text(
        "timestamp,x,y,z\n1.7345014855003267e+18,1,2,3\n1734501485600000001,4,5,6\n"
    )
    table = read_position_csv(tmp_path / "t.csv")
    assert table.stamp_ns.tolist() == [int(1.7345014855003267e18), 1734501485600000001]
    assert table.inexact_stamps == 1
    exact = read_position_csv(tmp_path / "t.csv", np.array([1734501485500326730]))
    assert exact.stamp_ns[0] == 1734501485500326730 and exact.inexact_stamps == 0


def _small_case(tmp_path: Path, rows: int = 30) -> Path:
    case = tmp_path / "case"
    case.mkdir()
    for name in [f"{a}.csv" for a in ANCHORS] + ["trajectory.csv", "LS.csv", "ESKF.csv", "gnss.csv"]:
        lines = (CASE / name).read_text().splitlines(keepends=True)
        (case / name).write_text("".join(lines[: rows + 1]))
    return case


def test_bad_rows_are_rejected_and_counted(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    case = _small_case(tmp_path)
    lines = (case / "A3.csv").read_text().splitlines(keepends=True)
    fields = lines[5].split(",")
    lines[5] = ",".join(fields[:6] + ["nan"] + fields[7:])
    fields = lines[6].split(",")
    lines[6] = ",".join(fields[:6] + ["-1.5"] + fields[7:])
    (case / "A3.csv").write_text("".join(lines))
    assert _run(case, tmp_path / "out", "--range-std-m", "0.3") == 0
    assert "A3.csv: 28 ranges (rejected: non_finite 1, range_not_positive 1)" in capsys.readouterr().out
    with BagReader(tmp_path / "out") as reader:
        msgs = [m.decode() for m in reader.messages([UWB_TOPIC])]
    assert len(msgs) == 4 * 30 - 2
    assert all(math.isfinite(m.range_m) and m.range_m > 0 and m.range_std_m == 0.3 for m in msgs)


def _assert_one_line_error(capsys: pytest.CaptureFixture[str], fragment: str) -> None:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("uwb_dataset_to_bag: error: ") and fragment in err[0], err


def test_errors_exit_2_with_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert _run(tmp_path / "missing", tmp_path / "o1") == 2
    _assert_one_line_error(capsys, "no such case directory")

    case = _small_case(tmp_path)
    (case / "trajectory.csv").unlink()
    assert _run(case, tmp_path / "o2") == 2
    _assert_one_line_error(capsys, "no trajectory.csv")

    shutil.rmtree(case)
    case = _small_case(tmp_path)
    for a in ANCHORS:
        (case / f"{a}.csv").unlink()
    assert _run(case, tmp_path / "o3") == 2
    _assert_one_line_error(capsys, "no anchor files")

    shutil.rmtree(case)
    case = _small_case(tmp_path)
    text = (case / "A5.csv").read_text().replace("field.distanceFromTag", "range")
    (case / "A5.csv").write_text(text)
    assert _run(case, tmp_path / "o4") == 2
    _assert_one_line_error(capsys, "A5.csv:1: unexpected header")

    shutil.rmtree(case)
    case = _small_case(tmp_path)
    lines = (case / "A9.csv").read_text().splitlines(keepends=True)
    lines[3] = "1734501485,oops" + lines[3][lines[3].index(",", 20):]
    (case / "A9.csv").write_text("".join(lines))
    assert _run(case, tmp_path / "o5") == 2
    _assert_one_line_error(capsys, "A9.csv:4: cannot read integer header stamp")

    shutil.rmtree(case)
    case = _small_case(tmp_path)
    assert _run(case, tmp_path / "o6", "--range-std-m", "-1") == 2
    _assert_one_line_error(capsys, "--range-std-m must be > 0")
    for n in range(1, 7):
        assert not (tmp_path / f"o{n}").exists()


def test_output_exists(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    case = _small_case(tmp_path)
    assert _run(case, tmp_path / "out") == 0
    capsys.readouterr()
    assert _run(case, tmp_path / "out") == 2
    _assert_one_line_error(capsys, "exists already")
    assert _run(case, tmp_path / "out", "--overwrite") == 0
