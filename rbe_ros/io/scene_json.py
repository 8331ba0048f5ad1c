"""The JSON scene format (documented in the README): read and write scenes."""
from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np

from ..geometry.repair import repair_block
from ..scene import (BOX_FACES, Block, DEFAULT_GRAVITY, Hold, Scene, SceneError, box_vertices,
                     finite_array, make_block, make_scene)


def scene_from_dict(data: dict, base_dir: Path | None = None) -> Scene:
    """Build a scene from the JSON scene format documented in the README."""
    if not isinstance(data, dict):
        raise SceneError("a scene must be a JSON object")
    raw_blocks = data.get("blocks")
    if not isinstance(raw_blocks, list):
        raise SceneError('a scene needs a "blocks" list')
    blocks, warnings = [], []
    for i, raw in enumerate(raw_blocks):
        block, warning = _block_from_dict(i, raw, base_dir)
        blocks.append(block)
        if warning:
            warnings.append(warning)
    seq = data.get("sequence") or ()
    if not isinstance(seq, (list, tuple)):
        raise SceneError('"sequence" must be a list of block ids')
    holds = data.get("holds") or ()
    if not isinstance(holds, (list, tuple)):
        raise SceneError('"holds" must be a list of {"block", "from_step", "until_step"}')
    return make_scene(data.get("name", "scene"), blocks, data.get("gravity", DEFAULT_GRAVITY), seq,
                      [_hold_from_dict(i, h) for i, h in enumerate(holds)],
                      data.get("pose_uncertainty"), _approach_from(data.get("approach")),
                      warnings)


def _approach_from(raw) -> tuple:
    """The "approach" list (one [x, y, z] or null per step of the sequence), or none."""
    if raw is None:
        return ()
    if not isinstance(raw, (list, tuple)):
        raise SceneError('"approach" must be a list of [x, y, z] or null, one per step')
    return tuple(raw)


def _hold_from_dict(index: int, raw) -> Hold:
    if not isinstance(raw, dict) or "block" not in raw:
        raise SceneError(f'hold #{index} must be an object with a "block"')
    unknown = set(raw) - {"block", "from_step", "until_step", *_HOLD_EXTRA}
    if unknown:
        raise SceneError(f"hold #{index}: unknown keys {sorted(unknown)}")
    return Hold(str(raw["block"]), raw.get("from_step", 0), raw.get("until_step"),
                *(raw.get(k) for k in _HOLD_EXTRA))


#: A robot's grip (block frame, m) and capacities (N, N m) of a hold, each optional.
_HOLD_EXTRA = ("grip", "max_force", "max_torque")


def _block_from_dict(index: int, raw, base_dir: Path | None) -> tuple[Block, str | None]:
    """The block of one entry of "blocks", its mesh repaired if it is open or wound
    inconsistently (:func:`rbe_ros.geometry.repair.repair_block`), and the warning of it."""
    if not isinstance(raw, dict):
        raise SceneError(f"block #{index} must be a JSON object")
    if "id" not in raw:
        raise SceneError(f'block #{index} has no "id"')
    bid = str(raw["id"])
    shapes = [k for k in ("box", "mesh", "mesh_file") if k in raw]
    if len(shapes) != 1:
        raise SceneError(f'block {bid!r}: give exactly one shape: "box", "mesh" or "mesh_file"')
    if "box" in raw:
        size = finite_array(raw["box"], (3,), f"block {bid!r}: box")
        if np.any(size <= 0):
            raise SceneError(f"block {bid!r}: box edge lengths must be positive")
        vertices, faces = box_vertices(size), BOX_FACES
        repair = False
    elif "mesh" in raw:
        mesh = raw["mesh"]
        if not isinstance(mesh, dict) or "vertices" not in mesh or "faces" not in mesh:
            raise SceneError(f'block {bid!r}: "mesh" needs "vertices" and "faces"')
        vertices, faces = mesh["vertices"], mesh["faces"]
        repair = True
    else:
        vertices, faces = _load_mesh_file(bid, raw["mesh_file"], base_dir)
        repair = True
    block = make_block(bid, vertices, faces, raw.get("position", (0, 0, 0)),
                       raw.get("orientation", (0, 0, 0, 1)), density=raw.get("density", 0.0),
                       mass=raw.get("mass", 0.0), support=bool(raw.get("support", False)))
    return repair_block(block) if repair else (block, None)


def _load_mesh_file(bid: str, rel: str, base_dir: Path | None):
    import trimesh  # deferred: only mesh files need it at load time

    path = (base_dir or Path.cwd()) / str(rel)
    try:
        mesh = trimesh.load(path, force="mesh", process=True)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise SceneError(f"block {bid!r}: cannot read mesh file {str(path)!r}: {exc}") from None
    return np.asarray(mesh.vertices), [list(f) for f in mesh.faces]


def read_json(path, what: str = "scene") -> tuple[object, str]:
    """The JSON document of a file (gzip-compressed when its name ends in ``.gz``) and the
    file's name for messages; SceneError names the file and the problem."""
    path = Path(path)
    try:
        raw = path.read_bytes()
        text = (gzip.decompress(raw) if path.suffix == ".gz" else raw).decode("utf-8")
    except OSError as exc:
        raise SceneError(f"cannot read {what} {str(path)!r}: "
                         f"{exc.strerror or exc}") from None
    except (UnicodeDecodeError, EOFError) as exc:
        raise SceneError(f"cannot read {what} {str(path)!r}: {exc}") from None
    try:
        return json.loads(text), path.name
    except json.JSONDecodeError as exc:
        raise SceneError(f"{path.name}: invalid JSON at line {exc.lineno}: {exc.msg}") from None


def load_scene(path) -> Scene:
    """Read a scene JSON file (raises :class:`SceneError` for any problem)."""
    data, _ = read_json(path)
    return scene_from_dict(data, Path(path).parent)


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
    if scene.holds:
        out["holds"] = [{"block": h.block, "from_step": h.from_step,
                         **({} if h.until_step is None else {"until_step": h.until_step}),
                         **{k: (list(getattr(h, k)) if k == "grip" else getattr(h, k))
                            for k in _HOLD_EXTRA if getattr(h, k) is not None}}
                        for h in scene.holds]
    if scene.pose_uncertainty is not None:
        out["pose_uncertainty"] = list(scene.pose_uncertainty)
    if scene.approach:
        out["approach"] = [None if d is None else [float(x) for x in d] for d in scene.approach]
    return out
