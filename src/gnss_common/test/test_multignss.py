"""Multi-GNSS on a real station hour (ESBC00DNK, 2020-06-25 00:00-01:00 GPST, RINEX 3.05 mixed,
Hatanaka + gzip): RINEX 3 parsing, compressed input, Galileo / BeiDou / GLONASS / GPS satellite
states checked against the station's published coordinate, GLONASS orbit continuity, Doppler
wavelength per signal, and bad input."""

from __future__ import annotations

import gzip
import math
from pathlib import Path

import hatanaka
import numpy as np
import pytest

from gnss_common.constants import (
    BEIDOU_B1I_FREQUENCY_HZ,
    GALILEO_E1_FREQUENCY_HZ,
    GLONASS_G1_BASE_FREQUENCY_HZ,
    GPS_L1_FREQUENCY_HZ,
)
from gnss_common.coordinates import azimuth_elevation
from gnss_common.corrections import ionosphere_frequency_scale
from gnss_common.ephemeris import earth_rotation_correction, is_beidou_geo, pack_ephemerides, satellite_states
from gnss_common.glonass import glonass_g1_frequency_hz, glonass_states, pack_glonass
from gnss_common.measurements import GnssEpochBuilder, MeasurementBuilderParams
from gnss_common.observations import BEIDOU, GALILEO, GLONASS, GPS
from gnss_common.positioning import CONVERGED, least_squares_position
from gnss_common.rinex import RinexFormatError, read_rinex_nav, read_rinex_navs, read_rinex_obs

DATA = Path(__file__).resolve().parent / "data"
OBS = DATA / "ESBC00DNK_R_20201770000_01H_30S_MO.crx.gz"
NAV = DATA / "ESBC00DNK_R_20201770000_01H_MN.rnx.gz"
STATION_ECEF_M = np.array([3582105.2910, 532589.7313, 5232754.8054])
"""ESBC00DNK's published coordinate (cm level), ECEF m."""

SPP_RMS_LIMIT_M = 5.0
"""A broadcast-ephemeris single-frequency single-point fix with Klobuchar and a standard
troposphere lands within a few metres (about 1-3 m 3D RMS for a good station); 5 m is the bound
for every system: a wrong time scale (14 s of BeiDou), constant (mu, Omega_e) or frame rotation
moves the fix by tens of metres to kilometres."""


@pytest.fixture(scope="module")
def obs():
    return read_rinex_obs(OBS)


@pytest.fixture(scope="module")
def nav():
    return read_rinex_nav(NAV)


@pytest.fixture(scope="module")
def built(obs, nav):
    builder = GnssEpochBuilder.from_rinex(obs, nav)
    return [builder.build(e) for e in obs.epochs[::6]]  # every 3 min


def test_rinex3_mixed_obs_from_crx_gz(obs):
    h = obs.header
    assert h.version == pytest.approx(3.05)
    assert h.marker_name == "ESBC00DNK"
    np.testing.assert_allclose(h.approx_position_ecef_m, STATION_ECEF_M)
    assert set(h.obs_types) == {"C", "E", "G", "J", "R", "S"}
    assert len(h.obs_types["E"]) == 20 and h.obs_types["E"][:3] == ("C1C", "C5Q", "C6C")
    assert h.obs_types["C"][:3] == ("C2I", "C6I", "C7I")
    assert h.glonass_channels[1] == 1 and h.glonass_channels[2] == -4 and h.glonass_channels[10] == -7
    assert len(h.glonass_channels) == 23
    assert len(obs.epochs) == 120
    e0 = obs.epochs[0]
    assert (e0.gps_week, e0.tow_s) == (2111, 345600.0)  # 2020-06-25 00:00:00 GPST, a Thursday
    assert obs.epochs[-1].tow_s - e0.tow_s == 119 * 30.0
    assert len(e0.observations) == 43
    # Values as they stand in the file text (first epoch, C05 and C07 lines).
    c05, c07 = e0.observations["C05"], e0.observations["C07"]
    assert c05["C2I"] == 40715949.461 and math.isnan(c05["C6I"]) and c05["C7I"] == 40715946.882
    assert c05["S2I"] == 34.5 and c05["S7I"] == 38.0
    assert c07["C6I"] == 39491927.647 and c07["D2I"] == -484.694 and c07["L7I"] == 159017680.340


