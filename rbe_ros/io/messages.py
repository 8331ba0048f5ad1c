"""Conversions between core objects and *message dicts* (the single place that knows the layout).

A message dict is a plain nested dict/list shaped exactly like the ROS message, as
``rosidl_runtime_py.message_to_ordereddict`` gives it: field names as keys, nested messages as
dicts (``geometry_msgs/Point`` as ``{"x", "y", "z"}``), arrays as lists, numbers as Python
``float``/``int``. :mod:`rbe_ros.io.cdr` encodes them to CDR bytes (the node's reports, bags);
:mod:`rbe_ros.ros.convert` turns them into rclpy messages and back (a ``set_message_fields``
like rosidl_runtime_py's).
Nothing here imports rclpy or the generated ``rbe_msgs`` package.

Incoming dicts may omit fields: a missing field takes the ROS default (zeros, empty arrays,
identity quaternion), exactly as ``set_message_fields`` would leave it.
"""
from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ..analysis.planning import Plan, PlanProgress
from ..analysis.timeline import Timeline
from ..geometry.repair import repair_block
from ..rbe.result import NOT_COMPUTED, HoldWrench, InterfaceResult, NearContact, Report, Status
from ..scene import (BOX_FACES, Hold, Scene, SceneError, blame, box_vertices, make_block,
                     make_scene)
from .plans import PlanLimits

SOLID_PRIMITIVE_BOX = 1  # shape_msgs/SolidPrimitive.BOX
_XYZ = ("x", "y", "z")
_XYZW = ("x", "y", "z", "w")


# --- small helpers ----------------------------------------------------------------------------

# Numbers go through numpy's ``tolist`` (Python floats, the same values as ``float()`` of each
# element, in one call): a report of a 1000-block wall holds ~50k vectors.

def _vec(v, keys=_XYZ) -> dict:
    """A Point/Vector3 (or Quaternion with ``keys=_XYZW``) dict from a sequence of numbers."""
    return dict(zip(keys, np.asarray(v, dtype=float).ravel().tolist()))


def _vecs(rows) -> list[dict]:
    """Point/Vector3 dicts of the rows of an (n, 3) array."""
    return [{"x": x, "y": y, "z": z}
            for x, y, z in np.asarray(rows, dtype=float).reshape(-1, 3).tolist()]


def _floats(values) -> list[float]:
    return np.asarray(values, dtype=float).ravel().tolist()


def _field(d, key: str, default, what: str):
    """``d[key]`` with a ROS default for a missing key; ``d`` must be a mapping."""
    if not isinstance(d, Mapping):
        raise SceneError(f"{what} must be a mapping (message dict), got {type(d).__name__}")
    value = d.get(key, default)
    return default if value is None else value


def _list(d, key: str, what: str) -> list:
    value = _field(d, key, [], what)
    if isinstance(value, (str, bytes, Mapping)) or not hasattr(value, "__iter__"):
        raise SceneError(f"{what}.{key} must be a list, got {type(value).__name__}")
    return list(value)


def _number(d, key: str, what: str) -> float:
    value = _field(d, key, 0.0, what)
    try:
        return float(value)
    except (TypeError, ValueError):
        raise SceneError(f"{what}: {key} must be a number, got {value!r}") from None


def _xyz(d, what: str, keys=_XYZ, default=None) -> list:
    """Numbers of a Point/Vector3/Quaternion dict (validated later by make_block/make_scene)."""
    default = default or (0.0,) * len(keys)
    return [_field(d, k, dflt, what) for k, dflt in zip(keys, default)]


def _points(points) -> np.ndarray:
    """(n, 3) array from a list of Point/Vector3 dicts."""
    return np.array([[float(p[k]) for k in _XYZ] for p in points], dtype=float).reshape(-1, 3)


