"""The Jazzy ``main()`` pattern for the suite's nodes, with ``--help`` from the parameter docs."""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from typing import Any

from rfi_node_common.params import describe, unknown_parameters, unknown_parameters_message


def help_text(executable: str, summary: str, params_cls: type | None, topics: str) -> str:
    text = f'usage: ros2 run <package> {executable} [--ros-args -p NAME:=VALUE ... | --params-file FILE]\n\n'
    text += summary.strip() + '\n\n' + topics.strip() + '\n'
    if params_cls is not None:
        text += '\nparameters:\n' + describe(params_cls) + '\n'
    return text


def run_node(node_factory: Callable[[], Any], *, executable: str, summary: str, topics: str,
             params_cls: type | None = None, argv: Sequence[str] | None = None) -> int:
    """Create the node, spin it on a SingleThreadedExecutor until shutdown, and clean up.

    ``--help`` / ``-h`` (outside ``--ros-args``) prints the node's topics and parameters and exits.
    A configuration error (invalid parameter, or a parameter given for this node that it does not have,
    e.g. a misspelt ``-p``: :func:`rfi_node_common.params.unknown_parameters`) prints one line and
    returns 2.
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
    from rclpy.signals import uninstall_signal_handlers
    from rclpy.utilities import remove_ros_args

    argv = list(sys.argv if argv is None else argv)
    user_args = remove_ros_args(argv)[1:]
    if '--help' in user_args or '-h' in user_args:
        print(help_text(executable, summary, params_cls, topics))
        return 0
    if user_args:
        print(f'{executable}: error: unrecognised arguments {" ".join(user_args)} (parameters go after --ros-args)',
              file=sys.stderr)
        return 2
    restore = _SigintHandler()
    _skip_final_collection_at_exit()
    node = None
    try:
        rclpy.init(args=argv)
        node = node_factory()
        # from here Ctrl-C ends the node through the context's shutdown (rclpy's handler); while the node is built
        # (its compiled kernels loaded: up to a minute with a cold cache) it stops it at once, as before rclpy.init
        restore.ros_running = True
        unknown = unknown_parameters(node)
        if unknown:
            raise ValueError(unknown_parameters_message(node, unknown))
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        node.get_logger().info(f'{executable} ready')  # after set-up: from here Ctrl-C ends spin cleanly
        executor.spin()
        return 0
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    except _rclpy.RCLError:
        # rclpy's SIGINT handler shuts the context down asynchronously: when that happens while the
        # executor builds its next wait set (between its checks of context.ok()), rcl reports an
        # invalid context as RCLError instead of ExternalShutdownException. Shutdown, not a fault.
        if rclpy.ok():
            raise
        return 0
    except ValueError as err:
        print(f'{executable}: error: {err}', file=sys.stderr)
        return 2
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        # rclpy.try_shutdown leaves rclpy's SIGINT/SIGTERM handlers installed (rclpy.shutdown of the default context
        # removes them): they would now only shut down a context that is gone, so a SIGTERM while the process exits
        # (ros2 launch's escalation 5 s after its SIGINT) did nothing, and launch killed the node 10 s later (seen in
        # CI: gnss_integrity_node). With them removed, SIGTERM ends the process at once.
        uninstall_signal_handlers()
        restore()


class _SigintHandler:
    """The Python-level SIGINT handler while a node runs (``run_node``); calling the object puts the previous one back.

    rclpy.init installs rclpy's own SIGINT handler, which shuts the context down (``executor.spin`` then ends with
    ExternalShutdownException) and then calls the Python-level handler that was there before it. Python's default
    one raises KeyboardInterrupt in the main thread at whatever bytecode it is running: inside an rclpy object's
    constructor (the executor builds a Task for every callback) it leaves a half-built object whose ``__del__``
    prints a traceback at exit (seen on Ctrl-C of ubx_source while it read a port). Once the node is built and spins
    this handler does nothing, and the context's shutdown alone ends the node; before (imports, rclpy.init, the node's
    construction with its warm-up of compiled kernels) it raises KeyboardInterrupt as usual, so that Ctrl-C during a
    long start-up stops the node at once instead of after it (``run_node`` returns 0)."""

    def __init__(self) -> None:
        import signal
        import threading

        self.ros_running = False
        self._previous = None
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.getsignal(signal.SIGINT)
            signal.signal(signal.SIGINT, self._on_sigint)

    def _on_sigint(self, signum: int, frame: Any) -> None:
        if not self.ros_running:
            raise KeyboardInterrupt

    def __call__(self) -> None:
        import signal

        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None


_FINAL_COLLECTION_SKIPPED = False


def _skip_final_collection_at_exit() -> None:
    """Register, once per process, an exit hook that freezes the heap (``gc.freeze``) before the interpreter's final
    garbage collection, so that the collection does not traverse it.

    A node's heap holds numba's compiled kernels, their type objects and scipy: the interpreter's exit then spends most
    of its time in that last collection, freeing cycles that the process's end frees anyway (0.5 s of CPU for
    gnss_integrity_node, against 0.07 s with the heap frozen: docs/node_exit.md; on a loaded machine that is seconds
    of wall time, and ros2 launch escalates to SIGTERM 5 s after its SIGINT). Exit hooks run last-registered first
    and before the final collection, so every other hook still runs; ``__del__`` of objects left in reference cycles
    at exit is not called (the nodes release their ROS handles and files in ``destroy_node``, before this). Only at
    exit: a process that calls ``run_node`` and goes on collects as usual."""
    global _FINAL_COLLECTION_SKIPPED
    if _FINAL_COLLECTION_SKIPPED:
        return
    import atexit
    import gc

    atexit.register(gc.freeze)
    _FINAL_COLLECTION_SKIPPED = True
