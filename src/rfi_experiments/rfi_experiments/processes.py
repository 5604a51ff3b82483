"""The ``processes`` transport of ``run``: the three node executables as separate processes fed by ``play``.

The nodes are resolved through the ament index as ``ros2 run`` does (:func:`executable_path`), given
``--ros-args --params-file`` for the parameters files, each input subscription made reliable with
``qos_overrides.<topic>.subscription.reliability`` (:func:`reliable_input_arguments`), then the
caller's ``--ros-args`` (:func:`ros_arguments`). ``play`` feeds them the bag once each input topic
has its subscriber (after a slow warm-up, see :func:`run_processes`), and this process records their
outputs (reliable, keep-all subscriptions) until every node has answered its last input; then the
nodes are stopped with SIGINT (killed if they do not exit), also on Ctrl-C, SIGTERM or an error
(:class:`ChildProcesses`), and what they publish while stopping is still recorded.

With a namespace (``run --namespace /robot1``) the whole suite lives under it: each node gets
``-r __ns:=/robot1`` (its data topics are relative names) and ``-r /diagnostics:=/robot1/diagnostics``
(the status names are the node names, the same in every suite, so the recorder must read its own
suite's reports apart), ``play`` publishes into it (``-r /rfi/if_samples:=/robot1/rfi/if_samples``
and so on) and the recorder subscribes there (:func:`suite_topic`): two suites side by side in one
domain do not see each other. With external nodes (``run --external-nodes``) the nodes are not
started here but expected in the graph (started on another host, say: see
docs/guide/deployment.md) with reliable inputs; ``play`` and the recorder run here as usual.

With the correlator (``run --with-correlator``) gnss_correlator_node is started too: it takes the same
``/rfi/if_samples`` as the monitor and publishes the ``/gnss/correlators`` that imm_carrier tracks, so the bag's own
``/gnss/correlators`` (a simulator's) are not played. With an IF input instead of a bag (``run --if-input FILE``, a
capture file, ``-`` for standard input, or a named pipe) ``if_source`` takes play's place and only the nodes of the
IF stream run: the monitor, and with the correlator also gnss_correlator and imm_carrier (:func:`suite_nodes`);
if_source gets the same ``--params-file`` files (its ``if_source:`` section: the format) and waits for its
subscribers. The run ends when if_source has ended (end of the file or of the pipe) and each node has answered the
last block (:func:`if_source_segment`).
"""

from __future__ import annotations

import argparse
import math
import os
import re
import signal
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rfi_experiments.bag_io import BagReader
from rfi_experiments.child_processes import ChildProcesses, RunError, executable_path
from rfi_experiments.play import window_ns, window_s

PROCESSES_DEFAULT_RATE = 1.0
"""Default pace of ``--transport processes``, x real time. Measured on the whole of bags/default
(2 shared cores, two runs each): at 1x every output equals the direct transport's, field for
field; at 3x (2.3-2.6x real time end to end) one or two of 11694 /fusion/status messages carried a
cumulative rejection count one lower (a jammer state that the fusion rejects on arrival came after
them), all else equal. Faster still, messages can reach the fusion after its 0.1 s re-ordering
window and be rejected."""

NODE_EXECUTABLES = (('rfi_monitor', 'rfi_monitor', 'rfi_monitor_node'),
                    ('gnss_integrity', 'gnss_integrity', 'gnss_integrity_node'),
                    ('uwb_gnss_fusion', 'uwb_gnss_fusion', 'fusion_node'),
                    ('imm_carrier', 'imm_carrier', 'imm_carrier_node'))
"""(node name, package, executable) of the suite's nodes."""

CORRELATOR_EXECUTABLE = ('gnss_correlator', 'gnss_correlator', 'gnss_correlator_node')
"""(node name, package, executable) of the correlator, started with ``--with-correlator``."""

IF_STREAM_NODES = ('rfi_monitor', 'gnss_correlator', 'imm_carrier')
"""The nodes that an IF stream alone feeds (``--if-input``): the others have no input then."""

CORRELATOR_PERIOD_NS = 1_000_000
"""The correlator's output grid, ns: one CorrelatorArray per 1 ms of the stream, stamped at the interval's end, so
its last one ends less than this before the end of the last block (gnss_correlator.receiver)."""

