"""Geometry kernels against second computations that share no code with them, written for
mutants that survived the rest of the suite (docs/MUTATION.md): kerns against the brute-force
intersection of their no-tension half-planes (shapely) in any vertex order, penetration depths
of crossed ridges and of many-faced blocks against closed forms, and the as-built mid-plane
against line-plane intersections."""
import numpy as np
import pytest
import shapely
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from rbe_ros.analysis.assembly import Assembly
from rbe_ros.geometry.contacts import ContactOptions, _overlaps, _shapely_overlaps, detect_interfaces
from rbe_ros.geometry.kern import kerns, kerns_ragged
from rbe_ros.geometry.overlap import _inscribed_radius, find_penetration
from rbe_ros.geometry.polygon import tangent_basis
from rbe_ros.geometry.uncertainty import gaps, mid_frames
from rbe_ros.scene import box_block, make_block, make_scene

from helpers import DENSITY
from test_mass_properties import prism_faces


def _second_moments(ring: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Area, centroid and J_G of a convex ring by fanning it into triangles from its first
    vertex (a triangle's second moment about its centroid is A/12 (sum of e e^T over its
    corners' offsets from the centroid), closed form)."""
    area, first, second = 0.0, np.zeros(2), np.zeros((2, 2))
    for b, c in zip(ring[1:-1], ring[2:]):
        tri = np.array([ring[0], b, c])
        (bx, by), (cx, cy) = b - ring[0], c - ring[0]
        a = 0.5 * abs(bx * cy - by * cx)
        g = tri.mean(axis=0)
        e = tri - g
        area += a
        first += a * g
        second += a * (e.T @ e / 12 + np.outer(g, g))
    g = first / area
    return area, g, second - area * np.outer(g, g)


def kern_by_half_planes(ring: np.ndarray) -> shapely.Polygon:
    """The kern as the set of resultant positions c under which the linear stress
    N/A (1 + A (c - G)^T J^-1 (v - G)) is >= 0 at every vertex v of the hull: a big square
    clipped by one half-plane per vertex."""
    hull = ring[ConvexHull(ring).vertices]
    area, g, j = _second_moments(hull)
    region = shapely.box(-1e3, -1e3, 1e3, 1e3)
    for v in hull:
        a = area * np.linalg.solve(j, v - g)          # 1 + a . (c - G) >= 0
        # the line a . c = a . G - 1, kept on the side of G
        d = a / (a @ a)
        foot = g + d * -1.0
        t = np.array([-a[1], a[0]]) * 1e4
        far = foot + d * 1e4
        region = region.intersection(shapely.Polygon([foot - t, foot + t, far + t, far - t]))
    return region


def _polygons(seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for k in (3, 4, 5, 7, 11):
        pts = rng.normal(size=(3 * k, 2)) * rng.uniform(0.2, 3.0, size=2) + rng.normal(size=2)
        out.append(pts[ConvexHull(pts).vertices][:k] if k < 11 else pts)
    return out


@pytest.mark.parametrize("order", ["ccw", "cw", "rolled"])
def test_kerns_are_the_no_tension_region_of_their_hull(order):
    """Convex counter-clockwise rings (k vertices: k poles), clockwise ones and point clouds
    (their hull's), several vertex counts in one call: each kern is the intersection of the
    half-planes in which a compressive resultant leaves every vertex in compression."""
    rings = _polygons(7)
    if order == "cw":
        rings = [r[::-1] for r in rings]
    elif order == "rolled":
        rings = [np.roll(r, 2, axis=0) for r in rings]
    for ring, got in zip(rings, kerns(rings)):
        hull = ring[ConvexHull(ring).vertices]
        want = kern_by_half_planes(ring)
        assert len(got) == len(hull)
        assert shapely.Polygon(got).is_valid and shapely.Polygon(got).exterior.is_ccw
        assert shapely.Polygon(got).symmetric_difference(want).area < 1e-9 * want.area
        for p in got:                                  # every pole is a corner of the oracle
            assert min(np.hypot(*(np.asarray(want.exterior.coords) - p).T)) < 1e-7


def test_kern_of_a_square_with_a_vertex_on_an_edge_is_its_hull_kern():
    """A vertex on an edge (a straight angle) makes the ring not strictly convex: the kern is
    the square's, the middle-third rhombus, with its 4 vertices."""
    square = np.array([[0, 0], [3, 0], [3, 1.5], [3, 3], [0, 3]], dtype=float)
    [got] = kerns([square])
    assert len(got) == 4
    want = kern_by_half_planes(square)
    assert shapely.Polygon(got).symmetric_difference(want).area < 1e-12
    assert want.area == pytest.approx(0.5, abs=1e-12)           # diagonals 1 and 1


def _pole_of_edge(ring: np.ndarray, i: int) -> np.ndarray:
    """The pole of edge (v_i, v_i+1): the resultant position at which the stress vanishes at
    both its ends (the two half-plane boundaries of kern_by_half_planes meet there)."""
    area, g, j = _second_moments(ring)
    a = area * np.linalg.solve(j, np.array([ring[i], ring[(i + 1) % len(ring)]]).T - g[:, None])
    return g + np.linalg.solve(a.T, [-1.0, -1.0])


@pytest.mark.parametrize("scale", [1.0, 0.05])
def test_kern_of_a_convex_ccw_ring_lists_the_pole_of_edge_i_at_i(scale):
    """On a convex counter-clockwise ring, kern vertex i is the pole of edge i (the order the
    report's kern keeps), also beside a clockwise ring that needs its hull; small rings too
    (edge cross products far below 1)."""
    rings = [np.roll(r, s + 1, axis=0) * scale for s, r in enumerate(_polygons(3)[:4])]
    for ring, got in zip(rings, kerns(rings + [rings[2][::-1]])):
        want = np.array([_pole_of_edge(ring, i) for i in range(len(ring))])
        assert np.allclose(got, want, rtol=0, atol=1e-9 * scale)


def test_kerns_of_integer_rings_and_of_none():
    """Integer coordinates are read as floats (the kern of the 3 x 3 square is the rhombus
    of its middle thirds, corners at 1.5 +- 0.5: not truncated); no polygons give no kerns."""
    pts, counts = kerns_ragged(np.array([[0, 0], [3, 0], [3, 3], [0, 3]]), [4])
    assert np.allclose(pts, [[1.5, 2], [1, 1.5], [1.5, 1], [2, 1.5]], rtol=0, atol=1e-12)
    assert counts.tolist() == [4]
    pts, counts = kerns_ragged(np.zeros((0, 2)), [])
    assert pts.shape == (0, 2) and len(counts) == 0
    assert kerns([]) == []


def _crossed_ridges(overlap: float, b_above: bool):
    """Two long boxes turned 45 deg (a about y, b about x), ridge against ridge, overlapping by
    ``overlap`` along z; a is long in y and b in x, so that the projections of the two blocks
    differ on every axis. The ridges cross at a point: the shortest separating translation is
    along z, by ``overlap``, which only an edge-edge axis finds."""
    qa = Rotation.from_euler("y", 45, degrees=True).as_quat()
    qb = Rotation.from_euler("x", 45, degrees=True).as_quat()
    side = 1 if b_above else -1
    z = side * (np.sqrt(2) - overlap)                  # each ridge is sqrt(2) / 2 off centre
    return Assembly.from_scene(make_scene("ridges", [
        box_block("g", (9, 9, 0.2), (0, 0, -9), support=True, density=DENSITY),
        box_block("a", (1, 3, 1), (0, 0, 0), qa, density=DENSITY),
        box_block("b", (3, 1, 1), (0, 0, z), qb, density=DENSITY)])).blocks


@pytest.mark.parametrize("b_above", [True, False])
def test_crossed_ridges_penetrate_by_their_overlap(b_above):
    hit = find_penetration(list(_crossed_ridges(0.1, b_above)), 0.01)
    assert (hit.a, hit.b) == (1, 2) and hit.depth == pytest.approx(0.1, rel=1e-9)
    assert find_penetration(list(_crossed_ridges(0.005, b_above)), 0.01) is None


def _cylinder(block_id: str, z: float, x: float = 0.0, height: float = 1.0, sides: int = 70):
    """A prism on a regular polygon of radius 1 (``sides`` + 2 faces, a vertex on +x), from
    z to z + height."""
    t = 2 * np.pi * np.arange(sides) / sides
    ring = np.column_stack((np.cos(t), np.sin(t)))
    vertices = np.vstack([np.column_stack((ring, np.full(sides, h))) for h in (0.0, height)])
    return make_block(block_id, vertices, prism_faces(vertices), (x, 0, z), density=DENSITY)


@pytest.mark.parametrize("overlap", [0.3, 0.04])
def test_many_faced_blocks_overlapping_hold_a_ball_of_half_the_overlap(overlap):
    """Blocks of more than 64 faces are decided by the largest ball inside both: two coaxial
    prisms overlapping by h along their axis share a slab of thickness h, whose largest ball
    has radius h / 2 (h is below the inradius); the depth reported is the overlap along the
    axis, a face normal."""
    blocks = list(Assembly.from_scene(make_scene("posts", [
        box_block("g", (9, 9, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        _cylinder("a", 0.0), _cylinder("b", 1.0 - overlap)])).blocks)
    assert _inscribed_radius(blocks[1], blocks[2]) == pytest.approx(overlap / 2, rel=1e-6)
    hit = find_penetration(blocks, 0.01)
    assert (hit.a, hit.b) == (1, 2) and hit.depth == pytest.approx(overlap, rel=1e-9)
    apart = list(Assembly.from_scene(make_scene("posts", [
        box_block("g", (9, 9, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        _cylinder("a", 0.0), _cylinder("b", 1.2)])).blocks)
    assert _inscribed_radius(apart[1], apart[2]) == 0.0


def test_many_faced_blocks_side_by_side_hold_a_ball_set_by_their_lateral_overlap():
    """Two such prisms side by side, overlapping by w = 0.3 across their vertices on the x
    axis, one 1 m and one 0.4 m tall: the largest ball sits on the x axis halfway between
    them, away from the midpoint of their centroids (z 0.35), touching the faces next to
    each vertex: radius cos(pi / 70) w / 2."""
    blocks = list(Assembly.from_scene(make_scene("posts", [
        box_block("g", (9, 9, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        _cylinder("a", 0.0), _cylinder("b", 0.0, x=1.7, height=0.4)])).blocks)
    assert _inscribed_radius(blocks[1], blocks[2]) == pytest.approx(np.cos(np.pi / 70) * 0.15,
                                                                    rel=1e-6)


def _plane_point(point, direction, normal, offset):
    """Where the line point + t direction meets the plane normal . x = offset (solved as a
    3 x 3 system with two equations fixing the line)."""
    a = np.vstack((normal, np.cross(direction, [1.0, 0.3, 0.1]), np.cross(direction, [0.2, 1.0, 0.7])))
    b = [offset, a[1] @ point, a[2] @ point]
    return np.linalg.solve(a, b)


def test_mid_frame_is_halfway_between_tilted_planes_on_the_bisector():
    """Faces 10 deg from opposite, 0.02 m apart: the frame's normal is the bisector of n_a and
    -n_b, its origin halfway between the two planes on the line along it through the midpoint
    of the face points, its axes those of the design frame of that normal, right-handed."""
    n_a = np.array([[0.0, 0.0, 1.0], [0.9, 0.3, np.sqrt(0.1)]])
    tilt = Rotation.from_euler("x", 10, degrees=True).apply(-n_a)
    n_b = np.array([tilt[0], -n_a[1]])
    o_a = np.array([[0.3, -0.2, 1.0], [1.0, 2.0, 3.0]])
    o_b = np.array([[0.5, 0.4, 1.05], [1.5, 2.5, 3.5]])
    d_a = np.einsum("ij,ij->i", n_a, o_a)
    d_b = np.einsum("ij,ij->i", n_b, o_b) + 0.02
    origin, u, v, n = mid_frames(n_a, d_a, o_a, n_b, d_b, o_b)
    for k in range(2):
        bisector = (n_a[k] - n_b[k]) / np.linalg.norm(n_a[k] - n_b[k])
        assert np.allclose(n[k], bisector, rtol=0, atol=1e-15)
        centre = 0.5 * (o_a[k] + o_b[k])
        want = 0.5 * (_plane_point(centre, n[k], n_a[k], d_a[k])
                      + _plane_point(centre, n[k], n_b[k], d_b[k]))
        assert np.allclose(origin[k], want, rtol=0, atol=1e-12)
        gap = gaps(origin[k:k + 1], n[k:k + 1], n_a[k:k + 1], d_a[k:k + 1], n_b[k:k + 1],
                   d_b[k:k + 1])
        assert gap[0] == pytest.approx(np.linalg.norm(_plane_point(centre, n[k], n_b[k], d_b[k])
                                                      - _plane_point(centre, n[k], n_a[k], d_a[k]))
                                       * np.sign(gap[0]), rel=1e-12)
        du, dv = tangent_basis(n[k])
        assert np.allclose([u[k], v[k]], [du, dv], rtol=0, atol=1e-15)
        assert np.allclose(np.cross(u[k], v[k]), n[k], rtol=0, atol=1e-15)
    assert n[1][0] == 0.9                     # on the limit of the design frame's helper axis


def test_overlaps_of_non_convex_outlines_are_their_polygon_pieces_counter_clockwise():
    """A U (3 x 2, notch 1 wide and 1 deep from the top) against: a bar across both arms
    (two 1 x 0.5 pieces), a square sitting in the notch (touching along lines only: no
    piece), a far square (nothing); the bar given clockwise. Each piece: its ring counter-
    clockwise (shoelace area positive), its area and centroid in closed form, its pair."""
    u_shape = shapely.Polygon([(0, 0), (3, 0), (3, 2), (2, 2), (2, 1), (1, 1), (1, 2), (0, 2)])
    bar = shapely.Polygon([(-1, 1.5), (-1, 2), (4, 2), (4, 1.5)])                  # clockwise
    notch = shapely.box(1, 1, 2, 2)
    far = shapely.box(10, 10, 11, 11)
    ring, counts, owner, area, centroid = _shapely_overlaps(
        np.array([u_shape, u_shape, u_shape, u_shape]), np.array([bar, notch, far, bar]),
        np.array([4, 7, 9, 11]))
    assert owner.tolist() == [4, 4, 11, 11] and counts.tolist() == [4, 4, 4, 4]
    assert np.allclose(area, 0.5)
    assert np.allclose(sorted(centroid[:2].tolist()), [[0.5, 1.75], [2.5, 1.75]])
    for k, start in enumerate(np.cumsum(counts) - counts):
        x, y = ring[start:start + counts[k]].T
        assert 0.5 * (x @ np.roll(y, -1) - np.roll(x, -1) @ y) == pytest.approx(0.5)


def _wedge(block_id: str, x: float, z: float):
    """A right triangle (legs 1, in x and z) extruded 0.125 along y: 6 vertices, 5 faces,
    volume 1/16, so size (the cube root of the volume) 0.397; its base at height z."""
    tri = np.array([[0, 0], [1, 0], [0, 1]], dtype=float)
    vertices = np.vstack([np.column_stack((tri[:, 0], np.full(3, y), tri[:, 1]))
                          for y in (-0.0625, 0.0625)])
    return make_block(block_id, vertices, prism_faces(vertices), (x, 0, z), density=DENSITY)


def test_the_deepest_penetration_is_found_with_the_smaller_blocks_tolerance():
    """Two wedges sunk into the top of a 2 m cube by 0.02 and 0.01 (the cube 8 vertices,
    a wedge 6: padded to one count): the deeper is reported, with the tolerance of the smaller
    block of its pair (1 % of the wedge's size, 0.004, not of the cube's, 0.02), and only
    two blocks suffice; the wedge's pose allowance adds to the tolerance."""
    size = (1 / 16) ** (1 / 3)
    cube = box_block("cube", (2, 2, 2), (0, 0, 1), density=DENSITY)
    blocks = list(Assembly.from_scene(make_scene("sunk", [
        box_block("g", (9, 9, 0.2), (0, 0, -0.1), support=True, density=DENSITY), cube,
        _wedge("w1", -0.8, 2 - 0.01), _wedge("w2", 0.2, 2 - 0.02)])).blocks)
    hit = find_penetration(blocks, 0.01)
    assert (hit.a, hit.b) == (1, 3)
    assert hit.depth == pytest.approx(0.02, rel=1e-9) and hit.tol == pytest.approx(0.01 * size)
    for pair in (blocks[1:3], blocks[2:0:-1]):
        hit = find_penetration(pair, 0.01)
        assert (hit.a, hit.b) == (0, 1) and hit.depth == pytest.approx(0.01, rel=1e-9)
        assert hit.tol == pytest.approx(0.01 * size)
    assert find_penetration(blocks[1:3], 0.01, allowance=np.array([0.0, 0.007])) is None
    assert find_penetration(blocks[1:3], 0.01, allowance=np.array([0.007, 0.0])) is None
    assert find_penetration(blocks[1:3], 0.01, allowance=np.array([0.0, 0.005])).tol \
        == pytest.approx(0.01 * size + 0.005)


def test_detected_interfaces_follow_the_distance_tolerance():
    """A unit cube 2 mm above another (1 x 1 faces): no interface within the default 1e-3 of
    the size, one of area 1 within 3e-3; the near contacts are another list."""
    blocks = list(Assembly.from_scene(make_scene("gap", [
        box_block("g", (1, 1, 1), (0, 0, 0.5), support=True, density=DENSITY),
        box_block("c", (1, 1, 1), (0, 0, 1.502), density=DENSITY)])).blocks)
    assert detect_interfaces(blocks) == []
    [it] = detect_interfaces(blocks, ContactOptions(distance_tol=3e-3))
    assert (it.a, it.b) == (0, 1) and it.area == pytest.approx(1.0, rel=1e-12)


def test_no_outline_pairs_have_no_overlaps():
    ring, counts, rows, area, centroid = _overlaps(None, None, None, None, None, None, None,
                                                   None, np.zeros(0, dtype=np.intp))
    assert ring.shape == (0, 2) and centroid.shape == (0, 2)
    assert counts.shape == area.shape == rows.shape == (0,) and counts.dtype == np.intp
