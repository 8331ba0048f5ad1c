"""The 3D view of a report as a visualization_msgs/MarkerArray message dict (ROS-free).

One builder for every consumer: the node publishes and records these dicts as CDR
(:mod:`rbe_ros.cdr`), the CLI and ``rbe-ros replay`` record them in bags beside states and
reports (topic ``/rbe_node/markers``), so RViz and Foxglove's 3D panel draw the same thing.
Points and colours are (n, 3) and (n, 4) numpy arrays, which :mod:`rbe_ros.cdr` writes in one
``tobytes``; every Marker dict is complete (all fields), so no slow path is taken.

Namespaces (after a DELETEALL, so the markers of an earlier report vanish):

* ``blocks``: every present block as a translucent TRIANGLE_LIST of its mesh (supports grey,
  stable blocks neutral, the block just placed highlighted, held blocks marked, unstable
  blocks red, on INVALID_INPUT the blocks at fault magenta): one marker per block, ``text``
  its id, up to :data:`BLOCK_MARKER_LIMIT` present blocks; beyond that one marker per colour
  (``text`` the role), so a 1000-block wall stays a few markers;
* ``forces``: LINE_LISTs, one segment per interface vertex from the vertex along the force
  block_a exerts on block_b there, length proportional to its magnitude (the largest is
  ``max_length``); id 0 compression (green), id 1 tension (red);
* ``interfaces``: LINE_LISTs of the closed contact polygons; id 0 plain (grey), 1 friction
  exceeded (orange), 2 tension (red); ``kerns``: a LINE_LIST of the kern outlines (blue). In
  aggregated scenes only the interfaces in tension or over friction get their outline and
  kern (the force segments' feet still mark every polygon), which keeps the markers of a
  1000-block wall step under 2 MB;
* ``insertion``: an ARROW along the placed block's insertion direction, ending at its
  centre, one and a half times its extent long (none when it has no direction);
* ``holds``: one ARROW per held block with a robot's wrench, from its grip point along the
  force on the block (the largest hold force 0.3 times the assembly's size long; id: the
  hold's index in the report), amber, red when it exceeds the capacity (utilisation > 1);
* ``text``: a TEXT_VIEW_FACING above the assembly: step, block, verdict and the reason.

A cell's timeline (:func:`cell_markers`, the state after one action): ``robots``, a CYLINDER
at each robot's base and its name (``robot_names``); ``grippers``, a CUBE of each busy
robot's gripper box at its grip; ``robot_wrenches``, the acting robot's force on its block
as an ARROW from the grip (orange when it pushes into the face, violet when it pulls) and a
TEXT_VIEW_FACING with robot, block, force and torque.

Nothing here imports rclpy.
"""
from __future__ import annotations

import threading
import weakref
from collections.abc import Mapping, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from ..analysis.grips import GripFrame, tool_box_pose
from ..analysis.options import CheckOptions
from ..analysis.steps import final_state, sequence_step, step_count
from ..analysis.validate import validated_assembly
from ..cell import Cell, Robot
from ..rbe.result import Report, Status
from ..scene import BOX_FACES, Scene, SceneError, box_vertices
from .messages import SOLID_PRIMITIVE_BOX, report_from_dict, scene_from_state_dict

#: Marker types and actions (visualization_msgs/Marker constants).
ARROW, CUBE, CYLINDER, LINE_LIST, TRIANGLE_LIST, TEXT_VIEW_FACING = 0, 1, 3, 5, 11, 9
ADD, DELETEALL = 0, 3
#: Topic of the markers in bags, the name the node publishes them under.
MARKER_TOPIC = "/rbe_node/markers"
MARKER_TYPE = "visualization_msgs/msg/MarkerArray"
#: Up to this many present blocks, one marker per block; beyond, one per colour.
BLOCK_MARKER_LIMIT = 200

#: Colours (r, g, b, a) of the blocks by role, in the order of ``ROLES``.
ROLES = ("support", "stable", "placed", "held", "unstable", "fault")
ROLE_COLOURS = {
    "support": (0.55, 0.55, 0.55, 0.9),
    "stable": (0.85, 0.80, 0.68, 0.35),
    "placed": (0.15, 0.55, 1.0, 0.55),
    "held": (0.95, 0.80, 0.10, 0.55),
    "unstable": (1.0, 0.05, 0.05, 0.55),
    "fault": (1.0, 0.0, 1.0, 0.7),
}
COMPRESSION = (0.1, 0.75, 0.2, 1.0)
TENSION = (0.9, 0.1, 0.1, 1.0)
INTERFACE_COLOURS = ((0.8, 0.8, 0.8, 1.0), (1.0, 0.55, 0.0, 1.0), (0.9, 0.1, 0.1, 1.0))
KERN = (0.2, 0.4, 1.0, 1.0)
APPROACH = (0.15, 0.55, 1.0, 1.0)
TEXT = (1.0, 1.0, 1.0, 1.0)


