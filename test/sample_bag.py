"""A small bag of every rfi_msgs input type, written by the tests themselves (seeded)."""

from __future__ import annotations

import math

import numpy as np

from rfi_experiments.bag_io import BagWriter
from rfi_msgs.msg import (
    Correlator,
    CorrelatorArray,
    GnssMeasurement,
    GnssMeasurementArray,
    IfSamples,
    JammerState,
    UwbRange,
)
from rfi_node_common.stamps import ns_to_stamp

START_NS = 1_700_000_000_000_000_000


def write_sample_bag(path, *, seconds: float = 2.0, seed: int = 1) -> dict[str, int]:
    """Write IF blocks (10 Hz), GNSS epochs (5 Hz), UWB ranges (20 Hz), correlators (50 Hz) and
    jammer states (10 Hz) over ``seconds``; return the count per topic."""
    rng = np.random.default_rng(seed)
    with BagWriter(path, overwrite=True) as bag:
        events = []
        for k in range(int(seconds * 10)):
            events.append((START_NS + k * 100_000_000, 'if', k))
            events.append((START_NS + k * 100_000_000 + 1, 'jam', k))
        for k in range(int(seconds * 5)):
            events.append((START_NS + k * 200_000_000 + 7, 'gnss', k))
        for k in range(int(seconds * 20)):
            events.append((START_NS + k * 50_000_000 + 3, 'uwb', k))
        for k in range(int(seconds * 50)):
            events.append((START_NS + k * 20_000_000 + 5, 'corr', k))
        for stamp_ns, kind, k in sorted(events):
            if kind == 'if':
                m = IfSamples(sample_rate_hz=4e6, intermediate_frequency_hz=0.0, center_frequency_hz=1575.42e6,
                              is_complex=True, first_sample_index=k * 4000, scale=1.0 / 127, bits_per_sample=8,
                              sample_format=IfSamples.INT8)
                m.header.stamp = ns_to_stamp(stamp_ns)
                m.header.frame_id = 'front_end'
                m.samples = rng.integers(-128, 128, 8000, dtype=np.int16).astype(np.int8).tobytes()
                bag.write('/rfi/if_samples', m, stamp_ns)
            elif kind == 'jam':
                m = JammerState(type=JammerState.CHIRP, confidence=0.9, jammer_to_noise_db=12.0,
                                jammer_to_signal_db=28.0, frequency_hz=float(rng.normal(0, 1e6)),
                                frequency_std_hz=1e3, sweep_rate_hz_per_s=1e12, sweep_period_s=8.6e-6,
                                sweep_start_frequency_hz=-5e6, sweep_bandwidth_hz=math.nan,
                                center_frequency_hz=1575.42e6, sample_rate_hz=4e6)
                m.header.stamp = ns_to_stamp(stamp_ns)
                bag.write('/rfi/jammer_state', m, stamp_ns)
            elif kind == 'gnss':
                m = GnssMeasurementArray(gps_week=2358, gps_time_of_week_s=100.0 + 0.2 * k)
                m.header.stamp = ns_to_stamp(stamp_ns)
                m.header.frame_id = 'earth'
                for svid in (3, 7, 12, 19, 25):
                    g = GnssMeasurement(constellation=GnssMeasurement.GPS, svid=svid,
                                        pseudorange_m=2.1e7 + rng.normal(0, 1e5),
                                        pseudorange_rate_mps=float(rng.normal(0, 500)), cn0_dbhz=45.0,
                                        satellite_clock_bias_m=float(rng.normal(0, 1e4)),
                                        satellite_clock_drift_mps=0.01,
                                        ionosphere_delay_m=3.0, troposphere_delay_m=2.4,
                                        pseudorange_std_m=math.nan, pseudorange_rate_std_mps=math.nan)
                    g.satellite_position_ecef_m = rng.normal(0, 2e7, 3)
                    g.satellite_velocity_ecef_mps = rng.normal(0, 3e3, 3)
                    m.measurements.append(g)
                bag.write('/gnss/measurements', m, stamp_ns)
            elif kind == 'uwb':
                m = UwbRange(anchor_id=f'A{k % 3}', range_m=10 + rng.random(), range_std_m=0.05, rssi_dbm=math.nan)
                m.header.stamp = ns_to_stamp(stamp_ns)
                m.header.frame_id = 'map'
                m.anchor_position.x, m.anchor_position.y, m.anchor_position.z = (float(v) for v in rng.normal(0, 10, 3))
                bag.write('/uwb/ranges', m, stamp_ns)
            else:
                m = CorrelatorArray()
                m.header.stamp = ns_to_stamp(stamp_ns)
                for svid in (3, 7):
                    m.correlators.append(Correlator(constellation=1, svid=svid, integration_time_s=0.02,
                                                    in_phase=float(rng.normal()), quadrature=float(rng.normal()),
                                                    cn0_dbhz=45.0, predicted_phase_change_rad=0.1))
                bag.write('/gnss/correlators', m, stamp_ns)
        return dict(bag.counts)
