"""A simulated u-blox receiver: GnssEpoch objects and broadcast ephemerides -> a UBX byte stream.

Turns the measurements of a simulation (:mod:`rfi_sim.gnss_uwb`) into what a u-blox receiver
would send for them, with pyubx2's own message generator (``UBXMessage(...).serialize()``):
UBX-RXM-RAWX per epoch (GPS L1 C/A), UBX-RXM-SFRBX subframes 1-3 per satellite encoded from the
ephemerides by :func:`gnss_common.lnav.encode_ephemeris_subframes`, a subframe 4 page 18 with the
Klobuchar coefficients, UBX-MON-HW and UBX-MON-SPAN. Used by tests and to feed ``ubx_source`` without a
receiver. Pure: never imports rclpy.

What a receiver reports is quantised, and so is this stream: C/N0 to an integer dB-Hz
(RAWX ``cno``), Doppler to float32, the std fields to their 4-bit exponents, the ephemerides and
Klobuchar coefficients to their LNAV scale factors.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np

from gnss_common.constants import GPS_L1_WAVELENGTH_M
from gnss_common.ephemeris import GpsEphemeris
from gnss_common.inav import encode_page, encode_words
from gnss_common.lnav import encode_ephemeris_subframes, encode_iono_subframe
from gnss_common.observations import GPS, GnssEpoch

DEFAULT_PSEUDORANGE_STD_M = 0.64
"""prStdev reported when a simulated observation carries no std, m (0.01 * 2**6)."""


def _std_exponent(value: float, unit: float, default: int) -> int:
    if not math.isfinite(value) or value <= 0.0:
        return default
    return int(min(15, max(0, round(math.log2(value / unit)))))


def rawx_from_rinex(week: int, tow_s: float, observations: dict[str, dict[str, float]],
                    leap_seconds: int = 18) -> bytes:
    """One UBX-RXM-RAWX frame of RINEX 3 observations: GPS and QZSS ``C1C/D1C/S1C`` (L1 C/A),
    Galileo ``C1C/D1C/S1C`` (E1 C), BeiDou ``C2I/D2I/S2I`` (B1I); other satellites are left out."""
    from pyubx2 import GET, UBXMessage

    signals = {"G": (0, 0, "1C"), "E": (2, 0, "1C"), "C": (3, 0, "2I"), "J": (5, 0, "1C")}
    fields: dict[str, object] = dict(rcvTow=float(tow_s), week=int(week), leapS=int(leap_seconds), leapSec=1,
                                     version=1)
    n = 0
    for sat, values in sorted(observations.items()):
        if sat[0] not in signals:
            continue
        gnss_id, sig_id, code = signals[sat[0]]
        pr = values.get("C" + code, math.nan)
        if not math.isfinite(pr):
            continue
        n += 1
        s = f"_{n:02d}"
        dop = values.get("D" + code, math.nan)
        cn0 = values.get("S" + code, math.nan)
        fields.update({
            "prMes" + s: float(pr), "cpMes" + s: 0.0, "doMes" + s: float(dop) if math.isfinite(dop) else 0.0,
            "gnssId" + s: gnss_id, "svId" + s: int(sat[1:]), "sigId" + s: sig_id, "freqId" + s: 0,
            "locktime" + s: 64500, "cno" + s: int(round(cn0)) if math.isfinite(cn0) else 0,
            "prStd" + s: 5, "cpStd" + s: 15, "doStd" + s: 6, "prValid" + s: 1,
        })
    fields["numMeas"] = n
    return UBXMessage("RXM", "RXM-RAWX", GET, **fields).serialize()


def rawx_frame(epoch: GnssEpoch, leap_seconds: int = 18) -> bytes:
    """One UBX-RXM-RAWX frame of an epoch's GPS observations (L1 C/A, pseudorange valid).

    Args:
        epoch: the epoch (its GPS week and time of week become week / rcvTow).
        leap_seconds: leapS field (GPS - UTC, s; informative only).
    """
    from pyubx2 import GET, UBXMessage

    fields: dict[str, object] = dict(rcvTow=float(epoch.gps_time_of_week_s), week=int(epoch.gps_week),
                                     leapS=int(leap_seconds), leapSec=1, version=1)
    obs = [o for o in epoch.observations if o.constellation == GPS]
    for i, o in enumerate(obs, start=1):
        s = f"_{i:02d}"
        doppler = -o.pseudorange_rate_mps / GPS_L1_WAVELENGTH_M if math.isfinite(o.pseudorange_rate_mps) else 0.0
        fields.update({
            "prMes" + s: float(o.pseudorange_m), "cpMes" + s: 0.0, "doMes" + s: float(doppler),
            "gnssId" + s: 0, "svId" + s: int(o.svid), "sigId" + s: 0, "freqId" + s: 0,
            "locktime" + s: 64500,
            "cno" + s: int(min(255, max(0, round(o.cn0_dbhz)))) if math.isfinite(o.cn0_dbhz) else 0,
            "prStd" + s: _std_exponent(o.pseudorange_std_m, 0.01, _std_exponent(DEFAULT_PSEUDORANGE_STD_M, 0.01, 6)),
            "cpStd" + s: 15,
            "doStd" + s: _std_exponent(o.pseudorange_rate_std_mps / GPS_L1_WAVELENGTH_M, 0.002, 6),
            "prValid" + s: 1, "cpValid" + s: 0, "halfCyc" + s: 0, "subHalfCyc" + s: 0,
        })
    fields["numMeas"] = len(obs)
    return UBXMessage("RXM", "RXM-RAWX", GET, **fields).serialize()


def sfrbx_frame(prn: int, words: Sequence[int], gnss_id: int = 0, sig_id: int = 0) -> bytes:
    """One UBX-RXM-SFRBX frame (version 2): ten GPS LNAV words (default) or, with ``gnss_id`` 2 and
    ``sig_id`` 1 (E1 B), the eight words of a Galileo I/NAV page pair."""
    from pyubx2 import GET, UBXMessage

    return UBXMessage("RXM", "RXM-SFRBX", GET, gnssId=int(gnss_id), svId=int(prn), sigId=int(sig_id), freqId=0,
                      numWords=len(words), chn=0, version=2,
                      **{f"dwrd_{i:02d}": int(w) for i, w in enumerate(words, start=1)}).serialize()


def ephemeris_frames(ephemerides: Iterable[GpsEphemeris], week: int, tow_s: float) -> bytes:
    """SFRBX frames of subframes 1-3 of each record, as broadcast from the 30 s frame before ``tow_s``."""
    start = math.floor(tow_s / 30.0) * 30.0 - 30.0
    wk = week
    if start < 0:
        start += 604800.0
        wk -= 1
    out = bytearray()
    for eph in ephemerides:
        for words in encode_ephemeris_subframes(eph, wk, start):
            out += sfrbx_frame(eph.prn, words)
    return bytes(out)


def galileo_frames(ephemerides: Iterable[GpsEphemeris], tow_s: float) -> bytes:
    """SFRBX frames of I/NAV word types 1-5 of each Galileo record (``system="E"``), E1 B, with GST
    ``tow_s`` (s) in word type 5."""
    out = bytearray()
    for eph in ephemerides:
        words = encode_words(eph, tow_s)
        for k in (1, 2, 3, 4, 5):
            out += sfrbx_frame(eph.prn, encode_page(words[k]), gnss_id=2, sig_id=1)
    return bytes(out)


def klobuchar_frame(prn: int, alpha: np.ndarray, beta: np.ndarray, tow_s: float) -> bytes:
    """SFRBX frame of a subframe 4 page 18 (Klobuchar alpha, beta) sent by ``prn``."""
    start = math.floor(tow_s / 30.0) * 30.0 + 18.0 - 30.0
    return sfrbx_frame(prn, encode_iono_subframe(alpha, beta, start % 604800.0))


def mon_hw_frame(jamming_state: int, jam_indicator: int, agc_count: int, noise_per_ms: int) -> bytes:
    """A UBX-MON-HW frame with the given interference fields (antenna OK and powered)."""
    from pyubx2 import GET, UBXMessage

    return UBXMessage("MON", "MON-HW", GET, noisePerMS=int(noise_per_ms), agcCnt=int(agc_count), aStatus=2,
                      aPower=1, jammingState=int(jamming_state), jamInd=int(jam_indicator)).serialize()


def mon_span_frame(blocks: Sequence[tuple[Sequence[int], int, int, int, int]]) -> bytes:
    """A UBX-MON-SPAN frame: per RF block (256 spectrum counts of 0.25 dB, span Hz, res Hz, center Hz,
    pga dB)."""
    from pyubx2 import GET, UBXMessage

    fields: dict[str, object] = dict(version=0, numRfBlocks=len(blocks))
    for i, (counts, span, res, center, pga) in enumerate(blocks, start=1):
        s = f"_{i:02d}"
        fields.update({"spectrum" + s: [int(c) for c in counts], "span" + s: int(span), "res" + s: int(res),
                       "center" + s: int(center), "pga" + s: int(pga)})
    return UBXMessage("MON", "MON-SPAN", GET, **fields).serialize()
