"""The benchmarks' progress: one stderr line per finished case (``[fusion_jamming 3/12] JSR 40 dB: 12.3 s,
41.0 s in all``) and a summary on stdout, neither with ``--quiet`` (``-q``).

A thin layer over :class:`rfi_experiments.progress.CaseLog`, the suite's one implementation of the progress
line; that module imports only the standard library, so it is taken from ``src/rfi_experiments`` when the
install tree is not sourced (the benchmarks run with ``PYTHONPATH=src/<pkg>:...`` too).

    from bench_progress import add_quiet_argument, case_log
    log = case_log(__file__, total=len(CASES), quiet=args.quiet)
    for case in log.cases_of(CASES, label=str): ...
    log.say(table)                      # the tables on stdout, not with --quiet
    log.finish(f'wrote {OUT / "x.md"}')  # "<name>: N cases in <time>", then the lines
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

try:
    from rfi_experiments.progress import CaseLog, add_quiet_argument
except ImportError:  # not on the path: the source tree's copy (the module is pure standard library)
    sys.path.insert(0, str(ROOT / 'src' / 'rfi_experiments'))
    from rfi_experiments.progress import CaseLog, add_quiet_argument

__all__ = ['CaseLog', 'add_quiet_argument', 'case_log', 'quiet_requested']


def quiet_requested(argv: Sequence[str] | None = None) -> bool:
    """Whether ``-q``/``--quiet`` is among the arguments (for the benchmarks that read ``sys.argv`` directly)."""
    return any(a in ('-q', '--quiet') for a in (sys.argv[1:] if argv is None else argv))


def case_log(script: str, total: int | None = None, *, quiet: bool | None = None) -> CaseLog:
    """The case log of a benchmark script (``__file__``; its stem names the lines). ``quiet``: default
    :func:`quiet_requested`."""
    return CaseLog(Path(script).stem, total, quiet=quiet_requested() if quiet is None else quiet)
