"""UBX decoding (rfi_experiments.ubx_decode): framing and bad input on pyubx2's real sample logs,
field values checked against pyubx2's own parse / the samples' README, RAWX flags, SFRBX -> epochs,
a real log without SFRBX -> measurements with NaN satellite states, the real MON-SPAN spectra."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pyubx2 import GET, UBXMessage, UBXReader

from gnss_common.constants import GPS_L1_FREQUENCY_HZ, SPEED_OF_LIGHT_MPS
from gnss_common.glonass import glonass_g1_frequency_hz
from gnss_common.observations import BEIDOU, GALILEO, GLONASS, GPS
from rfi_experiments.ubx_decode import (
    JAMMING_CRITICAL,
    SOURCE_MON_HW,
    SOURCE_MON_RF,
    SOURCE_SEC_SIG,
    EpochOutput,
    InterferenceReport,
    SpectrumReport,
    UbxDecoder,
    UbxDecoderParams,
    UbxFramer,
    decode_stream,
    header_stamp_ns,
    rawx_from_message,
    rawx_to_observations,
    ubx_checksum,
)
from rfi_experiments.ubx_synth import mon_span_frame

DATA = Path(__file__).parent / "data" / "ubx"
ALL = (DATA / "pygpsdata-ALL.log").read_bytes()
MON = (DATA / "pygpsdata-MON.log").read_bytes()
RAWX = (DATA / "pygpsdata-RXMRAWX.log").read_bytes()


def frames_of(data: bytes) -> list[bytes]:
    framer = UbxFramer()
    out = framer.feed(data)
    framer.finish()
    return out


def test_sample_logs_frame_completely():
    for data, n in ((ALL, 103), (MON, 12), (RAWX, 14)):
        framer = UbxFramer()
        frames = framer.feed(data)
        framer.finish()
        assert len(frames) == n
        assert framer.rejected == {"bad_checksum": 0, "bad_length": 0, "truncated": 0}
        assert framer.skipped_bytes == 0
        assert b"".join(frames) == data


def test_framing_does_not_depend_on_chunking():
    rng = np.random.default_rng(7)
    whole = frames_of(ALL)
    framer = UbxFramer()
    got: list[bytes] = []
    pos = 0
    while pos < len(ALL):
        n = int(rng.integers(1, 300))
        got += framer.feed(ALL[pos:pos + n])
        pos += n
    assert got == whole


def test_bad_checksum_is_counted_and_the_next_frames_survive():
    frames = frames_of(RAWX)
    bad = bytearray(frames[3])
    bad[40] ^= 0x10
    data = b"".join(frames[:3]) + bytes(bad) + b"".join(frames[4:])
    dec = UbxDecoder()
    decode_stream([data], dec)
    assert dec.counts["bad_checksum"] == 1
    assert dec.counts["rawx_epochs"] == 13


def test_corrupted_length_field_resynchronises():
    frames = frames_of(MON)
    for new_len in (0xFFFF, 4):  # impossible length; plausible but wrong length (checksum then fails)
        bad = bytearray(frames[2])
        bad[4:6] = new_len.to_bytes(2, "little")
        data = b"".join(frames[:2]) + bytes(bad) + b"".join(frames[3:])
        framer = UbxFramer()
        got = framer.feed(data)
        framer.finish()
        assert got == frames[:2] + frames[3:]  # nothing after the corrupted frame is lost
        assert framer.rejected["bad_length"] + framer.rejected["bad_checksum"] == 1


def test_truncated_stream_and_noise_between_frames():
    frames = frames_of(MON)
    data = b"$GPGGA,noise*00\r\n" + b"".join(frames) + frames[0][:9]
    dec = UbxDecoder()
    decode_stream([data], dec)
    assert dec.counts["truncated"] == 1
    assert dec.counts["frames"] == 12
    assert dec.counts["skipped_bytes"] == len(b"$GPGGA,noise*00\r\n")


def test_unknown_and_unparsable_messages_are_counted():
    body = bytes([0x77, 0x01, 2, 0, 1, 2])
    unknown = b"\xb5\x62" + body + ubx_checksum(body)
    body = bytes([0x02, 0x15, 3, 0, 1, 2, 3])  # RXM-RAWX with a 3-byte payload
    short_rawx = b"\xb5\x62" + body + ubx_checksum(body)
    dec = UbxDecoder()
    decode_stream([unknown + short_rawx + MON], dec)
    assert dec.counts["unknown_messages"] == 1
    assert dec.counts["unparsable"] == 1
    assert dec.ignored["MON-VER"] == 1 and "MON-SPAN" not in dec.ignored
    assert dec.counts["spectrum_before_time"] == 1  # MON-SPAN before any RAWX: no time to stamp it with


def _first_rawx():
    return UBXReader.parse(frames_of(RAWX)[0])


def test_rawx_fields_match_pyubx2_parse_of_the_sample():
    # Values as pyubx2 parses the first RXM-RAWX of pygpsdata-RXMRAWX.log (prStd etc. raw 4-bit
    # codes there; the scalings are the u-blox interface description's).
    r = rawx_from_message(_first_rawx())
    assert (r.week, r.tow_s, r.leap_seconds, r.leap_seconds_valid, r.clock_reset) == (2327, 223793.0, 18, True, False)
    assert len(r.measurements) == 23
    m = r.measurements[0]
    assert (m.gnss_id, m.sv_id, m.sig_id) == (0, 11, 0)
    assert m.pseudorange_m == 21431659.961167824
    assert m.carrier_phase_cycles == 112624126.09217028
    assert m.doppler_hz == 366.0107421875
    assert m.cn0_dbhz == 43.0 and m.lock_time_s == 64.5
    assert m.pseudorange_std_m == pytest.approx(0.16) and m.carrier_phase_std_cycles == pytest.approx(0.004)
    assert m.doppler_std_hz == pytest.approx(0.128)
    assert (m.pr_valid, m.cp_valid, m.half_cycle_resolved, m.half_cycle_subtracted) == (True, True, True, False)
    g17 = r.measurements[8]  # GLONASS 17: carrier phase not valid
    assert (g17.gnss_id, g17.sv_id, g17.freq_id, g17.cp_valid, g17.half_cycle_resolved) == (6, 17, 11, False, False)
    assert math.isnan(g17.carrier_phase_cycles) and math.isnan(g17.carrier_phase_std_cycles)
    assert g17.pseudorange_m == 21889633.295237724
    assert r.measurements[2].half_cycle_subtracted  # BeiDou 21: subHalfCyc 1


def test_rawx_to_rinex_observables():
    obs, unmapped = rawx_to_observations(rawx_from_message(_first_rawx()))
    assert unmapped == 0
    assert obs.observations["G11"]["C1C"] == 21431659.961167824
    assert obs.observations["G11"]["D1C"] == 366.0107421875
    assert obs.observations["G11"]["S1C"] == 43.0
    assert obs.observations["C11"]["C2I"] == 23388266.420824006  # BeiDou B1I
    assert obs.observations["E08"]["C1C"] == 23858352.861107133  # Galileo E1C
    assert math.isnan(obs.observations["R17"]["L1C"])
    assert obs.observations["R03"]["C1C"] == 20505357.148789547
    assert (obs.gps_week, obs.tow_s) == (2327, 223793.0)


def test_receiver_leap_seconds_are_checked_against_the_table():
    frames = frames_of(RAWX)  # 2024, leapS 18 (valid)
    dec = UbxDecoder()
    decode_stream([b"".join(frames)], dec)
    assert dec.counts["leap_seconds_disagree"] == 0
    msg = UBXMessage("RXM", "RXM-RAWX", GET, rcvTow=223793.0, week=2327, leapS=17, leapSec=1, numMeas=0, version=1)
    decode_stream([msg.serialize()], dec)
    assert dec.counts["leap_seconds_disagree"] == 1


def test_invalid_pseudorange_is_never_used():
    msg = UBXMessage("RXM", "RXM-RAWX", GET, rcvTow=100.0, week=2000, leapS=18, numMeas=1, version=1,
                     prMes_01=2.1e7, cpMes_01=0.0, doMes_01=10.0, gnssId_01=0, svId_01=5, sigId_01=0, cno_01=40,
                     prStd_01=5, cpStd_01=15, doStd_01=5, prValid_01=0)
    r = rawx_from_message(UBXReader.parse(msg.serialize()))
    assert math.isnan(r.measurements[0].pseudorange_m) and not r.measurements[0].pr_valid
    obs, _ = rawx_to_observations(r)
    assert math.isnan(obs.observations["G05"]["C1C"])


def test_without_publish_without_ephemeris_epochs_wait_for_ephemeris_and_are_counted():
    dec = UbxDecoder(UbxDecoderParams(publish_without_ephemeris=False))
    out = decode_stream([RAWX], dec)
    assert out == []  # no ephemeris in the log: nothing published half-empty
    assert dec.counts["rawx_epochs"] == 14 and dec.counts["epochs_waiting_for_ephemeris"] == 14
    gps = sum(1 for m in rawx_from_message(_first_rawx()).measurements if m.gnss_id == 0)
    assert dec.skipped["no_ephemeris"] >= gps
    assert dec.counts["satellites_without_ephemeris"] == 0


def test_a_real_log_without_sfrbx_gives_measurements_with_nan_satellite_states():
    # pygpsdata-RXMRAWX.log: 14 real RXM-RAWX epochs (GPS, Galileo, BeiDou, GLONASS), no RXM-SFRBX
    dec = UbxDecoder()
    out = [o for o in decode_stream([RAWX], dec) if isinstance(o, EpochOutput)]
    assert len(out) == 14 and dec.counts["epochs_waiting_for_ephemeris"] == 0
    assert dec.counts["satellites_without_ephemeris"] == sum(len(o.epoch.observations) for o in out)
    assert dec.skipped["no_ephemeris"] == 0  # published, not skipped
    first = out[0]
    rawx = rawx_from_message(_first_rawx())
    assert first.rawx == rawx and first.epoch.gps_time_of_week_s == 223793.0
    by_sat = {(o.constellation, o.svid): o for o in first.epoch.observations}
    assert {c for c, _ in by_sat} == {GPS, GALILEO, BEIDOU, GLONASS}
    for o in first.epoch.observations:  # never a valid-looking state
        assert np.isnan(o.satellite_position_ecef_m).all() and np.isnan(o.satellite_velocity_ecef_mps).all()
        assert math.isnan(o.satellite_clock_bias_m) and math.isnan(o.satellite_clock_drift_mps)
        assert math.isnan(o.ionosphere_delay_m) and math.isnan(o.troposphere_delay_m)
        assert 1.0e7 < o.pseudorange_m < 4.8e7 and 10.0 < o.cn0_dbhz < 60.0
    g11 = by_sat[(GPS, 11)]  # values as pyubx2 parses them (test_rawx_fields_match_pyubx2_parse_of_the_sample)
    assert g11.pseudorange_m == 21431659.961167824 and g11.cn0_dbhz == 43.0
    assert g11.pseudorange_rate_mps == pytest.approx(-366.0107421875 * SPEED_OF_LIGHT_MPS / GPS_L1_FREQUENCY_HZ)
    assert g11.pseudorange_std_m == pytest.approx(0.16)  # the receiver's prStdev, as for modelled satellites
    r17 = by_sat[(GLONASS, 17)]  # GLONASS: the carrier of the RAWX frequency channel (freqId 11: k = 4)
    assert r17.carrier_frequency_hz == glonass_g1_frequency_hz(4) and r17.pseudorange_m == 21889633.295237724
    assert by_sat[(BEIDOU, 11)].pseudorange_m == 23388266.420824006


def _reports(data: bytes) -> list[InterferenceReport]:
    rawx = frames_of(RAWX)[0]  # a receive time for the reports (they carry none)
    dec = UbxDecoder()
    out = decode_stream([rawx + data], dec)
    return [o for o in out if isinstance(o, InterferenceReport)]


def test_mon_hw_and_mon_rf_fields_match_the_readme():
    reports = _reports(MON)
    hw = [r for r in reports if r.source == SOURCE_MON_HW]
    rf = [r for r in reports if r.source == SOURCE_MON_RF]
    assert len(hw) == 1 and len(rf) == 2
    assert (hw[0].noise_per_ms, hw[0].agc_count, hw[0].jamming_state, hw[0].jam_indicator) == (92, 1404, 0, 7)
    assert (hw[0].antenna_status, hw[0].antenna_power) == (2, 1)
    assert (rf[0].jam_indicator, rf[0].jamming_state, rf[0].rf_block_id) == (7, 0, 0)
    assert (rf[1].jam_indicator, rf[1].jamming_state) == (255, JAMMING_CRITICAL)
    assert all(r.gps_week == 2327 and r.gps_time_of_week_s == 223793.0 for r in reports)
    reports = _reports(ALL)
    assert [(r.source, r.jam_indicator, r.noise_per_ms, r.agc_count) for r in reports] == [
        (SOURCE_MON_HW, 12, 97, 1404), (SOURCE_MON_RF, 11, 97, 1404)]


def test_reports_before_any_receive_time_are_counted_not_stamped():
    dec = UbxDecoder()
    assert decode_stream([MON], dec) == []
    assert dec.counts["interference_before_time"] == 3


@pytest.mark.parametrize("version", [1, 2])
def test_sec_sig(version):
    sig = UBXMessage("SEC", "SEC-SIG", GET, version=version, jamDetEnabled=1, jammingState=2, spfDetEnabled=1,
                     spoofingState=3).serialize()
    (r,) = _reports(sig)
    assert (r.source, r.jamming_state, r.jamming_detection_enabled, r.spoofing_state) == (SOURCE_SEC_SIG, 2, True, 3)
    assert r.spoofing_detection_enabled
    assert math.isnan(r.jam_indicator) and math.isnan(r.agc_count)


def test_decoder_params_are_checked():
    with pytest.raises(ValueError):
        UbxDecoderParams(min_satellites=0)


SPECTRA_JSON = Path(__file__).resolve().parents[2] / "gnss_integrity" / "test" / "data" / "mon_span_pyubx2.json"


def _spectra(data: bytes) -> tuple[list[SpectrumReport], UbxDecoder]:
    dec = UbxDecoder()
    out = decode_stream([frames_of(RAWX)[0] + data], dec)  # a receive time for the reports
    return [o for o in out if isinstance(o, SpectrumReport)], dec


def test_real_mon_span_decodes_as_pyubx2_parses_it():
    for data in (MON, ALL):
        (report,), dec = _spectra(data)
        msg = next(m for m in (UBXReader.parse(f) for f in frames_of(data)) if m.identity == "MON-SPAN")
        assert report.power_db == tuple(0.25 * c for c in msg.spectrum_01)  # 0.25 dB units -> dB
        assert (report.center_frequency_hz, report.span_hz, report.resolution_hz, report.pga_gain_db) == (
            msg.center_01, msg.span_01, msg.res_01, msg.pga_01) == (1583.4e6, 128e6, 0.5e6, 12.0)
        assert report.rf_block_id == 0 and dec.counts["spectrum_reports"] == 1
        assert (report.gps_week, report.gps_time_of_week_s) == (2327, 223793.0)
        assert report.stamp_ns == header_stamp_ns(2327, 223793.0)  # stamped like the interference reports
        # block 0 is the L1 band: 1519.4-1647.4 MHz around GPS L1 (1575.42 MHz, bin 111), whose bin
        # lies in the front-end passband, 20 dB and more above the ends of the span
        assert report.span_hz == 256 * report.resolution_hz
        assert abs(report.center_frequency_hz - 1575.42e6) < 10e6
        bin_l1 = round(127 + (1575.42e6 - report.center_frequency_hz) / report.resolution_hz)
        x = np.array(report.power_db)
        assert bin_l1 == 111 and x[bin_l1] > max(x[:10].max(), x[-10:].max()) + 20.0


def test_the_receivers_centre_spur_sits_in_bin_127():
    # u-blox: "a spur may be visible at the center frequency"; the interface description's
    # f(i) = center + span (i - 127) / 256 puts the centre in bin 127, and there it is
    from scipy.ndimage import median_filter

    (report,), _ = _spectra(ALL)
    x = np.array(report.power_db)
    rise = x - median_filter(x, size=15, mode="nearest")
    assert 60 + int(np.argmax(rise[60:200])) == 127 and rise[127] == 2.5


def test_mon_span_blocks_and_bad_blocks():
    l1 = (list(range(256)), 128_000_000, 500_000, 1_583_400_000, 12)
    l2 = ([30] * 256, 128_000_000, 500_000, 1_227_600_000, 20)
    zero_span = ([40] * 256, 0, 500_000, 1_583_400_000, 12)
    truncated = bytearray(mon_span_frame([l1]))
    truncated[7] = 2  # numRfBlocks 2 with one block of payload
    body = bytes(truncated[2:-2])
    truncated = b"\xb5\x62" + body + ubx_checksum(body)
    dec = UbxDecoder()
    out = decode_stream([frames_of(RAWX)[0] + mon_span_frame([l1, l2]) + mon_span_frame([zero_span]) + truncated], dec)
    spectra = [o for o in out if isinstance(o, SpectrumReport)]
    assert [(s.rf_block_id, s.center_frequency_hz, s.pga_gain_db) for s in spectra] == [
        (0, 1583.4e6, 12.0), (1, 1227.6e6, 20.0)]
    assert spectra[0].power_db[255] == 63.75 and spectra[1].power_db == (7.5,) * 256
    assert dec.counts["spectrum_reports"] == 2 and dec.counts["unparsable"] == 2  # never published


def test_the_spectra_copied_for_gnss_integrity_equal_the_decoded_ones():
    import hashlib
    import json

    entries = json.loads(SPECTRA_JSON.read_text())["spectra"]
    assert len(entries) == 2
    for entry, data in zip(entries, (MON, ALL), strict=True):
        (report,), _ = _spectra(data)
        assert entry["source_sha256"] == hashlib.sha256(data).hexdigest()
        assert tuple(0.25 * c for c in entry["counts"]) == report.power_db
        assert (entry["center_hz"], entry["span_hz"], entry["res_hz"], entry["pga_db"]) == (
            report.center_frequency_hz, report.span_hz, report.resolution_hz, report.pga_gain_db)
