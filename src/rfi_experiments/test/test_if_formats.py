"""Pure tests of rfi_experiments.if_formats: layouts against hand-built bytes, the real captures against
np.fromfile, short reads, stamps, gaps and bad input (no rclpy)."""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from rfi_experiments.if_formats import (
    INT8,
    INT16,
    ITEM_TYPES,
    BlockAssembler,
    FormatError,
    IfFormat,
    LiveLag,
    check_file_size,
    iter_file_blocks,
    parse_start_time,
    sample_stamp_ns,
    unpack,
)

DATA = Path(__file__).resolve().parents[2] / 'rfi_monitor' / 'test' / 'data'
START_NS = parse_start_time('2021-12-02T08:47:00Z')

# (file, format, block samples, direct read: dtype and values per block)
CAPTURES = [
    ('pocketsdr_L1_4MHz_IQ_10ms.bin', IfFormat('ibyte', 4e6, bits_per_sample=2), 4000, np.int8),
    ('pocketsdr_L1_12MHz_I_10ms.bin', IfFormat('byte', 12e6, 3e6, center_frequency_hz=1572.42e6 + 3e6,
                                               bits_per_sample=2), 12000, np.int8),
    ('gnsssdr_cttc_4Msps_4ms.dat', IfFormat('gr_complex', 4e6), 2000, np.float32),
]


def test_storage_codes_are_the_message_constants():
    from rfi_msgs.msg import IfSamples
    assert (INT8, INT16) == (IfSamples.INT8, IfSamples.INT16)


@pytest.mark.parametrize('name,fmt,block,dtype', CAPTURES, ids=[c[0] for c in CAPTURES])
def test_real_captures_equal_the_direct_read(name, fmt, block, dtype):
    direct = np.fromfile(DATA / name, dtype=dtype)
    per_block = block * fmt.values_per_sample
    asm = BlockAssembler(fmt, block, START_NS)
    blocks = list(iter_file_blocks(DATA / name, fmt, block, START_NS, asm))
    assert len(blocks) == direct.size // per_block >= 8
    for k, b in enumerate(blocks):
        assert b.counts.dtype == fmt.dtype
        assert np.array_equal(b.counts, direct[k * per_block:(k + 1) * per_block])  # exact: integers
        assert b.first_sample_index == k * block
        assert b.stamp_ns == START_NS + round(k * block * 1e9 / fmt.sampling_frequency_hz)
    assert asm.counters['final_partial_block_samples'] == 0 and asm.counters['trailing_bytes'] == 0
    if fmt.item_type == 'gr_complex':  # the CTTC floats are whole counts: the conversion is exact
        assert asm.counters['rounded_values'] == asm.counters['clipped_values'] == 0
        assert fmt.published_scale == 1.0


@pytest.mark.parametrize('name,fmt,block,dtype', CAPTURES, ids=[c[0] for c in CAPTURES])
def test_short_reads_give_the_same_blocks(name, fmt, block, dtype):
    raw = (DATA / name).read_bytes()
    whole = BlockAssembler(fmt, block, START_NS).feed(raw)
    asm = BlockAssembler(fmt, block, START_NS)
    rng = np.random.default_rng(7)
    pieces, pos = [], 0
    while pos < len(raw):
        n = int(rng.integers(1, 3000))
        pieces.append(raw[pos:pos + n])
        pos += n
    got = [b for p in pieces for b in asm.feed(p)]
    assert len(got) == len(whole)
    for a, b in zip(got, whole, strict=True):
        assert np.array_equal(a.counts, b.counts) and a.first_sample_index == b.first_sample_index
        assert a.stamp_ns == b.stamp_ns
    assert asm.counters['partial_item_reads'] > 0 if fmt.chunk_bytes > 1 else True
    assert asm.counters['bytes_in'] == len(raw)


def _pack_2bit(v: np.ndarray, msb_first: bool = False) -> bytes:
    """Four 2-bit two's-complement fields per byte, the first in bits 1-0 (GNSS-SDR's default) or 7-6."""
    f = (v.reshape(-1, 4) & 0x3).astype(np.uint8)
    if msb_first:
        f = f[:, ::-1]
    return (f[:, 0] | f[:, 1] << 2 | f[:, 2] << 4 | f[:, 3] << 6).astype(np.uint8).tobytes()


