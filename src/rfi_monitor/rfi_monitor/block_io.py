"""The node's message conversions (pure: no rclpy): an ``rfi_msgs/IfSamples`` block checked and decoded before the
core sees it, the core's estimate encoded as an ``rfi_msgs/JammerState``.

Checks, in this order (``rejected_<reason>``), with the physical ranges they enforce:

* ``unknown_sample_format``; ``bad_bits_per_sample`` (outside 1..16, or above 8 for INT8);
* ``bad_sample_rate``: not in [SAMPLE_RATE_MIN_HZ, SAMPLE_RATE_MAX_HZ] = [1e5, 1e11] Hz (a GNSS
  signal needs at least ~1 MS/s, direct-RF samplers stay below 100 GS/s; at a tiny rate the
  periodicity analysis, one per ``analysis_hop_s``, would run once per sample);
* ``bad_intermediate_frequency``: not finite, or |IF| at or beyond the Nyquist band (fs/2 real,
  fs complex);
* ``bad_scale``: not in [SCALE_MIN, SCALE_MAX] = [1e-12, 1e3] V/count. Every real front end fits:
  a 16-bit ADC with 1 V full scale has 3e-5 V/count, a front end reporting full-scale units 1/2^(bits-1)
  or counts 1.0. 1e-12 V/count would put a 16-bit full scale at 33 nV, below the thermal noise of any
  input stage (about 0.6 uV rms over 2 MHz at 50 ohm); no ADC has a count of 1 kV. Within the range
  the block's power (count * scale)^2 is a normal double and fits the single-precision Welch FFT;
  outside it (5e-324, 1e150, 1e308) it underflows to zero or overflows;
* ``bad_center_frequency``: not finite, negative or above CENTER_FREQUENCY_MAX_HZ = 1e11 Hz (0 is
  accepted for a stream referenced to its IF);
* ``empty_block``, ``truncated_sample`` (INT16 with an odd byte count), ``odd_length_iq``,
  ``short_block`` (fewer samples than ``min_block_samples``), ``long_block`` (more than
  ``max_block_samples``: bounds memory and the time one callback takes);
* ``bad_first_sample_index``: ``first_sample_index + samples`` beyond 2^53 (the core keeps
  absolute sample positions in float64, exact only up to 2^53: 7.5 years at 38.192 MS/s);
* ``values_exceed_bits``: a stored value outside what ``bits_per_sample`` can hold (:func:`count_range`: two's
  complement for 4-16 bits, odd levels up to +-(2**bits - 1) for 1-3 bits), e.g. an INT16 block declaring 8 bits
  with values to +-32767 (issue 27 item 3): malformed, not analysed as a clipped block;
* ``blank_block``: every sample equal (real), or every I and every Q equal (complex): a block
  with no variation (all zero, a stuck ADC) carries no information about a jammer;
* from the core (``JammerEstimate.rejection``): ``non_finite`` (more than ``max_invalid_fraction``
  of the samples not finite; clipped blocks are analysed, issue 14), ``blank_block`` (no power in the
  analysed Welch frames),
  ``power_overflow``, ``below_noise_floor`` (10 dB below the calibrated noise floor) and
  ``implausible_power`` (120 dB above it): gain or scale no longer match the calibration, see
  rfi_monitor.monitor;
* ``core_error``: the core raised on a block that passed the checks; ``node_error``: the node's own
  checks raised (both bugs, logged as errors, and the diagnostics are ERROR).

Saturation: full scale is ``(2**(bits_per_sample - 1) - 1) * scale`` for two's-complement front ends
(bits >= 4). A clipped block is analysed: its clipped fraction is in the JammerState and in /diagnostics
(``last_clipped_fraction``, ``core.clipped_blocks``, ``core.saturated_samples``), its J/N flagged as a lower
bound above ``clip_lower_bound_fraction``. For 1-3 bit sign/magnitude front ends the largest level is a
normal value (a 2-bit front end puts about a third of its samples there), so no saturation check is made.

Output policy (one decision, applied to every block):

* Exactly one JammerState per block that the core *analysed* (``JammerEstimate.valid``): header
  copied from the block (stamp = time of its first sample, frame_id of the front end), frequencies
  relative to the block's ``center_frequency_hz`` (the core converts from the IF), NaN where the
  core does not know a value. While the noise floor is being learned the core reports UNKNOWN
  (confidence 0.5, NaNs); that is published, since it is what the monitor knows.
* Nothing for a rejected block: malformed or physically impossible blocks (checked here before the
  core sees them) and blocks the core refuses to analyse (``valid`` False). An invalid estimate is
  therefore never on the topic, and in particular a block that carries no information (blank,
  absurd scale) never gives "NONE, confidence 1"; a consumer that needs the monitor's status reads
  /diagnostics or notices the missing state. Each rejection is counted as ``rejected_<reason>`` and
  gives one warning, throttled to ``warning_throttle_s``.
"""

from __future__ import annotations

import numpy as np

from rfi_monitor.estimate import JammerEstimate
from rfi_msgs.msg import IfSamples, JammerState
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


def decode_samples(msg: IfSamples) -> np.ndarray:
    """The block's values in volts: float64, shape (n,) real or (2n,) interleaved I, Q.

    ``msg`` must have passed :func:`check_block`. Values are ``count * scale``.
    """
    return decode_counts(msg).astype(np.float64) * msg.scale


def full_scale(msg: IfSamples) -> float | None:
    """Largest magnitude of the front end, V: (2**(bits - 1) - 1) * scale for bits >= 4, else None
    (odd-level 1-3 bit quantisers reach their top level in normal operation)."""
    if msg.bits_per_sample < 4:
        return None
    return float((2 ** (msg.bits_per_sample - 1) - 1) * msg.scale)


def jammer_state_msg(est: JammerEstimate, block: IfSamples) -> JammerState:
    """JammerEstimate -> rfi_msgs/JammerState (header and center frequency from the block).

    float32 fields are rounded to float32 here, so the message is the same whether a subscriber gets
    it over the wire or in-process (rclpy keeps a Python float's float64 value until serialisation).
    """
    m = JammerState()
    m.header = block.header
    m.type = int(est.type)
    m.confidence = float(np.float32(est.confidence))
    m.jammer_to_noise_db = float(est.jammer_to_noise_db)
    m.jammer_to_signal_db = float(est.jammer_to_signal_db)
    m.frequency_hz = float(est.frequency_hz)
    m.frequency_std_hz = float(est.frequency_std_hz)
    m.sweep_rate_hz_per_s = float(est.sweep_rate_hz_per_s)
    m.sweep_period_s = float(est.sweep_period_s)
    m.sweep_start_frequency_hz = float(est.sweep_start_frequency_hz)
    m.sweep_bandwidth_hz = float(est.sweep_bandwidth_hz)
    m.center_frequency_hz = float(block.center_frequency_hz)
    m.sample_rate_hz = float(est.sample_rate_hz)
    m.noise_reference = int(est.noise_reference)
    m.jammer_to_noise_is_lower_bound = bool(est.jammer_to_noise_is_lower_bound)
    m.clipped_fraction = float(np.float32(est.clipped_fraction))
    m.sweep_shape = int(est.sweep_shape)
    m.in_band_fraction = float(np.float32(est.in_band_fraction))
    return m