def test_compressed_and_plain_read_the_same(obs, tmp_path):
    text = hatanaka.decompress(OBS.read_bytes())
    plain = tmp_path / "esbc.rnx"
    plain.write_bytes(text)
    crx = tmp_path / "esbc.crx"
    crx.write_bytes(gzip.decompress(OBS.read_bytes()))
    for path in (plain, crx):
        other = read_rinex_obs(path)
        assert len(other.epochs) == len(obs.epochs)
        for a, b in zip(other.epochs[::17], obs.epochs[::17], strict=True):
            assert (a.gps_week, a.tow_s) == (b.gps_week, b.tow_s)
            assert a.observations.keys() == b.observations.keys()
            for sat in a.observations:
                np.testing.assert_array_equal(list(a.observations[sat].values()), list(b.observations[sat].values()))


def test_mixed_nav_records_by_system(nav):
    counts = nav.record_counts()
    assert set(counts) == {"G", "E", "C", "R", "J"}
    assert all(n > 0 for n in counts.values())
    assert nav.header.leap_seconds == 18
    # F/NAV records are skipped for the E1 user, and counted.
    assert nav.skipped_reasons["E"] == {"galileo_fnav": nav.skipped_records["E"]}
    gal = [e for e in nav.other_ephemerides if e.system == "E"]
    bds = [e for e in nav.other_ephemerides if e.system == "C"]
    assert gal and all(e.week == 2111 for e in gal)
    assert bds and all(e.week == 755 + 1356 for e in bds)  # BDT week 755 numbered as a GPS week
    r01 = next(e for e in nav.glonass_ephemerides if e.slot == 1)
    # First R01 record: epoch 2020-06-24 23:15:00 UTC -> GPST + 18 s; X = 10908.94238281 km.
    assert (r01.tb_week, r01.tb_s) == (2111, 3 * 86400 + 23 * 3600 + 15 * 60 + 18.0)
    assert r01.position_m[0] == pytest.approx(10908942.38281)
    assert r01.frequency_channel == 1
    assert r01.carrier_frequency_hz == GLONASS_G1_BASE_FREQUENCY_HZ + 0.5625e6


def _spp(observations, mask_deg: float = 10.0) -> np.ndarray | None:
    """Plain least-squares fix from the given observations alone (own receiver clock)."""
    if len(observations) < 5:
        return None
    sat = np.array([o.satellite_position_ecef_m for o in observations])
    rot, _, _ = earth_rotation_correction(sat, STATION_ECEF_M)
    _, el = azimuth_elevation(STATION_ECEF_M, rot)
    keep = el > math.radians(mask_deg)
    if keep.sum() < 5:
        return None
    sat = sat[keep]
    rho = np.array([
        o.pseudorange_m + o.satellite_clock_bias_m - o.ionosphere_delay_m - o.troposphere_delay_m
        for o, k in zip(observations, keep, strict=True) if k
    ])
    w = np.ones(len(rho))

    def model(x):
        diff = earth_rotation_correction(sat, x[:3])[0] - x[:3]
        rng = np.linalg.norm(diff, axis=1)
        return rng + x[3], diff / rng[:, None], w

    sol = least_squares_position(model, rho, np.zeros(4), 20, 1.0e-4, max_variance_m2=np.inf)
    return sol.x[:3] if sol.status == CONVERGED else None


@pytest.mark.parametrize("constellation", [GPS, GALILEO, BEIDOU, GLONASS])
def test_single_system_fix_lands_on_the_station(built, constellation):
    errors = []
    for r in built:
        fix = _spp([o for o in r.epoch.observations if o.constellation == constellation])
        if fix is not None:
            errors.append(np.linalg.norm(fix - STATION_ECEF_M))
    assert len(errors) == len(built)  # every sampled epoch has a fix from this system alone
    rms = float(np.sqrt(np.mean(np.square(errors))))
    assert rms < SPP_RMS_LIMIT_M, f"3D RMS {rms:.2f} m"