# --- block meshes ------------------------------------------------------------------------------

class Meshes:
    """World-frame triangles of blocks: ``triangles[start[i]:end[i]]`` are block ``ids[i]``'s
    (fan-triangulated faces, (t, 3, 3) m)."""

    def __init__(self, ids: Sequence[str], per_block: Sequence[np.ndarray]):
        self.ids = tuple(ids)
        self.index = {b: i for i, b in enumerate(self.ids)}
        counts = np.array([len(t) for t in per_block], dtype=int)
        self.end = np.cumsum(counts)
        self.start = self.end - counts
        self.triangles = (np.concatenate(per_block) if len(per_block)
                          else np.empty((0, 3, 3)))

    def of(self, ids) -> np.ndarray:
        """Triangle vertices of the blocks ``ids`` (known ones, in that order), (3t, 3)."""
        parts = [self.triangles[self.start[i]:self.end[i]]
                 for i in (self.index[b] for b in ids if b in self.index)]
        return np.concatenate(parts).reshape(-1, 3) if parts else np.empty((0, 3))


def _fan(faces) -> list[int]:
    return [i for f in faces for k in range(1, len(f) - 1) for i in (f[0], f[k], f[k + 1])]


def scene_meshes(scene: Scene) -> Meshes:
    """The meshes of a validated scene's blocks (cached for the last scene asked)."""
    with _CACHE_LOCK:
        ref, meshes = _CACHE
        if ref is not None and ref() is scene:
            return meshes
    per_block = []
    for b in scene.blocks:
        world = Rotation.from_quat(b.orientation).apply(b.vertices) + b.position
        per_block.append(world[_fan(b.faces)].reshape(-1, 3, 3))
    meshes = Meshes([b.id for b in scene.blocks], per_block)
    with _CACHE_LOCK:
        _CACHE[:] = [weakref.ref(scene), meshes]
    return meshes


_CACHE_LOCK = threading.Lock()
_CACHE: list = [None, None]


def state_meshes(state: Mapping, max_blocks: int = 5000, max_vertices: int = 10000) -> Meshes:
    """Best-effort meshes of an AssemblyState dict that may be invalid (to show what is
    wrong): mesh triangles or a BOX primitive, posed; triangles with an index out of range or
    a non-finite vertex are left out, so is everything beyond the block and vertex limits."""
    ids, per_block = [], []
    for raw in list(state.get("blocks") or [])[:max_blocks]:
        try:
            pose = raw.get("pose") or {}
            p, q = pose.get("position") or {}, pose.get("orientation") or {}
            position = np.array([float(p.get(k, 0.0)) for k in "xyz"])
            quat = np.array([float(q.get(k, d)) for k, d in zip("xyzw", (0, 0, 0, 1))])
            mesh = raw.get("mesh") or {}
            tris = mesh.get("triangles") or []
            if tris:
                vertices = np.array([[float(v[k]) for k in "xyz"]
                                     for v in (mesh.get("vertices") or [])[:max_vertices]])
                faces = [list(t["vertex_indices"]) for t in tris]
            else:
                prim = raw.get("primitive") or {}
                if prim.get("type") != SOLID_PRIMITIVE_BOX:
                    continue
                vertices, faces = box_vertices(np.asarray(prim["dimensions"], float)), BOX_FACES
            norm = np.linalg.norm(quat)
            rot = Rotation.from_quat(quat / norm) if np.isfinite(norm) and norm > 0 \
                else Rotation.identity()
            world = rot.apply(vertices.reshape(-1, 3)) + position
            idx = np.array(_fan(faces), dtype=int).reshape(-1, 3)
            idx = idx[np.all((idx >= 0) & (idx < len(world)), axis=1)]
            t = world[idx]
            t = t[np.all(np.isfinite(t), axis=(1, 2))]
        except (TypeError, ValueError, KeyError, AttributeError, IndexError):
            continue
        ids.append(str(raw.get("id", "")))
        per_block.append(t)
    return Meshes(ids, per_block)


