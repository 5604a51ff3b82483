"""benchmarks/bench_progress.py, the benchmarks' progress line (issue 30 item 5), works as the benchmarks run: from
the source tree alone (``PYTHONPATH=src/<pkg>:...``, no install tree sourced), -q/--quiet read from the command line."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = """
import bench_progress
log = bench_progress.case_log('/somewhere/fusion_example.py', total=2)
log.done('first')
log.done('second')
log.say('| table |')
log.finish('wrote docs/x.md')
print(sys.modules['rfi_experiments.progress'].__file__, file=sys.stderr)
"""


def _run(*args: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != 'PYTHONPATH'}  # rfi_experiments not installed on the path
    return subprocess.run([sys.executable, '-c', 'import sys\n' + SCRIPT, *args], cwd=ROOT / 'benchmarks', env=env,
                          capture_output=True, text=True, timeout=60)


def test_case_lines_and_summary_from_the_source_tree():
    done = _run()
    assert done.returncode == 0, done.stderr
    err = done.stderr.splitlines()
    assert err[0].startswith('[fusion_example 1/2] first: ') and err[0].endswith(' in all')
    assert err[1].startswith('[fusion_example 2/2] second: ')
    assert err[2] == str(ROOT / 'src' / 'rfi_experiments' / 'rfi_experiments' / 'progress.py')  # the fallback
    out = done.stdout.splitlines()
    assert out[0] == '| table |' and out[1].startswith('fusion_example: 2 cases in ') and out[2] == 'wrote docs/x.md'


def test_quiet_from_the_command_line():
    for flag in ('--quiet', '-q'):
        done = _run(flag)
        assert done.returncode == 0, done.stderr
        assert done.stdout == '' and done.stderr.splitlines()[0].endswith('progress.py')
        assert len(done.stderr.splitlines()) == 1
