"""The tools' bounded teardown and immediate exit (rfi_experiments.cli): a ROS shutdown that hangs does not keep
``play`` or ``record`` alive after their work is done (once in several hundred test-suite runs ``record`` had
closed its bag and never exited)."""

import subprocess
import sys
import threading
import time

from rfi_experiments import cli


def _run_python(code: str) -> subprocess.CompletedProcess:
    """``python -c code`` in a new interpreter, which must end by itself well before the 30 s kill."""
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=30)
    assert time.monotonic() - t0 < 20
    return proc


class _Node:
    def __init__(self) -> None:
        self.destroyed = False

    def destroy_node(self) -> None:
        self.destroyed = True


class _Executor:
    def __init__(self, hang: threading.Event | None = None) -> None:
        self.hang = hang
        self.removed = False

    def remove_node(self, node) -> None:
        if self.hang is not None:
            self.hang.wait()          # a middleware call that never returns
        self.removed = True


class _Rclpy:
    def __init__(self) -> None:
        self.shut_down = False

    def try_shutdown(self) -> None:
        self.shut_down = True


def test_a_teardown_that_returns_is_complete(capsys):
    node, executor, rclpy = _Node(), _Executor(), _Rclpy()
    cli.bounded_teardown("play", executor, node, rclpy)
    assert executor.removed and node.destroyed and rclpy.shut_down
    assert capsys.readouterr().err == ""


def test_a_teardown_that_hangs_is_left_behind_and_reported(monkeypatch, capsys):
    monkeypatch.setattr(cli, "TEARDOWN_TIMEOUT_S", 0.2)
    hang = threading.Event()
    node, executor, rclpy = _Node(), _Executor(hang), _Rclpy()
    t0 = time.monotonic()
    try:
        cli.bounded_teardown("record", executor, node, rclpy)
        elapsed = time.monotonic() - t0
    finally:
        hang.set()                    # release the daemon thread
    assert 0.15 < elapsed < 5.0
    assert not node.destroyed
    assert "record: ROS shutdown did not finish within 0.2 s; exiting anyway" in capsys.readouterr().err


def test_exit_now_ends_the_process_with_main_s_code_despite_a_live_thread():
    """A non-daemon thread that never ends would keep an ordinary interpreter alive at exit; exit_now does not
    wait for it, and what main printed is flushed."""
    code = (
        "import threading, time\n"
        "from rfi_experiments.cli import exit_now\n"
        "threading.Thread(target=lambda: time.sleep(60)).start()\n"
        "def main():\n"
        "    print('done', end='')\n"
        "    return 3\n"
        "exit_now(main)\n"
    )
    proc = _run_python(code)
    assert proc.returncode == 3 and proc.stdout == "done"


class _EndpointNode:
    def __init__(self) -> None:
        self.subscriptions = ['s1', 's2']
        self.publishers = ['p1']
        self.destroyed: list[str] = []

    def destroy_subscription(self, sub) -> None:
        self.destroyed.append(sub)

    def destroy_publisher(self, pub) -> None:
        self.destroyed.append(pub)


def test_release_endpoints_destroys_subscriptions_and_publishers():
    node = _EndpointNode()
    cli.release_endpoints(node, timeout_s=5.0)
    assert node.destroyed == ['s1', 's2', 'p1']


def test_release_endpoints_that_hang_end_the_process_with_its_stacks():
    """The watchdog is C-level (faulthandler): a release that never returns ends the process (status 1, every
    thread's stack on stderr) instead of hanging it."""
    code = (
        "import time\n"
        "from rfi_experiments.cli import release_endpoints\n"
        "class Node:\n"
        "    subscriptions = ['s']\n"
        "    publishers = []\n"
        "    def destroy_subscription(self, sub):\n"
        "        time.sleep(60)\n"
        "release_endpoints(Node(), timeout_s=0.5)\n"
        "print('not reached')\n"
    )
    proc = _run_python(code)
    assert proc.returncode == 1 and 'not reached' not in proc.stdout
    assert 'Timeout' in proc.stderr and 'destroy_subscription' in proc.stderr