# --- roles ---------------------------------------------------------------------------------------

def step_roles(scene: Scene, report: Report) -> dict[str, str]:
    """Role of every block present at the report's step (its ``step_index``; -1: the
    assembly as a whole), in scene order: support, stable, placed, held or unstable."""
    if report.step_index >= 0:
        step = sequence_step(scene, min(report.step_index, step_count(scene) - 1))
        present, held = step.present, step.held
    else:
        present, held = final_state(scene)
    supports = {b.id for b in scene.blocks if b.support}
    unstable, held = set(report.unstable_blocks), set(held) | set(report.held_blocks)
    roles = {}
    for bid in present:
        roles[bid] = ("support" if bid in supports else "held" if bid in held
                      else "unstable" if bid in unstable
                      else "placed" if bid == report.block_placed else "stable")
    return roles


def fault_roles(meshes: Meshes, fault: Sequence[str]) -> dict[str, str]:
    """Roles of the blocks of an invalid state: those at fault, the others stable."""
    bad = set(fault)
    return {bid: "fault" if bid in bad else "stable" for bid in meshes.ids}


# --- markers ------------------------------------------------------------------------------------

def _marker(header: Mapping, ns: str, marker_id: int, kind: int, colour, *,
            points=None, colors=None, scale=(1.0, 1.0, 1.0), position=(0.0, 0.0, 0.0),
            text: str = "", action: int = ADD, orientation=(0.0, 0.0, 0.0, 1.0)) -> dict:
    """A complete visualization_msgs/Marker dict."""
    empty_header = {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""}
    return {
        "header": header, "ns": ns, "id": int(marker_id), "type": int(kind),
        "action": int(action),
        "pose": {"position": dict(zip("xyz", map(float, position))),
                 "orientation": dict(zip("xyzw", map(float, orientation)))},
        "scale": dict(zip("xyz", map(float, scale))),
        "color": dict(zip("rgba", map(float, colour))),
        "lifetime": {"sec": 0, "nanosec": 0}, "frame_locked": False,
        "points": np.empty((0, 3)) if points is None else np.asarray(points, dtype=float),
        "colors": np.empty((0, 4), np.float32) if colors is None else colors,
        "texture_resource": "", "texture": {"header": empty_header, "format": "",
                                            "data": np.empty(0, np.uint8)},
        "uv_coordinates": np.empty((0, 2), np.float32), "text": text, "mesh_resource": "",
        "mesh_file": {"filename": "", "data": np.empty(0, np.uint8)},
        "mesh_use_embedded_materials": False,
    }


def _rows(a) -> np.ndarray:
    return np.asarray(a, dtype=float).reshape(-1, 3)


def _edges(counts) -> np.ndarray:
    """Indices of the two ends of each edge of closed outlines of polygons of ``counts``
    vertices, stored one after another (a 2-gon is one edge, fewer vertices none), (2e,)."""
    counts = np.asarray(counts, dtype=int)
    last = np.cumsum(counts) - 1
    first = last - counts + 1
    owner = np.repeat(np.arange(len(counts)), counts)
    start = np.arange(int(counts.sum()))
    end = start + 1
    end[last[counts > 0]] = first[counts > 0]
    keep = counts[owner] >= 2
    keep[last[counts == 2]] = False
    return np.stack([start[keep], end[keep]], axis=1).reshape(-1)


def _outlines(polygons: list[np.ndarray]) -> np.ndarray:
    """LINE_LIST points of the closed outlines of ``polygons``."""
    if not polygons:
        return np.empty((0, 3))
    return np.concatenate(polygons)[_edges([len(p) for p in polygons])]


def text_of(report: Report) -> str:
    """The caption: step and block, verdict, reason."""
    where = f"step {report.step_index} ({report.block_placed or 'release'}): " \
        if report.step_index >= 0 else ""
    return f"{where}{report.status.name}\n{report.message}"


