"""``ros2 run rfi_experiments play BAG``: publish a bag's messages on their topics.

Messages go out as the serialized bytes stored in the bag (no re-encoding), in log-time order,
at the recorded pace times ``--rate`` or as fast as the middleware takes them (``--max``), the
whole bag or a window of it (``--start``, ``--duration``: seconds after the bag's first message).
A progress bar runs on stderr; a table per topic ends the run.

Nothing is lost by default:

- Before the first message, the player waits (at most ``--wait-subscribers`` s, default 10) until
  its publishers are matched with the subscribers: those given by ``--expect-subscribers`` (``N``
  for every topic, or ``TOPIC:N``), every subscription that the graph shows on a played topic, and,
  without ``--expect-subscribers``, at least one subscriber of some played topic. Then it waits
  until that set has been unchanged for ``--start-delay`` s (default 0.5): the subscribers' side of
  each match completes a little later (2-75 ms measured here), and a best-effort subscriber loses
  what comes before. Without ``--expect-subscribers``, while some played topics have subscribers
  and others none, it waits for 2 s without change instead (:data:`PARTIAL_SETTLE_S`): a process
  announces its subscriptions one by one. ``--expect-subscribers 0`` does not wait for anyone.
- The publishers are reliable and keep all samples, and at the end the player waits until every
  reliable subscriber has acknowledged every message (``--ack-timeout``).
- The final table says, per topic, how many subscribers it had and how many messages went out
  while none was matched ("to nobody": those are lost). Then, per topic, how many messages were sent
  and to whom: reliable subscribers (the nodes' inputs are, with the default best-available QoS,
  while no best-effort driver publishes on the topic) acknowledged every one (into their queue: a node
  that falls more than its queue depth behind drops the oldest, and counts them); a best-effort
  subscriber does not acknowledge, so the player says so, how to make it reliable (``--ros-args -p
  qos_overrides.<topic>.subscription.reliability:=reliable`` on that node), and what the node's last
  ``/diagnostics`` report said it received and lost (``input.<topic>.received`` / ``lost``); a loss
  that a subscriber reports is a warning that names it.

With ``--sync IN:OUT`` the player waits after each message on IN until the node that answers it has
published its stamped output on OUT (closed-loop pacing, used by ``run --transport processes`` so
that the monitor's jammer state reaches the fusion before the next GNSS/UWB messages, as in a
replay in one process). The player reads ``/fusion/status`` for the fusion node's rejections of
messages that came after its re-ordering window, which are reported at the end: after the last
message it waits until the fusion node has published a status stamped at or after the latest header
stamp played on its inputs (every message then processed or rejected), up to ``--status-timeout``,
and says so if that wait ran out.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from rfi_experiments.bag_io import BagError, BagReader, message_class
from rfi_experiments.cli import bounded_teardown, error_reporter, exit_now, release_endpoints
from rfi_experiments.progress import ProgressLine, add_quiet_argument, summary_printer
from rfi_node_common.stamps import peek_header_stamp_ns

fail = error_reporter('play')


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='play', description='Publish the messages of a bag (mcap) on their topics, in log-time order.')
    parser.add_argument('bag', help='bag directory (rosbag2 layout with metadata.yaml)')
    pace = parser.add_mutually_exclusive_group()
    pace.add_argument('--rate', type=float, default=1.0,
                      help='replay speed as a multiple of the recorded pace (default 1.0)')
    pace.add_argument('--max', action='store_true', help='publish as fast as possible')
    parser.add_argument('--topics', nargs='+', metavar='TOPIC', help='play only these topics')
    add_window_arguments(parser)
    parser.add_argument('--wait-subscribers', type=float, default=10.0, metavar='SECONDS',
                        help='before playing, wait up to this long for the subscribers (see --expect-subscribers); '
                             'after that, play anyway and report the topics without one (default 10; 0: no wait)')
    parser.add_argument('--expect-subscribers', action='append', default=[], metavar='N|TOPIC:N',
                        help='subscribers to wait for: N on every played topic, or N on TOPIC (may be repeated). '
                             'Default: every subscription the graph shows on a played topic, and at least one '
                             'on some played topic; 0: wait for nobody')
    parser.add_argument('--start-delay', type=float, default=0.5, metavar='SECONDS',
                        help='once the subscribers are matched, wait until they have been unchanged for this long '
                             'before the first message: the subscribers\' side of discovery completes a little '
                             'later, and a best-effort subscriber loses what comes before (default 0.5)')
    parser.add_argument('--warmup', type=float, default=0.0, metavar='SECONDS',
                        help='play the first SECONDS of the bag (or window) at --warmup-rate, the rest at --rate: '
                             'slow first messages give the subscribers time for their first-call costs (default 0)')
    parser.add_argument('--warmup-rate', type=float, default=0.1, metavar='RATE',
                        help='pace of the --warmup part, x the recorded pace (default 0.1)')
    parser.add_argument('--ack-timeout', type=float, default=10.0, metavar='SECONDS',
                        help='after playing, wait up to this long for subscribers to acknowledge (default 10)')
    parser.add_argument('--sync', action='append', default=[], metavar='IN:OUT',
                        help='after each message on topic IN, wait until a message with the same header stamp (or a '
                             'later one) is published on topic OUT before going on: a node that answers each input '
                             'with a stamped output (e.g. /rfi/if_samples:/rfi/jammer_state) is then never more than '
                             'one message behind, whatever its speed; may be given more than once')
    parser.add_argument('--sync-timeout', type=float, default=10.0, metavar='SECONDS',
                        help='longest wait for an answer on OUT; an input left unanswered (a rejected one) is '
                             'counted and reported (default 10)')
    parser.add_argument('--status-timeout', type=float, default=10.0, metavar='SECONDS',
                        help='after playing, wait up to this long for a fusion node (/fusion/status) to have '
                             'processed the last message played on its inputs, so that its count of late '
                             'rejections is final (default 10)')
    parser.add_argument('--no-progress', action='store_true', help='no progress line')
    add_quiet_argument(parser)
    return parser


def add_window_arguments(parser: argparse.ArgumentParser) -> None:
    """``--start`` and ``--duration``: a window of the bag (shared by ``play`` and ``run``)."""
    parser.add_argument('--start', type=float, default=0.0, metavar='SECONDS',
                        help='begin this many seconds after the bag\'s first message (log time; default 0)')
    parser.add_argument('--duration', type=float, default=None, metavar='SECONDS',
                        help='play only this many seconds of the bag from --start (default: to the end)')


def window_s(start_s: float, duration_s: float | None) -> tuple[float, float] | None:
    """The window [start, stop) in seconds after the bag's first message, or None for the whole bag.

    Raises:
        ValueError: start < 0, duration <= 0, or either not finite.
    """
    if not (math.isfinite(start_s) and start_s >= 0.0):
        raise ValueError(f'--start must be a finite number >= 0 (got {start_s})')
    if duration_s is not None and not (math.isfinite(duration_s) and duration_s > 0.0):
        raise ValueError(f'--duration must be a finite number > 0 (got {duration_s})')
    if start_s == 0.0 and duration_s is None:
        return None
    return start_s, math.inf if duration_s is None else start_s + duration_s


def window_ns(bag_start_ns: int, window: tuple[float, float] | None) -> tuple[int | None, int | None]:
    """Absolute log times [start_ns, stop_ns) of a window from :func:`window_s` (None: unbounded)."""
    if window is None:
        return None, None
    stop = None if math.isinf(window[1]) else bag_start_ns + round(window[1] * 1e9)
    return bag_start_ns + round(window[0] * 1e9), stop


def due_offset_s(offset_s: float, rate: float, warmup_s: float = 0.0, warmup_rate: float = 1.0) -> float:
    """Wall time after the first message at which a message ``offset_s`` of bag time later is due, s:
    the first ``warmup_s`` of bag time at ``warmup_rate``, the rest at ``rate``."""
    slow = min(offset_s, warmup_s)
    return slow / warmup_rate + (offset_s - slow) / rate


def parse_expectations(items: Sequence[str], topics: Sequence[str]) -> dict[str, int] | None:
    """``--expect-subscribers`` values -> topic: subscribers to wait for (None: none given, the default).

    Raises:
        ValueError: a malformed value, a negative count, or a topic that is not played.
    """
    if not items:
        return None
    expected: dict[str, int] = {}
    for item in items:
        topic, sep, count = item.rpartition(':')
        try:
            n = int(count)
        except ValueError:
            raise ValueError(f'--expect-subscribers wants N or TOPIC:N, got {item!r}') from None
        if n < 0:
            raise ValueError(f'--expect-subscribers: a count must be >= 0, got {item!r}')
        if not sep:
            expected.update({t: n for t in topics})
        elif topic not in topics:
            raise ValueError(f'--expect-subscribers: {topic} is not played (played: {", ".join(topics)})')
        else:
            expected[topic] = n
    return expected


@dataclass
class Delivery:
    """What happened to the messages of one topic."""

    published: int = 0
    to_nobody: int = 0  # published while no subscriber was matched: lost
    subscribers: int = 0  # most subscribers matched at once
    best_effort: set[str] = field(default_factory=set)  # nodes whose subscription is best effort
    reliable: set[str] = field(default_factory=set)  # nodes whose subscription is reliable


def subscriber_view(node: Any, publishers: dict[str, Any]) -> dict[str, tuple[int, int]]:
    """Topic -> (subscriptions matched with our publisher, subscriptions the graph shows)."""
    return {t: (p.get_subscription_count(), len(node.get_subscriptions_info_by_topic(p.topic_name)))
            for t, p in publishers.items()}


def unmet(view: dict[str, tuple[int, int]], expected: dict[str, int] | None) -> list[str]:
    """What the subscribers of ``view`` still lack (empty: ready to play)."""
    missing = [f'{t}: {matched} of the {graph} subscriptions in the graph matched'
               for t, (matched, graph) in view.items() if matched < graph]
    if expected is None:
        if not any(matched for matched, _ in view.values()):
            missing.append('no subscriber on any played topic')
    else:
        missing += [f'{t}: {view[t][0]} of {n} expected subscribers' for t, n in expected.items() if view[t][0] < n]
    return missing


PARTIAL_SETTLE_S = 2.0
"""Without ``--expect-subscribers``, while some played topics have a subscriber and others none, the
subscribers must be unchanged this long (not just ``--start-delay``) before playing, s: a process
that subscribes several topics announces them one by one, and under load seconds apart."""


def wait_for_subscribers(node: Any, executor: Any, publishers: dict[str, Any], expected: dict[str, int] | None,
                         wait_s: float, settle_s: float) -> list[str]:
    """Wait until the subscribers are there (:func:`unmet` empty) and unchanged for ``settle_s``
    (:data:`PARTIAL_SETTLE_S` at least, without ``expected``, while some topic has none), at most
    ``wait_s`` (0: do not wait). Returns what was still missing when the time ran out."""
    if wait_s <= 0:
        return unmet(subscriber_view(node, publishers), expected)
    deadline = time.monotonic() + wait_s
    stable: tuple[dict, float] | None = None
    while True:
        view = subscriber_view(node, publishers)
        missing = unmet(view, expected)
        now = time.monotonic()
        if not missing:
            if stable is None or stable[0] != view:
                stable = (view, now)
            partial = expected is None and not all(matched for matched, _ in view.values())
            if now - stable[1] >= (max(settle_s, PARTIAL_SETTLE_S) if partial else settle_s):
                return []
        else:
            stable = None
        if now > deadline:
            return missing
        executor.spin_once(timeout_sec=0.02)


def subscribers_by_reliability(node: Any, topic: str) -> tuple[set[str], set[str]]:
    """Nodes (namespace/name) with a reliable, and with a best-effort, subscription on ``topic``."""
    from rclpy.qos import ReliabilityPolicy

    def name(i: Any) -> str:
        return (f'{i.node_namespace.rstrip("/")}/{i.node_name}' if i.node_name not in ('', '_NODE_NAME_UNKNOWN_')
                else '(a node whose name is not discovered yet)')

    infos = [i for i in node.get_subscriptions_info_by_topic(topic) if name(i) != '/rfi_play']
    return ({name(i) for i in infos if i.qos_profile.reliability == ReliabilityPolicy.RELIABLE},
            {name(i) for i in infos if i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT})


def best_effort_subscribers(node: Any, topic: str) -> set[str]:
    """Nodes (namespace/name) with a best-effort subscription on ``topic``."""
    return subscribers_by_reliability(node, topic)[1]


InputReports = dict[tuple[str, str], tuple[int, int]]
"""(diagnostics status name, topic) -> (messages received, messages lost) of a node's input, from its last
/diagnostics report (``input.<topic>.received``; lost: the larger of ``.lost`` and ``.middleware_lost``, which
count the same losses: ``rfi_node_common.inputs``)."""


def read_input_reports(msg: Any, topics: Sequence[str], reports: InputReports) -> None:
    """Keep in ``reports`` the input counters of the played ``topics`` found in one /diagnostics message."""
    for status in msg.status:
        values = {kv.key: kv.value for kv in status.values}
        for t in topics:
            try:
                received = int(values[f'input.{t}.received'])
                lost = max(int(values.get(f'input.{t}.lost', 0)), int(values.get(f'input.{t}.middleware_lost', 0)))
            except (KeyError, ValueError):
                continue
            reports[(status.name, t)] = (received, lost)


LATE_REASON = 'late_beyond_reorder_window'
"""The fusion node's rejection reason for a message that came after its re-ordering window."""


