"""Test support (not used at run time): the in-process rig of the node tests.

One node under test runs in a :class:`rclpy.context.Context` of its own with a test node that
publishes its inputs and collects its outputs, both in one ``SingleThreadedExecutor``. Every
publish of the node on an output topic is counted, so a test spins (bounded, never sleeps) until
the node has taken its inputs and every message it published has arrived::

    rig = NodeRig(lambda context, overrides: MyNode(context=context, parameter_overrides=overrides),
                  inputs={'/in': (In, DATA_QOS)}, outputs={'/out': Out, '/diagnostics': DiagnosticArray})
    rig.pubs['/in'].publish(msg)
    rig.settle_until(lambda: rig.node.counts['received'] == 1)
    rig.close()

Each node package's test module subclasses :class:`NodeRig` with its topics and a ``send``.

Waits are bounded by progress, not by a fixed total (issue 27 item 6): a :class:`Stall` watch fails a wait
only when nothing it counts has moved for ``stall_s`` of wall time (no message taken or collected, no CPU
spent by the process a test waits for), so a loaded machine or a numba compile inside a callback makes a wait
longer but never fails it, and a node that hangs still fails within ``stall_s``. A far larger ``limit_s``
ends a wait that keeps progressing without ever getting there (a livelock, a timer that publishes forever).
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections import Counter
from collections.abc import Callable, Hashable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rclpy.subscription import Subscription

from rfi_node_common.params import ConfigFile, parameter_fields
from rfi_node_common.qos import DATA_QOS

STALL_S = 60.0
"""Longest a wait goes on with nothing progressing before the test fails, s (wall clock). A bound on a hang,
not on speed: one message delivered, one callback run, one CPU tick of the awaited process resets it."""
LIMIT_S = 600.0
"""Longest a wait goes on even while it progresses, s (wall clock): the bound on a livelock only."""
SPIN_DEADLINE_S = STALL_S
"""Default ``spin_deadline_s`` of a rig: how long its spins may go without progress, s (:data:`STALL_S`)."""


class Stall:
    """A deadline that moves with progress: :meth:`check` fails once ``progress()`` has returned the same value
    for ``stall_s``, or once ``limit_s`` has passed in all.

    Args:
        progress: a value that changes whenever the awaited work moves (a count of messages, a tuple of counts,
            a process's CPU ticks); compared with ``==``.
        what: what is awaited, for the failure message.
        stall_s: wall time without a change of ``progress()`` that fails, s.
        limit_s: wall time that fails in any case, s.
        look_every_s: ``progress()`` is called at most this often (it may read ``/proc``), and always before a
            failure, s.

    ::

        watch = Stall(lambda: len(received), 'the blocks')
        while len(received) < 10:
            watch.check()
            executor.spin_once(timeout_sec=0.05)
    """

    def __init__(self, progress: Callable[[], Hashable], what: str = 'the wait', *, stall_s: float = STALL_S,
                 limit_s: float = LIMIT_S, look_every_s: float = 0.2) -> None:
        if not 0.0 < stall_s <= limit_s:
            raise ValueError(f'need 0 < stall_s <= limit_s, got stall_s={stall_s}, limit_s={limit_s}')
        self.progress, self.what, self.stall_s, self.limit_s = progress, what, stall_s, limit_s
        self.look_every_s = look_every_s
        self.start = self.moved = self.looked = time.monotonic()
        self.last = progress()
        self.changes = 0

    def check(self) -> None:
        """Note progress; raise AssertionError if none for ``stall_s``, or if ``limit_s`` has passed."""
        now = time.monotonic()
        if now - self.looked >= self.look_every_s or now - self.moved >= self.stall_s:
            self.looked = now
            value = self.progress()
            if value != self.last:
                self.last, self.moved = value, now
                self.changes += 1
        assert now - self.moved < self.stall_s, \
            f'{self.what}: nothing progressed for {self.stall_s} s ({self.changes} steps of progress before, ' \
            f'last {self.last!r})'
        assert now - self.start < self.limit_s, \
            f'{self.what}: not done within {self.limit_s} s although it progressed ({self.changes} steps)'


def wait_until(done: Callable[[], bool], step: Callable[[], object], progress: Callable[[], Hashable],
               what: str = 'the wait', *, stall_s: float = STALL_S, limit_s: float = LIMIT_S) -> None:
    """Call ``step()`` (one ``spin_once``, a short poll) until ``done()``, failing as :class:`Stall` does."""
    watch = Stall(progress, what, stall_s=stall_s, limit_s=limit_s)
    while not done():
        watch.check()
        step()


_TICK_S = 1.0 / os.sysconf('SC_CLK_TCK') if hasattr(os, 'sysconf') else 0.01


def process_cpu_s(pid: int, *, descendants: bool = True) -> float:
    """CPU time (user + system) that process ``pid`` has used so far, s, with that of its live descendants
    (the nodes a ``run`` or a launch started) unless ``descendants`` is False; 0.0 for a process that has
    ended. Read from ``/proc`` (Linux); where there is no ``/proc``, always 0.0 (no progress is seen, so a wait
    on it is bounded by its stall time).

    A process that compiles kernels or analyses blocks spends CPU and so progresses however slowly a loaded
    machine lets it; one that waits for input it will never get spends none."""
    stats: dict[int, tuple[int, float]] = {}
    try:
        names = os.listdir('/proc') if descendants else [str(pid)]
    except OSError:
        return 0.0
    for name in names:
        if not name.isdigit():
            continue
        try:
            with open(f'/proc/{name}/stat', 'rb') as f:
                raw = f.read()
        except OSError:
            continue
        fields = raw[raw.rfind(b')') + 2:].split()   # after "pid (comm) ": state ppid ... utime(12) stime(13)
        stats[int(name)] = (int(fields[1]), (int(fields[11]) + int(fields[12])) * _TICK_S)
    total, todo, seen = 0.0, [pid], set()
    while todo:
        p = todo.pop()
        if p in seen or p not in stats:
            continue
        seen.add(p)
        total += stats[p][1]
        if descendants:
            todo.extend(child for child, (parent, _) in stats.items() if parent == p)
    return total


def communicate(proc: subprocess.Popen, what: str, *, input: Any = None, stall_s: float = STALL_S,
                limit_s: float = LIMIT_S, stop_signal: int = signal.SIGKILL,
                also: Sequence[int] = ()) -> tuple[Any, Any]:
    """``proc.communicate(input)`` bounded by progress: it fails once the process and its descendants have spent
    no CPU for ``stall_s`` (:func:`process_cpu_s`), or after ``limit_s``, not after a fixed time. Returns
    (stdout, stderr) as ``communicate`` does.

    ``also``: ids of other processes whose CPU time counts as progress too: those ``proc`` waits for (``play``
    waiting for a node that compiles its kernels, or for a recorder's acknowledgements).

    On failure ``proc`` gets ``stop_signal`` (SIGINT for a ``run`` that must stop its node processes itself),
    then SIGKILL if it has not ended 60 s later; the AssertionError ends with the last 3000 characters of its
    stderr."""
    watch = Stall(lambda: tuple(process_cpu_s(pid) for pid in (proc.pid, *also)), what, stall_s=stall_s,
                  limit_s=limit_s, look_every_s=0.5)
    while True:
        try:
            return proc.communicate(input, timeout=0.5)   # a retry loses no output (subprocess docs)
        except subprocess.TimeoutExpired:
            pass
        try:
            watch.check()
        except AssertionError as e:
            proc.send_signal(stop_signal)
            try:
                _, err = proc.communicate(timeout=60.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                _, err = proc.communicate()
            tail = err[-3000:] if err else ''
            raise AssertionError(f'{e}; stderr:\n{tail!s}') from None


def run_process(args: list[str], what: str | None = None, *, input: Any = None, stall_s: float = STALL_S,
                limit_s: float = LIMIT_S, also: Sequence[int] = (), stop_signal: int = signal.SIGKILL,
                **popen: Any) -> subprocess.CompletedProcess:
    """``subprocess.run(args, capture_output=True, input=input, **popen)``, bounded by progress as
    :func:`communicate` is instead of by a ``timeout``: a process that compiles numba kernels on a cold cache
    beside a CPU hog takes as long as it takes, one that hangs fails after ``stall_s``. ``also`` and
    ``stop_signal``: as in :func:`communicate`."""
    stdin = subprocess.PIPE if input is not None else popen.pop('stdin', None)
    with subprocess.Popen(args, stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE, **popen) as proc:
        out, err = communicate(proc, what or f'{os.path.basename(str(args[0]))} did not end', input=input,
                               stall_s=stall_s, limit_s=limit_s, also=also, stop_signal=stop_signal)
    return subprocess.CompletedProcess(args, proc.returncode, out, err)


class CountingExecutor(SingleThreadedExecutor):
    """A SingleThreadedExecutor that counts the subscription callbacks it has taken (the progress of a rig:
    a message taken by the node or by the test node; timers do not count)."""

    def __init__(self, *, context: Context) -> None:
        super().__init__(context=context)
        self.messages_taken = 0

    def wait_for_ready_callbacks(self, *args: Any, **kwargs: Any) -> Any:
        ready: Any = super().wait_for_ready_callbacks(*args, **kwargs)
        if isinstance(ready[1], Subscription):
            self.messages_taken += 1
        return ready

NodeFactory = Callable[[Context, list[Parameter]], Node]
"""Builds the node under test in the given context with the given parameter overrides."""

Output = type | tuple[type, Callable[[Any], bool]]
"""An output topic's message type, or (type, accept): only messages that ``accept`` are collected
(e.g. those of this node when another process of the same ROS domain publishes on the topic)."""

R = TypeVar('R', bound='NodeRig')


class NodeRig:
    """The node under test plus a test node that publishes its inputs and collects its outputs.

    Args:
        make_node: builds the node under test (``make_node(context, parameter_overrides)``).
        params: parameter overrides of the node, by name.
        args: command-line arguments of ``rclpy.init`` (e.g. ``--ros-args --params-file ...``).
        inputs: input topic -> (message type, QoS of the test's publisher).
        outputs: output topic -> message type, or (type, accept).
        name: name of the test node.
        spin_deadline_s: how long each :meth:`spin_until` may go without progress (no message taken by either
            node, nothing published by the node under test) before the test fails, s.
        spin_limit_s: bound of each :meth:`spin_until` even while it progresses, s.

    Attributes:
        node: the node under test; ``io``: the test node; ``pubs``: input topic -> publisher;
        ``out``: output topic -> messages received, in arrival order; ``published``: output topic
        -> messages the node published.
    """

    def __init__(self, make_node: NodeFactory, *, inputs: Mapping[str, tuple[type, QoSProfile]],
                 outputs: Mapping[str, Output], params: Mapping[str, Any] | None = None,
                 args: list[str] | None = None, name: str = 'node_test_io',
                 spin_deadline_s: float = SPIN_DEADLINE_S, spin_limit_s: float = LIMIT_S) -> None:
        self.spin_deadline_s = spin_deadline_s
        self.spin_limit_s = max(spin_limit_s, spin_deadline_s)
        self.context = Context()
        rclpy.init(args=args, context=self.context)
        overrides = [Parameter(k, value=v) for k, v in (params or {}).items()]
        try:
            self.node = make_node(self.context, overrides)
        except Exception:
            rclpy.shutdown(context=self.context)
            raise
        self.io = Node(name, context=self.context)
        self.pubs = {topic: self.io.create_publisher(cls, topic, qos) for topic, (cls, qos) in inputs.items()}
        self.out: dict[str, list] = {}
        for topic, spec in outputs.items():
            cls, accept = spec if isinstance(spec, tuple) else (spec, None)
            self.out[topic] = []
            self.io.create_subscription(cls, topic, self._collector(self.out[topic], accept), DATA_QOS)
        self.published: Counter[str] = Counter()
        self._node_pubs = [p for p in self.node.publishers if p.topic_name in self.out]
        missing = set(self.out) - {p.topic_name for p in self._node_pubs}
        assert not missing, f'the node does not publish {sorted(missing)}'
        for pub in self._node_pubs:
            pub.publish = self._counting(pub.publish, pub.topic_name)  # type: ignore[method-assign,assignment]
        self.executor = CountingExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.io)
        self.spin_until(lambda: all(p.get_subscription_count() >= 1 for p in self.pubs.values())
                        and all(p.get_subscription_count() >= 1 for p in self._node_pubs), 'discovery')

    @staticmethod
    def _collector(into: list, accept: Callable[[Any], bool] | None) -> Callable[[Any], None]:
        if accept is None:
            return into.append

        def collect(msg: Any) -> None:
            if accept(msg):
                into.append(msg)
        return collect

    def _counting(self, publish: Callable[[Any], None], topic: str) -> Callable[[Any], None]:
        def counted(msg: Any) -> None:
            self.published[topic] += 1
            publish(msg)
        return counted

    def progress(self) -> tuple[int, int]:
        """(messages taken by the node under test and the test node, messages the node published): what a
        spin waits on moves only when one of them does (discovery aside: see :meth:`spin_until`)."""
        return self.executor.messages_taken, sum(self.published.values())

    def spin_until(self, done: Callable[[], bool], what: str = 'the graph') -> None:
        """Spin the executor until ``done()``; fail the test once nothing has progressed (:meth:`progress`) for
        ``spin_deadline_s``, or after ``spin_limit_s`` in all. (Discovery and graph changes are no message: a
        wait for them alone is bounded by ``spin_deadline_s`` from its start.)"""
        wait_until(done, lambda: self.executor.spin_once(timeout_sec=0.05), self.progress, f'{what} did not settle',
                   stall_s=self.spin_deadline_s, limit_s=self.spin_limit_s)

    def outputs_arrived(self) -> bool:
        """Every message the node published on an output topic has been collected."""
        return all(len(msgs) == self.published[topic] for topic, msgs in self.out.items())

    def settle_until(self, taken: Callable[[], bool], what: str = 'delivery') -> None:
        """Spin until ``taken()`` (the node has received what was sent) and every output has arrived."""
        self.spin_until(lambda: taken() and self.outputs_arrived(), what)

    def close(self) -> None:
        """Stop the executor, destroy both nodes and shut the context down (idempotent: a test may close a rig
        before building the next, so that the first node no longer receives the second one's inputs)."""
        if getattr(self, "_closed", False):
            return
        self._closed = True
        self.executor.shutdown()
        self.node.destroy_node()
        self.io.destroy_node()
        rclpy.shutdown(context=self.context)


@contextmanager
def rig_factory(make: Callable[..., R]) -> Iterator[Callable[..., R]]:
    """``make`` wrapped so that every rig it built is closed at the end (the body of a pytest fixture).

    ::

        @pytest.fixture
        def rig_factory():
            with testing.rig_factory(Rig) as make:
                yield make
    """
    rigs: list[R] = []

    def build(*args: Any, **kwargs: Any) -> R:
        rig = make(*args, **kwargs)
        rigs.append(rig)
        return rig

    try:
        yield build
    finally:
        for rig in rigs:
            rig.close()


def start_error(make_node: NodeFactory, params: Mapping[str, Any]) -> str:
    """The message of the ``ValueError`` a node built with these parameter overrides stops with.

    The node is built in a context of its own, shut down afterwards; a node that starts instead fails the
    test (``AssertionError``). ``make_node`` as for :class:`NodeRig`, e.g.
    ``lambda context, overrides: MyNode(context=context, parameter_overrides=overrides)``.
    """
    context = Context()
    rclpy.init(context=context)
    try:
        try:
            node = make_node(context, [Parameter(k, value=v) for k, v in params.items()])
        except ValueError as err:
            return str(err)
        node.destroy_node()
        raise AssertionError(f'the node started with {dict(params)}')
    finally:
        rclpy.try_shutdown(context=context)


def check_config_file(make_rig: Callable[..., NodeRig], config: ConfigFile, path: Path, executable: str) -> None:
    """A node's shipped config file is the one generated from its parameter definitions (``tools/generate_config.py``),
    and the node started with it as ``--params-file`` has every parameter at its dataclass default.

    Args:
        make_rig: builds the node's rig; called as ``make_rig(args=[...])`` (rclpy's command line).
        config: the node's :class:`rfi_node_common.params.ConfigFile`.
        path: the shipped file in the source tree (``src/<package>/config/<node>.yaml``).
        executable: the node's executable name (``argv[0]``).
    """
    assert path.read_text() == config.text(), 'run python tools/generate_config.py'
    rig = make_rig(args=[executable, '--ros-args', '--params-file', str(path)])
    defaults = config.params_cls()
    node: Any = rig.node  # the suite's nodes keep their parameter dataclass in .params
    assert node.params == defaults
    for field in parameter_fields(defaults):
        assert node.get_parameter(field.name).value == getattr(defaults, field.name), field.name
