"""From an IF capture to carrier phase in one command (issue 29 item 5): `run --transport processes
--with-correlator`, the monitor, gnss_correlator and imm_carrier as separate processes on one IF stream.

The real 150-ms PocketSDR 4 MS/s I/Q capture (the copy of the correlator's tests, src/gnss_correlator/test/data/,
BSD-2-Clause, (c) T. Takasu: see the README there) goes in twice as a user gives it: read by if_source
(`--if-input FILE`, the format in the if_source: section of a parameters file) and, converted by if_to_bag, as a
bag. Each time the monitor answers every 1-ms block, the correlator publishes one array per 1-ms interval stamped
from the IF stamps (the capture's start time plus whole milliseconds, the last at its end), and imm_carrier
answers each array with carrier-phase estimates, IMM and PLL, of the satellites the correlator tracks: the six
that the correlator's own tests find on this capture (16 18 26 29 31 32; PRN 24, a likely false alarm, may be
there too).
"""

from __future__ import annotations

import math
import signal
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

from rfi_experiments.bag_io import BagReader
from rfi_experiments.if_formats import parse_start_time
from rfi_msgs.msg import Correlator

ROOT = Path(__file__).resolve().parents[1]
CAPTURE = ROOT / 'src' / 'gnss_correlator' / 'test' / 'data' / 'pocketsdr_L1_4MHz_IQ_150ms.bin'
START = '2021-12-02T08:47:00Z'
START_NS = parse_start_time(START)
MS = 1_000_000
BLOCKS = 150  # 1-ms blocks of the 150-ms capture
TRACKED = {16, 18, 26, 29, 31, 32}
PARAMS = f"""\
if_source:
  ros__parameters:
    item_type: ibyte
    sampling_frequency_hz: 4000000.0
    intermediate_frequency_hz: 0.0
    center_frequency_hz: 1575420000.0
    bits_per_sample: 2
    block_duration_s: 0.001
    start_time: '{START}'
gnss_correlator:
  ros__parameters:
    spectrum_inverted: true
imm_carrier:
  ros__parameters:
    diagnostics_period_s: 0.02
"""
"""The user's parameters file: the capture's format for if_source, its spectral inversion for the correlator
(docs/gnss_correlator/README.md); imm_carrier's reports every 20 ms of stamp time (the default 1 s gives one report
over the 150 ms), for the counts of correlators that came unlocked. (Every 10 ms, 100 reports in a burst, the
pipe test's run once missed if_source's final report on /diagnostics.)"""


def run(args: list[str], out: Path, stdin: bytes | None = None) -> subprocess.CompletedProcess:
    proc = subprocess.Popen([sys.executable, '-m', 'rfi_experiments.run', *args, '--out', str(out), '--no-progress',
                             '--timeout', '240',
                             '--record-outputs', str(out / 'outputs')],
                            stdin=subprocess.PIPE if stdin is not None else subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        out_bytes, err_bytes = proc.communicate(stdin, timeout=600)
        stdout, stderr = out_bytes.decode(errors='replace'), err_bytes.decode(errors='replace')
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGINT)  # run stops its node processes on Ctrl-C
        _, err_bytes = proc.communicate(timeout=60)
        pytest.fail(f'run took over 600 s (interrupted, nodes stopped):\n{err_bytes.decode(errors="replace")[-3000:]}')
    done = subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)
    assert done.returncode == 0, done.stderr
    assert 'Traceback' not in done.stderr
    return done