def line_markers(report: Report, header: Mapping, *, outlines_of_all: bool = True,
                 max_length: float | None = None, tension_tol: float = 1e-5) -> list[dict]:
    """The LINE_LIST markers of ``report``: forces, interface outlines and kerns (see the
    module docstring; ``outlines_of_all=False``: only of interfaces in tension or over
    friction)."""
    markers: list[dict] = []
    interfaces = list(report.interfaces)
    polygons = [_rows(r.polygon) for r in interfaces]
    if interfaces:
        vertices = np.concatenate(polygons)
        counts = [len(p) for p in polygons]
        normal_forces = np.concatenate([np.asarray(r.normal_forces, float).reshape(-1)
                                        for r in interfaces])
        normals = np.repeat(_rows([r.normal for r in interfaces]), counts, axis=0)
        forces = normal_forces[:, None] * normals + np.concatenate(
            [_rows(r.tangential_forces) for r in interfaces])
        f_ref = float(np.linalg.norm(forces, axis=1).max(initial=0.0))
        if max_length is None:
            extent = max((float(np.ptp(p, axis=0).max()) for p in polygons if len(p)),
                         default=0.0)
            max_length = max(0.5 * extent, 0.05)
        scale = max_length / f_ref if f_ref > 0 else 0.0
        ends = vertices + scale * forces
        tension = normal_forces < -tension_tol * f_ref
        width = 0.05 * max_length
        for k, (mask, colour) in enumerate(((~tension, COMPRESSION), (tension, TENSION))):
            if mask.any():
                segments = np.stack([vertices[mask], ends[mask]], axis=1).reshape(-1, 3)
                markers.append(_marker(header, "forces", k, LINE_LIST, colour,
                                       points=segments, scale=(width, 0, 0)))
        kind = [2 if r.tension else 1 if r.friction_exceeded else 0 for r in interfaces]
        shown = [k > 0 or outlines_of_all for k in kind]
        line = 0.01 * max_length
        for k, colour in enumerate(INTERFACE_COLOURS):
            outline = _outlines([p for p, kk, s in zip(polygons, kind, shown) if kk == k and s])
            if len(outline):
                markers.append(_marker(header, "interfaces", k, LINE_LIST, colour,
                                       points=outline, scale=(2 * line, 0, 0)))
        kerns = _outlines([_rows(r.kern) for r, s in zip(interfaces, shown) if s])
        if len(kerns):
            markers.append(_marker(header, "kerns", 0, LINE_LIST, KERN, points=kerns,
                                   scale=(line, 0, 0)))
    return markers


def approach_markers(meshes: Meshes, report: Report, header: Mapping) -> list[dict]:
    """The ARROW of the placed block's insertion direction (none without one)."""
    d = np.asarray(report.insertion_direction, dtype=float)
    if report.block_placed not in meshes.index or not np.any(d):
        return []
    vertices = meshes.of([report.block_placed]).reshape(-1, 3)
    centre = vertices.mean(axis=0)
    extent = float(np.ptp(vertices, axis=0).max())
    return [_marker(header, "insertion", 0, ARROW, APPROACH,
                    points=[centre - 1.5 * extent * d, centre],
                    scale=(0.06 * extent, 0.15 * extent, 0.25 * extent))]


