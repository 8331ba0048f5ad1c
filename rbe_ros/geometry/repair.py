"""Meshes as they come: repair open or inconsistently wound meshes that are closed within a
tolerance, at load, and say what was repaired.

Exported meshes often arrive as triangle soups (every vertex repeated per triangle), with a
few triangles missing (open edges) or turned inside out. A block must be a closed, outward
wound polyhedron (:mod:`rbe_ros.geometry.block`), so :func:`repair_mesh` first leaves a mesh
that is one untouched, and otherwise, in this order:

1. merges vertices closer than MERGE_TOL times the mesh's longest extent (a k-d tree) and
   drops degenerate and repeated triangles (trimesh);
2. makes the winding consistent (trimesh's ``fix_winding``), then outward (every face turned
   when the signed volume of the closed mesh is negative);
3. closes every hole whose boundary is one loop: planar within PLANAR_TOL times the extent,
   the loop becomes one polygon face (wound against its boundary edges), whatever its shape
   (a fan of triangles would fold over a non-convex hole); else (triangles missing across an
   edge or a corner of the block) a fan from one of its vertices whose every triangle lies
   in the plane of a face along the hole;
4. when the closed mesh is convex (its volume within HULL_TOL of its convex hull's), replaces
   it by that hull, so that the checks treat it as the convex block it is (noise of an export
   can put a vertex just outside a face plane).

What cannot be closed so (a hole neither planar nor such a fan, an edge shared by more than
two faces, no volume) stays a :class:`ValueError` with the reason, which the loader turns into
INVALID_INPUT naming the block.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
import shapely
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, cKDTree

from ..scene import Block, SceneError
from .block import is_closed, signed_volume

#: Vertices closer than this share of the mesh's longest extent are one vertex.
MERGE_TOL = 1e-6
#: A hole's boundary within this share of the extent of its best-fit plane is filled.
PLANAR_TOL = 1e-4
#: A repaired mesh whose volume is within this share of its convex hull's is its hull.
HULL_TOL = 1e-4


@dataclass(frozen=True)
class Repaired:
    """A mesh after :func:`repair_mesh`: vertices, polygon faces and what was done (empty:
    the mesh was closed and kept as given)."""

    vertices: np.ndarray
    faces: tuple[tuple[int, ...], ...]
    notes: tuple[str, ...] = ()


def repair_block(block: Block) -> tuple[Block, str | None]:
    """``block`` with its mesh repaired (:func:`repair_mesh`) and the warning that names it
    and says what was repaired (None: the mesh was closed, the block is returned as is);
    SceneError naming the block when the mesh cannot be closed. The one repair of every
    loader: scene files (CLI, the node's design_file), COMPAS files and AssemblyState
    messages (node, replay)."""
    try:
        fixed = repair_mesh(block.vertices, block.faces)
    except ValueError as exc:
        raise SceneError(f"block {block.id!r}: {exc}", [block.id]) from None
    if not fixed.notes:
        return block, None
    return (replace(block, vertices=fixed.vertices, faces=fixed.faces),
            f"block {block.id!r}: mesh repaired: {'; '.join(fixed.notes)}")


def repair_mesh(vertices, faces) -> Repaired:
    """The mesh of ``vertices`` and polygon ``faces``, repaired if it is open or wound
    inconsistently (module docstring); raises ValueError when it cannot be closed."""
    vertices = np.asarray(vertices, dtype=float)
    faces = tuple(tuple(int(i) for i in f) for f in faces)
    if _sound(np.ascontiguousarray(vertices).tobytes(), faces):
        return Repaired(vertices, faces)
    scale = float(np.ptp(vertices, axis=0).max()) or 1.0
    triangles = np.array([t for f in faces for t in _triangles(vertices, f)],
                         dtype=np.int64).reshape(-1, 3)
    notes = []
    triangles = _merged(vertices, triangles, MERGE_TOL * scale)
    mesh = trimesh.Trimesh(vertices, triangles, process=False, validate=False)
    mesh.remove_unreferenced_vertices()
    if len(mesh.vertices) < len(vertices):
        notes.append(f"merged {len(vertices) - len(mesh.vertices)} duplicate vertices")
    keep = mesh.nondegenerate_faces() & mesh.unique_faces()
    if not keep.all():
        mesh.update_faces(keep)
        notes.append(f"dropped {int((~keep).sum())} degenerate or repeated triangles")
    flipped = _fix_winding(mesh)
    if flipped:
        notes.append(f"turned {flipped} triangles to a consistent winding")
    out_faces = [tuple(int(i) for i in f) for f in mesh.faces]
    holes = _boundary_loops(out_faces)
    planes = _edge_planes(mesh, out_faces) if holes else {}
    for loop in holes:
        out_faces += _fill(loop, np.asarray(mesh.vertices), planes, PLANAR_TOL * scale)
    if holes:
        notes.append(f"filled {len(holes)} hole{'s' if len(holes) > 1 else ''}")
    verts = np.asarray(mesh.vertices, dtype=float)
    if not _closed(out_faces):
        raise ValueError("mesh is not closed (every edge must join exactly two faces, wound "
                         "consistently) and could not be repaired")
    volume = signed_volume(verts, out_faces)
    if volume < 0:
        out_faces = [tuple(reversed(f)) for f in out_faces]
        volume = -volume
        notes.append("turned inside out (faces wound inward)")
    if not volume > 1e-9 * scale ** 3:
        raise ValueError(f"mesh has no volume (volume {volume:.3g} m^3)")
    hull = ConvexHull(verts)
    if abs(hull.volume - volume) <= HULL_TOL * hull.volume:
        verts, out_faces = _hull_mesh(verts, hull)
        notes.append(f"replaced by its convex hull (volumes agree within {HULL_TOL:g})")
    return Repaired(verts, tuple(out_faces), tuple(notes))


@lru_cache(maxsize=4096)
def _sound(vertex_bytes: bytes, faces) -> bool:
    """Closed, consistently wound and outward: nothing to repair (cached by the exact mesh,
    so a wall of identical bricks is looked at once). Every directed edge once, and its
    reverse present: for the few faces of a block, sets of Python tuples (faster than
    arrays there); for many, the array test of the shape analysis."""
    if len(faces) > _FEW:
        closed = _closed(faces)
    else:
        directed = {(f[i - 1], f[i]) for f in faces for i in range(len(f))}
        closed = (len(directed) == sum(len(f) for f in faces) and min(map(len, faces)) >= 3
                  and all((v, u) in directed for u, v in directed))
    return closed and signed_volume(np.frombuffer(vertex_bytes).reshape(-1, 3), faces) > 0


#: Meshes of more faces are checked with arrays (:func:`_sound`).
_FEW = 256


def _closed(faces) -> bool:
    return bool(faces) and all(len(f) >= 3 for f in faces) and is_closed(faces)


def _triangles(vertices: np.ndarray, face: tuple[int, ...]) -> list[tuple[int, int, int]]:
    """A polygon face as triangles wound as it is: a fan when the face is convex, else a
    constrained Delaunay triangulation in its plane (a fan would fold over a notch of an
    L-shaped face)."""
    if len(face) == 3:
        return [face]
    points = vertices[list(face)]
    normal = np.cross(points - points.mean(axis=0), np.roll(points, -1, axis=0)
                      - points.mean(axis=0)).sum(axis=0)     # Newell: the face's area vector
    turns = np.cross(np.roll(points, -1, axis=0) - points,
                     np.roll(points, -2, axis=0) - np.roll(points, -1, axis=0)) @ normal
    fan = [(face[0], face[i], face[i + 1]) for i in range(1, len(face) - 1)]
    if (turns >= 0).all() or not np.linalg.norm(normal) > 0:
        return fan
    u = points[1] - points[0]
    u /= np.linalg.norm(u)
    v = np.cross(normal / np.linalg.norm(normal), u)
    flat = np.column_stack(((points - points[0]) @ u, (points - points[0]) @ v))
    index = {tuple(p): k for k, p in enumerate(flat.tolist())}
    try:
        pieces = shapely.constrained_delaunay_triangles(shapely.Polygon(flat)).geoms
    except shapely.errors.GEOSException:        # a self-intersecting outline: as given
        return fan
    out = []
    for piece in pieces:
        a, b, c = (index.get(tuple(p)) for p in piece.exterior.coords[:3])
        if None in (a, b, c):                   # a point GEOS added: keep the fan
            return fan
        # counter-clockwise in (u, v) is the face's own turn (v = n x u)
        (ux, uy), (vx, vy) = flat[b] - flat[a], flat[c] - flat[a]
        out.append((face[a], face[b], face[c]) if ux * vy - uy * vx > 0
                   else (face[a], face[c], face[b]))
    return out


def _merged(vertices: np.ndarray, triangles: np.ndarray, tol: float) -> np.ndarray:
    """``triangles`` with vertices within ``tol`` (m) of each other, transitively, made one
    (the first of each group; by distance, not by rounding, so that two copies of a vertex
    either side of a rounding boundary are one too)."""
    pairs = cKDTree(vertices).query_pairs(tol, output_type="ndarray")
    count = len(vertices)
    _, group = connected_components(coo_matrix((np.ones(len(pairs)), pairs.T),
                                               shape=(count, count)), directed=False)
    first = np.full(group.max() + 1, count)
    np.minimum.at(first, group, np.arange(count))
    return first[group][triangles]


def _edge_planes(mesh: trimesh.Trimesh, faces) -> dict:
    """Per directed edge of the triangles ``faces``, the plane (unit normal, offset) of its
    triangle."""
    normals = np.asarray(mesh.face_normals)
    offsets = np.einsum("ij,ij->i", normals, np.asarray(mesh.vertices)[[f[0] for f in faces]])
    return {(f[i - 1], f[i]): (normals[k], offsets[k]) for k, f in enumerate(faces)
            for i in range(3)}


def _fill(loop, vertices: np.ndarray, planes: dict, tol: float) -> list[tuple[int, ...]]:
    """Faces closing the hole bounded by ``loop``: one polygon when the loop is planar
    within ``tol`` (m); else the fan, from one of its vertices, whose every triangle lies in
    the plane of a face along the hole (the triangles missing across an edge or a corner of
    the block); ValueError when neither closes it."""
    points = vertices[list(loop)]
    centred = points - points.mean(axis=0)
    # the smallest singular value bounds the rms distance from the best plane
    if np.linalg.svd(centred, compute_uv=False)[-1] / np.sqrt(len(loop)) <= tol:
        return [tuple(reversed(loop))]
    ring = list(reversed(loop))
    around = [planes[(loop[i - 1], loop[i])] for i in range(len(loop))]
    for start in range(len(ring)):
        r = ring[start:] + ring[:start]
        fan = [(r[0], r[i], r[i + 1]) for i in range(1, len(r) - 1)]
        if all(_in_one(vertices[list(t)], around, tol) for t in fan):
            return fan
    raise ValueError(f"mesh is not closed: a hole of {len(loop)} edges is neither planar "
                     "nor a fan of the planes around it (cannot be filled)")


def _in_one(triangle: np.ndarray, planes, tol: float) -> bool:
    """Whether ``triangle`` (3, 3) is non-degenerate and lies, facing the same way, in one
    of ``planes`` within ``tol``."""
    normal = np.cross(triangle[1] - triangle[0], triangle[2] - triangle[0])
    length = float(np.linalg.norm(normal))
    if length <= tol * tol:
        return False
    normal /= length
    return any(normal @ n > 1 - 1e-6 and np.abs(triangle @ n - d).max() <= tol
               for n, d in planes)


def _fix_winding(mesh: trimesh.Trimesh) -> int:
    """Make the triangles' winding consistent (trimesh), returning how many were turned."""
    before = mesh.faces.copy()
    trimesh.repair.fix_winding(mesh)
    return int((mesh.faces != before).any(axis=1).sum())


def _boundary_loops(faces) -> list[tuple[int, ...]]:
    """The loops of directed edges whose reverse no face has (the holes' boundaries); raises
    ValueError where they do not form simple loops (an edge of more than two faces)."""
    directed = [(f[i], f[(i + 1) % len(f)]) for f in faces for i in range(len(f))]
    present = set(directed)
    if len(present) < len(directed):
        raise ValueError("mesh is not closed: an edge is shared by more than two faces or "
                         "wound the same way twice (cannot be repaired)")
    following: dict[int, int] = {}
    for u, v in directed:
        if (v, u) not in present:
            if u in following:
                raise ValueError("mesh is not closed: two holes meet at a vertex (cannot be "
                                 "repaired)")
            following[u] = v
    loops = []
    while following:
        start = min(following)
        loop = [start]
        nxt = following.pop(start)
        while nxt != start:
            if nxt not in following:
                raise ValueError("mesh is not closed: an open edge does not return to "
                                 "its start (cannot be repaired)")
            loop.append(nxt)
            nxt = following.pop(nxt)
        loops.append(tuple(loop))
    return loops


def _hull_mesh(vertices: np.ndarray, hull: ConvexHull):
    """The hull's vertices and triangles, wound outward."""
    index = np.full(len(vertices), -1)
    index[hull.vertices] = np.arange(len(hull.vertices))
    simplices = hull.simplices.copy()
    a, b, c = (vertices[simplices[:, k]] for k in range(3))
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), hull.equations[:, :3]) < 0
    simplices[inward] = simplices[inward][:, ::-1]
    return vertices[hull.vertices], [tuple(int(i) for i in index[s]) for s in simplices]
