"""rclpy messages <-> message dicts, and the node's conversion of states to scenes.

A *message dict* (see :mod:`rbe_ros.io.messages`, the one place that knows the rbe_msgs layout)
is a nested dict/list shaped like the message. The generic converters below work for any
generated rclpy message type by walking its ``SLOT_TYPES`` (the rosidl type descriptions that
every generated class carries), like ``rosidl_runtime_py.message_to_ordereddict`` and
``set_message_fields`` do; ``rosidl_runtime_py`` itself is not published as a PyPI wheel, so
this module does not depend on it.

The walk is planned once per message class (per field a getter, a converter and a setter,
cached) rather than decided per value. Bulk data may be given as numpy arrays: a sequence of
messages whose fields are all floats (``geometry_msgs/Point``, ``Vector3``, ``Quaternion``,
``std_msgs/ColorRGBA``) as an ``(n, k)`` array of their field values in field order
(``rbe_ros.io.messages.report_to_dict(..., arrays=True)`` gives that form), and a
``float64[]``/``float32[]`` sequence as a 1-D array, handed to the setter as the
``array.array`` rclpy stores anyway. (The node's reports do not come this way: they are
encoded to CDR directly, :mod:`rbe_ros.io.cdr`.)
"""
from __future__ import annotations

import array
import importlib
from collections.abc import Mapping

import numpy as np
from rosidl_parser.definition import (AbstractGenericString, AbstractNestedType,
                                      AbstractSequence, BasicType, NamespacedType)

from ..io.messages import scene_from_state_dict
from ..scene import Scene, SceneError, ValidationLimits, check_block_count

