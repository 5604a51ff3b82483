"""The progress line and --quiet (issue 30 item 5): the line's text and rhythm on and off a terminal, the
benchmarks' case log, and the converters and ``simulate`` with and without --quiet (the progress on stderr, the
summary on stdout, nothing of either with --quiet, and the same bag either way)."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from rfi_experiments.bag_io import BagReader
from rfi_experiments.progress import CaseLog, ProgressLine, format_duration, summary_printer

PKG = Path(__file__).resolve().parents[1]
IF_FILE = PKG.parent / 'rfi_monitor' / 'test' / 'data' / 'pocketsdr_L1_12MHz_I_10ms.bin'
IF_OPTIONS = ['--item-type', 'byte', '--sampling-frequency-hz', '12e6', '--intermediate-frequency-hz', '3e6',
              '--center-frequency-hz', '1575.42e6', '--bits-per-sample', '2', '--start-time', '2021-11-25T00:40:00Z']
HANYANG_CASE = PKG / 'test' / 'data' / 'uwb_hanyang_los_a1'


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_off_a_terminal_one_line_per_tenth_and_one_at_the_end():
    stream, clock = io.StringIO(), FakeClock()
    line = ProgressLine('replay x.mcap', 1000, 'msg', stream=stream, terminal=False, clock=clock)
    for _ in range(1000):
        clock.t += 0.01
        line.update()
    line.close()
    line.close()  # idempotent
    lines = stream.getvalue().splitlines()
    assert '\r' not in stream.getvalue()
    assert lines[0] == 'replay x.mcap: 10% (100/1000 msg), 1.0 s'
    assert [ln.split(': ')[1].split('%')[0] for ln in lines] == [str(p) for p in range(10, 101, 10)]
    assert lines[-1] == 'replay x.mcap: 100% (1000/1000 msg), 10.0 s'


def test_a_jump_writes_one_line_and_an_unknown_total_a_line_every_period():
    stream = io.StringIO()
    line = ProgressLine('simulate s', 200, 's', stream=stream, terminal=False, clock=FakeClock())
    line.set_done(130)  # 65 %: one line, not six
    line.set_done(140)  # 70 %
    assert stream.getvalue().splitlines() == ['simulate s: 65% (130/200 s), 0.0 s',
                                              'simulate s: 70% (140/200 s), 0.0 s']

    stream, clock = io.StringIO(), FakeClock()
    line = ProgressLine('read', None, 'kB', stream=stream, terminal=False, every_s=30.0, clock=clock)
    for _ in range(100):
        clock.t += 1.0
        line.update(2)
    line.close()
    assert stream.getvalue().splitlines() == ['read: 60 kB, 30.0 s', 'read: 120 kB, 1 min 00 s',
                                              'read: 180 kB, 1 min 30 s', 'read: 200 kB, 1 min 40 s']


def test_on_a_terminal_a_bar_redrawn_in_place_and_disabled_writes_nothing():
    stream = io.StringIO()
    with ProgressLine('play', 50, 'msg', stream=stream, terminal=True) as line:
        for item in range(50):
            line.update()
            assert item < 50
    text = stream.getvalue()
    assert '\r' in text and 'play' in text and '50/50' in text
    assert text.count('\n') <= 1

    quiet = io.StringIO()
    line = ProgressLine('play', 50, 'msg', enabled=False, stream=quiet, terminal=False)
    assert list(line.iterate(range(50))) == list(range(50))
    assert line.done == 50 and line.closed
    assert quiet.getvalue() == ''


def test_refuses_a_step_that_never_advances():
    with pytest.raises(ValueError, match='step_percent'):
        ProgressLine('x', 10, step_percent=0.0)


def test_durations_read_as_a_person_says_them():
    assert [format_duration(s) for s in (0.04, 59.94, 65.0, 3599.0, 3725.0)] == [
        '0.0 s', '59.9 s', '1 min 05 s', '59 min 59 s', '1 h 02 min']


def test_case_log_one_line_per_case_then_the_summary_on_stdout():
    err, out, clock = io.StringIO(), io.StringIO(), FakeClock()
    log = CaseLog('fusion_jamming', 3, stream=err, out=out, clock=clock)
    for seconds, label in zip((2.0, 70.0, 0.5), log.cases_of(['JSR 30 dB', 'JSR 40 dB', 'JSR 50 dB']), strict=True):
        clock.t += seconds
        assert label.startswith('JSR')
    log.finish('wrote docs/fusion/jamming.md')
    assert err.getvalue().splitlines() == ['[fusion_jamming 1/3] JSR 30 dB: 2.0 s, 2.0 s in all',
                                           '[fusion_jamming 2/3] JSR 40 dB: 1 min 10 s, 1 min 12 s in all',
                                           '[fusion_jamming 3/3] JSR 50 dB: 0.5 s, 1 min 12 s in all']
    assert out.getvalue().splitlines() == ['fusion_jamming: 3 cases in 1 min 12 s', 'wrote docs/fusion/jamming.md']

    err, out = io.StringIO(), io.StringIO()
    quiet = CaseLog('fusion_jamming', None, quiet=True, stream=err, out=out, clock=clock)
    assert quiet.done('one') == 0.0
    quiet.finish('wrote it')
    assert quiet.cases == 1 and err.getvalue() == '' and out.getvalue() == ''


def test_summary_printer(capsys):
    summary_printer(False)('shown', 1)
    summary_printer(True)('hidden')
    assert capsys.readouterr().out == 'shown 1\n'


def _messages(bag: Path) -> list[tuple[str, int, str]]:
    """Topic, log time and the decoded message's repr (not the raw CDR: its alignment padding is not
    initialised; not the message: NaN fields never compare equal)."""
    with BagReader(bag) as reader:
        return [(m.topic, m.stamp_ns, repr(m.decode())) for m in reader.messages()]


@pytest.mark.parametrize('tool', ['if_to_bag', 'uwb_dataset_to_bag'])
def test_converter_progress_summary_and_quiet(tool, tmp_path, capsys):
    if tool == 'if_to_bag':
        from rfi_experiments.if_to_bag import main
        args = [str(IF_FILE), *IF_OPTIONS]
        first_line = 'if_to_bag pocketsdr_L1_12MHz_I_10ms.bin: 10% (1/10 block), '
        last_line = 'if_to_bag pocketsdr_L1_12MHz_I_10ms.bin: 100% (10/10 block), '
    else:
        from rfi_experiments.uwb_dataset_to_bag import main
        args = [str(HANYANG_CASE)]
        first_line = 'uwb_dataset_to_bag uwb_hanyang_los_a1: 10% ('
        last_line = 'uwb_dataset_to_bag uwb_hanyang_los_a1: 100% ('

    assert main([tool, *args, str(tmp_path / 'loud')]) == 0
    loud = capsys.readouterr()
    progress = loud.err.splitlines()
    assert progress[0].startswith(first_line) and progress[-1].startswith(last_line)
    assert len(progress) == 10 and '\r' not in loud.err  # pytest's stderr is no terminal: plain lines
    assert loud.out.startswith(f'{tool}: wrote {tmp_path / "loud"}\n') and len(loud.out.splitlines()) > 1

    for flag in ('--quiet', '-q'):
        out = tmp_path / f'quiet{flag}'
        assert main([tool, *args, str(out), flag]) == 0
        quiet = capsys.readouterr()
        assert quiet.out == '' and quiet.err == ''
        assert _messages(out) == _messages(tmp_path / 'loud')

    # errors still print with --quiet
    assert main([tool, *args, str(tmp_path / 'loud'), '--quiet']) == 2
    refused = capsys.readouterr()
    assert refused.out == '' and refused.err.startswith(f'{tool}: error: ') and 'exists already' in refused.err


def test_simulate_progress_summary_and_quiet(tmp_path, capsys):
    from rfi_experiments.simulate import main

    path = PKG / 'scenarios' / 'spoofed.yaml'  # 180 s of GNSS and UWB, 14700 messages

    assert main(['simulate', str(path), str(tmp_path / 'loud')]) == 0
    loud = capsys.readouterr()
    lines = loud.err.splitlines()
    assert lines[0].startswith('simulate spoofed: 10% (18/180 s), ') and len(lines) == 10, lines
    assert lines[-1].startswith('simulate spoofed: 100% (180/180 s), '), lines
    assert loud.out.splitlines()[-1].startswith('simulate: wrote ')

    assert main(['simulate', str(path), str(tmp_path / 'quiet'), '--quiet']) == 0
    quiet = capsys.readouterr()
    assert quiet.out == '' and quiet.err == ''
    assert _messages(tmp_path / 'quiet') == _messages(tmp_path / 'loud')

    assert main(['simulate', str(path), str(tmp_path / 'no_progress'), '--no-progress']) == 0
    no_progress = capsys.readouterr()
    assert no_progress.err == '' and no_progress.out.replace('no_progress', 'loud') == loud.out
