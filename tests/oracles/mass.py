"""Volume, mass and centroid of a scene block from its vertices and faces alone.

The divergence theorem: every face polygon is fanned from its vertex mean (exact for a
planar face, which the scene requires), each triangle closes a signed tetrahedron with the
origin of the block frame; volumes add, and so do their first moments (a tetrahedron's
centroid is the mean of its four corners). No trimesh, no rbe_ros geometry: an oracle for
rbe_ros.geometry.block, which computes the same quantities another way.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def volume_centroid(vertices, faces) -> tuple[float, np.ndarray]:
    """Volume and centroid of a closed polyhedron with outward-wound planar faces."""
    vertices = np.asarray(vertices, dtype=float)
    volume, moment = 0.0, np.zeros(3)
    for face in faces:
        ring = vertices[list(face)]
        mid = ring.mean(axis=0)
        for a, b in zip(ring, np.roll(ring, -1, axis=0)):
            v = float(np.dot(mid, np.cross(a, b))) / 6.0
            volume += v
            moment += v * (mid + a + b) / 4.0
    return volume, moment / volume


def mass_centroid(block) -> tuple[float, np.ndarray]:
    """Mass (kg) and world centroid of a scene Block (density or mass, pose (x, y, z, w))."""
    volume, centre = volume_centroid(block.vertices, block.faces)
    mass = block.mass if block.mass > 0 else block.density * volume
    world = Rotation.from_quat(block.orientation).apply(centre) + np.asarray(block.position)
    return float(mass), world