NODE_ENDPOINTS = {
    'rfi_monitor': (('/rfi/if_samples',), ('/rfi/jammer_state', '/diagnostics')),
    'gnss_integrity': (('/gnss/measurements', '/uwb/ranges', '/gnss/receiver_interference', '/gnss/receiver_spectrum',
                        '/rfi/jammer_state'), ('/gnss/integrity', '/diagnostics')),
    'uwb_gnss_fusion': (('/gnss/measurements', '/uwb/ranges', '/rfi/jammer_state', '/gnss/integrity'),
                        ('/fusion/odometry', '/fusion/local_odometry', '/fusion/fix', '/fusion/datum',
                         '/fusion/status', '/diagnostics')),
    'imm_carrier': (('/gnss/correlators',), ('/carrier/estimates', '/diagnostics')),
    'gnss_correlator': (('/rfi/if_samples',), ('/gnss/correlators', '/diagnostics')),
}
"""Node name -> (topics it subscribes, topics it publishes), before remapping."""

OUTPUT_TYPES = {
    '/rfi/jammer_state': 'rfi_msgs/msg/JammerState',
    '/gnss/integrity': 'rfi_msgs/msg/GnssIntegrity',
    '/fusion/odometry': 'nav_msgs/msg/Odometry',
    '/fusion/local_odometry': 'nav_msgs/msg/Odometry',
    '/fusion/fix': 'sensor_msgs/msg/NavSatFix',
    '/fusion/datum': 'sensor_msgs/msg/NavSatFix',
    '/fusion/status': 'rfi_msgs/msg/FusionStatus',
    '/carrier/estimates': 'rfi_msgs/msg/CarrierPhaseArray',
    '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
}
"""Every topic the suite's four nodes publish, and its type: what ``processes`` records."""

CORRELATOR_OUTPUT_TYPES = {'/gnss/correlators': 'rfi_msgs/msg/CorrelatorArray'}
"""What ``processes`` records besides :data:`OUTPUT_TYPES` when the correlator runs."""


def suite_nodes(with_correlator: bool, if_input: bool) -> tuple[tuple[str, str, str], ...]:
    """(node name, package, executable) of the nodes a ``processes`` run starts: the suite's four, plus the
    correlator with ``with_correlator``; with ``if_input`` (an IF stream, no bag) only those of
    :data:`IF_STREAM_NODES` (imm_carrier only with the correlator, which feeds it)."""
    nodes = NODE_EXECUTABLES + ((CORRELATOR_EXECUTABLE,) if with_correlator else ())
    if if_input:
        keep = IF_STREAM_NODES if with_correlator else ('rfi_monitor',)
        nodes = tuple(n for n in nodes if n[0] in keep)
    return nodes


def output_types(nodes: Sequence[tuple[str, str, str]]) -> dict[str, str]:
    """Topic -> type of what ``nodes`` publish (what the recorder subscribes)."""
    types = {**OUTPUT_TYPES, **CORRELATOR_OUTPUT_TYPES}
    names = {name for name, _, _ in nodes}
    published = {t for name in names for t in NODE_ENDPOINTS[name][1]}
    return {t: m for t, m in types.items() if t in published}

ANSWERED_BY_STAMP = (('rfi_monitor', ('/rfi/if_samples',), '/rfi/jammer_state'),
                     ('gnss_integrity', ('/gnss/measurements',), '/gnss/integrity'),
                     ('uwb_gnss_fusion', ('/gnss/measurements', '/uwb/ranges'), '/fusion/status'),
                     ('imm_carrier', ('/gnss/correlators',), '/carrier/estimates'))
"""(node, inputs, output): the node publishes the output with the header stamp of each input it
processes, in stamp order, so an output stamped at its last input's stamp shows that the node is
done. The fusion processes its last inputs (those in its re-ordering window) at the end of input:
when none has arrived for its ``idle_flush_s`` (wall time, 1 s by default)."""

DISCOVERY_SETTLE_S = 1.0
"""Wait after this process sees every node's endpoints, and after play's publishers are matched, s:
the other side of each match (the subscriber's) completes a little later, and until then the
middleware delivers the first messages only by retransmission, up to seconds late."""

