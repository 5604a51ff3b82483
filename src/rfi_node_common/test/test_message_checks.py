"""The nodes' plausibility checks (message_checks, shared by fusion_node and gnss_integrity_node): every bound, both
sides, and real values pass."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from gnss_common.observations import GPS, SatelliteObservation, UwbRangeMeasurement
from rfi_node_common import message_checks as mc

ARL1_ECEF_M = np.array([-740289.9, -5457071.7, 3207245.5])


def _range(**kw) -> UwbRangeMeasurement:
    base = dict(stamp_ns=1, anchor_id='A1', anchor_position_m=ARL1_ECEF_M + 10.0, frame_id='earth', range_m=12.0,
                range_std_m=math.nan)
    base.update(kw)
    return UwbRangeMeasurement(**base)


def _satellite(**kw) -> SatelliteObservation:
    """Values as in bags/default and bags/arl1_jammed (real broadcast ephemeris)."""
    base = dict(constellation=GPS, svid=5, pseudorange_m=2.2e7, pseudorange_rate_mps=-420.0, cn0_dbhz=44.0,
                satellite_position_ecef_m=np.array([1.5e7, -2.0e7, 0.8e7]),
                satellite_velocity_ecef_mps=np.array([-1200.0, 2500.0, 1500.0]), satellite_clock_bias_m=186820.3,
                satellite_clock_drift_mps=0.0015, ionosphere_delay_m=9.0, troposphere_delay_m=13.2)
    base.update(kw)
    return SatelliteObservation(**base)


def test_valid_values_pass():
    assert mc.uwb_range_reason(_range()) is None
    assert mc.uwb_range_reason(_range(range_std_m=0.05)) is None
    assert mc.uwb_range_reason(_range(range_std_m=mc.UWB_RANGE_STD_MAX_M)) is None
    assert mc.uwb_range_reason(_range(frame_id='map', anchor_position_m=np.array([5e5, 4.2e6, 30.0]))) is None
    assert mc.satellite_reason(_satellite()) is None
    assert mc.satellite_reason(_satellite(cn0_dbhz=math.nan, pseudorange_std_m=3.0,
                                          pseudorange_rate_std_mps=0.1)) is None


@pytest.mark.parametrize('std', [-math.inf, math.inf, 0.0, -0.0, -1.0, 100.0001, 1e300, 5e-324, 9e-7])
def test_uwb_range_std_only_nan_means_default(std):
    assert mc.uwb_range_reason(_range(range_std_m=std)) == 'invalid_range_std'


@pytest.mark.parametrize('frame, position', [
    ('earth', [0.0, 0.0, 0.0]), ('earth', [1e300, 0.0, 0.0]), ('earth', [5.9e6, 0.0, 0.0]),
    ('earth', [7.1e6, 0.0, 0.0]), ('map', [0.0, 0.0, 1.1e7]), ('map', [-1e300, 0.0, 0.0]),
])
def test_uwb_anchor_off_the_earth_or_beyond_any_local_frame(frame, position):
    meas = _range(frame_id=frame, anchor_position_m=np.array(position))
    assert mc.uwb_range_reason(meas) == 'nonphysical_anchor_position'


@pytest.mark.parametrize('frame', ['earth', 'map'])
def test_uwb_nonfinite_anchor_is_rejected(frame):
    """The integrity monitor checks no anchor: the node must (the fusion's core counts the same reason)."""
    for bad in (math.nan, math.inf, -math.inf):
        meas = _range(frame_id=frame, anchor_position_m=np.array([1.0, bad, 2.0]))
        assert mc.uwb_range_reason(meas) == 'nonfinite_anchor_position'


@pytest.mark.parametrize('range_m, reason', [
    (math.nan, 'nonfinite_range'), (math.inf, 'nonfinite_range'), (-math.inf, 'nonfinite_range'),
    (-3.0, 'negative_range'), (-5e-324, 'negative_range'), (0.0, 'range_too_short'), (5e-324, 'range_too_short'),
    (9.99e-4, 'range_too_short'), (10000.001, 'range_too_long'), (1e300, 'range_too_long'),
])
def test_uwb_range_outside_the_limits_is_rejected(range_m, reason):
    """The limits 1 mm - 10 km, applied by both nodes (issue 27: the fuzzer's 1e300 and 5e-324 made the integrity
    monitor's residuals infinite; the fusion's core applied 5e-324 as a valid range)."""
    assert mc.uwb_range_reason(_range(range_m=range_m)) == reason
    assert mc.uwb_range_reason(_range(frame_id='map', anchor_position_m=np.array([5.0, 3.0, 2.0]),
                                      range_m=range_m)) == reason


@pytest.mark.parametrize('range_m', [mc.UWB_RANGE_MIN_M, 0.3, 499.0, 2000.0, mc.UWB_RANGE_MAX_M])
def test_uwb_range_at_or_inside_the_limits_passes(range_m):
    """Both limits are inclusive; a range beyond the fusion's ``uwb_max_range_m`` is its core's to count."""
    assert mc.uwb_range_reason(_range(range_m=range_m)) is None


@pytest.mark.parametrize('fields, reason', [
    ({'cn0_dbhz': math.inf}, 'nonphysical_cn0'), ({'cn0_dbhz': -math.inf}, 'nonphysical_cn0'),
    ({'cn0_dbhz': 100.5}, 'nonphysical_cn0'),
    ({'pseudorange_std_m': -math.inf}, 'invalid_measurement_std'),
    ({'pseudorange_std_m': 0.0}, 'invalid_measurement_std'),
    ({'pseudorange_std_m': -2.0}, 'invalid_measurement_std'), ({'pseudorange_std_m': 2e4}, 'invalid_measurement_std'),
    ({'pseudorange_rate_std_mps': math.inf}, 'invalid_measurement_std'),
    ({'pseudorange_rate_std_mps': 0.0}, 'invalid_measurement_std'),
    ({'pseudorange_rate_std_mps': 2e3}, 'invalid_measurement_std'),
    ({'satellite_velocity_ecef_mps': np.array([1e300, 0.0, 0.0])}, 'nonphysical_satellite_state'),
    ({'satellite_velocity_ecef_mps': np.array([8e3, 8e3, 0.0])}, 'nonphysical_satellite_state'),
    ({'satellite_clock_bias_m': 1e300}, 'nonphysical_satellite_state'),
    ({'satellite_clock_bias_m': -1.1e8}, 'nonphysical_satellite_state'),
    ({'satellite_clock_drift_mps': 1e9}, 'nonphysical_satellite_state'),
    ({'ionosphere_delay_m': 1e6}, 'nonphysical_atmospheric_delay'),
    ({'troposphere_delay_m': 1.1e3}, 'nonphysical_atmospheric_delay'),
])
def test_satellite_with_an_impossible_value_is_dropped(fields, reason):
    assert mc.satellite_reason(_satellite(**fields)) == reason


@pytest.mark.parametrize('fields', [
    {'satellite_velocity_ecef_mps': np.array([math.nan, 0.0, 0.0])}, {'satellite_clock_drift_mps': math.inf},
    {'satellite_clock_bias_m': math.nan}, {'ionosphere_delay_m': math.inf}, {'pseudorange_m': math.nan},
])
def test_nonfinite_values_are_left_to_the_core(fields):
    """The core counts them (nonfinite_pseudorange, invalid_doppler): no second reason for one fault."""
    assert mc.satellite_reason(_satellite(**fields)) is None


def test_reasons_are_listed():
    sat = _satellite()
    seen = {mc.satellite_reason(replace(sat, cn0_dbhz=math.inf)),
            mc.satellite_reason(replace(sat, pseudorange_std_m=-1.0)),
            mc.satellite_reason(replace(sat, satellite_clock_bias_m=1e9)),
            mc.satellite_reason(replace(sat, troposphere_delay_m=1e9))}
    assert seen == set(mc.SATELLITE_REASONS)
    uwb = [_range(range_std_m=-1.0), _range(anchor_position_m=np.array([math.nan, 0.0, 0.0])),
           _range(anchor_position_m=np.zeros(3)), _range(range_m=math.nan), _range(range_m=-1.0),
           _range(range_m=1e-4), _range(range_m=1e5)]
    assert [mc.uwb_range_reason(m) for m in uwb] == list(mc.UWB_REASONS)


@pytest.mark.parametrize('field, std', [('pseudorange_std_m', 5e-324), ('pseudorange_std_m', 9e-4),
                                        ('pseudorange_rate_std_mps', 5e-324), ('pseudorange_rate_std_mps', 9e-5)])
def test_a_subnormal_or_sub_millimetre_std_is_a_corrupt_field(field, std):
    """The fuzzer's 5e-324 squared to 0 in the core (a singular noise matrix, a counted core exception): such stds are
    dropped at the node, at or below a floor no receiver reaches (1 mm, 0.1 mm/s); stds above it pass."""
    values = {'pseudorange_std_m': 3.0, 'pseudorange_rate_std_mps': 0.1, field: std}
    assert mc.satellite_reason(_satellite(cn0_dbhz=math.nan, **values)) == 'invalid_measurement_std'
    values[field] = 2e-3 if field == 'pseudorange_std_m' else 2e-4
    assert mc.satellite_reason(_satellite(cn0_dbhz=math.nan, **values)) is None
