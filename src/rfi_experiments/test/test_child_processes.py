"""stop_processes: the signal first, SIGKILL only for a process still there after the timeout."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

from rfi_experiments.child_processes import stop_processes

IGNORES_SIGINT = ('import signal, time\nsignal.signal(signal.SIGINT, signal.SIG_IGN)\nprint("ready", flush=True)\n'
                  'time.sleep(60)')
EXITS_ON_SIGINT = ('import signal, sys, time\nsignal.signal(signal.SIGINT, lambda *_: sys.exit(0))\n'
                   'print("ready", flush=True)\ntime.sleep(60)')
"""(its own handler: a child of a shell's background job inherits SIGINT ignored)"""


def _start(code: str) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == 'ready'
    return proc


def test_a_process_that_takes_the_signal_exits_by_it_and_one_that_ignores_it_is_killed():
    polite, deaf = _start(EXITS_ON_SIGINT), _start(IGNORES_SIGINT)
    t0 = time.monotonic()
    codes = stop_processes([polite, deaf], timeout_s=1.0)
    assert codes[0] == 0
    assert codes[1] == -signal.SIGKILL
    assert time.monotonic() - t0 < 30       # not the children's 60 s
    for proc in (polite, deaf):
        assert proc.stdout is not None
        proc.stdout.close()


def test_already_ended_processes_keep_their_exit_code():
    done = subprocess.Popen([sys.executable, '-c', 'raise SystemExit(3)'])
    done.wait()
    assert stop_processes([done], sig=signal.SIGTERM) == [3]