RELIABLE_INPUTS = 'reliable'
"""What ``processes`` sets each node's input subscriptions to (``qos_overrides.<topic>.subscription.
reliability``): the nodes' inputs take their publishers' reliability by default, and become best effort
if a best-effort driver publishes on the topic, which would let a replay lose messages silently; fixed
reliable, every message of play reaches the node or play waits."""

SYNCED = (('rfi_monitor', '/rfi/if_samples', '/rfi/jammer_state'),
          ('gnss_integrity', '/gnss/measurements', '/gnss/integrity'))
"""(node, input, output) that ``play`` paces on (``--sync``): after each IF block it waits for the
monitor's jammer state, and after each GNSS epoch for gnss_integrity's verdict of it, so the fusion
gets them before the messages that follow in the bag, as in a replay in one process, however long
the node takes. Without the second, a verdict that gnss_integrity (starved of CPU on a loaded
machine) published more than the fusion's re-ordering window after play's next messages was
rejected as late (``late_beyond_reorder_window``): seen in 1 of 3 runs of test_two_suites beside a
busy loop; a DETECTED verdict lost that way would leave spoofed GNSS in the fusion."""


def suite_topic(namespace: str, topic: str) -> str:
    """The name of one of the suite's topics (a root name: ``/rfi/if_samples``) under ``namespace``
    (``/`` or ``''``: the root name itself)."""
    return namespace.rstrip('/') + topic


def namespaced_params_file(path: Path, namespace: str, workdir: Path) -> Path:
    """``path`` itself at the root; under a namespace, a copy whose node keys carry it.

    A parameters file names nodes by their fully qualified name, and a plain key (``rfi_monitor:``)
    means the node at the root: ``/robot1/rfi_monitor`` would silently get none of its parameters.
    The suite's own files are written for the root, so each plain top-level key ``k`` becomes
    ``<namespace>/k``; keys that are already absolute or wildcards (``/**``) are kept. Only those key
    lines are rewritten, as text: every value stays exactly as written (a YAML round trip would not
    keep e.g. ``2.0e6``, which PyYAML reads as a string and rcl as a double).
    """
    path = path.resolve()
    if namespace.rstrip('/') == '':
        return path
    try:
        lines = path.read_text().splitlines(keepends=True)
    except OSError as err:
        raise RunError(f'cannot read parameters file {path}: {err}') from err
    prefix = namespace.rstrip('/')
    out = [_TOP_LEVEL_NODE_KEY.sub(lambda m: f'{prefix}/{m.group(1)}:', line, count=1) for line in lines]
    workdir.mkdir(parents=True, exist_ok=True)
    target = workdir / f'{path.stem}.namespaced{path.suffix or ".yaml"}'
    target.write_text(''.join(out))
    return target


_TOP_LEVEL_NODE_KEY = re.compile(r'^([A-Za-z_][A-Za-z0-9_]*)\s*:')
"""A top-level key of a parameters file that is a plain node name (no namespace, no wildcard)."""


def namespace_arguments(namespace: str, topics: Sequence[str]) -> list[str]:
    """``-r`` remaps (for ``--ros-args``) that put a process into ``namespace`` and move each of the
    absolute ``topics`` it uses there: the node's namespace, then ``/t:=<namespace>/t`` per topic
    (remapping moves absolute names, which a namespace alone leaves where they are). Empty at the root."""
    if namespace.rstrip('/') == '':
        return []
    out = ['-r', f'__ns:={namespace}']
    for topic in topics:
        out += ['-r', f'{topic}:={suite_topic(namespace, topic)}']
    return out


def ros_arguments(argv: Sequence[str]) -> list[str]:
    """The ``--ros-args ... [--]`` parts of ``argv`` (remaps, parameters), to pass on to other processes."""
    out: list[str] = []
    inside = False
    for arg in argv:
        if arg == '--ros-args':
            inside = True
            out.append(arg)
        elif inside and arg == '--':
            inside = False
            out.append(arg)
        elif inside:
            out.append(arg)
    return out


def reliable_input_arguments(topics: Sequence[str], resolve: Any = None) -> list[str]:
    """``-p qos_overrides.<topic>.subscription.reliability:=reliable`` for each input topic of a node
    (and for its remapped name, which is what the node's override is declared under, when ``resolve``
    maps it elsewhere): see :data:`RELIABLE_INPUTS`."""
    names: list[str] = []
    for topic in topics:
        for name in (topic, resolve(topic) if resolve is not None else topic):
            if name not in names:
                names.append(name)
    out: list[str] = []
    for name in names:
        out += ['-p', f'qos_overrides.{name}.subscription.reliability:={RELIABLE_INPUTS}']
    return out


