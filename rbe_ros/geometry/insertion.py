"""From where a block can arrive: its insertion cone and a swept-path check.

A block moves into its final pose along a unit direction d. Locally, each interface with a
present block, normal n into the moving block, allows only d . n <= 0 (the block may slide
along the face or move towards it, never come out of the neighbour): the feasible directions
are the polyhedral cone {d : N d <= 0} (Wilson and Latombe 1994). The direction chosen is the
feasible one closest to straight down along gravity (a top-down approach suits grippers).

That direction is exact without a solver: the unit direction of a 3D polyhedral cone closest
to g is g itself, or g projected onto one face's plane, or onto one edge (the cross product of
two face normals). :func:`cone_directions` enumerates these with a set that generates the
cone (its extreme rays and its lineality space both ways: a piece locked in a planar wall
comes in along the wall's normal), keeps the feasible ones within the largest approach angle
from g and sorts them by their angle to g, so the path check can try them in turn.

The path: a convex body translated along -d sweeps exactly the convex hull of its start and
end vertices, so one discrete collision test of that body per present convex body decides the
path (python-fcl's GJK, after a bounding-box broad phase). A non-convex block, moving or
present, is its exact convex pieces (:mod:`rbe_ros.geometry.decompose`), so its path is exact
too; without a decomposition a present block is its triangle mesh (exact, see
:func:`present_pieces`) and a moving one, or a present one shrunk by a declared pose
uncertainty, its convex hull (conservative: a path accepted is free).
The path runs from where the block is clear of every present block's bounding box to its
pose, or over a given distance. The moving block's pieces have their faces moved in by a
clearance first (:func:`shrunk`), so that its neighbours at contact (touching, or
overlapping as much as the scene validation accepts) do not count as collisions, and a slide
along a face in contact is free.

Under a declared pose uncertainty every block, the present ones too, is also shrunk by its
allowance a (:func:`rbe_ros.geometry.uncertainty.allowances`: no point of the block is
farther than a from where its pose puts it): the measured hull with its faces moved in by a
lies inside the block wherever it truly is, so a path refused is blocked for every pose the
declaration allows, and two blocks overlapping by what their allowances explain (a contact to
the contact detection and the validation) do not block each other.
"""
from __future__ import annotations

import math
import threading
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property

import fcl
import numpy as np
from scipy.spatial import ConvexHull

from .block import PosedBlock
from .decompose import convex_pieces

#: Feasibility of a direction of the cone: n . d <= FEASIBLE_TOL (numerical zero).
FEASIBLE_TOL = 1e-9


@dataclass(frozen=True)
class Insertion:
    """Whether a block can reach its pose, along which unit direction (zeros when it cannot),
    and, when it cannot, the blocks that blocked the directions tried."""

    insertable: bool
    direction: np.ndarray = field(default_factory=lambda: np.zeros(3))
    blocked_by: tuple[str, ...] = ()
    reason: str = ""


def _unit(v: np.ndarray) -> np.ndarray | None:
    norm = float(np.linalg.norm(v))
    return None if norm < 1e-9 else v / norm


def in_cone(direction, normals: np.ndarray, tol: float = FEASIBLE_TOL) -> bool:
    """Whether unit ``direction`` satisfies n . d <= tol for every row n of ``normals``."""
    return bool(len(normals) == 0 or np.max(np.asarray(normals) @ direction) <= tol)


def distinct_normals(normals: np.ndarray, tol: float = FEASIBLE_TOL) -> np.ndarray:
    """The unit rows of ``normals`` without repeats (within 1e-9), in a deterministic order;
    a row within ``tol`` (chord) of an earlier one is left out too (the faces of a mesh as
    exported, not quite parallel, give one normal)."""
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    if not len(normals):
        return normals
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.unique(np.round(normals, 9), axis=0)
    if tol <= FEASIBLE_TOL:
        return normals
    kept = []
    for n in normals:
        if not kept or np.min(np.linalg.norm(np.array(kept) - n, axis=1)) > tol:
            kept.append(n)
    return np.array(kept)


