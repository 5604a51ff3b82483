"""Checks and decoding of an ``rfi_msgs/IfSamples`` block, shared by every node that reads the front end's
stream (rfi_monitor, gnss_correlator): pure, no rclpy. The checks, their order and the physical ranges they
enforce are documented in :mod:`rfi_monitor.block_io` (the monitor's conversions, where they first lived);
each returns a ``rejected_<reason>`` key.
"""

from __future__ import annotations

import numpy as np

from rfi_msgs.msg import IfSamples
from rfi_node_common.stamps import peek_header_stamp_ns

SAMPLE_RATE_MIN_HZ = 1.0e5
"""Lowest sample rate accepted, Hz (module docstring: a GNSS band needs >= ~1 MS/s)."""
SAMPLE_RATE_MAX_HZ = 1.0e11
"""Highest sample rate accepted, Hz (beyond any direct-RF sampler)."""
SCALE_MIN = 1.0e-12
"""Smallest volts (or full-scale units) per count accepted (module docstring)."""
SCALE_MAX = 1.0e3
"""Largest volts (or full-scale units) per count accepted (module docstring)."""
CENTER_FREQUENCY_MAX_HZ = 1.0e11
"""Highest RF reference frequency accepted, Hz (GNSS bands are 1.1-2.5 GHz; 100 GHz leaves room for any band)."""
MAX_SAMPLE_INDEX = 2 ** 53
"""first_sample_index + samples may not exceed this: the core's sample positions are float64, exact to 2^53."""

SAMPLE_WIDTH_BYTES: dict[int, int] = {IfSamples.INT8: 1, IfSamples.INT16: 2}
"""IfSamples.sample_format -> bytes per stored value."""

SAMPLE_DTYPES: dict[int, np.dtype] = {IfSamples.INT8: np.dtype('<i1'), IfSamples.INT16: np.dtype('<i2')}
"""IfSamples.sample_format -> numpy dtype of the stored values (little-endian)."""

def check_block(msg: IfSamples, min_block_samples: int, max_block_samples: int = 2 ** 31 - 1) -> str | None:
    """Why an IF block cannot be analysed (a ``rejected_<reason>`` key), or None if it is well formed.

    Checks the fields only (module docstring, in that order); :func:`is_blank` checks the values.

    Args:
        msg: rfi_msgs/IfSamples.
        min_block_samples, max_block_samples: shortest and longest block, samples (complex: I/Q pairs).
    """
    width = SAMPLE_WIDTH_BYTES.get(msg.sample_format)
    if width is None:
        return 'unknown_sample_format'
    if not 1 <= msg.bits_per_sample <= 8 * width:
        return 'bad_bits_per_sample'
    fs = msg.sample_rate_hz
    if not SAMPLE_RATE_MIN_HZ <= fs <= SAMPLE_RATE_MAX_HZ:   # False for NaN
        return 'bad_sample_rate'
    nyquist = fs if msg.is_complex else fs / 2.0
    if not abs(msg.intermediate_frequency_hz) < nyquist:
        return 'bad_intermediate_frequency'
    if not SCALE_MIN <= msg.scale <= SCALE_MAX:
        return 'bad_scale'
    if not 0.0 <= msg.center_frequency_hz <= CENTER_FREQUENCY_MAX_HZ:
        return 'bad_center_frequency'
    if len(msg.samples) == 0:
        return 'empty_block'
    if len(msg.samples) % width:
        return 'truncated_sample'
    values = len(msg.samples) // width
    if msg.is_complex and values % 2:
        return 'odd_length_iq'
    n = values // (2 if msg.is_complex else 1)
    if n < min_block_samples:
        return 'short_block'
    if n > max_block_samples:
        return 'long_block'
    if msg.first_sample_index + n > MAX_SAMPLE_INDEX:
        return 'bad_first_sample_index'
    return None


def peek_stamp_ns(raw: bytes) -> int | None:
    """header.stamp of a serialised IfSamples in ns, read from its first bytes (little-endian CDR: a 4-byte
    encapsulation header, then stamp.sec int32 and stamp.nanosec uint32), or None if the bytes do not look
    like that (the message is then deserialised and checked as usual). The reading is
    :func:`rfi_node_common.stamps.peek_header_stamp_ns`, shared with ``play``."""
    return peek_header_stamp_ns(raw)


def decode_counts(msg: IfSamples) -> np.ndarray:
    """The block's stored values (counts), read only: int8 or int16, shape (n,) real or (2n,) I, Q."""
    return np.frombuffer(msg.samples, dtype=SAMPLE_DTYPES[msg.sample_format])


def is_blank(counts: np.ndarray, is_complex: bool) -> bool:
    """True if the block has no variation: every value equal (real), or every I and every Q equal."""
    if not is_complex:
        return bool(counts.min() == counts.max())
    i, q = counts[0::2], counts[1::2]
    return bool(i.min() == i.max() and q.min() == q.max())


def count_range(bits: int) -> tuple[int, int]:
    """(lowest, highest) count a front end of ``bits`` bits per real value can deliver: two's complement
    ``[-2**(bits-1), 2**(bits-1) - 1]`` for bits >= 4; odd sign/magnitude levels ``+-(2**bits - 1)`` for 1-3 bits
    (MAX2769-type: 2 bits are +-1, +-3), which also holds a 1-3 bit two's-complement front end's values."""
    if bits < 4:
        return -(2 ** bits - 1), 2 ** bits - 1
    return -(2 ** (bits - 1)), 2 ** (bits - 1) - 1


def exceeds_bits(counts: np.ndarray, bits: int) -> bool:
    """True if a stored value lies outside :func:`count_range` of the declared ``bits_per_sample`` (issue 27 item
    3: a 16-bit container declaring 8 bits with values to +-32767 is malformed, not a clipped block). Values
    that fill their container (8 bits in INT8, 16 in INT16) cannot exceed it."""
    lo, hi = count_range(bits)
    info = np.iinfo(counts.dtype)
    if lo <= info.min and hi >= info.max:
        return False
    return bool(counts.min() < lo or counts.max() > hi)