@dataclass
class ProcessesRun:
    """What a ``processes`` run measured besides the recorded outputs."""

    exit_codes: dict[str, int]
    completion: str


@dataclass
class Segment:
    """The window of the bag that a ``processes`` run plays, and what it holds."""

    start_s: float
    duration_s: float | None  # None: to the end of the bag
    counts: dict[str, int]
    first_ns: int | None  # log times of its first and last input
    last_ns: int | None
    last_input: dict[str, int]  # node -> latest header stamp of its inputs (ANSWERED_BY_STAMP), ns


def _segment(reader: BagReader, inputs: list[str], start_s: float, duration_s: float | None) -> Segment:
    start_ns, stop_ns = window_ns(reader.start_ns, window_s(start_s, duration_s) or (0.0, math.inf))
    counts = {t: 0 for t in inputs}
    first = last = None
    last_raw: dict[str, Any] = {}
    stamped = {topic: node for node, topics, _ in ANSWERED_BY_STAMP for topic in topics}
    for message in reader.messages(inputs, start_ns=start_ns, stop_ns=stop_ns):
        counts[message.topic] += 1
        first = message.stamp_ns if first is None else first
        last = message.stamp_ns
        if message.topic in stamped:
            last_raw[message.topic] = message
    last_input: dict[str, int] = {}
    for topic, message in last_raw.items():
        try:
            stamp = message.decode().header.stamp
        except Exception as err:  # rclpy raises its own RMWError for a layout mismatch
            raise RunError(f'cannot decode a {message.msgtype} of {topic} in the bag ({" ".join(str(err).split())}): '
                           'was it written with other definitions of the messages? Regenerate it or rebuild '
                           'rfi_msgs to match') from None
        node = stamped[topic]
        last_input[node] = max(last_input.get(node, 0), stamp.sec * 1_000_000_000 + stamp.nanosec)
    return Segment(start_s, duration_s, counts, first, last, last_input)


