"""rfi_msgs <-> the integrity core's plain types (no rclpy: message classes only).

The node calls these to turn its inputs into :mod:`gnss_integrity.monitor` inputs and an
:class:`~gnss_integrity.monitor.IntegrityReport` into an rfi_msgs/GnssIntegrity. A test checks that
the core's constants (:mod:`gnss_integrity.outcome`) equal the messages'.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gnss_integrity.monitor import IntegrityReport
from gnss_integrity.receiver_agc import ReceiverInterferenceReport
from gnss_integrity.receiver_spectrum import SpectrumInput
from rfi_msgs.msg import GnssIntegrity, IntegrityTest, ReceiverInterference, ReceiverSpectrum
from rfi_node_common.stamps import ns_to_stamp, stamp_to_ns


def _float(value: Any) -> float:
    return float(value) if value is not None else math.nan


def receiver_report(msg: ReceiverInterference) -> ReceiverInterferenceReport:
    """A ReceiverInterference message as the core's report (NaN and 0 where the message says unknown)."""
    return ReceiverInterferenceReport(
        stamp_ns=stamp_to_ns(msg.header.stamp), source=int(msg.source), rf_block_id=int(msg.rf_block_id),
        jamming_state=int(msg.jamming_state), jamming_detection_enabled=bool(msg.jamming_detection_enabled),
        jam_indicator=_float(msg.jam_indicator), agc_count=_float(msg.agc_count),
        noise_per_ms=_float(msg.noise_per_ms), antenna_status=int(msg.antenna_status),
        antenna_power=int(msg.antenna_power), spoofing_state=int(msg.spoofing_state),
        spoofing_detection_enabled=bool(msg.spoofing_detection_enabled))


def spectrum_input(msg: ReceiverSpectrum) -> SpectrumInput:
    """A ReceiverSpectrum message as the core's input.

    Raises:
        ValueError: non-finite bins or frequencies (``SpectrumInput`` validates).
    """
    return SpectrumInput(np.asarray(msg.power_db, dtype=float), float(msg.center_frequency_hz),
                         float(msg.span_hz), float(msg.resolution_hz), float(msg.pga_gain_db),
                         int(msg.rf_block_id))


def report_to_msg(report: IntegrityReport, frame_id: str) -> GnssIntegrity:
    """An IntegrityReport as rfi_msgs/GnssIntegrity (stamped with the GNSS epoch's stamp)."""
    msg = GnssIntegrity()
    msg.header.stamp = ns_to_stamp(report.stamp_ns)
    msg.header.frame_id = frame_id
    msg.jamming_state = int(report.jamming_state)
    msg.jammer_to_signal_db = float(report.jammer_to_signal_db)
    msg.jammer_to_signal_std_db = float(report.jammer_to_signal_std_db)
    msg.jammer_to_signal_is_lower_bound = bool(report.jammer_to_signal_is_lower_bound)
    msg.jamming_evidence = int(report.jamming_evidence)
    msg.cn0_elevation_model_in_use = bool(report.cn0_elevation_model_in_use)
    msg.cn0_drop_db = float(report.cn0_drop_db)
    msg.satellites_with_cn0 = min(int(report.satellites_with_cn0), 65535)
    msg.jammer_type = int(report.jammer_type)
    msg.jammer_frequency_hz = float(report.jammer_frequency_hz)
    msg.jammer_bandwidth_hz = float(report.jammer_bandwidth_hz)
    msg.spoofing_state = int(report.spoofing_state)
    msg.spoofing_scope = int(report.spoofing_scope)
    msg.affected_constellations = [int(c) for c in report.affected_constellations]
    msg.affected_satellite_constellations = [int(c) for c, _ in report.affected_satellites]
    msg.affected_svids = [int(s) for _, s in report.affected_satellites]
    if report.first_alarm_ns > 0:
        msg.first_alarm_stamp = ns_to_stamp(report.first_alarm_ns)
    if report.first_detection_ns > 0:
        msg.first_detection_stamp = ns_to_stamp(report.first_detection_ns)
    msg.tests = [IntegrityTest(name=o.name, category=int(o.category), decision=int(o.decision),
                               statistic=float(o.statistic), suspect_threshold=float(o.suspect_threshold),
                               alarm_threshold=float(o.alarm_threshold),
                               false_alarm_probability=float(o.false_alarm_probability), unit=o.unit)
                 for o in report.tests]
    return msg