def _checked_arguments(args: argparse.Namespace) -> tuple[tuple[float, float] | None, dict[str, str]] | str:
    """(the play window, the --sync pairs IN -> OUT) of the parsed arguments, or what is wrong with them."""
    if not args.max and not args.rate > 0.0:
        return f'--rate must be > 0 (got {args.rate})'
    try:
        window = window_s(args.start, args.duration)
    except ValueError as err:
        return str(err)
    for name in ('start_delay', 'warmup', 'wait_subscribers', 'status_timeout'):
        value = getattr(args, name)
        if not (math.isfinite(value) and value >= 0):
            return f'--{name.replace("_", "-")} must be a finite number >= 0 (got {value})'
    if not (math.isfinite(args.warmup_rate) and args.warmup_rate > 0):
        return f'--warmup-rate must be a finite number > 0 (got {args.warmup_rate})'
    sync: dict[str, str] = {}
    for item in args.sync:
        inp, sep, out = item.partition(':')
        if not sep or not inp.startswith('/') or not out.startswith('/'):
            return f'--sync wants IN:OUT (two topic names), got {item!r}'
        sync[inp] = out
    if not (math.isfinite(args.sync_timeout) and args.sync_timeout > 0):
        return f'--sync-timeout must be a finite number > 0 (got {args.sync_timeout})'
    return window, sync


