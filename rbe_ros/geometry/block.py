"""A block posed in the scene: world vertices, planar faces, volume, mass and centroid.

What does not depend on the pose (faces grouped by plane, their 2D outlines, volume and
centroid) is computed once per distinct shape in the block frame and cached, so a wall of a
thousand identical bricks costs one shape analysis; posing is then a rigid transform.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
import shapely
from scipy.spatial.transform import Rotation
from trimesh.triangles import mass_properties

from ..scene import Block, SceneError
from .polygon import PlaneFrame, cross, tangent_basis

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
    position: np.ndarray        # (3,) origin of the block frame: pose errors turn about it

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
    offsets = np.concatenate([s.offsets for s in shapes]) + (
        normals[:, 0] * p[:, 0] + normals[:, 1] * p[:, 1] + normals[:, 2] * p[:, 2])
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
                              shape.outlines, pos[k]))
    return out


def _rotate(x: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Rows of ``x`` (n, 3) rotated by their matrices ``rot`` (n, 3, 3): ``x[i] @ rot[i].T``,
    the same sums in the same order as a matrix product row by row."""
    return x[:, 0:1] * rot[:, :, 0] + x[:, 1:2] * rot[:, :, 1] + x[:, 2:3] * rot[:, :, 2]


@lru_cache(maxsize=4096)
def _shape(vertex_bytes: bytes, count: int, faces) -> _Shape:
    """Cached by the exact mesh, so identical blocks share it (raises ValueError)."""
    vertices = np.frombuffer(vertex_bytes).reshape(count, 3)
    tri = np.array([(f[0], f[i], f[i + 1]) for f in faces for i in range(1, len(f) - 1)])
    if not _is_closed(tri):
        raise ValueError("mesh is not closed (every edge must join exactly two faces,"
                         " wound consistently)")
    volume, centroid = _volume_centroid(_centre_fans(vertices, faces))
    scale = float(np.ptp(vertices, axis=0).max())
    if not volume > 1e-9 * scale ** 3:
        raise ValueError(f"mesh has no volume or is wound inside out (volume {volume:.3g} m^3)")
    return _Shape(*_planar_faces(vertices, faces, volume ** (1.0 / 3.0)), volume, centroid)


def _is_closed(tri: np.ndarray) -> bool:
    """Every directed edge appears once and its reverse once: closed and consistently wound."""
    edges = np.concatenate((tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]))
    n = int(tri.max()) + 1
    keys = edges[:, 0] * n + edges[:, 1]
    reverse = edges[:, 1] * n + edges[:, 0]
    return len(np.unique(keys)) == len(keys) and bool(np.isin(reverse, keys).all())


def _centre_fans(vertices: np.ndarray, faces) -> np.ndarray:
    """Triangles (m, 3, 3) fanning each face from its vertex mean: the same as any fan for
    planar faces, and for slightly non-planar ones (scanned or exported meshes) the symmetric
    choice COMPAS makes too."""
    out = []
    for f in faces:
        pts = vertices[list(f)]
        if len(f) == 3:
            out.append(pts[None])
            continue
        centre = np.broadcast_to(pts.mean(axis=0), pts.shape)
        out.append(np.stack((centre, pts, np.concatenate((pts[1:], pts[:1]))), axis=1))
    return np.concatenate(out)


def _volume_centroid(triangles: np.ndarray) -> tuple[float, np.ndarray]:
    props = mass_properties(triangles, skip_inertia=True)
    return float(props["volume"]), np.asarray(props["center_mass"], dtype=float)


def _planar_faces(vertices: np.ndarray, faces, size: float):
    """Faces grouped by plane, each with a frame and one merged 2D outline (block frame)."""
    groups: list[tuple[np.ndarray, float, list[np.ndarray]]] = []
    for f in faces:
        pts = vertices[list(f)]
        area_vector = 0.5 * cross(pts[1:-1] - pts[0], pts[2:] - pts[0]).sum(axis=0)
        length = np.linalg.norm(area_vector)
        if length == 0.0:
            continue                                  # degenerate sliver face
        n = area_vector / length
        d = float(n @ pts.mean(axis=0))
        for gn, gd, members in groups:
            if gn @ n > np.cos(ANGLE_TOL) and abs(gd - d) <= PLANE_TOL * size + 1e-12:
                members.append(pts)
                break
        else:
            groups.append((n, d, [pts]))
    normals, offsets, origins, us, vs, outlines = [], [], [], [], [], []
    for n, d, members in groups:
        u, v = tangent_basis(n)
        frame = PlaneFrame(members[0].mean(axis=0), u, v, n)
        if len(members) == 1:
            outline = shapely.Polygon(frame.to_2d(members[0]))
        else:   # a triangulated face: merge, dropping the collinear vertices of the seams
            outline = shapely.union_all([shapely.Polygon(frame.to_2d(p)).buffer(0)
                                         for p in members]).simplify(0.0)
        normals.append(n)
        offsets.append(d)
        origins.append(frame.origin)
        us.append(u)
        vs.append(v)
        outlines.append(outline)
    shared = np.empty(len(outlines), dtype=object)
    shared[:] = outlines
    shared.flags.writeable = False
    return (np.array(normals), np.array(offsets), np.array(origins), np.array(us), np.array(vs),
            shared)