def header_dict(frame_id: str, stamp_ns: int) -> dict:
    """A std_msgs/Header dict (stamp split into sec and nanosec)."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": str(frame_id)}


def report_header(state_header: Mapping | None, frame_id: str = "world") -> dict:
    """The header of the reports answering a state with ``state_header``: its stamp, and
    its frame or ``frame_id`` when that is empty (the node's ``frame_id`` parameter)."""
    header = {"stamp": dict((state_header or {}).get("stamp") or {"sec": 0, "nanosec": 0}),
              "frame_id": str((state_header or {}).get("frame_id") or frame_id)}
    return header


def header_stamp_ns(header: Mapping) -> int:
    """Nanoseconds of a Header dict's stamp."""
    stamp = header.get("stamp") or {}
    return int(stamp.get("sec", 0)) * 1_000_000_000 + int(stamp.get("nanosec", 0))


# --- AssemblyState ----------------------------------------------------------------------------

def _fan(face) -> list[dict]:
    """Fan triangulation of a convex polygon face as shape_msgs/MeshTriangle dicts."""
    return [{"vertex_indices": [int(face[0]), int(face[i]), int(face[i + 1])]}
            for i in range(1, len(face) - 1)]


def _block_to_dict(b) -> dict:
    return {
        "id": b.id,
        "pose": {"position": _vec(b.position), "orientation": _vec(b.orientation, _XYZW)},
        "primitive": {"type": 0, "dimensions": [], "polygon": {"points": []}},
        "mesh": {"triangles": [t for f in b.faces for t in _fan(f)], "vertices": _vecs(b.vertices)},
        "density": float(b.density),
        "mass": float(b.mass),
        "support": bool(b.support),
    }


def state_to_dict(scene: Scene, frame_id: str = "world", stamp_ns: int = 0) -> dict:
    """An rbe_msgs/AssemblyState dict of ``scene``; every block is sent as a triangle mesh."""
    return {
        "header": header_dict(frame_id, stamp_ns),
        "blocks": [_block_to_dict(b) for b in scene.blocks],
        "sequence": list(scene.sequence),
        "gravity": _vec(scene.gravity),
        "holds": [_hold_to_dict(h) for h in scene.holds],
        "approach": [_vec(np.zeros(3) if d is None else d) for d in scene.approach],
    }


def _hold_to_dict(h: Hold) -> dict:
    """A Hold dict: capacities <= 0 and has_grip false stand for the check's options and the
    centroid (a hold's capacity 0, a pin grip, is sent as 0 too: the message cannot say it)."""
    return {"block": h.block, "from_step": int(h.from_step),
            "until_step": -1 if h.until_step is None else int(h.until_step),
            "max_force": float(h.max_force or 0.0), "max_torque": float(h.max_torque or 0.0),
            "grip": _vec(h.grip if h.grip is not None else (0.0, 0.0, 0.0)),
            "has_grip": h.grip is not None}


def _block_from_dict(index: int, raw):
    if not isinstance(raw, Mapping):
        raise SceneError(f"block #{index} must be a mapping (message dict), "
                         f"got {type(raw).__name__}")
    bid = raw.get("id")
    if not isinstance(bid, str) or not bid:
        raise SceneError(f"block #{index} has no id (a non-empty string)")
    where = f"block {bid!r}"
    pose = _field(raw, "pose", {}, where)
    position = _xyz(_field(pose, "position", {}, f"{where}: pose"), f"{where}: pose.position")
    orientation = _xyz(_field(pose, "orientation", {}, f"{where}: pose"),
                       f"{where}: pose.orientation", _XYZW, (0.0, 0.0, 0.0, 1.0))
    mesh = _field(raw, "mesh", {}, where)
    triangles = _list(mesh, "triangles", f"{where}: mesh")
    if triangles:
        vertices = [_xyz(p, f"{where}: mesh vertex")
                    for p in _list(mesh, "vertices", f"{where}: mesh")]
        faces = []
        for t in triangles:
            idx = _list(t, "vertex_indices", f"{where}: mesh triangle")
            if len(idx) != 3:
                raise SceneError(f"{where}: a mesh triangle needs 3 vertex indices, got {len(idx)}")
            faces.append(idx)
        if not vertices:
            raise SceneError(f"{where}: mesh has triangles but no vertices")
    else:
        prim = _field(raw, "primitive", {}, where)
        ptype = _field(prim, "type", 0, f"{where}: primitive")
        dims = _list(prim, "dimensions", f"{where}: primitive")
        if ptype != SOLID_PRIMITIVE_BOX:
            raise SceneError(f"{where}: no shape: give mesh triangles or a BOX primitive "
                             f"(type {SOLID_PRIMITIVE_BOX}), got primitive type {ptype!r}")
        try:
            size = np.asarray(dims, dtype=float)
        except (TypeError, ValueError):
            raise SceneError(f"{where}: BOX dimensions must be numbers") from None
        if size.shape != (3,) or not np.all(np.isfinite(size)) or np.any(size <= 0):
            raise SceneError(f"{where}: a BOX needs 3 positive finite dimensions (full edge "
                             f"lengths), got {dims!r}")
        vertices, faces = box_vertices(size), BOX_FACES
    block = make_block(bid, vertices, faces, position, orientation,
                       density=_number(raw, "density", where), mass=_number(raw, "mass", where),
                       support=bool(_field(raw, "support", False, where)))
    return repair_block(block) if triangles else (block, None)


def scene_from_state_dict(d) -> Scene:
    """The validated scene of an rbe_msgs/AssemblyState dict (raises :class:`SceneError`).

    Mesh blocks keep their triangles as faces (no merging of coplanar triangles here); an
    open or inconsistently wound mesh is repaired, the scene's ``warnings`` say so
    (:func:`rbe_ros.geometry.repair.repair_block`).
    The scene is named after the header frame ("assembly" when empty).
    """
    if not isinstance(d, Mapping):
        raise SceneError("an AssemblyState must be a mapping (message dict), "
                         f"got {type(d).__name__}")
    blocks, warnings = [], []
    for i, b in enumerate(_list(d, "blocks", "AssemblyState")):
        with blame(b.get("id") if isinstance(b, Mapping) else ""):
            block, warning = _block_from_dict(i, b)
        blocks.append(block)
        if warning:
            warnings.append(warning)
    sequence = _list(d, "sequence", "AssemblyState")
    if not all(isinstance(s, str) for s in sequence):
        raise SceneError("AssemblyState.sequence must be a list of block ids (strings)")
    gravity = _xyz(_field(d, "gravity", {}, "AssemblyState"), "AssemblyState.gravity")
    name = _field(_field(d, "header", {}, "AssemblyState"), "frame_id", "", "AssemblyState.header")
    holds = [_hold_from_dict(i, h) for i, h in enumerate(_list(d, "holds", "AssemblyState"))]
    # a state read without its sequence (a check of the whole) has no steps to approach
    approach = [_xyz(v, "AssemblyState.approach") for v in _list(d, "approach", "AssemblyState")
                if sequence]
    return make_scene(str(name) or "assembly", blocks, gravity, sequence,  # zero gravity: default
                      holds, approach=[v if any(v) else None for v in approach],
                      warnings=warnings)


def _hold_from_dict(index: int, raw) -> Hold:
    where = f"AssemblyState.holds[{index}]"
    block = _field(raw, "block", "", where)
    if not isinstance(block, str) or not block:
        raise SceneError(f"{where} has no block id (a non-empty string)")
    steps = []
    for key, default in (("from_step", 0), ("until_step", -1)):
        value = _field(raw, key, default, where)
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise SceneError(f"{where}: {key} must be an integer, got {value!r}")
        steps.append(int(value))
    from_step, until_step = steps
    if until_step < -1:
        raise SceneError(f"{where}: until_step must be -1 (to the end) or a step, got {until_step}")
    capacities = []
    for key in ("max_force", "max_torque"):
        value = _field(raw, key, 0.0, where)
        if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) \
                or not math.isfinite(value):
            raise SceneError(f"{where}: {key} must be a finite number, got {value!r}")
        capacities.append(float(value) if value > 0 else None)
    has_grip = _field(raw, "has_grip", False, where)
    grip = _xyz(_field(raw, "grip", {}, where), f"{where}.grip") if has_grip else None
    return Hold(block, from_step, None if until_step == -1 else until_step,
                None if grip is None else tuple(float(x) for x in grip), *capacities)


