"""A block posed in the scene: world vertices, planar faces, volume, mass and centroid.

What does not depend on the pose (faces grouped by plane, their 2D outlines, volume and
centroid) is computed once per distinct shape in the block frame and cached, so a wall of a
thousand identical bricks costs one shape analysis; posing is then a rigid transform.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property, lru_cache
from itertools import chain

import numpy as np
import shapely
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from trimesh.triangles import mass_properties

from ..deadline import checkpoint
from ..scene import Block, SceneError
from .polygon import PlaneFrame, cross, tangent_basis
from .support import projection_extents

#: Faces whose normals differ by less than this (radians) and whose planes are within
#: PLANE_TOL of the block size are one face (a triangulated mesh has several per plane).
ANGLE_TOL = 1e-6
PLANE_TOL = 1e-9


@dataclass(frozen=True)
class Face:
    """One planar face of a posed block: its plane frame (n outward) and 2D outline."""

    frame: PlaneFrame
    outline: shapely.Polygon | shapely.MultiPolygon   # in frame coordinates (u, v)
    offset: float                                      # n . x for points x of the plane


@dataclass(frozen=True)
class PosedBlock:
    """A block in scene coordinates, with what contacts and equilibrium need of it.

    The faces are stored as arrays (one row per face) for the vectorised contact tests;
    :attr:`faces` gives them as :class:`Face` objects, built on first use."""

    id: str
    support: bool
    vertices: np.ndarray        # (n, 3) world
    centroid: np.ndarray        # (3,) world centre of mass
    volume: float
    mass: float
    size: float                 # cube root of the volume: the block's length scale
    aabb: np.ndarray            # (2, 3) min and max corner
    face_normals: np.ndarray    # (F, 3) the faces' n, for vectorised contact tests
    face_offsets: np.ndarray    # (F,)
    face_origins: np.ndarray    # (F, 3)
    face_us: np.ndarray         # (F, 3) the faces' frame axes u and v
    face_vs: np.ndarray         # (F, 3)
    face_outlines: np.ndarray   # (F,) shapely outlines in face frame coordinates (shared,
                                #      read-only: they do not depend on the pose)
    face_extents: np.ndarray    # (F, 2) min and max of n . x over the block's vertices x
    convex: bool                # every vertex inside every face plane (to 1e-6 of the size)
    # the mesh in the block frame and the pose, for the exact shape of a non-convex block
    # (rbe_ros.geometry.decompose): shared by identical blocks, read-only
    local_vertices: np.ndarray | None = None    # (n, 3) block frame
    triangles: np.ndarray | None = None         # (m, 3) vertex indices, wound outward
    rotation: np.ndarray | None = None          # (3, 3) block frame -> world
    position: np.ndarray | None = None          # (3,)

    @cached_property
    def faces(self) -> tuple[Face, ...]:
        """The planar faces (frame with n outward, 2D outline, plane offset)."""
        return tuple(Face(PlaneFrame(o, u, v, n), outline, float(d)) for o, u, v, n, outline, d
                     in zip(self.face_origins, self.face_us, self.face_vs, self.face_normals,
                            self.face_outlines, self.face_offsets))


@dataclass(frozen=True)
class _Shape:
    """Pose-independent analysis of a block's mesh, in the block frame."""

    normals: np.ndarray
    offsets: np.ndarray
    origins: np.ndarray
    us: np.ndarray
    vs: np.ndarray
    outlines: np.ndarray        # (F,) object array, read-only
    volume: float
    centroid: np.ndarray
    extents: np.ndarray         # (F, 2) min and max of n . x over the vertices
    convex: bool
    vertices: np.ndarray        # (n, 3) as keyed (rounded to 1e-12 m), read-only
    triangles: np.ndarray       # (m, 3) the faces' fans, read-only


def pose_block(block: Block) -> PosedBlock:
    """Place ``block`` in the scene and compute its mass properties (raises SceneError)."""
    return pose_blocks([block])[0]


