"""A block posed in the scene: world vertices, planar faces, volume, mass and centroid."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
import trimesh
from scipy.spatial.transform import Rotation

from ..scene import Block, SceneError
from .polygon import PlaneFrame, newell_normal, tangent_basis

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
    """A block in scene coordinates, with what contacts and equilibrium need of it."""

    id: str
    support: bool
    vertices: np.ndarray        # (n, 3) world
    faces: tuple[Face, ...]
    centroid: np.ndarray        # (3,) world centre of mass
    volume: float
    mass: float
    size: float                 # cube root of the volume: the block's length scale
    aabb: np.ndarray            # (2, 3) min and max corner


def pose_block(block: Block) -> PosedBlock:
    """Place ``block`` in the scene and compute its mass properties (raises SceneError)."""
    rot = Rotation.from_quat(block.orientation)      # scalar-last (x, y, z, w), as ROS
    world = block.vertices @ rot.as_matrix().T + block.position
    triangles = [(f[0], f[i], f[i + 1]) for f in block.faces for i in range(1, len(f) - 1)]
    mesh = trimesh.Trimesh(world, np.array(triangles), process=False)
    if not mesh.is_watertight:
        raise SceneError(f"block {block.id!r}: mesh is not closed (watertight)")
    volume = float(mesh.volume)
    scale = float(np.ptp(world, axis=0).max())
    if not volume > 1e-9 * scale ** 3:
        raise SceneError(f"block {block.id!r}: mesh has no volume or is wound inside out"
                         f" (volume {volume:.3g} m^3)")
    mass = block.mass if block.mass > 0 else block.density * volume
    size = volume ** (1.0 / 3.0)
    return PosedBlock(block.id, block.support, world, _planar_faces(world, block.faces, size),
                      np.asarray(mesh.center_mass, dtype=float), volume, float(mass), size,
                      np.array([world.min(axis=0), world.max(axis=0)]))


def _planar_faces(world: np.ndarray, faces, size: float) -> tuple[Face, ...]:
    """Group the polygon faces by plane and merge each group into one 2D outline."""
    groups: list[tuple[np.ndarray, float, list[np.ndarray]]] = []
    for f in faces:
        pts = world[list(f)]
        n = newell_normal(pts)
        if not np.any(n):
            continue                                  # degenerate sliver face
        d = float(n @ pts.mean(axis=0))
        for gn, gd, members in groups:
            if gn @ n > np.cos(ANGLE_TOL) and abs(gd - d) <= PLANE_TOL * size + 1e-12:
                members.append(pts)
                break
        else:
            groups.append((n, d, [pts]))
    out = []
    for n, d, members in groups:
        u, v = tangent_basis(n)
        frame = PlaneFrame(members[0].mean(axis=0), u, v, n)
        outline = shapely.union_all([shapely.Polygon(frame.to_2d(p)).buffer(0) for p in members])
        outline = outline.simplify(0.0)               # drop collinear vertices of merged triangles
        out.append(Face(frame, outline, d))
    return tuple(out)
