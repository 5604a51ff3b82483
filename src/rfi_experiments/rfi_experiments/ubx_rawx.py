"""UBX-RXM-RAWX (pure): the message -> :class:`RawxEpoch` records -> RINEX 3 observables, and the
measurement of a satellite without a usable ephemeris (NaN satellite states).

Used by :class:`rfi_experiments.ubx_decode.UbxDecoder` (which re-exports these names); never
imports rclpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from gnss_common.constants import SPEED_OF_LIGHT_MPS
from gnss_common.glonass import glonass_g1_frequency_hz
from gnss_common.measurements import CONSTELLATION_CODES, MeasurementBuilderParams
from gnss_common.observation_codes import select_signal
from gnss_common.observations import SatelliteObservation
from gnss_common.rinex import RinexObsEpoch

GNSS_LETTERS = {0: "G", 1: "S", 2: "E", 3: "C", 5: "J", 6: "R", 7: "I"}
"""UBX gnssId -> RINEX satellite system letter (u-blox interface description, GNSS identifiers)."""

RINEX_CODES: dict[tuple[int, int], str] = {
    (0, 0): "1C", (0, 3): "2L", (0, 4): "2S", (0, 6): "5I", (0, 7): "5Q",
    (1, 0): "1C",
    (2, 0): "1C", (2, 1): "1B", (2, 3): "5I", (2, 4): "5Q", (2, 5): "7I", (2, 6): "7Q",
    (3, 0): "2I", (3, 1): "2I", (3, 2): "7I", (3, 3): "7I", (3, 5): "1P", (3, 7): "5P",
    (5, 0): "1C", (5, 1): "1Z", (5, 4): "2S", (5, 5): "2L", (5, 8): "5I", (5, 9): "5Q",
    (6, 0): "1C", (6, 2): "2C",
    (7, 0): "5A",
}
"""(gnssId, sigId) of UBX-RXM-RAWX -> RINEX 3 signal code (band + attribute; RINEX 3.04 Table 4,
u-blox F9 interface description, signal identifiers)."""


@dataclass(frozen=True)
class RawxMeasurement:
    """One measurement of UBX-RXM-RAWX (one satellite, one signal).

    Attributes:
        gnss_id, sv_id, sig_id, freq_id: UBX identifiers (freq_id: GLONASS channel + 7).
        pseudorange_m: m; NaN when ``prValid`` is 0.
        carrier_phase_cycles: cycles; NaN when ``cpValid`` is 0.
        doppler_hz: Hz, positive for an approaching satellite (as RINEX).
        cn0_dbhz: dB-Hz (integer as reported).
        lock_time_s: carrier-phase lock time, s (capped at 64.5 s by the receiver).
        pseudorange_std_m: 0.01 * 2**prStdev, m.
        carrier_phase_std_cycles: 0.004 * cpStdev, cycles (NaN when cpStdev = 15: invalid).
        doppler_std_hz: 0.002 * 2**doStdev, Hz.
        pr_valid, cp_valid, half_cycle_resolved, half_cycle_subtracted: trkStat bits 0-3.
    """

    gnss_id: int
    sv_id: int
    sig_id: int
    freq_id: int
    pseudorange_m: float
    carrier_phase_cycles: float
    doppler_hz: float
    cn0_dbhz: float
    lock_time_s: float
    pseudorange_std_m: float
    carrier_phase_std_cycles: float
    doppler_std_hz: float
    pr_valid: bool
    cp_valid: bool
    half_cycle_resolved: bool
    half_cycle_subtracted: bool

    @property
    def satellite_id(self) -> str | None:
        """RINEX 3 satellite id ("G05", "E11", "S23" for SBAS PRN 123), None if not representable."""
        letter = GNSS_LETTERS.get(self.gnss_id)
        if letter is None:
            return None
        number = self.sv_id - 100 if letter == "S" else self.sv_id
        if letter == "J" and number > 10:
            number -= 192  # QZSS PRN 193.. reported as svId 193..
        if not 1 <= number <= 99:
            return None
        return f"{letter}{number:02d}"


@dataclass(frozen=True)
class RawxEpoch:
    """One UBX-RXM-RAWX message.

    Attributes:
        week: continuous GPS week of the receive time.
        tow_s: receive time of week (receiver local time), s.
        leap_seconds: GPS - UTC, s, as the receiver reports it; ``leap_seconds_valid`` its flag.
        clock_reset: recStat clkReset (receiver clock reset: phase and lock times restart).
        measurements: every measurement of the message, in message order.
    """

    week: int
    tow_s: float
    leap_seconds: int
    leap_seconds_valid: bool
    clock_reset: bool
    measurements: tuple[RawxMeasurement, ...]


def _num(msg: Any, name: str, default: float = math.nan) -> Any:
    return getattr(msg, name, default)


def rawx_from_message(msg: Any) -> RawxEpoch:
    """Decode a pyubx2 UBX-RXM-RAWX message (fields with the ``_NN`` suffix per measurement)."""
    meas = []
    for i in range(1, int(msg.numMeas) + 1):
        s = f"_{i:02d}"
        pr_valid = bool(_num(msg, "prValid" + s, 0))
        cp_valid = bool(_num(msg, "cpValid" + s, 0))
        cp_std = int(_num(msg, "cpStd" + s, 15))
        meas.append(RawxMeasurement(
            gnss_id=int(_num(msg, "gnssId" + s)),
            sv_id=int(_num(msg, "svId" + s)),
            sig_id=int(_num(msg, "sigId" + s, 0)),
            freq_id=int(_num(msg, "freqId" + s, 0)),
            pseudorange_m=float(_num(msg, "prMes" + s)) if pr_valid else math.nan,
            carrier_phase_cycles=float(_num(msg, "cpMes" + s)) if cp_valid else math.nan,
            doppler_hz=float(_num(msg, "doMes" + s)),
            cn0_dbhz=float(_num(msg, "cno" + s)),
            lock_time_s=float(_num(msg, "locktime" + s)) / 1000.0,
            pseudorange_std_m=0.01 * 2.0 ** int(_num(msg, "prStd" + s, 15)),
            carrier_phase_std_cycles=0.004 * cp_std if cp_std != 15 else math.nan,
            doppler_std_hz=0.002 * 2.0 ** int(_num(msg, "doStd" + s, 15)),
            pr_valid=pr_valid,
            cp_valid=cp_valid,
            half_cycle_resolved=bool(_num(msg, "halfCyc" + s, 0)),
            half_cycle_subtracted=bool(_num(msg, "subHalfCyc" + s, 0)),
        ))
    return RawxEpoch(
        week=int(msg.week),
        tow_s=float(msg.rcvTow),
        leap_seconds=int(_num(msg, "leapS", 0)),
        leap_seconds_valid=bool(_num(msg, "leapSec", 0)),
        clock_reset=bool(_num(msg, "clkReset", 0)),
        measurements=tuple(meas),
    )


def rawx_to_observations(rawx: RawxEpoch) -> tuple[RinexObsEpoch, int]:
    """RINEX 3 observables of one RAWX epoch, for :class:`GnssEpochBuilder`.

    Returns:
        ``(epoch, n_unmapped)``: satellite id -> {``C``/``L``/``D``/``S`` + signal code: value}
        (pseudorange m, phase cycles, Doppler Hz, C/N0 dB-Hz; invalid values NaN), and the
        number of measurements whose constellation or signal has no RINEX code here.
    """
    obs: dict[str, dict[str, float]] = {}
    unmapped = 0
    for m in rawx.measurements:
        code = RINEX_CODES.get((m.gnss_id, m.sig_id))
        sat = m.satellite_id
        if code is None or sat is None:
            unmapped += 1
            continue
        values = obs.setdefault(sat, {})
        values["C" + code] = m.pseudorange_m
        values["L" + code] = m.carrier_phase_cycles
        values["D" + code] = m.doppler_hz
        values["S" + code] = m.cn0_dbhz
    epoch = RinexObsEpoch(gps_week=rawx.week, tow_s=rawx.tow_s, epoch_flag=0,
                          receiver_clock_offset_s=math.nan, observations=obs, line_no=0)
    return epoch, unmapped


def observation_without_ephemeris(sat: str, values: dict[str, float], rawx: RawxEpoch,
                                  params: MeasurementBuilderParams) -> SatelliteObservation:
    """The measurement of a satellite without a usable ephemeris, with NaN satellite states:
    the observables the builder would take (same tracking attribute, picked by
    :func:`gnss_common.observation_codes.select_signal`; same C/N0 bounds), the Doppler rate on
    the signal's carrier (GLONASS: the channel of the RAWX freqId; NaN when unknown). All NaN when
    no attribute of the signal's band has a pseudorange."""
    system = sat[0]
    signal = params.signals[system]
    selected = select_signal(values, signal)
    pr = selected.pseudorange_m if selected is not None else math.nan
    cn0 = selected.cn0_dbhz if selected is not None else math.nan
    doppler = selected.doppler_hz if selected is not None else math.nan
    freq = signal.carrier_frequency_hz
    if system == "R":
        freq = next((glonass_g1_frequency_hz(m.freq_id - 7) for m in rawx.measurements
                     if m.gnss_id == 6 and m.pseudorange_m == pr and 0 <= m.freq_id <= 13), math.nan)
    rate = -(SPEED_OF_LIGHT_MPS / freq) * doppler
    nan3 = np.full(3, math.nan)
    return SatelliteObservation(
        constellation=CONSTELLATION_CODES[system], svid=int(sat[1:]), pseudorange_m=pr,
        pseudorange_rate_mps=rate, cn0_dbhz=cn0 if 0.0 < cn0 < 100.0 else math.nan,
        satellite_position_ecef_m=nan3, satellite_velocity_ecef_mps=nan3.copy(), satellite_clock_bias_m=math.nan,
        satellite_clock_drift_mps=math.nan, ionosphere_delay_m=math.nan, troposphere_delay_m=math.nan,
        carrier_frequency_hz=freq)