def _await_answer(executor: Any, answered: dict[str, int], out: str, message: Any, timeout_s: float) -> bool:
    """Spin until a message stamped at least as late as ``message`` came on ``out`` (``--sync``), or timeout_s."""
    header = message.decode().header.stamp
    stamp_ns = header.sec * 1_000_000_000 + header.nanosec
    give_up = time.monotonic() + timeout_s
    while answered.get(out, -1) < stamp_ns and time.monotonic() < give_up:
        executor.spin_once(timeout_sec=0.01)
    return answered.get(out, -1) >= stamp_ns


def main(argv: Sequence[str] | None = None, *, teardown: bool = True) -> int:
    """Play (module docstring); the exit code. ``teardown`` False: leave the node and ROS as they are once the
    messages are delivered (the executable, which ends the process at once: :func:`cli`)."""
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.utilities import remove_ros_args

    from rfi_node_common.qos import PLAYER_QOS, RECORDER_QOS

    argv = list(sys.argv if argv is None else argv)
    args = build_parser().parse_args(remove_ros_args(argv)[1:])
    checked = _checked_arguments(args)
    if isinstance(checked, str):
        return fail(checked)
    window, sync = checked

    try:
        reader = BagReader(args.bag)
    except BagError as err:
        return fail(str(err))
    with reader:
        available = reader.topics
        selection = _selection(reader, args, window, sync)
        if isinstance(selection, str):
            return fail(selection)
        topics, expected, classes, start_ns, stop_ns, total = selection

        rclpy.init(args=argv)
        node = rclpy.create_node('rfi_play')
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        delivery = {t: Delivery() for t in topics}
        answered: dict[str, int] = {}
        unanswered = {t: 0 for t in sync}
        fusion = FusionWatch()
        last_stamp: dict[str, int] = {}
        try:
            publishers = {t: node.create_publisher(classes[t], t, PLAYER_QOS) for t in topics}
            missing = wait_for_subscribers(node, executor, publishers, expected, args.wait_subscribers,
                                           args.start_delay)
            if missing:
                print(f'play: warning: playing without every subscriber ({args.wait_subscribers:g} s waited): '
                      + '; '.join(missing), file=sys.stderr)
            for inp, out in sync.items():
                out_class = _discover_class(node, executor, out, max(args.wait_subscribers, args.sync_timeout))
                if out_class is None:
                    return fail(f'--sync: no publisher of {out} appeared (is the node answering {inp} up?)')
                node.create_subscription(out_class, out, _answer_recorder(answered, out), RECORDER_QOS)
            status_sub = _watch_fusion_status(node, fusion, RECORDER_QOS)
            reports: InputReports = {}
            watching = _watch_input_reports(node, topics, reports, RECORDER_QOS)
            for t, p in publishers.items():
                reliable, best_effort = subscribers_by_reliability(node, p.topic_name)
                delivery[t].reliable |= reliable
                delivery[t].best_effort |= best_effort
            progress = ProgressLine('play', total, 'msg', enabled=not (args.no_progress or args.quiet))
            wall_start = time.monotonic()
            bag_start = None
            for message in reader.messages(topics, start_ns=start_ns, stop_ns=stop_ns):
                if not args.max:
                    bag_start = message.stamp_ns if bag_start is None else bag_start
                    due = wall_start + due_offset_s((message.stamp_ns - bag_start) * 1e-9, args.rate, args.warmup,
                                                    args.warmup_rate)
                    delay = due - time.monotonic()
                    if delay > 0:
                        time.sleep(delay)
                pub = publishers[message.topic]
                pub.publish(message.raw)
                stamp = peek_header_stamp_ns(message.raw)
                if stamp is not None:
                    last_stamp[message.topic] = max(last_stamp.get(message.topic, stamp), stamp)
                d = delivery[message.topic]
                d.published += 1
                matched = pub.get_subscription_count()
                d.subscribers = max(d.subscribers, matched)
                if matched == 0:
                    d.to_nobody += 1
                if message.topic in sync:
                    if not _await_answer(executor, answered, sync[message.topic], message, args.sync_timeout):
                        unanswered[message.topic] += 1
                elif watching or status_sub.get_publisher_count():
                    executor.spin_once(timeout_sec=0)  # keep up with /fusion/status and /diagnostics
                progress.update(1)
            progress.close()
            unacked = [t for t, p in publishers.items()
                       if p.get_subscription_count() > 0 and not p.wait_for_all_acked(
                           rclpy.duration.Duration(seconds=args.ack_timeout))]
            for t, p in publishers.items():
                reliable, best_effort = subscribers_by_reliability(node, p.topic_name)
                delivery[t].reliable |= reliable
                delivery[t].best_effort |= best_effort
            behind = _await_fusion_status(node, executor, fusion, status_sub,
                                          {publishers[t].topic_name: s for t, s in last_stamp.items()},
                                          args.status_timeout)
            if watching:  # the nodes' /diagnostics of the last messages (a report as seen, not awaited)
                end = time.monotonic() + 0.5
                while time.monotonic() < end:
                    executor.spin_once(timeout_sec=0.05)
            say = summary_printer(args.quiet)
            print_summary(topics, available, delivery, sync, unanswered, args.sync_timeout, fusion.counts, say)
            if behind:
                print(behind, file=sys.stderr)
            print_receipts(delivery, reports, unacked, say)
            if unacked:
                print(f'play: warning: not acknowledged by every subscriber within {args.ack_timeout} s: '
                      f'{", ".join(unacked)}', file=sys.stderr)
                return 1
            return 0
        except BagError as err:
            return fail(str(err))
        except (KeyboardInterrupt, ExternalShutdownException):
            played = sum(d.published for d in delivery.values())
            print(f'play: interrupted after {played} of {total} messages', file=sys.stderr)
            return 130
        finally:
            if teardown:
                bounded_teardown('play', executor, node, rclpy)
            else:
                release_endpoints(node)


