"""An exact convex decomposition of a non-convex block: convex pieces whose union is the mesh.

For the swept-path test of insertion (:mod:`rbe_ros.geometry.insertion`): a convex piece
translated along a line sweeps exactly the convex hull of its start and end, so a block that
is a union of convex pieces has an exact swept volume, the union of its pieces' sweeps.

The pieces come from a binary space partition by the planes of the faces at the mesh's
reflex edges (an edge where the solid turns inward): a cell in which no reflex edge is left
holds a part of the solid without reflex edges, which is convex when connected, the
intersection of the cell with the planes of the mesh faces that meet it; a cell that holds
more than one such part is cut again by a face plane crossing it. A polycube, an L, a U or a
T prism, a block with a blind hole are cut along their inner corners into a few boxes.

Every decomposition is verified before it is used: every face's part in a piece's cell lies
on the piece's boundary, no face cuts into a piece, and each piece's centroid is inside the
mesh (winding number), so each piece is a part of the solid, and the pieces' volumes
(disjoint cells) sum to the mesh's volume, so their union is the solid, all within a
tolerance of :data:`TOLERANCES` (1e-6 of the mesh's diagonal, else 1e-4 for a mesh as
exported). A mesh that fails both, needs more than :data:`MAX_PIECES` pieces or has more than
:data:`MAX_TRIANGLES` triangles has no decomposition here (None): the caller falls back to
the convex hull (conservative: a path accepted is free). Cached per mesh, so identical
blocks in any pose share one decomposition.
"""
from __future__ import annotations

import itertools
from functools import lru_cache

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from ..deadline import checkpoint

#: Larger meshes, or meshes needing more pieces, are not decomposed (their hull is used).
MAX_TRIANGLES = 4000
MAX_PIECES = 64

#: Tolerances tried in turn, relative to the mesh's bounding-box diagonal: a reflex edge turns
#: inward by more than this, a face meets a cell when it reaches this far inside it, and the
#: pieces' volumes sum to the mesh's within ten times this share of it. The first is for
#: exact meshes, the second for exported ones (coordinates rounded, faces not quite planar):
#: both far below the clearance of the path check (2% of the block's size).
TOLERANCES = (1e-6, 1e-4)


def convex_pieces(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, ...] | None:
    """The vertices of the convex pieces (block frame) whose union is the closed mesh
    (``triangles`` wound outward) within the first of :data:`TOLERANCES` that verifies; None
    when it has no decomposition here."""
    vertices = np.ascontiguousarray(vertices, dtype=float)
    triangles = np.ascontiguousarray(triangles, dtype=np.int64)
    for relative in TOLERANCES:
        found = _pieces(vertices.tobytes(), triangles.tobytes(), relative)
        if found is not None:
            return found
    return None


@lru_cache(maxsize=1024)
def _pieces(vertex_bytes: bytes, triangle_bytes: bytes, relative: float):
    vertices = np.frombuffer(vertex_bytes).reshape(-1, 3)
    triangles = np.frombuffer(triangle_bytes, dtype=np.int64).reshape(-1, 3)
    if len(triangles) > MAX_TRIANGLES:
        return None
    tri = vertices[triangles]
    scale = float(np.linalg.norm(np.ptp(vertices, axis=0)))
    tol = relative * scale
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(normals, axis=1)
    keep = area > 1e-12 * scale ** 2
    tri, normals = tri[keep], normals[keep] / area[keep, None]
    offsets = np.einsum("ij,ij->i", normals, tri[:, 0])
    volume = float(np.einsum("ij,ij->", tri[:, 0], np.cross(tri[:, 1], tri[:, 2]))) / 6.0
    ends, planes = _reflex_edges(vertices, triangles[keep], normals, offsets, tol)
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    pad = 1e-3 * scale
    corners = np.array(list(itertools.product(*zip(low - pad, high + pad))))
    stack = [(np.vstack([np.eye(3), -np.eye(3)]), np.concatenate([high + pad, pad - low]),
              corners)]
    pieces, total, cells = [], 0.0, 0
    while stack:
        checkpoint()                            # a check's time limit covers this too
        cells += 1
        if cells > 4 * MAX_PIECES or len(pieces) > MAX_PIECES:
            return None
        a, b, corners = stack.pop()
        cut = _reflex_cut(ends, planes, a, b, tol)
        if cut is None:
            try:
                found = _cell_piece(tri, normals, offsets, a, b, corners, tol)
            except _NotExact:
                return None
            if isinstance(found, tuple):        # the cell holds more than one convex part
                cut = found
            elif found is not None:
                pieces.append(found)
                total += ConvexHull(found).volume
                continue
            else:
                continue
        n, d = cut
        for sign in (1.0, -1.0):
            part = _cut(corners, sign * n, sign * d, tol)
            if part is not None:
                stack.append((np.vstack([a, sign * n]), np.append(b, sign * d), part))
    if not pieces or abs(total - volume) > 10 * relative * volume:
        return None
    for p in pieces:
        p.flags.writeable = False
    return tuple(pieces)


