"""The rfi_msgs contract: every field documented with a comment, Header first, types importable."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
from ament_index_python.packages import get_package_share_directory

MSG_DIR = Path(get_package_share_directory('rfi_msgs')) / 'msg'
MESSAGES = sorted(p.stem for p in MSG_DIR.glob('*.msg'))
FIELD = re.compile(r'^\s*([A-Za-z0-9_/]+(\[\d*\])?)\s+([a-z][a-z0-9_]*)\s*(=.*)?$')


def fields(name: str) -> list[tuple[str, str, str]]:
    """(type, name, comment) of each field line of a .msg file (constants excluded)."""
    out = []
    for line in (MSG_DIR / f'{name}.msg').read_text().splitlines():
        code, _, comment = line.partition('#')
        match = FIELD.match(code)
        if match and not match.group(4) and not match.group(3).isupper():
            out.append((match.group(1), match.group(3), comment.strip()))
    return out


def test_all_messages_present():
    assert set(MESSAGES) >= {'IfSamples', 'JammerState', 'GnssMeasurement', 'GnssMeasurementArray', 'UwbRange',
                             'Correlator', 'CorrelatorArray', 'CarrierPhase', 'CarrierPhaseArray', 'FusionStatus'}


@pytest.mark.parametrize('name', MESSAGES)
def test_every_field_has_a_comment(name):
    undocumented = [f for _, f, comment in fields(name) if not comment]
    assert not undocumented, f'{name}: fields without unit/meaning comment: {undocumented}'


NOT_HEADED = ('GnssMeasurement', 'Correlator', 'CarrierPhase', 'IntegrityTest')
"""Messages used only as elements of an array message (no header of their own)."""


@pytest.mark.parametrize('name', [m for m in MESSAGES if m not in NOT_HEADED])
def test_header_first(name):
    assert fields(name)[0][:2] == ('std_msgs/Header', 'header')


CONTRACT = {
    'IfSamples': ['sample_rate_hz', 'intermediate_frequency_hz', 'center_frequency_hz', 'is_complex',
                  'first_sample_index', 'scale', 'samples'],
    'JammerState': ['type', 'confidence', 'jammer_to_noise_db', 'jammer_to_signal_db', 'frequency_hz',
                    'frequency_std_hz', 'sweep_rate_hz_per_s', 'sweep_period_s', 'sweep_start_frequency_hz',
                    'sweep_bandwidth_hz'],
    'GnssMeasurement': ['constellation', 'svid', 'pseudorange_m', 'pseudorange_rate_mps', 'cn0_dbhz',
                        'satellite_position_ecef_m', 'satellite_velocity_ecef_mps', 'satellite_clock_bias_m',
                        'satellite_clock_drift_mps', 'ionosphere_delay_m', 'troposphere_delay_m',
                        'pseudorange_std_m', 'pseudorange_rate_std_mps'],
    'GnssMeasurementArray': ['gps_time_of_week_s', 'gps_week', 'measurements'],
    'UwbRange': ['anchor_id', 'anchor_position', 'range_m', 'range_std_m'],
    'Correlator': ['svid', 'integration_time_s', 'in_phase', 'quadrature', 'cn0_dbhz', 'predicted_phase_change_rad',
                   'carrier_lock'],
    'CarrierPhase': ['svid', 'phase_rad', 'phase_std_rad', 'frequency_hz', 'frequency_std_hz', 'data_bit',
                     'data_bit_probability', 'mode_probabilities', 'locked', 'method'],
    'FusionStatus': ['satellites_used', 'satellites_rejected', 'uwb_used', 'uwb_rejected',
                     'normalized_innovation_squared', 'clock_bias_m', 'clock_drift_mps'],
}


@pytest.mark.parametrize('name', sorted(CONTRACT))
def test_contract_fields_present(name):
    present = {f for _, f, _ in fields(name)}
    assert set(CONTRACT[name]) <= present, set(CONTRACT[name]) - present


def test_constants_and_python_types():
    from imm_carrier import measurement_model
    from rfi_msgs.msg import CarrierPhase, Correlator, GnssMeasurement, IfSamples, JammerState

    assert [JammerState.NONE, JammerState.CW, JammerState.CHIRP, JammerState.WIDEBAND, JammerState.UNKNOWN] == \
        [0, 1, 2, 3, 4]
    assert {CarrierPhase.IMM, CarrierPhase.PLL, CarrierPhase.KF} == {1, 2, 3}
    assert GnssMeasurement.GPS == 1
    # a Correlator that does not set its lock says UNKNOWN; imm_carrier's codes are the message's
    assert Correlator().carrier_lock == Correlator.CARRIER_LOCK_UNKNOWN == measurement_model.CORRELATOR_LOCK_UNKNOWN
    assert (Correlator.CARRIER_LOCK_LOST, Correlator.CARRIER_LOCK_HELD) == (
        measurement_model.CORRELATOR_LOCK_LOST, measurement_model.CORRELATOR_LOCK_HELD)
    assert IfSamples.INT8 != IfSamples.INT16
    msg = GnssMeasurement(pseudorange_std_m=math.nan)
    assert math.isnan(msg.pseudorange_std_m)
    assert len(msg.satellite_position_ecef_m) == 3


def test_constellation_codes_match_the_pure_dataclasses():
    from gnss_common import observations
    from rfi_msgs.msg import GnssMeasurement

    for name in ('GPS', 'GLONASS', 'GALILEO', 'BEIDOU', 'QZSS', 'SBAS'):
        assert getattr(GnssMeasurement, name) == getattr(observations, name)