# --- BlockPoses -------------------------------------------------------------------------------

def poses_to_dict(poses, frame_id: str = "world", stamp_ns: int = 0) -> dict:
    """An rbe_msgs/BlockPoses dict of ``{id: (position, orientation)}``."""
    return {"header": header_dict(frame_id, stamp_ns), "ids": [str(i) for i in poses],
            "poses": [{"position": _vec(p), "orientation": _vec(q, _XYZW)}
                      for p, q in poses.values()]}


def poses_from_dict(d) -> dict:
    """``{id: (position, orientation)}`` of an rbe_msgs/BlockPoses dict (SceneError; the
    values are checked by :func:`rbe_ros.poses.scene_at_poses`)."""
    ids = _list(d, "ids", "BlockPoses")
    poses = _list(d, "poses", "BlockPoses")
    if len(ids) != len(poses):
        raise SceneError(f"BlockPoses has {len(ids)} ids but {len(poses)} poses")
    out = {}
    for i, (bid, pose) in enumerate(zip(ids, poses)):
        if not isinstance(bid, str) or not bid:
            raise SceneError(f"BlockPoses.ids[{i}] is not a block id (a non-empty string)")
        if bid in out:
            raise SceneError(f"BlockPoses names block {bid!r} twice")
        where = f"BlockPoses: block {bid!r}"
        out[bid] = (_xyz(_field(pose, "position", {}, where), f"{where}: position"),
                    _xyz(_field(pose, "orientation", {}, where), f"{where}: orientation",
                         _XYZW, (0.0, 0.0, 0.0, 1.0)))
    return out


