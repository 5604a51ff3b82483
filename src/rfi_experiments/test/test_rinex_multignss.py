"""rinex_to_bag on a real multi-GNSS station hour (ESBC00DNK, RINEX 3.05 mixed, Hatanaka + gzip):
every constellation with a satellite state is carried, the others are counted per constellation."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import hatanaka
import numpy as np
import pytest

from gnss_common.observations import BEIDOU, GALILEO, GLONASS, GPS
from rfi_experiments.bag_io import BagReader
from rfi_experiments.rinex_to_bag import MEASUREMENTS_TOPIC, TRUTH_TOPIC, convert_rinex, main
from rfi_node_common.conversions import msg_to_epoch

DATA = Path(__file__).resolve().parents[2] / "gnss_common" / "test" / "data"
OBS = DATA / "ESBC00DNK_R_20201770000_01H_30S_MO.crx.gz"
NAV = DATA / "ESBC00DNK_R_20201770000_01H_MN.rnx.gz"
NAV4 = DATA / "ESBC00DNK_R_20201770000_01H_MN_rinex4.rnx.gz"  # the same records, RINEX 4 layout
STATION_ECEF_M = np.array([3582105.2910, 532589.7313, 5232754.8054])


def _run(*args: object) -> int:
    return main(["rinex_to_bag", *map(str, args)])


@pytest.fixture(scope="module")
def esbc(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    out = tmp_path_factory.mktemp("esbc") / "bag"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert _run(OBS, NAV, out, "--elevation-mask-deg", "5") == 0
    return out, buf.getvalue()


def test_every_constellation_with_an_orbit_is_carried(esbc: tuple[Path, str]) -> None:
    out, text = esbc
    with BagReader(out) as reader:
        assert reader.topics[MEASUREMENTS_TOPIC][1] == 120
        assert reader.topics[TRUTH_TOPIC][1] == 120
        epochs = [msg_to_epoch(m.decode()) for m in reader.messages([MEASUREMENTS_TOPIC])]
    per_epoch = [{o.constellation for o in e.observations} for e in epochs]
    assert all(s >= {GPS, GALILEO, BEIDOU, GLONASS} for s in per_epoch)
    carriers = {o.constellation: set() for e in epochs for o in e.observations}
    for e in epochs:
        for o in e.observations:
            carriers[o.constellation].add(o.carrier_frequency_hz)
    assert carriers[GPS] == carriers[GALILEO] == {1575.42e6} and carriers[BEIDOU] == {1561.098e6}
    assert len(carriers[GLONASS]) > 3 and all(1598.0e6 <= f <= 1610.0e6 for f in carriers[GLONASS])
    for e in epochs[::20]:
        for o in e.observations:
            r = np.linalg.norm(o.satellite_position_ecef_m)
            assert 2.0e7 < r < 4.5e7 and 1.9e7 < o.pseudorange_m < 4.8e7
    # The printed summary says what was carried and what was skipped, per constellation.
    for fragment in ("measurements by constellation", "galileo", "beidou", "glonass", "gps",
                     "skipped satellites by constellation and reason", "sbas", "unsupported_constellation",
                     "navigation records not used, galileo: galileo_fnav"):
        assert fragment in text, fragment


def test_restricted_constellations_and_per_system_nav_files(tmp_path: Path) -> None:
    gps_only = convert_rinex(OBS, NAV, 5.0, ("G",))
    assert {o.constellation for e in gps_only.epochs for o in e.observations} == {GPS}
    assert gps_only.skipped_by_constellation["galileo"]["unsupported_constellation"] > 0
    assert gps_only.skipped_by_constellation["glonass"]["unsupported_constellation"] > 0
    # One nav file per system, as some archives publish them, gives the same measurements.
    lines = hatanaka.decompress(NAV.read_bytes()).decode().splitlines()
    end = next(i for i, line in enumerate(lines) if "END OF HEADER" in line)
    files: dict[str, list[str]] = {}
    current = ""
    for line in lines[end + 1:]:
        if line[:1].strip():
            current = line[0]
        files.setdefault(current, []).append(line)
    paths = []
    for letter, body in files.items():
        p = tmp_path / f"nav_{letter}.rnx"
        p.write_text("\n".join([lines[0][:40] + letter + lines[0][41:], *lines[1:end + 1], *body]) + "\n")
        paths.append(p)
    mixed = convert_rinex(OBS, NAV, 5.0, ("G", "E", "C", "R"))
    split = convert_rinex(OBS, paths, 5.0, ("G", "E", "C", "R"))
    assert split.measurements_by_constellation() == mixed.measurements_by_constellation()
    assert len(mixed.measurements_by_constellation()) == 4
    a, b = split.epochs[7].observations, mixed.epochs[7].observations
    assert [(o.constellation, o.svid) for o in a] == [(o.constellation, o.svid) for o in b]
    out = tmp_path / "bag"
    assert _run(OBS, *paths, out, "--constellations", "G,E") == 0
    with BagReader(out) as reader:
        seen = {m.constellation for msg in reader.messages([MEASUREMENTS_TOPIC]) for m in msg.decode().measurements}
    assert seen == {GPS, GALILEO}


def test_rinex4_nav_file_gives_the_same_measurements(tmp_path: Path) -> None:
    """A RINEX 4 nav file (records under '> EPH' lines, Klobuchar in an ION record) converts to the
    measurements of its RINEX 3 original; the records it cannot use are named in the summary."""
    systems = ("G", "E", "C", "R")
    rinex3 = convert_rinex(OBS, NAV, 5.0, systems)
    rinex4 = convert_rinex(OBS, NAV4, 5.0, systems)
    assert rinex4.measurements_by_constellation() == rinex3.measurements_by_constellation()
    assert len(rinex4.epochs) == len(rinex3.epochs) == 120
    for a, b in zip(rinex4.epochs[::10], rinex3.epochs[::10], strict=True):
        ids = [(o.constellation, o.svid) for o in b.observations]
        assert [(o.constellation, o.svid) for o in a.observations] == ids
        for x, y in zip(a.observations, b.observations, strict=True):
            assert x.pseudorange_m == y.pseudorange_m
            np.testing.assert_array_equal(x.satellite_position_ecef_m, y.satellite_position_ecef_m)
            assert x.ionosphere_delay_m == y.ionosphere_delay_m != 0.0  # the Klobuchar parameters of the ION record
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert _run(OBS, NAV4, tmp_path / "bag", "--constellations", "G,E") == 0
    assert "unsupported_message" in buf.getvalue() and "sto_record" in buf.getvalue()


def _one_line_error(capsys: pytest.CaptureFixture[str], fragment: str) -> None:
    err = capsys.readouterr().err.strip().splitlines()
    assert err and fragment in err[-1], err
    assert not any("Traceback" in line for line in err)


def test_bad_input_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cut = tmp_path / "cut.crx.gz"
    cut.write_bytes(OBS.read_bytes()[:40000])
    assert _run(cut, NAV, tmp_path / "out") == 2
    _one_line_error(capsys, "cannot decompress")
    assert not (tmp_path / "out").exists()
    assert _run(OBS, NAV, tmp_path / "out", "--constellations", "G,S") == 2
    _one_line_error(capsys, "expected system letters")
    nav_cut = tmp_path / "nav.rnx"
    text = hatanaka.decompress(NAV.read_bytes()).decode().splitlines()
    start = next(i for i, line in enumerate(text) if line.startswith("C"))
    nav_cut.write_text("\n".join(text[: start + 3]) + "\n")
    assert _run(OBS, nav_cut, tmp_path / "out") == 2
    _one_line_error(capsys, "truncated")


def test_gps_only_fusion_skips_the_other_constellations_by_name() -> None:
    """With ``multi_gnss=False`` the fusion filter uses GPS alone: on the multi-GNSS epochs it gives
    the same outputs as on their GPS subset, and counts every other satellite under
    ``skipped_constellation.<name>``, not as a rejected satellite (the multi-GNSS default is tested
    in uwb_gnss_fusion's test_multignss_filter.py)."""
    from dataclasses import replace

    from uwb_gnss_fusion.fusion_filter import FusionFilter, FusionParams

    conv = convert_rinex(OBS, NAV, 10.0)
    params = FusionParams(use_uwb=False, multi_gnss=False)
    mixed, gps = FusionFilter(params), FusionFilter(params)
    expected: dict[str, int] = {}
    names = {GALILEO: "galileo", BEIDOU: "beidou", GLONASS: "glonass"}
    used = rejected = 0
    for epoch in conv.epochs[:40]:
        for o in epoch.observations:
            if o.constellation != GPS:
                key = f"skipped_constellation.{names[o.constellation]}"
                expected[key] = expected.get(key, 0) + 1
        a = mixed.process_gnss(epoch)
        b = gps.process_gnss(replace(epoch, observations=tuple(o for o in epoch.observations
                                                               if o.constellation == GPS)))
        np.testing.assert_array_equal(a.position_m, b.position_m)
        assert (a.satellites_used, a.satellites_rejected) == (b.satellites_used, b.satellites_rejected)
        used += a.satellites_used
        rejected += a.satellites_rejected
    counts = mixed.rejection_counts
    assert {k: v for k, v in counts.items() if k.startswith("skipped_constellation.")} == expected
    assert set(expected) == {f"skipped_constellation.{n}" for n in ("galileo", "beidou", "glonass")}
    assert not any(k.startswith("skipped_constellation.") for k in gps.rejection_counts)
    assert used > 0 and rejected < used
    assert np.linalg.norm(a.position_m - STATION_ECEF_M) < 20.0
