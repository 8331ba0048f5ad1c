"""Scenes: blocks with shape, pose, mass and support flag, and their validation.

A scene is the input of every analysis. It is immutable data in SI units; loading checks
everything a later stage would otherwise trip over, so that bad input gives one clear
:class:`SceneError` naming the problem instead of a failure deep in the solver.
"""
from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

DEFAULT_GRAVITY = (0.0, 0.0, -9.81)


class SceneError(ValueError):
    """The scene cannot be analysed; the message names the block and the problem, and
    ``blocks`` the ids of the blocks at fault (empty when no block is), so that a view can
    highlight them."""

    def __init__(self, message: str, blocks: Sequence[str] = ()):
        super().__init__(message)
        self.blocks = tuple(str(b) for b in blocks)


@contextmanager
def blame(*block_ids: str) -> Iterator[None]:
    """A :class:`SceneError` raised inside, naming no block at fault, names ``block_ids``."""
    try:
        yield
    except SceneError as exc:
        if not exc.blocks:
            exc.blocks = tuple(str(b) for b in block_ids if b)
        raise


@dataclass(frozen=True)
class ValidationLimits:
    """Sane ranges of a scene, the one place the CLI (``--max-blocks``) and the node
    (``max_blocks``) take them from; a scene outside them is refused with a
    :class:`SceneError` naming the block and the limit (:func:`validate_scene`, and the
    geometric checks of :mod:`rbe_ros.analysis.validate`)."""

    max_blocks: int = 5000           # blocks in one scene
    max_vertices: int = 10000        # vertices of one block's mesh
    min_size: float = 1e-3           # m, shortest edge of a block's bounding box (block frame)
    max_size: float = 100.0          # m, longest edge
    min_density: float = 1.0         # kg/m^3, given, or implied by a given mass and the volume
    max_density: float = 30000.0
    max_distance: float = 1e4        # m, distance of a block's position from the origin
    min_gravity: float = 0.01        # m/s^2, |gravity| (all zeros means the default)
    max_gravity: float = 1000.0
    #: Two blocks overlapping deeper than this share of the smaller one's size (cube root of
    #: its volume) interpenetrate. Larger than the contact tolerance (1e-3): faces within
    #: 1 deg of opposite are a contact, and a tilted face's far end overlaps by up to ~1%.
    penetration_tol: float = 0.01


def check_block_count(count: int, limits: ValidationLimits) -> None:
    """Refuse more than ``limits.max_blocks`` blocks (cheap: before anything is converted)."""
    if count > limits.max_blocks:
        raise SceneError(f"the scene has {count} blocks, more than the limit of "
                         f"{limits.max_blocks} (max_blocks)")


def validate_scene(scene: "Scene", limits: ValidationLimits = ValidationLimits()) -> None:
    """Check ``scene`` against ``limits`` (raises :class:`SceneError` for the first problem):
    block count, vertices per block, block size, given densities, distances, gravity.
    Implied densities of given masses and interpenetration need the geometry: see
    :func:`rbe_ros.analysis.validate.validate_assembly`."""
    check_block_count(len(scene.blocks), limits)
    g = float(np.linalg.norm(scene.gravity))
    if not limits.min_gravity <= g <= limits.max_gravity:
        raise SceneError(f"|gravity| {g:.6g} m/s^2 is outside the sane range "
                         f"[{limits.min_gravity:g}, {limits.max_gravity:g}] m/s^2")
    # all blocks at once; then the first block at fault is named
    counts = np.array([len(b.vertices) for b in scene.blocks])
    starts = np.cumsum(counts) - counts
    vertices = np.concatenate([b.vertices for b in scene.blocks])
    extents = np.maximum.reduceat(vertices, starts) - np.minimum.reduceat(vertices, starts)
    distances = np.linalg.norm([b.position for b in scene.blocks], axis=1)
    densities = np.array([b.density for b in scene.blocks])
    bad = ((counts > limits.max_vertices) | (extents.min(axis=1) < limits.min_size)
           | (extents.max(axis=1) > limits.max_size) | (distances > limits.max_distance)
           | ((densities > 0) & ((densities < limits.min_density)
                                 | (densities > limits.max_density))))
    if not bad.any():
        return
    k = int(np.flatnonzero(bad)[0])
    b, extent, distance = scene.blocks[k], extents[k], float(distances[k])
    where = f"block {b.id!r}"
    if len(b.vertices) > limits.max_vertices:
        raise SceneError(f"{where}: {len(b.vertices)} vertices, more than the limit of "
                         f"{limits.max_vertices}", [b.id])
    if extent.min() < limits.min_size or extent.max() > limits.max_size:
        raise SceneError(f"{where}: size {' x '.join(f'{e:.6g}' for e in extent)} m is "
                         f"outside the sane range [{limits.min_size:g}, {limits.max_size:g}]"
                         " m per edge", [b.id])
    if distance > limits.max_distance:
        raise SceneError(f"{where}: position {distance:.6g} m from the origin, farther "
                         f"than the limit of {limits.max_distance:g} m", [b.id])
    raise SceneError(f"{where}: density {b.density:.6g} kg/m^3 is outside the sane "
                     f"range [{limits.min_density:g}, {limits.max_density:g}] kg/m^3", [b.id])


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
class Hold:
    """A temporary support during steps ``from_step`` .. ``until_step - 1`` of a sequence.

    On a free block: the block is held (by a robot or a scaffold), i.e. checked as a support,
    at those steps while it is placed, and free again from ``until_step`` on (released). On a
    support block (a scaffold, the centring of an arch): the support is present only at those
    steps (put up at ``from_step``, taken away at ``until_step``). ``until_step`` None: to the
    end (after the last step too).

    A robot's hold of a free block applies a wrench at ``grip`` (block frame, m; None: the
    centroid), the force within ``max_force`` (N) and the torque about the grip within
    ``max_torque`` (N m; 0: a pin grip); None: the check's options.
    """

    block: str
    from_step: int = 0
    until_step: int | None = None
    grip: tuple[float, float, float] | None = None
    max_force: float | None = None
    max_torque: float | None = None

    def active(self, step: int) -> bool:
        return self.from_step <= step and (self.until_step is None or step < self.until_step)


