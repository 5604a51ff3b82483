"""``ros2 run rfi_experiments simulate SCENARIO OUT``: generate a jamming experiment as a bag.

A scenario is a small YAML file (see ``scenarios/`` in this package's share directory): a seed, a
duration, the timeline (a ``start`` in GPS time and one ``jamming`` schedule that every stream
derives from, see :mod:`rfi_experiments.scenario`) and one section per input stream (IF
snapshots, GNSS measurements and UWB ranges, correlators). The run is reproducible: the same file gives the same
bag, message for message and field for field (not byte for byte: rclpy's serialiser leaves the
CDR alignment padding uninitialised, so the padding bytes may differ between two runs).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from rfi_experiments.bag_io import BagError
from rfi_experiments.cli import error_reporter
from rfi_experiments.progress import ProgressLine, add_quiet_argument, summary_printer
from rfi_experiments.scenario import ScenarioError, load_scenario, scenario_path, write_scenario_bag

fail = error_reporter('simulate')


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='simulate', description='Generate a jamming experiment bag from a scenario.')
    parser.add_argument('scenario', help='scenario YAML file, or the name of one shipped with the package '
                                         '(e.g. "default")')
    parser.add_argument('out', help='bag directory to write')
    parser.add_argument('--overwrite', action='store_true', help='replace an existing bag')
    parser.add_argument('--no-progress', action='store_true', help='no progress line')
    add_quiet_argument(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv if argv is None else argv)
    args = build_parser().parse_args(argv[1:])
    try:
        path = scenario_path(args.scenario)
        scenario = load_scenario(path)
        progress = ProgressLine(f'simulate {scenario.name}', unit='s', enabled=not (args.no_progress or args.quiet))
        counts = write_scenario_bag(scenario, Path(args.out), overwrite=args.overwrite, progress=progress)
    except (ScenarioError, BagError) as err:
        return fail(err)
    say = summary_printer(args.quiet)
    width = max((len(t) for t in counts), default=5)
    for topic, n in sorted(counts.items()):
        say(f'{topic:<{width}}  {n:>8}')
    say(f'simulate: wrote {sum(counts.values())} messages to {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
