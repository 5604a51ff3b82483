"""RINEX 4 navigation and observation files (IGS RINEX 4.01, 2022): the real ESBC00DNK hour
(RINEX 3.05, mixed) rewritten in the RINEX 4 layout must give the same ephemerides, Klobuchar
parameters and observations as the RINEX 3 original; the RINEX 4 records that carry no usable
ephemeris (CNAV, STO, EOP, other ION messages) are counted; malformed records name the line."""

from __future__ import annotations

import gzip
import re
from dataclasses import fields
from pathlib import Path

import hatanaka
import numpy as np
import pytest

from gnss_common.rinex import NAV_SKIP_REASONS, RinexFormatError, read_rinex_nav, read_rinex_navs, read_rinex_obs

DATA = Path(__file__).resolve().parent / "data"
NAV3 = DATA / "ESBC00DNK_R_20201770000_01H_MN.rnx.gz"
OBS3 = DATA / "ESBC00DNK_R_20201770000_01H_30S_MO.crx.gz"
NAV4 = DATA / "ESBC00DNK_R_20201770000_01H_MN_rinex4.rnx.gz"
"""The same records in the RINEX 4 layout (written by :func:`_rinex3_nav_to_rinex4`; other packages'
tests read it as a RINEX 4 nav file)."""
_GALILEO_INAV_BITS = 0b101

# Records that RINEX 4 adds and this reader does not use; the values are invented, the layouts
# those of RINEX 4.01 (STO, EOP, a Galileo NeQuick ION record, a GPS CNAV ephemeris).
_EXTRA_RECORDS = """> STO G05 LNAV
    2020 06 25 00 00 00 GPUT
     3.456000000000e+05 9.313225746155e-10 2.664535259100e-15 0.000000000000e+00
> EOP G05 CNVX
    2020 06 25 00 00 00 1.000000000000e-02 1.000000000000e-03 0.000000000000e+00
                        2.000000000000e-01 1.000000000000e-03 0.000000000000e+00
     3.456000000000e+05-1.000000000000e-03 1.000000000000e-04 0.000000000000e+00
> ION E01 IFNV
    2020 06 25 00 00 00 2.825000000000e+01 7.812500000000e-03 1.007080078125e-02
     0.000000000000e+00
> EPH G05 CNAV
G05 2020 06 25 00 00 00 1.000000000000e-04 1.000000000000e-12 0.000000000000e+00
     0.000000000000e+00 1.000000000000e+00 1.000000000000e-09 1.000000000000e+00
     1.000000000000e-06 1.000000000000e-02 1.000000000000e-06 5.153000000000e+03
     3.456000000000e+05 1.000000000000e-07 1.000000000000e+00 1.000000000000e-07
     9.600000000000e-01 2.000000000000e+02 1.000000000000e+00-8.000000000000e-09
     1.000000000000e-10 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00
     0.000000000000e+00 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00
     0.000000000000e+00 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00
     3.456000000000e+05 0.000000000000e+00
"""


def _field(x: float) -> str:
    """One RINEX 4 D19.12 field."""
    return f"{x:19.12e}"


def _rinex3_nav_to_rinex4(text: str, with_extras: bool = True) -> str:
    """The records of a RINEX 3 nav file in the RINEX 4 layout: version 4.00, the GPS Klobuchar
    parameters moved from the header into an ``ION G.. LNAV`` record, every ephemeris under a
    ``> EPH SAT MESSAGE`` line (Galileo I/NAV or F/NAV from its data-source bits, BeiDou GEO D2)."""
    lines = text.splitlines()
    end = next(i for i, ln in enumerate(lines) if ln[60:].strip() == "END OF HEADER")
    header = []
    alpha = beta = None
    for ln in lines[: end + 1]:
        label = ln[60:].strip()
        if label == "RINEX VERSION / TYPE":
            ln = "     4.00           NAVIGATION DATA     M" + " " * 19 + "RINEX VERSION / TYPE"
        elif label == "IONOSPHERIC CORR" and ln[0:4] in ("GPSA", "GPSB"):
            vals = [float(ln[5 + 12 * k: 17 + 12 * k].replace("D", "E")) for k in range(4)]
            alpha, beta = (vals, beta) if ln[0:4] == "GPSA" else (alpha, vals)
            continue
        header.append(ln)
    out = list(header)  # ends with END OF HEADER
    if alpha is not None and beta is not None:
        out += ["> ION G01 LNAV",
                "    2020 06 25 00 00 00" + "".join(_field(v) for v in alpha[0:3]),
                "    " + "".join(_field(v) for v in [alpha[3], *beta[0:3]]),
                "    " + _field(beta[3])]
    if with_extras:
        out += _EXTRA_RECORDS.splitlines()
    i = end + 1
    while i < len(lines):
        if not lines[i].strip():
            i += 1
            continue
        j = i + 1
        while j < len(lines) and lines[j][0:1] == " " and lines[j].strip():
            j += 1
        rec = lines[i:j]
        sat = rec[0][0:3]
        if sat[0] == "E":
            msg = "INAV" if int(float(rec[5][4:23].replace("D", "E"))) & _GALILEO_INAV_BITS else "FNAV"
        elif sat[0] == "C":
            msg = "D2" if int(sat[1:]) <= 5 or int(sat[1:]) >= 59 else "D1"
        elif sat[0] == "R":
            msg = "FDMA"
        elif sat[0] == "S":
            msg = "SBAS"
        else:
            msg = "LNAV"
        out.append(f"> EPH {sat} {msg}")
        out += rec
        i = j
    return "\n".join(out) + "\n"


@pytest.fixture(scope="module")
def nav3():
    return read_rinex_nav(NAV3)