def test_beidou_geo_satellites_fit_the_station(built):
    """GEOs (C01-C05) go through the ICD's extra rotation: their residual at the known position,
    after the epoch's BeiDou clock (median over the non-GEO satellites), is metres, not km."""
    geo_res = []
    for r in built:
        bds = [o for o in r.epoch.observations if o.constellation == BEIDOU]
        sat = np.array([o.satellite_position_ecef_m for o in bds])
        rot, _, _ = earth_rotation_correction(sat, STATION_ECEF_M)
        rng = np.linalg.norm(rot - STATION_ECEF_M, axis=1)
        res = np.array([o.pseudorange_m + o.satellite_clock_bias_m - o.ionosphere_delay_m - o.troposphere_delay_m
                        for o in bds]) - rng
        geo = np.array([is_beidou_geo(o.svid) for o in bds])
        assert geo.any() and (~geo).sum() >= 4
        geo_res.extend(res[geo] - np.median(res[~geo]))
    assert np.max(np.abs(geo_res)) < 15.0


def test_glonass_orbit_continuity_between_records(nav):
    """Two consecutive records (30 min apart) integrated to the midpoint agree (ICD A.3.1.2)."""
    by_slot: dict[int, list] = {}
    for e in nav.glonass_ephemerides:
        by_slot.setdefault(e.slot, []).append(e)
    diffs, clock = [], []
    for records in by_slot.values():
        records.sort(key=lambda e: (e.tb_week, e.tb_s))
        for a, b in zip(records, records[1:], strict=False):
            if (b.tb_week - a.tb_week) * 604800 + b.tb_s - a.tb_s != 1800.0:
                continue
            sa = glonass_states(pack_glonass([a]), a.tb_week, a.tb_s + 900.0)
            sb = glonass_states(pack_glonass([b]), a.tb_week, a.tb_s + 900.0)
            diffs.append(np.linalg.norm(sa.position_ecef_m - sb.position_ecef_m))
            clock.append(abs(sa.clock_bias_s[0] - sb.clock_bias_s[0]) * 299792458.0)
    assert len(diffs) >= 20
    assert max(diffs) < 5.0 and np.median(diffs) < 2.0
    assert max(clock) < 3.0
    # Zero integration time returns the record's own state.
    e = nav.glonass_ephemerides[0]
    s0 = glonass_states(pack_glonass([e]), e.tb_week, e.tb_s)
    np.testing.assert_allclose(s0.position_ecef_m[0], e.position_m, atol=1e-9)


def test_doppler_uses_each_signals_wavelength(built):
    """Pseudorange rate = LOS . v_sat - c sat_drift + common receiver drift: the residual after the
    common term is cm/s for most satellites of every system (a GPS L1 wavelength on a GLONASS channel or on BeiDou
    B1I would leave metres per second)."""
    for code in (GPS, GALILEO, BEIDOU, GLONASS):
        res = []
        for r in built:
            obs = [o for o in r.epoch.observations if o.constellation == code and math.isfinite(o.pseudorange_rate_mps)]
            sat = np.array([o.satellite_position_ecef_m for o in obs])
            vel = np.array([o.satellite_velocity_ecef_mps for o in obs])
            rot, vrot, _ = earth_rotation_correction(sat, STATION_ECEF_M, vel)
            los = (rot - STATION_ECEF_M) / np.linalg.norm(rot - STATION_ECEF_M, axis=1)[:, None]
            model = np.sum(los * vrot, axis=1) - np.array([o.satellite_clock_drift_mps for o in obs])
            rr = np.array([o.pseudorange_rate_mps for o in obs]) - model
            res.extend(rr - np.median(rr))
        assert len(res) > 50
        # 90 % within 0.2 m/s (a satellite low in the sky may be noisier); a wrong wavelength
        # scales rates of hundreds of m/s by 1-2 %.
        assert np.percentile(np.abs(res), 90) < 0.2, code


def test_carrier_and_ionosphere_per_signal(built):
    r = built[0]
    freqs = {o.constellation: set() for o in r.epoch.observations}
    for o in r.epoch.observations:
        freqs[o.constellation].add(o.carrier_frequency_hz)
    assert freqs[GPS] == {GPS_L1_FREQUENCY_HZ} and freqs[GALILEO] == {GALILEO_E1_FREQUENCY_HZ}
    assert freqs[BEIDOU] == {BEIDOU_B1I_FREQUENCY_HZ}
    assert all(f == glonass_g1_frequency_hz(round((f - 1602e6) / 0.5625e6)) for f in freqs[GLONASS])
    assert len(freqs[GLONASS]) > 1
    assert float(ionosphere_frequency_scale(BEIDOU_B1I_FREQUENCY_HZ)) == pytest.approx(
        (1575.42 / 1561.098) ** 2)
    assert float(ionosphere_frequency_scale(GPS_L1_FREQUENCY_HZ)) == 1.0
    with pytest.raises(ValueError):
        ionosphere_frequency_scale(0.0)
    assert r.skipped_by_constellation.get("sbas", {}).get("unsupported_constellation", 0) > 0
    assert "galileo" not in r.skipped_by_constellation or "unsupported_constellation" not in (
        r.skipped_by_constellation["galileo"])


