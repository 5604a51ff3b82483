"""The node's publish path: CorrelatorArrays serialised with numpy (gnss_correlator.correlator_cdr) are, byte for
byte, what rclpy serialises from the message built field by field (gnss_correlator.correlator_cdr.correlator_array), for
every alignment of the frame id, 0 to 14 channels, NaN / infinite / extreme values and every carrier-lock code:
the same length, every field's value equal bit for bit (Fast CDR leaves its buffer's old bytes in the padding,
the codec zeros), and rclpy decodes the bytes to the message."""

from __future__ import annotations

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message

from gnss_correlator.correlator_cdr import CorrelatorArrayWriter, correlator_array, correlator_array_bytes
from gnss_correlator.receiver import CorrelatorInterval
from rfi_msgs.msg import CorrelatorArray, GnssMeasurement
from rfi_node_common.cdr import layout

LAYOUT = layout(CorrelatorArray)


def interval(rng: np.random.Generator, n: int, stamp_ns: int) -> CorrelatorInterval:
    """An interval of n channels with values that exercise the fields (NaN lock std: carrier_lock UNKNOWN)."""
    def values() -> np.ndarray:
        v = rng.normal(scale=10.0 ** rng.uniform(-300, 300), size=n)
        special = rng.integers(0, 8, size=n)
        v[special == 0] = np.nan
        v[special == 1] = np.inf
        v[special == 2] = -np.inf
        v[special == 3] = -0.0
        return v

    std = rng.uniform(0.0, 1.0, size=n)
    std[rng.integers(0, 3, size=n) == 0] = np.nan
    return CorrelatorInterval(
        stamp_ns=stamp_ns, svid=rng.choice(np.arange(1, 38), size=n, replace=False).astype(np.int64),
        in_phase=values(), quadrature=values(), cn0_dbhz=values(), predicted_phase_change_rad=values(),
        integration_time_s=rng.choice([1e-3, 0.02, 0.000999755859375], size=n), locked=rng.integers(0, 2, n) > 0,
        phase_error_std_rad=std, half_cycle_wraps=np.zeros(n), pll_error_rad=np.zeros(n),
        cn0_m2m4_dbhz=np.zeros(n))


@pytest.mark.parametrize('frame_id', ['', 'a', 'ab', 'abc', 'abcd', 'gnss_receiver', 'front_end_1', 'räume'])
def test_bytes_equal_rclpy_serialisation_of_the_message_built_field_by_field(frame_id):
    rng = np.random.default_rng(29)
    writer = CorrelatorArrayWriter(frame_id)
    for n in range(15):
        for stamp_ns in (0, 1_700_000_000_123_456_789, (2 ** 31 - 1) * 1_000_000_000 + 999_999_999):
            iv = interval(rng, n, stamp_ns)
            msg = correlator_array(iv, frame_id)
            raw = correlator_array_bytes(iv, writer)
            ref = serialize_message(msg)
            # the same length and every field's value (the codec's streams: integers, float64 bit patterns,
            # the frame id's text); the padding is zero here, Fast CDR's buffer's old bytes there
            assert len(raw) == len(ref)
            ours, theirs = LAYOUT.decode(raw), LAYOUT.decode(ref)
            assert ours is not None and theirs is not None
            assert np.array_equal(ours.ints, theirs.ints) and ours.ints[3] == len(frame_id.encode())
            assert np.array_equal(ours.floats.view(np.int64), theirs.floats.view(np.int64)), (n, stamp_ns)
            assert raw[ours.ints[2]:ours.ints[2] + ours.ints[3]] == frame_id.encode()
            a, b = np.frombuffer(raw, np.uint8), np.frombuffer(ref, np.uint8)
            assert not a[a != b].any()  # where the bytes differ, ours are zero: padding
            back = deserialize_message(raw, CorrelatorArray)
            assert back.header == msg.header and len(back.correlators) == n
            assert all(b.constellation == GnssMeasurement.GPS for b in back.correlators)


def test_values_outside_the_fields_are_refused():
    writer = CorrelatorArrayWriter('x')
    ok = dict(stamp_ns=1, constellation=1, svid=np.array([3]), floats=np.zeros((1, 5)), carrier_lock=np.array([2]))
    assert deserialize_message(writer.serialize(**ok), CorrelatorArray).correlators[0].svid == 3
    for bad, match in (({'svid': np.array([70000])}, 'uint16'), ({'carrier_lock': np.array([-1])}, 'uint8'),
                       ({'floats': np.zeros((1, 4))}, 'shapes'), ({'svid': np.array([3, 4])}, 'shapes'),
                       ({'constellation': 256}, 'constellation'), ({'stamp_ns': 2 ** 31 * 10 ** 9}, 'int32'),
                       ({'stamp_ns': -1}, 'int32')):
        with pytest.raises(ValueError, match=match):
            writer.serialize(**(ok | bad))