def cone_directions(normals: np.ndarray, down: np.ndarray, max_angle: float = math.pi,
                    tol: float = FEASIBLE_TOL) -> list[np.ndarray]:
    """The candidate unit directions of the cone {d : N d <= tol} within ``max_angle``
    (radians) of ``down``, closest to ``down`` first (the first is the exact closest feasible
    direction); empty when there is none. ``tol`` (the sine of the contact angle tolerance):
    normals closer than that are one, and the lineality space is that of the normals' span
    up to it, so that faces not quite parallel (a mesh as exported) keep a wall's normal.

    The set generates the cone and holds its nearest direction to ``down``:

    - ``down``, and ``down`` projected onto each face plane n . d = 0 and onto each edge
      line n_i x n_j (the nearest direction lies in the relative interior of one face of the
      cone: the whole space, a facet, an edge);
    - the cone's extreme rays: of a pointed cone its feasible edges +-(n_i x n_j); with a line
      l of lineality (every normal perpendicular to l), the rays +-(l x n_i) in the plane
      across it; of a half-space, -n;
    - its lineality space both ways: the line +-l (a piece in a planar wall comes in along
      the wall's normal, either side); a plane's (the cone is a half-space, or the plane
      itself) in-plane axes, the world axes projected onto it, both ways; the whole space's
      (no interfaces) axes;
    - with ``max_angle`` below 90 deg the cap {d : angle(d, down) <= max_angle} cuts the
      cone: the directions where the cap's circle meets each face plane, the extreme
      directions of the cone within the cap."""
    normals = distinct_normals(normals, tol)
    down = np.asarray(down, dtype=float) / np.linalg.norm(down)
    raw = [down[None, :]]
    if len(normals):
        raw.append(down - (normals @ down)[:, None] * normals)     # onto each face plane
        axes = np.eye(3)[None, :, :] - normals[:, :, None] * normals[:, None, :]
        raw += [axes.reshape(-1, 3), -axes.reshape(-1, 3), -normals]
        i, j = np.triu_indices(len(normals), 1)
        edges = np.cross(normals[i], normals[j])
        raw += [edges, -edges]
        for line in lineality(normals, tol):
            across = np.cross(line, normals)
            raw += [line[None, :], -line[None, :], across, -across]
        if max_angle < math.pi:
            raw.append(_cap_crossings(normals, down, max_angle))
    else:
        raw += [np.eye(3), -np.eye(3)]
    raw = np.concatenate(raw)
    norms = np.linalg.norm(raw, axis=1)
    raw = raw[norms >= 1e-9] / norms[norms >= 1e-9, None]
    if len(normals):
        raw = raw[np.max(raw @ normals.T, axis=1) <= max(tol, FEASIBLE_TOL)]
    raw = raw[raw @ down >= math.cos(max_angle) - FEASIBLE_TOL]
    # closest to down first; ties broken by the rounded direction (deterministic)
    keys = np.round(raw, 9)
    order = np.lexsort((*keys.T[::-1], -np.round(raw @ down, 9)))
    _, first = np.unique(keys[order], axis=0, return_index=True)
    return list(raw[order[np.sort(first)]])


def lineality(normals: np.ndarray, tol: float = FEASIBLE_TOL) -> np.ndarray:
    """An orthonormal basis (rows) of the cone's lineality space {d : N d = 0} when it is a
    line (the normals span a plane, singular values beyond ``tol`` of the largest); empty
    otherwise (a plane's and the whole space's directions are the in-plane and world axes
    of :func:`cone_directions`)."""
    if len(normals) < 2:
        return np.zeros((0, 3))
    _, sigma, vt = np.linalg.svd(normals)
    rank = int(np.sum(sigma > max(tol, FEASIBLE_TOL) * sigma[0]))
    return vt[2:] if rank == 2 else np.zeros((0, 3))


def _cap_crossings(normals: np.ndarray, down: np.ndarray, angle: float) -> np.ndarray:
    """The unit directions at ``angle`` from ``down`` in each plane n . d = 0 (two per plane
    that the cap's circle crosses): d = cos(angle) down + sin(angle) u with u perpendicular
    to down and n . u = -cot(angle) n . down."""
    out = []
    for n in normals:
        side = n - (n @ down) * down                    # n's part across down
        w = float(np.linalg.norm(side))
        if w < 1e-12:
            continue
        target = -(n @ down) * math.cos(angle) / (w * math.sin(angle)) if angle > 0 else 0.0
        if abs(target) > 1.0:
            continue
        e = side / w
        f = np.cross(down, e)
        for sign in (1.0, -1.0):
            u = target * e + sign * math.sqrt(1.0 - target * target) * f
            out.append(math.cos(angle) * down + math.sin(angle) * u)
    return np.array(out).reshape(-1, 3)


def block_pieces(block: PosedBlock) -> list[np.ndarray]:
    """World vertices of convex pieces whose union is ``block``: the block itself when it is
    convex, its exact decomposition (:func:`rbe_ros.geometry.decompose.convex_pieces`) when
    it is not, else (no exact decomposition: a curved non-convex mesh, or too large) its
    convex hull, which is conservative."""
    if block.convex or block.triangles is None:
        return [block.vertices]
    pieces = convex_pieces(block.local_vertices, block.triangles)
    if pieces is None:
        return [block.vertices]
    return [p @ block.rotation.T + block.position for p in pieces]


