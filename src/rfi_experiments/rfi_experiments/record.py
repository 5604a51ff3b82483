"""``ros2 run rfi_experiments record OUT --topics ...``: subscribe and write an mcap bag.

Messages are written as the serialized bytes received (no re-encoding), with the receive time as
log time. Topic types are taken from the graph (``--type TOPIC=pkg/msg/Name`` when the publisher
is not up yet). Recording stops on Ctrl-C / SIGTERM, after ``--max-messages`` or after
``--duration`` seconds; the bag is closed cleanly in every case and a count per topic printed.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from collections.abc import Sequence

from rfi_experiments.bag_io import BagError, BagWriter, message_class

EXIT_USAGE = 2


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='record', description='Record topics into an mcap bag.')
    parser.add_argument('out', help='bag directory to create')
    parser.add_argument('--topics', nargs='+', required=True, metavar='TOPIC', help='topics to record')
    parser.add_argument('--type', action='append', default=[], metavar='TOPIC=TYPE',
                        help='type of a topic, e.g. /rfi/if_samples=rfi_msgs/msg/IfSamples '
                             '(default: discovered from the graph)')
    parser.add_argument('--discovery-timeout', type=float, default=10.0, metavar='SECONDS',
                        help='how long to wait for the publishers of topics without --type (default 10)')
    parser.add_argument('--max-messages', type=int, default=0, metavar='N',
                        help='stop after N messages in all (default: no limit)')
    parser.add_argument('--duration', type=float, default=0.0, metavar='SECONDS',
                        help='stop after this many seconds (default: no limit)')
    parser.add_argument('--overwrite', action='store_true', help='replace an existing bag')
    return parser


def fail(message: str) -> int:
    print(f'record: error: {message}', file=sys.stderr)
    return EXIT_USAGE


def main(argv: Sequence[str] | None = None) -> int:
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.utilities import remove_ros_args

    from rfi_node_common.qos import RECORDER_QOS

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
    try:
        deadline = time.monotonic() + args.discovery_timeout
        while any(t not in types for t in topics):
            graph = dict(node.get_topic_names_and_types())
            for t in topics:
                if t not in types and graph.get(t):
                    types[t] = graph[t][0]
            if time.monotonic() > deadline:
                missing = [t for t in topics if t not in types]
                return fail(f'no publisher of {", ".join(missing)} appeared within '
                            f'{args.discovery_timeout} s (give --type TOPIC=TYPE to record anyway)')
            executor.spin_once(timeout_sec=0.05)
        try:
            classes.update({t: message_class(types[t]) for t in topics if t not in classes})
            writer = BagWriter(args.out, overwrite=args.overwrite)
            writer.__enter__()
        except BagError as err:
            return fail(str(err))

        total = {'n': 0}

        def make_callback(topic: str):
            def on_message(raw: bytes) -> None:
                writer.write_raw(topic, types[topic], raw, node.get_clock().now().nanoseconds)
                total['n'] += 1
            return on_message

        for t in topics:
            node.create_subscription(classes[t], t, make_callback(t), RECORDER_QOS, raw=True)
        end = time.monotonic() + args.duration if args.duration > 0 else None
        while not stop['requested']:
            executor.spin_once(timeout_sec=0.1)
            if args.max_messages and total['n'] >= args.max_messages:
                break
            if end is not None and time.monotonic() > end:
                break
        return 0
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    finally:
        if writer is not None:
            writer.__exit__(None, None, None)
            width = max(len(t) for t in topics)
            for t in topics:
                print(f'{t:<{width}}  {types.get(t, "?"):<34} {writer.counts.get(t, 0):>9}')
            print(f'record: wrote {sum(writer.counts.values())} messages to {args.out}')
        executor.remove_node(node)
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    sys.exit(main())
