"""Automatic detection of contact interfaces between posed blocks.

Two blocks touch face to face where a face of one and a face of the other have opposite
normals and lie in one plane, within tolerances relative to the smaller block; the interface
is the intersection of the two face outlines. A sweep over axis-aligned bounding boxes keeps
the face tests to pairs of blocks that can touch.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
import shapely

from .block import PosedBlock
from .kern import kern, kerns
from .polygon import PlaneFrame, cross, drop_collinear


#: Vertices closer than this share of the block size to the line of their neighbours go.
COLLINEAR_TOL = 1e-6


@dataclass(frozen=True)
class ContactOptions:
    """Tolerances, relative to the smaller block's size (cube root of its volume)."""

    distance_tol: float = 1e-3      # gap or overlap between the two face planes
    angle_tol_deg: float = 1.0      # deviation of the normals from exactly opposite
    min_area: float = 1e-6          # smallest interface area, relative to size^2


@dataclass(frozen=True)
class Interface:
    """A planar contact polygon between blocks a and b (indices into the block list).

    ``frame.n`` points from a into b; ``frame.u`` follows the polygon's longest edge.
    ``points`` are the polygon vertices (world) at which the contact forces act.
    """

    a: int
    b: int
    frame: PlaneFrame
    points: np.ndarray
    area: float

    def polygon2d(self) -> np.ndarray:
        return self.frame.to_2d(self.points)

    @cached_property
    def kern(self) -> np.ndarray:
        """Kern vertices in world coordinates (computed once: results of every solve use it)."""
        return self.frame.to_3d(kern(self.polygon2d()))

    @staticmethod
    def compute_kerns(interfaces) -> None:
        """Compute the kerns of many interfaces at once (vectorised) into their caches."""
        todo = [it for it in interfaces if "kern" not in it.__dict__]
        for it, k in zip(todo, kerns([it.polygon2d() for it in todo])):
            it.__dict__["kern"] = it.frame.to_3d(k)

    def between(self, a: int, b: int) -> "Interface":
        """The same contact between blocks renumbered ``a`` and ``b``, sharing the kern."""
        out = replace(self, a=a, b=b)
        out.__dict__["kern"] = self.kern
        return out


