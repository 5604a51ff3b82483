"""The progress line of every long job (converters, ``run``, ``play``, ``simulate``, the benchmarks) and ``--quiet``.

One implementation, two shapes:

* :class:`ProgressLine`: a count towards a total (messages replayed, blocks written, seconds simulated).
  On a terminal it is tqdm's bar, redrawn in place (count, rate, time left). Elsewhere (a log file, a
  pipe, CI) a carriage-return bar would fill the log with thousands of redraws, so it writes a plain line
  each time another ``step_percent`` of the total is done and once at the end:
  ``replay bag: 40% (400/1000 msg), 12.3 s``.
* :class:`CaseLog`: one line per finished case of a benchmark (``[fusion_jamming 3/12] JSR 40 dB: 12.3 s,
  41.0 s in all``), whatever stderr is: a case takes seconds to minutes, so each line is worth keeping.

Both write to stderr; the summaries a job prints at its end go to stdout (:func:`summary_printer`).
``--quiet`` (:func:`add_quiet_argument`) turns off both; errors and warnings still print on stderr.
Elapsed times are wall-clock (``time.monotonic``): they describe the run, never the data.
This module imports only the standard library (tqdm only when a bar is drawn on a terminal), so the
benchmarks can use it with nothing but ``src/rfi_experiments`` on the path.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Iterable, Iterator
from time import monotonic
from types import TracebackType
from typing import Any, TextIO, TypeVar

T = TypeVar('T')

QUIET_HELP = 'print no progress line and no summary (errors and warnings still print on stderr)'


def add_quiet_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``-q/--quiet`` (``args.quiet``) to a tool's parser, with the one help text every tool shares."""
    parser.add_argument('-q', '--quiet', action='store_true', help=QUIET_HELP)


def summary_printer(quiet: bool) -> Callable[..., None]:
    """``print`` (to stdout), or a function that prints nothing when ``quiet``:
    ``say = summary_printer(args.quiet)``."""
    if quiet:
        return lambda *args, **kwargs: None
    return print


