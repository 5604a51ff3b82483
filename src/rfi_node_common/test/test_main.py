"""run_node (rfi_node_common.main): Ctrl-C while a node runs ends it through the context's shutdown, never through a
KeyboardInterrupt raised inside whatever Python was running (a half-built rclpy object then printed a traceback)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

CHILD = textwrap.dedent('''
    import atexit, gc, os, signal, sys, time
    import rclpy
    # registered before run_node's exit hook, so it runs after it (last registered, first run)
    atexit.register(lambda: print('heap frozen at exit', gc.get_freeze_count() > 0, flush=True))
    # Python's own Ctrl-C handler, whatever disposition this process inherited (a parent that ignores
    # SIGINT passes SIG_IGN on to its children, and Python then installs no handler at start)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    from rclpy.node import Node
    from rfi_node_common.main import run_node

    class Node_(Node):
        def __init__(self):
            super().__init__('sigint_probe')
            self.create_timer(0.05, self.tick)
            self.n = 0

        def tick(self):
            self.n += 1
            if self.n == 3:
                os.kill(os.getpid(), signal.SIGINT)   # Ctrl-C arrives in the middle of a callback
                t0 = time.monotonic()
                while time.monotonic() - t0 < 0.2:
                    pass
                print('callback completed', flush=True)

    code = run_node(Node_, executable='sigint_probe', summary='probe', topics='')
    print('exit', code, 'handler restored', signal.getsignal(signal.SIGINT) is signal.default_int_handler, flush=True)
    sys.exit(code)
''')


def test_ctrl_c_during_a_callback_ends_the_node_after_it_cleanly():
    done = subprocess.run([sys.executable, '-c', CHILD], capture_output=True, text=True, timeout=60)
    text = done.stdout + done.stderr
    assert done.returncode == 0, text
    assert 'callback completed' in done.stdout, text          # not interrupted half-way
    assert 'exit 0 handler restored True' in done.stdout, text
    # the interpreter's final garbage collection does not traverse the node's heap (numba's kernels: seconds of exit)
    assert 'heap frozen at exit True' in done.stdout, text
    assert 'Traceback' not in text and 'KeyboardInterrupt' not in text, text


CHILD_SLOW_START = textwrap.dedent('''
    import os, signal, sys, time
    signal.signal(signal.SIGINT, signal.default_int_handler)
    from rclpy.node import Node
    from rfi_node_common.main import run_node

    class Node_(Node):
        def __init__(self):
            super().__init__('sigint_start_probe')
            print('constructing', flush=True)
            t0 = time.monotonic()
            while time.monotonic() - t0 < 60.0:      # a start-up that compiles kernels for a minute
                pass
            print('constructed', flush=True)

    code = run_node(Node_, executable='sigint_start_probe', summary='probe', topics='')
    print('exit', code, flush=True)
    sys.exit(code)
''')


def test_ctrl_c_during_start_up_stops_the_node_at_once():
    """A node still starting up (its compiled kernels loading) stops on Ctrl-C at once, not after its start-up."""
    import signal
    import time

    proc = subprocess.Popen([sys.executable, '-c', CHILD_SLOW_START], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == 'constructing'
    t0 = time.monotonic()
    proc.send_signal(signal.SIGINT)
    out = proc.communicate(timeout=50)[0]
    assert time.monotonic() - t0 < 30.0, out                 # not after the minute of start-up
    assert proc.returncode == 0 and 'exit 0' in out and 'constructed' not in out, out
    assert 'Traceback' not in out, out


CHILD_SLOW_EXIT = textwrap.dedent('''
    import atexit, os, signal, sys, time
    signal.signal(signal.SIGINT, signal.default_int_handler)
    from rclpy.node import Node
    from rfi_node_common.main import run_node

    class Node_(Node):
        def __init__(self):
            super().__init__('sigterm_exit_probe')
            self.create_timer(0.05, lambda: os.kill(os.getpid(), signal.SIGINT))

    def slow_exit():
        # the interpreter's exit as on a loaded machine: seconds (until the test says so)
        print('exiting', flush=True)
        while not os.path.exists(sys.argv[1]):
            time.sleep(0.01)

    code = run_node(Node_, executable='sigterm_exit_probe', summary='probe', topics='', argv=sys.argv[:1])
    print('exit', code, flush=True)
    atexit.register(slow_exit)
    sys.exit(code)
''')


def test_sigterm_while_the_node_process_exits_ends_it(tmp_path):
    """After Ctrl-C the node shuts down and the interpreter exits; a SIGTERM then (ros2 launch escalates 5 s after its
    SIGINT) ends the process at once. rclpy's handlers, left installed by rclpy.try_shutdown, used to swallow it: in CI
    launch killed gnss_integrity_node 10 s later, its exit slowed by load (test_launch_real)."""
    import signal

    release = tmp_path / 'release'
    proc = subprocess.Popen([sys.executable, '-c', CHILD_SLOW_EXIT, str(release)], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    assert proc.stdout is not None
    lines = []
    for line in proc.stdout:                                   # the node has shut down and the process is exiting
        lines.append(line)
        if line.strip() == 'exiting':
            break
    assert lines[-2:] == ['exit 0\n', 'exiting\n'], ''.join(lines)
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        release.touch()                                        # the SIGTERM was ignored: let the exit finish
        proc.wait(timeout=60)
    out = ''.join(lines) + proc.stdout.read()
    assert proc.returncode == -signal.SIGTERM, f'SIGTERM during the exit ignored (exit code {proc.returncode}):\n{out}'