def pose_blocks(blocks) -> list[PosedBlock]:
    """:func:`pose_block` of every block, with the rigid transforms of all blocks applied in
    a few array operations (raises SceneError for the first block that cannot be posed)."""
    blocks = list(blocks)
    if not blocks:
        return []
    n_vert = np.array([len(b.vertices) for b in blocks])
    v0 = np.cumsum(n_vert) - n_vert
    vertices = np.concatenate([b.vertices for b in blocks])
    # rounded to 1e-12 m, so blocks equal but for float noise share one shape analysis
    rounded = np.round(vertices, 12)
    shapes = []
    for block, s, n in zip(blocks, v0.tolist(), n_vert.tolist()):
        try:
            shapes.append(_shape(rounded[s:s + n].tobytes(), n, block.faces))
        except ValueError as exc:
            raise SceneError(f"block {block.id!r}: {exc}", [block.id]) from None
    rot = Rotation.from_quat(np.array([b.orientation for b in blocks])).as_matrix()  # x, y, z, w
    pos = np.array([b.position for b in blocks], dtype=float)
    n_face = np.array([len(s.offsets) for s in shapes])
    of_vert = np.repeat(np.arange(len(blocks)), n_vert)         # the block of each row
    of_face = np.repeat(np.arange(len(blocks)), n_face)
    rv, rf = rot[of_vert], rot[of_face]
    world = _rotate(vertices, rv) + pos[of_vert]
    normals = _rotate(np.concatenate([s.normals for s in shapes]), rf)
    origins = _rotate(np.concatenate([s.origins for s in shapes]), rf) + pos[of_face]
    us = _rotate(np.concatenate([s.us for s in shapes]), rf)
    vs = _rotate(np.concatenate([s.vs for s in shapes]), rf)
    p = pos[of_face]
    shift = normals[:, 0] * p[:, 0] + normals[:, 1] * p[:, 1] + normals[:, 2] * p[:, 2]
    offsets = np.concatenate([s.offsets for s in shapes]) + shift
    extents = np.concatenate([s.extents for s in shapes]) + shift[:, None]
    centroids = _rotate(np.array([s.centroid for s in shapes]), rot) + pos
    aabb = np.stack((np.minimum.reduceat(world, v0), np.maximum.reduceat(world, v0)), axis=1)
    vert_ends, face_ends = np.cumsum(n_vert).tolist(), np.cumsum(n_face).tolist()
    out = []
    for k, (block, shape) in enumerate(zip(blocks, shapes)):
        vb, ve = vert_ends[k] - len(block.vertices), vert_ends[k]
        fb, fe = face_ends[k] - len(shape.offsets), face_ends[k]
        mass = block.mass if block.mass > 0 else block.density * shape.volume
        out.append(PosedBlock(block.id, block.support, world[vb:ve], centroids[k], shape.volume,
                              float(mass), shape.volume ** (1.0 / 3.0), aabb[k], normals[fb:fe],
                              offsets[fb:fe], origins[fb:fe], us[fb:fe], vs[fb:fe],
                              shape.outlines, extents[fb:fe], shape.convex, shape.vertices,
                              shape.triangles, rot[k], pos[k]))
    return out


