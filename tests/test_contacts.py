"""Contact detection: the fidelity rules (ContactOptions.min_width, vertex_tol) and the
vectorised polygon helpers against plain per-polygon references."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rbe_ros import generators as gen
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.geometry.block import pose_block, pose_blocks
from rbe_ros.geometry.contacts import ContactOptions, Interface, detect_interfaces
from rbe_ros.geometry.kern import kern
from rbe_ros.geometry.polygon import drop_collinear_rings, ring_widths
from rbe_ros.scene import box_block, make_block, make_scene

from helpers import DENSITY

EVERYTHING = ContactOptions(min_width=0.0, vertex_tol=0.0)


def strip_scene(overlap: float):
    """A unit cube on a slab and a unit cube beside it on top, whose bottom face overlaps
    the first cube's top face in a strip ``overlap`` wide (the cubes' size is 1)."""
    return make_scene("strip", [
        box_block("ground", (4, 4, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        box_block("a", (1, 1, 1), (0, 0, 0.5), density=DENSITY),
        box_block("b", (1, 1, 1), (1.0 - overlap, 0, 1.5), density=DENSITY),
    ])


def pairs(assembly):
    return {(assembly.blocks[it.a].id, assembly.blocks[it.b].id) for it in assembly.interfaces}


def test_a_strip_thinner_than_min_width_is_no_interface():
    thin = strip_scene(5e-4)
    assert ("a", "b") not in pairs(Assembly.from_scene(thin))
    kept = Assembly.from_scene(thin, EVERYTHING)           # min_width 0: the strip stays
    strip = next(it for it in kept.interfaces if (it.a, it.b) == (1, 2))
    assert strip.area == pytest.approx(5e-4, rel=1e-9)
    assert ("a", "b") in pairs(Assembly.from_scene(strip_scene(2e-3)))


def test_min_width_is_relative_to_the_smaller_block():
    scene = strip_scene(5e-4)
    assert ("a", "b") in pairs(Assembly.from_scene(scene, ContactOptions(min_width=4e-4)))
    assert ("a", "b") not in pairs(Assembly.from_scene(scene, ContactOptions(min_width=6e-4)))


def pentagon_prism(bump: float):
    """A unit square prism (height 1, on z = 1..2) whose -y side has an extra vertex at its
    middle, pushed outward by ``bump``: its bottom face is a pentagon with a near-collinear
    vertex."""
    ring = [(-0.5, -0.5), (0.0, -0.5 - bump), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)]
    vertices = [(x, y, 1.0) for x, y in ring] + [(x, y, 2.0) for x, y in ring]
    n = len(ring)
    faces = [tuple(reversed(range(n))), tuple(range(n, 2 * n))]
    faces += [(k, (k + 1) % n, n + (k + 1) % n, n + k) for k in range(n)]
    return make_block("p", vertices, faces, density=DENSITY)


def test_a_near_collinear_vertex_of_the_contact_polygon_is_dropped():
    scene = make_scene("bump", [
        box_block("ground", (4, 4, 1.0), (0, 0, 0.5), support=True, density=DENSITY),
        pentagon_prism(2e-4),
    ])
    (it,) = Assembly.from_scene(scene).interfaces
    assert len(it.points) == 4
    assert not np.any(np.all(np.isclose(it.points[:, :2], [0.0, -0.5 - 2e-4], atol=1e-12), axis=1))
    (full,) = Assembly.from_scene(scene, EVERYTHING).interfaces
    assert len(full.points) == 5
    assert it.area == full.area                         # area and origin: the exact overlap
    assert np.array_equal(it.frame.origin, full.frame.origin)
    # a bump beyond vertex_tol (relative to the prism's size 1) is a corner and stays
    (corner,) = Assembly.from_scene(make_scene("bump", [scene.blocks[0], pentagon_prism(2e-3)])
                                    ).interfaces
    assert len(corner.points) == 5


def test_min_width_and_vertex_tol_zero_keep_everything():
    square_with_midpoint = np.array([[0, 0], [0.5, 0], [1, 0], [1, 1], [0, 1.0]])
    assert drop_collinear_rings(square_with_midpoint, [5], 0.0)[1][0] == 5
    assert drop_collinear_rings(square_with_midpoint, [5], 1e-9)[1][0] == 4
    sliver = np.array([[0, 0], [1, 0], [1, 1e-9], [0, 1e-9]])
    assert ring_widths(sliver, [4])[0] == pytest.approx(1e-9)
    for scene in (strip_scene(1e-5), gen.dome(slices=8, courses=4)):
        fine = Assembly.from_scene(scene, EVERYTHING)
        coarse = Assembly.from_scene(scene)
        assert len(fine.interfaces) >= len(coarse.interfaces)
        assert sum(len(it.points) for it in fine.interfaces) >= sum(
            len(it.points) for it in coarse.interfaces)


@pytest.mark.parametrize("bad", [dict(min_width=-1e-3), dict(vertex_tol=math.nan),
                                 dict(distance_tol=math.inf), dict(min_area=-1.0),
                                 dict(angle_tol_deg=True)])
def test_contact_options_reject_negative_and_non_finite_values(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        ContactOptions(**bad)


def _drop_reference(points, tol):
    """The greedy rule one polygon at a time: drop the vertex nearest its neighbours' chord
    while it is closer than tol, down to 3 vertices."""
    pts = [np.asarray(p, dtype=float) for p in points]
    while len(pts) > 3:
        dist = []
        for k, p in enumerate(pts):
            a, b = pts[k - 1], pts[(k + 1) % len(pts)]
            chord = b - a
            length = math.hypot(*chord)
            dist.append(abs(chord[0] * (p - a)[1] - chord[1] * (p - a)[0]) / (length or 1.0))
        worst = int(np.argmin(dist))
        if not dist[worst] < tol:
            break
        del pts[worst]
    return np.array(pts)


def test_vectorised_vertex_dropping_matches_the_greedy_rule():
    rng = np.random.default_rng(7)
    polygons, tols = [], []
    for _ in range(300):
        k = int(rng.integers(3, 12))
        angle = np.sort(rng.uniform(0, 2 * np.pi, k))
        corners = np.column_stack((np.cos(angle), np.sin(angle))) * rng.uniform(0.5, 2, 2)
        ring = []
        for i in range(k):                      # near-collinear points on some edges
            ring.append(corners[i])
            for _ in range(int(rng.integers(0, 3))):
                e = corners[(i + 1) % k] - corners[i]
                ring.append(corners[i] + rng.uniform(0.1, 0.9) * e
                            + rng.normal() * 1e-3 * np.array([-e[1], e[0]]))
        polygons.append(np.array(ring))
        tols.append(rng.uniform(0, 2e-3))
    counts = [len(p) for p in polygons]
    kept, kept_counts = drop_collinear_rings(np.concatenate(polygons), counts, tols)
    assert (np.asarray(counts) - kept_counts).sum() > 100
    for ring, tol, got in zip(polygons, tols, np.split(kept, np.cumsum(kept_counts)[:-1])):
        assert np.array_equal(got, _drop_reference(ring, tol))


def test_ring_widths_of_convex_polygons_match_the_narrowest_direction():
    rng = np.random.default_rng(3)
    rings = []
    for _ in range(50):
        angle = np.sort(rng.uniform(0, 2 * np.pi, int(rng.integers(3, 10))))
        rings.append(np.column_stack((np.cos(angle), np.sin(angle))) * rng.uniform(0.1, 3, 2))
    widths = ring_widths(np.concatenate(rings), [len(r) for r in rings])
    directions = np.linspace(0, np.pi, 20001)
    directions = np.column_stack((np.cos(directions), np.sin(directions)))
    for ring, width in zip(rings, widths):
        proj = ring @ directions.T
        narrowest = (proj.max(axis=0) - proj.min(axis=0)).min()
        assert narrowest * (1 - 1e-3) <= width <= narrowest * (1 + 1e-12)


def test_batch_posing_matches_posing_one_block_at_a_time():
    rot = Rotation.from_euler("xyz", [10, 20, 30], degrees=True).as_quat()
    blocks = [box_block("a", (1, 2, 3), (1, 2, 3), rot, density=DENSITY),
              box_block("b", (1, 1, 1), (0, 0, 0), density=DENSITY)] + list(gen.dome(8, 3).blocks)
    for one, batch in zip((pose_block(b) for b in blocks), pose_blocks(blocks)):
        for field in ("vertices", "centroid", "aabb", "face_normals", "face_origins",
                      "face_us", "face_vs"):
            assert np.array_equal(getattr(one, field), getattr(batch, field))
        assert np.allclose(one.face_offsets, batch.face_offsets, rtol=0, atol=1e-12)
        for face, u, n in zip(batch.faces, batch.face_us, batch.face_normals):
            assert np.array_equal(face.frame.u, u) and np.array_equal(face.frame.n, n)


def test_cached_kerns_match_kerns_computed_afresh():
    blocks = pose_blocks(gen.dome(slices=8, courses=4).blocks)
    detected = detect_interfaces(blocks)
    fresh = [Interface(it.a, it.b, it.frame, it.points, it.area) for it in detected]
    Interface.compute_kerns(fresh)
    for it, new in zip(detected, fresh):
        assert np.allclose(it.kern, new.kern, rtol=0, atol=1e-12)
        assert np.allclose(new.kern, it.frame.to_3d(kern(it.polygon2d())), rtol=0, atol=1e-12)
