"""``ros2 run rfi_experiments play BAG``: publish a bag's messages on their topics.

Messages go out as the serialized bytes stored in the bag (no re-encoding), in log-time order,
at the recorded pace times ``--rate`` or as fast as the middleware takes them (``--max``), the
whole bag or a window of it (``--start``, ``--duration``: seconds after the bag's first message). The
publishers are reliable and keep all samples, and the player waits for every subscriber to
acknowledge before it exits, so nothing is dropped. A progress bar runs on stderr; a count per
topic ends the run. With ``--sync IN:OUT`` the player waits after each message on IN until the
node that answers it has published its stamped output on OUT (closed-loop pacing, used by ``run
--transport processes`` so that the monitor's jammer state reaches the fusion before the next
GNSS/UWB messages, as in a replay in one process).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence

from rfi_experiments.bag_io import BagError, BagReader, message_class

EXIT_USAGE = 2


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
    parser.add_argument('--wait-subscribers', type=float, default=0.0, metavar='SECONDS',
                        help='before playing, wait up to this long until every topic has a subscriber')
    parser.add_argument('--start-delay', type=float, default=0.0, metavar='SECONDS',
                        help='once the subscribers are matched, wait this long before the first message: the '
                             'subscribers\' side of discovery completes a little later, and until then the '
                             'middleware repairs their first messages only by retransmission (default 0)')
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
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')
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


def fail(message: str) -> int:
    print(f'play: error: {message}', file=sys.stderr)
    return EXIT_USAGE


def main(argv: Sequence[str] | None = None) -> int:
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.utilities import remove_ros_args

    from rfi_node_common.qos import PLAYER_QOS, RECORDER_QOS

    argv = list(sys.argv if argv is None else argv)
    args = build_parser().parse_args(remove_ros_args(argv)[1:])
    if not args.max and not args.rate > 0.0:
        return fail(f'--rate must be > 0 (got {args.rate})')
    try:
        window = window_s(args.start, args.duration)
    except ValueError as err:
        return fail(str(err))
    for name in ('start_delay', 'warmup'):
        value = getattr(args, name)
        if not (math.isfinite(value) and value >= 0):
            return fail(f'--{name.replace("_", "-")} must be a finite number >= 0 (got {value})')
    if not (math.isfinite(args.warmup_rate) and args.warmup_rate > 0):
        return fail(f'--warmup-rate must be a finite number > 0 (got {args.warmup_rate})')
    sync: dict[str, str] = {}
    for item in args.sync:
        inp, sep, out = item.partition(':')
        if not sep or not inp.startswith('/') or not out.startswith('/'):
            return fail(f'--sync wants IN:OUT (two topic names), got {item!r}')
        sync[inp] = out
    if not (math.isfinite(args.sync_timeout) and args.sync_timeout > 0):
        return fail(f'--sync-timeout must be a finite number > 0 (got {args.sync_timeout})')

    try:
        reader = BagReader(args.bag)
    except BagError as err:
        return fail(str(err))
    with reader:
        available = reader.topics
        topics = sorted(available) if not args.topics else list(dict.fromkeys(args.topics))
        unknown = [t for t in topics if t not in available]
        if unknown:
            return fail(f'topic filter matches nothing in {args.bag}: {", ".join(unknown)} '
                        f'(the bag has {", ".join(sorted(available)) or "no topics"})')
        if not topics:
            return fail(f'{args.bag} holds no topics')
        try:
            classes = {t: message_class(available[t][0]) for t in topics}
        except BagError as err:
            return fail(str(err))
        start_ns, stop_ns = window_ns(reader.start_ns, window)
        if window is None:
            total = sum(available[t][1] for t in topics)
        else:
            total = sum(1 for _ in reader.messages(topics, start_ns=start_ns, stop_ns=stop_ns))
            if total == 0:
                return fail(f'no message of {", ".join(topics)} in the window {window[0]}-{window[1]} s of {args.bag}')

        not_played = [t for t in sync if t not in topics]
        if not_played:
            return fail(f'--sync input {", ".join(not_played)} is not played')

        rclpy.init(args=argv)
        node = rclpy.create_node('rfi_play')
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        counts = {t: 0 for t in topics}
        answered: dict[str, int] = {}
        unanswered = {t: 0 for t in sync}
        try:
            publishers = {t: node.create_publisher(classes[t], t, PLAYER_QOS) for t in topics}
            deadline = time.monotonic() + args.wait_subscribers
            while args.wait_subscribers > 0 and time.monotonic() < deadline:
                if all(p.get_subscription_count() > 0 for p in publishers.values()):
                    break
                time.sleep(0.05)
            for inp, out in sync.items():
                out_class = _discover_class(node, executor, out, max(args.wait_subscribers, args.sync_timeout))
                if out_class is None:
                    return fail(f'--sync: no publisher of {out} appeared (is the node answering {inp} up?)')
                node.create_subscription(out_class, out, _answer_recorder(answered, out), RECORDER_QOS)
            progress = None
            if not args.no_progress:
                from tqdm import tqdm
                progress = tqdm(total=total, unit='msg', desc='play', file=sys.stderr, mininterval=0.5)
            if args.start_delay > 0:
                end = time.monotonic() + args.start_delay
                while time.monotonic() < end:
                    executor.spin_once(timeout_sec=0.05)
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
                publishers[message.topic].publish(message.raw)
                counts[message.topic] += 1
                if message.topic in sync:
                    out = sync[message.topic]
                    header = message.decode().header.stamp
                    stamp_ns = header.sec * 1_000_000_000 + header.nanosec
                    give_up = time.monotonic() + args.sync_timeout
                    while answered.get(out, -1) < stamp_ns and time.monotonic() < give_up:
                        executor.spin_once(timeout_sec=0.01)
                    if answered.get(out, -1) < stamp_ns:
                        unanswered[message.topic] += 1
                if progress is not None:
                    progress.update(1)
            if progress is not None:
                progress.close()
            unacked = [t for t, p in publishers.items()
                       if p.get_subscription_count() > 0 and not p.wait_for_all_acked(
                           rclpy.duration.Duration(seconds=args.ack_timeout))]
            width = max(len(t) for t in topics)
            print(f'{"topic":<{width}}  {"type":<34} {"published":>9}')
            for t in topics:
                print(f'{t:<{width}}  {available[t][0]:<34} {counts[t]:>9}')
            print(f'{"total":<{width}}  {"":<34} {sum(counts.values()):>9}')
            for inp, n in unanswered.items():
                print(f'sync {inp} -> {sync[inp]}: {counts[inp] - n} answered, {n} not within {args.sync_timeout:g} s')
            if unacked:
                print(f'play: warning: not acknowledged by every subscriber within {args.ack_timeout} s: '
                      f'{", ".join(unacked)}', file=sys.stderr)
                return 1
            return 0
        except BagError as err:
            return fail(str(err))
        except (KeyboardInterrupt, ExternalShutdownException):
            print(f'play: interrupted after {sum(counts.values())} of {total} messages', file=sys.stderr)
            return 130
        finally:
            executor.remove_node(node)
            node.destroy_node()
            rclpy.try_shutdown()


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