@dataclass(frozen=True)
class Scene:
    """An assembly of blocks under gravity, with an optional insertion sequence of block ids
    and temporary supports (holds) by step. ``pose_uncertainty`` (m, deg): how well the
    poses are known (measured, as built; about 3 sigma), None for design geometry."""

    name: str
    blocks: tuple[Block, ...]
    gravity: np.ndarray = field(default_factory=lambda: np.array(DEFAULT_GRAVITY))
    sequence: tuple[str, ...] = ()
    holds: tuple[Hold, ...] = ()
    pose_uncertainty: tuple[float, float] | None = None
    #: Per step of ``sequence``: the unit direction the block arrives along (checked, not
    #: chosen), or None (the check chooses one); empty: choose at every step.
    approach: tuple[np.ndarray | None, ...] = ()
    #: What loading changed and the user should know (a repaired mesh, naming the block).
    warnings: tuple[str, ...] = ()

    def approach_of(self, block_id: str) -> np.ndarray | None:
        """The given approach of ``block_id``'s step (None: none given)."""
        if block_id in self.sequence and self.approach:
            return self.approach[self.sequence.index(block_id)]
        return None

    def block(self, block_id: str) -> Block:
        for b in self.blocks:
            if b.id == block_id:
                return b
        raise KeyError(block_id)

    def subset(self, ids) -> "Scene":
        """The scene restricted to the blocks whose ids are in ``ids`` (order kept)."""
        keep = set(ids)
        return replace(self, blocks=tuple(b for b in self.blocks if b.id in keep), sequence=(),
                       holds=(), approach=())


def turned(scene: Scene, rotation: Rotation) -> Scene:
    """``scene`` turned rigidly by ``rotation`` about the world origin, gravity kept (as
    compas_cra's examples turn an assembly: ``rotate_assembly([0, 0, 0], axis, deg)``)."""
    blocks = tuple(replace(b, position=rotation.apply(b.position),
                           orientation=(rotation * Rotation.from_quat(b.orientation)).as_quat())
                   for b in scene.blocks)
    approach = tuple(None if d is None else rotation.apply(d) for d in scene.approach)
    return replace(scene, blocks=blocks, approach=approach)


def gravity_down(scene: Scene) -> Scene:
    """``scene`` turned rigidly so that its gravity points along -z, for tools that only know
    self-weight along -z (compas_cra, LMGC90)."""
    g = np.asarray(scene.gravity, dtype=float)
    target = np.array([0.0, 0.0, -1.0])
    if np.allclose(g / np.linalg.norm(g), target):
        return scene
    rotation, _ = Rotation.align_vectors([target], [g / np.linalg.norm(g)])
    return replace(turned(scene, rotation), gravity=np.linalg.norm(g) * target)


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
    with blame(block_id):
        name = str(block_id)
        where = f"block {name!r}"
        verts = finite_array(vertices, (-1, 3), f"{where}: vertices")
        if len(verts) < 4:
            raise SceneError(f"{where}: a block needs at least 4 vertices, got {len(verts)}")
        try:
            face_tuple = tuple(tuple(int(i) for i in f) for f in faces)
        except (TypeError, ValueError):
            raise SceneError(f"{where}: faces must be lists of vertex indices") from None
        if len(face_tuple) < 4:
            raise SceneError(f"{where}: a closed block needs at least 4 faces, "
                             f"got {len(face_tuple)}")
        for f in face_tuple:
            if len(f) < 3 or min(f) < 0 or max(f) >= len(verts):
                raise SceneError(f"{where}: face {list(f)} is not a polygon of existing "
                                 "vertices")
        pos = finite_array(position, (3,), f"{where}: position")
        quat = finite_array(orientation, (4,), f"{where}: orientation")
        norm = float(np.linalg.norm(quat))
        if abs(norm - 1.0) > 1e-3:
            raise SceneError(f"{where}: orientation quaternion (x, y, z, w) must have unit "
                             f"norm, has {norm:.6g}")
        density, mass = float(density or 0.0), float(mass or 0.0)
        if not (math.isfinite(density) and math.isfinite(mass)) or density < 0 or mass < 0:
            raise SceneError(f"{where}: density and mass must be finite and non-negative")
        if (density > 0) == (mass > 0):
            raise SceneError(f"{where}: give exactly one of a positive density (kg/m^3) or "
                             "mass (kg)")
        return Block(name, verts, face_tuple, pos, quat / norm, density, mass, bool(support))


