"""A robot cell: the robots that place and hold blocks, by name, each with its base, reach,
payload and tool (``rbe-ros plan --cell``, the node's ``cell_file``, the ``~/plan`` goal's
``cell``).

A plan for a cell is a timeline of robot actions (:mod:`rbe_ros.analysis.timeline`); the
cell bounds it: no more robots busy than it has, each grip within its robot's reach and
payload (the tool's own weight included). Validation here covers the fields alone; what
needs the scene (a base inside a block) or a kinematics library (a URDF that loads) is
checked where those are (:func:`rbe_ros.analysis.grips.check_cell`). Every error is a
:class:`CellError` naming the field.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .scene import SceneError

class CellError(SceneError):
    """A cell file the plan cannot use; the message names the field."""


@dataclass(frozen=True)
class Tool:
    """A gripper: a box of full edge lengths ``box`` (m, tool axes) behind the tool centre
    point, the TCP at ``tcp`` (m) from the robot's flange in tool axes, and its mass (kg).
    The tool frame's z axis points from the flange through the TCP into the gripped face."""

    box: tuple[float, float, float] = (0.1, 0.1, 0.1)
    tcp: tuple[float, float, float] = (0.0, 0.0, 0.1)
    mass: float = 0.0


@dataclass(frozen=True)
class Robot:
    """One robot of a cell: ``base`` (m, world), ``reach`` (m: the largest distance from the
    base to a grip), payload (N, N m: at the flange, the tool included), its tool, and
    optionally a URDF (``urdf``, ``tip``: the flange link; ``base_yaw`` rad about z) for
    inverse kinematics."""

    name: str
    base: tuple[float, float, float]
    reach: float
    payload_force: float
    payload_torque: float
    tool: Tool = Tool()
    urdf: str = ""
    tip: str = ""
    base_yaw: float = 0.0


@dataclass(frozen=True)
class Cell:
    """The robots of a cell, by name (unique)."""

    robots: tuple[Robot, ...]

    def robot(self, name: str) -> Robot:
        for r in self.robots:
            if r.name == name:
                return r
        raise CellError(f"cell: unknown robot {name!r} (the cell has "
                        f"{', '.join(r.name for r in self.robots)})")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.robots)


def _number(raw: Mapping, key: str, where: str, *, low: float = 0.0, strict: bool = False,
            default=None) -> float:
    if key not in raw:
        if default is not None:
            return default
        raise CellError(f"{where}: missing {key!r}")
    value = raw[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or value < low or (strict and value == low):
        raise CellError(f"{where}: {key!r} must be a number {'>' if strict else '>='} {low:g}, "
                        f"got {value!r}")
    return float(value)


def _vector(raw: Mapping, key: str, where: str, default=None) -> tuple[float, float, float]:
    if key not in raw:
        if default is not None:
            return default
        raise CellError(f"{where}: missing {key!r}")
    value = raw[key]
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        arr = np.zeros(0)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise CellError(f"{where}: {key!r} must be [x, y, z] (3 finite numbers), got {value!r}")
    return tuple(float(x) for x in arr)


def _tool(raw, where: str) -> Tool:
    if raw is None:
        return Tool()
    if not isinstance(raw, Mapping):
        raise CellError(f'{where}: "tool" must be an object with "box", "tcp", "mass"')
    box = _vector(raw, "box", f"{where}.tool", Tool.box)
    if min(box) <= 0:
        raise CellError(f"{where}.tool: 'box' edges must be > 0, got {list(box)}")
    return Tool(box, _vector(raw, "tcp", f"{where}.tool", Tool.tcp),
                _number(raw, "mass", f"{where}.tool", default=0.0))


def _robot(index: int, raw) -> Robot:
    where = f"cell: robots[{index}]"
    if not isinstance(raw, Mapping):
        raise CellError(f"{where} must be an object with \"name\", \"base\", \"reach\", "
                        "\"payload_force\", \"payload_torque\"")
    name = raw.get("name")
    if not isinstance(name, str) or not name:
        raise CellError(f"{where}: 'name' must be a non-empty string, got {name!r}")
    where = f"cell: robot {name!r}"
    urdf = raw.get("urdf", "") or ""
    if not isinstance(urdf, str):
        raise CellError(f"{where}: 'urdf' must be a path, got {urdf!r}")
    tip = raw.get("tip", "") or ""
    if not isinstance(tip, str):
        raise CellError(f"{where}: 'tip' must be a link name, got {tip!r}")
    return Robot(name, _vector(raw, "base", where),
                 _number(raw, "reach", where, strict=True),
                 _number(raw, "payload_force", where), _number(raw, "payload_torque", where),
                 _tool(raw.get("tool"), where), urdf, tip,
                 _number(raw, "base_yaw", where, low=-math.inf, default=0.0))


def cell_from_dict(data) -> Cell:
    """A validated :class:`Cell` from its JSON/YAML object (raises :class:`CellError`)."""
    if not isinstance(data, Mapping) or not isinstance(data.get("robots"), list):
        raise CellError('cell: must be an object with "robots": [{"name", "base", "reach", '
                        '"payload_force", "payload_torque", "tool"}, ...]')
    robots = tuple(_robot(i, r) for i, r in enumerate(data["robots"]))
    if not robots:
        raise CellError("cell: 'robots' is empty: a plan needs at least one robot")
    seen: set[str] = set()
    for r in robots:
        if r.name in seen:
            raise CellError(f"cell: robot name {r.name!r} appears twice")
        seen.add(r.name)
    return Cell(robots)


def cell_to_dict(cell: Cell) -> dict:
    """The JSON object of ``cell`` (read back by :func:`cell_from_dict`)."""
    out = []
    for r in cell.robots:
        d = {"name": r.name, "base": list(r.base), "reach": r.reach,
             "payload_force": r.payload_force, "payload_torque": r.payload_torque,
             "tool": {"box": list(r.tool.box), "tcp": list(r.tool.tcp), "mass": r.tool.mass}}
        if r.urdf:
            d.update(urdf=r.urdf, tip=r.tip, base_yaw=r.base_yaw)
        out.append(d)
    return {"robots": out}


__all__ = ["Cell", "CellError", "Robot", "Tool", "cell_from_dict", "cell_to_dict"]