def stamp_ns(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def outputs(bag: Path) -> dict[str, list]:
    got: dict[str, list] = defaultdict(list)
    with BagReader(bag) as reader:
        for message in reader.messages():
            got[message.topic].append(message.decode())
    return got


def check_carrier_from_capture(out: Path) -> None:
    got = outputs(out / 'outputs')
    # the monitor answered every block, stamped as the block: the capture's start plus whole milliseconds
    assert [stamp_ns(m.header) for m in got['/rfi/jammer_state']] == [START_NS + k * MS for k in range(BLOCKS)]
    # one array per 1-ms interval from the first channel's first C/N0 to the capture's end, stamps from the IF's
    arrays = got['/gnss/correlators']
    stamps = [stamp_ns(a.header) for a in arrays]
    assert len(arrays) >= 50, f'{len(arrays)} correlator arrays'
    assert stamps == list(range(stamps[0], START_NS + BLOCKS * MS + 1, MS))
    assert {c.svid for c in arrays[-1].correlators} >= TRACKED
    # imm_carrier answered each array with its stamp, IMM and PLL for every satellite in it
    estimates = got['/carrier/estimates']
    assert [stamp_ns(e.header) for e in estimates] == stamps
    for array, answer in zip(arrays, estimates, strict=True):
        expected = {(c.svid, method) for c in array.correlators for method in (1, 2)}
        assert {(e.svid, e.method) for e in answer.estimates} == expected
        assert all(math.isfinite(e.phase_rad) for e in answer.estimates)
    # every block received and processed by the correlator (its report at the stream's end, when it processes
    # the blocks it gathered, counts the whole stream)
    last = {}
    for array in got['/diagnostics']:
        for status in array.status:
            if status.name == 'gnss_correlator':
                last = {kv.key: kv.value for kv in status.values}
    assert last['blocks_received'] == last['blocks_processed'] == str(BLOCKS)
    assert last['accounting_ok'] == 'True'
    assert int(last['arrays_published']) == len(arrays)
    # the correlator's lock reaches imm_carrier: HELD for the tracked satellites at the end (UNKNOWN in the lock
    # rule's first 100 ms), and every imm_carrier report counts exactly the LOST correlators sent up to its stamp
    final = {c.svid: c.carrier_lock for c in arrays[-1].correlators}
    assert {final[prn] for prn in TRACKED} == {Correlator.CARRIER_LOCK_HELD}
    assert {c.carrier_lock for c in arrays[0].correlators} == {Correlator.CARRIER_LOCK_UNKNOWN}
    lost_until, lost = {}, 0
    for a in arrays:
        lost += sum(c.carrier_lock == Correlator.CARRIER_LOCK_LOST for c in a.correlators)
        lost_until[stamp_ns(a.header)] = lost
    reports = [({kv.key: kv.value for kv in status.values}, stamp_ns(array.header)) for array in got['/diagnostics']
               for status in array.status if status.name == 'imm_carrier' and stamp_ns(array.header) in lost_until]
    assert len(reports) >= 4  # (nonzero when PRN 24, LOST from 101 ms, was acquired: it was in the runs seen)
    for values, stamp in reports:
        for method in ('imm', 'pll'):
            assert int(values[f'{method}.correlator_unlocked']) == lost_until[stamp]
    replay = (out / 'replay.md').read_text()
    assert '## Carrier phase from the correlator' in replay
    for prn in TRACKED:
        assert f'| 1 / {prn} | IMM |' in replay and f'| 1 / {prn} | PLL |' in replay


@pytest.mark.slow
def test_if_capture_to_carrier_phase_in_one_command(tmp_path):
    params = tmp_path / 'front_end.yaml'
    params.write_text(PARAMS)
    done = run(['--transport', 'processes', '--with-correlator', '--if-input', str(CAPTURE), '--params-file',
                str(params)], tmp_path / 'run')
    assert f'{BLOCKS} IF blocks of {CAPTURE}' in done.stdout
    check_carrier_from_capture(tmp_path / 'run')
    logs = {p.name for p in (tmp_path / 'run' / 'logs').iterdir()}
    assert {'if_source.log', 'rfi_monitor.log', 'gnss_correlator.log', 'imm_carrier.log'} <= logs
    assert not {'gnss_integrity.log', 'uwb_gnss_fusion.log'} & logs  # no input for them on an IF stream alone


@pytest.mark.slow
def test_if_capture_through_a_pipe_to_carrier_phase(tmp_path):
    """The capture written to run's standard input (``--if-input -``), as an SDR tool's pipe gives it."""
    params = tmp_path / 'front_end.yaml'
    params.write_text(PARAMS)
    done = run(['--transport', 'processes', '--with-correlator', '--if-input', '-', '--params-file', str(params)],
               tmp_path / 'run', stdin=CAPTURE.read_bytes())
    assert f'{BLOCKS} IF blocks of -' in done.stdout
    check_carrier_from_capture(tmp_path / 'run')


@pytest.mark.slow
def test_bag_of_the_capture_through_the_suite_with_the_correlator(tmp_path):
    bag = tmp_path / 'capture_bag'
    conversion = subprocess.run(
        [sys.executable, '-m', 'rfi_experiments.if_to_bag', str(CAPTURE), str(bag), '--item-type', 'ibyte',
         '--sampling-frequency-hz', '4000000.0', '--bits-per-sample', '2', '--start-time', START,
         '--block-duration-s', '0.001', '-q'], capture_output=True, text=True, timeout=120)
    assert conversion.returncode == 0, conversion.stderr
    params = tmp_path / 'correlator.yaml'
    params.write_text('gnss_correlator:' + PARAMS.split('gnss_correlator:', 1)[1])
    run([str(bag), '--transport', 'processes', '--with-correlator', '--params-file', str(params), '--no-report'],
        tmp_path / 'run')
    check_carrier_from_capture(tmp_path / 'run')


def test_run_refuses_if_input_without_its_format_or_with_a_bag(tmp_path):
    base = [sys.executable, '-m', 'rfi_experiments.run', '--out', str(tmp_path / 'out')]
    no_format = subprocess.run([*base, '--transport', 'processes', '--if-input', str(CAPTURE)],
                               capture_output=True, text=True, timeout=60)
    assert no_format.returncode != 0 and 'if_source: section' in no_format.stderr
    both = subprocess.run([*base, str(ROOT / 'bags' / 'default'), '--transport', 'processes', '--if-input',
                           str(CAPTURE)], capture_output=True, text=True, timeout=60)
    assert both.returncode != 0 and 'not both' in both.stderr
    direct = subprocess.run([*base, str(ROOT / 'bags' / 'default'), '--with-correlator'], capture_output=True,
                            text=True, timeout=60)
    assert direct.returncode != 0 and 'processes only' in direct.stderr