_LOCK = threading.Lock()
_PRESENT: OrderedDict = OrderedDict()     # (mesh key, allowance) -> [(fcl object, aabb)]


def present_pieces(block: PosedBlock, allowance: float) -> list:
    """fcl objects and bounding boxes of ``block``'s convex pieces, each shrunk by
    ``allowance`` (m) if > 0 (kept for the last 4096 blocks asked: a present block is tested
    against many moving blocks). A non-convex block without a decomposition is its triangle
    mesh (a BVH) when no allowance shrinks it: a swept convex body meets the solid exactly
    when it meets its faces, for the body ends outside the solid (at the moving block's
    pose, shrunk by the clearance) and so cannot lie inside it."""
    key = (block.vertices.tobytes(), None if block.convex or block.triangles is None
           else block.triangles.tobytes(), allowance)
    with _LOCK:
        found = _PRESENT.get(key)
        if found is not None:
            _PRESENT.move_to_end(key)
            return found
    if (allowance == 0 and not block.convex and block.triangles is not None
            and convex_pieces(block.local_vertices, block.triangles) is None):
        mesh = fcl.BVHModel()
        mesh.beginModel(len(block.vertices), len(block.triangles))
        mesh.addSubModel(block.vertices, block.triangles)
        mesh.endModel()
        found = [(fcl.CollisionObject(mesh), block.aabb)]
    else:
        found = []
        for piece in block_pieces(block):
            points = shrunk(piece, allowance) if allowance > 0 else piece
            found.append((fcl.CollisionObject(_convex(points)),
                          np.array([points.min(axis=0), points.max(axis=0)])))
    with _LOCK:
        _PRESENT[key] = found
        if len(_PRESENT) > 4096:
            _PRESENT.popitem(last=False)
    return found


def _convex(points: np.ndarray) -> fcl.Convex:
    hull = ConvexHull(points)
    index = np.empty(len(points), dtype=np.int64)
    index[hull.vertices] = np.arange(len(hull.vertices))
    faces = np.column_stack([np.full(len(hull.simplices), 3), index[hull.simplices]])
    return fcl.Convex(points[hull.vertices], len(faces), faces.ravel())


def shrunk(vertices: np.ndarray, clearance: float) -> np.ndarray:
    """The vertices of the convex hull of ``vertices``, moved in so that each hull facet
    through a vertex moves in by ``clearance`` (at most a quarter of the facets' least
    distance from the hull's centre): per vertex m solves n . m = 1 over the facets through
    it (least squares where more than three planes meet), and the vertex moves by
    -clearance m. Linear in the hull's size (a 10,000-vertex mesh too)."""
    hull = ConvexHull(vertices)
    normals = hull.equations[:, :3]
    centre = vertices[hull.vertices].mean(axis=0)
    step = min(clearance, 0.25 * float(np.min(-(hull.equations[:, 3] + normals @ centre))))
    # per hull vertex, the sums over the facets through it of n n^T and of n
    per = np.hstack([(normals[:, :, None] * normals[:, None, :]).reshape(-1, 9), normals])
    corners = hull.simplices.ravel()
    order = np.argsort(corners, kind="stable")
    corners = corners[order]
    starts = np.flatnonzero(np.r_[True, corners[1:] != corners[:-1]])
    sums = np.add.reduceat(np.repeat(per, 3, axis=0)[order], starts, axis=0)
    m = np.einsum("vij,vj->vi", np.linalg.pinv(sums[:, :9].reshape(-1, 3, 3)), sums[:, 9:])
    return vertices[corners[starts]] - step * m


