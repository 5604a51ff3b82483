"""if_to_bag on the real captures (PocketSDR 12 MHz real, 4 MHz I/Q, GNSS-SDR 4 MS/s gr_complex): the bag holds
the blocks of the direct read (samples compared exactly, they are integers) and the monitor core gives the same
outputs on the bag's blocks as on the directly read ones; bad input is refused with one line, exit code 2."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from rfi_experiments.bag_io import BagReader
from rfi_experiments.if_to_bag import main
from rfi_monitor.monitor import RfiMonitor
from rfi_monitor.rfi_monitor_node import MonitorNodeParams, check_block, decode_counts, decode_samples, full_scale
from rfi_msgs.msg import IfSamples
from rfi_node_common import testing
from rfi_node_common.stamps import stamp_to_ns

DATA = Path(__file__).resolve().parents[2] / 'rfi_monitor' / 'test' / 'data'
SHARED = Path(__file__).resolve().parents[4] / 'shared' / 'data'

# file, options, direct read dtype, block samples, is_complex, fs, IF, bits
CASES = [
    ('pocketsdr_L1_12MHz_I_10ms.bin', ['--item-type', 'byte', '--sampling-frequency-hz', '12e6',
                                       '--intermediate-frequency-hz', '3e6', '--center-frequency-hz', '1575.42e6',
                                       '--bits-per-sample', '2', '--start-time', '2021-11-25T00:40:00Z'],
     np.int8, 12000, False, 12e6, 3e6, 2),
    ('pocketsdr_L1_4MHz_IQ_10ms.bin', ['--item-type', 'ibyte', '--sampling-frequency-hz', '4e6',
                                       '--bits-per-sample', '2', '--start-time', '2021-12-01T08:47:00Z'],
     np.int8, 4000, True, 4e6, 0.0, 2),
    ('gnsssdr_cttc_4Msps_4ms.dat', ['--item-type', 'gr_complex', '--sampling-frequency-hz', '4e6',
                                    '--block-duration-s', '0.0005', '--start-time', '1343309509'],
     np.float32, 2000, True, 4e6, 0.0, 16),
]
IDS = [c[0] for c in CASES]


def read_bag(path: Path) -> list[IfSamples]:
    with BagReader(path) as bag:
        msgs = list(bag.messages())
    assert {m.topic for m in msgs} == {'/rfi/if_samples'}
    return [m.decode() for m in msgs]


def estimate_key(est) -> tuple:
    """The fields of a JammerEstimate that go on the topic, NaN made comparable."""
    fields = (est.valid, est.rejection, est.type, est.confidence, est.jammer_to_noise_db, est.jammer_to_signal_db,
              est.frequency_hz, est.frequency_std_hz, est.sweep_rate_hz_per_s, est.sweep_period_s,
              est.sweep_start_frequency_hz, est.sweep_bandwidth_hz, est.sample_rate_hz)
    return tuple('nan' if isinstance(v, float) and math.isnan(v) else v for v in fields)


def core_on_messages(msgs: list[IfSamples]) -> list[tuple]:
    """What the monitor node's core computes for each block (the node's own decoding and arguments)."""
    mon = RfiMonitor(MonitorNodeParams().monitor_params())
    out = []
    for m in msgs:
        assert check_block(m, 1024) is None
        out.append(estimate_key(mon.process(decode_samples(m), m.sample_rate_hz, m.intermediate_frequency_hz,
                                            m.first_sample_index, stamp_to_ns(m.header.stamp),
                                            is_complex=bool(m.is_complex), full_scale=full_scale(m))))
    return out


def core_on_direct_read(path: Path, dtype, block: int, cplx: bool, fs: float, fif: float, bits: int,
                        start_ns: int, n_blocks: int | None = None) -> list[tuple]:
    """The core fed the file read with np.fromfile, cut by hand (scale 1: the values are the counts)."""
    x = np.fromfile(path, dtype=dtype).astype(np.float64)
    per = block * (2 if cplx else 1)
    mon = RfiMonitor(MonitorNodeParams().monitor_params())
    fs_counts = None if bits < 4 else float(2 ** (bits - 1) - 1)
    return [estimate_key(mon.process(x[k * per:(k + 1) * per], fs, fif, k * block,
                                     start_ns + round(k * block * 1e9 / fs), is_complex=cplx, full_scale=fs_counts))
            for k in range(min(x.size // per, n_blocks or x.size))]


def check_bag_against_direct_read(tmp_path, path, opts, dtype, block, cplx, fs, fif, bits, core_blocks=None):
    """Every block of the bag equals the direct read; the core's outputs on the first ``core_blocks`` (None: all)
    blocks of the bag equal those on the directly read ones."""
    out = tmp_path / 'bag'
    assert main(['if_to_bag', str(path), str(out), *opts]) == 0
    msgs = read_bag(out)
    direct = np.fromfile(path, dtype=dtype)
    per = block * (2 if cplx else 1)
    assert len(msgs) == direct.size // per
    start_ns = stamp_to_ns(msgs[0].header.stamp)
    for k, m in enumerate(msgs):
        assert np.array_equal(decode_counts(m), direct[k * per:(k + 1) * per])
        assert m.first_sample_index == k * block and bool(m.is_complex) == cplx
        assert m.sample_rate_hz == fs and m.intermediate_frequency_hz == fif and m.bits_per_sample == bits
        assert m.scale == 1.0 and m.center_frequency_hz == 1575.42e6 and m.header.frame_id == 'gnss_front_end'
        assert stamp_to_ns(m.header.stamp) == start_ns + round(k * block * 1e9 / fs)
    msgs = msgs[:core_blocks]
    via_bag = core_on_messages(msgs)
    assert via_bag == core_on_direct_read(path, dtype, block, cplx, fs, fif, bits, start_ns, core_blocks)
    assert sum(1 for e in via_bag if e[0]) == len(msgs)  # every block analysed (the first ones learn the floor)


@pytest.mark.parametrize('name,opts,dtype,block,cplx,fs,fif,bits', CASES, ids=IDS)
def test_bag_equals_direct_read_and_monitor_outputs_agree(tmp_path, name, opts, dtype, block, cplx, fs, fif, bits):
    check_bag_against_direct_read(tmp_path, DATA / name, opts, dtype, block, cplx, fs, fif, bits)


SHARED_CASES = [
    ('iq_clean_pocketsdr/L1_20211125_004000_12MHz_I.bin', *CASES[0][1:]),
    ('iq_clean_pocketsdr/L1_20211202_084700_4MHz_IQ.bin', *CASES[1][1:]),
    ('iq_clean_gnsssdr/GSoC_CTTC_capture_2012_07_26_4Msps_4ms.dat', *CASES[2][1:]),
]


@pytest.mark.skipif(not SHARED.is_dir(), reason='../shared/data is not here (a clone has the cuts only)')
@pytest.mark.parametrize('name,opts,dtype,block,cplx,fs,fif,bits', SHARED_CASES, ids=[c[0] for c in SHARED_CASES])
def test_whole_real_captures(tmp_path, name, opts, dtype, block, cplx, fs, fif, bits):
    """The whole captures of ../shared/data (0.1 s, 0.5 s and 4 ms), as above; the monitor on their first 0.1 s
    (the core runs twice per block: the 0.5 s capture would take about 25 s)."""
    check_bag_against_direct_read(tmp_path, SHARED / name, opts, dtype, block, cplx, fs, fif, bits,
                                  core_blocks=round(0.1 * fs / block))


def test_start_time_is_ros_time(tmp_path):
    out = tmp_path / 'bag'
    assert main(['if_to_bag', str(DATA / CASES[1][0]), str(out), *CASES[1][1]]) == 0
    first = read_bag(out)[0]
    assert (first.header.stamp.sec, first.header.stamp.nanosec) == (1638348420, 0)  # 2021-12-01T08:47:00Z UTC


@pytest.mark.skipif(not (SHARED / 'iq_clean_pocketsdr').is_dir(), reason='../shared/data is not here')
def test_whole_pocketsdr_capture_from_standard_input(tmp_path):
    """The whole 4 MHz I/Q capture (4,000,000 bytes: 0.5 s) through a real pipe into if_to_bag's standard input."""
    path = SHARED / 'iq_clean_pocketsdr' / 'L1_20211202_084700_4MHz_IQ.bin'
    out = tmp_path / 'bag'
    with path.open('rb') as f:
        done = testing.run_process([sys.executable, '-m', 'rfi_experiments.if_to_bag', '-', str(out), *CASES[1][1]],
                                   stdin=f, text=True)
    assert done.returncode == 0, done.stderr
    msgs = read_bag(out)
    direct = np.fromfile(path, dtype=np.int8)
    assert len(msgs) == direct.size // 8000 == 500
    assert np.array_equal(np.concatenate([decode_counts(m) for m in msgs]), direct)


