"""The processes of a ``run --transport processes`` (pure standard library and ament_index): where a node's
executable is, and the child processes started, logged and stopped in order."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO


class RunError(RuntimeError):
    """A replay could not be completed; the message says what is missing and where to look."""


def executable_path(package: str, name: str) -> str:
    """Where ``ros2 run package name`` looks: ``<prefix of package>/lib/<package>/<name>`` (as tools/ros2_run).

    Raises:
        RunError: the package is not in the ament index or has no such executable.
    """
    from ament_index_python.packages import PackageNotFoundError, get_package_prefix

    try:
        prefix = get_package_prefix(package)
    except PackageNotFoundError:
        raise RunError(f'package {package!r} not found (is install/setup.bash sourced?)') from None
    path = os.path.join(prefix, 'lib', package, name)
    if not os.access(path, os.X_OK):
        raise RunError(f'no executable {name!r} in package {package!r} ({path})')
    return path


def stop_processes(procs: Sequence[subprocess.Popen], timeout_s: float = 10.0,
                   sig: int = signal.SIGINT) -> list[int]:
    """``sig`` to every process still running, then SIGKILL to each not gone ``timeout_s`` after it; returns the
    exit codes in order (negative: killed by that signal)."""
    for proc in procs:
        if proc.poll() is None:
            proc.send_signal(sig)
    deadline = time.monotonic() + timeout_s
    codes = []
    for proc in procs:
        try:
            codes.append(proc.wait(timeout=max(0.0, deadline - time.monotonic())))
        except subprocess.TimeoutExpired:
            proc.kill()
            codes.append(proc.wait())
    return codes


class ChildProcesses:
    """The processes a ``processes`` run starts: each in its own session (a Ctrl-C reaches only this
    process, which then stops them in order), its output in ``log_dir/<name>.log``."""

    def __init__(self, log_dir: Path) -> None:
        self.log_dir = log_dir
        self.procs: dict[str, subprocess.Popen] = {}
        self._logs: dict[str, TextIO] = {}

    def start(self, name: str, command: list[str], *, stderr_to_terminal: bool = False,
              inherit_stdin: bool = False) -> subprocess.Popen:
        """Start ``command``; its standard input is this process's with ``inherit_stdin`` (if_source reading
        ``-``), else none."""
        self.log_dir.mkdir(parents=True, exist_ok=True)
        log = open(self.log_dir / f'{name}.log', 'w')  # noqa: SIM115 (closed in stop())
        self._logs[name] = log
        log.write('$ ' + ' '.join(command) + '\n')
        log.flush()
        proc = subprocess.Popen(command, stdin=None if inherit_stdin else subprocess.DEVNULL, stdout=log,
                                stderr=None if stderr_to_terminal else subprocess.STDOUT, start_new_session=True)
        self.procs[name] = proc
        return proc

    def log_tail(self, name: str, lines: int = 8) -> str:
        try:
            text = (self.log_dir / f'{name}.log').read_text(errors='replace').splitlines()
        except OSError:
            return ''
        return '\n'.join('    ' + line for line in text[-lines:])

    def check_alive(self, names: Sequence[str]) -> None:
        """Raise RunError if one of ``names`` has exited (with the end of its log)."""
        for name in names:
            code = self.procs[name].poll()
            if code is not None:
                raise RunError(f'{name} exited early with code {code}; the end of {self.log_dir / name}.log:\n'
                               + self.log_tail(name))

    def stop(self, timeout_s: float = 10.0, while_waiting: Any = None) -> dict[str, int]:
        """SIGINT to every process still running, then SIGKILL to those not gone after ``timeout_s``;
        return each process's exit code (negative: killed by that signal). ``while_waiting()`` is called
        repeatedly until they have exited (e.g. to keep recording what they publish while stopping)."""
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        deadline = time.monotonic() + timeout_s
        codes: dict[str, int] = {}
        try:
            while while_waiting is not None and time.monotonic() < deadline and any(
                    p.poll() is None for p in self.procs.values()):
                while_waiting()
            for name, proc in self.procs.items():
                try:
                    codes[name] = proc.wait(timeout=max(0.0, deadline - time.monotonic()))
                except subprocess.TimeoutExpired:
                    proc.kill()
                    codes[name] = proc.wait()
        finally:  # also on a second Ctrl-C while waiting: no process is left behind
            for name, proc in self.procs.items():
                if proc.poll() is None:
                    proc.kill()
                    codes[name] = proc.wait()
            for log in self._logs.values():
                log.close()
        return codes