# --- StabilityReport --------------------------------------------------------------------------

def _interface_to_dict(r: InterfaceResult, arrays: bool = False) -> dict:
    if arrays:      # the numpy form of rbe_ros.ros.convert: no dict per point
        vecs, floats = _rows, _array
    else:
        vecs, floats = _vecs, _floats
    normal, resultant, shear, centre = _vecs((r.normal, r.resultant, r.shear,
                                              r.centre_of_pressure))
    return {
        "block_a": r.block_a,
        "block_b": r.block_b,
        "normal": normal,
        "polygon": vecs(r.polygon),
        "normal_forces": floats(r.normal_forces),
        "tangential_forces": vecs(r.tangential_forces),
        "resultant_force": resultant,
        "normal_resultant": float(r.normal_resultant),
        "shear_resultant": shear,
        "centre_of_pressure": centre,
        "torque": float(r.torque),
        "kern": vecs(r.kern),
        "friction_ratio": float(r.friction_ratio),
        "tension": bool(r.tension),
        "friction_exceeded": bool(r.friction_exceeded),
    }


def _array(values) -> np.ndarray:
    return np.asarray(values, dtype=float).ravel()


def _rows(values) -> np.ndarray:
    return np.asarray(values, dtype=float).reshape(-1, 3)


def _interface_from_dict(d: Mapping) -> InterfaceResult:
    return InterfaceResult(
        block_a=d["block_a"], block_b=d["block_b"],
        normal=_points([d["normal"]])[0],
        polygon=_points(d["polygon"]),
        normal_forces=np.asarray(d["normal_forces"], dtype=float).reshape(-1),
        tangential_forces=_points(d["tangential_forces"]),
        resultant=_points([d["resultant_force"]])[0],
        normal_resultant=float(d["normal_resultant"]),
        shear=_points([d["shear_resultant"]])[0],
        centre_of_pressure=_points([d["centre_of_pressure"]])[0],
        torque=float(d["torque"]),
        kern=_points(d["kern"]),
        friction_ratio=float(d["friction_ratio"]),
        tension=bool(d["tension"]),
        friction_exceeded=bool(d["friction_exceeded"]),
    )