def _refused(capsys, argv: list[str], needle: str) -> None:
    assert main(['if_to_bag', *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith('if_to_bag: error: ') and needle in err and 'Traceback' not in err, err


def test_bad_input_is_refused_with_one_line(tmp_path, capsys):
    src = str(DATA / CASES[1][0])
    out = str(tmp_path / 'bag')
    base = ['--sampling-frequency-hz', '4e6', '--start-time', '1638434820']
    odd = tmp_path / 'odd.bin'
    odd.write_bytes(bytes(4002))
    _refused(capsys, [str(odd), out, '--item-type', 'ishort', *base], 'not a whole number of ishort items')
    _refused(capsys, [src, out, '--item-type', 'ibyte', '--intermediate-frequency-hz', '3e6', *base], 'fs/2')
    _refused(capsys, [src, out, '--item-type', 'ibyte', '--sampling-frequency-hz', '1e3',
                      '--start-time', '1638434820'], 'sampling_frequency_hz')
    _refused(capsys, [src, out, '--item-type', 'ibyte', '--sampling-frequency-hz', '4e6', '--start-time', 'noon'],
             'start time')
    _refused(capsys, [src, out, '--item-type', 'byte', '--sample-type', 'iq', *base], 'packed item types only')
    _refused(capsys, [str(tmp_path / 'missing.bin'), out, '--item-type', 'byte', *base], 'No such file')
    _refused(capsys, [src, out, '--item-type', 'byte', '--block-duration-s', '1.0', *base], 'fewer than one block')
    assert main(['if_to_bag', src, out, '--item-type', 'int12', *base]) == 2  # argparse: invalid choice
    assert 'invalid choice' in capsys.readouterr().err
    assert not Path(out).exists()
    assert main(['if_to_bag', src, out, '--item-type', 'ibyte', *base]) == 0
    capsys.readouterr()  # the run's progress lines (stderr) and summary
    _refused(capsys, [src, out, '--item-type', 'ibyte', *base], 'exists already')


def test_truncated_standard_input_is_reported(tmp_path, capsys, monkeypatch):
    import io

    raw = (DATA / CASES[1][0]).read_bytes()[:4000 * 2 * 3 + 1001]  # 3 blocks, 500 samples and a lone byte
    monkeypatch.setattr(sys, 'stdin', io.TextIOWrapper(io.BytesIO(raw)))
    assert main(['if_to_bag', '-', str(tmp_path / 'bag'), *CASES[1][1]]) == 0
    text = capsys.readouterr().out
    assert '3 blocks of 4000 samples' in text
    assert '500 samples after the last whole block, not written' in text
    assert '1 trailing bytes' in text
    assert len(read_bag(tmp_path / 'bag')) == 3


def test_max_duration(tmp_path, capsys):
    assert main(['if_to_bag', str(DATA / CASES[1][0]), str(tmp_path / 'bag'), *CASES[1][1], '--max-duration-s',
                 '0.003']) == 0
    assert [m.first_sample_index for m in read_bag(tmp_path / 'bag')] == [0, 4000, 8000]
    last = capsys.readouterr().err.splitlines()[-1]  # --max-duration-s sets the progress line's total
    assert last.startswith('if_to_bag pocketsdr_L1_4MHz_IQ_10ms.bin: 100% (3/3 block)')
    _refused(capsys, [str(DATA / CASES[1][0]), str(tmp_path / 'bag2'), *CASES[1][1], '--max-duration-s', '0.0001'],
             'shorter than one block')