def _selection(reader: BagReader, args: argparse.Namespace, window: tuple[float, float] | None,
               sync: dict[str, str]) -> str | tuple[list[str], dict[str, int] | None, dict[str, Any], int | None,
                                                    int | None, int]:
    """What to play: the topics (``--topics`` or all), the subscribers expected on each, their message classes,
    the window in bag time (ns, None: open) and the number of messages; or the reason it cannot be played."""
    available = reader.topics
    topics = sorted(available) if not args.topics else list(dict.fromkeys(args.topics))
    unknown = [t for t in topics if t not in available]
    if unknown:
        return (f'topic filter matches nothing in {args.bag}: {", ".join(unknown)} '
                f'(the bag has {", ".join(sorted(available)) or "no topics"})')
    if not topics:
        return f'{args.bag} holds no topics'
    try:
        expected = parse_expectations(args.expect_subscribers, topics)
        classes = {t: message_class(available[t][0]) for t in topics}
    except (ValueError, BagError) as err:
        return str(err)
    start_ns, stop_ns = window_ns(reader.start_ns, window)
    if window is None:
        total = sum(available[t][1] for t in topics)
    else:
        total = sum(1 for _ in reader.messages(topics, start_ns=start_ns, stop_ns=stop_ns))
        if total == 0:
            return f'no message of {", ".join(topics)} in the window {window[0]}-{window[1]} s of {args.bag}'
    not_played = [t for t in sync if t not in topics]
    if not_played:
        return f'--sync input {", ".join(not_played)} is not played'
    return topics, expected, classes, start_ns, stop_ns, total