def _rotate(x: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Rows of ``x`` (n, 3) rotated by their matrices ``rot`` (n, 3, 3): ``x[i] @ rot[i].T``,
    the same sums in the same order as a matrix product row by row."""
    return x[:, 0:1] * rot[:, :, 0] + x[:, 1:2] * rot[:, :, 1] + x[:, 2:3] * rot[:, :, 2]


@lru_cache(maxsize=4096)
def _shape(vertex_bytes: bytes, count: int, faces) -> _Shape:
    """Cached by the exact mesh, so identical blocks share it (raises ValueError)."""
    checkpoint()
    vertices = np.frombuffer(vertex_bytes).reshape(count, 3)
    ragged = _Ragged(faces)
    triangles = ragged.fans()
    if not _is_closed(triangles):
        raise ValueError("mesh is not closed (every edge must join exactly two faces,"
                         " wound consistently)")
    centres = ragged.sums(vertices[ragged.corners]) / ragged.counts[:, None]
    volume, centroid = _volume_centroid(_centre_fans(vertices, ragged, centres))
    scale = float(np.ptp(vertices, axis=0).max())
    if not volume > 1e-9 * scale ** 3:
        raise ValueError(f"mesh has no volume or is wound inside out (volume {volume:.3g} m^3)")
    size = volume ** (1.0 / 3.0)
    checkpoint()
    planes = _planar_faces(vertices, ragged, centres, size)
    normals, offsets = planes[0], planes[1]
    checkpoint()
    extents = projection_extents(vertices, normals)
    convex = bool((extents[:, 1] - offsets).max(initial=0.0) <= 1e-6 * size)
    vertices.flags.writeable = False
    triangles.flags.writeable = False
    return _Shape(*planes, volume, centroid, extents, convex, vertices, triangles)


def is_closed(faces) -> bool:
    """Whether the polygon ``faces`` (vertex index lists) close a consistently wound mesh."""
    return _is_closed(_Ragged(faces).fans())


def signed_volume(vertices: np.ndarray, faces) -> float:
    """The volume the polygon ``faces`` enclose, positive when they are wound outward (fans
    from each face's first vertex: exact for planar faces, any origin)."""
    tri = np.asarray(vertices, dtype=float)[_Ragged(faces).fans()]
    return float(np.einsum("ij,ij->", tri[:, 0], np.cross(tri[:, 1], tri[:, 2]))) / 6.0


def _is_closed(tri: np.ndarray) -> bool:
    """Every directed edge appears once and its reverse once: closed and consistently wound."""
    edges = np.concatenate((tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]))
    n = int(tri.max()) + 1
    keys = edges[:, 0] * n + edges[:, 1]
    reverse = edges[:, 1] * n + edges[:, 0]
    return len(np.unique(keys)) == len(keys) and bool(np.isin(reverse, keys).all())


class _Ragged:
    """The faces of a mesh as one array of corner indices, face after face."""

    def __init__(self, faces):
        self.counts = np.fromiter((len(f) for f in faces), dtype=np.intp, count=len(faces))
        self.corners = np.fromiter(chain.from_iterable(faces), dtype=np.intp,
                                   count=int(self.counts.sum()))
        self.starts = np.cumsum(self.counts) - self.counts
        self.face_of_corner = np.repeat(np.arange(len(faces)), self.counts)

    def sums(self, values: np.ndarray, of: np.ndarray | None = None) -> np.ndarray:
        """Per face, the sum of the rows of ``values`` (m, 3) whose face is ``of`` (default:
        one row per corner)."""
        of = self.face_of_corner if of is None else of
        return np.column_stack([np.bincount(of, values[:, k], len(self.counts))
                                for k in range(3)])

    def fans(self) -> np.ndarray:
        """(m, 3) vertex indices: each face as triangles (f0, f[i], f[i+1]), i = 1 .. k-2."""
        fans = np.maximum(self.counts - 2, 0)
        self.fan_face = np.repeat(np.arange(len(self.counts)), fans)
        second = (self.starts[self.fan_face] + np.arange(len(self.fan_face))
                  - np.repeat(np.cumsum(fans) - fans, fans) + 1)
        c = self.corners
        return np.column_stack((c[self.starts[self.fan_face]], c[second], c[second + 1]))


def _centre_fans(vertices: np.ndarray, ragged: _Ragged, centres: np.ndarray) -> np.ndarray:
    """Triangles (m, 3, 3) fanning each face from its vertex mean ``centres``: the same as
    any fan for planar faces, and for slightly non-planar ones (scanned or exported meshes)
    the symmetric choice COMPAS makes too. Triangles are kept as they are."""
    k = ragged.counts
    per_face = np.where(k == 3, 1, k)
    face = np.repeat(np.arange(len(k)), per_face)
    j = np.arange(len(face)) - np.repeat(np.cumsum(per_face) - per_face, per_face)
    first = ragged.starts[face]
    triangle = (k == 3)[face]
    points = np.concatenate((vertices, centres))
    apex = np.where(triangle, ragged.corners[first], len(vertices) + face)
    b = ragged.corners[first + np.where(triangle, 1, j)]
    c = ragged.corners[first + np.where(triangle, 2, (j + 1) % k[face])]
    return points[np.column_stack((apex, b, c))]


def _volume_centroid(triangles: np.ndarray) -> tuple[float, np.ndarray]:
    props = mass_properties(triangles, skip_inertia=True)
    return float(props["volume"]), np.asarray(props["center_mass"], dtype=float)


def _planar_faces(vertices: np.ndarray, ragged: _Ragged, centres: np.ndarray, size: float):
    """Faces grouped by plane, each with a frame and one merged 2D outline (block frame).

    A face joins the first plane (in face order) whose normal is within ANGLE_TOL of its own
    and whose offset is within PLANE_TOL of the size; the candidates come from a k-d tree, so
    grouping the F faces costs about F log F (a 10,000-vertex hull has 20,000 triangles), and
    the normals, offsets and outlines are computed for all faces at once."""
    counts, corners, corner_face = ragged.counts, ragged.corners, ragged.face_of_corner
    # area vectors from each face's fan of triangles around its first vertex
    fan = vertices[ragged.fans()]
    area_vectors = ragged.sums(0.5 * cross(fan[:, 1] - fan[:, 0], fan[:, 2] - fan[:, 0]),
                               ragged.fan_face)
    lengths = np.sqrt((area_vectors ** 2).sum(axis=1))
    kept = np.flatnonzero(lengths > 0.0)                  # degenerate sliver faces go
    normals = area_vectors[kept] / lengths[kept, None]
    offsets = (normals * centres[kept]).sum(axis=1)
    group, first = _group_planes(normals, offsets, PLANE_TOL * size + 1e-12)
    n = normals[first]
    u, v = tangent_basis(n)
    origins = centres[kept[first]]
    # every kept face's outline in its plane's frame, then merged per plane
    member = np.zeros(len(counts), dtype=bool)
    member[kept] = True
    plane_of_face = np.full(len(counts), -1)
    plane_of_face[kept] = group
    on = member[corner_face]
    plane = plane_of_face[corner_face[on]]
    d = vertices[corners[on]] - origins[plane]
    coords = np.column_stack(((d * u[plane]).sum(axis=1), (d * v[plane]).sum(axis=1)))
    outlines = shapely.polygons(shapely.linearrings(coords, indices=np.repeat(
        np.arange(len(kept)), counts[kept])))
    sizes = np.bincount(group, minlength=len(first))
    shared = np.empty(len(first), dtype=object)
    shared[:] = outlines[first]
    for p in np.flatnonzero(sizes > 1):   # a triangulated face: merge, dropping the seams' vertices
        shared[p] = shapely.union_all(shapely.buffer(outlines[group == p], 0)).simplify(0.0)
    shared.flags.writeable = False
    return n, offsets[first], origins, u, v, shared


def _group_planes(normals: np.ndarray, offsets: np.ndarray, plane_tol: float):
    """Each face's plane index and each plane's first face: face j joins the plane of the
    first face i < j starting a plane with n_i . n_j > cos(ANGLE_TOL) and |d_i - d_j| <=
    plane_tol (the order in which faces are met, as a linear scan would group them)."""
    chord = 2.0 * math.sin(ANGLE_TOL / 2.0)       # |n_i - n_j| at the angle tolerance
    # offsets scaled so that both tolerances are one distance; the ball (with room for
    # rounding) holds every match, which the exact test then confirms
    points = np.column_stack((normals, offsets * (chord / plane_tol)))
    near = cKDTree(points).query_ball_point(points, 2.0 * chord)
    cos_tol = math.cos(ANGLE_TOL)
    group = np.full(len(normals), -1)
    first = []
    for i, candidates in enumerate(near):
        if i % 4096 == 0:
            checkpoint()
        if group[i] >= 0:
            continue
        group[i] = len(first)
        first.append(i)
        for j in candidates:
            if (j > i and group[j] < 0 and normals[i] @ normals[j] > cos_tol
                    and abs(offsets[i] - offsets[j]) <= plane_tol):
                group[j] = group[i]
    return group, np.array(first, dtype=np.intp)
