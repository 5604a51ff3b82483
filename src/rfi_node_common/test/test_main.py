"""run_node (rfi_node_common.main): Ctrl-C while a node runs ends it through the context's shutdown, never through a
KeyboardInterrupt raised inside whatever Python was running (a half-built rclpy object then printed a traceback)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

CHILD = textwrap.dedent('''
    import os, signal, sys, time
    import rclpy
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
