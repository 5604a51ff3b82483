"""The shared parameter check of the tests' false-alarm probabilities (gnss_integrity.outcome)."""

from __future__ import annotations

import pytest

from gnss_integrity.cn0_jamming import Cn0JammingParams
from gnss_integrity.cn0_spoofing import Cn0SpoofingParams
from gnss_integrity.kinematics_test import KinematicsTestParams
from gnss_integrity.outcome import check_false_alarm_probabilities
from gnss_integrity.receiver_agc import ReceiverAgcParams
from gnss_integrity.uwb_range_rate import UwbRangeRateParams

PARAMS = (Cn0JammingParams, Cn0SpoofingParams, KinematicsTestParams, ReceiverAgcParams, UwbRangeRateParams)


@pytest.mark.parametrize('params_cls', PARAMS)
@pytest.mark.parametrize('suspect, alarm', [(1e-3, 1e-2), (0.5, 1e-3), (1e-3, 0.0), (1e-3, -1e-4)])
def test_each_test_refuses_an_alarm_probability_out_of_order(params_cls, suspect, alarm):
    with pytest.raises(ValueError, match=f'{params_cls.__name__}: need 0 < alarm_false_alarm_probability'):
        params_cls(false_alarm_probability=suspect, alarm_false_alarm_probability=alarm)


@pytest.mark.parametrize('params_cls', PARAMS)
def test_equal_probabilities_are_accepted(params_cls):
    params = params_cls(false_alarm_probability=1e-3, alarm_false_alarm_probability=1e-3)
    check_false_alarm_probabilities(params)
    assert params.alarm_false_alarm_probability == params.false_alarm_probability == 1e-3