def test_per_system_nav_files_equal_the_mixed_file(obs, nav, tmp_path):
    """Archives publishing one nav file per system (``_GN``, ``_EN``, ``_CN``, ``_RN``, ``_JN``)."""
    lines = hatanaka.decompress(NAV.read_bytes()).decode().splitlines()
    end = next(i for i, line in enumerate(lines) if "END OF HEADER" in line)
    header, body = lines[: end + 1], lines[end + 1:]
    per_sys: dict[str, list[str]] = {}
    current = None
    for line in body:
        if line[:1].strip():
            current = line[0]
        per_sys.setdefault(str(current), []).append(line)
    paths = []
    for sys_char, rec in per_sys.items():
        first = header[0][:40] + sys_char + header[0][41:]
        p = tmp_path / f"nav_{sys_char}.rnx"
        p.write_text("\n".join([first, *header[1:], *rec]) + "\n")
        paths.append(p)
    merged = read_rinex_navs(paths)
    assert merged.record_counts() == nav.record_counts()
    a = GnssEpochBuilder.from_rinex(obs, merged).build(obs.epochs[5])
    b = GnssEpochBuilder.from_rinex(obs, nav).build(obs.epochs[5])
    assert [(o.constellation, o.svid) for o in a.epoch.observations] == [
        (o.constellation, o.svid) for o in b.epoch.observations]
    for x, y in zip(a.epoch.observations, b.epoch.observations, strict=True):
        np.testing.assert_allclose(x.satellite_position_ecef_m, y.satellite_position_ecef_m, atol=1e-6)
    with pytest.raises(ValueError):
        read_rinex_navs([])


def test_gps_only_builder_skips_the_others_by_constellation(obs, nav):
    r = GnssEpochBuilder.from_rinex(obs, nav, MeasurementBuilderParams(constellations=("G",))).build(obs.epochs[0])
    assert {o.constellation for o in r.epoch.observations} == {GPS}
    skipped = {k: v.get("unsupported_constellation", 0) for k, v in r.skipped_by_constellation.items()}
    assert skipped["galileo"] > 0 and skipped["beidou"] > 0 and skipped["glonass"] > 0
    with pytest.raises(ValueError):
        MeasurementBuilderParams(constellations=("S",))


def test_galileo_and_beidou_time_scales(nav):
    """BeiDou records are on BDT = GPST - 14 s: evaluating at t_oe + 14 s of GPS time is t_k = 0,
    so the position equals the closed form at the ascending-node argument (no 14 s of motion,
    about 40 km for a MEO)."""
    e = next(x for x in nav.other_ephemerides if x.system == "C" and not is_beidou_geo(x.prn))
    arr = pack_ephemerides([e])
    at_toe = satellite_states(arr, e.week, e.toe_s + 14.0)
    off = satellite_states(arr, e.week, e.toe_s)
    step = np.linalg.norm(at_toe.position_ecef_m - off.position_ecef_m)
    speed = np.linalg.norm(at_toe.velocity_ecef_mps)
    assert step == pytest.approx(14.0 * speed, rel=0.02)
    tc = (e.week - e.toc_week) * 604800 + e.toe_s - e.toc_s
    assert at_toe.clock_bias_s[0] - at_toe.relativistic_s[0] + e.tgd_s == pytest.approx(
        e.af0_s + e.af1_s_per_s * tc + e.af2_s_per_s2 * tc * tc, abs=1e-15)


# ----------------------------------------------------------------------------------------------
# bad input


