"""One definition per parameter: groups, internal fields, --help and the generated config file (no rclpy)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import pytest
import yaml

from rfi_node_common.params import (
    TUNING,
    USER,
    build,
    check_positive_finite,
    config_yaml,
    describe,
    internal,
    parameter,
    parameter_fields,
    runtime_parameter_names,
    yaml_value,
)


@dataclass(frozen=True)
class Core:
    gain_db: float = parameter(3.0, 'Gain, dB.', minimum=0.0, maximum=10.0, read_only=False)
    frame_id: str = parameter('map', 'Frame of the outputs.', group=USER)
    registry: tuple = internal(())


@dataclass(frozen=True)
class Node(Core):
    psd_m2ps3: float = parameter(1.0e-8, 'PSD, m^2/s^3.', minimum=1e-15, maximum=1.0)
    limit: float = parameter(math.inf, 'A limit (.inf: none).', minimum=0.01)
    lever_arm_m: tuple = parameter((0.0, 1.5, -2.0), 'Lever arm, m.', group=USER)
    mode: str = parameter('none', 'Mode: none or velocity.', choices=('none', 'velocity'), group=USER)
    count: int = parameter(5, 'Count.', minimum=1, maximum=9)
    enabled: bool = parameter(True, 'Switch.')


def test_parameter_fields_skip_internal_fields_and_list_the_user_group_first():
    names = [f.name for f in parameter_fields(Node)]
    assert names == ['frame_id', 'lever_arm_m', 'mode', 'gain_db', 'psd_m2ps3', 'limit', 'count', 'enabled']
    assert runtime_parameter_names(Node) == ('gain_db',)
    with pytest.raises(ValueError, match='group'):
        parameter(1.0, 'x', group='expert')


def test_internal_fields_are_not_range_checked_nor_needed_to_build():
    node = build(Node, {'gain_db': 4.0})
    assert node.registry == () and node.gain_db == 4.0
    with pytest.raises(ValueError, match='gain_db = 11.0 is above its maximum 10.0'):
        build(Node, {'gain_db': 11.0})


def test_describe_prints_the_user_group_first_with_ranges_and_settable_marks():
    text = describe(Node)
    assert text.index('user parameters') < text.index('frame_id') < text.index('tuning parameters') \
        < text.index('gain_db')
    assert "gain_db (default 3.0) [0.0, 10.0] [settable while running]" in text
    assert "mode (default 'none') {none, velocity}" in text
    assert 'registry' not in text


def test_generated_yaml_reads_back_as_the_defaults_with_their_types():
    text = config_yaml('my_node', Node, 'A header.\nSecond line.')
    assert text.startswith('# A header.\n# Second line.\nmy_node:\n  ros__parameters:\n')
    data = yaml.safe_load(text)['my_node']['ros__parameters']
    defaults = Node()
    assert list(data) == [f.name for f in parameter_fields(Node)]
    for name, value in data.items():
        expected = getattr(defaults, name)
        assert (tuple(value) if isinstance(expected, tuple) else value) == expected, name
        assert type(value) is (list if isinstance(expected, tuple) else type(expected)), name
    assert '    # [settable while running] Gain, dB. Range [0.0, 10.0].\n    gain_db: 3.0\n' in text
    assert '    # Mode: none or velocity. One of {none, velocity}.\n    mode: none\n' in text


@pytest.mark.parametrize('value, text', [
    (1.0e-8, '1.0e-08'), (2.0e-19, '2.0e-19'), (0.5, '0.5'), (10.0, '10.0'), (math.inf, '.inf'),
    (-math.inf, '-.inf'), (True, 'true'), (3, '3'), ((0.0, 1.0), '[0.0, 1.0]'), ('gnss_receiver+uwb_tag',
                                                                               'gnss_receiver+uwb_tag'),
    ('', '""'), ('true', '"true"'), ('a b: c', '"a b: c"'), ('3d', '"3d"'),
])
def test_yaml_values_keep_their_type(value, text):
    assert yaml_value(value) == text
    read = yaml.safe_load(f'k: {text}')['k']
    assert (tuple(read) if isinstance(value, tuple) else read) == value
    assert type(read) is (list if isinstance(value, tuple) else type(value))


def test_groups_are_the_two_documented_ones():
    assert (USER, TUNING) == ('user', 'tuning')


def test_parameter_from_copies_the_core_definition_and_may_narrow_its_choices():
    """A node's field taken from a core field keeps its default, description, range and group; ``choices`` may be
    narrowed to a subset that holds the default, anything else is refused."""
    from rfi_node_common.params import parameter_from

    @dataclass(frozen=True)
    class Narrow:
        mode: str = parameter_from(Node, 'mode', choices=('none',))
        count: int = parameter_from(Node, 'count', read_only=False)

    narrow = {f.name: f for f in parameter_fields(Narrow)}
    assert narrow['mode'].metadata['rfi_doc']['choices'] == ('none',)
    assert narrow['count'].metadata['rfi_doc']['minimum'] == 1 and runtime_parameter_names(Narrow) == ('count',)
    assert Narrow().mode == 'none' and Narrow().count == 5
    with pytest.raises(ValueError, match='not one of none'):
        build(Narrow, {'mode': 'velocity'})
    for choices in (('none', 'other'), ('velocity',)):
        with pytest.raises(ValueError, match='subset'):
            parameter_from(Node, 'mode', choices=choices)
    with pytest.raises(TypeError, match='cannot change default'):
        parameter_from(Node, 'count', default=3)
    with pytest.raises(TypeError, match='not a field defined with parameter'):
        parameter_from(Node, 'registry')


def test_check_positive_finite_names_the_first_bad_field():
    @dataclass(frozen=True)
    class Limits:
        gain: float = 2.0
        window_s: float = 1.0
        label: str = 'x'

    check_positive_finite(Limits(), ('gain', 'window_s'))
    for bad in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(ValueError, match=r'^Limits.window_s must be finite and > 0, got'):
            check_positive_finite(Limits(window_s=bad), ('gain', 'window_s'))
    with pytest.raises(ValueError, match='Limits.label'):
        check_positive_finite(Limits(), ('label',))
