"""The progress line and --quiet of `play` and `run` (issue 30 item 5), run as a user runs them: the progress on
stderr (plain lines, stderr being a pipe here), the summary on stdout, and with --quiet neither, the warnings still
on stderr and the replay's outputs unchanged."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from ament_index_python.packages import get_package_prefix
from sample_bag import write_sample_bag

from rfi_node_common import testing

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / 'bags' / 'default'
PARAMS = ROOT / 'bags' / 'default.params.yaml'


def tool(name: str) -> str:
    return os.path.join(get_package_prefix('rfi_experiments'), 'lib', 'rfi_experiments', name)


def test_play_progress_summary_and_quiet(tmp_path):
    path = tmp_path / 'sample'
    counts = write_sample_bag(path, seconds=1.0)
    total = sum(counts.values())
    command = [tool('play'), str(path), '--max', '--wait-subscribers', '0.2']

    loud = testing.run_process(command, text=True)
    assert loud.returncode == 0, loud.stderr
    progress = [line for line in loud.stderr.splitlines() if line.startswith('play: ') and '% (' in line]
    assert progress[-1].startswith(f'play: 100% ({total}/{total} msg), '), loud.stderr
    assert len(progress) == 10 and '\r' not in loud.stderr
    assert any(line.split()[0] == 'total' for line in loud.stdout.splitlines()), loud.stdout

    quiet = testing.run_process([*command, '--quiet'], text=True)
    assert quiet.returncode == 0, quiet.stderr
    assert quiet.stdout == ''
    assert '% (' not in quiet.stderr
    # the warnings still print: every message went to nobody
    assert 'published while no subscriber was matched (lost)' in quiet.stderr


@pytest.mark.slow
def test_run_progress_summary_and_quiet(tmp_path, capsys):
    """Two in-process replays of 3 s of bags/default (--no-report: counts only), in this process: the nodes'
    compilation and imports are paid once."""
    from rfi_experiments.run import main

    base = ['run', str(BAG), '--params-file', str(PARAMS), '--transport', 'direct', '--duration', '3', '--no-report']
    assert main([*base, '--out', str(tmp_path / 'loud')]) == 0
    loud = capsys.readouterr()
    progress = [line for line in loud.err.splitlines() if line.startswith('replay default: ')]
    assert progress and progress[-1].startswith('replay default: 100% ('), loud.err[-3000:]
    assert 'replayed through rfi_monitor' in loud.out and 'counts and diagnostics written to' in loud.out

    assert main([*base, '--out', str(tmp_path / 'quiet'), '--quiet']) == 0
    quiet = capsys.readouterr()
    assert quiet.out == ''
    assert 'replay default: ' not in quiet.err and 'Traceback' not in quiet.err

    def counts(out: Path) -> list[str]:  # the table of replay.md (its first lines hold the wall time)
        return [line for line in (out / 'replay.md').read_text().splitlines() if line.startswith('| /')]

    assert counts(tmp_path / 'quiet') == counts(tmp_path / 'loud') != []
