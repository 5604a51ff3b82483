"""``ros2 run rfi_experiments record OUT --topics ...``: subscribe and write an mcap bag.

Messages are written as the serialized bytes received (no re-encoding), with the receive time as
log time. Topic types are taken from the graph (``--type TOPIC=pkg/msg/Name`` when the publisher
is not up yet). Recording stops on Ctrl-C / SIGTERM, after ``--max-messages`` or after
``--duration`` seconds; the bag is closed cleanly in every case and a count per topic printed.

Reliability of each subscription (``--reliability``, default ``auto``): as rosbag2 does, from the
QoS that the topic's discovered publishers offer: reliable if every one of them is reliable, best
effort otherwise (a reliable subscription refuses a best-effort publisher, a sensor driver's
usual QoS, and would record nothing from it). With no publisher discovered within
``--discovery-timeout`` the subscription is reliable. The choice per topic is printed.

If the output folder disappears (or a write fails) while recording, ``record`` stops with an error
that names the folder and the number of messages written before, and exits with code 1.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rfi_experiments.bag_io import BagError, BagWriter, message_class
from rfi_experiments.cli import EXIT_FAILED, bounded_teardown, error_reporter, exit_now, release_endpoints

fail = error_reporter('record')

RELIABILITY_CHOICES = ('auto', 'reliable', 'best_effort')


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='record', description='Record topics into an mcap bag.')
    parser.add_argument('out', help='bag directory to create')
    parser.add_argument('--topics', nargs='+', required=True, metavar='TOPIC', help='topics to record')
    parser.add_argument('--type', action='append', default=[], metavar='TOPIC=TYPE',
                        help='type of a topic, e.g. /rfi/if_samples=rfi_msgs/msg/IfSamples '
                             '(default: discovered from the graph)')
    parser.add_argument('--discovery-timeout', type=float, default=10.0, metavar='SECONDS',
                        help='how long to wait for the publishers of the topics: their type (topics without '
                             '--type) and their QoS (--reliability auto) (default 10)')
    parser.add_argument('--reliability', choices=RELIABILITY_CHOICES, default='auto',
                        help='QoS reliability of the subscriptions: auto (default) = reliable if every '
                             'discovered publisher of the topic is reliable, else best effort (as rosbag2); '
                             'reliable if no publisher was discovered')
    parser.add_argument('--max-messages', type=int, default=0, metavar='N',
                        help='stop after N messages in all (default: no limit)')
    parser.add_argument('--duration', type=float, default=0.0, metavar='SECONDS',
                        help='stop after this many seconds (default: no limit)')
    parser.add_argument('--overwrite', action='store_true', help='replace an existing bag')
    return parser


def offered_reliability(publishers: Sequence[Any]) -> tuple[str, str]:
    """Subscription reliability for a topic from its publishers' endpoint infos (as rosbag2 adapts
    to the offered QoS): ('reliable' | 'best_effort', why)."""
    from rclpy.qos import ReliabilityPolicy

    if not publishers:
        return 'reliable', 'no publisher discovered'
    best_effort = [p for p in publishers if p.qos_profile.reliability != ReliabilityPolicy.RELIABLE]
    if best_effort:
        names = ', '.join(sorted({p.node_name for p in best_effort} - {'', '_NODE_NAME_UNKNOWN_'}))
        return 'best_effort', (f'{len(best_effort)} of {len(publishers)} publishers offer best effort'
                               + (f': {names}' if names else ''))
    n = len(publishers)
    return 'reliable', f'{n} publisher{"s" if n > 1 else ""}, all reliable'


def subscription_qos(reliability: str) -> Any:
    """RECORDER_QOS (keep all, volatile) with the given reliability."""
    import copy

    from rclpy.qos import ReliabilityPolicy

    from rfi_node_common.qos import RECORDER_QOS

    qos = copy.copy(RECORDER_QOS)
    qos.reliability = ReliabilityPolicy.RELIABLE if reliability == 'reliable' else ReliabilityPolicy.BEST_EFFORT
    return qos


class RecordingFailed(Exception):
    """The bag could not be written any more (its folder disappeared, a write failed)."""


def main(argv: Sequence[str] | None = None, *, teardown: bool = True) -> int:
    """Record (module docstring); the exit code. ``teardown`` False: leave the node and ROS as they are once the bag is
    closed (the executable, which ends the process at once: :func:`cli`)."""
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.utilities import remove_ros_args

    argv = list(sys.argv if argv is None else argv)
    args = build_parser().parse_args(remove_ros_args(argv)[1:])
    types: dict[str, str] = {}
    for item in args.type:
        topic, sep, msgtype = item.partition('=')
        if not sep or not topic or not msgtype:
            return fail(f'--type wants TOPIC=pkg/msg/Name, got {item!r}')
        types[topic] = msgtype
    topics = list(dict.fromkeys(args.topics))
    try:
        classes = {t: message_class(m) for t, m in types.items()}
    except BagError as err:
        return fail(str(err))

    rclpy.init(args=argv)
    node = rclpy.create_node('rfi_record')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    stop = {'requested': False}
    signal.signal(signal.SIGTERM, lambda *_: stop.update(requested=True))
    writer = None
    out = Path(args.out)
    failure: list[str] = []
    try:
        # Wait for the publishers: the type of every topic without --type (required), and a publisher
        # of every topic to adapt the reliability to (--reliability auto; bounded by the timeout).
        deadline = time.monotonic() + args.discovery_timeout
        resolved = {t: node.resolve_topic_name(t) for t in topics}
        while True:
            graph = dict(node.get_topic_names_and_types())
            for t in topics:
                if t not in types and graph.get(resolved[t]):
                    types[t] = graph[resolved[t]][0]
            untyped = [t for t in topics if t not in types]
            silent = [t for t in topics if not node.get_publishers_info_by_topic(resolved[t])]
            if not untyped and (args.reliability != 'auto' or not silent):
                break
            if time.monotonic() > deadline:
                if untyped:
                    return fail(f'no publisher of {", ".join(untyped)} appeared within '
                                f'{args.discovery_timeout} s (give --type TOPIC=TYPE to record anyway)')
                break
            executor.spin_once(timeout_sec=0.05)
        try:
            classes.update({t: message_class(types[t]) for t in topics if t not in classes})
            writer = BagWriter(out, overwrite=args.overwrite)
            writer.__enter__()
        except BagError as err:
            return fail(str(err))

        total = {'n': 0}

        def make_callback(topic: str):
            def on_message(raw: bytes) -> None:
                if failure:
                    return
                try:
                    writer.write_raw(topic, types[topic], raw, node.get_clock().now().nanoseconds)
                except Exception as err:  # noqa: BLE001 - OSError, or rosbags' own errors on a broken file
                    failure.append(f'writing {topic} failed ({type(err).__name__}: {err})')
                    return
                total['n'] += 1
            return on_message

        chosen = {t: offered_reliability(node.get_publishers_info_by_topic(resolved[t]))
                  if args.reliability == 'auto' else (args.reliability, '--reliability') for t in topics}
        for t, (reliability, _) in chosen.items():  # all at once: a player waits for them together
            node.create_subscription(classes[t], t, make_callback(t), subscription_qos(reliability), raw=True)
        for t, (reliability, why) in chosen.items():
            print(f'record: {t}: {reliability.replace("_", " ")} subscription ({why})', flush=True)
        end = time.monotonic() + args.duration if args.duration > 0 else None
        next_check = 0.0
        while not stop['requested'] and not failure:
            executor.spin_once(timeout_sec=0.1)
            if time.monotonic() >= next_check:  # a write to a deleted folder succeeds (unlinked file): look
                next_check = time.monotonic() + 0.2
                if not out.is_dir() or not any(out.glob('*.mcap')):
                    failure.append(f'the output folder {out} (or its mcap file) disappeared')
            if args.max_messages and total['n'] >= args.max_messages:
                break
            if end is not None and time.monotonic() > end:
                break
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if writer is not None:
            try:
                writer.__exit__(None, None, None)
            except Exception as err:  # noqa: BLE001 - metadata.yaml cannot be written into a vanished folder
                if not failure:
                    failure.append(f'closing the bag in {out} failed ({type(err).__name__}: {err})')
            width = max(len(t) for t in topics)
            for t in topics:
                print(f'{t:<{width}}  {types.get(t, "?"):<34} {writer.counts.get(t, 0):>9}')
            written = sum(writer.counts.values())
            if failure:
                print(f'record: error: {failure[0]}; {written} messages had been written to {out} before, and '
                      f'the bag there is {"gone" if not out.is_dir() else "incomplete"}', file=sys.stderr)
            else:
                print(f'record: wrote {written} messages to {out}')
        if teardown:
            bounded_teardown('record', executor, node, rclpy)
        else:
            release_endpoints(node)
    return EXIT_FAILED if failure else 0


def cli() -> None:
    """The ``record`` executable: :func:`main` without the ROS teardown (only its endpoints are released:
    ``rfi_experiments.cli.release_endpoints``), then the process ends at once with its exit code
    (``rfi_experiments.cli.exit_now``: a teardown that hangs holding the GIL cannot be bounded by a thread)."""
    exit_now(lambda: main(teardown=False))
