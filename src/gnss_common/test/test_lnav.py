"""GPS LNAV subframes (gnss_common.lnav): parity on real u-blox words, ephemeris decoding,
Klobuchar page, the assembler's consistency rules, rejected input."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from gnss_common.ephemeris import GpsEphemeris, pack_ephemerides, satellite_states
from gnss_common.lnav import (
    GPS_PI,
    KlobucharParams,
    LnavAssembler,
    LnavError,
    decode_ephemeris,
    encode_ephemeris_subframes,
    encode_iono_subframe,
    parse_subframe,
    word_data,
)
from gnss_common.rinex import read_rinex_nav

DATA = Path(__file__).parent / "data"

# The ten words of the one UBX-RXM-SFRBX of pyubx2's tests/pygpsdata-ALL.log (GPS PRN 5, L1 C/A),
# as pyubx2's own parse lists them (dwrd_01 .. dwrd_10); see
# src/rfi_experiments/test/data/ubx/README.md for the file and its licence.
REAL_SFRBX_PRN5 = (583028782, 2463198336, 394902765, 2566867280, 1062207503, 675481840, 616371498,
                   2740700967, 768066377, 3045061856)

# Broadcast scale factor of each GpsEphemeris field (IS-GPS-200 Tables 20-I and 20-III), in the
# field's own unit (angles: semicircle LSB times pi).
LSB = {
    "af0_s": 2.0**-31, "af1_s_per_s": 2.0**-43, "af2_s_per_s2": 2.0**-55, "crs_m": 2.0**-5,
    "delta_n_radps": 2.0**-43 * GPS_PI, "m0_rad": 2.0**-31 * GPS_PI, "cuc_rad": 2.0**-29, "e": 2.0**-33,
    "cus_rad": 2.0**-29, "sqrt_a_sqrt_m": 2.0**-19, "toe_s": 16.0, "cic_rad": 2.0**-29,
    "omega0_rad": 2.0**-31 * GPS_PI, "cis_rad": 2.0**-29, "i0_rad": 2.0**-31 * GPS_PI, "crc_m": 2.0**-5,
    "omega_rad": 2.0**-31 * GPS_PI, "omega_dot_radps": 2.0**-43 * GPS_PI, "idot_radps": 2.0**-43 * GPS_PI,
    "tgd_s": 2.0**-31, "toc_s": 16.0,
}


@pytest.fixture(scope="module")
def nav():
    return read_rinex_nav(DATA / "arlm2000.15n")


def test_real_ublox_words_pass_parity_and_read_as_subframe_4():
    # Independent check of the word layout (D29*, D30* in bits 31-30, transmitted bits below):
    # the satellite computed these parity bits, not this code.
    data = [word_data(w) for w in REAL_SFRBX_PRN5]
    assert data[0] >> 16 == 0x8B  # TLM preamble
    sf = parse_subframe(5, REAL_SFRBX_PRN5)
    assert sf.subframe_id == 4
    assert 0 <= sf.tow_count < 100800
    assert sf.unsigned(48, 2) == 1  # data ID of the LNAV message (IS-GPS-200 20.3.3.5.1.1)


def test_every_single_bit_error_of_a_real_word_is_caught():
    for k, w in enumerate(REAL_SFRBX_PRN5):
        for bit in range(30):
            with pytest.raises(LnavError) as err:
                parse_subframe(5, REAL_SFRBX_PRN5[:k] + (w ^ (1 << bit),) + REAL_SFRBX_PRN5[k + 1:])
            assert err.value.reason == "parity"


def test_encoded_words_are_parity_consistent_across_inverted_words(nav):
    # The encoder chains D29*/D30*: some words are sent complemented (D30* = 1); all must decode.
    eph = nav.ephemerides[0]
    inverted = 0
    for words in encode_ephemeris_subframes(eph, eph.week, eph.toe_s - 7200.0):
        for w in words:
            word_data(w)
            inverted += (w >> 30) & 1
        assert words[9] & 0x3 == 0 and words[1] & 0x3 == 0  # t bits solved: D29 = D30 = 0
    assert inverted > 0


def test_round_trip_every_arl1_record_within_half_an_lsb(nav):
    asm = LnavAssembler()
    worst_m = 0.0
    for eph in nav.ephemerides:
        start = math.floor((eph.toe_s - 7200.0) / 30.0) * 30.0  # sent 2 h before t_oe (previous week for t_oe 0)
        week_tx = eph.week - 1 if start < 0 else eph.week
        words = encode_ephemeris_subframes(eph, week_tx, start % 604800.0)
        out = [asm.add(eph.prn, w, eph.week) for w in words]
        dec = out[2]
        assert isinstance(dec, GpsEphemeris) and out[:2] == [None, None]
        for name, lsb in LSB.items():
            a, b = getattr(eph, name), getattr(dec, name)
            if name in ("omega0_rad", "i0_rad", "omega_rad"):  # wrapped into [-pi, pi)
                a = (a + math.pi) % (2 * math.pi) - math.pi
                b = (b + math.pi) % (2 * math.pi) - math.pi
            assert abs(a - b) <= 0.5 * lsb * (1 + 1e-9) + 1e-15, (eph.prn, name, a, b)
        assert (dec.prn, dec.week, dec.toc_week, dec.health, dec.iode) == (eph.prn, eph.week, eph.toc_week,
                                                                             eph.health, eph.iode)
        t = eph.toe_s + 1800.0
        s1 = satellite_states(pack_ephemerides([eph]), eph.week, t)
        s2 = satellite_states(pack_ephemerides([dec]), eph.week, t)
        worst_m = max(worst_m, float(np.abs(s1.position_ecef_m - s2.position_ecef_m).max()),
                      float(abs(s1.clock_bias_s - s2.clock_bias_s)[0] * 299_792_458.0))
    assert asm.rejected == dict.fromkeys(asm.rejected, 0)
    assert worst_m < 0.01  # quantisation of RINEX's 12 digits to the broadcast LSBs: sub-cm


def test_week_rollover_and_week_crossover(nav):
    eph = nav.ephemerides[0]
    words = encode_ephemeris_subframes(eph, eph.week, eph.toe_s - 3600.0)
    sfs = [parse_subframe(eph.prn, w) for w in words]
    # any reference within 512 weeks restores the continuous week (10-bit WN broadcast)
    for ref in (eph.week - 500, eph.week, eph.week + 500):
        assert decode_ephemeris(*sfs, reference_week=ref).week == eph.week
    # a record with t_oe early in the next week, sent at the end of this week
    late = dataclasses.replace(eph, toe_s=7200.0, toc_s=7200.0, week=eph.week + 1, toc_week=eph.week + 1)
    sfs = [parse_subframe(eph.prn, w) for w in encode_ephemeris_subframes(late, eph.week, 604800.0 - 600.0)]
    dec = decode_ephemeris(*sfs, reference_week=eph.week)
    assert (dec.week, dec.toc_week, dec.toe_s) == (eph.week + 1, eph.week + 1, 7200.0)


def test_klobuchar_page_18(nav):
    alpha, beta = nav.header.iono_alpha, nav.header.iono_beta
    asm = LnavAssembler()
    kb = asm.add(3, encode_iono_subframe(alpha, beta, 1800.0), 1854)
    assert isinstance(kb, KlobucharParams)
    lsb_a = np.array([2.0**-30, 2.0**-27, 2.0**-24, 2.0**-24])
    lsb_b = np.array([2.0**11, 2.0**14, 2.0**16, 2.0**16])
    assert np.all(np.abs(kb.alpha - alpha) <= 0.5 * lsb_a + 1e-20)
    assert np.all(np.abs(kb.beta - beta) <= 0.5 * lsb_b)
    assert asm.add(4, encode_iono_subframe(alpha, beta, 2400.0), 1854) is None  # unchanged: not re-emitted


def test_assembler_never_mixes_uploads_and_counts_rejections(nav):
    eph = nav.ephemerides[0]
    new = dataclasses.replace(eph, iode=(eph.iode + 1) % 256, iodc=(eph.iodc + 1) % 1024, toe_s=eph.toe_s + 7200.0,
                              toc_s=eph.toc_s + 7200.0)
    old_words = encode_ephemeris_subframes(eph, eph.week, eph.toe_s - 3600.0)
    new_words = encode_ephemeris_subframes(new, eph.week, eph.toe_s)
    asm = LnavAssembler()
    assert asm.add(eph.prn, old_words[0], eph.week) is None
    assert asm.add(eph.prn, old_words[1], eph.week) is None
    assert asm.add(eph.prn, new_words[2], eph.week) is None  # subframe 3 of another upload: wait
    assert asm.add(eph.prn, new_words[0], eph.week) is None
    got = asm.add(eph.prn, new_words[1], eph.week)
    assert isinstance(got, GpsEphemeris) and got.iode == new.iode and got.toe_s == new.toe_s
    assert asm.add(eph.prn, new_words[2], eph.week) is None  # the same set again: not re-emitted
    bad = list(old_words[0])
    bad[4] ^= 1 << 12
    assert asm.add(eph.prn, bad, eph.week) is None
    assert asm.add(eph.prn, old_words[0][:9], eph.week) is None
    assert asm.rejected["parity"] == 1 and asm.rejected["word_count"] == 1


def test_preamble_and_subframe_id_errors():
    from gnss_common.lnav import encode_word

    words, prev = [], (0, 0)
    for k in range(10):
        w = encode_word(0x123456 if k == 0 else 0, *prev)
        words.append(w)
        prev = ((w >> 1) & 1, w & 1)
    with pytest.raises(LnavError) as err:
        parse_subframe(1, words)
    assert err.value.reason == "preamble"
    words, prev = [], (0, 0)
    for k in range(10):
        w = encode_word(0x8B0000 if k == 0 else (7 << 8 if k == 1 else 0), *prev)  # subframe id 7
        words.append(w)
        prev = ((w >> 1) & 1, w & 1)
    with pytest.raises(LnavError) as err:
        parse_subframe(1, words)
    assert err.value.reason == "subframe_id"