def print_summary(topics: Sequence[str], available: dict[str, tuple[str, int]], delivery: dict[str, Delivery],
                  sync: dict[str, str], unanswered: dict[str, int], sync_timeout: float,
                  fusion: dict[str, int], say: Callable[..., None] = print) -> None:
    """The table per topic (published, subscribers, to nobody) through ``say`` (stdout; nothing with --quiet),
    then the warnings (stderr, always)."""
    width = max(len(t) for t in topics)
    say(f'{"topic":<{width}}  {"type":<34} {"published":>9} {"subscribers":>11} {"to nobody":>9}')
    for t in topics:
        d = delivery[t]
        say(f'{t:<{width}}  {available[t][0]:<34} {d.published:>9} {d.subscribers:>11} {d.to_nobody:>9}')
    say(f'{"total":<{width}}  {"":<34} {sum(d.published for d in delivery.values()):>9} {"":>11} '
          f'{sum(d.to_nobody for d in delivery.values()):>9}')
    for inp, n in unanswered.items():
        say(f'sync {inp} -> {sync[inp]}: {delivery[inp].published - n} answered, {n} not within {sync_timeout:g} s')
    nobody = {t: d.to_nobody for t, d in delivery.items() if d.to_nobody}
    if nobody:
        print('play: warning: messages published while no subscriber was matched (lost): '
              + ', '.join(f'{t} {n} of {delivery[t].published}' for t, n in nobody.items())
              + ' (--expect-subscribers TOPIC:N waits for subscribers that come up late)', file=sys.stderr)
    for t, d in delivery.items():
        if d.best_effort:
            print(f'play: note: {t}: best-effort subscriber {", ".join(sorted(d.best_effort))}: delivery is not '
                  'acknowledged, so a message it drops after the last one it receives is lost without anyone '
                  'counting it; to make it reliable, start it with '
                  f'--ros-args -p qos_overrides.{t}.subscription.reliability:=reliable', file=sys.stderr)
    if fusion.get(LATE_REASON):
        print(f'play: warning: the fusion node rejected {fusion[LATE_REASON]} messages that reached it after its '
              're-ordering window (/fusion/status, cumulative since the node started): the nodes lagged behind '
              'the replay; play at a lower --rate, or raise the node\'s reorder_window_s', file=sys.stderr)