@pytest.fixture(scope="module")
def nav4_path():
    return NAV4


def test_the_rinex4_test_file_is_the_rewritten_rinex3_file():
    rinex3 = gzip.decompress(NAV3.read_bytes()).decode()
    assert gzip.decompress(NAV4.read_bytes()).decode() == _rinex3_nav_to_rinex4(rinex3)


def _same_records(a, b) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        for f in fields(x):
            np.testing.assert_array_equal(getattr(x, f.name), getattr(y, f.name), err_msg=f.name)


def test_rinex4_nav_gives_the_records_of_its_rinex3_original(nav3, nav4_path):
    nav4 = read_rinex_nav(nav4_path)
    assert nav4.header.version == 4.0
    assert nav4.record_counts() == nav3.record_counts()
    assert all(n > 0 for n in nav4.record_counts().values())
    _same_records(nav4.ephemerides, nav3.ephemerides)
    _same_records(nav4.other_ephemerides, nav3.other_ephemerides)
    _same_records(nav4.glonass_ephemerides, nav3.glonass_ephemerides)
    # Klobuchar from the ION record (the header of a RINEX 4 file has none)
    np.testing.assert_array_equal(nav4.header.iono_alpha, nav3.header.iono_alpha)
    np.testing.assert_array_equal(nav4.header.iono_beta, nav3.header.iono_beta)
    assert np.all(np.isfinite(nav4.header.iono_alpha)) and nav4.header.leap_seconds == 18


def test_rinex4_records_not_used_are_counted_by_reason(nav3, nav4_path):
    nav4 = read_rinex_nav(nav4_path)
    g = nav4.skipped_reasons["G"]
    assert g == {"sto_record": 1, "eop_record": 1, "unsupported_message": 1}
    assert nav4.skipped_reasons["E"] == {**nav3.skipped_reasons["E"], "ion_record": 1}
    assert nav4.skipped_records["G"] == 3
    assert set(r for by in nav4.skipped_reasons.values() for r in by) <= set(NAV_SKIP_REASONS)


def test_rinex4_nav_one_file_per_system(nav3, nav4_path, tmp_path):
    """Archives that publish one RINEX 4 nav file per system: merged, the same records."""
    text = gzip.decompress(nav4_path.read_bytes()).decode()
    lines = text.splitlines()
    end = next(i for i, ln in enumerate(lines) if ln[60:].strip() == "END OF HEADER")
    head, body = lines[: end + 1], lines[end + 1:]
    per_sys: dict[str, list[str]] = {}
    cur: list[str] = []
    for ln in body:
        if ln.startswith(">"):
            cur = per_sys.setdefault(ln.split()[2][0], [])
        cur.append(ln)
    paths = []
    for sys_char, rec in sorted(per_sys.items()):
        p = tmp_path / f"nav_{sys_char}.rnx"
        p.write_text("\n".join(head + rec) + "\n")
        paths.append(p)
    merged = read_rinex_navs(paths)
    assert merged.record_counts() == nav3.record_counts()
    np.testing.assert_array_equal(merged.header.iono_alpha, nav3.header.iono_alpha)


def test_rinex4_obs_reads_as_its_rinex3_original(tmp_path):
    text = hatanaka.decompress(OBS3.read_bytes()).decode()
    lines = text.splitlines()
    assert lines[0].startswith("     3.05")
    lines[0] = "     4.00" + lines[0][9:]
    p = tmp_path / "esbc4.rnx"
    p.write_text("\n".join(lines) + "\n")
    obs4, obs3 = read_rinex_obs(p), read_rinex_obs(OBS3)
    assert obs4.header.version == 4.0
    assert len(obs4.epochs) == len(obs3.epochs) == 120
    for a, b in zip(obs4.epochs, obs3.epochs, strict=True):
        assert (a.gps_week, a.tow_s) == (b.gps_week, b.tow_s)
        assert a.observations.keys() == b.observations.keys()


_HEADER4 = ("     4.00           NAVIGATION DATA     M" + " " * 19 + "RINEX VERSION / TYPE\n"
            + " " * 60 + "END OF HEADER\n")


@pytest.mark.parametrize(
    ("body", "line", "words"),
    [
        ("G05 2020 06 25 00 00 00 1.0e-04 0.0 0.0\n", 3, "expected a '> TYPE SAT MESSAGE' line"),
        ("> EPH\n", 3, "malformed RINEX 4 record line"),
        ("> EPH G05 LNAV\nG05 2020 06 25 00 00 00 1.0e-04 0.0 0.0\n", 3, "truncated (needs 8 lines)"),
        ("> EPH G05 LNAV\n" + "G06 2020 06 25 00 00 00" + " " * 57 + "\n" + "     0.0\n" * 7, 4,
         "record of 'G06' under '> EPH G05'"),
        ("> ION G01 LNAV\n    2020 06 25 00 00 00 1.0e-08\n", 3, "ION G01 LNAV record truncated"),
    ],
)
def test_malformed_rinex4_nav_names_the_line(tmp_path, body, line, words):
    p = tmp_path / "bad4.rnx"
    p.write_text(_HEADER4 + body)
    with pytest.raises(RinexFormatError, match=f"bad4.rnx:{line}: .*{re.escape(words)}") as info:
        read_rinex_nav(p)
    assert info.value.line_no == line


def test_unknown_rinex_version_is_refused(tmp_path):
    p = tmp_path / "v5.rnx"
    p.write_text(_HEADER4.replace("4.00", "5.00"))
    with pytest.raises(RinexFormatError, match="unsupported RINEX version 5.0"):
        read_rinex_nav(p)
