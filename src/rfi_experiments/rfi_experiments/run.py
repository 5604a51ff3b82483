"""``ros2 run rfi_experiments run BAG --out DIR``: replay a jamming experiment through the suite.

The four nodes (rfi_monitor, gnss_integrity, uwb_gnss_fusion, imm_carrier with ``method: both``) are wired by
their topics exactly as on a robot, in one of three ways (``--transport``):

- ``direct`` (default) and ``dds``: the nodes run in this process and the bag's messages are fed
  through them by :class:`rfi_experiments.replay.ReplayHarness` (deterministic, nothing dropped),
  handed over in-process (the same callbacks, much faster) or over the middleware on one
  SingleThreadedExecutor;
- ``processes``: the three node executables run as separate processes (resolved through the
  ament index as ``ros2 run`` does, ``--ros-args --params-file`` for the parameters files, each
  input subscription made reliable with ``qos_overrides.<topic>.subscription.reliability``, then
  the caller's ``--ros-args``), ``play`` feeds them the bag at ``--rate`` once each input topic has
  its subscriber (after a slow warm-up, see :func:`run_processes`), and this process records their
  outputs (reliable, keep-all subscriptions) until every node has answered its last input; then the
  nodes are stopped with SIGINT (killed if they do not exit), also on Ctrl-C, SIGTERM or an error,
  and what they publish while stopping is still recorded. ``--namespace /robot1`` runs the whole
  suite (nodes, ``play``, the recorder) under a namespace, so that several suites run side by side
  in one domain; ``--external-nodes`` starts no node but replays to and records from nodes already
  running (on another host, say).

With ``--with-correlator`` (processes only) gnss_correlator_node runs beside them on the same
``/rfi/if_samples`` and feeds imm_carrier its ``/gnss/correlators`` (the bag's own are not played); with
``--if-input FILE`` instead of a bag (a capture file, ``-`` for standard input or a named pipe: a live SDR) if_source
feeds the IF stream's nodes (the monitor, and with the correlator gnss_correlator and imm_carrier) with the format
of the ``if_source:`` section of a ``--params-file``: the one command from an SDR or a capture to jammer state and
carrier phase (docs/guide/if_to_carrier.md). Without a bag there is no truth to score against: ``replay.md`` then
holds the counts, the diagnostics and a per-satellite table of the carrier phase estimates.

After the last input the in-process transports call each node's ``end_of_input()`` (the fusion
node then processes what its re-ordering buffer holds); a node process does the same by itself
when its input stops (the fusion's ``idle_flush_s``).

A window of the bag can be replayed (``--start``, ``--duration``). At the end a summary table is
printed and a report folder written: ``index.md`` with figures (rfi_experiments.report, scored on
the replayed window) and the same as one self-contained web page, ``index.html`` (with
``replay.html``), ``summary.json`` and ``replay.md`` (per-topic counts, the nodes' final
diagnostics, where the time went); with ``processes`` also ``logs/`` (the output of each process).
``--no-report`` writes only ``replay.md`` (and ``--record-outputs``).
The summary and the report end with a warning when the fusion node rejected messages as later than
its re-ordering window, or a node counted input messages lost (:func:`delivery_warnings`).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rfi_experiments.bag_io import BagError, BagReader
from rfi_experiments.cli import error_reporter, ros_namespace
from rfi_experiments.play import LATE_REASON, add_window_arguments, window_ns, window_s
from rfi_experiments.processes import (
    NODE_ENDPOINTS,
    PROCESSES_DEFAULT_RATE,
    RunError,
    reliable_input_arguments,
    ros_arguments,
    run_processes,
)
from rfi_experiments.progress import ProgressLine, add_quiet_argument, summary_printer

fail = error_reporter('run')

REPORT_TOPICS = ('/rfi/jammer_state', '/gnss/integrity', '/fusion/odometry', '/fusion/status', '/carrier/estimates')


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='run', description=__doc__.splitlines()[0].split(': ', 1)[1])
    parser.add_argument('bag', nargs='?', default=None, help='bag directory (mcap); none with --if-input')
    parser.add_argument('--out', default='report', help='report folder to write (default: report)')
    parser.add_argument('--rate', type=float, default=None,
                        help='replay pace as a multiple of real time (default: as fast as possible with direct and '
                             f'dds, which never drop or reorder; {PROCESSES_DEFAULT_RATE:g} with processes: measured '
                             'on bags/default to give the direct transport\'s outputs field for field; faster, the '
                             'fusion can get jammer states after its 0.1 s re-ordering window)')
    parser.add_argument('--transport', choices=('direct', 'dds', 'processes'), default='direct',
                        help='direct: the nodes\' callbacks get the messages handed over in-process (default, '
                             'fast); dds: the nodes talk over the middleware on one executor, as separate nodes '
                             'on a robot do (about a millisecond per hop here); processes: the node executables '
                             'run as separate processes that `play` feeds, and this process records their outputs')
    add_window_arguments(parser)
    parser.add_argument('--timeout', type=float, default=60.0, metavar='SECONDS',
                        help='processes: longest wait for the node processes to come up, and for the last outputs '
                             'after play has finished (default 60)')
    parser.add_argument('--record-outputs', metavar='BAG',
                        help='also write every message the nodes published to this (new) mcap bag, in the order '
                             'received (log time: the run\'s start plus the receive index, ns)')
    parser.add_argument('--warmup', type=float, default=0.5, metavar='SECONDS',
                        help='processes: play the first SECONDS of the bag at --warmup-rate, the rest at --rate, so '
                             'that the nodes\' first-call costs (numba, imports) do not pile up a backlog (default '
                             '0.5; 0: none)')
    parser.add_argument('--warmup-rate', type=float, default=0.1, metavar='RATE',
                        help='processes: pace of the warm-up, x real time (default 0.1)')
    parser.add_argument('--settle', type=float, default=1.0, metavar='SECONDS',
                        help='processes: the run is complete once every node has answered its last input and '
                             'nothing has been published for this long (default 1)')
    parser.add_argument('--params-file', action='append', default=[], metavar='YAML',
                        help='ROS 2 parameters file (node_name: ros__parameters: ...; "/**" for all nodes), '
                             'e.g. the one shipped beside a bag; may be given more than once')
    parser.add_argument('--namespace', type=ros_namespace, default='/', metavar='NS',
                        help='processes: run the suite under this ROS namespace (e.g. /robot1): the nodes get '
                             '-r __ns:=NS and their /diagnostics at NS/diagnostics, play publishes to NS/<topic>, '
                             'the outputs are recorded from there; several suites with different namespaces run '
                             'side by side in one ROS domain without seeing each other (default: /, the root)')
    parser.add_argument('--external-nodes', action='store_true',
                        help='processes: start no node; replay to and record from rfi_monitor, uwb_gnss_fusion and '
                             'imm_carrier already running in --namespace (e.g. on another host, see '
                             'docs/guide/deployment.md), their inputs reliable '
                             '(-p qos_overrides.<topic>.subscription.reliability:=reliable)')
    parser.add_argument('--with-correlator', action='store_true',
                        help='processes: also start gnss_correlator_node on /rfi/if_samples; its /gnss/correlators '
                             'feed imm_carrier (the bag\'s own /gnss/correlators are not played). Its parameters '
                             '(spectrum_inverted, ...) from a --params-file section gnss_correlator:')
    parser.add_argument('--if-input', metavar='FILE|-',
                        help='processes, instead of a bag: feed the IF stream\'s nodes (rfi_monitor; with '
                             '--with-correlator also gnss_correlator and imm_carrier) from if_source reading this '
                             'capture file, "-" (standard input) or named pipe, in the format given by the '
                             'if_source: section of a --params-file (item_type, sampling_frequency_hz, ...; '
                             'docs/guide/if_to_carrier.md); ends at the end of the input')
    parser.add_argument('--no-report', action='store_true',
                        help='write only replay.md (counts, diagnostics) and --record-outputs, no figures or scores '
                             '(index.md, summary.json): about 10 s less per run')
    parser.add_argument('--no-progress', action='store_true', help='no progress line')
    add_quiet_argument(parser)
    return parser


def load_params_files(paths: Sequence[str]) -> dict[str, dict[str, object]]:
    """Node name -> {parameter: value} from ROS 2 parameters files ('/**' applies to every node).

    Raises:
        ValueError: a file is missing or not in the ROS 2 parameters-file layout.
    """
    import yaml

    merged: dict[str, dict[str, object]] = {}
    for path in paths:
        try:
            data = yaml.safe_load(Path(path).read_text())
        except (OSError, yaml.YAMLError) as err:
            raise ValueError(f'cannot read parameters file {path}: {err}') from None
        if not isinstance(data, dict):
            raise ValueError(f'{path}: not a ROS 2 parameters file (expected node_name: ros__parameters: ...)')
        for node, section in data.items():
            params = section.get('ros__parameters') if isinstance(section, dict) else None
            if not isinstance(params, dict):
                raise ValueError(f'{path}: node {node!r} has no ros__parameters mapping')
            merged.setdefault(str(node).lstrip('/'), {}).update(params)
    return merged


def overrides_for(node_name: str, params: dict[str, dict[str, object]]) -> list:
    """rclpy Parameter overrides of one node: the '/**' (or '**') entries, then its own."""
    from rclpy.parameter import Parameter

    values = {**params.get('**', {}), **params.get(node_name, {})}
    return [Parameter(name, value=value) for name, value in values.items()]


def diagnostics_summary(messages: list) -> dict[str, dict[str, str]]:
    """Last key/values reported by each status name on /diagnostics."""
    last: dict[str, dict[str, str]] = {}
    for array in messages:
        for status in array.status:
            last[status.name] = {kv.key: kv.value for kv in status.values} | {'message': status.message}
    return last


def write_outputs_bag(result: Any, path: str) -> None:
    """Write every output of a replay (ReplayResult) to a new bag, in receive order across topics.

    Raises:
        BagError: the bag exists or cannot be written.
    """
    from rfi_experiments.bag_io import BagWriter

    items = sorted((i, topic, m) for topic, messages in result.outputs.items() for i, m in messages)
    t0 = time.time_ns()
    with BagWriter(path) as bag:
        for i, topic, m in items:
            if isinstance(m, bytes):
                bag.write_raw(topic, result.output_types[topic], m, t0 + i)
            else:
                bag.write(topic, m, t0 + i)


def delivery_warnings(result: Any) -> list[str]:
    """What the nodes say they lost or rejected for coming too late, from their last /fusion/status and
    /diagnostics (empty: nothing): the fusion's rejections of messages that came after its re-ordering
    window, and the input messages each node counted lost (per node and topic the larger of the publisher
    sequence gaps and the middleware's count, which see the same losses: ``rfi_node_common.inputs``)."""
    warnings = []
    diagnostics = diagnostics_summary(result.messages('/diagnostics')) if '/diagnostics' in result.outputs else {}
    fusion = diagnostics.get('uwb_gnss_fusion', {})
    late = int(fusion.get(f'rejected.{LATE_REASON}', 0))
    statuses = result.outputs.get('/fusion/status')
    if statuses:
        last = result.messages('/fusion/status')[-1]
        late = max(late, dict(zip(last.rejection_reasons, last.rejection_counts, strict=False)).get(LATE_REASON, 0))
    if late:
        window = fusion.get('reorder_window_s')
        grown = f' (its window is now {float(window):g} s)' if window is not None else ''
        warnings.append(f'the fusion node rejected {late} messages that reached it later than its re-ordering '
                        f'window{grown}: the nodes lagged behind the replay (load, or a --rate too high), so the '
                        'outputs differ from a replay in one process')
    lost: dict[str, int] = {}
    for values in diagnostics.values():
        node_lost: dict[str, int] = {}  # the gap count and the middleware's count see the same losses: the larger
        for key, value in values.items():
            if key.startswith('input.') and key.endswith(('.lost', '.middleware_lost')):
                topic = key[len('input.'):].rsplit('.', 1)[0]
                try:
                    node_lost[topic] = max(node_lost.get(topic, 0), int(value))
                except ValueError:
                    continue
        for topic, n in node_lost.items():
            lost[topic] = lost.get(topic, 0) + n
    lost = {t: n for t, n in lost.items() if n}
    if lost:
        warnings.append('the nodes counted input messages lost before reaching them: '
                        + ', '.join(f'{t} {n}' for t, n in sorted(lost.items())))
    return warnings


def carrier_summary(messages: list) -> list[str]:
    """A markdown table of /carrier/estimates (rfi_msgs/CarrierPhaseArray, in order): per satellite and method the
    estimates, the stamps of the first and last (s after the first array), the locked fraction of its last 100
    estimates, the cycle slips counted, the last phase and its 1-sigma. Empty without a message."""
    if not messages:
        return []
    t0 = messages[0].header.stamp.sec + messages[0].header.stamp.nanosec * 1e-9
    rows: dict[tuple[int, int, int], list[tuple[float, Any]]] = {}
    for array in messages:
        t = array.header.stamp.sec + array.header.stamp.nanosec * 1e-9 - t0
        for e in array.estimates:
            rows.setdefault((e.constellation, e.svid, e.method), []).append((t, e))
    methods = {1: 'IMM', 2: 'PLL', 3: 'KF'}
    lines = ['| constellation / svid | method | estimates | first / last stamp (s) | locked, last 100 | cycle slips | '
             'last phase (rad) | its 1-sigma (rad) |', '|---|---|---|---|---|---|---|---|']
    for (constellation, svid, method), got in sorted(rows.items()):
        tail = [e.locked for _, e in got[-100:]]
        last = got[-1][1]
        lines.append(f'| {constellation} / {svid} | {methods.get(method, method)} | {len(got)} | '
                     f'{got[0][0]:.3f} / {got[-1][0]:.3f} | {100 * sum(tail) / len(tail):.0f} % | {last.cycle_slips} | '
                     f'{last.phase_rad:.3f} | {last.phase_std_rad:.3f} |')
    return lines


def argument_problem(args: argparse.Namespace, argv: Sequence[str]) -> str | None:
    """What is wrong with run's command line (the message for :func:`fail`), None when nothing is."""
    if args.rate is not None and not (math.isfinite(args.rate) and args.rate > 0):
        return f'--rate must be a finite number > 0 (got {args.rate})'
    for name in ('timeout', 'settle', 'warmup', 'warmup_rate'):
        value = getattr(args, name)
        if not (math.isfinite(value) and (value > 0 or (name == 'warmup' and value == 0))):
            return f'--{name.replace("_", "-")} must be a finite number > 0 (got {value})'
    if args.transport != 'processes' and (args.namespace != '/' or args.external_nodes or args.with_correlator
                                          or args.if_input is not None):
        return '--namespace, --external-nodes, --with-correlator and --if-input apply to --transport processes only'
    if (args.bag is None) == (args.if_input is None):
        return 'give a bag or --if-input FILE (not both)'
    if args.if_input is not None and (args.start != 0.0 or args.duration is not None):
        return '--start and --duration select a window of a bag; with --if-input cut the capture instead'
    if args.external_nodes and args.params_file:
        return ('--params-file sets the parameters of the nodes run starts; with --external-nodes give it to the '
                'nodes themselves (--ros-args --params-file FILE)')
    if any(a.startswith('__ns:=') for a in ros_arguments(argv)):
        return ('give the namespace as --namespace NS (run moves play and its recorder there too), '
                'not as --ros-args -r __ns:=NS')
    return None


def write_replay_document(args: argparse.Namespace, result: Any, inputs: list[str],
                          topics: dict[str, tuple[str, int]], window: tuple[float, float] | None, how: str,
                          notes: list[str], out: Path) -> tuple[str, list[str]]:
    """``out/replay.md``: what was replayed, the message counts per topic, the correlator's carrier phases and
    the nodes' last diagnostics. Returns the one-line account of the replay and the carrier-phase table's lines
    (empty without the correlator)."""
    diagnostics = diagnostics_summary(result.messages('/diagnostics')) if '/diagnostics' in result.outputs else {}
    window_text = '' if window is None else (
        f' (window {window[0]:g}-{"end" if math.isinf(window[1]) else f"{window[1]:g}"} s of the bag)')
    if args.if_input is not None:
        names = 'rfi_monitor' + (', gnss_correlator and imm_carrier' if args.with_correlator else '')
        replay_line = (f'{sum(result.inputs.values())} IF blocks of {args.if_input} through {names} ({how}): '
                       f'{result.bag_duration_s:.3f} s of stream (first to last block stamp) in '
                       f'{result.wall_time_s:.1f} s.')
    else:
        names = ('rfi_monitor, gnss_integrity, uwb_gnss_fusion, ' + ('gnss_correlator ' if args.with_correlator
                                                                     else '') + 'and imm_carrier')
        replay_line = (f'{sum(result.inputs.values())} input messages{window_text} replayed through {names} '
                       f'({how}): {result.bag_duration_s:.1f} s of data in {result.wall_time_s:.1f} s, '
                       f'{result.real_time_factor:.1f}x real time.')
    lines = [f'# Replay of {args.bag or args.if_input}', '', replay_line, '']
    if notes:
        lines += [' '.join(notes), '']
    lines += ['| topic | direction | messages |', '|---|---|---|']
    for t in inputs:
        lines.append(f'| {t} | in | {result.inputs.get(t, 0)} |')
    for t in sorted(result.outputs):
        lines.append(f'| {t} | out | {len(result.outputs[t])} |')
    for t in sorted(set(topics) - set(inputs)):
        lines.append(f'| {t} | truth (not replayed) | {topics[t][1]} |')
    carrier = carrier_summary(result.messages('/carrier/estimates')) if (
        args.with_correlator and '/carrier/estimates' in result.outputs) else []
    if carrier:
        lines += ['', '## Carrier phase from the correlator', '',
                  'Per satellite that gnss_correlator tracked and method of imm_carrier (stamps from the IF stamps, '
                  's after the first estimate; the estimates themselves: --record-outputs):', '', *carrier]
    for name, values in diagnostics.items():
        lines += ['', f'## Diagnostics of {name}', '', '| key | value |', '|---|---|']
        lines += [f'| {k} | {v} |' for k, v in values.items()]
    (out / 'replay.md').write_text('\n'.join(lines) + '\n')
    return replay_line, carrier


def main(argv: Sequence[str] | None = None) -> int:
    from rclpy.utilities import remove_ros_args

    from rfi_experiments.report import write_report

    argv = list(sys.argv if argv is None else argv)
    args = build_parser().parse_args(remove_ros_args(argv)[1:])
    # Synchronous publication: about 3x lower latency per hop for the in-process replay.
    os.environ.setdefault('RMW_FASTRTPS_PUBLICATION_MODE', 'SYNCHRONOUS')
    problem = argument_problem(args, argv)
    if problem is not None:
        return fail(problem)
    try:
        window = window_s(args.start, args.duration)
        params = load_params_files(args.params_file)
    except ValueError as err:
        return fail(str(err))
    params.setdefault('imm_carrier', {}).setdefault('method', 'both')
    if args.if_input is not None:
        if args.if_input != '-' and not Path(args.if_input).exists():
            return fail(f'--if-input {args.if_input}: no such file or named pipe')
        if 'if_source' not in params:
            return fail('--if-input needs the format of the samples: a --params-file with an if_source: section '
                        '(item_type, sampling_frequency_hz, ...; docs/guide/if_to_carrier.md)')
        topics: dict[str, tuple[str, int]] = {}
        replayed_ns: tuple[int | None, int | None] = (None, None)
        inputs = ['/rfi/if_samples']
    else:
        try:
            with BagReader(args.bag) as reader:
                topics = reader.topics
                replayed_ns = window_ns(reader.start_ns, window)
        except BagError as err:
            return fail(str(err))
        # with the correlator, imm_carrier's correlators are its, not the bag's
        inputs = sorted(t for t in topics if not t.startswith('/truth/')
                        and not (args.with_correlator and t == '/gnss/correlators'))
        if not inputs:
            return fail(f'{args.bag} holds no input topics (only {", ".join(sorted(topics)) or "nothing"})')
    if args.record_outputs and Path(args.record_outputs).exists():
        return fail(f'--record-outputs {args.record_outputs} exists already')
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    notes: list[str] = []
    if args.transport == 'processes':
        try:
            result, run = run_processes(args, argv, inputs, params, window, out)
        except (RunError, BagError) as err:
            return fail(str(err))
        except KeyboardInterrupt:
            print('run: interrupted; node processes stopped', file=sys.stderr)
            return 130
        rate = PROCESSES_DEFAULT_RATE if args.rate is None else args.rate
        feeder = f'if_source reading {args.if_input}' if args.if_input is not None else f'play at {rate:g}x'
        how = (f'processes transport: {"external nodes" if args.external_nodes else "node executables"} fed by '
               f'{feeder}' + ('' if args.namespace == '/' else f', namespace {args.namespace}'))
        notes.append(f'Completion: {run.completion}.')
        notes.append('Exit codes after SIGINT: ' + ', '.join(f'{n} {c}' for n, c in run.exit_codes.items())
                     + '. Output of each process: [logs/](logs/).')
        bad = {n: c for n, c in run.exit_codes.items() if c != 0}
        if bad:
            print(f'run: warning: processes did not exit cleanly: {bad} (logs in {out / "logs"})', file=sys.stderr)
    else:
        try:
            result = run_in_process(args, argv, inputs, topics, params, window)
        except ValueError as err:
            return fail(str(err))
        except (BagError, RuntimeError) as err:
            return fail(str(err))
        how = f'{args.transport} transport'
    warnings = delivery_warnings(result)
    for warning in warnings:
        notes.append(f'Warning: {warning}.')
        print(f'run: warning: {warning}', file=sys.stderr)
    if args.record_outputs:
        try:
            write_outputs_bag(result, args.record_outputs)
        except BagError as err:
            return fail(str(err))
    # the correlator's satellites are not the bag's simulated ones: its carrier phases are listed, not scored
    outputs = {t: result.messages(t) for t in REPORT_TOPICS
               if t in result.outputs and not (args.with_correlator and t == '/carrier/estimates')}
    replay_line, carrier = write_replay_document(args, result, inputs, topics, window, how, notes, out)
    say = summary_printer(args.quiet)  # the warnings are on stderr already
    if args.if_input is not None:
        say(replay_line)
        if carrier:
            say()
            for line in carrier:
                say(line)
            say()
        elif args.with_correlator:
            say('no carrier phase estimate: the correlator tracked no satellite (see replay.md, its diagnostics)')
        for warning in warnings:
            say(f'warning: {warning}')
        say(f'counts, diagnostics and carrier phases written to {out / "replay.md"} (no bag: no truth to score)')
        return 0
    if args.no_report:
        say(replay_line)
        for warning in warnings:
            say(f'warning: {warning}')
        say(f'counts and diagnostics written to {out / "replay.md"} (--no-report: no figures, no scores)')
        return 0
    start = time.monotonic()
    header = replay_line + ' Counts and diagnostics: [replay.md](replay.md).'
    if warnings:
        header += ''.join(f'\n\n**Warning**: {w}.' for w in warnings)
    summary = write_report(args.bag, outputs, out, window_ns=replayed_ns, header=header)
    say(replay_line)
    say()
    say(summary.table())
    say()
    for warning in warnings:
        say(f'warning: {warning}')
    say(f'report written to {out / "index.md"} and {out / "index.html"} (figures and tables; evaluation took '
        f'{time.monotonic() - start:.1f} s)')
    return 0


def run_in_process(args: argparse.Namespace, argv: Sequence[str], inputs: list[str],
                   topics: dict[str, tuple[str, int]], params: dict[str, dict[str, object]],
                   window: tuple[float, float] | None) -> Any:
    """The four nodes in this process, fed by ReplayHarness (``direct`` or ``dds``).

    Raises:
        ValueError: a node rejected its parameters (the message names the node).
        BagError, ReplayStalled: the bag cannot be read, or the graph did not settle.
    """
    import rclpy

    from gnss_integrity.gnss_integrity_node import GnssIntegrityNode
    from imm_carrier.imm_carrier_node import ImmCarrierNode
    from rfi_experiments.replay import ReplayHarness
    from rfi_monitor.rfi_monitor_node import RfiMonitorNode
    from uwb_gnss_fusion.fusion_node import FusionNode

    context = rclpy.context.Context()
    rclpy.init(args=list(argv), context=context)
    nodes = []
    try:
        for name, cls in (('rfi_monitor', RfiMonitorNode), ('gnss_integrity', GnssIntegrityNode),
                          ('uwb_gnss_fusion', FusionNode), ('imm_carrier', ImmCarrierNode)):
            # reliable inputs (dds: over the middleware), unless a parameters file says otherwise
            reliable = reliable_input_arguments(NODE_ENDPOINTS[name][0])[1::2]
            defaults = {k: v for k, _, v in (a.partition(':=') for a in reliable) if k not in params.get('**', {})}
            try:
                nodes.append(cls(context=context, parameter_overrides=overrides_for(
                    name, {**params, name: {**defaults, **params.get(name, {})}})))
            except ValueError as err:
                raise ValueError(f'{name}: {err}') from None
        harness = ReplayHarness(nodes, context=context, transport=args.transport)
        with BagReader(args.bag) as reader:
            span_s = reader.duration_ns * 1e-9
        harness_window = None if window is None else (window[0], min(window[1], span_s + 1.0))
        if harness_window is not None:
            with BagReader(args.bag) as reader:
                start_ns, stop_ns = window_ns(reader.start_ns, harness_window)
                n_inputs = sum(1 for _ in reader.messages(inputs, start_ns=start_ns, stop_ns=stop_ns))
        else:
            n_inputs = sum(topics[t][1] for t in inputs)
        with ProgressLine(f'replay {Path(args.bag).name}', n_inputs, 'msg',
                          enabled=not (args.no_progress or args.quiet)) as progress:
            result = harness.run(args.bag, topics=inputs, rate=args.rate, window_s=harness_window,
                                 progress=lambda done, _total: progress.set_done(done))
        harness.destroy()
        return result
    finally:
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


if __name__ == '__main__':
    sys.exit(main())