def run_processes(args: argparse.Namespace, argv: Sequence[str], inputs: list[str],
                  params: dict[str, dict[str, object]], window: tuple[float, float] | None,
                  out: Path) -> tuple[Any, ProcessesRun]:
    """Replay ``inputs`` of the bag through the node executables as separate processes fed by ``play``.

    ``play`` plays the first ``--warmup`` seconds at ``--warmup-rate`` and the rest at ``--rate``,
    and after each IF block and GNSS epoch waits for the answer (``--sync``, :data:`SYNCED`). Without the slow
    start, the nodes' first-call costs (numba compilation or cache loading, imports) pile up a
    backlog at a real-time pace; the fusion node's executor then takes GNSS, UWB and jammer
    messages out of arrival order and rejects those later than its re-ordering window. Neither
    changes anything else: the nodes take their time from the stamps.

    ``args.namespace`` (default ``/``) puts the suite under a namespace (see the module docstring);
    with ``args.external_nodes`` the nodes are not started but expected in the graph;
    ``args.with_correlator`` adds gnss_correlator (its ``/gnss/correlators`` feed imm_carrier; ``inputs`` must not
    hold the topic); ``args.if_input`` (a path, ``-`` or a named pipe; ``args.bag`` then None) feeds the IF
    stream's nodes from ``if_source`` instead of a bag (module docstring).

    Returns:
        ``(ReplayResult, ProcessesRun)``: the recorded outputs (CDR bytes, in arrival order per topic)
        and input counts as the in-process transports give them, and the exit codes of the processes.

    Raises:
        RunError: an executable is missing, a process died, discovery or the last outputs did not
            come within ``--timeout``, or ``play`` (if_source) failed (the message names it and its log).
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from rfi_experiments.bag_io import message_class
    from rfi_experiments.replay import ReplayResult
    from rfi_node_common.qos import RECORDER_QOS

    rate = PROCESSES_DEFAULT_RATE if args.rate is None else args.rate
    namespace = getattr(args, 'namespace', '/')
    external = getattr(args, 'external_nodes', False)
    with_correlator = getattr(args, 'with_correlator', False)
    if_input = getattr(args, 'if_input', None)
    nodes = suite_nodes(with_correlator, if_input is not None)
    types = output_types(nodes)
    endpoints = {name: NODE_ENDPOINTS[name] for name, _, _ in nodes}
    paths = {} if external else {name: executable_path(package, exe) for name, package, exe in nodes}
    forwarded = ros_arguments(argv)
    seg: Segment | None = None
    if if_input is None:
        feeder = executable_path('rfi_experiments', 'play')
        start_s, stop_s = window if window is not None else (0.0, math.inf)
        with BagReader(args.bag) as reader:
            seg = _segment(reader, inputs, start_s, None if math.isinf(stop_s) else stop_s - start_s)
        if seg.first_ns is None or seg.last_ns is None:
            raise RunError(f'no input message in the selected window of {args.bag}')
    else:
        feeder = executable_path('rfi_experiments', 'if_source')

    children = ChildProcesses(out / 'logs')
    context = rclpy.context.Context()
    # Ctrl-C is ours, not rclpy's: its handler would shut the context down under the executor and
    # leave the outcome to timing (an exception from spin_once, or loops waiting for the children);
    # ours raises KeyboardInterrupt, and the finally below stops the children in order.
    rclpy.init(args=list(argv), context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node('rfi_run_recorder', context=context, namespace=namespace)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    recorded: dict[str, list[tuple[int, bytes]]] = {t: [] for t in types}
    received: dict[str, Any] = {'n': 0, 'at': time.monotonic()}  # messages so far, time of the last
    previous = {sig: signal.signal(sig, _raise_interrupt) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    exit_codes: dict[str, int] = {}
    try:
        subs = {t: node.create_subscription(message_class(m), suite_topic(namespace, t),
                                            _recorder(recorded[t], received), RECORDER_QOS,
                                            raw=True)
                for t, m in types.items()}
        params_files = [str(namespaced_params_file(Path(f), namespace, out / 'logs')) for f in args.params_file]
        for name, path in paths.items():
            children.start(name, _node_command(name, path, params_files, params, namespace, forwarded,
                                               node.resolve_topic_name))
        _wait_for_graph(node, executor, subs, children, args.timeout, namespace, external, endpoints)
        node_names = list(paths)
        wall_start = time.monotonic()
        quiet = args.no_progress or args.quiet  # play's summary goes to its log either way
        if seg is not None:
            player = children.start('play', _play_command(args, feeder, inputs, seg, rate, namespace, forwarded,
                                                          endpoints, types), stderr_to_terminal=not quiet)
        else:
            player = children.start('if_source', _if_source_command(args, feeder, params_files, namespace, forwarded,
                                                                    endpoints), inherit_stdin=args.if_input == '-')
        _record_until_done(player, 'play' if seg is not None else 'if_source', executor, children, node_names)
        if seg is None:
            seg = if_source_segment(executor, recorded, children, node_names, args.timeout)
        last_input = dict(seg.last_input)
        if with_correlator and 'rfi_monitor' in last_input:
            # its last array ends within one period before the last block's end, so after the last block's start
            # less one period (the block is at least one sample long)
            last_input['gnss_correlator'] = last_input['rfi_monitor'] - CORRELATOR_PERIOD_NS + 1
        completion = _wait_for_last_outputs(executor, recorded, last_input, received, children, node_names,
                                            args, with_correlator)
        wall_time_s = received['at'] - wall_start  # the first play's start to the last output
    finally:
        # keep recording while the nodes stop: what they publish on the way out is theirs too
        exit_codes = children.stop(while_waiting=lambda: executor.spin_once(timeout_sec=0.05))
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        executor.remove_node(node)
        node.destroy_node()
        executor.shutdown()
        rclpy.try_shutdown(context=context)
    assert seg.first_ns is not None and seg.last_ns is not None
    result = ReplayResult(outputs={t: v for t, v in recorded.items() if v},
                          output_types={t: types[t] for t, v in recorded.items() if v},
                          inputs={t: n for t, n in seg.counts.items() if n}, wall_time_s=wall_time_s,
                          bag_duration_s=(seg.last_ns - seg.first_ns) * 1e-9)
    return result, ProcessesRun(exit_codes=exit_codes, completion=completion)


def _recorder(messages: list[tuple[int, bytes]], received: dict[str, Any]) -> Any:
    """The raw callback of one recorded topic: each message appended with its arrival number over all topics;
    ``received`` holds that count (``n``) and the wall time of the last (``at``)."""
    def on_message(raw: bytes) -> None:
        received['n'] += 1
        received['at'] = time.monotonic()
        messages.append((received['n'], raw))
    return on_message


def _record_until_done(player: Any, feeder_name: str, executor: Any, children: ChildProcesses,
                       node_names: list[str]) -> None:
    """Spin the recorder until the feeder (play or if_source) exits; RunError if a node died or the feeder
    failed (with the end of its log)."""
    while player.poll() is None:
        executor.spin_once(timeout_sec=0.05)
        children.check_alive(node_names)
    if player.returncode != 0:
        raise RunError(f'{feeder_name} exited with code {player.returncode}; the end of '
                       f'{children.log_dir}/{feeder_name}.log:\n' + children.log_tail(feeder_name))


def _node_command(name: str, path: str, params_files: list[str], params: dict[str, dict[str, object]],
                  namespace: str, forwarded: list[str], resolve: Any) -> list[str]:
    """The command line of node ``name``'s executable: the parameters files, run's imm_carrier method, reliable
    inputs, the namespace, then the caller's own ``--ros-args`` (last: the caller's ``-p`` wins)."""
    command = [path, '--ros-args']
    for params_file in params_files:
        command += ['--params-file', params_file]
    if name == 'imm_carrier':  # run's default, unless a parameters file sets it
        command += ['-p', f'method:={params["imm_carrier"]["method"]}']
    # the names the node resolves its inputs to (the override is declared under those; another
    # name would be refused as an unknown parameter)
    command += reliable_input_arguments([resolve(suite_topic(namespace, t)) for t in NODE_ENDPOINTS[name][0]])
    command += namespace_arguments(namespace, ['/diagnostics'])
    command += forwarded[1:] if forwarded else []
    return command


def _if_source_command(args: argparse.Namespace, source: str, params_files: list[str], namespace: str,
                       forwarded: list[str], endpoints: dict[str, tuple[tuple[str, ...], tuple[str, ...]]]
                       ) -> list[str]:
    """The command line of ``if_source`` for :func:`run_processes` with ``--if-input``: the parameters files (its
    ``if_source:`` section gives the format), the input, a wait for every subscriber of the IF stream, the
    namespace, then the caller's ``--ros-args``."""
    subscribers = sum('/rfi/if_samples' in subscribes for subscribes, _ in endpoints.values())
    command = [source, '--ros-args']
    for params_file in params_files:
        command += ['--params-file', params_file]
    quoted = "'" + str(args.if_input).replace("'", "''") + "'"  # a YAML string: "-" or "123" alone are not
    command += ['-p', f'input:={quoted}', '-p', f'wait_for_subscribers:={subscribers}',
                '-p', f'wait_timeout_s:={float(args.timeout)!r}', '-p', 'exit_at_end:=true']
    command += namespace_arguments(namespace, ['/diagnostics'])
    return command + (forwarded[1:] if forwarded else [])


