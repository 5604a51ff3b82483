"""Declare ROS parameters from a frozen dataclass, with descriptors, and read them back validated.

A node's parameters are one frozen dataclass whose fields carry their documentation::

    @dataclass(frozen=True)
    class Params:
        noise_floor_db: float = parameter(-20.0, 'Calibrated noise floor, dBFS.', minimum=-200.0, maximum=0.0)

``declare(node, Params)`` declares every field with a ``ParameterDescriptor`` (description,
range, read-only) and returns a ``Params`` built from the values the node was given (command
line, YAML file), so the dataclass's own ``__post_init__`` validation runs on them. ``describe``
renders the same documentation for ``--help``.

Changes while running. A field declared with ``read_only=False`` can be set while the node runs
(``ros2 param set``, the ``SetParameters`` service). :class:`RuntimeParameters` validates a change
with the same code as at start (rclpy checks the descriptor's type and range, then the dataclass is
rebuilt with the new values, so its ``__post_init__`` and :func:`validate_ranges` run on it: a value
refused at start is refused here with the same reason) and keeps it pending; the node applies it at
a safe point of its own (between two input messages) with :meth:`RuntimeParameters.take`. Every
other field stays read-only (the descriptor says so and rclpy refuses the change); each node's
documentation says why (typically: the value sizes or shapes state that a change would corrupt).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable
from typing import Any, Generic, TypeVar

T = TypeVar('T')

_DOC = 'rfi_doc'
_INTERNAL = 'rfi_internal'

USER = 'user'
"""Group of the few parameters a user sets for an installation (frames, lever arms, sensors used):
listed first by ``--help``, the config file and docs/reference/parameters.md."""
TUNING = 'tuning'
"""Group of the parameters of the method (noise levels, thresholds, windows): the defaults are the
tested values; change them only with a reason the description gives."""
GROUPS = (USER, TUNING)


def parameter(default: Any, description: str, *, minimum: float | None = None,
              maximum: float | None = None, read_only: bool = True, choices: tuple[str, ...] = (),
              group: str = TUNING) -> Any:
    """A dataclass field that is also a documented ROS parameter: the one place of its default and text.

    Args:
        default: default value (its type is the parameter's type).
        description: meaning and unit, as shown by ``--help``, ``ros2 param describe`` and the generated
            config file (:func:`config_yaml`).
        minimum, maximum: inclusive range of a numeric parameter.
        read_only: the parameter cannot change after start-up (the default). False: settable while the
            node runs (:class:`RuntimeParameters`), for values the node can apply between two messages.
        choices: allowed values of a string parameter.
        group: :data:`USER` (set per installation, listed first) or :data:`TUNING` (the default).
    """
    if group not in GROUPS:
        raise ValueError(f'parameter group {group!r} is not one of {", ".join(GROUPS)}')
    doc = {'description': description, 'minimum': minimum, 'maximum': maximum,
           'read_only': read_only, 'choices': tuple(choices), 'group': group}
    if isinstance(default, (list, tuple)):
        return dataclasses.field(default_factory=lambda: tuple(default), metadata={_DOC: doc})
    return dataclasses.field(default=default, metadata={_DOC: doc})


def internal(default: Any = dataclasses.MISSING, *, default_factory: Any = dataclasses.MISSING) -> Any:
    """A field of a parameter dataclass that is not a ROS parameter (e.g. a value derived from parameters,
    or a core's option that a node fills from its inputs): :func:`declare`, :func:`describe`,
    :func:`config_yaml` and :func:`validate_ranges` skip it."""
    return dataclasses.field(default=default, default_factory=default_factory, metadata={_INTERNAL: True})


def parameter_from(owner: type, name: str, **changes: Any) -> Any:
    """A node's parameter field that is the field ``name`` of the core dataclass ``owner``, defined there
    with :func:`parameter`: same default, description, range and group (``changes`` may set ``read_only``,
    ``group`` or ``description``, and ``choices`` to a subset of the core's, for a node that offers fewer
    values than its core accepts). For a node whose parameter names differ from its core's (a prefix, a
    core split in several dataclasses): the default and the text stay in the core's definition.

    Raises:
        TypeError: ``owner`` has no such field, or it was not defined with :func:`parameter`.
        ValueError: ``choices`` that are not a subset of the core's or leave out the default.
    """
    fields = {f.name: f for f in dataclasses.fields(owner)}
    if name not in fields or _DOC not in fields[name].metadata:
        raise TypeError(f'{owner.__name__}.{name} is not a field defined with parameter()')
    field = fields[name]
    doc = dict(field.metadata[_DOC])
    unknown = set(changes) - {'read_only', 'group', 'description', 'choices'}
    if unknown:
        raise TypeError(f'parameter_from cannot change {", ".join(sorted(unknown))}')
    if 'choices' in changes:
        changes['choices'] = tuple(changes['choices'])
        if not set(changes['choices']) <= set(doc['choices']) or field.default not in changes['choices']:
            raise ValueError(f'choices of {owner.__name__}.{name} must be a subset of {doc["choices"]} '
                             f'that holds the default {field.default!r}')
    doc.update(changes)
    if doc['group'] not in GROUPS:
        raise ValueError(f'parameter group {doc["group"]!r} is not one of {", ".join(GROUPS)}')
    return dataclasses.field(default=field.default, default_factory=field.default_factory,  # type: ignore[misc]
                             metadata={_DOC: doc})


def parameter_fields(params_cls: Any) -> list[dataclasses.Field]:
    """The fields of ``params_cls`` (a class or an instance) that are ROS parameters, the :data:`USER`
    group first, each group in field order."""
    fields = [f for f in dataclasses.fields(params_cls) if not f.metadata.get(_INTERNAL, False)]
    return sorted(fields, key=lambda f: GROUPS.index(_doc(f)['group']))


def _doc(field: dataclasses.Field) -> dict[str, Any]:
    doc = {'description': '', 'minimum': None, 'maximum': None, 'read_only': True, 'choices': (),
           'group': TUNING}
    doc.update(field.metadata.get(_DOC, {}))
    return doc


def _default(field: dataclasses.Field) -> Any:
    if field.default is not dataclasses.MISSING:
        return field.default
    if field.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        return field.default_factory()  # type: ignore[misc]
    raise TypeError(f'parameter {field.name} has no default')


def check_positive_finite(params: object, keys: tuple[str, ...]) -> None:
    """Refuse a parameter set whose fields ``keys`` are not all finite numbers > 0 (the check of a core's
    frozen parameter dataclass in its ``__post_init__``, with or without :func:`parameter` metadata).

    Raises:
        ValueError: naming the first such field as ``<class>.<key>``, with its value.
    """
    for key in keys:
        value = getattr(params, key)
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
            raise ValueError(f'{type(params).__name__}.{key} must be finite and > 0, got {value!r}')


def validate_ranges(params: Any) -> None:
    """Check every field against its declared range and choices.

    Raises:
        ValueError: naming the parameter, its value and the allowed range.
    """
    for field in parameter_fields(params):
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
    for field in parameter_fields(params_cls):
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
    return build(params_cls, values)


def build(params_cls: type[T], values: dict[str, Any]) -> T:
    """``params_cls(**values)`` checked by :func:`validate_ranges`: the one validation of the parameters,
    at start (:func:`declare`) and for a change while running (:class:`RuntimeParameters`).

    Raises:
        ValueError: a value is out of range or fails the dataclass's own validation.
    """
    try:
        params = params_cls(**values)
    except TypeError as err:
        raise ValueError(str(err)) from None
    validate_ranges(params)
    return params


def runtime_parameter_names(params_cls: type) -> tuple[str, ...]:
    """Names of the fields settable while the node runs (declared with ``read_only=False``)."""
    return tuple(f.name for f in parameter_fields(params_cls) if not _doc(f)['read_only'])


class RuntimeParameters(Generic[T]):
    """Changes of a node's settable parameters while it runs, validated as at start, applied by the node.

    Registers an ``on_set_parameters`` callback on ``node``. rclpy itself refuses a read-only parameter,
    a wrong type and a value outside the descriptor's range; for a change of the node's own parameters
    that rclpy accepts, the callback rebuilds the parameter dataclass with the new values (on top of any
    change still pending) through :func:`build`, the code that validated the start values, and refuses
    the whole set (``SetParametersResult.successful`` false, the reason of the ValueError) if it fails.
    An accepted change is pending until the node calls :meth:`take` at a safe point (between two
    messages), which returns the new dataclass for the node to apply to its core.

    Args:
        node: the rclpy node that declared ``params`` (with :func:`declare`).
        params: the values in force.

    Attributes:
        current: the values in force (updated by :meth:`take`).
        changes_applied / changes_refused: counts, for /diagnostics.
    """

    def __init__(self, node: Any, params: T) -> None:
        self.current = params
        self._pending: T | None = None
        self._names = {f.name for f in parameter_fields(params)}
        self._tuples = {f.name for f in parameter_fields(params) if isinstance(getattr(params, f.name), tuple)}
        self.changes_applied = 0
        self.changes_refused = 0
        node.add_on_set_parameters_callback(self._on_set)

    def _on_set(self, parameters: Iterable[Any]) -> Any:
        from rcl_interfaces.msg import SetParametersResult

        changes = {p.name: (tuple(p.value) if p.name in self._tuples else p.value)
                   for p in parameters if p.name in self._names}
        if not changes:  # not ours (e.g. use_sim_time): rclpy's own checks decide
            return SetParametersResult(successful=True)
        try:
            self._pending = self.validate(changes)
        except ValueError as err:
            self.changes_refused += 1
            return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def validate(self, changes: dict[str, Any]) -> T:
        """The parameters in force (and any change pending) with ``changes``, validated as at start.

        Raises:
            ValueError: as :func:`build` at start.
        """
        base = self._pending if self._pending is not None else self.current
        values = {f.name: getattr(base, f.name) for f in parameter_fields(base)}
        values.update(changes)
        return build(type(base), values)

    @property
    def pending(self) -> bool:
        """A validated change waits for :meth:`take`."""
        return self._pending is not None

    def take(self) -> T | None:
        """The new parameters if a change is pending (they are then in force), else None."""
        new, self._pending = self._pending, None
        if new is not None:
            self.current = new
            self.changes_applied += 1
        return new

    def apply_pending(self, apply: Callable[[T, T], None]) -> bool:
        """If a change is pending: ``apply(old, new)`` (the node hands the new values to its core) and
        return True; the new values are in force afterwards even if ``apply`` raises."""
        old = self.current
        new = self.take()
        if new is None:
            return False
        apply(old, new)
        return True


def changed_names(old: Any, new: Any) -> list[str]:
    """Fields whose value differs between two instances of one parameter dataclass."""
    return [f.name for f in parameter_fields(old) if getattr(old, f.name) != getattr(new, f.name)]


def _first_line(err: Exception) -> str:
    text = str(err).strip().splitlines()
    return text[0] if text else type(err).__name__


def _limits(doc: dict[str, Any]) -> str:
    if doc['choices']:
        return f'{{{", ".join(doc["choices"])}}}'
    if doc['minimum'] is not None or doc['maximum'] is not None:
        low = doc['minimum'] if doc['minimum'] is not None else '-inf'
        high = doc['maximum'] if doc['maximum'] is not None else 'inf'
        return f'[{low}, {high}]'
    return ''


GROUP_TITLES = {USER: 'user parameters (set for your installation)',
                TUNING: 'tuning parameters (the method; defaults are the tested values)'}


def describe(params_cls: type) -> str:
    """Plain-text documentation of the parameters, for ``--help``: the :data:`USER` group first."""
    lines = []
    group = None
    for field in parameter_fields(params_cls):
        doc = _doc(field)
        if doc['group'] != group:
            group = doc['group']
            lines.append(f' {GROUP_TITLES[group]}:')
        limits = _limits(doc)
        limits = f' {limits}' if limits else ''
        live = '' if doc['read_only'] else ' [settable while running]'
        lines.append(f'  {field.name} (default {_default(field)!r}){limits}{live}\n      {doc["description"]}')
    return '\n'.join(lines)


def yaml_value(value: Any) -> str:
    """``value`` written as the ROS 2 parameter-file parser reads it back with the same type (floats with
    a decimal point, ``.inf``; tuples as flow sequences)."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return '.nan'
        if math.isinf(value):
            return '.inf' if value > 0 else '-.inf'
        text = repr(value)
        if 'e' in text and '.' not in text.split('e')[0]:
            mantissa, exponent = text.split('e')
            text = f'{mantissa}.0e{exponent}'
        return text
    if isinstance(value, (tuple, list)):
        return '[' + ', '.join(yaml_value(v) for v in value) + ']'
    if isinstance(value, str):
        import json

        plain = value and value.replace('_', '').replace('-', '').replace('+', '').replace('#', '').isalnum() \
            and not value[0].isdigit() and value.lower() not in {'true', 'false', 'yes', 'no', 'on', 'off', 'null'}
        return value if plain else json.dumps(value)
    raise TypeError(f'no YAML form for {value!r}')


def config_yaml(node_name: str, params_cls: type, header: str, width: int = 100) -> str:
    """The config file of a node, generated from its parameter dataclass: ``header`` as comment lines, then
    ``node_name: ros__parameters:`` with every parameter (the :data:`USER` group first) at its default,
    each after its description, its range and ``[settable while running]`` where it is.

    The shipped ``config/<node>.yaml`` is this text (``tools/generate_config.py`` writes it; each node's
    tests check that the file equals it), so a default or a description is changed in the dataclass only.
    """
    import textwrap

    lines = [('# ' + line).rstrip() for line in header.strip().splitlines()]
    lines += [f'{node_name}:', '  ros__parameters:']
    group = None
    for field in parameter_fields(params_cls):
        doc = _doc(field)
        if doc['group'] != group:
            group = doc['group']
            title = f'# --- {GROUP_TITLES[group]} '
            lines += ['', '    ' + title + '-' * max(3, width - 4 - len(title))]
        text = doc['description']
        if not doc['read_only']:
            text = '[settable while running] ' + text
        limits = _limits(doc)
        if limits:
            text += f' Range {limits}.' if not doc['choices'] else f' One of {limits}.'
        lines += textwrap.wrap(text, width=width, initial_indent='    # ', subsequent_indent='    # ',
                               break_on_hyphens=False, break_long_words=False)
        lines.append(f'    {field.name}: {yaml_value(_default(field))}')
    return '\n'.join(lines) + '\n'


def markdown_table(params_cls: type, group: str | None = USER) -> str:
    """A Markdown table of the parameters of ``group`` (all if None): name, default, range, settable while
    running, description; for docs/reference/parameters.md (written by ``tools/generate_config.py``)."""
    rows = ['| parameter | default | range | settable while running | description |', '|---|---|---|---|---|']
    for field in parameter_fields(params_cls):
        doc = _doc(field)
        if group is not None and doc['group'] != group:
            continue
        cells = [f'`{field.name}`', f'`{yaml_value(_default(field))}`', _limits(doc).replace('|', '\\|'),
                 '' if doc['read_only'] else 'yes', doc['description'].replace('|', '\\|')]
        rows.append('| ' + ' | '.join(cells) + ' |')
    return '\n'.join(rows) + '\n'


@dataclasses.dataclass(frozen=True)
class ConfigFile:
    """A node's shipped config file, generated from its parameter dataclass (:func:`config_yaml`).

    Attributes:
        package: the ROS package (directory ``src/<package>``).
        path: the file, relative to the package directory (``config/<node>.yaml``).
        node_name: the node's name, the file's top-level key.
        params_cls: the node's parameter dataclass.
        header: comment text above the parameters (use, inputs, outputs), without ``#``.
    """

    package: str
    path: str
    node_name: str
    params_cls: type
    header: str

    def text(self) -> str:
        """The file's content."""
        return config_yaml(self.node_name, self.params_cls, self.header)


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


def set_parameters_remotely(client_node: Any, executor: Any, node_name: str, values: dict[str, Any],
                            timeout_s: float = 10.0) -> list[Any]:
    """What ``ros2 param set NODE NAME VALUE`` does, from rclpy: call NODE's ``set_parameters`` service.

    Args:
        client_node: a node of the caller, added to ``executor``.
        executor: spun (bounded by ``timeout_s``) until the answer arrives; it must also spin the
            target node if that node lives in this process.
        node_name: fully qualified name of the target node (``/uwb_gnss_fusion``).
        values: parameter name -> value (Python types as for ``rclpy.parameter.Parameter``).
        timeout_s: wall-clock bound on the service's discovery and answer, s.

    Returns:
        one ``rcl_interfaces/SetParametersResult`` per value, in order (``successful``, ``reason``).

    Raises:
        TimeoutError: the service did not appear or answer within ``timeout_s``.
    """
    import time

    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter

    client = client_node.create_client(SetParameters, f'{node_name.rstrip("/")}/set_parameters')
    try:
        deadline = time.monotonic() + timeout_s
        while not client.service_is_ready():
            if time.monotonic() > deadline:
                raise TimeoutError(f'{node_name}/set_parameters did not appear within {timeout_s} s')
            executor.spin_once(timeout_sec=0.05)
        request = SetParameters.Request(
            parameters=[Parameter(name, value=value).to_parameter_msg() for name, value in values.items()])
        future = client.call_async(request)
        executor.spin_until_future_complete(future, timeout_sec=max(0.0, deadline - time.monotonic()))
        if not future.done():
            raise TimeoutError(f'{node_name}/set_parameters did not answer within {timeout_s} s')
        return list(future.result().results)
    finally:
        client_node.destroy_client(client)
