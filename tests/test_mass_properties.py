"""Volume, mass and centroid of posed blocks against closed forms and a second computation.

Closed forms: a tetrahedron (|det| / 6, the mean of its corners), a trapezoidal prism and a
wedge (area x length, the plane figure's centroid). Random convex hulls: scipy's hull volume,
trimesh's mass properties of the same points and tests/oracles/mass.py (the divergence
theorem over the faces), which the equilibrium checks of the other tests use too. A
trapezoidal prism tells the centroid from the mean of the vertices (they differ by
h (a - b) / (6 (a + b)) in height), which a box, a tetrahedron or a wedge cannot.
"""
import math

import numpy as np
import pytest
import trimesh
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from rbe_ros import generators as gen
from rbe_ros.geometry.block import pose_block
from rbe_ros.scene import make_block

from oracles.mass import mass_centroid, volume_centroid

POSE = dict(position=(1.5, -0.7, 2.25),
            orientation=Rotation.from_euler("xyz", [25, -40, 110], degrees=True).as_quat())


def prism_faces(vertices) -> list[list[int]]:
    """Faces of a prism whose vertices are a k-gon (0..k-1) and its translate (k..2k-1),
    wound outwards (the orientation of the k-gon decides, so the volume fixes the sign)."""
    k = len(vertices) // 2
    faces = [list(range(k)), [k + i for i in range(k)][::-1],
             *[[(i + 1) % k, i, k + i, k + (i + 1) % k] for i in range(k)]]
    if volume_centroid(vertices, faces)[0] < 0:
        faces = [f[::-1] for f in faces]
    return faces


def extrude(outline_xz, length: float) -> np.ndarray:
    """The 2D outline (x, z) extruded along +y."""
    xz = np.asarray(outline_xz, dtype=float)
    low = np.column_stack((xz[:, 0], np.zeros(len(xz)), xz[:, 1]))
    return np.vstack((low, low + [0.0, length, 0.0]))


def posed(vertices, faces, density=2300.0):
    block = make_block("b", vertices, faces, density=density, **POSE)
    return block, pose_block(block)


def to_world(p):
    return Rotation.from_quat(POSE["orientation"]).apply(p) + POSE["position"]


def test_tetrahedron_volume_is_det_over_6_and_centroid_the_mean_corner():
    corners = np.array([[0.1, 0.0, 0.0], [1.3, 0.2, -0.1], [0.4, 0.9, 0.05], [0.5, 0.3, 0.8]])
    faces = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]]
    volume = abs(np.linalg.det(corners[1:] - corners[0])) / 6.0
    _, p = posed(corners, faces)
    assert p.volume == pytest.approx(volume, rel=1e-12)
    assert p.mass == pytest.approx(2300.0 * volume, rel=1e-12)
    assert np.allclose(p.centroid, to_world(corners.mean(axis=0)), atol=1e-12)


@pytest.mark.parametrize("a, b, s", [(1.0, 0.4, 0.3), (0.6, 1.4, -0.2), (1.2, 0.0001, 0.6)])
def test_trapezoidal_prism_centroid_is_that_of_the_trapezoid(a, b, s):
    """Bottom edge [0, a] at z = 0, top edge [s, s + b] at z = h, extruded by L along y:
    area (a + b) h / 2, centroid x = (a^2 + a b + b^2 + s (a + 2 b)) / (3 (a + b)),
    z = h (a + 2 b) / (3 (a + b))."""
    h, length = 0.7, 0.9
    vertices = extrude([(0, 0), (s, h), (s + b, h), (a, 0)], length)
    _, p = posed(vertices, prism_faces(vertices))
    area = (a + b) * h / 2
    x = (a * a + a * b + b * b + s * (a + 2 * b)) / (3 * (a + b))
    z = h * (a + 2 * b) / (3 * (a + b))
    assert p.volume == pytest.approx(area * length, rel=1e-12)
    assert np.allclose(p.centroid, to_world([x, length / 2, z]), atol=1e-12)
    # the mean of the vertices is elsewhere: a test of this block tells the two apart
    assert np.linalg.norm(to_world(vertices.mean(axis=0)) - p.centroid) > 0.02 * h