def test_two_bit_packed_layout_of_gnss_sdr():
    # 0b11_10_01_00: fields (bits 1-0 first) 0, 1, 2, 3 -> v 0, 1, -2, -1 -> 2v + 1
    assert unpack(IfFormat('two_bit_packed', 4e6), bytes([0b11100100])).tolist() == [1, 3, -3, -1]
    assert unpack(IfFormat('two_bit_packed', 4e6, big_endian_bytes=True), bytes([0b11100100])).tolist() == \
        [-1, -3, 3, 1]
    rng = np.random.default_rng(3)
    v = rng.integers(-2, 2, size=400)
    assert np.array_equal(unpack(IfFormat('two_bit_packed', 4e6), _pack_2bit(v)), 2 * v + 1)
    assert np.array_equal(unpack(IfFormat('two_bit_packed', 4e6, big_endian_bytes=True), _pack_2bit(v, True)),
                          2 * v + 1)
    iq = IfFormat('two_bit_packed', 4e6, sample_type='iq')
    assert iq.is_complex and iq.chunk_samples == 2
    assert np.array_equal(unpack(iq, _pack_2bit(v)), 2 * v + 1)
    qi = unpack(IfFormat('two_bit_packed', 4e6, sample_type='qi'), _pack_2bit(v))
    assert np.array_equal(qi[0::2], 2 * v[1::2] + 1) and np.array_equal(qi[1::2], 2 * v[0::2] + 1)
    # 16-bit words: big-endian items (GNSS-SDR's default) hold the second byte of the file first
    words = _pack_2bit(v)
    swapped = bytes(b for pair in zip(words[1::2], words[0::2], strict=True) for b in pair)
    assert np.array_equal(unpack(IfFormat('two_bit_packed_short', 4e6), swapped), 2 * v + 1)
    assert np.array_equal(unpack(IfFormat('two_bit_packed_short', 4e6, big_endian_items=False), words), 2 * v + 1)


def test_four_bit_cpx_layout_of_gnss_sdr():
    # low nibble I, high nibble Q, 4-bit two's complement v -> 2v + 1
    out = unpack(IfFormat('four_bit_cpx', 4e6), bytes([0x8F, 0x70, 0x1E]))
    assert out.tolist() == [-1, -15, 1, 15, -3, 3]
    assert unpack(IfFormat('four_bit_cpx', 4e6, sample_type='qi'), bytes([0x8F])).tolist() == [-15, -1]
    assert IfFormat('four_bit_cpx', 4e6).published_bits_per_sample == 5  # full scale 15 = the top code


def test_rtl_sdr_offset_binary():
    fmt = IfFormat('uibyte', 2.048e6)
    out = unpack(fmt, bytes([0, 255, 127, 128]))
    assert out.tolist() == [-255, 255, -1, 1]  # 2u - 255
    assert (out * fmt.published_scale).tolist() == [-127.5, 127.5, -0.5, 0.5]  # u - 127.5
    assert fmt.sample_format == INT16 and fmt.published_bits_per_sample == 9


def test_short_and_ishort_little_endian():
    x = np.array([-32768, -1, 0, 1, 32767, 1234], dtype='<i2')
    assert np.array_equal(unpack(IfFormat('short', 4e6), x.tobytes()), x)
    assert np.array_equal(unpack(IfFormat('ishort', 4e6), x.tobytes()), x)
    assert np.array_equal(unpack(IfFormat('cshort', 4e6), x.tobytes()), x)


def test_gr_complex_scaling_is_counted():
    counters: Counter[str] = Counter()
    fmt = IfFormat('gr_complex', 4e6, float_counts_per_unit=32767.0)
    x = np.array([0.5, -1.0, 1.0, 2.0, np.nan, 0.25], dtype='<f4')
    out = unpack(fmt, x.tobytes(), counters)
    assert out.tolist() == [16384, -32767, 32767, 32767, 0, 8192]
    assert counters == {'rounded_values': 2, 'clipped_values': 1, 'non_finite_values': 1}
    assert fmt.published_scale == pytest.approx(1 / 32767)


def test_spectral_inversion():
    real = IfFormat('byte', 12e6, 3e6, spectral_inversion=True)
    assert real.published_intermediate_frequency_hz == -3e6
    assert unpack(real, bytes([1, 2, 3, 4])).tolist() == [1, 2, 3, 4]
    cplx = IfFormat('ibyte', 4e6, 1e6, spectral_inversion=True)
    assert unpack(cplx, bytes([1, 2, 3, 4])).tolist() == [2, 1, 4, 3]
    assert cplx.published_intermediate_frequency_hz == -1e6
    # the swapped pair Q + jI = j conj(x): a tone at +f appears at -f
    n = np.arange(64)
    tone = np.exp(2j * np.pi * 0.125 * n)
    iq = np.empty(128)
    iq[0::2], iq[1::2] = np.round(100 * tone.real), np.round(100 * tone.imag)
    out = unpack(cplx, iq.astype(np.int8).tobytes()).astype(float)
    spec = np.fft.fft(out[0::2] + 1j * out[1::2])
    assert int(np.argmax(np.abs(spec))) == 64 - 8


@pytest.mark.parametrize('kwargs,needle', [
    ({'item_type': 'int12'}, 'unknown item_type'),
    ({'sampling_frequency_hz': 0.0}, 'sampling_frequency_hz'),
    ({'sampling_frequency_hz': math.nan}, 'sampling_frequency_hz'),
    ({'intermediate_frequency_hz': 2.5e6}, 'fs/2'),
    ({'intermediate_frequency_hz': -1e6}, 'spectral_inversion'),
    ({'center_frequency_hz': -1.0}, 'center_frequency_hz'),
    ({'bits_per_sample': 9}, 'bits_per_sample'),
    ({'scale': 1e6}, 'scale'),
    ({'sample_type': 'iq'}, 'packed item types only'),
    ({'sample_type': 'xy'}, 'sample_type'),
    ({'float_counts_per_unit': 0.0}, 'float_counts_per_unit'),
])
def test_bad_format_parameters_are_refused_with_their_name(kwargs, needle):
    args = {'item_type': 'byte', 'sampling_frequency_hz': 4e6, **kwargs}
    with pytest.raises(FormatError, match=needle):
        IfFormat(**args)


