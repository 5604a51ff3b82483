#!/usr/bin/env python3
"""Run the test suite several times beside CPU hogs and tally the results (issue 27 item 6).

``make test-loaded RUNS=10`` runs this: it starts ``--hogs`` busy loops (``python3 -c 'while True: pass'``,
default 1: on a 2-core machine the "other core" is busy), runs ``python -m pytest`` ``--runs`` times with
whatever pytest arguments follow ``--`` (every test by default), and prints one line per run (outcome, time,
the ids of the failing tests) and a tally: runs passed, and each failing test with the runs it failed in.
``{run}`` in a pytest argument is replaced by the run's number (``--basetemp=/tmp/loaded/run{run}`` keeps each
run's temporary files apart).
With ``--cold-cache`` every run starts on a cold numba cache, as the first run after a source edit and
``make setup`` does: the cached kernels (``*.nbi``, ``*.nbc`` under ``install/`` and ``$NUMBA_CACHE_DIR``) are
deleted before each run, so the nodes and tests compile them again beside the hogs.
The hogs run at the tests' own priority and are stopped (by their process ids) when the runs end, also on
Ctrl-C and on SIGTERM. Each run's JUnit XML and output go to ``--out`` (default ``log/test_loaded``).

Exit status: 0 when every run passed, 1 otherwise, 2 on bad arguments.

Example (the candidates of a flaky failure, 5 times beside 2 hogs)::

    tools/test_loaded.py --runs 5 --hogs 2 -- test/test_two_suites.py -x -q
    tools/test_loaded.py --runs 3 --hogs 2 --cold-cache -- test/test_executables.py -k starts -q
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path

from rfi_experiments.child_processes import stop_processes

HOG = 'while True: pass'
ROOT = Path(__file__).resolve().parents[1]


def cache_dirs() -> list[Path]:
    """Where the suite's numba caches are: the install tree (``__pycache__`` beside each module) and
    ``$NUMBA_CACHE_DIR`` when it is set."""
    dirs = [ROOT / 'install']
    if os.environ.get('NUMBA_CACHE_DIR'):
        dirs.append(Path(os.environ['NUMBA_CACHE_DIR']))
    return dirs


def drop_numba_caches(dirs: list[Path]) -> int:
    """Delete every numba cache file (``*.nbi`` index, ``*.nbc`` data) under ``dirs``; return how many."""
    n = 0
    for d in dirs:
        if d.is_dir():
            for path in [*d.rglob('*.nbi'), *d.rglob('*.nbc')]:
                path.unlink(missing_ok=True)
                n += 1
    return n


def start_hogs(n: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, '-c', HOG], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL) for _ in range(n)]


def stop_hogs(hogs: list[subprocess.Popen]) -> None:
    stop_processes(hogs, sig=signal.SIGTERM)


def failing_ids(junit: Path) -> list[str]:
    """Ids (``file::name``) of the failed or erroring test cases of a JUnit XML report; [] if it is missing."""
    if not junit.is_file():
        return []
    out = []
    for case in ET.parse(junit).getroot().iter('testcase'):
        if case.find('failure') is not None or case.find('error') is not None:
            path = case.get('classname', '').replace('.', '/')
            out.append(f'{path}.py::{case.get("name")}' if path else str(case.get('name')))
    return out


def summary_line(output: str) -> str:
    """pytest's last line (``== 3 passed, 1 failed in 12.3s ==``), without the rulers."""
    lines = [line.strip('= ').strip() for line in output.splitlines() if line.strip()]
    return lines[-1] if lines else '(no output)'


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    pytest_args: list[str] = []
    if '--' in argv:
        cut = argv.index('--')
        argv, pytest_args = argv[:cut], argv[cut + 1:]
    parser = argparse.ArgumentParser(prog='test_loaded', description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', type=int, default=10, help='times to run the tests (default 10)')
    parser.add_argument('--hogs', type=int, default=1, help='busy loops beside them (default 1)')
    parser.add_argument('--out', type=Path, default=Path('log/test_loaded'), help='JUnit XML and logs of each run')
    parser.add_argument('--cold-cache', action='store_true',
                        help='delete the numba caches before each run (each run compiles every kernel anew)')
    args = parser.parse_args(argv)
    if args.runs < 1 or args.hogs < 0:
        parser.error('--runs must be >= 1 and --hogs >= 0')
    args.out.mkdir(parents=True, exist_ok=True)
    print(f'test_loaded: {args.runs} runs of pytest {" ".join(pytest_args) or "(every test)"} beside {args.hogs} '
          f'busy loop(s) on {os.cpu_count()} CPUs{", cold numba cache" if args.cold_cache else ""}; logs in {args.out}',
          flush=True)
    failures: dict[str, list[int]] = defaultdict(list)
    passed = 0
    # SIGTERM too ends the runs through the ``finally`` below (the pytest run is killed, the hogs stopped): a job
    # started in the background of a non-interactive shell ignores SIGINT
    signal.signal(signal.SIGTERM, lambda signum, _: sys.exit(128 + signum))
    hogs = start_hogs(args.hogs)
    try:
        for run in range(1, args.runs + 1):
            junit = args.out / f'run{run}.xml'
            junit.unlink(missing_ok=True)
            if args.cold_cache:
                print(f'run {run}/{args.runs}: {drop_numba_caches(cache_dirs())} numba cache files deleted',
                      flush=True)
            t0 = time.monotonic()
            done = subprocess.run([sys.executable, '-m', 'pytest', f'--junitxml={junit}',
                                   *(a.replace('{run}', str(run)) for a in pytest_args)],
                                  stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
            (args.out / f'run{run}.log').write_text(done.stdout)
            ids = failing_ids(junit)
            for test_id in ids:
                failures[test_id].append(run)
            ok = done.returncode == 0
            passed += ok
            print(f'run {run}/{args.runs}: {"PASS" if ok else "FAIL"} ({done.returncode}) in '
                  f'{time.monotonic() - t0:.0f} s: {summary_line(done.stdout)}', flush=True)
            for test_id in ids:
                print(f'    failed: {test_id}', flush=True)
    except KeyboardInterrupt:
        print('test_loaded: interrupted', file=sys.stderr)
        return 130
    finally:
        stop_hogs(hogs)
    print(f'test_loaded: {passed} of {args.runs} runs passed beside {args.hogs} busy loop(s)')
    for test_id, runs in sorted(failures.items(), key=lambda kv: (-len(kv[1]), kv[0])):
        print(f'  {test_id}: failed in {len(runs)} run(s) ({", ".join(map(str, runs))})')
    return 0 if passed == args.runs else 1


if __name__ == '__main__':
    sys.exit(main())