def if_source_segment(executor: Any, recorded: dict[str, list[tuple[int, bytes]]], children: ChildProcesses,
                      node_names: list[str], timeout_s: float) -> Segment:
    """What an ``if_source`` that has exited published, from its /diagnostics: the blocks (its final report,
    whose text starts with 'end of input; ', is stamped with the last block's stamp), the first block's stamp (its
    first report's: the first is due at the first block), the last one's as the monitor's last input.

    Raises:
        RunError: the final report did not reach the recorder within ``timeout_s``.
    """
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import deserialize_message

    deadline = time.monotonic() + timeout_s
    seen = 0
    first: int | None = None
    while True:
        messages = recorded.get('/diagnostics', [])
        for _, raw in messages[seen:]:
            array = deserialize_message(raw, DiagnosticArray)
            stamp = array.header.stamp.sec * 1_000_000_000 + array.header.stamp.nanosec
            for status in array.status:
                if status.name != 'if_source':
                    continue
                first = stamp if first is None else min(first, stamp)
                if status.message.startswith('end of input; '):
                    values = {kv.key: kv.value for kv in status.values}
                    blocks = int(values.get('blocks_published', '0'))
                    if blocks == 0:
                        raise RunError('if_source published no block (see its log: '
                                       f'{children.log_dir}/if_source.log)')
                    return Segment(0.0, None, {'/rfi/if_samples': blocks}, first, stamp, {'rfi_monitor': stamp})
        seen = len(messages)
        if time.monotonic() > deadline:
            raise RunError(f'if_source ended without its final report within {timeout_s:g} s (its log: '
                           f'{children.log_dir}/if_source.log)')
        executor.spin_once(timeout_sec=0.05)
        children.check_alive(node_names)


