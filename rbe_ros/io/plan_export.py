"""What ``rbe-ros plan -o`` writes and ``rbe-ros check --timeline`` reads back.

The planned scene keeps the capacities it was planned under: each hold's ``max_force`` and
``max_torque`` (the options' hold capacities; for a cell, its robot's payload less its
tool's share, and the grip its robot takes: :func:`rbe_ros.analysis.timeline.
scene_with_grips`). Planned for a cell,
the file also holds the cell (``"cell"``, URDF paths resolved) and the timeline
(``"timeline"``: rbe_msgs/RobotAction dicts, :func:`rbe_ros.io.messages.timeline_to_dicts`),
so that the timeline is re-checked from the file alone (:func:`read_timeline`).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from ..analysis.grips import GripFrame
from ..analysis.options import CheckOptions
from ..analysis.planning import Plan
from ..cell import Cell, CellError, cell_from_dict, cell_to_dict
from ..scene import Scene
from .messages import header_dict, timeline_to_dicts
from .scene_json import read_json, scene_to_dict


def planned_scene(plan: Plan, options: CheckOptions) -> Scene | None:
    """``plan``'s scene, each hold with the capacities it was planned under (its own: a
    cell's robot; else the options')."""
    scene = plan.scene
    if scene is None:
        return None
    return replace(scene, holds=tuple(
        replace(h, max_force=_finite(options.hold_force_max if h.max_force is None
                                     else h.max_force),
                max_torque=_finite(options.hold_torque_max if h.max_torque is None
                                   else h.max_torque))
        for h in scene.holds))


def _finite(value) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def plan_export(plan: Plan, options: CheckOptions, frame_id: str = "world") -> dict:
    """The planned scene's JSON (capacities kept) and, for a cell, ``"cell"``,
    ``"robots"`` and ``"timeline"``."""
    out = scene_to_dict(planned_scene(plan, options))
    if plan.timeline is not None:
        out["cell"] = cell_to_dict(plan.timeline.cell)
        out["robots"] = list(plan.timeline.robots)
        out["timeline"] = timeline_to_dicts(plan.timeline, header_dict(frame_id, 0))
    return out


@dataclass(frozen=True)
class ExportedAction:
    """One action of an exported timeline, as :func:`rbe_ros.analysis.timeline.
    recheck_timeline` reads it, and the state's verdict the plan recorded."""

    action: str
    robot: str
    block: str
    step: int
    grip: GripFrame
    stable: bool


def _pose(d: Mapping, what: str) -> tuple[np.ndarray, np.ndarray]:
    try:
        p, q = d["pose"]["position"], d["pose"]["orientation"]
        point = np.array([p["x"], p["y"], p["z"]], dtype=float)
        quat = np.array([q["x"], q["y"], q["z"], q["w"]], dtype=float)
    except (KeyError, TypeError, ValueError):
        raise CellError(f"timeline: {what} must be a PoseStamped dict") from None
    if not (np.all(np.isfinite(point)) and abs(np.linalg.norm(quat) - 1.0) < 1e-6):
        raise CellError(f"timeline: {what} must have a finite position and a unit quaternion")
    return point, Rotation.from_quat(quat).as_matrix()


def read_timeline(data: Mapping) -> tuple[Cell, list[ExportedAction]]:
    """The cell and the actions of a file ``rbe-ros plan --cell -o`` wrote (CellError naming
    the field when it has none or they are malformed)."""
    if "timeline" not in data or "cell" not in data:
        raise CellError('timeline: the file has no "timeline" and "cell" (write it with '
                        "rbe-ros plan --cell CELL -o FILE)")
    cell = cell_from_dict(data["cell"])
    raw = data["timeline"]
    if not isinstance(raw, list):
        raise CellError('timeline: "timeline" must be a list of actions')
    out = []
    for i, a in enumerate(raw):
        what = f"timeline[{i}]"
        if not isinstance(a, Mapping) or a.get("action") not in ("place", "hold", "release"):
            raise CellError(f'{what}: "action" must be "place", "hold" or "release"')
        cell.robot(str(a.get("robot", "")))
        point, rotation = _pose(a.get("grip", {}), f"{what}.grip")
        out.append(ExportedAction(a["action"], str(a["robot"]), str(a.get("block", "")),
                                  int(a.get("step", 0)),
                                  GripFrame(str(a.get("block", "")), -1, point, rotation,
                                            -rotation[:, 2]),
                                  bool(a.get("stable", False))))
    return cell, out


def plan_cell(path) -> Cell | None:
    """The cell the planned scene file at ``path`` was planned for (``rbe-ros plan --cell
    -o`` writes it beside its timeline), None for a file without one (CellError naming the
    field when it is malformed)."""
    doc, _ = read_json(path)
    if not isinstance(doc, Mapping) or "cell" not in doc or "timeline" not in doc:
        return None
    return read_timeline(doc)[0]


__all__ = ["ExportedAction", "plan_cell", "plan_export", "planned_scene", "read_timeline"]
