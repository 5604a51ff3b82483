"""Build ``diagnostic_msgs/DiagnosticArray`` messages from a node's counters, with levels that mean something.

What the levels of the suite's nodes mean (each node's docstring lists its own conditions):

* OK: the node receives its inputs and its output is valid; isolated rejections (a range gated now
  and then on clean data) do not change this.
* WARN: the inputs are degraded: over the last ``diagnostics_window_s`` of stamp time a fraction of
  the input above ``warn_rejected_fraction`` was rejected, or a fraction above ``warn_lost_fraction``
  was lost before reaching the node (:class:`CountWindow`, :func:`degraded_inputs`), or a node-specific
  condition (a jammer reported, a filter re-initialised).
* ERROR: the output is not valid (no solution, estimates suppressed), or the node's own accounting
  failed or its core or a handler raised since the last report.
* STALE: nothing received for ``input_timeout_s`` of wall time (:class:`rfi_node_common.inputs.StaleInputWatch`).

``hardware_id`` of every status is the node's ``hardware_id`` parameter: the device behind the node's
input (front end, receiver, UWB tag), as diagnostic aggregators group by it, not the node's name.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from rfi_node_common.params import parameter
from rfi_node_common.stamps import ns_to_stamp

OK = DiagnosticStatus.OK
WARN = DiagnosticStatus.WARN
ERROR = DiagnosticStatus.ERROR


def diagnostic_array(stamp_ns: int, name: str, hardware_id: str, level: bytes, message: str,
                     values: Mapping[str, object]) -> DiagnosticArray:
    """One-status DiagnosticArray stamped ``stamp_ns`` with ``values`` as key/value pairs.

    ``level`` is one of OK, WARN, ERROR (the DiagnosticStatus byte constants).
    """
    array = DiagnosticArray()
    array.header.stamp = ns_to_stamp(stamp_ns)
    status = DiagnosticStatus(level=level, name=name,
                              message=message, hardware_id=hardware_id)
    status.values = [KeyValue(key=str(k), value=str(v)) for k, v in values.items()]
    array.status = [status]
    return array


def counted_level(values: Mapping[str, object], warn_keys: Sequence[str], error: str | None = None
                  ) -> tuple[bytes, str]:
    """The level of a source node (a reader that publishes what it reads) from its counters.

    Args:
        values: the node's counters.
        warn_keys: the counters that make a WARN when above zero, in the order the message names them.
        error: the reason of an ERROR (the input failed), or None.

    Returns:
        ``(ERROR, error)``; else ``(WARN, 'counted: gaps 2, ...')`` naming each warn counter above zero;
        else ``(OK, 'publishing')``.
    """
    if error:
        return ERROR, error
    warn = [k for k in warn_keys if values.get(k)]
    if warn:
        return WARN, 'counted: ' + ', '.join(f'{k} {values[k]}' for k in warn)
    return OK, 'publishing'


def publish_status(node: Any, publisher: Any, stamp_ns: int, name: str, hardware_id: str, level: bytes, text: str,
                   values: Mapping[str, object], final: bool) -> None:
    """Publish a source node's status; the final one's text starts with 'end of input; '.

    A failure to publish is logged on the node, never raised: a report must never end the reader.
    The stamp is at least 1 ns (a status before the first input is stamped 1 ns, not 0).
    """
    if final:
        text = 'end of input; ' + text
    try:
        publisher.publish(diagnostic_array(max(1, stamp_ns), name, hardware_id, level, text, values))
    except Exception as err:  # noqa: BLE001 - a report must never end the reader
        node.get_logger().error(f'/diagnostics not published: {type(err).__name__}: {err}')


class StampTimer:
    """Fires every ``period_s`` of *message* time (never wall time), so replays are deterministic.

    ``due(stamp_ns)`` returns True on the first call and then whenever ``period_s`` has elapsed
    since the last time it returned True.
    """

    def __init__(self, period_s: float) -> None:
        if not period_s > 0:
            raise ValueError(f'period must be > 0 s, got {period_s}')
        self._period_ns = int(round(period_s * 1e9))
        self._last_ns: int | None = None

    def due(self, stamp_ns: int) -> bool:
        if self._last_ns is None or stamp_ns - self._last_ns >= self._period_ns or stamp_ns < self._last_ns:
            self._last_ns = stamp_ns
            return True
        return False


STALE = DiagnosticStatus.STALE


def input_timeout_parameter() -> Any:
    """The ``input_timeout_s`` parameter field shared by the nodes (rfi_node_common.inputs.StaleInputWatch)."""
    return parameter(
        5.0, 'Wall-clock silence after which /diagnostics reports the node STALE (no input received), s; '
        '0: never. Used only for this report: no estimate depends on the wall clock.', minimum=0.0, maximum=86400.0)


def max_stamp_jump_parameter(default_s: float = 120.0) -> Any:
    """The ``max_stamp_jump_s`` parameter field shared by the nodes (rfi_node_common.input_checks.StampGate)."""
    return parameter(
        default_s, 'A header stamp further than this from the latest accepted stamp is rejected '
        '(stamp_far_future / stamp_far_past) unless stamp_jump_confirmations messages in a row agree on the '
        'jump (a clock or bag restart), s.', minimum=0.01, maximum=1.0e6)


def stamp_jump_confirmations_parameter(default: int = 5) -> Any:
    """The ``stamp_jump_confirmations`` parameter field shared by the nodes."""
    return parameter(
        default, 'Consecutive messages, each newer than the last and within max_stamp_jump_s of it, that '
        'confirm a stamp jump; the node then restarts its state from the new time line.',
        minimum=1, maximum=100000)


def diagnostics_period_parameter(minimum_s: float = 0.001) -> Any:
    """The ``diagnostics_period_s`` parameter field (the :class:`StampTimer` of /diagnostics); ``minimum_s``: the
    shortest period the node accepts, s."""
    return parameter(
        1.0, 'Period of /diagnostics in message (stamp) time, s.', minimum=minimum_s, maximum=3600.0)


def hardware_id_parameter(default: str, read_only: bool = False) -> Any:
    """The ``hardware_id`` parameter field (DiagnosticStatus.hardware_id of every report of the node);
    ``read_only``: for a node that takes no parameter change while running (the input nodes)."""
    return parameter(
        default, 'DiagnosticStatus.hardware_id of the node\'s reports: the device behind its input (model and '
        'serial number of the front end, receiver or UWB tag); diagnostic aggregators group statuses by it.',
        read_only=read_only)


def diagnostics_window_parameter(default_s: float = 10.0) -> Any:
    """The ``diagnostics_window_s`` parameter field: the window of :class:`CountWindow`."""
    return parameter(
        default_s, 'Window of message (stamp) time over which /diagnostics computes the rejected and lost '
        'fractions of the input that set WARN, s (counts since start until the window has filled).',
        minimum=0.001, maximum=3600.0, read_only=False)


def warn_rejected_fraction_parameter(default: float = 0.1) -> Any:
    """The ``warn_rejected_fraction`` parameter field (:func:`degraded_inputs`)."""
    return parameter(
        default, 'WARN (inputs degraded) when more than this fraction of an input (messages or measurements, '
        'per kind) was rejected over diagnostics_window_s; 1: never.', minimum=0.0, maximum=1.0, read_only=False)


def warn_lost_fraction_parameter(default: float = 0.01) -> Any:
    """The ``warn_lost_fraction`` parameter field (:func:`degraded_inputs`)."""
    return parameter(
        default, 'WARN (inputs degraded) when more than this fraction of the messages published to the node '
        'was lost before reaching it (publisher sequence gaps, middleware loss) over diagnostics_window_s; 1: '
        'never.', minimum=0.0, maximum=1.0, read_only=False)


@dataclass(frozen=True)
class NodeDiagnosticsParams:
    """The parameters every node that judges an input stream shares, written once: its stamp gate
    (:class:`rfi_node_common.input_checks.StampGate`), its silence watch
    (:class:`rfi_node_common.inputs.StaleInputWatch`) and its /diagnostics (period, ``hardware_id``, the WARN
    window and thresholds of :class:`CountWindow` and :func:`degraded_inputs`, the warning throttle).

    A node's parameter dataclass extends it and redefines a field whose default differs for the node (its
    ``hardware_id``, a ``max_stamp_jump_s`` suited to its input rate) with the same helper. Settable while
    running (the node applies them with :class:`rfi_node_common.params.RuntimeParameters` between two messages):
    ``hardware_id``, ``diagnostics_window_s``, the WARN thresholds and ``warning_throttle_s``; the others size
    the stamp gate and the timers, which hold state.
    """

    max_stamp_jump_s: float = max_stamp_jump_parameter(120.0)
    stamp_jump_confirmations: int = stamp_jump_confirmations_parameter(5)
    input_timeout_s: float = input_timeout_parameter()
    diagnostics_period_s: float = diagnostics_period_parameter()
    warning_throttle_s: float = parameter(
        5.0, 'Shortest interval between two warnings about rejected input, s (wall time; logging only).',
        minimum=0.0, maximum=3600.0, read_only=False)
    hardware_id: str = hardware_id_parameter('unknown')
    diagnostics_window_s: float = diagnostics_window_parameter()
    warn_rejected_fraction: float = warn_rejected_fraction_parameter()
    warn_lost_fraction: float = warn_lost_fraction_parameter()


class CountWindow:
    """Increase of cumulative counters over the last ``window_s`` of stamp time.

    The node calls :meth:`update` at each report with its cumulative counters; it returns how much
    each grew since the newest snapshot at least ``window_s`` older (since start while the window has
    not filled). Time is the report's stamp, so a replay at any speed gives the same levels; a stamp
    older than the last one (a restart of the time line) starts the window again.

    Args:
        window_s: window length, s (> 0).
    """

    def __init__(self, window_s: float) -> None:
        if not window_s > 0:
            raise ValueError(f'window must be > 0 s, got {window_s}')
        self.window_ns = int(round(window_s * 1e9))
        self._snapshots: deque[tuple[int, dict[str, int]]] = deque()

    def update(self, stamp_ns: int, totals: Mapping[str, int]) -> dict[str, int]:
        """Record ``totals`` at ``stamp_ns`` and return their increase over the window, per key."""
        if self._snapshots and stamp_ns < self._snapshots[-1][0]:
            self._snapshots.clear()
        if not self._snapshots:
            self._snapshots.append((stamp_ns, {}))  # the start: every counter from zero
        self._snapshots.append((stamp_ns, dict(totals)))
        # keep one snapshot at or before the window's start as the base
        while len(self._snapshots) > 2 and self._snapshots[1][0] <= stamp_ns - self.window_ns:
            self._snapshots.popleft()
        base = self._snapshots[0][1]
        return {k: int(v) - int(base.get(k, 0)) for k, v in totals.items()}


def fraction(numerator: int, denominator: int) -> float:
    """numerator / denominator, 0 when the denominator is 0."""
    return numerator / denominator if denominator > 0 else 0.0


def degraded_inputs(checks: Sequence[tuple[str, int, int]], threshold: float) -> list[str]:
    """Texts of the checks whose fraction exceeds ``threshold``.

    Args:
        checks: (what, count, out of) per input kind, e.g. ``('UWB ranges rejected', 12, 600)``.
        threshold: fraction, 0..1 (1: never).

    Returns:
        e.g. ``['UWB ranges rejected 12/60 (20%)']``, in the order of ``checks``.
    """
    return [f'{what} {n}/{total} ({100.0 * fraction(n, total):.0f}%)'
            for what, n, total in checks if fraction(n, total) > threshold]
