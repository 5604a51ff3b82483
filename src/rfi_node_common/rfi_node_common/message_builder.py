"""Fast constructors of message objects, generated from the message classes' own description.

Part of the suite's codec layer (:mod:`rfi_node_common.cdr` reads and writes the bytes of the same
descriptions). A generated rosidl ``__init__`` builds a default for every field, nested messages
included, even those given, and imports its sub-message classes on every call (an Odometry through
its constructors took about 40 us). Outputs that must stay Python objects (the fusion node inspects
its NavSatFix before publishing it, and the in-process replay hands the published object to the
subscribers) are built with :func:`message_builder` instead. No rclpy import.
"""

from __future__ import annotations

import copy
from array import array
from collections.abc import Callable
from functools import cache
from typing import Any

import numpy as np

from rfi_node_common.cdr import KIND_BOOL, KIND_FLOAT, KIND_SIGNED, PRIMITIVES, message_class

_MISSING: Any = object()


_DIRECT = ("BasicType", "UnboundedString", "BoundedString")
"""rosidl types whose generated setter stores the value as given when field checks are off."""


def _fields(msg_class: Any) -> list[tuple[str, Any]]:
    return list(zip(msg_class.get_fields_and_field_types(), msg_class.SLOT_TYPES, strict=True))


@cache
def _generated_builder(msg_class: Any) -> Callable[..., Any]:
    """Source of ``build(**leaves)`` for the whole message tree, generated and compiled once."""
    env: dict[str, Any] = {"_new": object.__new__, "_MISSING": _MISSING, "_copy": copy.copy}
    params: list[str] = []
    body: list[str] = []

    def emit(cls: Any, prefix: str) -> str:
        var = f"m{len(env)}"
        env[f"_c{var}"] = cls
        default = cls()
        body.append(f"    {var} = _new(_c{var})")
        body.append(f"    {var}._check_fields = False")
        for name, t in _fields(cls):
            path = prefix + name
            kind = type(t).__name__
            if kind == "NamespacedType":
                body.append(f"    {var}._{name} = {emit(message_class(t), path + '__')}")
            elif kind in _DIRECT:
                env[f"_d_{path}"] = getattr(default, name)  # immutable: int, float, bool or str
                params.append(f"{path}=_d_{path}")
                body.append(f"    {var}._{name} = {path}")
            else:  # arrays and sequences: the generated setter's conversion; a default is a fresh copy
                env[f"_s_{path}"] = getattr(cls, name).fset
                env[f"_d_{path}"] = getattr(default, name)
                params.append(f"{path}=_MISSING")
                body.append(f"    _s_{path}({var}, _copy(_d_{path}) if {path} is _MISSING else {path})")
        return var

    top = emit(msg_class, "")
    source = f"def build(*, {', '.join(params)}):\n" + "\n".join(body) + f"\n    return {top}\n"
    exec(compile(source, f"<message_builder {msg_class.__name__}>", "exec"), env)  # noqa: S102 - generated
    return env["build"]


def _construct(msg_class: Any, leaves: dict[str, Any]) -> Any:
    """The public constructors, nested, from leaf keywords (the reference path)."""
    direct: dict[str, Any] = {}
    nested: dict[str, dict[str, Any]] = {}
    for key, value in leaves.items():
        head, sep, rest = key.partition("__")
        if sep:
            nested.setdefault(head, {})[rest] = value
        else:
            direct[key] = value
    types = dict(_fields(msg_class))
    for head, sub in nested.items():
        direct[head] = _construct(message_class(types[head]), sub)
    return msg_class(**direct)


def _public_builder(msg_class: Any) -> Callable[..., Any]:
    def build(**leaves: Any) -> Any:
        return _construct(msg_class, leaves)
    return build


def leaf_values(msg: Any, prefix: str = "") -> dict[str, Any]:
    """The keywords of :func:`message_builder` that rebuild ``msg``: every leaf field by its path
    (nested message fields joined by ``__``, e.g. ``header__stamp__sec``)."""
    out: dict[str, Any] = {}
    for name, t in _fields(type(msg)):
        value = getattr(msg, name)
        if type(t).__name__ == "NamespacedType":
            out.update(leaf_values(value, f"{prefix}{name}__"))
        else:
            out[prefix + name] = value
    return out


@cache
def message_builder(msg_class: Any, fast: bool = True) -> Callable[..., Any]:
    """A constructor of ``msg_class`` taking its leaf fields as keywords, generated from its description.

    The keywords are the paths of the leaf fields, nested messages joined by ``__``
    (``header__stamp__sec``, ``pose__pose__position__x``; rosidl forbids ``__`` in field names).
    The generated function builds the whole tree in one call: walking ``get_fields_and_field_types()``
    and ``SLOT_TYPES`` of the class and of every nested class, it creates each nested message once and
    stores a scalar or string in its slot as given (what the generated setter does with field checks
    off); an array or sequence goes through the generated setter (which makes its fresh copy). A leaf
    not given gets the field's default.

    Args:
        msg_class: generated message class.
        fast: False gives the public constructors instead (nested, from the same keywords).

    Returns:
        ``build(**leaves) -> message``. Values must already have the field's type (float for a
        double, int for an integer); arrays and sequences take anything the setter takes.

    The generated constructor is used only if :func:`builders_agree` holds for the class (the
    generated classes have ``_<field>`` slots, field checks are off, and it builds messages equal to
    the public constructors'); otherwise this returns the public one.
    """
    if fast and builders_agree(msg_class):
        return _generated_builder(msg_class)
    return _public_builder(msg_class)


