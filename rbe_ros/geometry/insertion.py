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
through a notch of a non-convex neighbour may still be free. The moving block's hull has its
faces moved in by a clearance first, so that its neighbours at contact (touching, or
overlapping as much as the scene validation accepts) do not count as collisions.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import fcl
import numpy as np
from scipy.spatial import ConvexHull, HalfspaceIntersection

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
    raw = [down]
    for n in normals:
        raw.append(down - (down @ n) * n)
        for axis in np.eye(3):
            in_plane = axis - (axis @ n) * n
            raw += [in_plane, -in_plane]
    for i in range(len(normals)):
        for j in range(i + 1, len(normals)):
            edge = np.cross(normals[i], normals[j])
            raw += [edge, -edge]
    if not len(normals):
        raw += [*np.eye(3), *-np.eye(3)]
    found: dict[tuple, np.ndarray] = {}
    for v in raw:
        d = _unit(v)
        if d is not None and in_cone(d, normals):
            found.setdefault(tuple(np.round(d, 9)), d)
    # closest to down first; ties broken by the rounded direction (deterministic)
    return [found[k] for k in sorted(found, key=lambda k: (-round(float(found[k] @ down), 9), k))]


@lru_cache(maxsize=4096)
def _hull_object(key: bytes) -> fcl.Convex:
    """An fcl convex body of the hull of the vertices serialised in ``key`` (cached: a
    present block is tested against many moving blocks)."""
    return _convex(np.frombuffer(key).reshape(-1, 3))


def _convex(points: np.ndarray) -> fcl.Convex:
    hull = ConvexHull(points)
    vertices = points[hull.vertices]
    index = {int(v): k for k, v in enumerate(hull.vertices)}
    faces = np.array([[3, *(index[int(v)] for v in tri)] for tri in hull.simplices])
    return fcl.Convex(vertices, len(faces), faces.ravel())


def shrunk(vertices: np.ndarray, clearance: float) -> np.ndarray:
    """The vertices of the convex hull of ``vertices`` with every face moved in by
    ``clearance`` (by at most half the face's distance from the hull's centre)."""
    hull = ConvexHull(vertices)
    centre = vertices[hull.vertices].mean(axis=0)
    depth = -(hull.equations[:, :3] @ centre + hull.equations[:, 3])
    offset = np.minimum(clearance, 0.5 * depth.min())
    planes = hull.equations + np.column_stack([np.zeros((len(depth), 3)),
                                               np.full(len(depth), offset)])
    return HalfspaceIntersection(planes, centre).intersections


def sweep_blockers(moving: PosedBlock, present: Sequence[PosedBlock], direction: np.ndarray,
                   distance: float, clearance: float) -> tuple[str, ...]:
    """Ids of the ``present`` blocks that the convex hull of ``moving`` (shrunk by
    ``clearance``) hits on its way into its pose along ``direction`` over ``distance`` m."""
    end = shrunk(moving.vertices, clearance)
    swept = np.vstack([end, end - distance * np.asarray(direction, dtype=float)])
    low, high = swept.min(axis=0), swept.max(axis=0)
    if not present:
        return ()
    boxes = np.array([b.aabb for b in present])
    near = np.flatnonzero(np.all(boxes[:, 0] <= high, axis=1) & np.all(boxes[:, 1] >= low, axis=1))
    if not len(near):
        return ()
    body = fcl.CollisionObject(_convex(swept))
    request, hits = fcl.CollisionRequest(), []
    for k in near:
        other = fcl.CollisionObject(_hull_object(np.ascontiguousarray(
            present[k].vertices, dtype=float).tobytes()))
        if fcl.collide(body, other, request, fcl.CollisionResult()):
            hits.append(present[k].id)
    return tuple(hits)


def insertion(moving: PosedBlock, normals: np.ndarray, present: Sequence[PosedBlock],
              down: np.ndarray, distance: float, clearance: float,
              given: np.ndarray | None = None, angle_tol: float = 0.0) -> Insertion:
    """How ``moving`` reaches its pose past the ``present`` blocks, ``normals`` (k, 3) those
    of its interfaces, into it: the first direction of :func:`cone_directions` whose path
    over ``distance`` is free, or ``given`` (unit) checked alone, within ``angle_tol``
    (radians) of the cone."""
    normals = distinct_normals(normals)
    if given is not None:
        given = np.asarray(given, dtype=float) / np.linalg.norm(given)
        if not in_cone(given, normals, np.sin(angle_tol)):
            return Insertion(False, reason=f"the given approach {_fmt(given)} comes out of a "
                             "neighbour (against an interface normal)")
        candidates = [given]
    else:
        candidates = cone_directions(normals, down)
        if not candidates:
            return Insertion(False, reason="enclosed: no direction leaves every interface")
    blockers: dict[str, None] = {}
    for d in candidates:
        hits = sweep_blockers(moving, present, d, distance, clearance)
        if not hits:
            return Insertion(True, d)
        blockers.update(dict.fromkeys(hits))
    tried = "the given approach" if given is not None else f"{len(candidates)} directions"
    return Insertion(False, blocked_by=tuple(blockers),
                     reason=f"{tried} blocked by {', '.join(blockers)}")


def _fmt(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.3g}" for x in v) + ")"
