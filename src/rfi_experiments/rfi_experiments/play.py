"""``ros2 run rfi_experiments play BAG``: publish a bag's messages on their topics.

Messages go out as the serialized bytes stored in the bag (no re-encoding), in log-time order,
at the recorded pace times ``--rate`` or as fast as the middleware takes them (``--max``). The
publishers are reliable and keep all samples, and the player waits for every subscriber to
acknowledge before it exits, so nothing is dropped. A progress bar runs on stderr; a count per
topic ends the run.
"""

from __future__ import annotations

import argparse
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
    parser.add_argument('--wait-subscribers', type=float, default=0.0, metavar='SECONDS',
                        help='before playing, wait up to this long until every topic has a subscriber')
    parser.add_argument('--ack-timeout', type=float, default=10.0, metavar='SECONDS',
                        help='after playing, wait up to this long for subscribers to acknowledge (default 10)')
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')
    return parser


def fail(message: str) -> int:
    print(f'play: error: {message}', file=sys.stderr)
    return EXIT_USAGE


def main(argv: Sequence[str] | None = None) -> int:
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.utilities import remove_ros_args

    from rfi_node_common.qos import PLAYER_QOS

    argv = list(sys.argv if argv is None else argv)
    args = build_parser().parse_args(remove_ros_args(argv)[1:])
    if not args.max and not args.rate > 0.0:
        return fail(f'--rate must be > 0 (got {args.rate})')

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
        total = sum(available[t][1] for t in topics)

        rclpy.init(args=argv)
        node = rclpy.create_node('rfi_play')
        counts = {t: 0 for t in topics}
        try:
            publishers = {t: node.create_publisher(classes[t], t, PLAYER_QOS) for t in topics}
            deadline = time.monotonic() + args.wait_subscribers
            while args.wait_subscribers > 0 and time.monotonic() < deadline:
                if all(p.get_subscription_count() > 0 for p in publishers.values()):
                    break
                time.sleep(0.05)
            progress = None
            if not args.no_progress:
                from tqdm import tqdm
                progress = tqdm(total=total, unit='msg', desc='play', file=sys.stderr, mininterval=0.5)
            wall_start = time.monotonic()
            bag_start = None
            for message in reader.messages(topics):
                if not args.max:
                    bag_start = message.stamp_ns if bag_start is None else bag_start
                    due = wall_start + (message.stamp_ns - bag_start) * 1e-9 / args.rate
                    delay = due - time.monotonic()
                    if delay > 0:
                        time.sleep(delay)
                publishers[message.topic].publish(message.raw)
                counts[message.topic] += 1
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
            node.destroy_node()
            rclpy.try_shutdown()


if __name__ == '__main__':
    sys.exit(main())
