"""The benchmarks' progress: one stderr line per finished case (``[fusion_jamming 3/12] JSR 40 dB: 12.3 s,
41.0 s in all``) and a summary on stdout, neither with ``--quiet`` (``-q``).

A thin layer over :class:`rfi_experiments.progress.CaseLog`, the suite's one implementation of the progress
line; that module imports only the standard library (its package's ``__init__`` imports gnss_common's kernel-cache
hook, itself standard library until numba loads), so it is taken from ``src/rfi_experiments`` and ``src/gnss_common``
when the install tree is not sourced (the benchmarks run with ``PYTHONPATH=src/<pkg>:...`` too).

    from bench_progress import add_quiet_argument, case_log
    log = case_log(__file__, total=len(CASES), quiet=args.quiet)
    for case in log.cases_of(CASES, label=str): ...
    log.say(table)                      # the tables on stdout, not with --quiet
    log.finish(f'wrote {OUT / "x.md"}')  # "<name>: N cases in <time>", then the lines
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

try:
    from rfi_experiments.progress import CaseLog, add_quiet_argument
except ImportError:  # not on the path: the source tree's copy (the module is pure standard library)
    for _pkg in ('gnss_common', 'rfi_experiments'):
        if str(ROOT / 'src' / _pkg) not in sys.path:
            sys.path.insert(0, str(ROOT / 'src' / _pkg))
    for _name in [m for m in sys.modules if m == 'rfi_experiments' or m.startswith('rfi_experiments.')]:
        del sys.modules[_name]       # a failed partial import must not be reused
    from rfi_experiments.progress import CaseLog, add_quiet_argument

__all__ = ['CaseLog', 'add_quiet_argument', 'answer_help', 'case_log', 'quiet_requested']


def quiet_requested(argv: Sequence[str] | None = None) -> bool:
    """Whether ``-q``/``--quiet`` is among the arguments (for the benchmarks that read ``sys.argv`` directly)."""
    return any(a in ('-q', '--quiet') for a in (sys.argv[1:] if argv is None else argv))


def answer_help(script: str) -> None:
    """For the benchmarks that read ``sys.argv`` directly: ``-h``/``--help`` prints the script's docstring and
    its ``-q`` option and exits, instead of running the benchmark and rewriting its document; other arguments
    are left to the script."""
    main = sys.modules.get('__main__')
    parser = argparse.ArgumentParser(prog=Path(script).name, description=getattr(main, '__doc__', None),
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_quiet_argument(parser)
    parser.parse_known_args()


def case_log(script: str, total: int | None = None, *, quiet: bool | None = None) -> CaseLog:
    """The case log of a benchmark script (``__file__``; its stem names the lines). ``quiet``: default
    :func:`quiet_requested` (and then ``--help`` answered first: :func:`answer_help`)."""
    if quiet is None:
        answer_help(script)
    return CaseLog(Path(script).stem, total, quiet=quiet_requested() if quiet is None else quiet)
