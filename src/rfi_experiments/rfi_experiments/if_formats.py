"""Raw GNSS front-end samples (capture files, SDR streams) -> blocks of integer counts for rfi_msgs/IfSamples.

The one reader behind ``if_source`` (node) and ``if_to_bag`` (tool). Pure: no rclpy, no wall clock
(the callers pass the times in), no ROS messages (the callers build them from :class:`IfBlock`).

Item types (``item_type``; the names of GNSS-SDR's file signal sources where GNSS-SDR has one):

============================  ========  ====================================================  ============
item_type                     complex   bytes on disk                                         stored as
============================  ========  ====================================================  ============
``byte``                      no        int8 per sample (PocketSDR ``-I`` files)              INT8
``ibyte`` (``cbyte``)         yes       int8 I, int8 Q (PocketSDR IQ files, hackrf_transfer)  INT8
``short``                     no        int16 little-endian per sample                        INT16
``ishort`` (``cshort``)       yes       int16 LE I, int16 LE Q (UHD ``sc16``)                 INT16
``gr_complex``                yes       float32 LE I, float32 LE Q (GNU Radio complex64)      INT16
``uibyte``                    yes       uint8 I, uint8 Q, offset 127.5 (``rtl_sdr`` files)    INT16
``two_bit_packed``            both      four 2-bit samples per byte (GNSS-SDR, below)         INT8
``two_bit_packed_short``      both      eight 2-bit samples per 16-bit word (GNSS-SDR)        INT8
``four_bit_cpx``              yes       one I/Q pair per byte, 4 bits each (GNSS-SDR)         INT8
============================  ========  ====================================================  ============

Counts (what ``IfSamples.samples`` holds) are exact integers, never rescaled floats:

* ``byte``, ``ibyte``, ``short``, ``ishort``: the file's values, unchanged (``scale`` 1: volts = ADC counts
  unless the user gives a scale). PocketSDR stores its 2-bit values as int8 +-1, +-3 (set
  ``bits_per_sample`` 2).
* Mid-rise codes are stored as odd integers ``2 v + 1`` (half-LSB units), which removes the half-LSB DC
  offset of the code exactly and needs one more bit than the ADC; the default ``scale`` is then 0.5, so the
  decoded values are in ADC LSBs:

  - ``uibyte`` (rtl_sdr: unsigned 8-bit, zero at 127.5, as librtlsdr documents): count = ``2 u - 255``, odd in
    -255..255, INT16, ``bits_per_sample`` 9 (the monitor's full scale, ``(2**8 - 1) * scale``, is then the
    ADC's top code); decoded value ``u - 127.5``.
  - ``two_bit_packed`` / ``two_bit_packed_short``: GNSS-SDR's ``Two_Bit_Packed_File_Signal_Source``
    (``src/algorithms/signal_source/adapters/two_bit_packed_file_signal_source.cc`` and
    ``gnuradio_blocks/unpack_2bit_samples.cc``, C. O'Driscoll, GPL-3.0; layout only, no code taken): each
    byte holds four 2-bit two's-complement fields v in {-2, -1, 0, 1}, decoded as ``2 v + 1`` in
    {-3, -1, +1, +3}; with ``big_endian_bytes`` false (GNSS-SDR's default) the field in bits 1-0 is the first
    sample, then bits 3-2, 5-4, 7-6; true reverses that order. ``two_bit_packed_short`` reads 16-bit words,
    big-endian when ``big_endian_items`` (GNSS-SDR's default, true). ``sample_type`` real, iq (I first) or qi
    (Q first). ``bits_per_sample`` 2 (no saturation check in the monitor, as for PocketSDR's 2-bit data).
  - ``four_bit_cpx``: GNSS-SDR's ``Four_Bit_Cpx_File_Signal_Source`` (``gnuradio_blocks/
    unpack_byte_4bit_samples.cc``): the low nibble is I, the high nibble Q (``sample_type`` qi swaps them), each
    a 4-bit two's-complement v in -8..7 decoded as ``2 v + 1`` (odd, -15..15); ``bits_per_sample`` 5 (full
    scale 15 = the top code).
* ``gr_complex`` floats: count = ``round(value * float_counts_per_unit)``, INT16, and ``scale`` =
  ``1 / float_counts_per_unit``, so that ``count * scale`` is the file's float value whenever it is a whole
  number of counts. The default ``float_counts_per_unit`` 1 fits files whose floats are ADC counts, as
  GNSS-SDR's own short-to-complex conversion writes them (the CTTC 2012 USRP capture holds integers up to
  750); for floats normalised to +-1 (UHD ``fc32``, osmocom) use 32767. Values that had to be rounded
  (``rounded_values``), clipped to +-32767 (``clipped_values``) or were not finite (set to 0,
  ``non_finite_values``) are counted: the conversion is exact only when all three stay 0.

Spectral inversion (``spectral_inversion``: the RF spectrum is mirrored in the samples, high-side LO):
real samples keep their values and are published with a negative ``intermediate_frequency_hz`` (the
IfSamples convention the monitor reads); complex samples are published with I and Q swapped, ``Q + jI =
j conj(x)``, whose spectrum is upright (mirrored back, times a constant phase), and the IF becomes -IF.

Blocks: ``block_samples`` samples (complex: I/Q pairs) each, cut at sample boundaries; ``first_sample_index``
counts samples since the first one read and is continuous unless the caller declares a gap
(:meth:`BlockAssembler.skip`); the stamp of a block is ``start_ns + first_sample_index / fs`` (exact
rational arithmetic, rounded to the ns), so stamps never drift from the sample count.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import stat
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numpy as np

from gnss_common.constants import NS_PER_S
from rfi_node_common.params import USER, parameter

INT8 = 0
"""IfSamples.INT8 (samples holds int8 values); checked against rfi_msgs by the tests."""
INT16 = 1
"""IfSamples.INT16 (samples holds little-endian int16 values)."""

SAMPLE_RATE_MIN_HZ = 1.0e5
"""Lowest sampling_frequency_hz accepted (what rfi_monitor accepts; a GNSS band needs >= ~1 MS/s)."""
SAMPLE_RATE_MAX_HZ = 1.0e11
"""Highest sampling_frequency_hz accepted, Hz."""
CENTER_FREQUENCY_MAX_HZ = 1.0e11
"""Highest center_frequency_hz accepted, Hz."""
SCALE_MIN = 1.0e-12
"""Smallest scale accepted, V/count (rfi_monitor's range)."""
SCALE_MAX = 1.0e3
"""Largest scale accepted, V/count."""
MAX_BLOCK_SAMPLES = 2 ** 26
"""Longest block accepted, samples (about 67 M; rfi_monitor's own default limit is 2^22)."""
INT16_MAX = 32767
"""Largest |count| a gr_complex value is converted to (clipped symmetric, so that the negative of a count fits)."""


@dataclass(frozen=True)
class ItemType:
    """How one item type is laid out on disk and stored in IfSamples.

    Attributes:
        name: the ``item_type`` parameter value.
        is_complex: True for I/Q, False for real, None if ``sample_type`` decides (packed 2-bit).
        chunk_bytes: bytes of the smallest whole unit (real: per ``chunk_samples`` values).
        chunk_values: values (real samples, or I and Q counted separately) in one chunk.
        sample_format: INT8 or INT16, the storage type of the counts.
        bits_per_sample: default quantisation reported in IfSamples.bits_per_sample.
        scale: default volts (or LSB units) per count.
        description: one line for help texts.
    """

    name: str
    is_complex: bool | None
    chunk_bytes: int
    chunk_values: int
    sample_format: int
    bits_per_sample: int
    scale: float
    description: str


ITEM_TYPES: dict[str, ItemType] = {t.name: t for t in (
    ItemType('byte', False, 1, 1, INT8, 8, 1.0, 'int8 real (GNSS-SDR byte, PocketSDR I files)'),
    ItemType('ibyte', True, 2, 2, INT8, 8, 1.0, 'int8 I, Q interleaved (GNSS-SDR ibyte, PocketSDR IQ, hackrf)'),
    ItemType('cbyte', True, 2, 2, INT8, 8, 1.0, 'int8 I, Q (GNSS-SDR cbyte: same bytes as ibyte)'),
    ItemType('short', False, 2, 1, INT16, 16, 1.0, 'int16 little-endian real (GNSS-SDR short)'),
    ItemType('ishort', True, 4, 2, INT16, 16, 1.0, 'int16 LE I, Q interleaved (GNSS-SDR ishort, UHD sc16)'),
    ItemType('cshort', True, 4, 2, INT16, 16, 1.0, 'int16 LE I, Q (GNSS-SDR cshort: same bytes as ishort)'),
    ItemType('gr_complex', True, 8, 2, INT16, 16, 1.0, 'float32 LE I, Q (GNU Radio complex64), rounded to int16 '
             'counts after multiplying by float_counts_per_unit'),
    ItemType('uibyte', True, 2, 2, INT16, 9, 0.5, 'uint8 I, Q with zero at 127.5 (rtl_sdr), stored as 2u - 255'),
    ItemType('two_bit_packed', None, 1, 4, INT8, 2, 0.5, '2-bit two\'s-complement samples, four per byte '
             '(GNSS-SDR two_bit_packed_file_signal_source, item_type byte), stored as 2v + 1'),
    ItemType('two_bit_packed_short', None, 2, 8, INT8, 2, 0.5, '2-bit samples, eight per 16-bit word (GNSS-SDR '
             'two_bit_packed_file_signal_source, item_type short), stored as 2v + 1'),
    ItemType('four_bit_cpx', True, 1, 2, INT8, 5, 0.5, '4-bit I (low nibble) and Q (high nibble) per byte '
             '(GNSS-SDR four_bit_cpx_file_signal_source), stored as 2v + 1'),
)}
"""item_type -> layout (module docstring)."""

SAMPLE_TYPES = ('real', 'iq', 'qi')
"""sample_type values of the packed 2-bit types (GNSS-SDR's names); four_bit_cpx takes iq or qi."""


class FormatError(ValueError):
    """Format parameters that cannot describe a capture, or input that does not fit them; one-line message."""


def _finite(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise FormatError(f'{name} = {value} is not a finite number')
    return value


@dataclass(frozen=True)
class IfFormat:
    """What the bytes are: item type, rates and frequencies, as GNSS engineers name them.

    Args:
        item_type: one of :data:`ITEM_TYPES`.
        sampling_frequency_hz: samples per second (complex: I/Q pairs per second), in [1e5, 1e11].
        intermediate_frequency_hz: IF of the digitised signal as it appears in the samples, Hz: real samples
            in [0, fs/2), complex in (-fs/2, fs/2) (0: baseband).
        center_frequency_hz: RF frequency the samples are referenced to (the LO for complex baseband, the
            LO +- IF for a real IF), Hz, in [0, 1e11] (e.g. 1575.42e6).
        spectral_inversion: the RF spectrum is mirrored in the samples (module docstring).
        sample_type: packed types only: 'real', 'iq' or 'qi' ('' = real for two_bit_packed*, iq for four_bit_cpx).
        big_endian_bytes: two_bit_packed*: the first sample is in the two most significant bits.
        big_endian_items: two_bit_packed_short: the 16-bit words are big-endian.
        bits_per_sample: IfSamples.bits_per_sample; 0: the item type's default.
        scale: IfSamples.scale, volts (or full-scale units) per count; 0: the item type's default.
        float_counts_per_unit: gr_complex: counts per unit of the file's floats (> 0).

    The fields with a default are also parameters of if_source (and options of if_to_bag): default,
    description and range written here once (:func:`rfi_node_common.params.parameter`).
    """

    item_type: str
    sampling_frequency_hz: float
    intermediate_frequency_hz: float = parameter(
        0.0, 'IF of the signal as it appears in the samples, Hz: real in [0, fs/2), complex in (-fs/2, fs/2); 0 for '
        'complex baseband (PocketSDR 12 MHz real L1: 3000000.0).', minimum=-5.0e10, maximum=5.0e10, group=USER)
    center_frequency_hz: float = parameter(
        1575.42e6, 'RF frequency the samples are referenced to, Hz (GPS L1: 1575.42e6). The monitor reports jammer '
        'frequencies relative to it.', minimum=0.0, maximum=1.0e11, group=USER)
    spectral_inversion: bool = parameter(
        False, 'The RF spectrum is mirrored in the samples (high-side LO injection): real samples are published with '
        'a negative IF (the IfSamples convention), complex samples with I and Q swapped.', group=USER)
    sample_type: str = parameter(
        '', "Packed types only: real, iq or qi (GNSS-SDR's names); empty: real, four_bit_cpx: iq.",
        choices=('', 'real', 'iq', 'qi'))
    big_endian_bytes: bool = parameter(
        False, 'two_bit_packed*: the first sample of a byte is in its two most significant bits (GNSS-SDR: false).')
    big_endian_items: bool = parameter(
        True, "two_bit_packed_short: the 16-bit words are big-endian (GNSS-SDR's default: true).")
    bits_per_sample: int = parameter(
        0, "Quantisation reported in the message, bits; 0: the item type's (8 for int8, 16 for int16 and gr_complex, "
        "9 for uibyte, 2 for two_bit_packed, 5 for four_bit_cpx). PocketSDR's int8 files hold 2-bit values: set 2 "
        '(the monitor then makes no saturation check, as for any 1-3 bit front end).', minimum=0, maximum=16)
    scale: float = parameter(
        0.0, "Volts (or full-scale units) per stored count; 0: the item type's (1 for integer items, 0.5 for the "
        '2v+1 codes of uibyte and the packed types, 1/float_counts_per_unit for gr_complex).',
        minimum=0.0, maximum=1.0e3)
    float_counts_per_unit: float = parameter(
        1.0, "gr_complex: counts per unit of the file's floats. 1: the floats are ADC counts (GNSS-SDR's own "
        'short-to-complex conversion); 32767 for floats normalised to +-1 (UHD fc32, osmocom). Rounding, clipping '
        'to +-32767 and non-finite values are counted on /diagnostics.', minimum=1.0e-6, maximum=1.0e9)

    def __post_init__(self) -> None:
        item = ITEM_TYPES.get(self.item_type)
        if item is None:
            raise FormatError(f'unknown item_type {self.item_type!r}: one of {", ".join(ITEM_TYPES)}')
        fs = _finite('sampling_frequency_hz', self.sampling_frequency_hz)
        if not SAMPLE_RATE_MIN_HZ <= fs <= SAMPLE_RATE_MAX_HZ:
            raise FormatError(f'sampling_frequency_hz = {fs} is outside [{SAMPLE_RATE_MIN_HZ:g}, '
                              f'{SAMPLE_RATE_MAX_HZ:g}] Hz')
        packed = item.is_complex is None
        if self.sample_type and self.sample_type not in SAMPLE_TYPES:
            raise FormatError(f'sample_type {self.sample_type!r} is not one of {", ".join(SAMPLE_TYPES)}')
        if self.sample_type and not packed and self.item_type != 'four_bit_cpx':
            raise FormatError(f'sample_type applies to the packed item types only, not to {self.item_type} '
                              '(use spectral_inversion to swap I and Q)')
        if self.item_type == 'four_bit_cpx' and self.sample_type == 'real':
            raise FormatError('four_bit_cpx is complex: sample_type iq or qi')
        fif = _finite('intermediate_frequency_hz', self.intermediate_frequency_hz)
        if self.is_complex:
            if not abs(fif) < fs / 2:
                raise FormatError(f'intermediate_frequency_hz = {fif} Hz: |IF| must be below fs/2 = {fs / 2} Hz '
                                  'for complex samples')
        elif not 0.0 <= fif < fs / 2:
            raise FormatError(f'intermediate_frequency_hz = {fif} Hz must be in [0, fs/2 = {fs / 2}) Hz for real '
                              'samples (a mirrored spectrum is spectral_inversion, not a negative IF)')
        fc = _finite('center_frequency_hz', self.center_frequency_hz)
        if not 0.0 <= fc <= CENTER_FREQUENCY_MAX_HZ:
            raise FormatError(f'center_frequency_hz = {fc} Hz is outside [0, {CENTER_FREQUENCY_MAX_HZ:g}] Hz')
        width = 8 if item.sample_format == INT8 else 16
        if self.bits_per_sample and not 1 <= self.bits_per_sample <= width:
            raise FormatError(f'bits_per_sample = {self.bits_per_sample} must be in 1..{width} for {self.item_type} '
                              '(0: the item type\'s default)')
        scale = _finite('scale', self.scale)
        if scale and not SCALE_MIN <= scale <= SCALE_MAX:
            raise FormatError(f'scale = {scale} V/count is outside [{SCALE_MIN:g}, {SCALE_MAX:g}] (0: default)')
        k = _finite('float_counts_per_unit', self.float_counts_per_unit)
        if not 1e-6 <= k <= 1e9:
            raise FormatError(f'float_counts_per_unit = {k} is outside [1e-06, 1e+09]')
        if self.item_type == 'gr_complex' and not scale and not SCALE_MIN <= 1.0 / k <= SCALE_MAX:
            raise FormatError(f'scale 1/float_counts_per_unit = {1.0 / k} is outside [{SCALE_MIN:g}, {SCALE_MAX:g}]')

    @property
    def item(self) -> ItemType:
        return ITEM_TYPES[self.item_type]

    @property
    def is_complex(self) -> bool:
        """True for I/Q samples."""
        c = self.item.is_complex
        return (self.sample_type in ('iq', 'qi')) if c is None else c

    @property
    def values_per_sample(self) -> int:
        """Stored values per sample: 2 for complex (I, Q), 1 for real."""
        return 2 if self.is_complex else 1

    @property
    def chunk_bytes(self) -> int:
        """Bytes of the smallest whole number of samples."""
        return self.item.chunk_bytes

    @property
    def chunk_samples(self) -> int:
        """Samples in one chunk (complex: I/Q pairs)."""
        return self.item.chunk_values // self.values_per_sample

    @property
    def sample_format(self) -> int:
        return self.item.sample_format

    @property
    def published_bits_per_sample(self) -> int:
        return self.bits_per_sample or self.item.bits_per_sample

    @property
    def published_scale(self) -> float:
        if self.scale:
            return float(self.scale)
        if self.item_type == 'gr_complex':
            return 1.0 / float(self.float_counts_per_unit)
        return self.item.scale

    @property
    def published_intermediate_frequency_hz(self) -> float:
        """IF as IfSamples carries it: negated under spectral inversion (module docstring)."""
        fif = float(self.intermediate_frequency_hz)
        return -fif if self.spectral_inversion else fif

    @property
    def dtype(self) -> np.dtype:
        """numpy dtype of the stored counts."""
        return np.dtype('<i1') if self.sample_format == INT8 else np.dtype('<i2')

    def block_samples(self, block_duration_s: float) -> int:
        """Samples per block of ``block_duration_s`` (rounded to a whole number of samples, >= 1).

        Raises:
            FormatError: duration not finite and > 0, or beyond :data:`MAX_BLOCK_SAMPLES`.
        """
        d = _finite('block_duration_s', block_duration_s)
        n = round(d * float(self.sampling_frequency_hz)) if d > 0 else 0
        if n < 1:
            raise FormatError(f'block_duration_s = {d} s gives no whole sample at {self.sampling_frequency_hz} Hz')
        if n > MAX_BLOCK_SAMPLES:
            raise FormatError(f'block_duration_s = {d} s gives {n} samples per block, more than {MAX_BLOCK_SAMPLES}')
        return int(n)


def unpack(fmt: IfFormat, data: bytes | bytearray | memoryview | np.ndarray,
           counters: Counter[str] | None = None) -> np.ndarray:
    """Counts of whole chunks of raw bytes: int8 or int16, shape (n,) real or (2n,) interleaved I, Q.

    Args:
        fmt: the format.
        data: raw bytes, a whole number of ``fmt.chunk_bytes``.
        counters: gr_complex conversion counts are added here (``rounded_values``, ``clipped_values``,
            ``non_finite_values``).

    Raises:
        FormatError: ``data`` is not a whole number of chunks.
    """
    raw = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data.view(np.uint8).ravel()
    if raw.size % fmt.chunk_bytes:
        raise FormatError(f'{raw.size} bytes are not a whole number of {fmt.item_type} items '
                          f'({fmt.chunk_bytes} bytes each)')
    name = fmt.item_type
    out: np.ndarray
    if name in ('byte', 'ibyte', 'cbyte'):
        out = raw.view(np.int8).copy()
    elif name in ('short', 'ishort', 'cshort'):
        out = raw.view('<i2').astype(np.int16)
    elif name == 'uibyte':
        out = raw.astype(np.int16) * 2 - 255
    elif name == 'gr_complex':
        out = _floats_to_counts(raw.view('<f4'), float(fmt.float_counts_per_unit), counters)
    elif name in ('two_bit_packed', 'two_bit_packed_short'):
        out = _unpack_2bit(raw, fmt)
    elif name == 'four_bit_cpx':
        nib = np.empty(raw.size * 2, dtype=np.int16)
        nib[0::2] = raw & 0x0F
        nib[1::2] = raw >> 4
        v = np.where(nib >= 8, nib - 16, nib)
        out = (2 * v + 1).astype(np.int8)
        if fmt.sample_type == 'qi':
            out = _swap_iq(out)
    else:  # pragma: no cover - ITEM_TYPES and this table are kept together
        raise FormatError(f'no unpacker for item_type {name!r}')
    if fmt.spectral_inversion and fmt.is_complex:
        out = _swap_iq(out)
    return out


def _swap_iq(values: np.ndarray) -> np.ndarray:
    out = np.empty_like(values)
    out[0::2] = values[1::2]
    out[1::2] = values[0::2]
    return out


def _floats_to_counts(x: np.ndarray, k: float, counters: Counter[str] | None) -> np.ndarray:
    with np.errstate(invalid='ignore', over='ignore'):  # NaN / inf / overflow: counted below, not warned
        y = x.astype(np.float64) * k
    finite = np.isfinite(y)
    y = np.where(finite, y, 0.0)
    r = np.rint(y)
    clipped = np.clip(r, -INT16_MAX, INT16_MAX)
    if counters is not None:
        counters['non_finite_values'] += int(finite.size - np.count_nonzero(finite))
        counters['rounded_values'] += int(np.count_nonzero(r != y))
        counters['clipped_values'] += int(np.count_nonzero(clipped != r))
    return clipped.astype(np.int16)


def _unpack_2bit(raw: np.ndarray, fmt: IfFormat) -> np.ndarray:
    if fmt.item_type == 'two_bit_packed_short' and fmt.big_endian_items:
        raw = raw.reshape(-1, 2)[:, ::-1].ravel()  # big-endian words -> bytes in little-endian word order
    fields = np.empty((raw.size, 4), dtype=np.int16)
    for k in range(4):
        fields[:, k] = (raw >> (2 * k)) & 0x3
    if fmt.big_endian_bytes:
        fields = fields[:, ::-1]
    v = np.where(fields >= 2, fields - 4, fields)
    out = (2 * v + 1).astype(np.int8).ravel()
    if fmt.sample_type == 'qi':
        out = _swap_iq(out)
    return out


def parse_start_time(text: str) -> int:
    """A start time given by a user -> ns since 1970 UTC (ROS time).

    Accepts Unix seconds (``1638434820.5``) or ISO 8601 UTC (``2021-12-02T08:47:00Z``, ``2021-12-02 08:47:00``,
    ``...+00:00``; a time without zone is UTC; another offset is converted). Leap seconds are not counted, as in
    Unix and ROS time.

    Raises:
        FormatError: unreadable, or not after 1970-01-01 (a stamp must be > 0).
    """
    s = str(text).strip()
    try:
        ns = round(Fraction(s) * NS_PER_S)
    except (ValueError, ZeroDivisionError):
        try:
            t = _dt.datetime.fromisoformat(s[:-1] + '+00:00' if s.endswith(('Z', 'z')) else s)
        except ValueError:
            raise FormatError(f'start time {text!r} is neither Unix seconds nor ISO 8601 UTC '
                              '(e.g. 2021-12-02T08:47:00Z)') from None
        if t.tzinfo is None:
            t = t.replace(tzinfo=_dt.timezone.utc)
        delta = t - _dt.datetime(1970, 1, 1, tzinfo=_dt.timezone.utc)
        ns = (delta.days * 86400 + delta.seconds) * NS_PER_S + delta.microseconds * 1000
    if ns <= 0:
        raise FormatError(f'start time {text!r} is not after 1970-01-01T00:00:00Z (stamps must be > 0)')
    return int(ns)


def sample_stamp_ns(start_ns: int, sample_index: int, sampling_frequency_hz: float) -> int:
    """Stamp of sample ``sample_index``: ``start_ns + index / fs`` in exact rational arithmetic, rounded to ns."""
    return int(start_ns) + round(Fraction(int(sample_index) * NS_PER_S) / Fraction(float(sampling_frequency_hz)))


@dataclass(frozen=True)
class IfBlock:
    """One block of counts, ready to become an rfi_msgs/IfSamples.

    Attributes:
        counts: int8 or int16 counts, (n,) real or (2n,) interleaved I, Q (the message's ``samples``).
        first_sample_index: index of the block's first sample since the stream started.
        stamp_ns: time of the first sample, ns since 1970 UTC.
    """

    counts: np.ndarray
    first_sample_index: int
    stamp_ns: int
    is_complex: bool

    @property
    def n_samples(self) -> int:
        """Samples in the block (complex: I/Q pairs)."""
        return int(self.counts.size // (2 if self.is_complex else 1))


@dataclass
class BlockAssembler:
    """Raw bytes in any pieces -> whole blocks (pure; counts everything it cannot use).

    ``feed`` takes bytes as they come (short reads, items split across reads), ``skip`` declares samples
    lost upstream (the next block starts ``n`` samples later, so the jump in ``first_sample_index``
    shows the gap), ``finish`` accounts for what is left at the end of the input.

    Attributes:
        counters: ``bytes_in``, ``blocks``, ``samples``, ``partial_item_reads`` (pieces that ended
            inside an item), ``gaps``, ``samples_lost`` (declared by ``skip``), ``samples_dropped_at_gap``
            (the unfinished block before a gap), ``final_partial_block_samples``, ``trailing_bytes``,
            and the gr_complex conversion counts of :func:`unpack`.
    """

    fmt: IfFormat
    block_samples: int
    start_ns: int
    counters: Counter[str] = field(default_factory=Counter)

    def __post_init__(self) -> None:
        if self.block_samples < 1 or self.block_samples > MAX_BLOCK_SAMPLES:
            raise FormatError(f'block_samples = {self.block_samples} is outside 1..{MAX_BLOCK_SAMPLES}')
        if self.start_ns <= 0:
            raise FormatError(f'start time {self.start_ns} ns is not > 0')
        self._pending = bytearray()       # bytes of an unfinished chunk
        self._values: list[np.ndarray] = []
        self._n_values = 0                # values in self._values
        self._next_index = 0              # index of the first sample in self._values
        self._block_values = self.block_samples * self.fmt.values_per_sample

    @property
    def next_sample_index(self) -> int:
        """Index the next sample fed will get."""
        return self._next_index + self._n_values // self.fmt.values_per_sample

    @property
    def pending_bytes(self) -> int:
        """Bytes of an unfinished item held back until the rest of it arrives."""
        return len(self._pending)

    @property
    def buffered_bytes(self) -> int:
        """Bytes held (unfinished item and block), not yet in a block."""
        samples = self._n_values // self.fmt.values_per_sample
        return len(self._pending) + samples * self.fmt.chunk_bytes // self.fmt.chunk_samples

    def feed(self, data: bytes | bytearray | memoryview) -> list[IfBlock]:
        """Add raw bytes; return the blocks they complete (in order)."""
        self.counters['bytes_in'] += len(data)
        cb = self.fmt.chunk_bytes
        if self._pending:
            self._pending += data
            buf: bytes | bytearray | memoryview = self._pending
        else:
            buf = data
        whole = len(buf) - len(buf) % cb
        rest = bytes(buf[whole:])
        if whole:
            counts = unpack(self.fmt, bytes(buf[:whole]), self.counters)
            self._values.append(counts)
            self._n_values += counts.size
        if rest:
            self.counters['partial_item_reads'] += 1
        self._pending = bytearray(rest)
        return self._cut()

    def _cut(self) -> list[IfBlock]:
        if self._n_values < self._block_values:
            return []
        allv = np.concatenate(self._values) if len(self._values) > 1 else self._values[0]
        blocks = []
        n_blocks = allv.size // self._block_values
        for k in range(n_blocks):
            counts = allv[k * self._block_values:(k + 1) * self._block_values]
            blocks.append(self._block(counts))
        rest = allv[n_blocks * self._block_values:]
        self._values = [rest] if rest.size else []
        self._n_values = int(rest.size)
        return blocks

    def _block(self, counts: np.ndarray) -> IfBlock:
        index = self._next_index
        self._next_index += self.block_samples
        self.counters['blocks'] += 1
        self.counters['samples'] += self.block_samples
        stamp = sample_stamp_ns(self.start_ns, index, self.fmt.sampling_frequency_hz)
        return IfBlock(np.ascontiguousarray(counts), index, stamp, self.fmt.is_complex)

    def skip(self, n_samples: int) -> None:
        """Declare ``n_samples`` (> 0) lost upstream: the unfinished block is dropped (counted) and the next
        block starts after the gap. The bytes of an unfinished item are kept: the next bytes complete it (a
        writer loses whole buffers, so the item boundaries of the stream stay where they were)."""
        n_samples = int(n_samples)
        if n_samples <= 0:
            return
        held = self._n_values // self.fmt.values_per_sample
        self.counters['gaps'] += 1
        self.counters['samples_lost'] += n_samples
        self.counters['samples_dropped_at_gap'] += held
        self._next_index += held + n_samples
        self._values = []
        self._n_values = 0

    def finish(self) -> None:
        """End of input: count the samples of an unfinished last block and the bytes of an unfinished item."""
        self.counters['final_partial_block_samples'] += self._n_values // self.fmt.values_per_sample
        self.counters['trailing_bytes'] += len(self._pending)
        self._values = []
        self._n_values = 0
        self._pending = bytearray()


def is_live(path: str) -> bool:
    """True for a live stream: standard input ('-') or a path that is not a regular file (a named pipe, a
    device). Standard input redirected from a regular file (``< capture.bin``) is not live."""
    try:
        mode = os.fstat(0).st_mode if path == '-' else os.stat(path).st_mode
    except OSError:
        return path == '-'
    return not stat.S_ISREG(mode)


def check_file_size(path: str | Path, fmt: IfFormat, block_samples: int) -> int:
    """Bytes of a capture file, checked against the format.

    Raises:
        FormatError: the file cannot be read, is empty, its size is not a whole number of items (usually a
            wrong item_type), or it holds less than one block.
    """
    try:
        size = os.stat(path).st_size
    except OSError as err:
        raise FormatError(f'{path}: {err.strerror or err}') from None
    cb = fmt.chunk_bytes
    if size % cb:
        raise FormatError(f'{path}: {size} bytes is not a whole number of {fmt.item_type} items ({cb} bytes '
                          f'per {fmt.chunk_samples} sample(s)); {size % cb} bytes left over: wrong item_type?')
    samples = size // cb * fmt.chunk_samples
    if samples < block_samples:
        raise FormatError(f'{path}: {samples} samples, fewer than one block of {block_samples}')
    return size


def iter_file_blocks(path: str | Path, fmt: IfFormat, block_samples: int, start_ns: int,
                     assembler: BlockAssembler | None = None, read_bytes: int = 1 << 20) -> Iterator[IfBlock]:
    """Blocks of a capture file (checked first with :func:`check_file_size`), read ``read_bytes`` at a time.

    A last block shorter than ``block_samples`` is not yielded; it is counted in the assembler's
    ``final_partial_block_samples`` (pass ``assembler`` to read the counters).
    """
    check_file_size(path, fmt, block_samples)
    asm = assembler if assembler is not None else BlockAssembler(fmt, block_samples, start_ns)
    with open(path, 'rb') as f:
        while chunk := f.read(read_bytes):
            yield from asm.feed(chunk)
    asm.finish()


@dataclass
class LiveLag:
    """Gap detection on a live stream by the sample count (pure: the caller passes the elapsed times).

    A stream delivers ``fs`` samples per second. After the first byte arrives at ``t0``, by time ``t`` the
    reader should have seen ``(t - t0) * fs`` samples, counting those still waiting in the pipe. When that
    count exceeds what was received by more than ``tolerance_s * fs``, samples were lost upstream (the
    SDR tool overran while the reader fell behind, or dropped USB buffers): :meth:`update` returns the
    missing count, the caller declares it a gap (:meth:`BlockAssembler.skip`), and the reference moves on.
    A stream more than ``tolerance_s`` ahead of ``fs`` (a fast sampling clock, a burst after a stall) re-bases
    the reference (counted in :attr:`ahead_rebases`), so that a later loss is not hidden behind the advance.
    A sampling clock off by ``d`` ppm accumulates ``d * 1e-6 * T``: the tolerance must cover it over a run
    (50 ppm x 1 h = 0.18 s) as well as the tool's buffering (rtl_sdr: 256 KiB buffers).

    Args:
        fs: sampling_frequency_hz.
        tolerance_s: lag that declares a gap, s (> 0).
    """

    fs: float
    tolerance_s: float
    lag_s: float = 0.0
    ahead_rebases: int = 0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.tolerance_s) and self.tolerance_s > 0):
            raise FormatError(f'gap tolerance {self.tolerance_s} s must be > 0')
        self._t0: float | None = None
        self._base = 0

    def update(self, elapsed_s: float, samples_seen: int) -> int:
        """``elapsed_s``: monotonic time now, s; ``samples_seen``: samples received plus waiting (since the
        start, including gaps already declared). Returns the samples to declare lost (0: none)."""
        if self._t0 is None:
            self._t0, self._base = float(elapsed_s), int(samples_seen)
            return 0
        expected = (float(elapsed_s) - self._t0) * self.fs
        got = int(samples_seen) - self._base
        self.lag_s = (expected - got) / self.fs
        if self.lag_s > self.tolerance_s:
            missing = int(expected - got)
            self._t0, self._base = float(elapsed_s), int(samples_seen) + missing
            self.lag_s = 0.0
            return missing
        if self.lag_s < -self.tolerance_s:  # ahead (a fast sampling clock, a burst): re-base, or a later loss
            self._t0, self._base = float(elapsed_s), int(samples_seen)  # would hide behind the advance
            self.ahead_rebases += 1
        return 0
