"""Round trips between the gnss_common dataclasses and the rfi_msgs / geometry_msgs messages."""

from __future__ import annotations

import math
from dataclasses import fields, replace

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message

from gnss_common.observations import GALILEO, GPS, GnssEpoch, SatelliteObservation, UwbRangeMeasurement
from rfi_msgs.msg import GnssMeasurementArray, UwbRange
from rfi_node_common.conversions import (
    epoch_to_msg,
    msg_to_epoch,
    msg_to_point,
    msg_to_uwb,
    point_to_msg,
    uwb_to_msg,
)


def _obs(rng: np.random.Generator, constellation: int, svid: int, **kw) -> SatelliteObservation:
    base = dict(
        constellation=constellation,
        svid=svid,
        pseudorange_m=float(rng.uniform(2.0e7, 2.6e7)),
        pseudorange_rate_mps=float(rng.normal(0.0, 500.0)),
        cn0_dbhz=float(rng.uniform(30.0, 50.0)),
        satellite_position_ecef_m=rng.normal(0.0, 1.5e7, 3),
        satellite_velocity_ecef_mps=rng.normal(0.0, 3.0e3, 3),
        satellite_clock_bias_m=float(rng.normal(0.0, 1.0e4)),
        satellite_clock_drift_mps=float(rng.normal(0.0, 1.0e-3)),
        ionosphere_delay_m=float(rng.uniform(1.0, 10.0)),
        troposphere_delay_m=float(rng.uniform(2.0, 20.0)),
        pseudorange_std_m=float(rng.uniform(1.0, 5.0)),
        pseudorange_rate_std_mps=float(rng.uniform(0.05, 0.5)),
    )
    base.update(kw)
    return SatelliteObservation(**base)


def _same_float(a: float, b: float) -> bool:
    """Bitwise float equality (NaN equals NaN, -0.0 differs from 0.0)."""
    return np.float64(a).tobytes() == np.float64(b).tobytes()


def _assert_obs_identical(a: SatelliteObservation, b: SatelliteObservation) -> None:
    for f in fields(SatelliteObservation):
        va, vb = getattr(a, f.name), getattr(b, f.name)
        if isinstance(va, np.ndarray):
            assert np.asarray(va, dtype=float).tobytes() == np.asarray(vb, dtype=float).tobytes(), f.name
        elif isinstance(va, float):
            assert isinstance(vb, float) and _same_float(va, vb), f.name
        else:
            assert va == vb and type(vb) is int, f.name


@pytest.fixture
def epoch() -> GnssEpoch:
    rng = np.random.default_rng(20240601)
    obs = (
        _obs(rng, GPS, 5),
        _obs(rng, GPS, 12, cn0_dbhz=math.nan, pseudorange_std_m=math.nan, pseudorange_rate_mps=math.nan),
        _obs(rng, GALILEO, 5, ionosphere_delay_m=-0.0,
             satellite_velocity_ecef_mps=np.array([np.nan, 1.0, 2.0])),
        _obs(rng, GPS, 32, pseudorange_m=2.1234567890123456e7, satellite_clock_bias_m=5e-324),
    )
    return GnssEpoch(stamp_ns=1_121_385_617_123_456_789, gps_week=1854, gps_time_of_week_s=17.123456789,
                     observations=obs)


def test_epoch_round_trip_is_bit_exact_with_nan(epoch: GnssEpoch) -> None:
    msg = epoch_to_msg(epoch)
    assert msg.header.frame_id == "earth"
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1_121_385_617, 123_456_789)
    back = msg_to_epoch(msg)
    assert back.stamp_ns == epoch.stamp_ns and type(back.stamp_ns) is int
    assert back.gps_week == epoch.gps_week and _same_float(back.gps_time_of_week_s, epoch.gps_time_of_week_s)
    assert len(back.observations) == len(epoch.observations)
    for a, b in zip(epoch.observations, back.observations, strict=True):
        _assert_obs_identical(a, b)


def test_epoch_survives_cdr_serialisation(epoch: GnssEpoch) -> None:
    """What a bag or a subscriber receives converts back to the same epoch."""
    raw = serialize_message(epoch_to_msg(epoch))
    back = msg_to_epoch(deserialize_message(raw, GnssMeasurementArray))
    for a, b in zip(epoch.observations, back.observations, strict=True):
        _assert_obs_identical(a, b)
    assert back.stamp_ns == epoch.stamp_ns


def test_message_fields_are_the_dataclass_fields(epoch: GnssEpoch) -> None:
    """Every field of GnssMeasurement is carried, so a new message field cannot be silently dropped."""
    msg = epoch_to_msg(epoch)
    msg_fields = set(msg.measurements[0].get_fields_and_field_types())
    assert msg_fields == {f.name for f in fields(SatelliteObservation)}
    m = msg.measurements[1]
    assert m.constellation == GPS and m.svid == 12 and math.isnan(m.cn0_dbhz)