def is_terminal(stream: TextIO) -> bool:
    """Whether ``stream`` is a terminal (a closed or detached stream is not)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


def format_duration(seconds: float) -> str:
    """``12.3 s`` under a minute, ``4 min 05 s`` under an hour, ``1 h 02 min`` beyond."""
    if seconds < 60:
        return f'{seconds:.1f} s'
    if seconds < 3600:
        return f'{int(seconds // 60)} min {int(seconds % 60):02d} s'
    return f'{int(seconds // 3600)} h {int(seconds % 3600 // 60):02d} min'


class ProgressLine:
    """A count towards ``total`` shown on stderr while a job runs (see the module docstring).

    Args:
        desc: what is being done, the line's prefix (``replay default.mcap``).
        total: the count at the end, or None when it is not known (off a terminal, a line is then written
            every ``every_s`` seconds and at the end).
        unit: the unit of the count (``msg``, ``block``, ``s``).
        enabled: False (``--quiet``, ``--no-progress``): nothing is written.
        stream: where the line goes (default ``sys.stderr``, looked up at construction).
        terminal: draw a bar redrawn in place (default: whether ``stream`` is a terminal).
        step_percent: off a terminal, a line each time this much more of ``total`` is done.
        every_s: off a terminal with no total, a line at most this often.
        clock: seconds, monotonic (tests pass a fake one).

    ``total`` may be set until the first count. Usable as a context manager (closed on exit) and through
    :meth:`iterate`.
    """

    def __init__(self, desc: str, total: int | None = None, unit: str = 'it', *, enabled: bool = True,
                 stream: TextIO | None = None, terminal: bool | None = None, step_percent: float = 10.0,
                 every_s: float = 30.0, clock: Callable[[], float] = monotonic) -> None:
        if not step_percent > 0:
            raise ValueError(f'step_percent must be > 0 (got {step_percent})')
        self.desc = desc
        self.total = total if total is None else max(0, int(total))
        self.unit = unit
        self.enabled = enabled
        self.stream = sys.stderr if stream is None else stream
        self.terminal = is_terminal(self.stream) if terminal is None else terminal
        self.step_percent = step_percent
        self.every_s = every_s
        self.clock = clock
        self.done = 0
        self.closed = False
        self._start = clock()
        self._next_percent = step_percent
        self._last_line_at = self._start
        self._bar: Any = None  # tqdm's, made at the first count (``total`` may be set until then)

    @property
    def elapsed_s(self) -> float:
        """Seconds since the line was made."""
        return self.clock() - self._start

    def update(self, n: int = 1) -> None:
        """``n`` more done."""
        self.set_done(self.done + n)

    def set_done(self, done: int) -> None:
        """The count is now ``done`` (for jobs that know where they are rather than how much they did)."""
        step = done - self.done
        self.done = done
        if not self.enabled or self.closed:
            return
        if self.terminal:
            if self._bar is None:
                from tqdm import tqdm
                self._bar = tqdm(total=self.total, unit=self.unit, desc=self.desc, file=self.stream, mininterval=0.5)
            if step > 0:
                self._bar.update(step)
            return
        if self.total:
            percent = 100.0 * done / self.total
            if percent >= self._next_percent and done < self.total:
                self._write()
                while self._next_percent <= percent:
                    self._next_percent += self.step_percent
        elif self.every_s > 0 and self.clock() - self._last_line_at >= self.every_s:
            self._write()

    def close(self) -> None:
        """End the line: the bar is closed, or (off a terminal) the last line written. Idempotent."""
        if self.closed:
            return
        self.closed = True
        if not self.enabled:
            return
        if self.terminal:
            if self._bar is not None:
                self._bar.close()
        else:
            self._write()

    def iterate(self, items: Iterable[T]) -> Iterator[T]:
        """Yield ``items``, one count each, and close the line at the end."""
        try:
            for item in items:
                yield item
                self.update(1)
        finally:
            self.close()

    def line(self) -> str:
        """The text of an off-terminal line: ``desc: 40% (400/1000 msg), 12.3 s``."""
        if self.total:
            count = f'{100.0 * self.done / self.total:.0f}% ({self.done}/{self.total} {self.unit})'
        else:
            count = f'{self.done} {self.unit}'
        return f'{self.desc}: {count}, {format_duration(self.elapsed_s)}'

    def _write(self) -> None:
        self._last_line_at = self.clock()
        print(self.line(), file=self.stream, flush=True)

    def __enter__(self) -> ProgressLine:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()


class CaseLog:
    """One stderr line per finished case of a long job (a benchmark's rows), and its summary on stdout.

    Args:
        name: the job (the benchmark's file stem).
        total: the number of cases, or None when not known beforehand.
        quiet: write nothing (``--quiet``).
        stream, out: where the case lines and the summary go (default ``sys.stderr``, ``sys.stdout``).
        clock: seconds, monotonic.
    """

    def __init__(self, name: str, total: int | None = None, *, quiet: bool = False, stream: TextIO | None = None,
                 out: TextIO | None = None, clock: Callable[[], float] = monotonic) -> None:
        self.name = name
        self.total = total
        self.quiet = quiet
        self.stream = sys.stderr if stream is None else stream
        self.out = sys.stdout if out is None else out
        self.clock = clock
        self.cases = 0
        self._start = clock()
        self._last = self._start

    @property
    def elapsed_s(self) -> float:
        """Seconds since the log was made."""
        return self.clock() - self._start

    def done(self, label: str) -> float:
        """Case ``label`` is finished: write ``[name i/total] label: <its time>, <time so far> in all``.
        Returns the case's seconds (since the previous case, or the start)."""
        now = self.clock()
        case_s, self._last = now - self._last, now
        self.cases += 1
        if not self.quiet:
            count = f'{self.cases}/{self.total}' if self.total else f'{self.cases}'
            print(f'[{self.name} {count}] {label}: {format_duration(case_s)}, '
                  f'{format_duration(now - self._start)} in all', file=self.stream, flush=True)
        return case_s

    def cases_of(self, items: Iterable[T], label: Callable[[T], str] = str) -> Iterator[T]:
        """Yield ``items``; each one is a case, finished when the loop asks for the next."""
        for item in items:
            yield item
            self.done(label(item))

    def say(self, *args: object) -> None:
        """``print(*args)`` to the summary's stream, unless quiet (a benchmark's tables on stdout)."""
        if not self.quiet:
            print(*args, file=self.out, flush=True)

    def finish(self, *lines: str) -> None:
        """The summary on stdout: ``name: N cases in <time>`` and then ``lines`` (what was written where)."""
        if self.quiet:
            return
        print(f'{self.name}: {self.cases} case{"" if self.cases == 1 else "s"} in {format_duration(self.elapsed_s)}',
              file=self.out, flush=True)
        for line in lines:
            print(line, file=self.out, flush=True)