def print_receipts(delivery: dict[str, Delivery], reports: InputReports, unacked: Sequence[str],
                   say: Callable[..., None] = print) -> None:
    """Per topic: how many messages were sent and to whom, acknowledged or not, and what the subscribers'
    /diagnostics said they received and lost, through ``say`` (a reported loss is a warning, on stderr always)."""
    for t, d in delivery.items():
        if d.reliable:
            acked = ('not every message acknowledged' if t in unacked else
                     'every message acknowledged (a subscriber that falls more than its queue depth behind drops '
                     f'the oldest and counts them: input.{t}.lost in its /diagnostics)')
            say(f'delivery {t}: {d.published} sent; reliable subscribers {", ".join(sorted(d.reliable))}: {acked}')
        if d.best_effort:
            say(f'delivery {t}: {d.published} sent; best-effort subscribers {", ".join(sorted(d.best_effort))}: '
                  'not acknowledged')
        for (name, topic), (received, lost) in sorted(reports.items()):
            if topic != t:
                continue
            say(f'delivery {t}: {name} reported (last /diagnostics) {received} received, {lost} lost '
                  '(by its last report seen during the play; it may still be taking the rest)')
            if lost:
                print(f'play: warning: {t}: {name} reports {lost} messages lost before reaching it '
                      f'(input.{t}.lost in its /diagnostics)', file=sys.stderr)