def test_empty_epoch_round_trip() -> None:
    epoch = GnssEpoch(stamp_ns=0, gps_week=0, gps_time_of_week_s=0.0)
    back = msg_to_epoch(epoch_to_msg(epoch))
    assert back == epoch


def test_epoch_to_msg_rejects_bad_input(epoch: GnssEpoch) -> None:
    with pytest.raises(ValueError, match="negative stamp"):
        epoch_to_msg(replace(epoch, stamp_ns=-1))
    with pytest.raises(ValueError, match="integer number of ns"):
        epoch_to_msg(replace(epoch, stamp_ns=1.5e18))
    with pytest.raises(ValueError, match="gps_week"):
        epoch_to_msg(replace(epoch, gps_week=70000))
    with pytest.raises(ValueError, match="appears twice"):
        epoch_to_msg(replace(epoch, observations=epoch.observations + epoch.observations[:1]))
    bad_shape = replace(epoch.observations[0], satellite_position_ecef_m=np.zeros(2))
    with pytest.raises(ValueError, match=r"satellite_position_ecef_m must have shape \(3,\)"):
        epoch_to_msg(replace(epoch, observations=(bad_shape,)))
    with pytest.raises(ValueError, match="svid"):
        epoch_to_msg(replace(epoch, observations=(replace(epoch.observations[0], svid=-3),)))


def test_msg_to_epoch_rejects_wrong_frame_and_duplicates(epoch: GnssEpoch) -> None:
    msg = epoch_to_msg(epoch, frame_id="map")
    with pytest.raises(ValueError, match="expected 'earth'"):
        msg_to_epoch(msg)
    assert msg_to_epoch(msg, expected_frame_id=None).stamp_ns == epoch.stamp_ns
    msg = epoch_to_msg(epoch)
    msg.measurements = list(msg.measurements) + [msg.measurements[0]]
    with pytest.raises(ValueError, match="appears twice"):
        msg_to_epoch(msg)


def test_uwb_round_trip_is_exact() -> None:
    meas = UwbRangeMeasurement(stamp_ns=1_734_501_485_318_213_939, anchor_id="A12",
                               anchor_position_m=np.array([0.69, 0.87, -0.0]), frame_id="map",
                               range_m=6.053687, range_std_m=math.nan)
    msg = uwb_to_msg(meas, rssi_dbm=-78.99)
    assert msg.header.frame_id == "map" and msg.anchor_id == "A12" and msg.rssi_dbm == -78.99
    back = msg_to_uwb(deserialize_message(serialize_message(msg), UwbRange))
    assert back.stamp_ns == meas.stamp_ns and back.anchor_id == meas.anchor_id and back.frame_id == "map"
    assert back.anchor_position_m.tobytes() == meas.anchor_position_m.tobytes()
    assert back.range_m == meas.range_m and math.isnan(back.range_std_m)
    assert math.isnan(uwb_to_msg(meas).rssi_dbm)


def test_uwb_to_msg_rejects_bad_input() -> None:
    meas = UwbRangeMeasurement(stamp_ns=5, anchor_id="1", anchor_position_m=np.zeros(3), frame_id="map",
                               range_m=3.0)
    with pytest.raises(ValueError, match="anchor_position_m"):
        uwb_to_msg(replace(meas, anchor_position_m=np.zeros((3, 1))))
    with pytest.raises(ValueError, match="anchor_id"):
        uwb_to_msg(replace(meas, anchor_id=7))
    with pytest.raises(ValueError, match="negative stamp"):
        uwb_to_msg(replace(meas, stamp_ns=-5))


def test_point_round_trip() -> None:
    xyz = np.array([-740289.918, -5457071.734, 3207245.542])
    msg = point_to_msg(1_121_385_600_000_000_000, xyz, "earth")
    stamp_ns, back, frame = msg_to_point(msg)
    assert stamp_ns == 1_121_385_600_000_000_000 and frame == "earth"
    assert back.tobytes() == xyz.tobytes()
    with pytest.raises(ValueError, match="position_m"):
        point_to_msg(0, np.zeros(4), "map")