def report_to_dict(report: Report, header: dict, *, arrays: bool = False) -> dict:
    """An rbe_msgs/StabilityReport dict of ``report`` (``header``: see :func:`header_dict`).

    ``arrays=True``: the same dict, but each sequence of Points/Vector3s as an (n, 3) float
    array and each float64[] as a 1-D float array: the form that :mod:`rbe_ros.io.cdr` (the
    node's reports) and :func:`rbe_ros.ros.convert.dict_to_message` take without a dict per
    point. Not for comparisons.
    """
    return {
        "header": header,
        "step_index": int(report.step_index),
        "block_placed": str(report.block_placed),
        "stable": bool(report.stable),
        "status": int(report.status),
        "max_tension": float(report.max_tension),
        "worst_friction_ratio": float(report.worst_friction_ratio),
        "solve_time": float(report.solve_time),
        "num_blocks": int(report.num_blocks),
        "interfaces": [_interface_to_dict(r, arrays) for r in report.interfaces],
        "unstable_blocks": [str(b) for b in report.unstable_blocks],
        "held_blocks": [str(b) for b in report.held_blocks],
        "suggested_holds": [str(b) for b in report.suggested_holds],
        "message": str(report.message),
        "model": str(report.model),
        "dropped_states": int(report.dropped_states),
        "near_contacts": [{"block_a": str(c.block_a), "block_b": str(c.block_b),
                           "gap": float(c.gap), "overlap_area": float(c.overlap_area)}
                          for c in report.near_contacts],
        "verdict_sensitive": bool(report.verdict_sensitive),
        "margin_g": float(report.margin_g),
        "margin_direction": _vec(report.margin_direction),
        "insertable": bool(report.insertable),
        "insertion_direction": _vec(report.insertion_direction),
        "hold_wrenches": [{"block": str(w.block), "force": _vec(w.force),
                           "torque": _vec(w.torque), "grip_point": _vec(w.grip_point),
                           "utilisation": float(w.utilisation)} for w in report.hold_wrenches],
    }


def report_json(report: Report, header: dict | None = None) -> dict:
    """The message dict of ``report`` as the CLI prints it: the same names and structure as
    the StabilityReport, made by :func:`report_to_dict` (header: frame "world", stamp 0,
    unless given), with non-finite numbers as null (JSON has no infinity)."""
    return json_safe(report_to_dict(report, header or header_dict("world", 0)))


