"""Contact detection: the fidelity rules (ContactOptions.min_width, vertex_tol), the
vectorised polygon helpers against plain per-polygon references, and the batched convex
clipping against shapely."""
import math

import numpy as np
import pytest
import shapely
from scipy.spatial.transform import Rotation

from rbe_ros import generators as gen
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.geometry.block import pose_block, pose_blocks
from rbe_ros.geometry.clip import clip_convex, padded_rings
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


# ---------------------------------------------------------------- batched convex clipping

def _clip(pairs, eps=1e-12):
    """clip_convex on (polygon a, polygon b) vertex lists, read as detect_interfaces reads
    face outlines (shapely coordinates through padded_rings: any orientation, any vertex
    counts, one batch): {pair index: (ring, area, centroid)} for the pairs that overlap."""
    outlines = [np.array([shapely.Polygon(a) for a, _ in pairs]),
                np.array([shapely.Polygon(b) for _, b in pairs])]
    rows, size = np.arange(len(pairs)), np.ones(len(pairs))
    (ax, ay, na, convex_a), (bx, by, nb, convex_b) = (
        padded_rings(*shapely.get_coordinates(o, return_index=True), rows, size) for o in outlines)
    assert convex_a.all() and convex_b.all()
    ring, counts, of, area, centroid = clip_convex(ax, ay, na, bx, by, nb,
                                                    np.full(len(pairs), eps))
    rings = np.split(ring, np.cumsum(counts)[:-1])
    return {int(k): (r, a, c) for k, r, a, c in zip(of, rings, area, centroid)}


def _same_vertices(ring, expected, tol=1e-12):
    """Whether ``ring`` has the vertices of ``expected`` (any start, same count)."""
    expected = np.asarray(expected, dtype=float)
    if len(ring) != len(expected):
        return False
    d = np.linalg.norm(ring[:, None] - expected[None], axis=2)
    return bool((d.min(axis=0) <= tol).all() and (d.min(axis=1) <= tol).all())


def _signed_area(ring):
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


SQUARE = [(0, 0), (1, 0), (1, 1), (0, 1)]


def test_clip_of_two_offset_squares():
    offset = [(0.5, 0.25), (0.5, 1.25), (1.5, 1.25), (1.5, 0.25)]        # clockwise, as face b
    ((ring, area, centroid),) = _clip([(SQUARE, offset)]).values()
    assert _same_vertices(ring, [(0.5, 0.25), (1, 0.25), (1, 1), (0.5, 1)])
    assert _signed_area(ring) == pytest.approx(area) and area == pytest.approx(0.375)
    assert centroid == pytest.approx([0.75, 0.625])


def test_clip_of_a_triangle_and_a_hexagon_matches_shapely():
    angle = np.arange(6) * np.pi / 3
    hexagon = np.column_stack((np.cos(angle), np.sin(angle)))
    triangle = np.array([(-1.2, -0.3), (1.5, -0.3), (0.2, 1.6)])
    got = _clip([(triangle, hexagon), (hexagon, triangle[::-1])])
    reference = shapely.Polygon(triangle).intersection(shapely.Polygon(hexagon))
    expected = np.array(reference.exterior.coords[:-1])
    assert len(got) == 2
    for ring, area, centroid in got.values():
        assert _same_vertices(ring, expected)
        assert area == pytest.approx(reference.area, rel=1e-12)
        assert centroid == pytest.approx(np.array(reference.centroid.coords[0]), abs=1e-12)
        assert _signed_area(ring) > 0                                       # counter-clockwise


def test_squares_sharing_an_edge_or_a_corner_have_no_overlap():
    beside = [(1, 0), (2, 0), (2, 1), (1, 1)]
    corner = [(1, 1), (2, 1), (2, 2), (1, 2)]
    noisy = [(1 - 1e-16, 0), (2, 0), (2, 1), (1 + 1e-16, 1)]              # rounding of a frame
    sliver = [(1 - 1e-13, 0), (2, 0), (2, 1), (1 - 1e-13, 1)]            # thinner than eps
    strip = [(1 - 1e-9, 0), (2, 0), (2, 1), (1 - 1e-9, 1)]
    got = _clip([(SQUARE, beside), (SQUARE, corner), (SQUARE, noisy), (SQUARE, sliver),
                 (SQUARE, strip)])
    assert list(got) == [4]
    ring, area, _ = got[4]
    assert _same_vertices(ring, [(1 - 1e-9, 0), (1, 0), (1, 1), (1 - 1e-9, 1)])
    assert area == pytest.approx(1e-9, rel=1e-6)


