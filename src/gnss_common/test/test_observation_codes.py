"""The observation-code table and the choice of one tracking attribute per satellite
(gnss_common.observation_codes): every attribute of the RINEX 3.05 / 4.00 tables is read, the
priority keeps the codes files already used first, and pseudorange, Doppler, C/N0 and phase come
from one attribute."""

from __future__ import annotations

import math

import pytest

from gnss_common.measurements import MeasurementBuilderParams
from gnss_common.observation_codes import DEFAULT_SIGNALS, OBSERVATION_ATTRIBUTES, select_signal

NAN = math.nan


def test_table_covers_every_system_and_band_once() -> None:
    assert set(OBSERVATION_ATTRIBUTES) == {"G", "R", "E", "C", "J", "I", "S"}
    for system, bands in OBSERVATION_ATTRIBUTES.items():
        for band, attributes in bands.items():
            assert band.isdigit() and attributes.isalpha() and attributes.isupper(), (system, band)
            assert len(set(attributes)) == len(attributes), (system, band, attributes)
    # Spot checks against the RINEX 3.05 / 4.00 tables (the codes the issue and real files name).
    assert "X" in OBSERVATION_ATTRIBUTES["C"]["2"]  # Trimble NetR9 B1I: C2X
    assert set("BCXZ") <= set(OBSERVATION_ATTRIBUTES["E"]["1"])  # Galileo E1: C1B, C1C, C1X, C1Z
    assert "P" in OBSERVATION_ATTRIBUTES["R"]["1"]  # GLONASS C1P
    assert set("CSLXZ") <= set(OBSERVATION_ATTRIBUTES["J"]["1"])  # QZSS L1 C/A, L1C, L1S
    assert set("ABCX") <= set(OBSERVATION_ATTRIBUTES["I"]["5"])  # NavIC L5
    assert set("DPX") <= set(OBSERVATION_ATTRIBUTES["C"]["1"])  # BeiDou B1C


def test_preferred_signals_try_every_attribute_of_their_band_and_keep_the_old_first_choice() -> None:
    """The first candidate of each system is the code read before every attribute was (so files
    that worked convert as before); the list is a permutation of the band's attributes."""
    first = {"G": "1C", "E": "1C", "C": "2I", "R": "1C", "J": "1C"}
    assert set(DEFAULT_SIGNALS) == set(first)
    for system, pref in DEFAULT_SIGNALS.items():
        assert sorted(pref.attributes) == sorted(OBSERVATION_ATTRIBUTES[system][pref.band]), system
        cands = pref.candidates(3.05)
        assert cands[0] == first[system]
        assert len(set(cands)) == len(cands)
    assert MeasurementBuilderParams().signals == DEFAULT_SIGNALS
    assert DEFAULT_SIGNALS["C"].pseudorange_observables(3.05) == ("C2I", "C2X", "C2Q", "C1I", "C1Q")
    assert DEFAULT_SIGNALS["C"].pseudorange_observables(3.01)[-1] == "C1X"
    assert DEFAULT_SIGNALS["G"].pseudorange_observables(2.11)[-1] == "C1"


@pytest.mark.parametrize("system", sorted(DEFAULT_SIGNALS))
def test_each_attribute_alone_is_read(system: str) -> None:
    pref = DEFAULT_SIGNALS[system]
    for attribute in OBSERVATION_ATTRIBUTES[system][pref.band]:
        code = pref.band + attribute
        sel = select_signal({"C" + code: 2.2e7, "D" + code: -100.0, "S" + code: 41.0, "L" + code: 1.1e8}, pref)
        assert sel is not None and sel.code == code, code
        assert (sel.pseudorange_m, sel.doppler_hz, sel.cn0_dbhz, sel.carrier_phase_cycles) == (2.2e7, -100.0, 41.0,
                                                                                              1.1e8)
        assert sel.pseudorange_observable == "C" + code


def test_all_four_observables_come_from_one_attribute() -> None:
    gps = DEFAULT_SIGNALS["G"]
    # C1C wins; its Doppler and C/N0 are missing: NaN, never D1X / S1W of another attribute.
    sel = select_signal({"C1C": 2.1e7, "D1X": -5.0, "S1W": 30.0, "L1W": 1.0e8, "C1W": 2.1e7 + 0.4}, gps)
    assert sel is not None and sel.code == "1C" and sel.pseudorange_m == 2.1e7
    assert math.isnan(sel.doppler_hz) and math.isnan(sel.cn0_dbhz) and math.isnan(sel.carrier_phase_cycles)
    # No C1C range (S1C and D1C alone do not make a measurement): C1W with its own S1W and D1W.
    sel = select_signal({"C1C": NAN, "S1C": 45.0, "D1C": -7.0, "C1W": 2.1e7, "S1W": 31.0, "D1W": -7.5}, gps)
    assert sel is not None and sel.code == "1W"
    assert (sel.pseudorange_m, sel.doppler_hz, sel.cn0_dbhz) == (2.1e7, -7.5, 31.0)
    # Priority among present attributes: Galileo pilot C before B+C before data B.
    gal = DEFAULT_SIGNALS["E"]
    assert select_signal({"C1B": 1.0, "C1X": 2.0, "C1C": 3.0}, gal).code == "1C"  # type: ignore[union-attr]
    assert select_signal({"C1B": 1.0, "C1X": 2.0}, gal).code == "1X"  # type: ignore[union-attr]
    assert select_signal({"C1Z": 1.0, "C1B": 2.0}, gal).code == "1B"  # type: ignore[union-attr]
    # Another band's range is not this signal's: E5a only -> nothing.
    assert select_signal({"C5Q": 2.4e7, "S5Q": 45.0}, gal) is None


def test_rinex2_observables() -> None:
    sel = select_signal({"C1": 2.0e7, "P1": 2.0e7 + 1.0, "L1": 1.0e8, "D1": -300.0, "S1": 44.0, "S2": 30.0},
                        DEFAULT_SIGNALS["G"], 2.11)
    assert sel is not None and sel.code == "C1" and sel.pseudorange_observable == "C1"
    assert (sel.pseudorange_m, sel.carrier_phase_cycles, sel.doppler_hz, sel.cn0_dbhz) == (2.0e7, 1.0e8, -300.0, 44.0)
    # P1 alone is not used (RINEX 2 cannot say which attribute L1/D1/S1 belong to): as before.
    assert select_signal({"P1": 2.0e7, "S1": 44.0}, DEFAULT_SIGNALS["G"], 2.11) is None


def test_beidou_band_numbers_of_rinex_301() -> None:
    """RINEX 3.01 wrote B1I on band 1 (C1I/C1Q/C1X); from 3.04 band 1 X is B1C (another signal,
    another carrier offset and clock group delay), so C1X is B1I only in files older than 3.02."""
    bds = DEFAULT_SIGNALS["C"]
    assert select_signal({"C1X": 2.2e7}, bds, 3.01).code == "1X"  # type: ignore[union-attr]
    assert select_signal({"C1X": 2.2e7}, bds, 3.04) is None
    assert select_signal({"C1X": 2.2e7}, bds, None) is None
    assert select_signal({"C1I": 2.2e7, "S1I": 40.0}, bds, 3.04).cn0_dbhz == 40.0  # type: ignore[union-attr]
    assert select_signal({"C1I": 2.2e7, "C2X": 2.3e7}, bds, 3.01).code == "2X"  # type: ignore[union-attr]