def test_uwb_range_cdr_decoder_equals_rclpy():
    from rclpy.serialization import serialize_message

    from rfi_node_common.conversions import decode_uwb_range_cdr

    rng = np.random.default_rng(12)
    for k in range(200):
        msg = UwbRange()
        msg.header.stamp.sec = int(rng.integers(0, 2**31 - 1))
        msg.header.stamp.nanosec = int(rng.integers(0, 10**9))
        msg.header.frame_id = "earth"[: int(rng.integers(0, 6))] + "é" * int(rng.integers(0, 2))
        msg.anchor_id = "A" * int(rng.integers(0, 12))
        msg.anchor_position.x, msg.anchor_position.y, msg.anchor_position.z = rng.normal(0, 1e6, 3).tolist()
        msg.range_m = float(rng.uniform(0, 100)) if k % 7 else math.nan
        msg.range_std_m = math.nan if k % 3 == 0 else float(rng.uniform(0, 1))
        msg.rssi_dbm = -math.inf if k % 5 == 0 else -80.0
        raw = serialize_message(msg)
        stamp_ns, frame, meas = decode_uwb_range_cdr(raw)
        ref = msg_to_uwb(msg)
        assert (stamp_ns, frame) == (ref.stamp_ns, msg.header.frame_id)
        assert (meas.stamp_ns, meas.anchor_id, meas.frame_id) == (ref.stamp_ns, ref.anchor_id, ref.frame_id)
        np.testing.assert_array_equal(meas.anchor_position_m, ref.anchor_position_m)
        np.testing.assert_array_equal([meas.range_m, meas.range_std_m], [ref.range_m, ref.range_std_m])
        # the node's frame map: a known frame is renamed, an unknown one gives no measurement
        _, _, mapped = decode_uwb_range_cdr(raw, {msg.header.frame_id: "core"})
        assert mapped is not None and mapped.frame_id == "core"
        assert decode_uwb_range_cdr(raw, {})[2] is None
        # cut short anywhere, or big-endian: declined (the node then uses rclpy, which reports it)
        assert decode_uwb_range_cdr(raw[: int(rng.integers(0, len(raw) - 8))]) is None
        assert decode_uwb_range_cdr(b"\x00\x00" + raw[2:]) is None


def _fuzzed_uwb_payloads(seed: int, count: int):
    """Seeded byte strings around a serialised UwbRange: random bytes, bit flips, overwritten bytes,
    truncations and extensions, absurd string lengths."""
    from rclpy.serialization import serialize_message

    msg = UwbRange()
    msg.header.stamp.sec, msg.header.frame_id, msg.anchor_id = 1_700_000_000, "earth", "A1"
    msg.anchor_position.x, msg.range_m, msg.range_std_m = 6.4e6, 12.0, math.nan
    raw = serialize_message(msg)
    rng = np.random.default_rng(seed)
    yield b""
    yield b"\x00\x01\x00\x00"
    yield b"\x00\x01\x00\x00" + b"\xff" * 12   # string length 2^32 - 1
    for n in range(len(raw) + 1):
        yield raw[:n]
    for at in (8, 20):  # payload offsets of the frame_id and anchor_id lengths: every small length
        for n in range(16):
            changed = bytearray(raw)
            changed[4 + at:8 + at] = n.to_bytes(4, "little")
            yield bytes(changed)
    for k in range(count):
        kind = k % 4
        if kind == 0:
            yield rng.integers(0, 256, int(rng.integers(0, 160)), dtype=np.uint8).tobytes()
        elif kind == 1:
            flipped = bytearray(raw)
            for _ in range(int(rng.integers(1, 4))):
                flipped[int(rng.integers(0, len(raw)))] ^= 1 << int(rng.integers(0, 8))
            yield bytes(flipped)
        elif kind == 2:
            changed = bytearray(raw)
            changed[int(rng.integers(0, len(raw)))] = int(rng.integers(0, 256))
            yield bytes(changed[: int(rng.integers(0, len(raw) + 16))]) + b"\x00" * int(rng.integers(0, 9))
        else:
            at = int(rng.choice([8, 20]))  # a string length: frame_id or anchor_id
            changed = bytearray(raw)
            changed[4 + at:8 + at] = int(rng.integers(0, 2**32)).to_bytes(4, "little")
            yield bytes(changed)


def test_uwb_range_cdr_decoder_never_raises_and_agrees_with_rclpy_on_fuzzed_bytes():
    """Any byte string: the decoder returns None or a well-formed result, never raises; whenever
    rclpy deserialises the same bytes, the two agree field for field."""
    from rclpy.serialization import deserialize_message

    from rfi_node_common.conversions import decode_uwb_range_cdr

    decoded = 0
    for raw in _fuzzed_uwb_payloads(seed=2024, count=4000):
        out = decode_uwb_range_cdr(raw)
        assert (decode_uwb_range_cdr(raw, {"earth": "earth"}) is None) == (out is None)
        if out is None:
            continue
        decoded += 1
        stamp_ns, frame, meas = out
        assert isinstance(stamp_ns, int) and isinstance(frame, str) and meas is not None
        assert meas.anchor_position_m.shape == (3,) and isinstance(meas.range_m, float)
        msg = deserialize_message(raw, UwbRange)  # what the decoder takes, rclpy takes too
        ref = msg_to_uwb(msg)
        assert (stamp_ns, frame, meas.anchor_id) == (ref.stamp_ns, msg.header.frame_id, ref.anchor_id)
        assert np.asarray(meas.anchor_position_m).tobytes() == ref.anchor_position_m.tobytes()
        assert _same_float(meas.range_m, ref.range_m) and _same_float(meas.range_std_m, ref.range_std_m)
    assert decoded > 500
