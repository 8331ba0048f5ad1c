"""Measured poses: the design's blocks where the robot or the camera says they are.

A fabrication pipeline sends the design once (shapes, masses, supports) and then, as blocks
are placed, their measured poses; it should not resend meshes with every measurement. The
as-built state is the design's supports plus the blocks measured so far, each at its last
measured pose (a measured support moves too); a block not measured yet is not placed.
:func:`scene_at_poses` is the one merge of a design and poses, used by the CLI (``--poses``),
the node (``~/poses``) and replay; :class:`AsBuilt` keeps the poses measured so far between
messages (node and replay).

A pose is ``(position, orientation)``: metres and a unit quaternion (x, y, z, w) of the block
frame, the frame the design gives the block's vertices in (a COMPAS block's: the world axes
at the mean of its vertices).
"""
from __future__ import annotations

from collections.abc import Mapping

from ..scene import Scene, SceneError, make_block, make_scene
from .scene_json import read_json

#: (position [x, y, z] in m, orientation [x, y, z, w]); validated by the merge
Pose = tuple


def scene_at_poses(design: Scene, poses: Mapping[str, Pose]) -> Scene:
    """The as-built scene: the design's supports and the blocks named in ``poses``, each at
    its measured pose, in the design's block order (the measuring order does not matter).

    The sequence keeps the measured blocks in the design's order; holds are not carried over
    (their steps count the design's placements, not the measured ones). Raises
    :class:`SceneError` for an id not in the design (named) or a bad pose (NaN, a
    non-unit quaternion: the block named)."""
    ids = {b.id for b in design.blocks}
    unknown = [i for i in poses if i not in ids]
    if unknown:
        shown = ", ".join(repr(i) for i in unknown[:5]) + (
            f" and {len(unknown) - 5} more" if len(unknown) > 5 else "")
        raise SceneError(f"measured poses name {'a block' if len(unknown) == 1 else 'blocks'} "
                         f"not in the design {design.name!r}: {shown}")
    blocks = []
    for b in design.blocks:
        if b.id in poses:
            position, orientation = poses[b.id]
            blocks.append(make_block(b.id, b.vertices, b.faces, position, orientation,
                                     density=b.density, mass=b.mass, support=b.support))
        elif b.support:
            blocks.append(b)
    return make_scene(design.name, blocks, design.gravity,
                      [s for s in design.sequence if s in poses],
                      pose_uncertainty=design.pose_uncertainty)


class AsBuilt:
    """The design and the poses measured so far: the node's and the replay's state between
    messages. A new design forgets the poses; an update that cannot be merged (unknown id,
    bad pose) is refused as a whole and changes nothing."""

    def __init__(self) -> None:
        self.design: Scene | None = None
        self.error = "no design yet: send one on ~/design or set design_file"
        self.measured: dict[str, Pose] = {}
        self.scene: Scene | None = None     # the as-built scene after the last update

    def set_design(self, design: Scene | None, error: str = "") -> Scene:
        """Take ``design`` (None: an invalid design, ``error`` says why); the as-built
        scene with nothing measured yet (the supports) is returned, or SceneError raised."""
        self.design, self.measured, self.scene = design, {}, None
        self.error = f"the design is invalid: {error}"
        return self.update({})

    def update(self, poses: Mapping[str, Pose]) -> Scene:
        """Add (or replace) measured poses; the as-built scene after them (SceneError).
        Poses equal to those measured already change nothing: the same scene object is
        returned (a cell sends every pose at 10 Hz; a replay re-checks a scene once)."""
        if self.design is None:
            raise SceneError(self.error)
        if self.scene is not None and all(_same(self.measured.get(i), p)
                                          for i, p in poses.items()):
            return self.scene
        measured = {**self.measured, **poses}
        scene = scene_at_poses(self.design, measured)
        self.measured, self.scene = measured, scene
        return scene


def _same(a: Pose | None, b: Pose) -> bool:
    """Whether two poses are the same numbers (NaN never is)."""
    if a is None:
        return False
    try:
        return all(len(x) == len(y) and all(float(u) == float(v) for u, v in zip(x, y))
                   for x, y in zip(a, b, strict=True))
    except (TypeError, ValueError):
        return False


def poses_from_json(data, where: str = "poses") -> dict[str, Pose]:
    """``{"poses": {ID: {"position": [x, y, z], "orientation": [x, y, z, w]}}}`` as poses
    (values checked by the merge)."""
    poses = data.get("poses") if isinstance(data, dict) else None
    if not isinstance(poses, dict):
        raise SceneError(f'{where}: a poses file is {{"poses": {{ID: {{"position": [x, y, z], '
                         f'"orientation": [x, y, z, w]}}}}}}')
    out = {}
    for bid, pose in poses.items():
        if not isinstance(pose, dict) or set(pose) != {"position", "orientation"}:
            raise SceneError(f"{where}: the pose of block {bid!r} needs exactly a position "
                             "[x, y, z] and an orientation [x, y, z, w]")
        out[str(bid)] = (pose["position"], pose["orientation"])
    return out


def load_poses(path) -> dict[str, Pose]:
    """The measured poses of a JSON file (:func:`poses_from_json`)."""
    data, name = read_json(path, "poses")
    return poses_from_json(data, name)


__all__ = ["AsBuilt", "Pose", "load_poses", "poses_from_json", "scene_at_poses"]
