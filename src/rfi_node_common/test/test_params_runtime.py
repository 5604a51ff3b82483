"""Parameters settable while a node runs (rfi_node_common.params.RuntimeParameters), set as `ros2 param set`
does: through the node's SetParameters service, from another node."""

from __future__ import annotations

from dataclasses import dataclass

import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from rfi_node_common import testing
from rfi_node_common.params import (
    RuntimeParameters,
    build,
    changed_names,
    declare,
    describe,
    parameter,
    runtime_parameter_names,
    set_parameters_remotely,
    validate_ranges,
)


@dataclass(frozen=True)
class Params:
    gate: float = parameter(3.0, 'A gate, sigma.', minimum=1.0, maximum=10.0, read_only=False)
    warn_above: float = parameter(5.0, 'Must exceed gate.', minimum=0.0, maximum=100.0, read_only=False)
    mode: str = parameter('a', 'A mode.', choices=('a', 'b'), read_only=False)
    lever_m: tuple = parameter((0.0, 0.0, 0.0), 'Three numbers, m.', read_only=False)
    window: int = parameter(10, 'A buffer size (read-only: sizes state).', minimum=1, maximum=100)

    def __post_init__(self) -> None:
        validate_ranges(self)
        if self.warn_above <= self.gate:
            raise ValueError(f'parameter warn_above ({self.warn_above}) must exceed gate ({self.gate})')
        if len(self.lever_m) != 3:
            raise ValueError(f'parameter lever_m must have 3 elements, got {list(self.lever_m)}')


class Target(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__('runtime_target', **kwargs)
        self.params = declare(self, Params)
        self.runtime = RuntimeParameters(self, self.params)


@pytest.fixture
def setup():
    context = Context()
    rclpy.init(context=context)
    target = Target(context=context)
    client = Node('runtime_client', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(target)
    executor.add_node(client)
    yield target, client, executor
    executor.shutdown()
    target.destroy_node()
    client.destroy_node()
    rclpy.shutdown(context=context)


def set_remote(setup, **values):
    target, client, executor = setup
    return set_parameters_remotely(client, executor, '/runtime_target', values)


def start_error(**values) -> str:
    """The error a node started with these values stops with."""
    return testing.start_error(lambda context, overrides: Target(context=context, parameter_overrides=overrides),
                               values)


def test_runtime_names_and_descriptors(setup):
    target, _, _ = setup
    assert runtime_parameter_names(Params) == ('gate', 'warn_above', 'mode', 'lever_m')
    described = {d.name: d for d in target.describe_parameters(['gate', 'window'])}
    assert not described['gate'].read_only and described['window'].read_only
    assert '[settable while running]' in describe(Params).split('window')[0]
    assert '[settable while running]' not in describe(Params).split('window')[1]


def test_an_accepted_change_is_pending_until_the_node_takes_it(setup):
    target, _, _ = setup
    results = set_remote(setup, gate=4.0, lever_m=[0.1, 0.2, 0.3])
    assert [r.successful for r in results] == [True, True]
    assert target.get_parameter('gate').value == 4.0
    assert target.runtime.pending and target.runtime.current.gate == 3.0   # not applied yet
    applied = []
    assert target.runtime.apply_pending(lambda old, new: applied.append(changed_names(old, new)))
    assert applied == [['gate', 'lever_m']]
    assert target.runtime.current.gate == 4.0 and target.runtime.current.lever_m == (0.1, 0.2, 0.3)
    assert not target.runtime.pending and target.runtime.take() is None
    assert target.runtime.changes_applied == 1


def test_refused_changes_give_the_reason_given_at_start_and_change_nothing(setup):
    target, _, _ = setup
    # the dataclass's own cross-check: the same ValueError as at start
    (result,) = set_remote(setup, warn_above=2.0)
    assert not result.successful
    assert result.reason == start_error(warn_above=2.0) == 'parameter warn_above (2.0) must exceed gate (3.0)'
    assert target.get_parameter('warn_above').value == 5.0 and not target.runtime.pending
    # a change that breaks the cross-check with a change still pending is refused too
    assert set_remote(setup, gate=4.5)[0].successful
    (result,) = set_remote(setup, warn_above=4.0)
    assert not result.successful and 'must exceed gate (4.5)' in result.reason
    assert target.runtime.take().warn_above == 5.0
    # choices and element counts: the dataclass's checks
    (result,) = set_remote(setup, mode='c')
    assert not result.successful and result.reason == start_error(mode='c')
    (result,) = set_remote(setup, lever_m=[1.0, 2.0])
    assert not result.successful and result.reason == start_error(lever_m=[1.0, 2.0])
    assert target.runtime.changes_refused == 4


def test_rclpy_refuses_read_only_out_of_range_and_wrong_type(setup):
    target, _, _ = setup
    (result,) = set_remote(setup, window=20)
    assert not result.successful and 'read-only' in result.reason
    (result,) = set_remote(setup, gate=11.0)
    assert not result.successful and 'out of range' in result.reason
    (result,) = set_remote(setup, gate='high')
    assert not result.successful and 'type' in result.reason.lower()
    assert target.get_parameter('window').value == 10 and target.get_parameter('gate').value == 3.0
    assert not target.runtime.pending


def test_build_is_the_validation_of_declare():
    with pytest.raises(ValueError, match='must exceed gate'):
        build(Params, {'gate': 6.0})
    with pytest.raises(ValueError, match='no_such'):
        build(Params, {'no_such': 1})
    assert build(Params, {'gate': 2.0}).gate == 2.0


def test_start_error_fails_a_node_that_starts():
    with pytest.raises(AssertionError, match='started'):
        testing.start_error(lambda context, overrides: Target(context=context, parameter_overrides=overrides),
                            {'gate': 4.0})