def test_truncated_compressed_file_is_a_clear_error(tmp_path):
    raw = OBS.read_bytes()
    p = tmp_path / "cut.crx.gz"
    p.write_bytes(raw[: len(raw) // 3])
    with pytest.raises(RinexFormatError, match="cannot decompress"):
        read_rinex_obs(p)
    crx = gzip.decompress(raw)
    q = tmp_path / "cut.crx"
    q.write_bytes(crx[: len(crx) // 2])
    with pytest.raises(RinexFormatError, match="cut.crx"):
        read_rinex_obs(q)
    n = tmp_path / "cut_nav.rnx.gz"
    n.write_bytes(NAV.read_bytes()[:5000])
    with pytest.raises(RinexFormatError, match="cannot decompress"):
        read_rinex_nav(n)


def test_truncated_and_corrupted_rinex3_text(tmp_path):
    text = hatanaka.decompress(OBS.read_bytes()).decode()
    lines = text.splitlines()
    epoch_lines = [i for i, line in enumerate(lines) if line.startswith(">")]
    cut = tmp_path / "cut.rnx"
    cut.write_text("\n".join(lines[: epoch_lines[3] + 5]) + "\n")
    with pytest.raises(RinexFormatError, match=r"cut.rnx:\d+: file ends inside"):
        read_rinex_obs(cut)
    bad = list(lines)
    k = epoch_lines[2] + 1
    bad[k] = bad[k][:3] + "  2102x4y56.77" + bad[k][16:]
    p = tmp_path / "bad_value.rnx"
    p.write_text("\n".join(bad) + "\n")
    with pytest.raises(RinexFormatError, match=f"bad_value.rnx:{k + 1}: malformed observation value"):
        read_rinex_obs(p)
    bad = list(lines)
    bad[k] = "X" + bad[k][1:]
    p = tmp_path / "bad_sys.rnx"
    p.write_text("\n".join(bad) + "\n")
    with pytest.raises(RinexFormatError, match="not declared in header"):
        read_rinex_obs(p)


def test_truncated_and_corrupted_nav_records(tmp_path):
    lines = hatanaka.decompress(NAV.read_bytes()).decode().splitlines()
    glo = next(i for i, line in enumerate(lines) if line.startswith("R"))
    gal = next(i for i, line in enumerate(lines) if line.startswith("E"))
    p = tmp_path / "trunc.rnx"
    p.write_text("\n".join([*lines[:glo + 2], *lines[gal:gal + 8]]) + "\n")
    with pytest.raises(RinexFormatError, match=f"trunc.rnx:{glo + 3}: .*truncated"):
        read_rinex_nav(p)
    bad = list(lines)
    bad[glo + 2] = bad[glo + 2][:61] + " 2.500000000000e+00"  # channel 2.5
    p = tmp_path / "chan.rnx"
    p.write_text("\n".join(bad) + "\n")
    with pytest.raises(RinexFormatError, match="frequency channel"):
        read_rinex_nav(p)
    bad = list(lines)
    bad[gal + 1] = bad[gal + 1][:5] + "x.xx" + bad[gal + 1][9:]
    p = tmp_path / "gal.rnx"
    p.write_text("\n".join(bad) + "\n")
    with pytest.raises(RinexFormatError, match=f"gal.rnx:{gal + 2}: cannot parse"):
        read_rinex_nav(p)


def _rinex2_value(v: float) -> str:
    mant, exp = f"{v:.12E}".split("E")
    return f"{mant}D{int(exp):+03d}".rjust(19)


def test_rinex2_glonass_nav_file_equals_rinex3_records(nav, tmp_path):
    """RINEX 2.11 GLONASS nav files (type G, ``.yyg``) as archives publish one file per system."""
    lines = hatanaka.decompress(NAV.read_bytes()).decode().splitlines()
    starts = [i for i, line in enumerate(lines) if line.startswith("R")][:12]
    out = [
        "     2.11           G: GLONASS NAV DATA                     RINEX VERSION / TYPE",
        "    18                                                      LEAP SECONDS",
        "                                                            END OF HEADER",
    ]
    for i in starts:
        first = lines[i]
        slot, yy = int(first[1:3]), int(first[4:8])
        mo, dd, hh, mi, ss = (int(first[k:k + 3]) for k in (8, 11, 14, 17, 20))
        vals = [float(first[23 + 19 * k: 42 + 19 * k]) for k in range(3)]
        out.append(f"{slot:2d} {yy % 100:02d} {mo:2d} {dd:2d} {hh:2d} {mi:2d}{float(ss):5.1f}"
                   + "".join(_rinex2_value(v) for v in vals))
        for j in (1, 2, 3):
            row = [float(lines[i + j][4 + 19 * k: 23 + 19 * k] or 0.0) for k in range(4)]
            out.append("   " + "".join(_rinex2_value(v) for v in row))
    p = tmp_path / "esbc1770.20g"
    p.write_text("\n".join(out) + "\n")
    v2 = read_rinex_nav(p)
    assert v2.ephemerides == () and len(v2.glonass_ephemerides) == 12
    for a, b in zip(v2.glonass_ephemerides, nav.glonass_ephemerides[:12], strict=True):
        assert (a.slot, a.tb_week, a.tb_s, a.frequency_channel, a.health) == (
            b.slot, b.tb_week, b.tb_s, b.frequency_channel, b.health)
        np.testing.assert_allclose(a.position_m, b.position_m, rtol=1e-12)
        np.testing.assert_allclose(a.velocity_mps, b.velocity_mps, rtol=1e-12)
        assert a.minus_tau_n_s == pytest.approx(b.minus_tau_n_s, rel=1e-12)


def _shift_epochs(text: str, seconds: int, time_system: str) -> str:
    """The observation text with every epoch line moved by ``seconds`` and TIME OF FIRST OBS's
    system replaced (epochs stay within the same minute range of this file)."""
    import datetime as dt

    out = []
    for line in text.splitlines():
        if line.startswith(">"):
            t = dt.datetime(int(line[2:6]), int(line[7:9]), int(line[10:12]), int(line[13:15]), int(line[16:18]))
            t += dt.timedelta(seconds=float(line[18:29]) + seconds)
            line = f"> {t:%Y %m %d %H %M} {t.second + t.microsecond / 1e6:10.7f}" + line[29:]
        elif line[60:].startswith("TIME OF FIRST OBS"):
            line = line[:48] + time_system + line[51:]
        out.append(line)
    return "\n".join(out) + "\n"


@pytest.mark.parametrize(("time_system", "offset_s"), [("BDT", -14), ("GLO", -18), ("GAL", 0)])
def test_obs_time_systems_are_converted_to_gps_time(obs, tmp_path, time_system, offset_s):
    """Epochs on BDT (GPST - 14 s), GLO (given as UTC, GPST - 18 s in 2020) or GAL (= GPST) read
    back on GPS time."""
    lines = hatanaka.decompress(OBS.read_bytes()).decode().splitlines()
    epoch_lines = [i for i, line in enumerate(lines) if line.startswith(">")]
    text = "\n".join(lines[: epoch_lines[3]]) + "\n"
    p = tmp_path / f"{time_system}.rnx"
    p.write_text(_shift_epochs(text, offset_s, time_system))
    other = read_rinex_obs(p)
    assert other.header.time_system == time_system
    assert [(e.gps_week, e.tow_s) for e in other.epochs] == [(e.gps_week, e.tow_s) for e in obs.epochs[:3]]
    bad = tmp_path / "tai.rnx"
    bad.write_text(_shift_epochs(text, 0, "TAI"))
    with pytest.raises(RinexFormatError, match="time system 'TAI' not supported"):
        read_rinex_obs(bad)


def test_galileo_fnav_used_when_the_file_has_no_inav(obs, tmp_path):
    """A nav file with only F/NAV Galileo records (data source bit 1): their clocks (BGD E5a/E1)
    serve the E1 user too, and the Galileo fix stays within the bound."""
    lines = hatanaka.decompress(NAV.read_bytes()).decode().splitlines()
    end = next(i for i, line in enumerate(lines) if "END OF HEADER" in line)
    out, i, n_fnav = lines[: end + 1], end + 1, 0
    while i < len(lines):
        j = i + 1
        while j < len(lines) and lines[j][:1] == " " and lines[j].strip():
            j += 1
        rec = lines[i:j]
        if rec[0].startswith("E"):
            source = int(float(rec[5][23:42]))
            if source & 0b101:  # I/NAV: dropped
                i = j
                continue
            n_fnav += 1
        out += rec
        i = j
    p = tmp_path / "fnav_only.rnx"
    p.write_text("\n".join(out) + "\n")
    nav = read_rinex_nav(p)
    gal = [e for e in nav.other_ephemerides if e.system == "E"]
    assert len(gal) == n_fnav > 0 and "E" not in nav.skipped_records
    builder = GnssEpochBuilder.from_rinex(obs, nav)
    errors = []
    for epoch in obs.epochs[::12]:
        x = _spp([o for o in builder.build(epoch).epoch.observations if o.constellation == GALILEO])
        assert x is not None
        errors.append(np.linalg.norm(x - STATION_ECEF_M))
    assert float(np.sqrt(np.mean(np.square(errors)))) < SPP_RMS_LIMIT_M
