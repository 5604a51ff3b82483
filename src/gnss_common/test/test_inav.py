"""Galileo I/NAV (gnss_common.inav): CRC-24Q against its published check value, round trip of every
Galileo record of a real broadcast file within the broadcast LSBs, rejected pages, issue-of-data rule."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from gnss_common.ephemeris import GpsEphemeris, pack_ephemerides, satellite_states
from gnss_common.inav import (
    InavAssembler,
    InavError,
    crc24q,
    decode_words,
    encode_page,
    encode_words,
    page_word,
)
from gnss_common.lnav import GPS_PI
from gnss_common.rinex import read_rinex_nav

DATA = Path(__file__).parent / "data"
LSB = {  # Galileo OS SIS ICD Tables 40-43, in the field's unit (angles: semicircle LSB times pi)
    "toe_s": 60.0, "toc_s": 60.0, "m0_rad": 2.0**-31 * GPS_PI, "e": 2.0**-33, "sqrt_a_sqrt_m": 2.0**-19,
    "omega0_rad": 2.0**-31 * GPS_PI, "i0_rad": 2.0**-31 * GPS_PI, "omega_rad": 2.0**-31 * GPS_PI,
    "idot_radps": 2.0**-43 * GPS_PI, "omega_dot_radps": 2.0**-43 * GPS_PI, "delta_n_radps": 2.0**-43 * GPS_PI,
    "cuc_rad": 2.0**-29, "cus_rad": 2.0**-29, "crc_m": 2.0**-5, "crs_m": 2.0**-5, "cic_rad": 2.0**-29,
    "cis_rad": 2.0**-29, "af0_s": 2.0**-34, "af1_s_per_s": 2.0**-46, "af2_s_per_s2": 2.0**-59, "tgd_s": 2.0**-32,
}


@pytest.fixture(scope="module")
def galileo():
    nav = read_rinex_nav(DATA / "ESBC00DNK_R_20201770000_01H_MN.rnx.gz")
    return [e for e in nav.other_ephemerides if e.system == "E"]


def test_crc24q_check_value():
    assert crc24q(b"123456789") == 0xCDE703  # the CRC-24Q ("OpenPGP"-polynomial, init 0) check value
    assert crc24q(b"") == 0


def test_round_trip_of_every_record_within_half_an_lsb(galileo):
    assert len(galileo) > 50
    worst_m = 0.0
    for eph in galileo:
        asm = InavAssembler()
        words = encode_words(eph, eph.toe_s + 30.0)
        out = [asm.add(eph.prn, encode_page(words[k]), eph.week) for k in (1, 2, 3, 4, 5)]
        dec = out[4]
        assert out[:4] == [None] * 4 and isinstance(dec, GpsEphemeris)
        for name, lsb in LSB.items():
            a, b = getattr(eph, name), getattr(dec, name)
            if name in ("omega0_rad", "i0_rad", "omega_rad", "m0_rad"):
                a, b = ((v + math.pi) % (2 * math.pi) - math.pi for v in (a, b))
            assert abs(a - b) <= 0.5 * lsb * (1 + 1e-9) + 1e-15, (eph.prn, name, a, b)
        assert (dec.system, dec.prn, dec.week, dec.toc_week, dec.iode, dec.health) == \
            ("E", eph.prn, eph.week, eph.toc_week, eph.iode, eph.health)
        t = eph.toe_s + 1200.0
        s1 = satellite_states(pack_ephemerides([eph]), eph.week, t)
        s2 = satellite_states(pack_ephemerides([dec]), eph.week, t)
        worst_m = max(worst_m, float(np.abs(s1.position_ecef_m - s2.position_ecef_m).max()),
                      float(abs(s1.clock_bias_s - s2.clock_bias_s)[0] * 299_792_458.0))
    assert worst_m < 0.01


def test_every_single_bit_error_of_a_page_is_caught(galileo):
    page = encode_page(encode_words(galileo[0], 3600.0)[3])
    assert page_word(page)[0] == 3
    for k in range(8):
        for bit in range(32):
            corrupted = list(page)
            corrupted[k] ^= 1 << bit
            pos = 32 * (k % 4) + (31 - bit)  # bit position within its 128-bit page part
            covered = pos < 114 if k < 4 else pos < 106
            if not covered:  # tail, padding and reserved bits outside the CRC
                continue
            with pytest.raises(InavError) as err:
                page_word(corrupted)
            assert err.value.reason in ("crc", "page_order")


def test_issue_of_data_rule_and_counted_rejections(galileo):
    eph = galileo[0]
    new = dataclasses.replace(eph, iode=(eph.iode + 1) % 1024, iodc=(eph.iode + 1) % 1024, toe_s=eph.toe_s + 600.0,
                              toc_s=eph.toc_s + 600.0)
    old_w, new_w = encode_words(eph, eph.toe_s), encode_words(new, eph.toe_s + 600.0)
    asm = InavAssembler()
    for k in (1, 2, 3, 5):
        assert asm.add(eph.prn, encode_page(old_w[k]), eph.week) is None
    assert asm.add(eph.prn, encode_page(new_w[4]), eph.week) is None  # IODnav 1-3 old, 4 new: wait
    for k in (1, 2):
        assert asm.add(eph.prn, encode_page(new_w[k]), eph.week) is None
    got = asm.add(eph.prn, encode_page(new_w[3]), eph.week)
    assert isinstance(got, GpsEphemeris) and got.iode == new.iode
    assert asm.add(eph.prn, encode_page(new_w[5]), eph.week) is None  # same set: not re-emitted
    assert asm.add(eph.prn, encode_page(new_w[1])[:7], eph.week) is None
    swapped = encode_page(new_w[1])
    assert asm.add(eph.prn, swapped[4:] + swapped[:4], eph.week) is None
    assert asm.rejected["word_count"] == 1 and asm.rejected["page_order"] == 1
    with pytest.raises(InavError) as err:
        decode_words(eph.prn, {**{k: old_w[k] for k in (1, 2, 3, 5)}, 4: new_w[4]}, eph.week)
    assert err.value.reason == "iod_mismatch"