def _play_command(args: argparse.Namespace, play: str, inputs: list[str], seg: Segment, rate: float, namespace: str,
                  forwarded: list[str], endpoints: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] | None = None,
                  types: dict[str, str] | None = None) -> list[str]:
    """The command line of ``play`` for :func:`run_processes`: the segment at ``rate`` after the slow start, an
    answer awaited after each input of :data:`SYNCED`, the subscribers each input must have (those of
    ``endpoints``, default the suite's four nodes), the namespace."""
    endpoints = endpoints if endpoints is not None else {n: NODE_ENDPOINTS[n] for n, _, _ in NODE_EXECUTABLES}
    types = types if types is not None else OUTPUT_TYPES
    command = [play, str(args.bag), '--topics', *inputs, '--rate', repr(rate), '--start', repr(seg.start_s)]
    if seg.duration_s is not None:
        command += ['--duration', repr(seg.duration_s)]
    command += ['--warmup', repr(args.warmup), '--warmup-rate', repr(args.warmup_rate),
                '--wait-subscribers', repr(args.timeout), '--start-delay', repr(DISCOVERY_SETTLE_S),
                '--ack-timeout', repr(args.timeout),
                # the first answers include each node's first-call cost (numba compilation on a
                # cold cache: 15-30 s per node with three starting at once on two cores)
                '--sync-timeout', repr(args.timeout)]
    command += [f'--sync={inp}:{out}' for node, inp, out in SYNCED if inp in inputs and node in endpoints]
    subscribers = {t: sum(t in subscribes for subscribes, _ in endpoints.values()) for t in inputs}
    command += [f'--expect-subscribers={t}:{n}' for t, n in subscribers.items()]
    if args.no_progress or args.quiet:
        command.append('--no-progress')
    moved = namespace_arguments(namespace, sorted(set(inputs) | set(types)))
    command += ['--ros-args', *moved, '--'] if moved else []
    return command + list(forwarded)


def _raise_interrupt(signum: int, _frame: Any) -> None:
    raise KeyboardInterrupt(f'signal {signum}')


def _wait_for_graph(node: Any, executor: Any, subs: dict[str, Any], children: ChildProcesses,
                    timeout_s: float, namespace: str = '/', external: bool = False,
                    endpoints: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] | None = None) -> None:
    """Wait until every node of ``endpoints`` (default: the suite's four; in ``namespace``) shows its endpoints in
    the graph and the recorder has matched every publisher of the recorded topics.

    Raises:
        RunError: not within ``timeout_s``; a node process exited; an external node's input is best
            effort (a message it drops would be lost unseen).
    """
    from rclpy.qos import ReliabilityPolicy

    endpoints = endpoints if endpoints is not None else {n: NODE_ENDPOINTS[n] for n, _, _ in NODE_EXECUTABLES}
    deadline = time.monotonic() + timeout_s
    ns = '/' + namespace.strip('/')
    while True:
        children.check_alive([] if external else list(endpoints))
        missing = []
        best_effort = []
        for name, (subscribes, publishes) in endpoints.items():
            for topic in subscribes:
                resolved = node.resolve_topic_name(suite_topic(namespace, topic))
                ours = [i for i in node.get_subscriptions_info_by_topic(resolved)
                        if i.node_name == name and i.node_namespace == ns]
                if not ours:
                    missing.append(f'{name} subscribing {resolved}')
                elif any(i.qos_profile.reliability != ReliabilityPolicy.RELIABLE for i in ours):
                    best_effort.append(f'-p qos_overrides.{resolved}.subscription.reliability:=reliable ({name})')
            for topic in publishes:
                resolved = node.resolve_topic_name(suite_topic(namespace, topic))
                if not any(i.node_name == name and i.node_namespace == ns
                           for i in node.get_publishers_info_by_topic(resolved)):
                    missing.append(f'{name} publishing {resolved}')
        if external and best_effort and not missing:
            raise RunError('the external nodes take these inputs best effort, so a message they drop would be '
                           'lost unseen; start them with --ros-args ' + ' '.join(best_effort))
        for sub in subs.values():
            n_graph = len(node.get_publishers_info_by_topic(sub.topic_name))
            if sub.get_publisher_count() < n_graph:
                missing.append(f'the recorder matched {sub.get_publisher_count()} of {n_graph} publishers of '
                               f'{sub.topic_name}')
        if not missing:
            # Our view of the graph is complete; the nodes' views of each other follow within the
            # discovery round trip. Give it that, so the monitor's first jammer state is not late.
            settle = time.monotonic() + DISCOVERY_SETTLE_S
            while time.monotonic() < settle:
                executor.spin_once(timeout_sec=0.05)
            return
        if time.monotonic() > deadline:
            raise RunError(f'the {"external nodes" if external else "node processes"} did not come up in '
                           f'namespace {ns} within {timeout_s} s (ROS_DOMAIN_ID '
                           f'{os.environ.get("ROS_DOMAIN_ID", "0")}, ROS_AUTOMATIC_DISCOVERY_RANGE '
                           f'{os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "unset")}); not seen: '
                           + '; '.join(missing) + f'. Logs: {children.log_dir}')
        executor.spin_once(timeout_sec=0.05)