def test_identical_and_nested_polygons():
    angle = np.linspace(0, 2 * np.pi, 11)[:-1]
    decagon = np.column_stack((np.cos(angle), np.sin(angle))) * 0.3 + 0.5
    got = _clip([(SQUARE, SQUARE), (SQUARE, SQUARE[::-1]), (decagon, decagon[::-1]),
                 (SQUARE, decagon), (decagon, SQUARE)])
    assert list(got) == [0, 1, 2, 3, 4]
    for k, polygon in enumerate([SQUARE, SQUARE, decagon, decagon, decagon]):
        ring, area, _ = got[k]
        assert _same_vertices(ring, polygon)              # no vertex added on shared edges
        assert area == pytest.approx(shapely.Polygon(polygon).area, rel=1e-12)


def _random_convex(rng, k):
    """A random convex polygon of up to k vertices (hull of k random points), often a
    rectangle or another polygon with edges on the lines of a square's edges."""
    if rng.random() < 0.3:
        x0, y0 = rng.choice([0.0, 0.25, 0.5, 1.0], 2)
        return [(x0, y0), (x0 + 1, y0), (x0 + 1, y0 + rng.choice([0.5, 1.0])), (x0, y0 + 1)][
            :4 if rng.random() < 0.5 else 3]
    pts = rng.normal(size=(k, 2)) * rng.uniform(0.2, 2, 2) + rng.normal(size=2) * 0.5
    return np.array(shapely.MultiPoint(pts).convex_hull.exterior.coords[:-1])


def test_clip_of_random_convex_polygons_matches_shapely():
    rng = np.random.default_rng(11)
    pairs = []
    for _ in range(600):
        a = _random_convex(rng, int(rng.integers(3, 14)))
        b = _random_convex(rng, int(rng.integers(3, 14)))
        pairs.append((a, b[::-1] if rng.random() < 0.5 else b))
    got = _clip(pairs)
    overlapping = 0
    for k, (a, b) in enumerate(pairs):
        reference = shapely.Polygon(a).intersection(shapely.Polygon(b))
        if k not in got:
            assert reference.area <= 1e-12
            continue
        overlapping += 1
        ring, area, centroid = got[k]
        assert area == pytest.approx(reference.area, rel=1e-9, abs=1e-13)
        assert _signed_area(ring) == pytest.approx(area, rel=1e-12)
        assert shapely.hausdorff_distance(shapely.Polygon(ring), reference) <= 1e-9
        assert centroid == pytest.approx(np.array(reference.centroid.coords[0]), abs=1e-9)
    assert overlapping > 300


def l_prism(block_id, z0, height=1.0):
    """An L-shaped prism (area 3: a 2 x 2 square without its corner quadrant) standing on
    z = z0: non-convex bottom and top faces."""
    ring = [(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)]
    vertices = [(x, y, z0) for x, y in ring] + [(x, y, z0 + height) for x, y in ring]
    n = len(ring)
    faces = [tuple(reversed(range(n))), tuple(range(n, 2 * n))]
    faces += [(k, (k + 1) % n, n + (k + 1) % n, n + k) for k in range(n)]
    return make_block(block_id, vertices, faces, density=DENSITY)


def test_faces_of_non_convex_blocks_are_still_clipped_exactly():
    scene = make_scene("L", [
        box_block("ground", (8, 8, 1.0), (0, 0, -0.5), support=True, density=DENSITY),
        l_prism("L", 0.0),
        box_block("cube", (1, 1, 1), (-2.5, 0.5, 0.5), density=DENSITY),
        box_block("top", (1.5, 1.5, 1), (1.25, 1.25, 1.5), density=DENSITY),   # over the notch
    ])
    found = {(scene.blocks[it.a].id, scene.blocks[it.b].id): it
             for it in Assembly.from_scene(scene).interfaces}
    assert found["ground", "L"].area == pytest.approx(3.0) and len(found["ground", "L"].points) == 6
    assert found["ground", "cube"].area == pytest.approx(1.0)
    assert found["L", "top"].area == pytest.approx(1.5 ** 2 - 1.0)    # an L again
    assert len(found["L", "top"].points) == 6
    assert [(it.a, it.b) for it in Assembly.from_scene(scene).interfaces] == sorted(
        (it.a, it.b) for it in found.values())
    (alone,) = Assembly.from_scene(make_scene("L", scene.blocks[:2])).interfaces  # shapely only
    assert alone.area == pytest.approx(3.0)
