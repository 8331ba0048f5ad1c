"""Scenes: blocks with shape, pose, mass and support flag; loading and validation.

A scene is the input of every analysis. It is immutable data in SI units; loading checks
everything a later stage would otherwise trip over, so that bad input gives one clear
:class:`SceneError` naming the problem instead of a failure deep in the solver.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

DEFAULT_GRAVITY = (0.0, 0.0, -9.81)


class SceneError(ValueError):
    """The scene cannot be analysed; the message names the block and the problem."""


@dataclass(frozen=True)
class Block:
    """A rigid block: a closed polyhedron in its own frame, posed in the scene frame.

    ``faces`` are polygons (vertex index lists) wound counter-clockwise seen from outside.
    ``orientation`` is a unit quaternion in ROS order (x, y, z, w).
    Exactly one of ``density`` (kg/m^3) and ``mass`` (kg) is positive.
    """

    id: str
    vertices: np.ndarray
    faces: tuple[tuple[int, ...], ...]
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    orientation: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    density: float = 0.0
    mass: float = 0.0
    support: bool = False


@dataclass(frozen=True)
class Scene:
    """An assembly of blocks under gravity, with an optional insertion sequence of block ids."""

    name: str
    blocks: tuple[Block, ...]
    gravity: np.ndarray = field(default_factory=lambda: np.array(DEFAULT_GRAVITY))
    sequence: tuple[str, ...] = ()

    def block(self, block_id: str) -> Block:
        for b in self.blocks:
            if b.id == block_id:
                return b
        raise KeyError(block_id)

    def subset(self, ids) -> "Scene":
        """The scene restricted to the blocks whose ids are in ``ids`` (order kept)."""
        keep = set(ids)
        return replace(self, blocks=tuple(b for b in self.blocks if b.id in keep), sequence=())


BOX_FACES = ((0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (2, 3, 7, 6), (1, 2, 6, 5), (0, 4, 7, 3))


def box_vertices(size) -> np.ndarray:
    """Corners of a box of full edge lengths ``size`` centred on the origin (order of BOX_FACES)."""
    sx, sy, sz = (0.5 * float(s) for s in size)
    return np.array([[-sx, -sy, -sz], [sx, -sy, -sz], [sx, sy, -sz], [-sx, sy, -sz],
                     [-sx, -sy, sz], [sx, -sy, sz], [sx, sy, sz], [-sx, sy, sz]])


def box_block(block_id: str, size, position=(0, 0, 0), orientation=(0, 0, 0, 1), *,
              density: float = 0.0, mass: float = 0.0, support: bool = False) -> Block:
    """A box block; a convenience for generators and tests."""
    return make_block(block_id, box_vertices(size), BOX_FACES, position, orientation,
                      density=density, mass=mass, support=support)


def make_block(block_id, vertices, faces, position=(0, 0, 0), orientation=(0, 0, 0, 1), *,
               density: float = 0.0, mass: float = 0.0, support: bool = False) -> Block:
    """A validated block (raises :class:`SceneError`)."""
    name = str(block_id)
    where = f"block {name!r}"
    verts = _finite_array(vertices, (-1, 3), f"{where}: vertices")
    if len(verts) < 4:
        raise SceneError(f"{where}: a block needs at least 4 vertices, got {len(verts)}")
    try:
        face_tuple = tuple(tuple(int(i) for i in f) for f in faces)
    except (TypeError, ValueError):
        raise SceneError(f"{where}: faces must be lists of vertex indices") from None
    if len(face_tuple) < 4:
        raise SceneError(f"{where}: a closed block needs at least 4 faces, got {len(face_tuple)}")
    for f in face_tuple:
        if len(f) < 3 or min(f) < 0 or max(f) >= len(verts):
            raise SceneError(f"{where}: face {list(f)} is not a polygon of existing vertices")
    pos = _finite_array(position, (3,), f"{where}: position")
    quat = _finite_array(orientation, (4,), f"{where}: orientation")
    norm = float(np.linalg.norm(quat))
    if abs(norm - 1.0) > 1e-3:
        raise SceneError(f"{where}: orientation quaternion (x, y, z, w) must have unit norm, has {norm:.6g}")
    density, mass = float(density or 0.0), float(mass or 0.0)
    if not (math.isfinite(density) and math.isfinite(mass)) or density < 0 or mass < 0:
        raise SceneError(f"{where}: density and mass must be finite and non-negative")
    if (density > 0) == (mass > 0):
        raise SceneError(f"{where}: give exactly one of a positive density (kg/m^3) or mass (kg)")
    return Block(name, verts, face_tuple, pos, quat / norm, density, mass, bool(support))


def _finite_array(value, shape, what: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SceneError(f"{what} must be numbers") from None
    if shape[0] == -1:
        ok = arr.ndim == 2 and arr.shape[1] == shape[1]
    else:
        ok = arr.shape == shape
    if not ok:
        raise SceneError(f"{what} must have shape {'N' if shape[0] == -1 else shape[0]}"
                         f"{'x' + str(shape[1]) if len(shape) > 1 else ''}, got {list(arr.shape)}")
    if not np.all(np.isfinite(arr)):
        raise SceneError(f"{what} contain NaN or infinity")
    return arr


def make_scene(name: str, blocks, gravity=DEFAULT_GRAVITY, sequence=()) -> Scene:
    """A validated scene: unique ids, a support, a sequence of existing free blocks."""
    blocks = tuple(blocks)
    if not blocks:
        raise SceneError("the scene has no blocks")
    ids = [b.id for b in blocks]
    seen: set[str] = set()
    for i in ids:
        if i in seen:
            raise SceneError(f"duplicate block id {i!r}")
        seen.add(i)
    if not any(b.support for b in blocks):
        raise SceneError("the scene has no support block: nothing can carry the load")
    g = _finite_array(gravity, (3,), "gravity")
    if not np.any(g):
        g = np.array(DEFAULT_GRAVITY)
    seq = tuple(str(s) for s in sequence)
    supports = {b.id for b in blocks if b.support}
    seq_seen: set[str] = set()
    for s in seq:
        if s not in seen:
            raise SceneError(f"sequence names block {s!r}, which is not in the scene")
        if s in supports:
            raise SceneError(f"sequence names block {s!r}, which is a support")
        if s in seq_seen:
            raise SceneError(f"sequence names block {s!r} twice")
        seq_seen.add(s)
    return Scene(str(name), blocks, g, seq)


def scene_from_dict(data: dict, base_dir: Path | None = None) -> Scene:
    """Build a scene from the JSON scene format documented in the README."""
    if not isinstance(data, dict):
        raise SceneError("a scene must be a JSON object")
    raw_blocks = data.get("blocks")
    if not isinstance(raw_blocks, list):
        raise SceneError('a scene needs a "blocks" list')
    blocks = [_block_from_dict(i, b, base_dir) for i, b in enumerate(raw_blocks)]
    seq = data.get("sequence") or ()
    if not isinstance(seq, (list, tuple)):
        raise SceneError('"sequence" must be a list of block ids')
    return make_scene(data.get("name", "scene"), blocks, data.get("gravity", DEFAULT_GRAVITY), seq)


def _block_from_dict(index: int, raw, base_dir: Path | None) -> Block:
    if not isinstance(raw, dict):
        raise SceneError(f"block #{index} must be a JSON object")
    if "id" not in raw:
        raise SceneError(f'block #{index} has no "id"')
    bid = str(raw["id"])
    shapes = [k for k in ("box", "mesh", "mesh_file") if k in raw]
    if len(shapes) != 1:
        raise SceneError(f'block {bid!r}: give exactly one shape: "box", "mesh" or "mesh_file"')
    if "box" in raw:
        size = _finite_array(raw["box"], (3,), f"block {bid!r}: box")
        if np.any(size <= 0):
            raise SceneError(f"block {bid!r}: box edge lengths must be positive")
        vertices, faces = box_vertices(size), BOX_FACES
    elif "mesh" in raw:
        mesh = raw["mesh"]
        if not isinstance(mesh, dict) or "vertices" not in mesh or "faces" not in mesh:
            raise SceneError(f'block {bid!r}: "mesh" needs "vertices" and "faces"')
        vertices, faces = mesh["vertices"], mesh["faces"]
    else:
        vertices, faces = _load_mesh_file(bid, raw["mesh_file"], base_dir)
    return make_block(bid, vertices, faces, raw.get("position", (0, 0, 0)),
                      raw.get("orientation", (0, 0, 0, 1)), density=raw.get("density", 0.0),
                      mass=raw.get("mass", 0.0), support=bool(raw.get("support", False)))


def _load_mesh_file(bid: str, rel: str, base_dir: Path | None):
    import trimesh  # deferred: only mesh files need it at load time

    path = (base_dir or Path.cwd()) / str(rel)
    try:
        mesh = trimesh.load(path, force="mesh", process=True)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise SceneError(f"block {bid!r}: cannot read mesh file {str(path)!r}: {exc}") from None
    return np.asarray(mesh.vertices), [list(f) for f in mesh.faces]


def load_scene(path) -> Scene:
    """Read a scene JSON file (raises :class:`SceneError` for any problem)."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise SceneError(f"cannot read scene {str(path)!r}: {exc.strerror}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SceneError(f"{path.name}: invalid JSON at line {exc.lineno}: {exc.msg}") from None
    return scene_from_dict(data, path.parent)


def scene_to_dict(scene: Scene) -> dict:
    """The JSON scene format of ``scene`` (meshes written inline)."""
    blocks = []
    for b in scene.blocks:
        d = {"id": b.id, "support": b.support,
             "mesh": {"vertices": b.vertices.tolist(), "faces": [list(f) for f in b.faces]},
             "position": b.position.tolist(), "orientation": b.orientation.tolist()}
        d["density" if b.density > 0 else "mass"] = b.density if b.density > 0 else b.mass
        blocks.append(d)
    out = {"name": scene.name, "gravity": scene.gravity.tolist(), "blocks": blocks}
    if scene.sequence:
        out["sequence"] = list(scene.sequence)
    return out