def json_safe(value):
    """``value`` (dicts, lists, numbers) with every non-finite float replaced by None."""
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list):
        return [json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def report_from_dict(d: Mapping) -> Report:
    """The :class:`Report` of a StabilityReport dict (header dropped; numpy arrays restored)."""
    return Report(
        status=Status(int(d["status"])), message=str(d["message"]),
        max_tension=float(d["max_tension"]), worst_friction_ratio=float(d["worst_friction_ratio"]),
        solve_time=float(d["solve_time"]), num_blocks=int(d["num_blocks"]),
        interfaces=[_interface_from_dict(i) for i in d["interfaces"]],
        unstable_blocks=[str(b) for b in d["unstable_blocks"]],
        step_index=int(d["step_index"]), block_placed=str(d["block_placed"]),
        held_blocks=[str(b) for b in d.get("held_blocks", [])],
        suggested_holds=[str(b) for b in d.get("suggested_holds", [])],
        model=str(d.get("model", "full")),
        dropped_states=int(d.get("dropped_states", 0)),
        near_contacts=[NearContact(str(c["block_a"]), str(c["block_b"]), float(c["gap"]),
                                   float(c["overlap_area"])) for c in d.get("near_contacts", [])],
        verdict_sensitive=bool(d.get("verdict_sensitive", False)),
        margin_g=float(d.get("margin_g", NOT_COMPUTED)),
        margin_direction=np.array(_xyz(d.get("margin_direction", {}), "margin_direction"),
                                  dtype=float),
        insertable=bool(d.get("insertable", True)),
        insertion_direction=np.array(_xyz(d.get("insertion_direction", {}),
                                          "insertion_direction"), dtype=float),
        hold_wrenches=[HoldWrench(str(w["block"]), *(np.array(_xyz(w[k], k), dtype=float)
                                                     for k in ("force", "torque", "grip_point")),
                                  float(w["utilisation"])) for w in d.get("hold_wrenches", [])],
    )


# --- PlanSequence action ---------------------------------------------------------------------

def plan_goal_to_dict(state: dict, limits: PlanLimits) -> dict:
    """An rbe_msgs/action/PlanSequence goal dict: the AssemblyState dict ``state`` to plan
    and the request's limits."""
    return {"assembly": state, "max_held": int(limits.max_held),
            "beam": int(limits.beam), "hold_force_max": float(limits.hold_force_max),
            "hold_torque_max": float(limits.hold_torque_max),
            "time_limit": float(limits.time_limit),
            "search_budget": int(limits.search_budget), "cell": str(limits.cell),
            "prefer": str(limits.prefer), "min_margin": float(limits.min_margin),
            "robust_samples": int(limits.robust_samples)}


def plan_goal_from_dict(d: Mapping) -> tuple[dict, PlanLimits]:
    """The AssemblyState dict and the limits of a PlanSequence goal dict (``beam`` 0: the
    default, 1); the limits are checked where they are used
    (:func:`rbe_ros.io.plans.plan_state`)."""
    return dict(d.get("assembly", {})), PlanLimits(
        int(d.get("max_held", 0)), int(d.get("beam", 0)) or 1,
        hold_force_max=float(d.get("hold_force_max", 0.0)),
        hold_torque_max=float(d.get("hold_torque_max", 0.0)),
        time_limit=float(d.get("time_limit", 0.0)),
        search_budget=int(d.get("search_budget", 0)), cell=str(d.get("cell", "") or ""),
        prefer=str(d.get("prefer", "")) or "holds", min_margin=float(d.get("min_margin", 0.0)),
        robust_samples=int(d.get("robust_samples", 0)))


def plan_result_to_dict(plan: Plan, header: dict) -> dict:
    """An rbe_msgs/action/PlanSequence result dict of ``plan``; ``header`` (of the goal's
    assembly, :func:`report_header`) is that of its reports and of the planned assembly."""
    state = state_to_dict(plan.scene, header["frame_id"], header_stamp_ns(header)) \
        if plan.scene is not None else {"header": header, "blocks": [], "sequence": [],
                                        "gravity": _vec((0.0, 0.0, 0.0)), "holds": []}
    return {"feasible": bool(plan.feasible), "message": str(plan.message),
            "order": [str(b) for b in plan.order],
            "holds": state.get("holds", []),
            "reports": [report_to_dict(r, header) for r in plan.reports],
            "failed_step": int(plan.failed_step), "plan": state,
            "timeline": timeline_to_dicts(plan.timeline, header),
            "robots": list(plan.timeline.robots) if plan.timeline is not None else [],
            **weakest_step(plan)}


def _pose_stamped(header: dict, frame=None) -> dict:
    """A geometry_msgs/PoseStamped dict of a grip frame (None: the identity)."""
    point, quat = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)) if frame is None \
        else (frame.point, frame.quaternion)
    return {"header": header, "pose": {"position": _vec(point),
                                       "orientation": _vec(quat, _XYZW)}}


def _wrench(force=None, torque=None) -> dict:
    """A geometry_msgs/Wrench dict (None: zero)."""
    return {"force": _vec(np.zeros(3) if force is None else force),
            "torque": _vec(np.zeros(3) if torque is None else torque)}


