"""What the command-line tools of rfi_experiments share: exit codes and the one-line error report.

Every tool (play, record, run, simulate, if_to_bag, rinex_to_bag, ubx_to_bag, uwb_dataset_to_bag) reports a
refused input as ``<prog>: error: <message>`` on stderr, on one line, and exits with :data:`EXIT_USAGE`; a run
that started but failed exits with :data:`EXIT_FAILED`.
"""

from __future__ import annotations

import argparse
import faulthandler
import os
import sys
import threading
from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path
from typing import Any

from rfi_experiments.progress import add_quiet_argument, summary_printer

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


def parse(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> argparse.Namespace | int:
    """Parse a full argument vector (``argv[0]`` is the program name; None: ``sys.argv``): the namespace, or
    argparse's exit code when it stopped (0 after ``--help``, 2 after a usage error it printed)."""
    argv = list(sys.argv if argv is None else argv)
    try:
        return parser.parse_args(argv[1:])
    except SystemExit as stop:
        return int(stop.code or 0)


def ros_namespace(text: str) -> str:
    """An argparse ``type``: a ROS namespace, absolute (``robot1`` -> ``/robot1``; ``/`` is the root).

    Raises:
        argparse.ArgumentTypeError: not a valid ROS namespace (the message says why).
    """
    from rclpy.exceptions import InvalidNamespaceException
    from rclpy.validate_namespace import validate_namespace

    namespace = '/' + text.strip().strip('/')
    try:
        validate_namespace(namespace)
    except InvalidNamespaceException as err:
        raise argparse.ArgumentTypeError(f'not a ROS namespace: {text!r} ({" ".join(str(err).split())})') from None
    return namespace


def output_refusal(out: Path, overwrite: bool) -> str | None:
    """Why a converter must not write ``out`` (it exists and ``--overwrite`` was not given), or None."""
    if out.exists() and not overwrite:
        return f"{out} exists already (remove it or pass --overwrite)"
    return None


def converter_start(parser: argparse.ArgumentParser, argv: Sequence[str] | None,
                    report: Callable[[str], int]) -> tuple[argparse.Namespace, Path] | int:
    """The start of a converter (``args.out`` is the bag to write, ``args.overwrite`` its flag): parse,
    then refuse an existing output. Returns ``(args, out)``, or the exit code to return (argparse's, or
    ``report(reason)``'s)."""
    args = parse(parser, argv)
    if isinstance(args, int):
        return args
    out = Path(args.out)
    refusal = output_refusal(out, args.overwrite)
    return report(refusal) if refusal else (args, out)


def run_converter(parser: argparse.ArgumentParser, argv: Sequence[str] | None, report: Callable[[str], int],
                  errors: tuple[type[BaseException], ...], convert: Callable[[argparse.Namespace, Path], Any],
                  summary: Callable[[argparse.Namespace, Any], Sequence[str]]) -> int:
    """A converter's ``main``: :func:`converter_start`, then ``convert(args, out)``, then the summary.

    The parser gets ``-q/--quiet`` here (:func:`rfi_experiments.progress.add_quiet_argument`): ``convert``
    shows its progress line only without it (``args.quiet``), and the summary is printed only without it.

    Args:
        parser, argv, report: as :func:`converter_start` (``report`` prints a one-line error and returns
            the exit code).
        errors: the exceptions that mean a refused input: ``report(str(err))``'s code is returned.
        convert: writes the bag; returns what the summary needs, or an int: the exit code to return
            (an input with nothing to write, say), without a summary.
        summary: the lines printed after ``<prog>: wrote <out>``.

    Returns:
        0, or the exit code of argparse, ``report`` or ``convert``.
    """
    add_quiet_argument(parser)
    start = converter_start(parser, argv, report)
    if isinstance(start, int):  # --help (0), a usage error (2, argparse printed it) or an existing output
        return start
    args, out = start
    try:
        result = convert(args, out)
    except errors as err:
        return report(str(err))
    if isinstance(result, int):
        return result
    say = summary_printer(args.quiet)
    say(f"{parser.prog}: wrote {out}")
    for line in summary(args, result):
        say(line)
    return 0


TEARDOWN_TIMEOUT_S = 10.0
"""Longest wait for a tool's node and ROS to shut down once its work is done; then the process exits anyway."""


def bounded_teardown(prog: str, executor: Any, node: Any, rclpy: Any) -> None:
    """Remove and destroy ``node`` and shut ROS down in a daemon thread, waiting at most
    :data:`TEARDOWN_TIMEOUT_S`; a hang is reported on stderr and left behind. For a tool's ``main``
    run in process. The executables release their endpoints and end at once (:func:`exit_now`):
    once in several hundred test-suite runs the recorder had written and closed every message and
    still did not exit, also with this bound (session 10's CI: a teardown that hangs in the
    middleware while holding the GIL stops the waiting thread too)."""
    def run() -> None:
        executor.remove_node(node)
        node.destroy_node()
        rclpy.try_shutdown()

    worker = threading.Thread(target=run, name=f'{prog}-teardown', daemon=True)
    worker.start()
    worker.join(TEARDOWN_TIMEOUT_S)
    if worker.is_alive():
        print(f'{prog}: ROS shutdown did not finish within {TEARDOWN_TIMEOUT_S:g} s; exiting anyway',
              file=sys.stderr, flush=True)


def exit_now(main: Callable[[], int]) -> None:
    """Run a tool's ``main`` and end the process at once with its exit code: stdout and stderr are
    flushed, but neither ROS nor the interpreter is shut down (the middleware's threads and
    participants end with the process; other participants see it leave). For the console-script
    entry points, whose ``main`` skips the ROS teardown after :func:`release_endpoints`."""
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def release_endpoints(node: Any, timeout_s: float = TEARDOWN_TIMEOUT_S) -> None:
    """Destroy ``node``'s subscriptions and publishers, so that their peers see them leave at once (a player waiting for
    a recorder's acknowledgements is released), before an executable ends without the ROS teardown
    (:func:`exit_now`). Under a C-level watchdog (``faulthandler``): should the middleware hang here holding the GIL,
    which no Python thread or signal handler can then interrupt, the process prints every thread's stack on stderr
    and exits with status 1 after ``timeout_s``, instead of hanging."""
    faulthandler.dump_traceback_later(timeout_s, exit=True)
    try:
        for sub in list(node.subscriptions):
            node.destroy_subscription(sub)
        for pub in list(node.publishers):
            node.destroy_publisher(pub)
    finally:
        faulthandler.cancel_dump_traceback_later()
