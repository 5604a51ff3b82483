"""Plain UBX decoder records -> ROS messages (no rclpy: message classes only), shared by
``ubx_to_bag`` and the ``ubx_source`` node."""

from __future__ import annotations

import math

from rfi_experiments.ubx_reports import InterferenceReport, SpectrumReport
from rfi_msgs.msg import ReceiverInterference, ReceiverSpectrum
from rfi_node_common.stamps import ns_to_stamp


def _f32(value: float) -> float:
    return float(value) if math.isfinite(value) else math.nan


def report_to_msg(report: InterferenceReport, frame_id: str) -> ReceiverInterference:
    """``rfi_msgs/ReceiverInterference`` of one :class:`InterferenceReport` (field for field)."""
    msg = ReceiverInterference()
    msg.header.stamp = ns_to_stamp(report.stamp_ns)
    msg.header.frame_id = frame_id
    msg.gps_week = int(report.gps_week)
    msg.gps_time_of_week_s = float(report.gps_time_of_week_s)
    msg.source = int(report.source)
    msg.rf_block_id = int(report.rf_block_id)
    msg.jamming_state = int(report.jamming_state)
    msg.jamming_detection_enabled = bool(report.jamming_detection_enabled)
    msg.jam_indicator = _f32(report.jam_indicator)
    msg.agc_count = _f32(report.agc_count)
    msg.noise_per_ms = _f32(report.noise_per_ms)
    msg.antenna_status = int(report.antenna_status)
    msg.antenna_power = int(report.antenna_power)
    msg.spoofing_state = int(report.spoofing_state)
    msg.spoofing_detection_enabled = bool(report.spoofing_detection_enabled)
    return msg


def spectrum_to_msg(report: SpectrumReport, frame_id: str) -> ReceiverSpectrum:
    """``rfi_msgs/ReceiverSpectrum`` of one :class:`SpectrumReport` (one RF block, field for field)."""
    msg = ReceiverSpectrum()
    msg.header.stamp = ns_to_stamp(report.stamp_ns)
    msg.header.frame_id = frame_id
    msg.gps_week = int(report.gps_week)
    msg.gps_time_of_week_s = float(report.gps_time_of_week_s)
    msg.rf_block_id = int(report.rf_block_id)
    msg.center_frequency_hz = float(report.center_frequency_hz)
    msg.span_hz = float(report.span_hz)
    msg.resolution_hz = float(report.resolution_hz)
    msg.pga_gain_db = _f32(report.pga_gain_db)
    msg.power_db = [float(v) for v in report.power_db]
    return msg
