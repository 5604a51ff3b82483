"""What the command-line tools of rfi_experiments share: exit codes and the one-line error report.

Every tool (play, record, run, simulate, rinex_to_bag, uwb_dataset_to_bag) reports a refused input
as ``<prog>: error: <message>`` on stderr, on one line, and exits with :data:`EXIT_USAGE`; a run
that started but failed exits with :data:`EXIT_FAILED`.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from functools import partial

EXIT_FAILED = 1
"""Exit code of a run that started but failed (a node died, messages were lost)."""
EXIT_USAGE = 2
"""Exit code of a refused input: bad arguments, unreadable files (argparse's code too)."""


def fail(prog: str, message: object, code: int = EXIT_USAGE) -> int:
    """Print ``{prog}: error: {message}`` on stderr, whitespace runs folded to one space; return ``code``."""
    print(f"{prog}: error: {' '.join(str(message).split())}", file=sys.stderr)
    return code


def error_reporter(prog: str) -> Callable[..., int]:
    """:func:`fail` bound to one tool: ``fail = error_reporter('play')``, then ``return fail('...')``."""
    return partial(fail, prog)