@cache
def builders_agree(msg_class: Any) -> bool:
    """True if the generated constructor of ``msg_class`` can be used (see :func:`message_builder`).

    Checks that field checks are off (``ROS_PYTHON_CHECK_FIELDS`` not ``1`` when the message
    module was imported) and that the class and every nested class have exactly the slots
    ``_<field>`` + ``_check_fields``, then that a message built from random leaf values (and one with
    every field defaulted) equals the public constructors', field by field and in storage type.
    """
    try:
        if not _slots_as_expected(msg_class):
            return False
        build = _generated_builder(msg_class)
        probe = msg_class(**probe_values(msg_class, np.random.default_rng(7)))
        return (messages_equal(build(**leaf_values(probe)), probe)
                and messages_equal(build(), msg_class()))
    except (AttributeError, TypeError, ValueError, AssertionError, NotImplementedError):
        return False


def _slots_as_expected(msg_class: Any) -> bool:
    names = list(msg_class.get_fields_and_field_types())
    if set(getattr(msg_class, "__slots__", ())) != {f"_{n}" for n in names} | {"_check_fields"}:
        return False
    if msg_class()._check_fields:
        return False
    for _, t in _fields(msg_class):
        if type(t).__name__ == "NamespacedType" and not _slots_as_expected(message_class(t)):
            return False
    return True


def probe_values(msg_class: Any, rng: np.random.Generator, max_sequence: int = 3) -> dict[str, Any]:
    """Random field values of ``msg_class`` (keywords for its constructor), seeded by ``rng``.

    Floats are drawn over a wide range and sometimes NaN or infinite, integers over their whole
    type, strings of 0-12 ASCII letters, sequences of 0..max_sequence elements (bounded: up to
    the bound), nested messages recursively. Used by the builders' self-check and by the tests that
    compare the codec with rclpy for every message type.
    """
    values: dict[str, Any] = {}
    for name, t in zip(msg_class.get_fields_and_field_types(), msg_class.SLOT_TYPES, strict=True):
        cls = type(t).__name__
        if cls in ("Array", "BoundedSequence", "UnboundedSequence"):
            if cls == "Array":
                n = int(t.size)
            else:
                n = int(rng.integers(0, max_sequence + 1))
                n = min(n, int(getattr(t, "maximum_size", n)))
            items = [_probe_one(t.value_type, rng, max_sequence) for _ in range(n)]
            vt = t.value_type
            if type(vt).__name__ == "BasicType" and vt.typename in ("float", "double"):
                values[name] = np.array(items, dtype=np.float32 if vt.typename == "float" else np.float64)
            else:
                values[name] = items
        else:
            values[name] = _probe_one(t, rng, max_sequence)
    return values


def _probe_one(t: Any, rng: np.random.Generator, max_sequence: int) -> Any:
    cls = type(t).__name__
    if cls == "NamespacedType":
        sub = message_class(t)
        return sub(**probe_values(sub, rng, max_sequence))
    if cls in ("UnboundedString", "BoundedString"):
        n = int(rng.integers(0, 13))
        n = min(n, int(getattr(t, "maximum_size", n)))
        return "".join(chr(int(c)) for c in rng.integers(97, 123, n))
    if cls != "BasicType":
        raise NotImplementedError(f"probe values: {cls} is not supported")
    size, kind = PRIMITIVES[t.typename]
    if kind == KIND_FLOAT:
        special = rng.random()
        if special < 0.1:
            return float(rng.choice([np.nan, np.inf, -np.inf, -0.0]))
        x = float(rng.normal() * 10.0 ** rng.integers(-6, 9))
        return float(np.float32(x)) if size == 4 else x
    if kind == KIND_BOOL:
        return bool(rng.integers(0, 2))
    if t.typename in ("octet", "char"):
        return bytes([int(rng.integers(0, 256))]) if t.typename == "octet" else chr(int(rng.integers(32, 127)))
    bits = 8 * size
    low, high = (-(2 ** (bits - 1)), 2 ** (bits - 1)) if kind == KIND_SIGNED else (0, 2**bits)
    return int(rng.integers(low, high, dtype=np.int64 if high <= 2**63 else np.uint64))


def messages_equal(a: Any, b: Any) -> bool:
    """Field-by-field equality of two messages, NaN equal to NaN and storage types compared
    (generated ``__eq__`` says NaN != NaN)."""
    if type(a) is not type(b):
        return False
    if hasattr(type(a), "get_fields_and_field_types"):
        return all(messages_equal(getattr(a, f), getattr(b, f)) for f in type(a).get_fields_and_field_types())
    if isinstance(a, (np.ndarray, array)):
        return (len(a) == len(b) and np.asarray(a).dtype == np.asarray(b).dtype
                and bool(np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)))
    if isinstance(a, list):
        return len(a) == len(b) and all(messages_equal(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and np.isnan(a):
        return bool(np.isnan(b))
    return bool(a == b)
