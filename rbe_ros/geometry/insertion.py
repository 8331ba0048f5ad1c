"""From where a block can arrive: its insertion cone and a swept-path check.

A block moves into its final pose along a unit direction d. Locally, each interface with a
present block, normal n into the moving block, allows only d . n <= 0 (the block may slide
along the face or move towards it, never come out of the neighbour): the feasible directions
are the polyhedral cone {d : N d <= 0} (Wilson and Latombe 1994). The direction chosen is the
feasible one closest to straight down along gravity (a top-down approach suits grippers).

That direction is exact without a solver: the unit direction of a 3D polyhedral cone closest
to g is g itself, or g projected onto one face's plane, or onto one edge (the cross product of
two face normals), so :func:`cone_directions` enumerates these few candidates, keeps the
feasible ones and sorts them by their angle to g. When g lies in the cone's polar (a block in
a slot across gravity), several directions tie at 90 deg; the sorted list then holds the
cone's edges and its faces' in-plane axes too, so the path check can try them in turn.

The path: the moving block's convex hull translated along -d over the approach distance
sweeps exactly the convex hull of its start and end vertices, one convex body, so one
discrete collision test of that body per present block decides the path (python-fcl's GJK,
after a bounding-box broad phase). Conservative for non-convex blocks: the moving block and
the present ones are their convex hulls, so a path accepted is free, and a path refused
through a notch of a non-convex neighbour may still be free. The moving block has its faces
moved in by a clearance first (:func:`shrunk`), so that its neighbours at contact (touching, or
overlapping as much as the scene validation accepts) do not count as collisions.

Under a declared pose uncertainty every block, the present ones too, is also shrunk by its
allowance a (:func:`rbe_ros.geometry.uncertainty.allowances`: no point of the block is
farther than a from where its pose puts it): the measured hull with its faces moved in by a
lies inside the block wherever it truly is, so a path refused is blocked for every pose the
declaration allows, and two blocks overlapping by what their allowances explain (a contact to
the contact detection and the validation) do not block each other.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import fcl
import numpy as np
from scipy.spatial import ConvexHull

from .block import PosedBlock

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


def distinct_normals(normals: np.ndarray) -> np.ndarray:
    """The unit rows of ``normals`` without repeats (within 1e-9), in a deterministic order."""
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    if not len(normals):
        return normals
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    return np.unique(np.round(normals, 9), axis=0)


def cone_directions(normals: np.ndarray, down: np.ndarray) -> list[np.ndarray]:
    """The candidate unit directions of the cone {d : N d <= 0}, closest to ``down`` first
    (the first is the exact closest feasible direction); empty when the cone is {0}.

    Candidates: ``down``; ``down`` projected onto each face plane n . d = 0; each edge
    +-(n_i x n_j); and each face plane's in-plane axes (projections of the world axes), so
    that a ground-only block also offers horizontal approaches."""
    normals = distinct_normals(normals)
    down = np.asarray(down, dtype=float) / np.linalg.norm(down)
    raw = [down[None, :]]
    if len(normals):
        raw.append(down - (normals @ down)[:, None] * normals)     # onto each face plane
        axes = np.eye(3)[None, :, :] - normals[:, :, None] * normals[:, None, :]
        raw += [axes.reshape(-1, 3), -axes.reshape(-1, 3)]          # each plane's axes
        i, j = np.triu_indices(len(normals), 1)
        edges = np.cross(normals[i], normals[j])
        raw += [edges, -edges]
    else:
        raw += [np.eye(3), -np.eye(3)]
    raw = np.concatenate(raw)
    norms = np.linalg.norm(raw, axis=1)
    raw = raw[norms >= 1e-9] / norms[norms >= 1e-9, None]
    if len(normals):
        raw = raw[np.max(raw @ normals.T, axis=1) <= FEASIBLE_TOL]
    # closest to down first; ties broken by the rounded direction (deterministic)
    keys = np.round(raw, 9)
    order = np.lexsort((*keys.T[::-1], -np.round(raw @ down, 9)))
    _, first = np.unique(keys[order], axis=0, return_index=True)
    return list(raw[order[np.sort(first)]])


@lru_cache(maxsize=4096)
def _hull_object(key: bytes, clearance: float) -> fcl.CollisionObject:
    """An fcl object of the convex hull of the vertices serialised in ``key``, shrunk by
    ``clearance`` (m) if > 0 (cached: a present block is tested against many moving blocks)."""
    points = np.frombuffer(key).reshape(-1, 3)
    return fcl.CollisionObject(_convex(shrunk(points, clearance) if clearance > 0 else points))


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
    entry, m, if given): its convex hull shrunk by ``clearance`` (once), swept over
    ``distance`` m along each direction asked."""

    def __init__(self, moving: PosedBlock, present: Sequence[PosedBlock], distance: float,
                 clearance: float, boxes: np.ndarray | None = None,
                 allowances: np.ndarray | None = None):
        self.end = shrunk(moving.vertices, clearance)
        self.present = list(present)
        self.boxes = (np.array([b.aabb for b in self.present]).reshape(-1, 2, 3)
                      if boxes is None else boxes)
        self.allowances = (np.zeros(len(self.present)) if allowances is None
                           else np.asarray(allowances, dtype=float))
        self.distance = distance

    def blockers(self, direction: np.ndarray) -> tuple[str, ...]:
        """Ids of the present blocks the path along unit ``direction`` hits."""
        swept = np.vstack([self.end, self.end - self.distance * np.asarray(direction, float)])
        low, high = swept.min(axis=0), swept.max(axis=0)
        boxes = self.boxes
        near = np.flatnonzero(np.all(boxes[:, 0] <= high, axis=1)
                              & np.all(boxes[:, 1] >= low, axis=1))
        if not len(near):
            return ()
        body = fcl.CollisionObject(_convex(swept))
        request, hits = fcl.CollisionRequest(), []
        for k in near:
            other = _hull_object(np.ascontiguousarray(self.present[k].vertices,
                                                      dtype=float).tobytes(),
                                 float(self.allowances[k]))
            if fcl.collide(body, other, request, fcl.CollisionResult()):
                hits.append(self.present[k].id)
        return tuple(hits)


def insertion(normals: np.ndarray, path: PathCheck, down: np.ndarray,
              given: np.ndarray | None = None, angle_tol: float = 0.0) -> Insertion:
    """How a block reaches its pose, ``normals`` (k, 3) those of its interfaces, into it:
    the first direction of :func:`cone_directions` whose ``path`` is free (straight down
    first if it is within ``angle_tol``, radians, of the cone), or ``given`` (unit) checked
    alone, within ``angle_tol`` of the cone."""
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    down = np.asarray(down, dtype=float) / np.linalg.norm(down)
    blockers: dict[str, None] = {}
    tried = 0
    if given is not None:
        given = np.asarray(given, dtype=float) / np.linalg.norm(given)
        if not in_cone(given, normals, np.sin(angle_tol)):
            return Insertion(False, reason=f"the given approach {_fmt(given)} comes out of a "
                             "neighbour (against an interface normal)")
        candidates = [given]
    elif in_cone(down, normals, np.sin(angle_tol)):
        # straight down is the closest direction when the cone holds it (within the contact
        # angle tolerance: a neighbour's face off vertical by less does not tilt the
        # approach): its path first, the other candidates only when it is blocked
        hits = path.blockers(down)
        if not hits:
            return Insertion(True, down)
        blockers.update(dict.fromkeys(hits))
        tried = 1
        candidates = cone_directions(normals, down)[1:]
    else:
        candidates = cone_directions(normals, down)
        if not candidates:
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