def candidate_pairs(blocks: list[PosedBlock], margin: float) -> np.ndarray:
    """Pairs (i < j), sorted, of blocks whose bounding boxes grown by ``margin`` overlap.

    Sweep and prune along the axis where the blocks spread most: sort by the lower bound, each
    block meets the blocks that start before it ends; then all three axes are tested at once.
    """
    if len(blocks) < 2:
        return np.zeros((0, 2), dtype=int)
    lo = np.array([b.aabb[0] for b in blocks]) - margin
    hi = np.array([b.aabb[1] for b in blocks]) + margin
    axis = int(np.argmax(np.ptp(lo + hi, axis=0)))
    order = np.argsort(lo[:, axis], kind="stable")
    starts = lo[order, axis]
    ends = np.searchsorted(starts, hi[order, axis], side="right")
    counts = np.maximum(ends - np.arange(len(order)) - 1, 0)
    first = np.repeat(np.arange(len(order)), counts)
    second = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts) + first + 1
    i, j = order[first], order[second]
    keep = np.all(lo[i] <= hi[j], axis=1) & np.all(lo[j] <= hi[i], axis=1)
    pairs = np.sort(np.column_stack((i[keep], j[keep])), axis=1)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def detect_interfaces(blocks: list[PosedBlock], options: ContactOptions = ContactOptions()
                      ) -> list[Interface]:
    """Every face-to-face interface between the blocks (deterministic order).

    Batched: face pairs of all candidate block pairs are screened in one numpy pass (opposite
    normals, one plane), and the polygon work of the survivors runs in vectorised shapely calls.
    """
    if len(blocks) < 2:
        return []
    margin = options.distance_tol * max(b.size for b in blocks)
    pairs = candidate_pairs(blocks, margin)
    face_count = np.array([len(b.faces) for b in blocks])
    face_start = np.concatenate(([0], np.cumsum(face_count)[:-1]))
    normals = np.concatenate([b.face_normals for b in blocks])
    origins = np.concatenate([b.face_origins for b in blocks])
    offsets = np.concatenate([b.face_offsets for b in blocks])
    faces = [f for b in blocks for f in b.faces]
    sizes = np.array([b.size for b in blocks])

    # every face of block i against every face of block j, for all candidate pairs
    fa_n, fb_n = face_count[pairs[:, 0]], face_count[pairs[:, 1]]
    combos = fa_n * fb_n
    pair_of = np.repeat(np.arange(len(pairs)), combos)
    k = np.arange(combos.sum()) - np.repeat(np.cumsum(combos) - combos, combos)
    fa = face_start[pairs[pair_of, 0]] + k // fb_n[pair_of]
    fb = face_start[pairs[pair_of, 1]] + k % fb_n[pair_of]
    scale = np.minimum(sizes[pairs[pair_of, 0]], sizes[pairs[pair_of, 1]])
    facing = np.einsum("ij,ij->i", normals[fa], normals[fb]) < -np.cos(np.radians(options.angle_tol_deg))
    gap = np.abs(np.einsum("ij,ij->i", normals[fa], origins[fb]) - offsets[fa])
    keep = facing & (gap <= options.distance_tol * scale)
    fa, fb, pair_of, scale = fa[keep], fb[keep], pair_of[keep], scale[keep]
    if not len(fa):
        return []

    outline_a = np.array([faces[f].outline for f in fa], dtype=object)
    outline_b = _in_frames([faces[f] for f in fb], [faces[f].frame for f in fa])
    overlap = shapely.intersection(outline_a, outline_b)
    pieces, owner = shapely.get_parts(overlap, return_index=True)
    is_polygon = shapely.get_type_id(pieces) == shapely.GeometryType.POLYGON
    area = shapely.area(pieces)
    ok = is_polygon & (area > options.min_area * scale[owner] ** 2)
    pieces, owner, area = pieces[ok], owner[ok], area[ok]
    rings, ring_of = shapely.get_coordinates(shapely.get_exterior_ring(pieces), return_index=True)
    bounds = np.searchsorted(ring_of, np.arange(len(pieces) + 1))
    ccw = shapely.is_ccw(shapely.get_exterior_ring(pieces))
    centroids = shapely.get_coordinates(shapely.centroid(pieces))
    out = []
    for m in range(len(pieces)):
        ring = rings[bounds[m]:bounds[m + 1] - 1]          # the closing point repeats the first
        pair = pairs[pair_of[owner[m]]]
        out.append(_interface(int(pair[0]), int(pair[1]), faces[fa[owner[m]]].frame,
                              ring if ccw[m] else ring[::-1], centroids[m], float(area[m]),
                              COLLINEAR_TOL * scale[owner[m]]))
    return out


def _in_frames(faces, frames) -> np.ndarray:
    """Each face's outline in the 2D coordinates of the matching frame (affine maps of the
    plane, applied to all coordinates at once)."""
    geoms = np.array([f.outline for f in faces], dtype=object)
    _, index = shapely.get_coordinates(geoms, return_index=True)
    src_o = np.array([f.frame.origin for f in faces])
    src_u = np.array([f.frame.u for f in faces])
    src_v = np.array([f.frame.v for f in faces])
    dst_o = np.array([f.origin for f in frames])
    dst_u = np.array([f.u for f in frames])
    dst_v = np.array([f.v for f in frames])

    def to_dst(coords):
        world = (src_o[index] + coords[:, :1] * src_u[index] + coords[:, 1:2] * src_v[index]
                 - dst_o[index])
        return np.column_stack((np.einsum("ij,ij->i", world, dst_u[index]),
                                np.einsum("ij,ij->i", world, dst_v[index])))

    return shapely.transform(geoms, to_dst)


def _interface(i: int, j: int, face_frame: PlaneFrame, ring: np.ndarray, centroid2d: np.ndarray,
               area: float, collinear_tol: float) -> Interface:
    """The interface of one overlap polygon (counter-clockwise ``ring`` in the face frame).
    Near-collinear vertices, which clipping leaves on straight edges, are dropped: as force
    points they would skew the QP's spread of forces."""
    pts = face_frame.to_3d(drop_collinear(ring, collinear_tol))
    edges = np.concatenate((pts[1:], pts[:1])) - pts
    lengths = np.sqrt(np.einsum("ij,ij->i", edges, edges))
    longest = int(np.argmax(lengths))
    u = edges[longest] / lengths[longest]
    n = face_frame.n
    centroid = face_frame.to_3d(centroid2d[None, :])[0]
    return Interface(i, j, PlaneFrame(centroid, u, cross(n, u), n), pts, area)
