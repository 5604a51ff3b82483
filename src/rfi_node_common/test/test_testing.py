"""The progress-bounded waits of rfi_node_common.testing (issue 27 item 6): a wait fails when nothing has moved
for its stall time, not after a fixed total, and never passes by itself.

Time passing is the stimulus here (short sleeps and busy loops), never what a result depends on: each bound below
is either a failure that must come (nothing progresses at all) or a margin of several times the stall time."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest
import rclpy
from rclpy.context import Context
from rclpy.node import Node
from std_msgs.msg import String

from rfi_node_common import testing
from rfi_node_common.qos import DATA_QOS


def test_a_wait_with_no_progress_fails_after_its_stall_time():
    watch = testing.Stall(lambda: 0, 'the thing', stall_s=0.2)
    t0 = time.monotonic()
    with pytest.raises(AssertionError, match='the thing: nothing progressed for 0.2 s'):
        while True:
            watch.check()
            time.sleep(0.01)
    assert time.monotonic() - t0 >= 0.2      # a lower bound: load can only make it later


def test_a_wait_that_progresses_goes_on_past_its_stall_time():
    count = [0]

    def progress() -> int:
        count[0] += 1                          # moves at every look
        return count[0]

    watch = testing.Stall(progress, stall_s=0.1, look_every_s=0.0)
    t0 = time.monotonic()
    while time.monotonic() - t0 < 0.5:         # five stall times, all the while progressing
        watch.check()
        time.sleep(0.01)
    assert watch.changes >= 2


def test_a_wait_that_progresses_forever_fails_at_its_limit():
    count = [0]

    def progress() -> int:
        count[0] += 1
        return count[0]

    watch = testing.Stall(progress, 'the livelock', stall_s=0.1, limit_s=0.3, look_every_s=0.0)
    with pytest.raises(AssertionError, match='the livelock: not done within 0.3 s although it progressed'):
        while True:
            watch.check()
            time.sleep(0.01)


def test_bounds_are_checked():
    with pytest.raises(ValueError):
        testing.Stall(lambda: 0, stall_s=0.0)
    with pytest.raises(ValueError):
        testing.Stall(lambda: 0, stall_s=2.0, limit_s=1.0)


def test_wait_until_returns_once_done_and_fails_when_nothing_moves():
    n = [0]
    testing.wait_until(lambda: n[0] >= 3, lambda: n.__setitem__(0, n[0] + 1), lambda: n[0], stall_s=0.5)
    assert n[0] == 3
    with pytest.raises(AssertionError, match='never: nothing progressed'):
        testing.wait_until(lambda: False, lambda: time.sleep(0.01), lambda: 0, 'never', stall_s=0.1)


BUSY = 'import time\nwhile time.process_time() < {cpu_s}: pass\n'
IDLE = 'import time\nprint("asleep", flush=True)\ntime.sleep(600)\n'


def test_process_cpu_s_grows_while_a_process_computes_and_not_while_it_sleeps():
    busy = subprocess.Popen([sys.executable, '-c', BUSY.format(cpu_s=600)])
    idle = subprocess.Popen([sys.executable, '-c', IDLE], stdout=subprocess.PIPE, text=True)
    try:
        assert idle.stdout.readline() == 'asleep\n'   # past its start-up (imports)
        b0, i0 = testing.process_cpu_s(busy.pid), testing.process_cpu_s(idle.pid)
        testing.wait_until(lambda: testing.process_cpu_s(busy.pid) >= b0 + 0.1, lambda: time.sleep(0.05),
                           lambda: testing.process_cpu_s(busy.pid), 'the busy process', stall_s=30.0)
        assert testing.process_cpu_s(idle.pid) - i0 < 0.05
    finally:
        for proc in (busy, idle):
            proc.kill()
            proc.wait()
    assert testing.process_cpu_s(busy.pid) == 0.0    # ended (and reaped): nothing to count


def test_process_cpu_s_counts_the_descendants():
    parent = subprocess.Popen([sys.executable, '-c', 'import subprocess, sys\n'
                               f'subprocess.run([sys.executable, "-c", {BUSY.format(cpu_s=600)!r}])\n'])
    try:
        testing.wait_until(lambda: testing.process_cpu_s(parent.pid) - testing.process_cpu_s(
            parent.pid, descendants=False) >= 0.2, lambda: time.sleep(0.05),
            lambda: testing.process_cpu_s(parent.pid), 'the child computing', stall_s=30.0)
    finally:
        for pid in (p for p in _children(parent.pid)):
            subprocess.run(['kill', '-9', str(pid)], check=False)
        parent.kill()
        parent.wait()


def _children(pid: int) -> list[int]:
    out = subprocess.run(['ps', '-o', 'pid=', '--ppid', str(pid)], capture_output=True, text=True).stdout
    return [int(x) for x in out.split()]


def test_run_process_lets_a_computing_process_run_past_its_stall_time():
    t0 = time.monotonic()
    done = testing.run_process([sys.executable, '-c', BUSY.format(cpu_s=2.0) + 'print("done")'], stall_s=1.0,
                               text=True)
    assert done.returncode == 0 and done.stdout == 'done\n'
    assert time.monotonic() - t0 > 1.0        # it took longer than the stall time, and did not fail


def test_run_process_fails_a_process_that_hangs_and_kills_it():
    with pytest.raises(AssertionError, match='hangs: nothing progressed for 1.0 s'):
        testing.run_process([sys.executable, '-c', 'import sys, time\nprint("started", file=sys.stderr, flush=True)\n'
                             'time.sleep(600)'], 'hangs', stall_s=1.0, text=True)


def test_run_process_counts_the_cpu_of_the_processes_it_waits_for():
    """A process that sleeps while another one it waits for computes (play waiting for a node's start-up) is not
    stalled; the same sleep with nothing computing fails."""
    busy = subprocess.Popen([sys.executable, '-c', BUSY.format(cpu_s=600)])
    try:
        done = testing.run_process([sys.executable, '-c', 'import time\ntime.sleep(2.5)\nprint("done")'],
                                   stall_s=1.5, also=(busy.pid,), text=True)
        assert done.returncode == 0 and done.stdout == 'done\n'
    finally:
        busy.kill()
        busy.wait()
    with pytest.raises(AssertionError, match='nothing progressed for 1.5 s'):
        testing.run_process([sys.executable, '-c', 'import time\ntime.sleep(2.5)'], stall_s=1.5, text=True)


def test_a_rig_counts_messages_taken_not_timer_callbacks():
    context = Context()
    rclpy.init(context=context)
    try:
        node = Node('counting_executor_test', context=context)
        got: list[String] = []
        node.create_subscription(String, '/counting_executor_test', got.append, DATA_QOS)
        pub = node.create_publisher(String, '/counting_executor_test', DATA_QOS)
        ticks = [0]
        node.create_timer(0.001, lambda: ticks.__setitem__(0, ticks[0] + 1))
        executor = testing.CountingExecutor(context=context)
        executor.add_node(node)
        testing.wait_until(lambda: ticks[0] >= 5, lambda: executor.spin_once(timeout_sec=0.05), lambda: ticks[0])
        assert executor.messages_taken == 0
        testing.wait_until(lambda: pub.get_subscription_count() >= 1, lambda: executor.spin_once(timeout_sec=0.05),
                           lambda: 0, 'no match')
        pub.publish(String(data='x'))
        testing.wait_until(lambda: bool(got), lambda: executor.spin_once(timeout_sec=0.05),
                           lambda: executor.messages_taken, 'not received')
        assert executor.messages_taken == 1
        executor.shutdown()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