def _wait_for_last_outputs(executor: Any, recorded: dict[str, list[tuple[int, bytes]]],
                           last_input: dict[str, int], received: dict[str, Any],
                           children: ChildProcesses, node_names: list[str], args: argparse.Namespace,
                           with_correlator: bool = False) -> str:
    """After ``play`` has finished (every input acknowledged by its subscriber), wait until each node
    with a one-to-one stamped output has published it for its last input and nothing has been
    published for ``--settle`` s; a node whose last input was rejected (no output for it) is taken as
    done after five times that quiet time. Return how completion was decided.

    With the correlator, its last input (``last_input['gnss_correlator']``) is the least stamp its last array can
    have, and imm_carrier's is the stamp of the last array recorded from it (imm_carrier answers each array with
    its stamp); a correlator that tracks no satellite publishes none and is taken as done by the quiet time.

    Raises:
        RunError: not complete within ``--timeout`` s.
    """
    from rclpy.serialization import deserialize_message

    from rfi_experiments.bag_io import message_class

    answered = [(name, topic) for name, _, topic in ANSWERED_BY_STAMP if topic in recorded]
    if with_correlator:
        answered.append(('gnss_correlator', '/gnss/correlators'))
    types = {**OUTPUT_TYPES, **CORRELATOR_OUTPUT_TYPES}
    classes = {topic: message_class(types[topic]) for _, topic in answered}

    def last_stamp(topic: str) -> int | None:
        if not recorded.get(topic):
            return None
        stamp = deserialize_message(recorded[topic][-1][1], classes[topic]).header.stamp
        return stamp.sec * 1_000_000_000 + stamp.nanosec

    start = time.monotonic()
    while True:
        executor.spin_once(timeout_sec=0.05)
        children.check_alive(node_names)
        waiting = []
        for name, topic in answered:
            if with_correlator and name == 'imm_carrier':
                expected = last_stamp('/gnss/correlators')
            else:
                expected = last_input.get(name)
            if expected is None:
                continue
            got = last_stamp(topic)
            if got is None or got < expected:
                waiting.append(f'{name}: last {topic} stamped {got} ns, its last input {expected} ns')
        quiet_s = time.monotonic() - max(received['at'], start)
        if not waiting and quiet_s >= args.settle:
            return (f'every node answered its last input (an output with that stamp) and nothing was '
                    f'published for {args.settle:g} s')
        if waiting and quiet_s >= 5 * args.settle:
            return (f'nothing was published for {5 * args.settle:g} s; not answered by stamp (last input rejected?): '
                    + '; '.join(waiting))
        if time.monotonic() - start > args.timeout:
            raise RunError(f'outputs still coming or incomplete {args.timeout:g} s after play finished: '
                           + ('; '.join(waiting) or f'messages still arriving ({received["n"]} so far)')
                           + f'. Logs: {children.log_dir}')