def _cell_piece(tri, normals, offsets, a, b, corners, tol):
    """The solid's part in the cell a x <= b (vertices ``corners``) when it is convex: its
    vertices (None: empty); else a plane (n, d) of a face crossing the cell to cut it by
    (a tuple)."""
    meets, clipped = _meets(tri, a, b, tol)
    if not meets.any():                         # the cell is all inside or all outside
        return corners if _winding(tri, _hull_centroid(corners, ConvexHull(corners))) > 0.5 \
            else None
    piece = corners
    for plane in np.unique(np.round(np.column_stack([normals[meets], offsets[meets]]), 12),
                           axis=0):
        piece = _cut(piece, plane[:3], plane[3], tol)
        if piece is None:
            break
    # convex and connected: every face's part in the cell lies on the piece's boundary, no
    # face cuts into the piece, and the piece is inside the solid
    if piece is not None:
        hull = ConvexHull(piece)
        eq = hull.equations
        on = all(np.all(poly @ eq[:, :3].T + eq[:, 3] <= tol) for poly in clipped)
        if on and not _meets(tri, eq[:, :3], -eq[:, 3], tol)[0].any() \
                and _winding(tri, _hull_centroid(piece, hull)) > 0.5:
            return piece[hull.vertices]
    side = corners @ normals[meets].T - offsets[meets]
    crossing = np.flatnonzero((side.max(axis=0) > tol) & (side.min(axis=0) < -tol))
    if not len(crossing):
        raise _NotExact
    k = np.flatnonzero(meets)[crossing[0]]
    return normals[k], offsets[k]


class _NotExact(Exception):
    """A cell that no face plane cuts holds a non-convex part (not met for closed meshes)."""


def _reflex_cut(ends, planes, a, b, tol):
    """A plane (n, d) of a face at a reflex edge that reaches into the closed cell a x <= b
    when the cell has neither of the edge's face planes on its boundary (a cut along either
    leaves the solid convex at the edge on both sides); the plane most such edges share
    first (an inner floor under two arms: one cut). None: no such edge."""
    if not len(ends):
        return None
    bounds = np.round(np.column_stack([a, b]) / tol)
    keys = np.round(planes / tol)
    resolved = ((keys[:, :, None, :] == bounds[None, None, :, :]).all(axis=3)
                | (keys[:, :, None, :] == -bounds[None, None, :, :]).all(axis=3))
    active = _segments_inside(ends, a, b + 2 * tol, tol) & ~resolved.any(axis=(1, 2))
    if not active.any():
        return None
    candidates = keys[active].reshape(-1, 4)
    shared = (candidates[:, None, :] == candidates[None, :, :]).all(axis=2).sum(axis=1)
    best = planes[active].reshape(-1, 4)[np.argmax(shared)]
    return best[:3], best[3]


def _reflex_edges(vertices, triangles, normals, offsets, tol):
    """(k, 2, 3) end points and (k, 2, 4) planes (n, d) of both faces of each reflex edge:
    an edge whose second face's far vertex lies above the first face's plane by more than
    ``tol``."""
    n = len(vertices)
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    far = np.concatenate([triangles[:, 2], triangles[:, 0], triangles[:, 1]])
    face = np.tile(np.arange(len(triangles)), 3)
    key = edges[:, 0] * n + edges[:, 1]
    reverse = edges[:, 1] * n + edges[:, 0]
    order = np.argsort(key)
    twin = order[np.minimum(np.searchsorted(key[order], reverse), len(key) - 1)]
    mine = np.flatnonzero((key[twin] == reverse) & (edges[:, 0] < edges[:, 1]))
    other = twin[mine]
    height = np.einsum("ij,ij->i", normals[face[mine]], vertices[far[other]]) \
        - offsets[face[mine]]
    hit = height > tol
    first, second = face[mine[hit]], face[other[hit]]
    planes = np.stack([np.column_stack([normals[f], offsets[f]]) for f in (first, second)],
                      axis=1)
    return vertices[edges[mine[hit]]], planes