def _watch_input_reports(node: Any, topics: Sequence[str], reports: InputReports, qos: Any) -> bool:
    """If someone publishes /diagnostics, keep the input counters of the played topics in ``reports``."""
    topic = node.resolve_topic_name('/diagnostics')
    if not node.get_publishers_info_by_topic(topic):
        return False
    from diagnostic_msgs.msg import DiagnosticArray

    node.create_subscription(DiagnosticArray, topic, lambda msg: read_input_reports(msg, topics, reports), qos)
    return True


@dataclass
class FusionWatch:
    """What the player saw of a fusion node's ``/fusion/status``."""

    counts: dict[str, int] = field(default_factory=dict)
    """Cumulative rejection counts of its latest status, per reason (empty: no status seen)."""
    latest_stamp_ns: int = -1
    """The latest header stamp of its statuses, ns (-1: none seen)."""

    def on_status(self, msg: Any) -> None:
        self.counts.update(zip(msg.rejection_reasons, msg.rejection_counts, strict=False))
        self.counts.setdefault(LATE_REASON, 0)
        self.latest_stamp_ns = max(self.latest_stamp_ns, msg.header.stamp.sec * 1_000_000_000
                                   + msg.header.stamp.nanosec)


def _watch_fusion_status(node: Any, fusion: FusionWatch, qos: Any) -> Any:
    """Subscribe ``fusion`` to /fusion/status (whether or not a fusion node is up yet: one that the graph shows
    only later, or whose publisher is discovered after its subscriptions, is still heard); the subscription."""
    from rfi_msgs.msg import FusionStatus

    return node.create_subscription(FusionStatus, node.resolve_topic_name('/fusion/status'), fusion.on_status, qos)


def _await_fusion_status(node: Any, executor: Any, fusion: FusionWatch, status_sub: Any,
                         last_stamp: dict[str, int], timeout_s: float) -> str | None:
    """After the last message: spin until the fusion node has published a status stamped at or after the latest
    header stamp played on the topics it subscribes to (``last_stamp``: resolved topic -> ns), i.e. until it has
    processed (or rejected) everything it was sent, or ``timeout_s``. The fusion node processes its inputs in stamp
    order and publishes a status after each update, also for the messages that its re-ordering window still holds
    when the input stops (its idle flush). Returns None, or a warning if the wait ran out."""
    if not status_sub.get_publisher_count():
        return None
    publishers = {(i.node_name, i.node_namespace) for i in node.get_publishers_info_by_topic(status_sub.topic_name)}
    inputs = [t for t in last_stamp
              if any((i.node_name, i.node_namespace) in publishers for i in node.get_subscriptions_info_by_topic(t))]
    if not inputs:
        return None
    target_ns = max(last_stamp[t] for t in inputs)
    give_up = time.monotonic() + timeout_s
    while fusion.latest_stamp_ns < target_ns and time.monotonic() < give_up:
        executor.spin_once(timeout_sec=0.05)
    if fusion.latest_stamp_ns >= target_ns:
        return None
    seen = 'no status' if fusion.latest_stamp_ns < 0 else f'its last status stamped {fusion.latest_stamp_ns} ns'
    return (f'play: warning: the fusion node had not processed the last message played on {", ".join(inputs)} '
            f'(stamped {target_ns} ns) within --status-timeout {timeout_s:g} s ({seen}): its late rejections after '
            'that are not counted here')


def _discover_class(node, executor, topic: str, timeout_s: float):
    """The message class of ``topic`` from the graph, or None if no endpoint appears in time."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        types = dict(node.get_topic_names_and_types()).get(node.resolve_topic_name(topic))
        if types:
            return message_class(types[0])
        executor.spin_once(timeout_sec=0.05)
    return None


def _answer_recorder(answered: dict[str, int], topic: str):
    """Callback keeping in ``answered[topic]`` the latest header stamp seen on ``topic``, ns."""
    def on_message(msg) -> None:
        stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        answered[topic] = max(answered.get(topic, -1), stamp_ns)
    return on_message


if __name__ == '__main__':
    sys.exit(main())


def cli() -> None:
    """The ``play`` executable: :func:`main` without the ROS teardown (only its endpoints are released:
    ``rfi_experiments.cli.release_endpoints``), then the process ends at once with its exit code
    (``rfi_experiments.cli.exit_now``: a teardown that hangs holding the GIL cannot be bounded by a thread)."""
    exit_now(lambda: main(teardown=False))
