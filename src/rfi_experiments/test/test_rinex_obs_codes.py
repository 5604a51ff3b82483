"""rinex_to_bag reads every tracking attribute (issue 27): the real ESBC00DNK hour with its
BeiDou and Galileo observables relabelled as a Trimble NetR9 writes them (``C2X``..., ``C1X``...;
same values, same order) converts to the same measurements as the original, and the summary and
the bag's metadata say which codes were used."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import hatanaka
import pytest

from rfi_experiments.bag_io import BagReader
from rfi_experiments.rinex_to_bag import CODES_METADATA_KEY, PRIORITY_METADATA_KEY, convert_rinex, main

DATA = Path(__file__).resolve().parents[2] / "gnss_common" / "test" / "data"
OBS = DATA / "ESBC00DNK_R_20201770000_01H_30S_MO.crx.gz"
NAV = DATA / "ESBC00DNK_R_20201770000_01H_MN.rnx.gz"
ESBC_BEIDOU = "C   12 C2I C6I C7I D2I D6I D7I L2I L6I L7I S2I S6I S7I      SYS / # / OBS TYPES"
ESBC_GALILEO = (
    "E   20 C1C C5Q C6C C7Q C8Q D1C D5Q D6C D7Q D8Q L1C L5Q L6C  SYS / # / OBS TYPES\n"
    "       L7Q L8Q S1C S5Q S6C S7Q S8Q                          SYS / # / OBS TYPES"
)


@pytest.fixture(scope="module")
def netr9_obs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The ESBC hour, plain text, with the BeiDou and Galileo type lines as a NetR9 writes them
    (every attribute X: the issue's ``C   12 C2X L2X D2X S2X C6X ...`` in ESBC's column order)."""
    text = hatanaka.decompress(OBS.read_bytes()).decode()
    head, sep, body = text.partition("END OF HEADER")
    assert ESBC_BEIDOU in head and ESBC_GALILEO in head
    beidou = ESBC_BEIDOU[:60].replace("I ", "X ") + ESBC_BEIDOU[60:]
    galileo = "\n".join(line[:60].replace("C ", "X ").replace("Q ", "X ") + line[60:]
                        for line in ESBC_GALILEO.splitlines())
    head = head.replace(ESBC_BEIDOU, beidou).replace(ESBC_GALILEO, galileo)
    assert "C   12 C2X C6X C7X D2X D6X D7X L2X L6X L7X S2X S6X S7X      SYS" in head
    assert "E   20 C1X C5X C6X C7X C8X D1X D5X D6X D7X D8X L1X L5X L6X  SYS" in head
    path = tmp_path_factory.mktemp("netr9") / "ESBC_as_NetR9.rnx"
    path.write_text(head + sep + body)
    return path


def test_netr9_codes_convert_like_the_original(netr9_obs: Path) -> None:
    relabelled = convert_rinex(netr9_obs, NAV, 0.0)
    original = convert_rinex(OBS, NAV, 0.0)
    assert relabelled.skipped_by_constellation.get("beidou", {}).get("missing_pseudorange", 0) == 0
    assert relabelled.measurements_by_constellation() == original.measurements_by_constellation()
    assert relabelled.measurements_by_constellation()["beidou"] > 1000
    for a, b in zip(relabelled.epochs, original.epochs, strict=True):
        assert [(o.constellation, o.svid, o.pseudorange_m, o.pseudorange_rate_mps, o.cn0_dbhz)
                for o in a.observations] == [(o.constellation, o.svid, o.pseudorange_m, o.pseudorange_rate_mps,
                                              o.cn0_dbhz) for o in b.observations]
    n = original.measurements_by_constellation()
    assert relabelled.codes_by_constellation["beidou"] == {"C2X": n["beidou"]}
    assert relabelled.codes_by_constellation["galileo"] == {"C1X": n["galileo"]}
    assert original.codes_by_constellation["beidou"] == {"C2I": n["beidou"]}
    assert original.codes_by_constellation["galileo"] == {"C1C": n["galileo"]}
    # ESBC's GPS and QZSS are C1C throughout; one GLONASS epoch of R17 (above the horizon) has C1P but no C1C range.
    assert original.codes_by_constellation["gps"] == {"C1C": n["gps"]}
    assert original.codes_by_constellation["glonass"] == {"C1C": n["glonass"] - 1, "C1P": 1}


def test_summary_and_bag_metadata_name_the_codes(netr9_obs: Path, tmp_path: Path) -> None:
    out = tmp_path / "bag"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["rinex_to_bag", str(netr9_obs), str(NAV), str(out)]) == 0
    text = buf.getvalue()
    conversion = convert_rinex(netr9_obs, NAV, 0.0)
    n = conversion.measurements_by_constellation()
    assert "observation codes used (pseudorange, Doppler, C/N0 of one tracking attribute):" in text
    assert f"beidou     C2X {n['beidou']}" in text
    assert f"galileo    C1X {n['galileo']}" in text
    assert f"glonass    C1C {n['glonass'] - 1}, C1P 1" in text
    with BagReader(out) as bag:
        custom = bag.custom_data
    assert json.loads(custom[CODES_METADATA_KEY]) == conversion.codes_by_constellation
    priority = json.loads(custom[PRIORITY_METADATA_KEY])
    assert priority["beidou"][:3] == ["C2I", "C2X", "C2Q"]
    assert priority["galileo"][:2] == ["C1C", "C1X"] and priority["gps"][0] == "C1C"
    assert set(priority) == {"gps", "galileo", "beidou", "glonass", "qzss"}
