"""Automatic detection of contact interfaces between posed blocks.

Two blocks touch face to face where a face of one and a face of the other have opposite
normals and lie in one plane, within tolerances relative to the smaller block; the interface
is the intersection of the two face outlines. A sweep over axis-aligned bounding boxes keeps
the face tests to pairs of blocks that can touch.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from .block import PosedBlock
from .kern import kern
from .polygon import PlaneFrame, drop_collinear


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

    def kern(self) -> np.ndarray:
        """Kern vertices in world coordinates."""
        return self.frame.to_3d(kern(self.polygon2d()))


def candidate_pairs(blocks: list[PosedBlock], margin: float) -> list[tuple[int, int]]:
    """Pairs (i < j) of blocks whose bounding boxes, grown by ``margin``, overlap."""
    if len(blocks) < 2:
        return []
    lo = np.array([b.aabb[0] for b in blocks]) - margin
    hi = np.array([b.aabb[1] for b in blocks]) + margin
    order = np.argsort(lo[:, 0], kind="stable")
    starts = lo[order, 0]
    pairs = []
    for k, i in enumerate(order):
        end = np.searchsorted(starts, hi[i, 0], side="right")
        for j in order[k + 1:end]:
            if np.all(lo[j] <= hi[i]) and np.all(lo[i] <= hi[j]):
                pairs.append((min(i, j), max(i, j)))
    return sorted(pairs)


def detect_interfaces(blocks: list[PosedBlock], options: ContactOptions = ContactOptions()
                      ) -> list[Interface]:
    """Every face-to-face interface between the blocks (deterministic order)."""
    margin = options.distance_tol * max(b.size for b in blocks) if blocks else 0.0
    out: list[Interface] = []
    for i, j in candidate_pairs(blocks, margin):
        out.extend(_pair_interfaces(i, j, blocks[i], blocks[j], options))
    return out


def _pair_interfaces(i: int, j: int, a: PosedBlock, b: PosedBlock, options: ContactOptions):
    scale = min(a.size, b.size)
    cos_tol = np.cos(np.radians(options.angle_tol_deg))
    for fa in a.faces:
        for fb in b.faces:
            if fa.frame.n @ fb.frame.n > -cos_tol:
                continue
            if abs(fa.frame.n @ fb.frame.origin - fa.offset) > options.distance_tol * scale:
                continue
            outline_b = shapely.transform(fb.outline, lambda c: fa.frame.to_2d(fb.frame.to_3d(c)))
            overlap = fa.outline.intersection(outline_b)
            for piece in getattr(overlap, "geoms", [overlap]):
                if isinstance(piece, shapely.Polygon) and piece.area > options.min_area * scale ** 2:
                    yield _interface(i, j, fa.frame, piece, COLLINEAR_TOL * scale)


def _interface(i: int, j: int, face_frame: PlaneFrame, piece: shapely.Polygon,
               collinear_tol: float) -> Interface:
    """The interface of one overlap polygon. Near-collinear vertices, which clipping leaves on
    straight edges, are dropped: as force points they would skew the QP's spread of forces."""
    ring = shapely.geometry.polygon.orient(piece, 1.0)     # counter-clockwise about n
    pts2d = drop_collinear(np.asarray(ring.exterior.coords)[:-1], collinear_tol)
    pts = face_frame.to_3d(pts2d)
    edges = np.roll(pts, -1, axis=0) - pts
    lengths = np.linalg.norm(edges, axis=1)
    u = edges[int(np.argmax(lengths))] / lengths.max()
    n = face_frame.n
    centroid = face_frame.to_3d(np.array(piece.centroid.coords))[0]
    frame = PlaneFrame(centroid, u, np.cross(n, u), n)
    return Interface(i, j, frame, pts, float(piece.area))
