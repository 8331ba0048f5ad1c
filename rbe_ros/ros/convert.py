"""rclpy messages <-> message dicts, and the two conversions the node needs.

A *message dict* (see :mod:`rbe_ros.messages`, the one place that knows the rbe_msgs layout)
is a nested dict/list shaped like the message. The generic converters below work for any
generated rclpy message type by walking its ``SLOT_TYPES`` (the rosidl type descriptions that
every generated class carries), like ``rosidl_runtime_py.message_to_ordereddict`` and
``set_message_fields`` do; ``rosidl_runtime_py`` itself is not published as a PyPI wheel, so
this module does not depend on it.
"""
from __future__ import annotations

import importlib
from collections.abc import Mapping

from rosidl_parser.definition import (AbstractGenericString, AbstractNestedType,
                                      BasicType, NamespacedType)

from ..messages import report_to_dict, scene_from_state_dict
from ..rbe.result import Report
from ..scene import Scene, SceneError, ValidationLimits, check_block_count

_FLOATS = {"float", "double", "long double"}
_INTS = {"int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "char"}


def _message_class(t: NamespacedType):
    module = importlib.import_module(".".join(t.namespaces))
    return getattr(module, t.name)


def _fields(msg):
    """(field name, rosidl type) pairs of a generated message instance or class."""
    return zip(msg.get_fields_and_field_types(), msg.SLOT_TYPES)


# --- message -> dict --------------------------------------------------------------------------

def message_to_dict(msg) -> dict:
    """The message dict of an rclpy message (numbers as Python ``int``/``float``, arrays as
    lists, ``byte`` fields as ``bytes``)."""
    return {name: _value_to_dict(typ, getattr(msg, name)) for name, typ in _fields(msg)}


def _value_to_dict(typ, value):
    if isinstance(typ, NamespacedType):
        return message_to_dict(value)
    if isinstance(typ, AbstractNestedType):
        item = typ.value_type
        if isinstance(item, NamespacedType):
            return [message_to_dict(v) for v in value]
        if isinstance(item, BasicType) and item.typename == "octet":
            return [bytes(v) for v in value]
        return [_cast(item, v) for v in value]
    return _cast(typ, value)


# --- dict -> message --------------------------------------------------------------------------

def set_message_fields(msg, values: Mapping):
    """Set the fields of ``msg`` from a message dict (missing keys keep their defaults; unknown
    keys raise ``ValueError``; numbers are cast to the field type). Returns ``msg``."""
    if not isinstance(values, Mapping):
        raise TypeError(f"{type(msg).__name__}: expected a message dict, "
                        f"got {type(values).__name__}")
    types = dict(_fields(msg))
    for name, value in values.items():
        typ = types.get(name)
        if typ is None:
            raise ValueError(f"{type(msg).__name__} has no field {name!r}")
        if isinstance(typ, NamespacedType):
            set_message_fields(getattr(msg, name), value)
            continue
        if isinstance(typ, AbstractNestedType):
            item = typ.value_type
            if isinstance(item, NamespacedType):
                cls = _message_class(item)
                value = [set_message_fields(cls(), v) for v in value]
            else:
                value = [_cast(item, v) for v in value]
        else:
            value = _cast(typ, value)
        setattr(msg, name, value)
    return msg


def dict_to_message(values: Mapping, msg_type):
    """A new ``msg_type`` message from a message dict."""
    return set_message_fields(msg_type(), values)


def _cast(typ, value):
    if isinstance(typ, AbstractGenericString):
        return str(value)
    if isinstance(typ, BasicType):
        name = typ.typename
        if name in _FLOATS:
            return float(value)
        if name in _INTS:
            return int(value)
        if name == "boolean":
            return bool(value)
        if name == "octet":
            return bytes(value) if not isinstance(value, int) else bytes([value])
    return value


# --- the node's conversions -------------------------------------------------------------------

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
                                 f"{limits.max_vertices} vertices")
    values = message_to_dict(msg)
    if not sequence:
        values["sequence"] = []
    return scene_from_state_dict(values)


def report_to_msg(report: Report, header):
    """An rbe_msgs/StabilityReport of ``report`` with ``header`` (a std_msgs/Header or a
    header dict)."""
    from rbe_msgs.msg import StabilityReport

    if not isinstance(header, Mapping):
        header = message_to_dict(header)
    return dict_to_message(report_to_dict(report, header), StabilityReport)


__all__ = ["message_to_dict", "set_message_fields", "dict_to_message", "scene_from_msg",
           "report_to_msg"]
