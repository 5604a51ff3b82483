"""A real multi-GNSS station hour (ESBC00DNK: RINEX 3.05 obs + broadcast nav) sent as a u-blox
receiver would send it: its GPS and Galileo observations as UBX-RXM-RAWX, its broadcast records as
UBX-RXM-SFRBX (GPS LNAV subframes and Klobuchar page, Galileo I/NAV word types 1-5). The decoder's
epochs equal those rinex_to_bag's builder makes from the RINEX files (one implementation), within
the broadcast quantisation of the ephemerides stated here."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gnss_common.ephemeris import EphemerisStore
from gnss_common.measurements import GnssEpochBuilder, MeasurementBuilderParams
from gnss_common.observations import GALILEO, GPS
from gnss_common.rinex import read_rinex_nav, read_rinex_obs
from rfi_experiments.ubx_decode import EpochOutput, UbxDecoder, UbxDecoderParams, decode_stream
from rfi_experiments.ubx_synth import ephemeris_frames, galileo_frames, klobuchar_frame, rawx_from_rinex

DATA = Path(__file__).resolve().parents[2] / "gnss_common" / "test" / "data"
OBS = DATA / "ESBC00DNK_R_20201770000_01H_30S_MO.crx.gz"
NAV = DATA / "ESBC00DNK_R_20201770000_01H_MN.rnx.gz"
N_EPOCHS = 10
QUANTISATION_M = 0.01
"""Satellite position and clock: RINEX's 12 significant digits rounded to the broadcast LSBs (GPS
LNAV, Galileo I/NAV) move them by < 1 mm; 1 cm leaves room."""


@pytest.fixture(scope="module")
def esbc():
    obs = read_rinex_obs(OBS)
    nav = read_rinex_nav(NAV)
    epochs = obs.epochs[:N_EPOCHS]
    first = epochs[0]
    store = EphemerisStore(nav.ephemerides)
    gps = [store.select(int(s[1:]), first.gps_week, first.tow_s)[0] for s in sorted(first.observations) if s[0] == "G"]
    gps = [e for e in gps if e is not None]
    gal = []
    for sat in sorted(s for s in first.observations if s[0] == "E"):  # the record nearest the first epoch
        cands = [e for e in nav.other_ephemerides if e.system == "E" and e.prn == int(sat[1:])
                 and abs(e.toe_s - first.tow_s) <= 7200.0]
        if cands:
            gal.append(min(cands, key=lambda e: abs(e.toe_s - first.tow_s)))
    stream = bytearray(ephemeris_frames(gps, first.gps_week, first.tow_s))
    stream += galileo_frames(gal, first.tow_s - 2.0)
    stream += klobuchar_frame(gps[0].prn, nav.header.iono_alpha, nav.header.iono_beta, first.tow_s)
    for e in epochs:
        stream += rawx_from_rinex(e.gps_week, e.tow_s, e.observations)
    return obs, nav, epochs, bytes(stream), len(gps), len(gal)


def test_gps_and_galileo_from_sfrbx_equal_the_rinex_path(esbc):
    obs, nav, epochs, stream, n_gps, n_gal = esbc
    ref = obs.header.approx_position_ecef_m
    decoder = UbxDecoder(UbxDecoderParams(use_receiver_std=False), reference_position_ecef_m=ref)
    out = [o for o in decode_stream([stream], decoder) if isinstance(o, EpochOutput)]
    assert decoder.counts["ephemerides_decoded"] == n_gps + n_gal and n_gal >= 6 and n_gps >= 6
    assert decoder.counts["klobuchar_decoded"] == 1
    assert decoder.lnav_rejected == dict.fromkeys(decoder.lnav_rejected, 0)
    assert decoder.inav_rejected == dict.fromkeys(decoder.inav_rejected, 0)
    assert len(out) == N_EPOCHS
    builder = GnssEpochBuilder(list(nav.ephemerides) + list(nav.other_ephemerides), nav.header.iono_alpha,
                               nav.header.iono_beta, ref, MeasurementBuilderParams(constellations=("G", "E")))
    n_gal_used = n_unmodelled = 0
    for got, rinex_epoch in zip(out, epochs, strict=True):
        want = builder.build(rinex_epoch).epoch
        assert (got.epoch.gps_week, got.epoch.gps_time_of_week_s) == (want.gps_week, want.gps_time_of_week_s)
        want_by_sat = {(o.constellation, o.svid): o for o in want.observations}
        got_all = {(o.constellation, o.svid): o for o in got.epoch.observations}
        got_by_sat = {k: o for k, o in got_all.items() if np.isfinite(o.satellite_position_ecef_m).all()}
        for key, o in got_all.items():  # no ephemeris sent (BeiDou, satellites risen later): NaN states
            if key not in got_by_sat:
                assert np.isnan(o.satellite_position_ecef_m).all() and math.isnan(o.satellite_clock_bias_m)
                assert math.isnan(o.ionosphere_delay_m) and math.isfinite(o.pseudorange_m)
                n_unmodelled += 1
        assert set(got_by_sat) <= set(want_by_sat)
        assert len(got_by_sat) >= len(want_by_sat) - 2  # satellites risen after the first epoch
        for key, g in got_by_sat.items():
            w = want_by_sat[key]
            assert key[0] in (GPS, GALILEO)
            n_gal_used += key[0] == GALILEO
            assert g.pseudorange_m == w.pseudorange_m
            assert np.abs(g.satellite_position_ecef_m - w.satellite_position_ecef_m).max() < QUANTISATION_M
            assert abs(g.satellite_clock_bias_m - w.satellite_clock_bias_m) < QUANTISATION_M
            assert abs(g.pseudorange_rate_mps - w.pseudorange_rate_mps) < 1e-3  # Doppler as float32
            assert abs(g.troposphere_delay_m - w.troposphere_delay_m) < 1e-9
            assert abs(g.ionosphere_delay_m - w.ionosphere_delay_m) < 1e-3  # Klobuchar LSBs
            assert g.cn0_dbhz == round(w.cn0_dbhz) or math.isnan(w.cn0_dbhz)
    assert n_gal_used >= 6 * N_EPOCHS
    assert n_unmodelled > 0 and decoder.counts["satellites_without_ephemeris"] == n_unmodelled


def test_corrupted_galileo_pages_are_counted(esbc):
    _, _, epochs, stream, _, _ = esbc
    from pyubx2 import GET, UBXMessage

    from rfi_experiments.ubx_synth import sfrbx_frame

    good = UBXMessage("RXM", "RXM-SFRBX", GET, gnssId=2, svId=3, sigId=1, numWords=8, version=2,
                      **{f"dwrd_{i:02d}": 0 for i in range(1, 9)}).serialize()
    bad_crc = sfrbx_frame(3, [0, 0, 0, 0, 1 << 31, 0, 0, 123], gnss_id=2, sig_id=1)
    decoder = UbxDecoder()
    decode_stream([stream[:0] + rawx_from_rinex(epochs[0].gps_week, epochs[0].tow_s, {}) + good + bad_crc], decoder)
    assert decoder.inav_rejected["page_order"] == 1 and decoder.inav_rejected["crc"] == 1