def report_markers(meshes: Meshes, roles: Mapping[str, str], report: Report, header: Mapping,
                   *, max_length: float | None = None, tension_tol: float = 1e-5) -> dict:
    """The visualization_msgs/MarkerArray dict of ``report``: the blocks of ``roles`` (id ->
    role, present blocks in order) drawn from ``meshes``, the forces, interfaces and kerns of
    the report, and its caption (``header``: a std_msgs/Header dict).

    ``max_length``: m, the segment of the largest vertex force (default: half the largest
    interface polygon extent, at least 0.05 m).
    """
    header = dict(header)
    markers = [_marker(header, "", 0, TRIANGLE_LIST, (0, 0, 0, 0), action=DELETEALL)]
    aggregate = len(roles) > BLOCK_MARKER_LIMIT
    if aggregate:
        for k, role in enumerate(ROLES):
            ids = [b for b, r in roles.items() if r == role]
            if ids:
                markers.append(_marker(header, "blocks", k, TRIANGLE_LIST, ROLE_COLOURS[role],
                                       points=meshes.of(ids), text=role))
    else:
        for bid, role in roles.items():
            if bid in meshes.index:
                markers.append(_marker(header, "blocks", meshes.index[bid], TRIANGLE_LIST,
                                       ROLE_COLOURS[role], points=meshes.of([bid]), text=bid))

    markers += line_markers(report, header, outlines_of_all=not aggregate,
                            max_length=max_length, tension_tol=tension_tol)
    markers += approach_markers(meshes, report, header)
    drawn = meshes.of(list(roles))
    if len(drawn):
        lo, hi = drawn.min(axis=0), drawn.max(axis=0)
        size = float(np.max(hi - lo))
        position = ((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, hi[2] + 0.15 * size)
    else:
        size, position = 1.0, (0.0, 0.0, 1.0)
    markers += hold_markers(report, header, 0.3 * size)
    markers.append(_marker(header, "text", 0, TEXT_VIEW_FACING, TEXT, position=position,
                           scale=(0, 0, max(0.04 * size, 0.02)), text=text_of(report)))
    return {"markers": markers}


#: Colours of the hold arrows: within the capacity, beyond it.
HOLD_COLOURS = ((1.0, 0.65, 0.0, 1.0), (1.0, 0.05, 0.05, 1.0))


def hold_markers(report: Report, header: Mapping, length: float) -> list[dict]:
    """An ARROW per hold wrench of ``report`` from its grip along its force, the largest
    ``length`` m long (see the module docstring)."""
    forces = [np.asarray(w.force, dtype=float) for w in report.hold_wrenches]
    largest = max((float(np.linalg.norm(f)) for f in forces), default=0.0)
    out = []
    for k, (w, f) in enumerate(zip(report.hold_wrenches, forces)):
        start = np.asarray(w.grip_point, dtype=float)
        end = start + (length / largest * f if largest > 0 else 0.0)
        out.append(_marker(header, "holds", k, ARROW, HOLD_COLOURS[w.utilisation > 1.0],
                           points=np.stack([start, end]),
                           scale=(0.04 * length, 0.08 * length, 0.12 * length)))
    return out


#: Colours of a cell's markers: robot bases, gripper boxes, a robot's force pushing into
#: the face it grips and pulling from it.
ROBOT, GRIPPER = (0.3, 0.3, 0.35, 1.0), (0.2, 0.6, 0.9, 0.6)
PUSH, PULL = (1.0, 0.5, 0.0, 1.0), (0.6, 0.2, 0.9, 1.0)

#: What the colour of each line and arrow means (the HTML view's legend). An interface
#: outline in tension has the tension colour.
LINE_LEGEND = (("compression", COMPRESSION), ("tension", TENSION),
               ("interface", INTERFACE_COLOURS[0]), ("friction exceeded", INTERFACE_COLOURS[1]),
               ("kern", KERN), ("insertion", APPROACH), ("hold force", HOLD_COLOURS[0]),
               ("hold beyond capacity", HOLD_COLOURS[1]), ("robot base", ROBOT),
               ("gripper", GRIPPER), ("robot pushes", PUSH), ("robot pulls", PULL))


def wrench_text(action: Mapping) -> str:
    """Hover text of a timeline action (a RobotAction dict): robot, block, force, torque."""
    f, m = (np.array([action[k][q][c] for c in "xyz"]) for k, q in
            (("wrench_world", "force"), ("wrench_tool", "torque")))
    return (f"{action['robot']} {action['action']} {action['block']}: |F| "
            f"{np.linalg.norm(f):.0f} N on the block ({'push' if pushes(action) else 'pull'}), "
            f"|M| {np.linalg.norm(m):.0f} N m at the tool (its weight included)")


def pushes(action: Mapping) -> bool:
    """Whether the robot's force on the block points into the face it grips (the tool's z)."""
    q = action["grip"]["pose"]["orientation"]
    z = Rotation.from_quat([q[c] for c in "xyzw"]).as_matrix()[:, 2]
    force = np.array([action["wrench_world"]["force"][c] for c in "xyz"])
    return bool(force @ z >= 0.0)


def gripper_box(action: Mapping, robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """(centre, quaternion x, y, z, w) of ``robot``'s gripper box at the action's grip."""
    pose = action["grip"]["pose"]
    point = np.array([pose["position"][c] for c in "xyz"])
    quat = np.array([pose["orientation"][c] for c in "xyzw"])
    rotation = Rotation.from_quat(quat).as_matrix()
    centre, _ = tool_box_pose(robot, GripFrame(action["block"], -1, point, rotation,
                                               -rotation[:, 2]))
    return centre, quat


def cell_markers(cell: Cell, timeline: Sequence[Mapping], index: int, header: Mapping,
                 length: float) -> list[dict]:
    """The markers of the state after action ``index`` of ``timeline`` (RobotAction dicts;
    -1: before the first, the robot bases alone): robot bases, the busy robots' gripper
    boxes, the acting robot's force (the largest of the timeline ``length`` m long) and its
    hover text (see the module docstring)."""
    out = []
    for k, r in enumerate(cell.robots):
        base = np.asarray(r.base, dtype=float)
        out.append(_marker(header, "robots", k, CYLINDER, ROBOT, position=base + [0, 0, 0.25],
                           scale=(0.3, 0.3, 0.5)))
        out.append(_marker(header, "robot_names", k, TEXT_VIEW_FACING, TEXT,
                           position=base + [0, 0, 0.7], scale=(0.2, 0.2, 0.2), text=r.name))
    busy: dict[str, Mapping] = {}
    for a in timeline[:index + 1]:
        if a["action"] == "release":
            busy.pop(a["robot"], None)
        else:
            busy[a["robot"]] = a
    for k, (name, a) in enumerate(sorted(busy.items())):
        robot = cell.robot(name)
        centre, quat = gripper_box(a, robot)
        out.append(_marker(header, "grippers", k, CUBE, GRIPPER, position=centre,
                           orientation=quat, scale=robot.tool.box))
    if index < 0:
        return out
    act = timeline[index]
    largest = max((np.linalg.norm([a["wrench_world"]["force"][c] for c in "xyz"])
                   for a in timeline), default=0.0)
    if act["action"] != "release" and largest > 0:
        pose = act["grip"]["pose"]["position"]
        start = np.array([pose[c] for c in "xyz"])
        force = np.array([act["wrench_world"]["force"][c] for c in "xyz"])
        out.append(_marker(header, "robot_wrenches", 0, ARROW,
                           PUSH if pushes(act) else PULL,
                           points=np.stack([start, start + length / largest * force]),
                           scale=(0.04 * length, 0.08 * length, 0.12 * length)))
        out.append(_marker(header, "robot_wrenches", 1, TEXT_VIEW_FACING, TEXT,
                           position=start + [0, 0, 0.3], scale=(0.12, 0.12, 0.12),
                           text=wrench_text(act)))
    return out


def step_markers(scene: Scene, report: Report, header: Mapping, **kw) -> dict:
    """The markers of a report on a valid ``scene`` (its step's blocks, see
    :func:`step_roles`)."""
    return report_markers(scene_meshes(scene), step_roles(scene, report), report, header, **kw)


def run_roles(state: Mapping, reports: Sequence[Report],
              options: CheckOptions = CheckOptions()) -> tuple[Meshes, list[dict[str, str]]]:
    """The meshes of the blocks of ``state`` (an AssemblyState dict checked with
    ``options``: step by step when it has a sequence) and the roles of the blocks at each of
    ``reports``. A state that cannot be read is drawn as it came; the blocks at fault of an
    INVALID_INPUT report are found by validating the state again (the error names them)."""
    scene, fault = None, ()
    try:
        scene = scene_from_state_dict(state if state.get("sequence")
                                      else {**state, "sequence": []})
        if any(r.status == Status.INVALID_INPUT for r in reports):
            validated_assembly(scene, options.limits, options.contact)
    except SceneError as exc:
        fault = exc.blocks
    meshes = state_meshes(state) if scene is None else scene_meshes(scene)
    return meshes, [fault_roles(meshes, fault)
                    if scene is None or r.status == Status.INVALID_INPUT
                    else step_roles(scene, r) for r in reports]


def run_markers(state: Mapping, reports: Sequence[Mapping],
                options: CheckOptions = CheckOptions()) -> list[dict]:
    """The markers of each StabilityReport dict of ``reports`` answering ``state`` (see
    :func:`run_roles`), each with its report's header."""
    parsed = [report_from_dict(r) for r in reports]
    meshes, roles = run_roles(state, parsed, options)
    return [report_markers(meshes, role, report, r["header"])
            for role, report, r in zip(roles, parsed, reports)]


__all__ = ["BLOCK_MARKER_LIMIT", "LINE_LEGEND", "MARKER_TOPIC", "MARKER_TYPE", "Meshes", "ROLES",
           "ROLE_COLOURS", "cell_markers", "fault_roles", "gripper_box", "line_markers",
           "pushes", "report_markers", "run_markers", "run_roles", "scene_meshes",
           "state_meshes", "step_markers", "step_roles", "text_of", "wrench_text"]