def timeline_to_dicts(timeline: Timeline | None, header: dict) -> list[dict]:
    """rbe_msgs/RobotAction dicts of a plan's timeline (empty without one): each action's
    TCP frames as PoseStamped (pre-grip and approach for a place only), the acting robot's
    wrench on the block (world axes) and with its tool's weight (tool axes), the check of
    the state after it."""
    out = []
    for a in timeline.actions if timeline is not None else ():
        frames, w = a.frames(), a.wrench
        report = a.report
        out.append({
            "action": a.action, "robot": a.robot, "block": a.block, "step": int(a.step),
            "grip": _pose_stamped(header, frames["grip"]),
            "pre_grip": _pose_stamped(header, frames.get("pre_grip")),
            "approach": _pose_stamped(header, frames.get("approach")),
            "wrench_world": _wrench(*(() if w is None else (w.force_world, w.torque_world))),
            "wrench_tool": _wrench(*(() if w is None else (w.force_tool, w.torque_tool))),
            "stable": bool(report is not None and report.stable),
            "status": int(report.status) if report is not None else int(Status.INVALID_INPUT),
            "message": report.message if report is not None else "not checked"})
    return out


def weakest_step(plan: Plan) -> dict:
    """The PlanSequence result fields of ``plan``'s weakest step (-1: no margin computed)."""
    w = plan.weakest
    return {"weakest_step": -1 if w is None else int(w.step_index),
            "weakest_block": "" if w is None else str(w.block_placed),
            "weakest_margin_g": NOT_COMPUTED if w is None else float(w.margin_g)}


def plan_feedback_to_dict(progress: PlanProgress) -> dict:
    """An rbe_msgs/action/PlanSequence feedback dict of a plan's progress."""
    return {"placed": int(progress.placed), "total": int(progress.total),
            "step": int(progress.step), "block": str(progress.block),
            "held": [str(b) for b in progress.held], "elapsed": float(progress.elapsed),
            "checks": int(progress.checks), "remaining": float(progress.estimate)}


# --- plan execution (~/execution, ~/plan_update) -----------------------------------------------

def lookahead_step_to_dict(step) -> dict:
    """An rbe_msgs/LookaheadStep dict of a step checked ahead
    (:class:`rbe_ros.analysis.lookahead.StepAhead`)."""
    return {"step": int(step.step), "block": str(step.block), "stable": bool(step.stable),
            "status": int(step.status), "insertable": bool(step.insertable),
            "margin_g": float(step.margin_g), "max_hold_force": float(step.max_hold_force),
            "message": str(step.message)}


def execution_to_dict(header: dict, *, active: bool, current_step: int, total_steps: int,
                      as_built: dict | None, lookahead: list[dict], first_failing_step: int,
                      message: str) -> dict:
    """An rbe_msgs/ExecutionState dict (``as_built``: a StabilityReport dict, None: empty)."""
    return {"header": header, "active": bool(active), "current_step": int(current_step),
            "total_steps": int(total_steps),
            "as_built": as_built if as_built is not None else report_to_dict(
                Report(Status.INVALID_INPUT, ""), header),
            "lookahead": list(lookahead), "first_failing_step": int(first_failing_step),
            "message": str(message)}


def plan_update_to_dict(header: dict, *, reason: str, changed_step: int, feasible: bool,
                        repair: str, order, holds, message: str,
                        timeline: list[dict] | None = None) -> dict:
    """An rbe_msgs/PlanUpdate dict: the repaired plan (whole order, holds by step; a cell's
    timeline, RobotAction dicts)."""
    return {"header": header, "reason": str(reason), "changed_step": int(changed_step),
            "feasible": bool(feasible), "repair": str(repair),
            "order": [str(b) for b in order], "holds": [_hold_to_dict(h) for h in holds],
            "timeline": list(timeline or []), "message": str(message)}


__all__ = ["SOLID_PRIMITIVE_BOX", "execution_to_dict", "header_dict", "header_stamp_ns",
           "json_safe", "lookahead_step_to_dict", "plan_feedback_to_dict", "plan_goal_from_dict",
           "plan_goal_to_dict", "plan_result_to_dict", "plan_update_to_dict", "poses_from_dict",
           "poses_to_dict", "report_from_dict", "report_header", "report_json", "report_to_dict",
           "scene_from_state_dict", "state_to_dict", "timeline_to_dicts"]