_FLOATS = {"float", "double", "long double"}
_INTS = {"int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "char"}
#: array.array type codes of the float sequences (what rclpy's setters store)
_FLOAT_CODES = {"float": "f", "double": "d"}


def _message_class(t: NamespacedType):
    module = importlib.import_module(".".join(t.namespaces))
    return getattr(module, t.name)


def _fields(msg):
    """(field name, rosidl type) pairs of a generated message instance or class."""
    return zip(msg.get_fields_and_field_types(), msg.SLOT_TYPES)


def _caster(typ):
    """The function that casts a value to the basic or string type ``typ`` (identity for
    other types)."""
    if isinstance(typ, AbstractGenericString):
        return str
    if isinstance(typ, BasicType):
        name = typ.typename
        if name in _FLOATS:
            return float
        if name in _INTS:
            return int
        if name == "boolean":
            return bool
        if name == "octet":
            return _octet
    return _identity


def _octet(value):
    return bytes(value) if not isinstance(value, int) else bytes([value])


def _identity(value):
    return value


def _float_fields(cls) -> tuple[str, ...] | None:
    """The field names of ``cls`` if all its fields are float/double scalars, else None."""
    names = tuple(cls.get_fields_and_field_types())
    if names and all(isinstance(t, BasicType) and t.typename in ("float", "double")
                     for t in cls.SLOT_TYPES):
        return names
    return None


class _Plan:
    """How to read and write the fields of one message class, worked out once: per field a
    getter (message -> dict value), a converter (dict value -> field value) and a setter
    (message, dict value -> None; nested messages are set in place); ``build`` makes a new
    message from a message dict in one constructor call, ``from_rows`` (all-float types only)
    the messages of rows of field values."""

    __slots__ = ("cls", "getters", "converters", "setters", "from_rows")

    def __init__(self, cls):
        self.cls = cls
        self.getters: dict = {}
        self.converters: dict = {}
        self.setters: dict = {}
        self.from_rows = None
        for name, typ in _fields(cls):      # nested types: their plans are made on first use
            self.getters[name] = _getter(name, typ)
            convert = self.converters[name] = _converter(typ)
            self.setters[name] = _setter(name, typ, convert)
        floats = _float_fields(cls)
        if floats is not None:
            self.from_rows = lambda rows: [cls(**dict(zip(floats, row))) for row in rows]

    def build(self, values):
        if not isinstance(values, Mapping):
            raise TypeError(f"{self.cls.__name__}: expected a message dict, "
                            f"got {type(values).__name__}")
        converters = self.converters
        kwargs = {}
        for name, value in values.items():
            convert = converters.get(name)
            if convert is None:
                raise ValueError(f"{self.cls.__name__} has no field {name!r}")
            kwargs[name] = convert(value)
        return self.cls(**kwargs)


_PLANS: dict[type, _Plan] = {}


def _plan(cls) -> _Plan:
    """The plan of a message class (made once, then cached; complete before it is shared)."""
    plan = _PLANS.get(cls)
    if plan is None:
        plan = _PLANS.setdefault(cls, _Plan(cls))
    return plan


def _lazy_plan(t: NamespacedType):
    """A function giving the plan of the message class of ``t``, imported on first use."""
    found = None

    def plan_of() -> _Plan:
        nonlocal found
        if found is None:
            found = _plan(_message_class(t))
        return found
    return plan_of


def _float_rows(values: np.ndarray, cls) -> list:
    """Rows of Python floats of an (n, k) float array of a sequence of all-float ``cls``
    messages (k: its number of fields)."""
    k = len(cls.SLOT_TYPES)
    if values.ndim != 2 or values.shape[1] != k:
        raise ValueError(f"{cls.__name__}: expected an (n, {k}) array of field values, "
                         f"got shape {values.shape}")
    return np.asarray(values, dtype=float).tolist()


# --- message -> dict --------------------------------------------------------------------------

def message_to_dict(msg) -> dict:
    """The message dict of an rclpy message (numbers as Python ``int``/``float``, arrays as
    lists, ``byte`` fields as ``bytes``)."""
    return {name: get(msg) for name, get in _plan(type(msg)).getters.items()}


def _getter(name: str, typ):
    if isinstance(typ, NamespacedType):
        return lambda msg: message_to_dict(getattr(msg, name))
    if isinstance(typ, AbstractNestedType):
        item = typ.value_type
        if isinstance(item, NamespacedType):
            return lambda msg: [message_to_dict(v) for v in getattr(msg, name)]
        if isinstance(item, BasicType) and item.typename == "octet":
            return lambda msg: [bytes(v) for v in getattr(msg, name)]
        if isinstance(item, BasicType) and item.typename in _FLOAT_CODES:
            return lambda msg: _float_list(getattr(msg, name))
        cast = _caster(item)
        return lambda msg: [cast(v) for v in getattr(msg, name)]
    cast = _caster(typ)
    return lambda msg: cast(getattr(msg, name))


def _float_list(values) -> list[float]:
    if isinstance(values, array.array):
        return values.tolist()      # Python floats, as float() of each would give
    return [float(v) for v in values]


# --- dict -> message --------------------------------------------------------------------------

def set_message_fields(msg, values: Mapping):
    """Set the fields of ``msg`` from a message dict (missing keys keep their defaults; unknown
    keys raise ``ValueError``; numbers are cast to the field type). Returns ``msg``."""
    if not isinstance(values, Mapping):
        raise TypeError(f"{type(msg).__name__}: expected a message dict, "
                        f"got {type(values).__name__}")
    setters = _plan(type(msg)).setters
    for name, value in values.items():
        setter = setters.get(name)
        if setter is None:
            raise ValueError(f"{type(msg).__name__} has no field {name!r}")
        setter(msg, value)
    return msg


def _setter(name: str, typ, convert):
    if isinstance(typ, NamespacedType):
        return lambda msg, value: set_message_fields(getattr(msg, name), value)
    return lambda msg, value: setattr(msg, name, convert(value))


def _converter(typ):
    """The function from a dict value to the value of a field of type ``typ``."""
    if isinstance(typ, NamespacedType):
        plan_of = _lazy_plan(typ)
        return lambda value: plan_of().build(value)
    if isinstance(typ, AbstractNestedType):
        item = typ.value_type
        if isinstance(item, NamespacedType):
            plan_of = _lazy_plan(item)

            def messages(value):
                plan = plan_of()
                if isinstance(value, np.ndarray) and plan.from_rows is not None:
                    return plan.from_rows(_float_rows(value, plan.cls))
                build = plan.build
                return [build(v) for v in value]
            return messages
        cast = _caster(item)
        code = _FLOAT_CODES.get(item.typename) if isinstance(item, BasicType) else None
        if code is not None and isinstance(typ, AbstractSequence):
            dtype = np.dtype(code)

            def floats(value):
                if isinstance(value, np.ndarray) and value.ndim == 1:
                    out = array.array(code)
                    out.frombytes(np.ascontiguousarray(value, dtype=dtype).tobytes())
                    return out
                if isinstance(value, (list, tuple)):
                    try:
                        return array.array(code, value)
                    except TypeError:       # e.g. a string among the numbers: cast each
                        pass
                return [cast(v) for v in value]
            return floats
        return lambda value: [cast(v) for v in value]
    return _caster(typ)


def dict_to_message(values: Mapping, msg_type):
    """A new ``msg_type`` message from a message dict (as ``set_message_fields(msg_type(),
    values)``, in one constructor call)."""
    return _plan(msg_type).build(values)


# --- the node's conversion --------------------------------------------------------------------

def scene_from_msg(msg, *, sequence: bool = True, limits: ValidationLimits | None = None) -> Scene:
    """The validated scene of an rbe_msgs/AssemblyState (raises :class:`SceneError`).

    ``sequence=False`` drops the state's sequence (not validated then): the assembly as it is.
    With ``limits``, the counts of blocks and of mesh vertices and triangles are checked on the
    message first, before anything is converted (a hostile message costs nothing then); the
    other limits are checked with the scene (:func:`rbe_ros.analysis.validate.validated_assembly`).
    """
    if limits is not None:
        check_block_count(len(msg.blocks), limits)
        for block in msg.blocks:
            vertices, triangles = len(block.mesh.vertices), len(block.mesh.triangles)
            if vertices > limits.max_vertices or triangles > 2 * limits.max_vertices:
                raise SceneError(f"block {block.id!r}: mesh of {vertices} vertices and "
                                 f"{triangles} triangles, more than the limit of "
                                 f"{limits.max_vertices} vertices", [block.id])
    values = message_to_dict(msg)
    if not sequence:
        values["sequence"] = []
    return scene_from_state_dict(values)


__all__ = ["message_to_dict", "set_message_fields", "dict_to_message", "scene_from_msg"]