def test_wedge_volume_and_centroid():
    """A right triangle with legs p (x) and q (z), extruded by L: volume p q L / 2,
    centroid (p / 3, L / 2, q / 3)."""
    p_, q_, length = 0.8, 0.5, 1.1
    vertices = extrude([(0, 0), (0, q_), (p_, 0)], length)
    _, p = posed(vertices, prism_faces(vertices))
    assert p.volume == pytest.approx(p_ * q_ * length / 2, rel=1e-12)
    assert np.allclose(p.centroid, to_world([p_ / 3, length / 2, q_ / 3]), atol=1e-12)


def hull_block(points):
    """The convex hull of ``points`` as a block: triangles wound outwards (scipy's facet
    equations give the outward normals)."""
    hull = ConvexHull(points)
    faces = []
    for tri, eq in zip(hull.simplices, hull.equations):
        a, b, c = points[tri]
        faces.append(list(tri) if np.cross(b - a, c - a) @ eq[:3] > 0 else list(tri[::-1]))
    return hull, faces


@pytest.mark.parametrize("seed", range(6))
def test_random_convex_hull_mass_properties_agree_three_ways(seed):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(int(rng.integers(8, 40)), 3)) * rng.uniform(0.2, 2.0, size=3)
    hull, faces = hull_block(points)
    block, p = posed(points, faces, density=1700.0)
    props = trimesh.convex.convex_hull(points).mass_properties
    volume, centre = volume_centroid(points, faces)
    assert hull.volume == pytest.approx(props["volume"], rel=1e-9)
    assert volume == pytest.approx(hull.volume, rel=1e-9)
    assert np.allclose(centre, props["center_mass"], atol=1e-9)
    assert p.volume == pytest.approx(hull.volume, rel=1e-9)
    assert p.mass == pytest.approx(1700.0 * hull.volume, rel=1e-9)
    assert np.allclose(p.centroid, to_world(props["center_mass"]), atol=1e-9)
    assert mass_centroid(block)[0] == pytest.approx(p.mass, rel=1e-9)
    assert np.allclose(mass_centroid(block)[1], p.centroid, atol=1e-9)


@pytest.mark.parametrize("scene", [gen.semicircular_arch(), gen.buttressed_arch(), gen.dome(),
                                   gen.two_blocks(incline_deg=23.6)],
                         ids=["arch", "buttressed", "dome", "incline"])
def test_generated_blocks_agree_with_the_oracle(scene):
    for block in scene.blocks:
        p = pose_block(block)
        mass, centroid = mass_centroid(block)
        assert p.mass == pytest.approx(mass, rel=1e-9), block.id
        assert np.linalg.norm(p.centroid - centroid) < 1e-9 * max(1.0, p.size), block.id


def test_semicircular_voussoir_volume_and_centroid_are_those_of_its_chord_triangles():
    """A voussoir (radial joints pi / n apart, planar chords at radii R -/+ t/2, depth d) is
    the difference of two isosceles triangles with apex at the arch centre: area
    (R_out^2 - R_in^2) sin(pi / n) / 2, centroid on the bisector at
    2 (R_out^3 - R_in^3) cos(pi / 2n) / (3 (R_out^2 - R_in^2))."""
    n, ratio, radius, depth = 15, 0.15, 1.0, 0.8
    scene = gen.semicircular_arch(n, ratio, radius, depth=depth)
    r_in, r_out = radius * (1 - ratio / 2), radius * (1 + ratio / 2)
    area = 0.5 * (r_out ** 2 - r_in ** 2) * math.sin(math.pi / n)
    reach = 2 * (r_out ** 3 - r_in ** 3) * math.cos(math.pi / (2 * n)) / (3 * (r_out ** 2 - r_in ** 2))
    centre = np.array([0.0, 0.0, ratio * radius])          # the generator's arch centre
    voussoirs = [b for b in scene.blocks if not b.support]
    assert len(voussoirs) == n
    for i, b in enumerate(voussoirs):
        p = pose_block(b)
        mid = math.pi * (i + 0.5) / n
        assert p.volume == pytest.approx(area * depth, rel=1e-9), b.id
        assert np.allclose(p.centroid, centre + reach * np.array([math.cos(mid), 0.0, math.sin(mid)]),
                           atol=1e-12), b.id
