"""Interpenetration of posed convex blocks: separating-axis test and penetration depth.

Two convex polyhedra are disjoint when some axis separates their projections; their
penetration depth is the smallest overlap of the projections over all axes (the shortest
translation that separates them), attained at a face normal of either block or at a cross
product of two edge directions. Blocks touching face to face are separated, within the
contact tolerance, by the normal of the contact face, so one vectorised pass over the face
normals of every candidate pair (bounding boxes overlapping) clears all ordinary contacts.
The few pairs it does not clear either interpenetrate or meet edge to edge (where a face
normal test reports overlap that an edge axis rules out): for them the edge axes are added
(edge directions as cross products of face normals, a superset of the true ones, which
changes no minimum), giving the exact depth. Blocks of more than 64 faces skip that (too many
axes); a small linear programme decides instead: the largest ball inside both blocks (the
intersection of their face half-spaces) has a radius above half the tolerance only when they
interpenetrate, and the depth reported is the face-normal bound.

Non-convex blocks (a vertex outside one of its own face planes) are skipped: their face
planes do not bound them. Pairs are tested in order of decreasing depth and the test stops at
the first one confirmed (a check needs only one reason to refuse a scene).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..deadline import checkpoint
from .block import PosedBlock
from .contacts import candidate_pairs
from .polygon import cross
from .support import projection_extents

#: Blocks with more vertices or faces than this are tested pair by pair (no padding).
_SMALL = 64
#: Largest number of projected values (pairs x vertices x axes) in one vectorised batch.
_BATCH = 4_000_000


class Penetration(NamedTuple):
    """Two blocks that overlap by more than the tolerance."""

    a: int          # block indices, a < b
    b: int
    depth: float    # m, the overlap of the projections along the best face normal
    tol: float      # m, the tolerance it exceeds


def find_penetration(blocks: list[PosedBlock], tol_rel: float,
                     allowance: np.ndarray | None = None) -> Penetration | None:
    """The deepest confirmed interpenetration of two convex blocks (overlap beyond ``tol_rel``
    times the smaller block's size, plus the two blocks' ``allowance`` (m) when given: what
    their pose uncertainty explains), or None."""
    if len(blocks) < 2:
        return None
    pairs = candidate_pairs(blocks, 0.0)
    if not len(pairs):
        return None
    sizes = np.array([b.size for b in blocks])
    convex = np.array([b.convex for b in blocks])
    pairs = pairs[convex[pairs[:, 0]] & convex[pairs[:, 1]]]
    tol = tol_rel * np.minimum(sizes[pairs[:, 0]], sizes[pairs[:, 1]])
    if allowance is not None:
        tol = tol + allowance[pairs[:, 0]] + allowance[pairs[:, 1]]
    depth = _face_axis_depths(blocks, pairs)
    suspect = np.flatnonzero(depth > tol * (1 + 1e-9))     # not for rounding at the limit
    for k in suspect[np.argsort(-depth[suspect], kind="stable")]:
        checkpoint()
        i, j = (int(x) for x in pairs[k])
        a, b = blocks[i], blocks[j]
        if len(a.face_normals) <= _SMALL and len(b.face_normals) <= _SMALL:
            d = min(float(depth[k]), _edge_axis_depth(a, b))
            if d > tol[k] * (1 + 1e-9):
                return Penetration(i, j, d, float(tol[k]))
        elif _inscribed_radius(a, b) > 0.5 * tol[k]:
            return Penetration(i, j, float(depth[k]), float(tol[k]))
    return None


def _edge_directions(normals: np.ndarray) -> np.ndarray:
    """Unit cross products of every two non-parallel face normals (every edge direction of
    a convex polyhedron is one of them)."""
    i, j = np.triu_indices(len(normals), 1)
    d = cross(normals[i], normals[j])
    length = np.linalg.norm(d, axis=1)
    return d[length > 1e-9] / length[length > 1e-9, None]


def _edge_axis_depth(a: PosedBlock, b: PosedBlock) -> float:
    """The smallest overlap of the projections on the cross products of the edge directions
    of a and b (inf when there is no such axis)."""
    ea, eb = _edge_directions(a.face_normals), _edge_directions(b.face_normals)
    axes = cross(ea[:, None, :], eb[None, :, :]).reshape(-1, 3)
    length = np.linalg.norm(axes, axis=1)
    axes = axes[length > 1e-9] / length[length > 1e-9, None]
    if not len(axes):
        return np.inf
    pa, pb = a.vertices @ axes.T, b.vertices @ axes.T
    return float(np.minimum(pa.max(axis=0) - pb.min(axis=0), pb.max(axis=0) - pa.min(axis=0)).min())


def _padded(arrays: list[np.ndarray], width: int) -> np.ndarray:
    """(n, width, 3): each array padded by repeating its first row (a repeated vertex or
    axis changes no projection extreme)."""
    if all(len(a) == width for a in arrays):
        return np.stack(arrays)
    out = np.empty((len(arrays), width, 3))
    for k, a in enumerate(arrays):
        out[k, :len(a)] = a
        out[k, len(a):] = a[0]
    return out


def _face_axis_depths(blocks: list[PosedBlock], pairs: np.ndarray) -> np.ndarray:
    """Per pair, the smallest overlap of the two blocks' projections on the face normals of
    either block (<= 0: separated)."""
    depth = np.empty(len(pairs))
    small = np.array([len(b.vertices) <= _SMALL and len(b.face_normals) <= _SMALL
                      for b in blocks])
    both = small[pairs[:, 0]] & small[pairs[:, 1]]
    idx = np.flatnonzero(both)
    if len(idx):
        used = np.unique(pairs[idx])
        nv = max(len(blocks[k].vertices) for k in used)
        nf = max(len(blocks[k].face_normals) for k in used)
        slot = np.full(len(blocks), -1)
        slot[used] = np.arange(len(used))
        verts = _padded([blocks[k].vertices for k in used], nv)
        normals = _padded([blocks[k].face_normals for k in used], nf)
        step = max(1, _BATCH // (2 * nv * 2 * nf))
        for s in range(0, len(idx), step):
            chunk = idx[s:s + step]
            a, b = slot[pairs[chunk, 0]], slot[pairs[chunk, 1]]
            axes = np.concatenate((normals[a], normals[b]), axis=1)          # (P, 2F, 3)
            axes_t = axes.transpose(0, 2, 1)
            pa, pb = verts[a] @ axes_t, verts[b] @ axes_t                   # (P, V, 2F)
            overlap = np.minimum(pa.max(axis=1) - pb.min(axis=1), pb.max(axis=1) - pa.min(axis=1))
            depth[chunk] = overlap.min(axis=1)
    for k in np.flatnonzero(~both):
        a, b = blocks[pairs[k, 0]], blocks[pairs[k, 1]]
        # each block's extents on its own normals are known from its shape
        ea = np.concatenate((a.face_extents, projection_extents(a.vertices, b.face_normals)))
        eb = np.concatenate((projection_extents(b.vertices, a.face_normals), b.face_extents))
        depth[k] = np.minimum(ea[:, 1] - eb[:, 0], eb[:, 1] - ea[:, 0]).min()
    return depth


def _inscribed_radius(a: PosedBlock, b: PosedBlock) -> float:
    """Radius of the largest ball inside both convex blocks (0 when they do not intersect):
    maximise r subject to n . x + r <= d for every face plane of both."""
    from scipy.optimize import linprog  # deferred: needed only for suspect pairs

    normals = np.concatenate((a.face_normals, b.face_normals))
    offsets = np.concatenate((a.face_offsets, b.face_offsets))
    centre = 0.5 * (a.centroid + b.centroid)        # shift for conditioning
    result = linprog(c=[0.0, 0.0, 0.0, -1.0],
                     A_ub=np.column_stack((normals, np.ones(len(normals)))),
                     b_ub=offsets - normals @ centre,
                     bounds=[(None, None)] * 3 + [(0.0, max(a.size, b.size))], method="highs")
    return float(result.x[3]) if result.status == 0 else 0.0