class PathCheck:
    """The swept-path test of one block moving into its pose past fixed ``present`` blocks
    (their bounding boxes ``boxes``, (n, 2, 3), if known; each shrunk by its ``allowances``
    entry, m, if given): the block's convex pieces (:func:`block_pieces`) shrunk by
    ``clearance`` (once), swept along each direction asked over ``distance`` m, or when it is
    None from where the block is clear of every present block's bounding box (its far side
    along the direction) to its pose."""

    def __init__(self, moving: PosedBlock, present: Sequence[PosedBlock],
                 distance: float | None, clearance: float, boxes: np.ndarray | None = None,
                 allowances: np.ndarray | None = None):
        self.moving, self.clearance = moving, clearance
        self.vertices = moving.vertices
        self.present = list(present)
        self.boxes = (np.array([b.aabb for b in self.present]).reshape(-1, 2, 3)
                      if boxes is None else boxes)
        self.allowances = (np.zeros(len(self.present)) if allowances is None
                           else np.asarray(allowances, dtype=float))
        self.distance = distance

    @cached_property
    def ends(self) -> list[np.ndarray]:
        """The moving block's convex pieces, shrunk by the clearance: made at the first sweep
        only (a step whose cone is empty, or a robot's approach length, needs none)."""
        return [shrunk(p, self.clearance) for p in block_pieces(self.moving)]

    def length(self, direction: np.ndarray) -> float:
        """m the block travels along unit ``direction`` into its pose: the given distance,
        else from beyond every present bounding box (along -direction) to the pose."""
        if self.distance is not None:
            return self.distance
        if not len(self.boxes):
            return 0.0
        back = -np.asarray(direction, dtype=float)
        far = float(np.max(np.maximum(self.boxes[:, 0] * back, self.boxes[:, 1] * back)
                           .sum(axis=1)))
        return max(0.0, far - float(np.min(self.vertices @ back)))

    def blockers(self, direction: np.ndarray) -> tuple[str, ...]:
        """Ids of the present blocks the path along unit ``direction`` hits (in their order)."""
        step = self.length(direction) * np.asarray(direction, dtype=float)
        hit = np.zeros(len(self.present), dtype=bool)
        request = fcl.CollisionRequest()
        for end in self.ends:
            swept = np.vstack([end, end - step])
            low, high = swept.min(axis=0), swept.max(axis=0)
            near = np.flatnonzero(~hit & np.all(self.boxes[:, 0] <= high, axis=1)
                                  & np.all(self.boxes[:, 1] >= low, axis=1))
            if not len(near):
                continue
            body = fcl.CollisionObject(_convex(swept))
            for k in near:
                for other, box in present_pieces(self.present[k], float(self.allowances[k])):
                    if (np.all(box[0] <= high) and np.all(box[1] >= low)
                            and fcl.collide(body, other, request, fcl.CollisionResult())):
                        hit[k] = True
                        break
        return tuple(self.present[k].id for k in np.flatnonzero(hit))


def insertion(normals: np.ndarray, path: PathCheck, down: np.ndarray,
              given: np.ndarray | None = None, angle_tol: float = 0.0,
              max_angle: float = math.pi) -> Insertion:
    """How a block reaches its pose, ``normals`` (k, 3) those of its interfaces, into it:
    the first direction of :func:`cone_directions` within ``max_angle`` (radians) of
    ``down`` whose ``path`` is free (straight down first if it is within ``angle_tol``,
    radians, of the cone), or ``given`` (unit) checked alone, within ``angle_tol`` of the
    cone and within ``max_angle`` of down."""
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    down = np.asarray(down, dtype=float) / np.linalg.norm(down)
    tol = math.sin(angle_tol)
    blockers: dict[str, None] = {}
    tried = 0
    if given is not None:
        given = np.asarray(given, dtype=float) / np.linalg.norm(given)
        if not in_cone(given, normals, tol):
            return Insertion(False, reason=f"the given approach {_fmt(given)} comes out of a "
                             "neighbour (against an interface normal)")
        off = math.acos(float(np.clip(given @ down, -1.0, 1.0)))
        if off > max_angle + 1e-9:
            return Insertion(False, reason=f"the given approach {_fmt(given)} is "
                             f"{math.degrees(off):.3g} deg from straight down, beyond "
                             f"{math.degrees(max_angle):.3g} deg")
        candidates = [given]
    elif in_cone(down, normals, tol):
        # straight down is the closest direction when the cone holds it (within the contact
        # angle tolerance: a neighbour's face off vertical by less does not tilt the
        # approach): its path first, the other candidates only when it is blocked
        hits = path.blockers(down)
        if not hits:
            return Insertion(True, down)
        blockers.update(dict.fromkeys(hits))
        tried = 1
        candidates = [d for d in cone_directions(normals, down, max_angle, tol)
                      if d @ down < 1.0 - 1e-12]
    else:
        candidates = cone_directions(normals, down, max_angle, tol)
        if not candidates:
            if max_angle < math.pi and cone_directions(normals, down, math.pi, tol):
                return Insertion(False, reason=f"no direction within "
                                 f"{math.degrees(max_angle):.3g} deg of straight down leaves "
                                 "every interface")
            return Insertion(False, reason="enclosed: no direction leaves every interface")
    for d in candidates:
        hits = path.blockers(d)
        if not hits:
            return Insertion(True, d)
        blockers.update(dict.fromkeys(hits))
    count = tried + len(candidates)
    what = "the given approach" if given is not None else \
        f"{count} direction{'' if count == 1 else 's'}"
    return Insertion(False, blocked_by=tuple(blockers),
                     reason=f"{what} blocked by {', '.join(blockers)}")


def _fmt(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.3g}" for x in v) + ")"
