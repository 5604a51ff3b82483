"""Build ``diagnostic_msgs/DiagnosticArray`` messages from a node's counters."""

from __future__ import annotations

from collections.abc import Mapping

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

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


def input_timeout_parameter() -> object:
    """The ``input_timeout_s`` parameter field shared by the nodes (rfi_node_common.inputs.StaleInputWatch)."""
    from rfi_node_common.params import parameter
    return parameter(
        5.0, 'Wall-clock silence after which /diagnostics reports the node STALE (no input received), s; '
        '0: never. Used only for this report: no estimate depends on the wall clock.', minimum=0.0, maximum=86400.0)


def max_stamp_jump_parameter(default_s: float = 120.0) -> object:
    """The ``max_stamp_jump_s`` parameter field shared by the nodes (rfi_node_common.input_checks.StampGate)."""
    from rfi_node_common.params import parameter
    return parameter(
        default_s, 'A header stamp further than this from the latest accepted stamp is rejected '
        '(stamp_far_future / stamp_far_past) unless stamp_jump_confirmations messages in a row agree on the '
        'jump (a clock or bag restart), s.', minimum=0.01, maximum=1.0e6)


def stamp_jump_confirmations_parameter(default: int = 5) -> object:
    """The ``stamp_jump_confirmations`` parameter field shared by the nodes."""
    from rfi_node_common.params import parameter
    return parameter(
        default, 'Consecutive messages, each newer than the last and within max_stamp_jump_s of it, that '
        'confirm a stamp jump; the node then restarts its state from the new time line.',
        minimum=1, maximum=100000)
