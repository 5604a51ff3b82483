"""Tests for gnss_common.rinex on the real RINEX 2 files and the hand-made RINEX 3 pair."""

import math
from pathlib import Path

import numpy as np
import pytest

from gnss_common.rinex import RinexFormatError, read_rinex_nav, read_rinex_obs

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def arl1_obs():
    return read_rinex_obs(DATA / "arlm200a.15o")


@pytest.fixture(scope="module")
def arl1_nav():
    return read_rinex_nav(DATA / "arlm2000.15n")


def test_arl1_obs_header_and_epochs(arl1_obs):
    h = arl1_obs.header
    assert h.version == pytest.approx(2.11)
    assert h.marker_name == "ARL1"
    np.testing.assert_allclose(h.approx_position_ecef_m, [-740289.918, -5457071.734, 3207245.542])
    assert h.obs_types["G"] == ("L1", "L2", "C1", "C2", "P1", "P2", "D1", "D2", "S1", "S2")
    assert h.interval_s == 30.0
    assert len(arl1_obs.epochs) == 120
    first, last = arl1_obs.epochs[0], arl1_obs.epochs[-1]
    assert (first.gps_week, first.tow_s) == (1854, 0.0)
    assert (last.gps_week, last.tow_s) == (1854, 3570.0)
    assert sorted(first.observations) == ["G02", "G05", "G06", "G10", "G12", "G20", "G25", "G29"]
    assert math.isnan(first.receiver_clock_offset_s)
    g02 = first.observations["G02"]
    # literal values from the file's first data lines
    assert g02["C1"] == 21276226.827
    assert g02["L1"] == -20304412.007
    assert g02["D1"] == -1011.373
    assert g02["S1"] == 45.770
    assert g02["S2"] == 51.240
    assert math.isnan(g02["C2"])  # written as 0.000 in the file: missing
    assert first.observations["G29"]["P2"] == 23333949.368


def test_geonet_obs_has_no_doppler_or_snr():
    obs = read_rinex_obs(DATA / "07590920.05o")
    assert obs.header.obs_types["G"] == ("L1", "C1", "L2", "P2")
    assert len(obs.epochs) == 120
    e0 = obs.epochs[0]
    assert (e0.gps_week, e0.tow_s) == (1316, 518400.0)
    assert sorted(e0.observations) == ["G03", "G07", "G08", "G11", "G19", "G20", "G24", "G28"]
    assert e0.observations["G03"]["C1"] == 24767686.375
    assert "D1" not in e0.observations["G03"]


def test_arl1_nav(arl1_nav):
    hdr = arl1_nav.header
    np.testing.assert_allclose(hdr.iono_alpha, [0.745058e-08, 0.711478e-08, -0.603921e-08, -0.384468e-08])
    np.testing.assert_allclose(hdr.iono_beta, [0.901120e05, 0.365063e05, -0.664019e04, -0.169091e05])
    assert hdr.leap_seconds == 17
    assert len(arl1_nav.ephemerides) == 168
    e = arl1_nav.ephemerides[0]
    assert e.prn == 2
    assert (e.toc_week, e.toc_s) == (1854, 7168.0)
    assert e.af0_s == pytest.approx(0.579084269702e-03, rel=1e-12)
    assert e.sqrt_a_sqrt_m == pytest.approx(0.515359719276e04, rel=1e-12)
    assert e.toe_s == 7168.0
    assert e.week == 1854
    assert e.tgd_s == pytest.approx(-0.204890966415e-07, rel=1e-12)
    assert e.iodc == 7
    assert e.fit_interval_h == 4.0
    assert {x.health for x in arl1_nav.ephemerides if x.prn == 10} == {63}