def test_block_duration():
    fmt = IfFormat('ibyte', 4e6)
    assert fmt.block_samples(0.001) == 4000 and fmt.block_samples(0.00025) == 1000
    for bad in (0.0, -1.0, math.inf, 1e-9, 100.0):
        with pytest.raises(FormatError, match='block_duration_s'):
            fmt.block_samples(bad)


def test_file_size_that_does_not_fit_the_item_type(tmp_path):
    path = tmp_path / 'odd.bin'
    path.write_bytes(bytes(4001))
    with pytest.raises(FormatError, match='not a whole number of ishort items.*1 bytes left over'):
        check_file_size(path, IfFormat('ishort', 4e6), 100)
    with pytest.raises(FormatError, match='fewer than one block'):
        check_file_size(path, IfFormat('byte', 4e6), 5000)
    with pytest.raises(FormatError, match='No such file'):
        check_file_size(tmp_path / 'missing.bin', IfFormat('byte', 4e6), 10)


def test_truncated_stream_is_counted_not_lost():
    asm = BlockAssembler(IfFormat('ishort', 4e6), 10, START_NS)
    blocks = asm.feed(bytes(4 * 25 + 3))   # 25 samples and 3 bytes of a 26th
    asm.finish()
    assert [b.n_samples for b in blocks] == [10, 10]
    assert asm.counters['final_partial_block_samples'] == 5 and asm.counters['trailing_bytes'] == 3


def test_gap_moves_the_sample_index_and_counts():
    fmt = IfFormat('byte', 1e6)
    asm = BlockAssembler(fmt, 100, START_NS)
    assert len(asm.feed(bytes(150))) == 1
    asm.skip(1000)
    b = asm.feed(bytes(100))[0]
    assert b.first_sample_index == 150 + 1000  # the unfinished block before the gap is dropped
    assert b.stamp_ns == START_NS + 1150 * 1000
    assert asm.counters['gaps'] == 1 and asm.counters['samples_lost'] == 1000
    assert asm.counters['samples_dropped_at_gap'] == 50


def test_live_lag_declares_a_gap_beyond_the_tolerance():
    lag = LiveLag(fs=1e6, tolerance_s=0.1)
    assert lag.update(10.0, 0) == 0
    assert lag.update(10.5, 500_000) == 0 and abs(lag.lag_s) < 1e-9      # on time
    assert lag.update(11.0, 950_000) == 0 and lag.lag_s == pytest.approx(0.05)  # within tolerance
    missing = lag.update(11.5, 1_200_000)                                 # 0.3 s missing
    assert missing == pytest.approx(300_000, abs=1)
    base = 1_200_000 + missing
    assert lag.update(12.0, base + 500_000) == 0                        # the reference moved on
    assert lag.update(12.5, base + 1_050_000) == 0 and lag.lag_s == pytest.approx(-0.05)  # ahead: no gap
    assert lag.ahead_rebases == 0
    assert lag.update(13.0, base + 2_000_000) == 0 and lag.ahead_rebases == 1  # 0.5 s ahead: re-based
    assert lag.update(13.5, base + 2_450_000) == 0                      # 0.05 s behind the new reference
    assert lag.update(14.0, base + 2_450_000) == pytest.approx(550_000, abs=1)  # a loss right after is seen


def test_stamps_are_exact_and_do_not_drift():
    fs = 16.368e6
    assert sample_stamp_ns(1, 16_368_000 * 3600, fs) == 1 + 3600 * 10 ** 9
    assert sample_stamp_ns(0, 3, 3e6) == 1000


def test_start_times():
    assert parse_start_time('2021-12-02T08:47:00Z') == parse_start_time('1638434820') == 1638434820 * 10 ** 9
    assert parse_start_time('2021-12-02T09:47:00+01:00') == 1638434820 * 10 ** 9
    assert parse_start_time('2021-12-02 08:47:00.25') == 1638434820 * 10 ** 9 + 250_000_000
    assert parse_start_time('1638434820.000000001') == 1638434820 * 10 ** 9 + 1
    for bad in ('yesterday', '-5', '0', '1970-01-01T00:00:00Z', ''):
        with pytest.raises(FormatError, match='start time'):
            parse_start_time(bad)


def test_every_item_type_round_trips_a_whole_chunk():
    for name, item in ITEM_TYPES.items():
        fmt = IfFormat(name, 4e6)
        out = unpack(fmt, bytes(item.chunk_bytes * 3))
        assert out.dtype == fmt.dtype and out.size == 3 * item.chunk_values, name
        if item.chunk_bytes > 1:
            with pytest.raises(FormatError, match='whole number'):
                unpack(fmt, bytes(item.chunk_bytes + 1))