def finite_array(value, shape, what: str) -> np.ndarray:
    """``value`` as a float array of ``shape`` (-1: any length) with finite entries, else a
    SceneError naming ``what``."""
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
        raise SceneError(f"{what} must be finite, got NaN or infinity")
    return arr


def make_scene(name: str, blocks, gravity=DEFAULT_GRAVITY, sequence=(), holds=(),
               pose_uncertainty=None, approach=(), warnings=()) -> Scene:
    """A validated scene: unique ids, a support, a sequence of existing free blocks, holds of
    existing blocks within the steps, a pose uncertainty of two numbers >= 0 (or None), an
    approach per step of the sequence (a non-zero vector, made unit, or None) or none."""
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
    g = finite_array(gravity, (3,), "gravity")
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
    steps = len(seq) or sum(not b.support for b in blocks)
    return Scene(str(name), blocks, g, seq, _check_holds(holds, seen, steps),
                 _check_uncertainty(pose_uncertainty), _check_approach(approach, seq),
                 tuple(str(w) for w in warnings))


def _check_approach(approach, sequence: tuple[str, ...]) -> tuple[np.ndarray | None, ...]:
    """Validated approaches: none, or one per step of ``sequence``, each None or a non-zero
    finite 3-vector (made unit)."""
    approach = tuple(approach or ())
    if not approach:
        return ()
    if len(approach) != len(sequence):
        raise SceneError(f'"approach" must have one entry per step of the sequence '
                         f"({len(sequence)}), has {len(approach)}")
    out: list[np.ndarray | None] = []
    for block, d in zip(sequence, approach):
        if d is None:
            out.append(None)
            continue
        v = finite_array(d, (3,), f"approach of block {block!r}")
        norm = float(np.linalg.norm(v))
        if norm < 1e-9:
            raise SceneError(f"approach of block {block!r} must be a non-zero vector (null: "
                             "choose one)", [block])
        out.append(v / norm)
    return tuple(out)


def _check_uncertainty(value) -> tuple[float, float] | None:
    """A declared pose uncertainty: [position m] or [position m, angle deg], finite, >= 0."""
    if value is None:
        return None
    what = '"pose_uncertainty" must be [position m, angle deg]'
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or not 1 <= len(value) <= 2:
        raise SceneError(f"{what}, got {value!r}")
    arr = finite_array(list(value) + [0.0] * (2 - len(value)), (2,), what.split(" must")[0])
    if np.any(arr < 0):
        raise SceneError(f"{what}, both >= 0, got {list(value)}")
    return float(arr[0]), float(arr[1])


def _check_holds(holds, ids: set[str], steps: int) -> tuple[Hold, ...]:
    """Validated holds: existing blocks, 0 <= from_step < until_step <= steps (the number of
    placements; until_step == steps releases after the last placement, at an extra step)."""
    out = []
    for h in holds:
        if not isinstance(h, Hold):
            raise SceneError(f"a hold must be a Hold, got {type(h).__name__}")
        where = f"hold of block {h.block!r}"
        if h.block not in ids:
            raise SceneError(f"{where}: no such block in the scene")
        if not _is_int(h.from_step) or h.from_step < 0:
            raise SceneError(f"{where}: from_step must be an integer >= 0, got {h.from_step!r}")
        if h.until_step is not None:
            if not _is_int(h.until_step) or not h.from_step < h.until_step <= steps:
                raise SceneError(f"{where}: until_step must be an integer in ({h.from_step}, "
                                 f"{steps}] (the scene has {steps} steps), got {h.until_step!r}")
        elif h.from_step >= max(steps, 1):
            raise SceneError(f"{where}: from_step {h.from_step} is past the last step "
                             f"({steps - 1})")
        out.append(Hold(h.block, int(h.from_step),
                        None if h.until_step is None else int(h.until_step),
                        None if h.grip is None else tuple(
                            float(x) for x in finite_array(h.grip, (3,), f"{where}: grip")),
                        _capacity(h.max_force, f"{where}: max_force"),
                        _capacity(h.max_torque, f"{where}: max_torque")))
    return tuple(out)


def _capacity(value, where: str) -> float | None:
    """A hold's capacity: None (the check's option) or a finite number >= 0."""
    if value is None:
        return None
    if (isinstance(value, bool) or not isinstance(value, (int, float, np.number))
            or not math.isfinite(value) or value < 0):
        raise SceneError(f"{where} must be a number >= 0 (or absent: the check's option), "
                         f"got {value!r}")
    return float(value)


def _is_int(x) -> bool:
    return isinstance(x, (int, np.integer)) and not isinstance(x, bool)