def test_rinex3_pair_equals_rinex2_source(arl1_obs, arl1_nav):
    obs3 = read_rinex_obs(DATA / "hand_rnx3.rnx")
    assert obs3.header.version == pytest.approx(3.04)
    assert obs3.header.obs_types["G"] == ("C1C", "L1C", "D1C", "S1C", "C2W")
    assert len(obs3.epochs) == 3  # the flag-4 event record is skipped
    mapping = {"C1C": "C1", "L1C": "L1", "D1C": "D1", "S1C": "S1", "C2W": "P2"}
    for e3, e2 in zip(obs3.epochs, arl1_obs.epochs[:3], strict=True):
        assert (e3.gps_week, e3.tow_s) == (e2.gps_week, e2.tow_s)
        assert set(e3.observations) == set(e2.observations) | {"R07", "E11"}
        for sat, vals in e2.observations.items():
            for c3, c2 in mapping.items():
                a, b = e3.observations[sat][c3], vals[c2]
                assert (math.isnan(a) and math.isnan(b)) or a == b
    assert obs3.epochs[0].observations["R07"]["C1C"] == 21000000.123

    nav3 = read_rinex_nav(DATA / "hand_rnx3.nav")
    assert nav3.skipped_records == {"R": 1, "E": 1}
    np.testing.assert_allclose(nav3.header.iono_alpha, arl1_nav.header.iono_alpha, rtol=1e-4)
    assert len(nav3.ephemerides) == 9
    for e3 in nav3.ephemerides:
        matches = [
            e for e in arl1_nav.ephemerides if e.prn == e3.prn and e.toe_s == e3.toe_s and e.iode == e3.iode
        ]
        assert len(matches) == 1
        e2 = matches[0]
        for name in (
            "af0_s",
            "af1_s_per_s",
            "m0_rad",
            "e",
            "sqrt_a_sqrt_m",
            "omega0_rad",
            "i0_rad",
            "omega_rad",
            "omega_dot_radps",
            "tgd_s",
            "toc_s",
        ):
            assert getattr(e3, name) == pytest.approx(getattr(e2, name), rel=1e-11, abs=1e-20)


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_malformed_files_name_file_and_line(tmp_path):
    src = (DATA / "arlm200a.15o").read_text().splitlines()
    # 1) a corrupted observation value on line 20
    bad = list(src)
    bad[19] = "  21282XXX.614" + bad[19][14:]
    p = _write(tmp_path, "bad_value.15o", "\n".join(bad) + "\n")
    with pytest.raises(RinexFormatError, match=r"bad_value\.15o:\d+: malformed observation"):
        read_rinex_obs(p)
    # 2) truncated inside an epoch
    p = _write(tmp_path, "trunc.15o", "\n".join(src[:18]) + "\n")
    with pytest.raises(RinexFormatError, match=r"trunc\.15o:\d+: file ends inside"):
        read_rinex_obs(p)
    # 3) header without END OF HEADER
    p = _write(tmp_path, "nohdr.15o", "\n".join(src[:10]) + "\n")
    with pytest.raises(RinexFormatError, match=r"nohdr\.15o:10: no END OF HEADER"):
        read_rinex_obs(p)
    # 4) a nav file given to the obs reader
    with pytest.raises(RinexFormatError, match=r"arlm2000\.15n:1: not an observation file"):
        read_rinex_obs(DATA / "arlm2000.15n")
    # 5) a broken epoch date
    bad = list(src)
    bad[15] = " 15  X 19" + bad[15][9:]
    p = _write(tmp_path, "bad_epoch.15o", "\n".join(bad) + "\n")
    with pytest.raises(RinexFormatError, match=r"bad_epoch\.15o:16: malformed epoch date"):
        read_rinex_obs(p)
    # 6) a nav record cut short, and a non-numeric orbit field
    nav = (DATA / "arlm2000.15n").read_text().splitlines()
    p = _write(tmp_path, "trunc.15n", "\n".join(nav[:10]) + "\n")
    with pytest.raises(RinexFormatError, match=r"trunc\.15n:8: navigation record truncated"):
        read_rinex_nav(p)
    bad = list(nav)
    bad[8] = bad[8][:22] + "   abc" + bad[8][28:]
    p = _write(tmp_path, "badnum.15n", "\n".join(bad) + "\n")
    with pytest.raises(RinexFormatError, match=r"badnum\.15n:9: cannot parse orbit parameter"):
        read_rinex_nav(p)
    with pytest.raises(RinexFormatError, match="cannot read file"):
        read_rinex_obs(tmp_path / "does_not_exist.15o")
