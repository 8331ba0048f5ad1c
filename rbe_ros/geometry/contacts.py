"""Automatic detection of contact interfaces between posed blocks.

Two blocks touch face to face where a face of one and a face of the other have opposite
normals and lie in one plane, within tolerances relative to the smaller block; the interface
is the intersection of the two face outlines. A sweep over axis-aligned bounding boxes keeps
the face tests to pairs of blocks that can touch. Overlaps thinner than an edge contact are
dropped and vertices that add no corner are removed (:class:`ContactOptions`: min_width,
vertex_tol), so the equilibrium problem is no larger than the answer needs.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import shapely

from ..deadline import checkpoint
from .block import PosedBlock
from .clip import clip_convex, padded_rings
from .kern import kern, kerns_ragged
from .polygon import (PlaneFrame, cross, drop_collinear_rings, first_argmin, ring_neighbours,
                      ring_widths)
from .uncertainty import NEAR_FACTOR, allowances, contact_angle_deg, gaps, mid_frames


@dataclass(frozen=True)
class ContactOptions:
    """Tolerances, relative to the smaller block's size (cube root of its volume).

    Fidelity: a contact is modelled no finer than the answer needs, since the conic problem
    grows with every interface vertex (its solve time roughly with their number).

    - ``min_width``: an overlap polygon thinner than this (its smallest extent perpendicular
      to one of its edges) is dropped. Within the tolerances it is an edge contact (the
      faces meet along a line, as at the slivers an imperfect mesh leaves between two faces
      that only touch at a rim): it has next to no area, so its compression cannot carry a
      moment worth modelling, yet it would add a full interface to the problem.
    - ``vertex_tol``: a vertex closer than this to the line through its neighbours is
      dropped (greedily, the least significant first, down to 3 vertices). Clipping leaves
      such vertices on straight edges, and meshes exported with noise leave almost straight
      corners; as force points they add unknowns but no moment capacity. For a convex
      polygon the result lies inside the original (an inner approximation: the polygon only
      shrinks, so a stable verdict stays safe). As ``min_width >= vertex_tol``, the corners
      that give a kept polygon its width (about that width away from their neighbours'
      chord) survive. The interface's ``area`` and frame origin (centroid) remain those of
      the exact overlap.

    Both compare strictly ("thinner than", "closer than"): at 0 they keep everything. All
    options must be finite and >= 0 (ValueError).
    """

    distance_tol: float = 1e-3      # gap or overlap between the two face planes
    angle_tol_deg: float = 1.0      # deviation of the normals from exactly opposite
    min_area: float = 1e-6          # smallest interface area, relative to size^2
    min_width: float = 1e-3         # thinnest interface polygon kept (edge contacts go)
    vertex_tol: float = 1e-3        # vertices this close to their neighbours' chord go
    #: Declared pose uncertainty (about 3 sigma of the measured poses): position in m, angle
    #: in deg. 0 and 0: design geometry (the rule above, one face's plane). Otherwise the
    #: rules of :mod:`rbe_ros.geometry.uncertainty` (tolerances grown by what the
    #: uncertainty explains, symmetric interfaces on the mid-plane of the two faces).
    pose_uncertainty_m: float = 0.0
    pose_uncertainty_deg: float = 0.0

    def __post_init__(self):
        for name in ("distance_tol", "angle_tol_deg", "min_area", "min_width", "vertex_tol",
                     "pose_uncertainty_m", "pose_uncertainty_deg"):
            value = getattr(self, name)
            if (isinstance(value, bool) or not isinstance(value, numbers.Real)
                    or not math.isfinite(value) or value < 0):
                raise ValueError(f"contact option {name} must be a finite number >= 0, "
                                 f"not {value!r}")

    @property
    def uncertain(self) -> bool:
        """Whether a pose uncertainty is declared (the as-built rules apply)."""
        return self.pose_uncertainty_m > 0 or self.pose_uncertainty_deg > 0


@dataclass(frozen=True)
class Interface:
    """A planar contact polygon between blocks a and b (indices into the block list).

    ``frame.n`` points from a into b; ``frame.u`` follows the polygon's longest edge.
    ``points`` are the polygon vertices (world) at which the contact forces act. ``gap``
    (m) is how far apart the two faces are (negative: they overlap), the largest over the
    polygon, and ``tol`` (m) the largest gap that makes them a contact.
    """

    a: int
    b: int
    frame: PlaneFrame
    points: np.ndarray
    area: float
    gap: float = 0.0
    tol: float = 0.0

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
        if not todo:
            return
        counts = np.array([len(it.points) for it in todo])
        rep = np.repeat(np.arange(len(todo)), counts)
        origin = np.array([it.frame.origin for it in todo])[rep]
        u = np.array([it.frame.u for it in todo])[rep]
        v = np.array([it.frame.v for it in todo])[rep]
        d = np.concatenate([it.points for it in todo]) - origin
        ring2d = np.column_stack((np.einsum("ij,ij->i", d, u), np.einsum("ij,ij->i", d, v)))
        pts, counts = kerns_ragged(ring2d, counts)
        rep = np.repeat(np.arange(len(todo)), counts)
        world = _lift(pts, *(np.array([getattr(it.frame, k) for it in todo])[rep]
                             for k in ("origin", "u", "v")))
        for it, k in zip(todo, np.split(world, np.cumsum(counts)[:-1])):
            it.__dict__["kern"] = k

    def between(self, a: int, b: int) -> "Interface":
        """The same contact between blocks renumbered ``a`` and ``b``, sharing the kern
        (direct construction, not dataclasses.replace: a sequence check renumbers every
        interface at every step)."""
        out = Interface(a, b, self.frame, self.points, self.area, self.gap, self.tol)
        out.__dict__["kern"] = self.kern
        return out


def candidate_pairs(blocks: list[PosedBlock], margin: float) -> np.ndarray:
    """Pairs (i < j), sorted, of blocks whose bounding boxes grown by ``margin`` overlap.

    Sweep and prune along the axis where the blocks spread most: sort by the lower bound, each
    block meets the blocks that start before it ends; then all three axes are tested at once.
    """
    if len(blocks) < 2:
        return np.zeros((0, 2), dtype=int)
    boxes = np.array([b.aabb for b in blocks])
    lo, hi = boxes[:, 0] - margin, boxes[:, 1] + margin
    axis = int(np.argmax(np.ptp(lo + hi, axis=0)))
    order = np.argsort(lo[:, axis], kind="stable")
    starts = lo[order, axis]
    ends = np.searchsorted(starts, hi[order, axis], side="right")
    counts = np.maximum(ends - np.arange(len(order)) - 1, 0)
    first = np.repeat(np.arange(len(order)), counts)
    second = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts) + first + 1
    i, j = order[first], order[second]
    keep = np.ones(len(i), dtype=bool)
    for lo_k, hi_k in zip(lo.T, hi.T):        # one axis at a time: 1D gathers are cheaper
        keep &= (lo_k[i] <= hi_k[j]) & (lo_k[j] <= hi_k[i])
    pairs = np.sort(np.column_stack((i[keep], j[keep])), axis=1)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def detect_interfaces(blocks: list[PosedBlock], options: ContactOptions = ContactOptions()
                      ) -> list[Interface]:
    """Every face-to-face interface between the blocks (deterministic order); see
    :func:`detect_contacts`."""
    return detect_contacts(blocks, options)[0]


def detect_contacts(blocks: list[PosedBlock], options: ContactOptions = ContactOptions()
                    ) -> tuple[list[Interface], list[Interface]]:
    """Every face-to-face interface between the blocks, and the near contacts (face pairs
    beyond the distance tolerance but within NEAR_FACTOR times it), deterministic order.

    Batched: face pairs of all candidate block pairs are screened in one numpy pass (opposite
    normals, one plane), the survivors' outlines are clipped against each other all at once
    (Sutherland-Hodgman in numpy, :func:`rbe_ros.geometry.clip.clip_convex`; shapely for
    faces of non-convex blocks), and the overlap polygons are then treated all at once as
    ragged arrays (vertices one polygon after another): width and vertex filters (see
    :class:`ContactOptions`), frames and lifting to 3D. Kerns are left to
    :meth:`Interface.compute_kerns` (batched) or to :attr:`Interface.kern` (on first use).
    With a declared pose uncertainty the tolerances and the interface plane follow
    :mod:`rbe_ros.geometry.uncertainty`.
    """
    if len(blocks) < 2:
        return [], []
    allow = allowances(blocks, options.pose_uncertainty_m, options.pose_uncertainty_deg)
    sizes = np.array([b.size for b in blocks])
    margin = NEAR_FACTOR * (options.distance_tol * sizes.max() + 2 * allow.max())
    pairs = candidate_pairs(blocks, margin)
    face_count = np.array([len(b.face_offsets) for b in blocks])
    face_start = np.concatenate(([0], np.cumsum(face_count)[:-1]))
    normals = np.concatenate([b.face_normals for b in blocks])
    origins = np.concatenate([b.face_origins for b in blocks])
    offsets = np.concatenate([b.face_offsets for b in blocks])
    us = np.concatenate([b.face_us for b in blocks])
    vs = np.concatenate([b.face_vs for b in blocks])
    outlines = np.concatenate([b.face_outlines for b in blocks])

    # faces of the candidate pairs with opposite normals, then those in one plane (or near)
    angle = contact_angle_deg(options.angle_tol_deg, options.pose_uncertainty_deg)
    pair_of, fa, fb = _facing(pairs, face_count, face_start, normals, -np.cos(np.radians(angle)))
    first, second = pairs[pair_of, 0], pairs[pair_of, 1]
    scale = np.minimum(sizes[first], sizes[second])
    tol = options.distance_tol * scale + (allow[first] + allow[second])
    gap = np.einsum("ij,ij->i", normals[fa], origins[fb]) - offsets[fa]
    reach = NEAR_FACTOR * tol
    if options.uncertain:       # tilted faces: face b's origin may be off the overlap
        tilt = 1 + np.einsum("ij,ij->i", normals[fa], normals[fb])
        reach = reach + np.sqrt(np.maximum(2 * tilt, 0.0)) * np.ptp(
            np.array([b.aabb for b in blocks])[second], axis=1).max(axis=1)
    keep = np.abs(gap) <= reach
    fa, fb, pair_of, scale, tol, gap = (x[keep] for x in (fa, fb, pair_of, scale, tol, gap))
    if not len(fa):
        return [], []

    checkpoint()
    # the overlap of the two outlines, in the frame of face a (or of the mid-plane)
    outline_a, outline_b = outlines[fa], outlines[fb]
    if options.uncertain:
        f_o, f_u, f_v, f_n = mid_frames(normals[fa], offsets[fa], origins[fa], normals[fb],
                                        offsets[fb], origins[fb])
        coords_a, index_a = _in_frames(outline_a, origins[fa], us[fa], vs[fa], f_o, f_u, f_v)
        outline_a = shapely.set_coordinates(outline_a, coords_a)
    else:
        f_o, f_u, f_v, f_n = origins[fa], us[fa], vs[fa], normals[fa]
        coords_a, index_a = shapely.get_coordinates(outline_a, return_index=True)
    coords_b, index_b = _in_frames(outline_b, origins[fb], us[fb], vs[fb], f_o, f_u, f_v)
    box_a, box_b = _bounds(coords_a, index_a, len(fa)), _bounds(coords_b, index_b, len(fa))
    meet = (np.all(box_a[:, :2] <= box_b[:, 2:], axis=1)
            & np.all(box_b[:, :2] <= box_a[:, 2:], axis=1))
    simple = ((shapely.get_type_id(outline_a) == shapely.GeometryType.POLYGON)
              & (shapely.get_num_interior_rings(outline_a) == 0)
              & (shapely.get_type_id(outline_b) == shapely.GeometryType.POLYGON)
              & (shapely.get_num_interior_rings(outline_b) == 0))
    meet = np.flatnonzero(meet & ~_apart_or_thin(coords_a, index_a, coords_b, index_b, simple,
                                                 scale, 0.5 * options.min_width * scale))
    ring, counts, owner, area, centroid2d = _overlaps(outline_a, coords_a, index_a, outline_b,
                                                      coords_b, index_b, simple, scale, meet)
    checkpoint()
    ok = area > options.min_area * scale[owner] ** 2
    if not ok.all():
        ring, counts = ring[np.repeat(ok, counts)], counts[ok]
        owner, area, centroid2d = owner[ok], area[ok], centroid2d[ok]
    if not len(owner):
        return [], []
    size = scale[owner]

    # edge contacts go: area <= width * diameter <= width * bounding-box diagonal, so only
    # rings with area < min width * diagonal need their width measured
    least = options.min_width * size
    starts = np.cumsum(counts) - counts
    extent = np.maximum.reduceat(ring, starts) - np.minimum.reduceat(ring, starts)
    thick = area >= least * np.sqrt(extent[:, 0] ** 2 + extent[:, 1] ** 2)
    if not thick.all():
        maybe = np.flatnonzero(~thick)
        thick[maybe] = ring_widths(ring[np.repeat(~thick, counts)], counts[maybe]) >= least[maybe]
    if not thick.all():
        ring, counts = ring[np.repeat(thick, counts)], counts[thick]
        owner, area, centroid2d, size = owner[thick], area[thick], centroid2d[thick], size[thick]
        if not len(owner):
            return [], []
    ring, counts = drop_collinear_rings(ring, counts, options.vertex_tol * size)

    # lifted to 3D; frames: n of face a (or of the mid-plane), u along the longest edge,
    # origin at the centroid
    rep = np.repeat(np.arange(len(counts)), counts)
    o, fu, fv, n = f_o[owner], f_u[owner], f_v[owner], f_n[owner]
    pts = _lift(ring, o[rep], fu[rep], fv[rep])
    _, nxt = ring_neighbours(counts)
    edges = pts[nxt] - pts
    lengths = np.sqrt(np.einsum("ij,ij->i", edges, edges))
    longest = first_argmin(-lengths, counts)
    u = edges[longest] / lengths[longest][:, None]
    v = cross(n, u)
    centroid = _lift(centroid2d, o, fu, fv)
    gap = gap[owner]
    if options.uncertain:       # the gap along n at every vertex; the largest counts
        face_a, face_b = fa[owner][rep], fb[owner][rep]
        at = gaps(pts, n[rep], normals[face_a], offsets[face_a], normals[face_b],
                  offsets[face_b])
        gap = at[first_argmin(-np.abs(at), counts)]
    within = (np.abs(gap) <= tol[owner]).tolist()

    pair = pairs[pair_of[owner]]
    ends = np.cumsum(counts).tolist()
    found = ([], [])
    for i, j, oo, uu, vv, nn, s, e, a, g, t, w in zip(
            pair[:, 0].tolist(), pair[:, 1].tolist(), centroid, u, v, n, [0] + ends[:-1], ends,
            area.tolist(), gap.tolist(), tol[owner].tolist(), within):
        found[not w].append(Interface(i, j, PlaneFrame(oo, uu, vv, nn), pts[s:e], a, g, t))
    return found


def _facing(pairs: np.ndarray, face_count: np.ndarray, face_start: np.ndarray,
            normals: np.ndarray, limit: float):
    """Every face a of block i and face b of block j, for each candidate pair (i, j), whose
    normals' dot product is below ``limit``, in order (pair, a, b): the pair indices and the
    two face indices. One batched matrix product of the pairs' normals (faces padded to
    the largest count) when that is not much more work than the face pairs themselves."""
    fa_n, fb_n = face_count[pairs[:, 0]], face_count[pairs[:, 1]]
    combos = fa_n * fb_n
    most = int(face_count.max())
    if len(pairs) * most * most <= 4 * int(combos.sum()):
        padded = np.full((len(face_count), most, 3), np.nan)     # NaN: never below limit
        owner = np.repeat(np.arange(len(face_count)), face_count)
        padded[owner, np.arange(len(normals)) - face_start[owner]] = normals
        dots = np.matmul(padded[pairs[:, 0]], padded[pairs[:, 1]].transpose(0, 2, 1))
        pair_of, a, b = np.nonzero(dots < limit)
        return pair_of, face_start[pairs[pair_of, 0]] + a, face_start[pairs[pair_of, 1]] + b
    pair_of = np.repeat(np.arange(len(pairs)), combos)
    k = np.arange(combos.sum()) - np.repeat(np.cumsum(combos) - combos, combos)
    fa = face_start[pairs[pair_of, 0]] + k // fb_n[pair_of]
    fb = face_start[pairs[pair_of, 1]] + k % fb_n[pair_of]
    keep = np.einsum("ij,ij->i", normals[fa], normals[fb]) < limit
    return pair_of[keep], fa[keep], fb[keep]


def _lift(points2d: np.ndarray, origin: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """2D points to 3D, row by row in the frame (origin, u, v) of each row (as PlaneFrame.to_3d)."""
    return origin + points2d[:, :1] * u + points2d[:, 1:2] * v


def _in_frames(geoms: np.ndarray, src_o, src_u, src_v, dst_o, dst_u, dst_v):
    """The coordinates of each outline, given in the 2D coordinates of the frame (src_o,
    src_u, src_v) of its row, in the 2D coordinates of the matching destination frame (affine
    maps of the plane, applied to all coordinates at once), and the row of each."""
    coords, index = shapely.get_coordinates(geoms, return_index=True)
    world = (src_o[index] + coords[:, :1] * src_u[index] + coords[:, 1:2] * src_v[index]
             - dst_o[index])
    coords = np.column_stack((np.einsum("ij,ij->i", world, dst_u[index]),
                              np.einsum("ij,ij->i", world, dst_v[index])))
    return coords, index


def _bounds(coords: np.ndarray, index: np.ndarray, n: int) -> np.ndarray:
    """(n, 4) xmin, ymin, xmax, ymax of each of n outlines (every one has coordinates), from
    their coordinates and the outline of each (sorted), as shapely.bounds."""
    starts = np.searchsorted(index, np.arange(n))
    return np.hstack((np.minimum.reduceat(coords, starts), np.maximum.reduceat(coords, starts)))


#: Clipping tolerance, relative to the smaller block's size: a vertex closer than this to a
#: clip edge's line is on it, closer vertices merge, thinner overlaps are edge contacts. Far
#: below the contact options' defaults, far above the rounding of the face coordinates
#: (~1e-16 of the scene's extent); as _convex_ring's allowance for rounding (1e-12 size^2).
_CLIP_TOL = 1e-12


def _overlaps(outline_a, coords_a, index_a, outline_b, coords_b, index_b, simple, scale, rows):
    """The overlap polygons of the outline pairs ``rows`` (b's coordinates in a's frame):
    their rings (counter-clockwise, without the closing vertex, one after another), vertex
    counts, the pair of each, areas and centroids, in the order of ``rows``. Two convex
    simple outlines (all faces of convex blocks) are clipped in numpy (:func:`clip_convex`);
    other pairs (faces of non-convex blocks) by shapely, which may give several pieces."""
    if not len(rows):
        return np.zeros((0, 2)), np.zeros(0, dtype=np.intp), rows, np.zeros(0), np.zeros((0, 2))
    ax, ay, na, convex_a = padded_rings(coords_a, index_a, rows, scale[rows])
    bx, by, nb, convex_b = padded_rings(coords_b, index_b, rows, scale[rows])
    convex = simple[rows] & convex_a & convex_b
    ring, counts, of, area, centroid = clip_convex(
        ax[convex], ay[convex], na[convex], bx[convex], by[convex], nb[convex],
        _CLIP_TOL * scale[rows[convex]])
    out = ring, counts, rows[convex][of], area, centroid
    if convex.all():
        return out
    other = rows[~convex]
    moved = shapely.set_coordinates(outline_b[other], coords_b[np.isin(index_b, other)])
    ring, counts, owner, area, centroid = (np.concatenate(x) for x in zip(
        out, _shapely_overlaps(outline_a[other], moved, other)))
    order = np.argsort(owner, kind="stable")             # back to the order of rows
    first = np.cumsum(counts) - counts
    take = (np.repeat(first[order] - np.cumsum(counts[order]) + counts[order], counts[order])
            + np.arange(counts.sum()))
    return ring[take], counts[order], owner[order], area[order], centroid[order]


def _shapely_overlaps(outline_a, outline_b, rows):
    """As :func:`_overlaps`, by shapely, for any two outlines (``rows``: the pair of each):
    every polygon piece of each overlap, its exterior ring turned counter-clockwise."""
    overlap = shapely.intersection(outline_a, outline_b)
    pieces, owner = shapely.get_parts(overlap, return_index=True)
    keep = (shapely.get_type_id(pieces) == shapely.GeometryType.POLYGON) & ~shapely.is_empty(
        pieces)
    pieces, owner = pieces[keep], rows[owner[keep]]
    exterior = shapely.get_exterior_ring(pieces)
    coords, ring_of = shapely.get_coordinates(exterior, return_index=True)
    counts = np.bincount(ring_of, minlength=len(pieces)) - 1
    begin = np.cumsum(counts + 1) - counts - 1
    ccw = np.repeat(shapely.is_ccw(exterior), counts)
    step = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    step = np.where(ccw, step, np.repeat(counts, counts) - 1 - step)      # reversed if clockwise
    ring = coords[np.repeat(begin, counts) + step]
    return (ring, counts, owner, shapely.area(pieces),
            shapely.get_coordinates(shapely.centroid(pieces)))


#: Outlines of more coordinates than this are not screened by _apart_or_thin.
_SCREEN_MAX = 16


def _apart_or_thin(coords_a, index_a, coords_b, index_b, simple, scale, thin) -> np.ndarray:
    """Per pair of outlines (coordinates of a and b with the pair of each), whether their
    overlap certainly yields no interface, so that it need not be computed: they are
    apart (their projections on an edge normal of either are separated by more than 1e-9 of
    ``scale``), or they are both convex simple polygons (``simple``: one exterior ring each)
    and their overlap, convex too, is thinner than ``thin`` (its width is at most the
    overlap of the projections on any direction; ``thin`` is half the width below which
    the overlap is dropped, a margin for rounding). Vectorised over the outlines of at most
    _SCREEN_MAX coordinates, padded to one count (arrays with the vertex or edge first: numpy
    reduces fastest over the first axis); larger ones are not screened."""
    n = len(simple)
    out = np.zeros(n, dtype=bool)
    count_a, count_b = np.bincount(index_a, minlength=n), np.bincount(index_b, minlength=n)
    rows = np.flatnonzero((count_a <= _SCREEN_MAX) & (count_b <= _SCREEN_MAX)
                          & (count_a > 0) & (count_b > 0))
    if not len(rows):
        return out
    count_a, count_b = count_a[rows], count_b[rows]
    k = int(max(count_a.max(), count_b.max()))
    ax, ay = _padded(coords_a, index_a, rows, count_a, k)               # (k, m) each
    bx, by = _padded(coords_b, index_b, rows, count_b, k)
    eax, eay, ebx, eby = ax[1:] - ax[:-1], ay[1:] - ay[:-1], bx[1:] - bx[:-1], by[1:] - by[:-1]
    ex, ey = np.concatenate((eax, ebx)), np.concatenate((eay, eby))    # (d, m): all edges
    length = np.sqrt(ex * ex + ey * ey)
    safe = np.where(length > 0, length, 1.0)
    nx, ny = -ey / safe, ex / safe
    proj_a = ax[:, None] * nx + ay[:, None] * ny                        # (k, d, m)
    proj_b = bx[:, None] * nx + by[:, None] * ny
    overlap = (np.minimum(proj_a.max(axis=0), proj_b.max(axis=0))
               - np.maximum(proj_a.min(axis=0), proj_b.min(axis=0)))    # (d, m)
    bound = np.where(length > 0, overlap, np.inf).min(axis=0)
    size = scale[rows]
    convex = (simple[rows] & _convex_ring(eax, eay, count_a, size)
              & _convex_ring(ebx, eby, count_b, size))
    out[rows] = (bound < -1e-9 * size) | (convex & (bound < thin[rows]))
    return out


def _padded(coords: np.ndarray, index: np.ndarray, rows: np.ndarray, count: np.ndarray,
            k: int) -> tuple[np.ndarray, np.ndarray]:
    """x and y (k, m) of the geometries ``rows`` (``count`` coordinates each), each padded
    by repeating its first coordinate (which adds no edge and no extreme)."""
    start = np.searchsorted(index, rows)
    j = np.arange(k)[:, None]
    take = np.where(j < count, start + j, start)
    return coords[:, 0][take], coords[:, 1][take]


def _convex_ring(ex: np.ndarray, ey: np.ndarray, count: np.ndarray, size: np.ndarray
                 ) -> np.ndarray:
    """Whether each closed ring, given by its padded edges (x and y, k - 1 by m; ``count``
    coordinates with the closing one), turns one way only (to rounding: 1e-12 of size^2)."""
    turn = ex[:-1] * ey[1:] - ey[:-1] * ex[1:]
    m = np.arange(len(count))
    last_x, last_y = ex[count - 2, m], ey[count - 2, m]        # the closing edge, into the start
    turn = np.concatenate((turn, (last_x * ey[0] - last_y * ex[0])[None]))
    eps = 1e-12 * size ** 2
    return np.all(turn >= -eps, axis=0) | np.all(turn <= eps, axis=0)
