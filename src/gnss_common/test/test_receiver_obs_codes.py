"""Observation files written with the ``SYS / # / OBS TYPES`` of real receivers (Trimble NetR9,
Septentrio PolaRx5, Leica GR50, u-blox F9P, Javad) as RINEX 3.05 and 4.00, filled with the real
values of the ESBC00DNK hour (the value of the same observable type and band), give the same
measurements as the ESBC file itself, from the code each receiver writes.

Header lines and where they come from (attribution):

- Septentrio PolaRx5: ESBC00DNK (EUREF/IGS, SDFE Denmark), this package's test data.
- Trimble NetR9: GEONET station 0228 (Setagaya; GSI Japan, RINEX 3.02 by BINEX2RINEX), as quoted in
  fenrir-naru/ninja-scan-light ``tool/test/test_RINEX.cpp``; its file carries no BeiDou, so the
  BeiDou line is the one of the NetR9 day reported in issue 27 (``C   12 C2X L2X D2X S2X C6X ...``).
- Leica GR50: ACOR00ESP (EUREF, IGN Spain), ``ACOR00ESP_R_20213550000_01D_30S_MO.rnx`` of
  georust/rinex ``test_resources/OBS/V3`` (MPL-2.0 repository; EUREF open data).
- u-blox ZED-F9P: the signal set RTKLIB ``convbin`` writes from UBX-RXM-RAWX of an F9P (the
  codes of :data:`rfi_experiments.ubx_rawx.RINEX_CODES`, u-blox F9 interface description):
  composed here, not copied from a file.
- Javad TRE_3: the observables the issue names for Javad files (GPS ``C1C C1W C2W C2L C5Q``,
  GLONASS ``C1C C1P C2C C2P``), sorted by type as gfzrnx writes IGS files: composed here, not
  copied from a file.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gnss_common.measurements import CONSTELLATION_CODES, GnssEpochBuilder
from gnss_common.observations import BEIDOU, GPS, SatelliteObservation
from gnss_common.rinex import RinexObs, RinexObsEpoch, read_rinex_nav, read_rinex_obs

DATA = Path(__file__).resolve().parent / "data"
OBS = DATA / "ESBC00DNK_R_20201770000_01H_30S_MO.crx.gz"
NAV = DATA / "ESBC00DNK_R_20201770000_01H_MN.rnx.gz"
N_EPOCHS = 4  # the first two minutes
LETTERS = {code: letter for letter, code in CONSTELLATION_CODES.items()}

LABEL = "SYS / # / OBS TYPES"

RECEIVERS: dict[str, tuple[str, list[str], dict[str, str]]] = {
    "trimble_netr9": (
        "00000               TRIMBLE NETR9       5.37,21/SEP/2018    REC # / TYPE / VERS",
        [
            "G   16 C1C L1C D1C S1C C2W L2W D2W S2W C2X L2X D2X S2X C5X  SYS / # / OBS TYPES",
            "       L5X D5X S5X                                          SYS / # / OBS TYPES",
            "R   16 C1C L1C D1C S1C C1P L1P D1P S1P C2C L2C D2C S2C C2P  SYS / # / OBS TYPES",
            "       L2P D2P S2P                                          SYS / # / OBS TYPES",
            "E   16 C1X L1X D1X S1X C5X L5X D5X S5X C7X L7X D7X S7X C8X  SYS / # / OBS TYPES",
            "       L8X D8X S8X                                          SYS / # / OBS TYPES",
            "J   16 C1C L1C D1C S1C C1X L1X D1X S1X C2X L2X D2X S2X C5X  SYS / # / OBS TYPES",
            "       L5X D5X S5X                                          SYS / # / OBS TYPES",
            "C   12 C2X L2X D2X S2X C6X L6X D6X S6X C7X L7X D7X S7X      SYS / # / OBS TYPES",
        ],
        {"G": "C1C", "R": "C1C", "E": "C1X", "J": "C1C", "C": "C2X"},
    ),
    "septentrio_polarx5": (
        "3047937             SEPT POLARX5        5.2.0               REC # / TYPE / VERS",
        [
            "C   12 C2I C6I C7I D2I D6I D7I L2I L6I L7I S2I S6I S7I      SYS / # / OBS TYPES",
            "E   20 C1C C5Q C6C C7Q C8Q D1C D5Q D6C D7Q D8Q L1C L5Q L6C  SYS / # / OBS TYPES",
            "       L7Q L8Q S1C S5Q S6C S7Q S8Q                          SYS / # / OBS TYPES",
            "G   18 C1C C1W C2L C2W C5Q D1C D2L D2W D5Q L1C L2L L2W L5Q  SYS / # / OBS TYPES",
            "       S1C S1W S2L S2W S5Q                                  SYS / # / OBS TYPES",
            "J   12 C1C C2L C5Q D1C D2L D5Q L1C L2L L5Q S1C S2L S5Q      SYS / # / OBS TYPES",
            "R   20 C1C C1P C2C C2P C3Q D1C D1P D2C D2P D3Q L1C L1P L2C  SYS / # / OBS TYPES",
            "       L2P L3Q S1C S1P S2C S2P S3Q                          SYS / # / OBS TYPES",
        ],
        {"G": "C1C", "R": "C1C", "E": "C1C", "J": "C1C", "C": "C2I"},
    ),
    "leica_gr50": (
        "1833574             LEICA GR50          4.50/7.710          REC # / TYPE / VERS",
        [
            "G   12 C1C L1C S1C C2S L2S S2S C2W L2W S2W C5Q L5Q S5Q      SYS / # / OBS TYPES",
            "R   12 C1C L1C S1C C2P L2P S2P C2C L2C S2C C3Q L3Q S3Q      SYS / # / OBS TYPES",
            "E   15 C1C L1C S1C C5Q L5Q S5Q C6C L6C S6C C7Q L7Q S7Q C8Q  SYS / # / OBS TYPES",
            "       L8Q S8Q                                              SYS / # / OBS TYPES",
            "C    9 C2I L2I S2I C6I L6I S6I C7I L7I S7I                  SYS / # / OBS TYPES",
        ],
        {"G": "C1C", "R": "C1C", "E": "C1C", "C": "C2I"},
    ),
    "ublox_f9p": (
        "                    ZED-F9P             HPG 1.32            REC # / TYPE / VERS",
        [
            "G    8 C1C L1C D1C S1C C2L L2L D2L S2L                      SYS / # / OBS TYPES",
            "R    8 C1C L1C D1C S1C C2C L2C D2C S2C                      SYS / # / OBS TYPES",
            "E    8 C1C L1C D1C S1C C7Q L7Q D7Q S7Q                      SYS / # / OBS TYPES",
            "C    8 C2I L2I D2I S2I C7I L7I D7I S7I                      SYS / # / OBS TYPES",
            "J    8 C1C L1C D1C S1C C2L L2L D2L S2L                      SYS / # / OBS TYPES",
        ],
        {"G": "C1C", "R": "C1C", "E": "C1C", "J": "C1C", "C": "C2I"},
    ),
    "javad_tre3": (
        "                    JAVAD TRE_3 DELTA   4.1.03              REC # / TYPE / VERS",
        [
            "G   20 C1C C1W C2L C2W C5Q D1C D1W D2L D2W D5Q L1C L1W L2L  SYS / # / OBS TYPES",
            "       L2W L5Q S1C S1W S2L S2W S5Q                          SYS / # / OBS TYPES",
            "R   16 C1C C1P C2C C2P D1C D1P D2C D2P L1C L1P L2C L2P S1C  SYS / # / OBS TYPES",
            "       S1P S2C S2P                                          SYS / # / OBS TYPES",
            "E   16 C1X C5X C7X C8X D1X D5X D7X D8X L1X L5X L7X L8X S1X  SYS / # / OBS TYPES",
            "       S5X S7X S8X                                          SYS / # / OBS TYPES",
            "C    8 C2I C7I D2I D7I L2I L7I S2I S7I                      SYS / # / OBS TYPES",
        ],
        {"G": "C1C", "R": "C1C", "E": "C1X", "C": "C2I"},
    ),
}
"""Receiver -> (REC # / TYPE / VERS line, SYS / # / OBS TYPES lines, expected pseudorange code per
system with an orbit model here)."""


@pytest.fixture(scope="module")
def esbc() -> RinexObs:
    return read_rinex_obs(OBS)


@pytest.fixture(scope="module")
def nav():
    return read_rinex_nav(NAV)


def _source_value(values: dict[str, float], source_codes: tuple[str, ...], code: str) -> float:
    """The ESBC value for ``code``: the same observable if ESBC has it, else the first ESBC
    observable of the same type and band (NaN when it has none)."""
    if code in source_codes:
        return values.get(code, math.nan)
    same = [c for c in source_codes if c[:2] == code[:2]]
    return values.get(same[0], math.nan) if same else math.nan


def _obs_line(value: float) -> str:
    return " " * 16 if not math.isfinite(value) else f"{value:14.3f}  "


def write_receiver_file(
    path: Path, version: str, receiver: str, esbc: RinexObs, blank: dict[str, tuple[str, ...]] | None = None
) -> Path:
    """An observation file with ``receiver``'s header lines and the first ``N_EPOCHS`` ESBC epochs.

    Args:
        blank: satellite id -> observables written blank (e.g. to remove one code).
    """
    rec_line, type_lines, _ = RECEIVERS[receiver]
    assert all(line[60:] == LABEL and len(line) == 79 for line in type_lines)
    types: dict[str, list[str]] = {}
    current = ""
    for line in type_lines:
        if line[0] != " ":
            current = line[0]
            types[current] = []
        types[current].extend(line[7:60].split())
    x, y, z = esbc.header.approx_position_ecef_m
    header = [
        f"{version:>9}{'':11}{'OBSERVATION DATA':<20}{'M':<20}RINEX VERSION / TYPE",
        f"{'test':<20}{'gnss_common':<20}{'20261207 000000 UTC':<20}PGM / RUN BY / DATE",
        f"{'ESBC00DNK':<60}MARKER NAME",
        rec_line,
        f"{x:14.4f}{y:14.4f}{z:14.4f}{'':18}APPROX POSITION XYZ",
        *type_lines,
        f"{'DBHZ':<60}SIGNAL STRENGTH UNIT",
        f"{'  2020     6    25     0     0    0.0000000     GPS':<60}TIME OF FIRST OBS",
        f"{'':60}END OF HEADER",
    ]
    body: list[str] = []
    for k, epoch in enumerate(esbc.epochs[:N_EPOCHS]):
        rows = []
        for sat in sorted(epoch.observations):
            if sat[0] not in types:
                continue
            src_codes = esbc.header.obs_types[sat[0]]
            values = [
                math.nan if code in (blank or {}).get(sat, ()) else
                _source_value(epoch.observations[sat], src_codes, code)
                for code in types[sat[0]]
            ]
            if any(math.isfinite(v) for v in values):
                rows.append(sat + "".join(_obs_line(v) for v in values).rstrip())
        sec = 30.0 * k
        body.append(f"> 2020 06 25 00 {int(sec // 60):02d}{sec % 60:11.7f}  0{len(rows):3d}")
        body.extend(rows)
    path.write_text("\n".join(header + body) + "\n")
    return path


def _built(obs: RinexObs, nav, epochs: tuple[RinexObsEpoch, ...] | None = None):
    builder = GnssEpochBuilder.from_rinex(obs, nav)
    return [builder.build(e) for e in (epochs if epochs is not None else obs.epochs)]


def test_trimble_netr9_beidou_c2x_is_read(tmp_path: Path, esbc: RinexObs, nav) -> None:
    """Issue 27: a NetR9 writes B1I as C2X (I+Q); it was skipped as missing_pseudorange."""
    obs = read_rinex_obs(write_receiver_file(tmp_path / "netr9.rnx", "3.05", "trimble_netr9", esbc))
    results = _built(obs, nav)
    reference = _built(esbc, nav, esbc.epochs[:N_EPOCHS])
    missing = sum(r.skipped_by_constellation.get("beidou", {}).get("missing_pseudorange", 0) for r in results)
    assert missing == 0
    bds = [[o for o in r.epoch.observations if o.constellation == BEIDOU] for r in results]
    ref = [[o for o in r.epoch.observations if o.constellation == BEIDOU] for r in reference]
    assert [len(b) for b in bds] == [len(b) for b in ref] and min(len(b) for b in ref) >= 8
    for got, want in zip(bds, ref, strict=True):
        for a, b in zip(got, want, strict=True):
            assert (a.svid, a.pseudorange_m, a.cn0_dbhz, a.pseudorange_rate_mps) == (
                b.svid, b.pseudorange_m, b.cn0_dbhz, b.pseudorange_rate_mps)


@pytest.mark.parametrize("version", ["3.05", "4.00"])
@pytest.mark.parametrize("receiver", sorted(RECEIVERS))
def test_receiver_headers_give_the_measurements_of_the_original(
    receiver: str, version: str, tmp_path: Path, esbc: RinexObs, nav
) -> None:
    obs = read_rinex_obs(write_receiver_file(tmp_path / f"{receiver}.rnx", version, receiver, esbc))
    assert obs.header.version == float(version)
    expected_codes = RECEIVERS[receiver][2]
    assert set(expected_codes) <= set(obs.header.obs_types)
    results = _built(obs, nav)
    reference = _built(esbc, nav, esbc.epochs[:N_EPOCHS])
    n_compared = 0
    for r, ref in zip(results, reference, strict=True):
        ref_sats = {k: o for k, o in _by_id(ref.epoch.observations).items() if k[0] in expected_codes}
        got = _by_id(r.epoch.observations)
        assert set(got) == set(ref_sats), receiver
        assert r.signal_codes == {sat: expected_codes[sat[0]] for sat in got}
        for sat, o in got.items():
            want = ref_sats[sat]
            code = r.signal_codes[sat]
            has = obs.header.obs_types[sat[0]]
            assert o.pseudorange_m == want.pseudorange_m
            np.testing.assert_allclose(o.satellite_position_ecef_m, want.satellite_position_ecef_m, atol=1e-6)
            assert o.carrier_frequency_hz == want.carrier_frequency_hz
            if "D" + code[1:] in has:
                assert o.pseudorange_rate_mps == want.pseudorange_rate_mps
            else:  # e.g. the GR50 writes no Doppler: NaN, not another code's
                assert math.isnan(o.pseudorange_rate_mps)
            if "S" + code[1:] in has and math.isfinite(want.cn0_dbhz):
                assert o.cn0_dbhz == want.cn0_dbhz
            n_compared += 1
    assert n_compared >= 4 * 25


def _by_id(observations: tuple[SatelliteObservation, ...]) -> dict[str, SatelliteObservation]:
    return {f"{LETTERS[o.constellation]}{o.svid:02d}": o for o in observations}


def test_javad_c1w_with_its_own_cn0_when_c1c_is_missing(tmp_path: Path, esbc: RinexObs, nav) -> None:
    """No C1C range for one GPS satellite: the measurement is made of C1W, D1W and S1W, not of
    C1W with the S1C / D1C the receiver still wrote."""
    sat = next(s for s in sorted(esbc.epochs[0].observations) if s[0] == "G"
               and all(math.isfinite(esbc.epochs[k].observations.get(s, {}).get(c, math.nan))
                       for k in range(N_EPOCHS) for c in ("C1C", "C1W", "S1C", "S1W")))
    path = write_receiver_file(tmp_path / "javad.rnx", "3.05", "javad_tre3", esbc, blank={sat: ("C1C",)})
    obs = read_rinex_obs(path)
    assert math.isfinite(obs.epochs[0].observations[sat]["S1C"])
    for k, r in enumerate(_built(obs, nav)):
        assert r.signal_codes[sat] == "C1W"
        o = _by_id(r.epoch.observations)[sat]
        assert o.constellation == GPS
        src = esbc.epochs[k].observations[sat]
        assert o.pseudorange_m == src["C1W"]
        assert o.cn0_dbhz == src["S1W"] != src["S1C"]