def _segments_inside(ends, a, b, tol):
    """Whether each segment (k, 2, 3) has a part of length > tol strictly inside the
    halfspaces a x <= b - tol."""
    if not len(ends):
        return np.zeros(0, dtype=bool)
    p, q = ends[:, 0], ends[:, 1]
    s, t = p @ a.T - (b - tol), (q - p) @ a.T           # s + u t <= 0 for u in [0, 1]
    low, high = np.zeros(len(p)), np.ones(len(p))
    with np.errstate(divide="ignore", invalid="ignore"):
        u = -s / t
    low = np.maximum(low, np.where(t < 0, u, -np.inf).max(axis=1))
    high = np.minimum(high, np.where(t > 0, u, np.inf).min(axis=1))
    outside = np.any((np.abs(t) <= 1e-300) & (s > 0), axis=1)
    length = np.linalg.norm(q - p, axis=1)
    return ~outside & ((high - low) * length > tol)


def _meets(tri, a, b, tol):
    """Whether each triangle (m, 3, 3) crosses the interior of the cell a x <= b (its part
    in the cell, by Sutherland-Hodgman clipping, lies in no boundary plane: its centroid is
    more than ``tol`` inside), and those parts."""
    hit = np.zeros(len(tri), dtype=bool)
    bounds = np.einsum("mvk,hk->mvh", tri, a) - b      # (m, 3, h) <= 0 inside
    within = np.all(bounds <= 0.0, axis=(1, 2))         # the whole triangle: no clipping
    hit[within] = np.all(tri[within].mean(axis=1) @ a.T - b < -tol, axis=1)
    parts = list(tri[hit])
    straddle = ~within & ~np.any(np.all(bounds > -tol, axis=1), axis=1)
    for i in np.flatnonzero(straddle):
        poly = tri[i]
        for n, d in zip(a, b):
            if not len(poly):
                break
            poly = _clip(poly, n, d)
        if len(poly) >= 3:
            area = np.linalg.norm(np.cross(poly[1:-1] - poly[0], poly[2:] - poly[0]).sum(0))
            # a convex part not in a boundary plane of the cell has its centroid inside
            if area > tol * tol and np.all(poly.mean(axis=0) @ a.T - b < -tol):
                hit[i] = True
                parts.append(poly)
    return hit, parts


def _clip(poly, n, d):
    """The polygon ``poly`` (k, 3) clipped to n . x <= d."""
    s = poly @ n - d
    out = []
    for k in range(len(poly)):
        j = (k + 1) % len(poly)
        if s[k] <= 0:
            out.append(poly[k])
        if (s[k] < 0 < s[j]) or (s[j] < 0 < s[k]):
            out.append(poly[k] + (poly[j] - poly[k]) * (s[k] / (s[k] - s[j])))
    return np.array(out).reshape(-1, 3)


def _cut(corners, n, d, tol):
    """The vertices of the part n . x <= d of the convex hull of ``corners``; None when it
    has no interior (thinner than ``tol``). Its vertices are among the corners inside and
    the points where the plane crosses the segments between corners on either side."""
    side = corners @ n - d
    if np.all(side <= tol):
        return corners
    if np.all(side >= -tol):
        return None
    inner, outer = corners[side < -tol], corners[side > tol]
    s_in, s_out = side[side < -tol][:, None, None], side[side > tol][None, :, None]
    crossing = inner[:, None] + (outer[None, :] - inner[:, None]) * (s_in / (s_in - s_out))
    points = np.vstack([corners[side <= tol], crossing.reshape(-1, 3)])
    try:
        hull = ConvexHull(points)
    except QhullError:
        return None
    if hull.volume <= tol * float(np.max(np.ptp(points, axis=0))) ** 2:
        return None
    return points[hull.vertices]


def _hull_centroid(points, hull):
    centre = points[hull.vertices].mean(axis=0)
    tri = points[hull.simplices] - centre
    vol = np.abs(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])))
    return centre + (vol[:, None] * tri.sum(axis=1) / 4.0).sum(axis=0) / vol.sum()


def _winding(tri, point):
    """The winding number of the closed triangle mesh ``tri`` about ``point`` (1 inside, 0
    outside): the sum of the triangles' solid angles over 4 pi (Van Oosterom and Strackee)."""
    r = tri - point
    length = np.linalg.norm(r, axis=2)
    a, b, c = r[:, 0], r[:, 1], r[:, 2]
    la, lb, lc = length[:, 0], length[:, 1], length[:, 2]
    numerator = np.einsum("ij,ij->i", a, np.cross(b, c))
    denominator = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc
                   + np.einsum("ij,ij->i", b, c) * la + np.einsum("ij,ij->i", c, a) * lb)
    return float(2.0 * np.arctan2(numerator, denominator).sum() / (4.0 * np.pi))
