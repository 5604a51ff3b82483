"""Declare ROS parameters from a frozen dataclass, with descriptors, and read them back validated.

A node's parameters are one frozen dataclass whose fields carry their documentation::

    @dataclass(frozen=True)
    class Params:
        noise_floor_db: float = parameter(-20.0, 'Calibrated noise floor, dBFS.', minimum=-200.0, maximum=0.0)

``declare(node, Params)`` declares every field with a ``ParameterDescriptor`` (description,
range, read-only) and returns a ``Params`` built from the values the node was given (command
line, YAML file), so the dataclass's own ``__post_init__`` validation runs on them. ``describe``
renders the same documentation for ``--help``.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, TypeVar

T = TypeVar('T')

_DOC = 'rfi_doc'


def parameter(default: Any, description: str, *, minimum: float | None = None,
              maximum: float | None = None, read_only: bool = True, choices: tuple[str, ...] = ()) -> Any:
    """A dataclass field that is also a documented ROS parameter.

    Args:
        default: default value (its type is the parameter's type).
        description: meaning and unit, as shown by ``--help`` and ``ros2 param describe``.
        minimum, maximum: inclusive range of a numeric parameter.
        read_only: the parameter cannot change after start-up (the default: nodes read them once).
        choices: allowed values of a string parameter.
    """
    doc = {'description': description, 'minimum': minimum, 'maximum': maximum,
           'read_only': read_only, 'choices': tuple(choices)}
    if isinstance(default, (list, tuple)):
        return dataclasses.field(default_factory=lambda: tuple(default), metadata={_DOC: doc})
    return dataclasses.field(default=default, metadata={_DOC: doc})


def _doc(field: dataclasses.Field) -> dict[str, Any]:
    return dict(field.metadata.get(_DOC, {'description': '', 'minimum': None, 'maximum': None,
                                          'read_only': True, 'choices': ()}))


def _default(field: dataclasses.Field) -> Any:
    if field.default is not dataclasses.MISSING:
        return field.default
    if field.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        return field.default_factory()  # type: ignore[misc]
    raise TypeError(f'parameter {field.name} has no default')


def validate_ranges(params: Any) -> None:
    """Check every field against its declared range and choices.

    Raises:
        ValueError: naming the parameter, its value and the allowed range.
    """
    for field in dataclasses.fields(params):
        doc = _doc(field)
        value = getattr(params, field.name)
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            if isinstance(value, float) and math.isnan(value):
                raise ValueError(f'parameter {field.name} is NaN')
            if doc['minimum'] is not None and value < doc['minimum']:
                raise ValueError(f'parameter {field.name} = {value} is below its minimum {doc["minimum"]}')
            if doc['maximum'] is not None and value > doc['maximum']:
                raise ValueError(f'parameter {field.name} = {value} is above its maximum {doc["maximum"]}')
        if doc['choices'] and value not in doc['choices']:
            raise ValueError(f'parameter {field.name} = {value!r} is not one of {", ".join(doc["choices"])}')


def declare(node: Any, params_cls: type[T]) -> T:
    """Declare the fields of ``params_cls`` as parameters of ``node`` and return their values.

    Raises:
        ValueError: a value is out of range or fails the dataclass's own validation.
    """
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
    from rclpy.exceptions import ParameterException

    values = {}
    for field in dataclasses.fields(params_cls):  # type: ignore[arg-type]
        doc = _doc(field)
        default = _default(field)
        descriptor = ParameterDescriptor(description=doc['description'], read_only=doc['read_only'])
        if doc['choices']:
            descriptor.additional_constraints = 'one of: ' + ', '.join(doc['choices'])
        if doc['minimum'] is not None and doc['maximum'] is not None:
            if isinstance(default, float):
                descriptor.floating_point_range = [FloatingPointRange(
                    from_value=float(doc['minimum']), to_value=float(doc['maximum']), step=0.0)]
            elif isinstance(default, int) and not isinstance(default, bool):
                descriptor.integer_range = [IntegerRange(
                    from_value=int(doc['minimum']), to_value=int(doc['maximum']), step=0)]
        ros_default = list(default) if isinstance(default, tuple) else default
        try:
            node.declare_parameter(field.name, ros_default, descriptor)
        except ParameterException as err:
            raise ValueError(f'parameter {field.name}: {_first_line(err)}') from None
        value = node.get_parameter(field.name).value
        values[field.name] = tuple(value) if isinstance(default, tuple) else value
    params = params_cls(**values)
    validate_ranges(params)
    return params


def _first_line(err: Exception) -> str:
    text = str(err).strip().splitlines()
    return text[0] if text else type(err).__name__


def describe(params_cls: type) -> str:
    """Plain-text documentation of the parameters, for ``--help``."""
    lines = []
    for field in dataclasses.fields(params_cls):
        doc = _doc(field)
        default = _default(field)
        limits = ''
        if doc['minimum'] is not None or doc['maximum'] is not None:
            limits = f' [{doc["minimum"] if doc["minimum"] is not None else "-inf"}, ' \
                     f'{doc["maximum"] if doc["maximum"] is not None else "inf"}]'
        if doc['choices']:
            limits = f' {{{", ".join(doc["choices"])}}}'
        lines.append(f'  {field.name} (default {default!r}){limits}\n      {doc["description"]}')
    return '\n'.join(lines)


def unknown_parameters(node: Any) -> list[str]:
    """Names given to ``node`` (``-p NAME:=VALUE``, its section of a ``--params-file``) that it never declared.

    rclpy ignores such a value silently, so a misspelt parameter would leave the default in force. Call
    after the node has declared everything (its own parameters and the ``qos_overrides.*`` of its
    subscriptions).
    """
    overrides = getattr(node, '_parameter_overrides', {})
    return sorted(name for name in overrides if not node.has_parameter(name))


def unknown_parameters_message(node: Any, unknown: list[str]) -> str:
    """One line naming the unknown parameters, each with the closest declared names."""
    import difflib

    declared = [name for name in node._parameters if not name.startswith('qos_overrides.')] \
        if hasattr(node, '_parameters') else []
    parts = []
    for name in unknown:
        close = difflib.get_close_matches(name, declared, n=2, cutoff=0.75)
        parts.append(f'{name} (did you mean {" or ".join(close)}?)' if close else name)
    return (f'unknown parameter{"s" if len(unknown) > 1 else ""} {", ".join(parts)}: '
            f'{node.get_name()} has no such parameter (see --help)')
