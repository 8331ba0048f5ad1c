"""Parametric scenes: the benchmarks of the paper and the literature, built in code.

Conventions shared by every generator: SI units, gravity along -z, the ground (or the
blocks standing for it) are supports. Every block is a closed convex polyhedron with planar
faces wound outward; its vertices are given relative to their mean, which is the block's
``position`` (identity orientation), so a block's frame sits at its centre. Ids are readable
and unique ("v03", "course3_slice07"), the output is deterministic and ``sequence`` lists
the free blocks in a build order (bottom up; arches from both springings to the key).
Sources: Kao et al. 2021 (RBE), Sec. 3.1-3.3; Paterson & Zwick 2009 (harmonic stack).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.spatial import ConvexHull

from .scene import BOX_FACES, Block, Scene, make_block, make_scene


# --------------------------------------------------------------------------- helpers

def _signed_volume(vertices: np.ndarray, faces) -> float:
    """Volume enclosed by the faces (positive when they are wound outward)."""
    total = 0.0
    for f in faces:
        a = vertices[f[0]]
        for i in range(1, len(f) - 1):
            total += float(np.dot(a, np.cross(vertices[f[i]], vertices[f[i + 1]])))
    return total / 6.0


def _prism(block_id: str, corners, *, density: float, support: bool = False) -> Block:
    """A hexahedron from 8 corners: a quad 0-3 and the quad 4-7 with corner 4+i joined to i,
    both quads in the same cyclic order (the ordering of :data:`BOX_FACES`). The faces are
    turned outward whichever way the quads run."""
    corners = np.asarray(corners, dtype=float)
    centre = corners.mean(axis=0)
    local = corners - centre
    faces = BOX_FACES
    if _signed_volume(local, faces) < 0:
        faces = tuple(tuple(reversed(f)) for f in faces)
    return make_block(block_id, local, faces, centre, density=density, support=support)


def _box(block_id: str, lo, hi, *, density: float, support: bool = False) -> Block:
    """An axis-aligned box between the corners ``lo`` and ``hi``."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    bottom = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0)]
    top = [(x, y, z1) for x, y, _ in bottom]
    return _prism(block_id, bottom + top, density=density, support=support)


def _x_prism(block_id: str, x0, x1, y0, y1, z_bottom, z_top, *, density: float,
             support: bool = False) -> Block:
    """A prism over the rectangle [x0, x1] x [y0, y1] between two planes z = f(x)."""
    bottom = [(x, y, z_bottom(x)) for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))]
    top = [(x, y, z_top(x)) for x, y, _ in bottom]
    return _prism(block_id, bottom + top, density=density, support=support)


def _ids(prefix: str, count: int) -> list[str]:
    """``prefix`` with a zero-padded index, as wide as the largest index needs (min. 2)."""
    width = max(2, len(str(count - 1)))
    return [f"{prefix}{i:0{width}d}" for i in range(count)]


def _voussoirs(ids, centre, r_in: float, r_out: float, depth: float, *,
               density: float) -> list[Block]:
    """Voussoirs of a semicircular arch in the xz-plane around ``centre``, from the springing
    at +x (angle 0) to the one at -x (angle pi); radial joints, planar intrados/extrados."""
    c = np.asarray(centre, dtype=float)
    n = len(ids)
    out = []
    for i, bid in enumerate(ids):
        quads = []
        for angle in (math.pi * i / n, math.pi * (i + 1) / n):
            d = np.array([math.cos(angle), 0.0, math.sin(angle)])
            y = np.array([0.0, depth / 2, 0.0])
            quads += [c + r_in * d - y, c + r_out * d - y, c + r_out * d + y, c + r_in * d + y]
        out.append(_prism(bid, quads, density=density))
    return out


def _key_order(ids) -> list[str]:
    """Alternately from both ends to the middle: the order in which an arch is closed."""
    ids = list(ids)
    order = []
    while ids:
        order.append(ids.pop(0))
        if ids:
            order.append(ids.pop())
    return order


# --------------------------------------------------------------------------- generators

def polycube(block_id: str, cells, size: float = 0.1, *, density: float = 2000.0,
             support: bool = False) -> Block:
    """A block made of the cubes ``cells`` (integer (i, j, k), cube [i, i+1] x ... times
    ``size`` m): the cubes' faces between a cube and no cube, wound outward, with vertices on
    the grid, posed at the cubes' mean centre. Cubes must meet face to face (not along an
    edge only), so the mesh is closed and manifold."""
    filled = {tuple(int(v) for v in c) for c in cells}
    corners: dict[tuple, int] = {}
    faces = []
    for c in sorted(filled):
        for axis in range(3):
            for side in (0, 1):
                step = [0, 0, 0]
                step[axis] = 2 * side - 1
                if tuple(np.add(c, step)) in filled:
                    continue
                u, v = (axis + 1) % 3, (axis + 2) % 3
                quad = []
                for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
                    p = list(c)
                    p[axis] += side
                    p[u] += du
                    p[v] += dv
                    quad.append(corners.setdefault(tuple(p), len(corners)))
                faces.append(tuple(quad) if side else tuple(quad[::-1]))
    grid = np.array(sorted(corners, key=corners.get), dtype=float) * size
    centre = (np.array(sorted(filled), dtype=float) + 0.5).mean(axis=0) * size
    return make_block(block_id, grid - centre, faces, centre, density=density, support=support)


#: A 4 x 4 square of four T tetrominoes, locked in its plane: (x, z) cells per piece.
T_SQUARE = (((0, 3), (1, 3), (2, 3), (1, 2)), ((3, 3), (3, 2), (2, 2), (3, 1)),
            ((0, 2), (0, 1), (1, 1), (0, 0)), ((2, 1), (1, 0), (2, 0), (3, 0)))


def tetromino_wall(squares_x: int = 2, squares_z: int = 2, size: float = 0.1,
                   density: float = 2000.0) -> Scene:
    """A wall one cube thick (y) of T tetrominoes on a support "ground" (top at z = 0),
    ``squares_x`` by ``squares_z`` copies of :data:`T_SQUARE`, pieces "t{n}" listed bottom
    up (no sequence: a plan chooses). A piece whose square holds it on four sides can only
    come in along the wall's normal (+-y)."""
    blocks = [_box("ground", (-size, -2 * size, -size), ((4 * squares_x + 1) * size, 3 * size,
                                                          0.0), density=density, support=True)]
    pieces = []
    for sz in range(squares_z):
        for sx in range(squares_x):
            for piece in T_SQUARE:
                pieces.append([(4 * sx + x, 0, 4 * sz + z) for x, z in piece])
    pieces.sort(key=lambda cells: (min(c[2] for c in cells), min(c[0] for c in cells)))
    ids = _ids("t", len(pieces))
    blocks += [polycube(i, cells, size, density=density) for i, cells in zip(ids, pieces)]
    return make_scene(f"tetromino-wall({squares_x}x{squares_z})", blocks)


def cradle_row(bars: int = 4, depth: int = 3, size: float = 0.1,
               density: float = 2000.0) -> Scene:
    """A non-convex support "cradle" (a comb: ``bars`` grooves along y, open above and at
    both ends), a bar "bar{i}" set into each groove standing one cube proud, and over each
    bar an inverted U "cap{i}" whose legs stand on the cradle beside the groove: blocks in
    a non-convex base, non-convex blocks over them (no sequence: a plan chooses)."""
    width = 4 * bars + 1
    grooves = [4 * i + 2 for i in range(bars)]
    base = [(x, y, z) for x in range(width) for y in range(depth) for z in (0, 1)
            if not (z == 1 and x in grooves)]
    blocks = [polycube("cradle", base, size, density=density, support=True)]
    for i, g in enumerate(grooves):
        blocks.append(polycube(f"bar{i}", [(g, y, z) for y in range(depth) for z in (1, 2)],
                               size, density=density))
        blocks.append(polycube(f"cap{i}", [(x, y, 3) for x in (g - 1, g, g + 1)
                                           for y in range(depth)]
                               + [(x, y, 2) for x in (g - 1, g + 1) for y in range(depth)],
                               size, density=density))
    return make_scene(f"cradle-row({bars})", blocks)


def two_blocks(shift: float = 0.0, incline_deg: float = 0.0, width: float = 1.0,
               depth: float = 1.0, height: float = 0.5, density: float = 2000.0) -> Scene:
    """Two stacked blocks (Kao et al. 2021, Sec. 3.1): support "base" under free "top".

    Both are ``width`` (x) by ``depth`` (y); the interface is at mid-height ``height`` of the
    pair, tilted by ``incline_deg`` about y (z = height + tan(incline) x: "base" is a wedge-shaped
    prism, "top" a prism with its bottom on that plane and a horizontal top at 2 height).
    ``shift`` moves "top" by shift * width along x (along the inclined plane when tilted).
    With a horizontal interface it tips beyond shift 0.5; inclined, it needs mu >= tan(incline)
    (Sec. 3.1.2: 23.6 deg, mu 0.44).
    """
    slope = math.tan(math.radians(incline_deg))
    if not abs(slope) * width / 2 < height:
        raise ValueError(f"incline {incline_deg} deg is too steep for width {width} and"
                         f" height {height}: the blocks would have no thickness at an edge")
    s = shift * width
    w = width / 2
    base = _x_prism("base", -w, w, -depth / 2, depth / 2, lambda x: 0.0,
                    lambda x: height + slope * x, density=density, support=True)
    top = _x_prism("top", s - w, s + w, -depth / 2, depth / 2, lambda x: height + slope * x,
                   lambda x: 2 * height + slope * s, density=density)
    name = f"two-blocks(shift={shift:g}, incline={incline_deg:g})"
    return make_scene(name, [base, top], sequence=["top"])


def stack(n: int = 5, width: float = 1.0, depth: float = 1.0, height: float = 0.5,
          offsets=None, density: float = 2000.0) -> Scene:
    """A straight tower of ``n`` boxes "b00" (bottom) ... on a support slab "ground"
    (top at z = 0); ``offsets`` (one per box) shift each box along x."""
    offsets = [0.0] * n if offsets is None else [float(o) for o in offsets]
    if len(offsets) != n:
        raise ValueError(f"stack: {len(offsets)} offsets for {n} blocks")
    reach = width + 2 * max((abs(o) for o in offsets), default=0.0)
    blocks = [_box("ground", (-reach, -depth, -height), (reach, depth, 0.0),
                   density=density, support=True)]
    ids = _ids("b", n)
    for k, (bid, dx) in enumerate(zip(ids, offsets)):
        blocks.append(_box(bid, (dx - width / 2, -depth / 2, k * height),
                           (dx + width / 2, depth / 2, (k + 1) * height), density=density))
    return make_scene(f"stack({n})", blocks, sequence=ids)


def harmonic_stack(n: int = 5, scale: float = 1.0, length: float = 1.0, depth: float = 0.5,
                   height: float = 0.2, density: float = 2000.0) -> Scene:
    """The harmonic stack (Paterson & Zwick, "Overhang", Amer. Math. Monthly 2009).

    ``n`` equal blocks ``length`` long (x) on a support "table" whose edge is x = 0 (top at
    z = 0). Counting k = 1 at the top, block "h{k}" overhangs the one below it (the bottom one,
    k = n, the table edge) by scale * length / (2k); the total overhang is scale * length *
    H_n / 2. At scale 1 every level is exactly marginal, below 1 it stands, above it falls.
    """
    width = max(2, len(str(n)))
    ids = [f"h{k:0{width}d}" for k in range(1, n + 1)]               # h01 is the top block
    edge = 0.0                                                    # right edge of the support below
    blocks = [_box("table", (-2 * length, -depth, -height), (0.0, depth, 0.0),
                   density=density, support=True)]
    for level, k in enumerate(range(n, 0, -1)):                     # bottom (k = n) up
        edge += scale * length / (2 * k)
        blocks.append(_box(ids[k - 1], (edge - length, -depth / 2, level * height),
                           (edge, depth / 2, (level + 1) * height), density=density))
    return make_scene(f"harmonic-stack({n}, scale={scale:g})", blocks,
                      sequence=list(reversed(ids)))


def semicircular_arch(n: int = 15, thickness_ratio: float = 0.15, radius: float = 1.0,
                      depth: float = 1.0, density: float = 2000.0) -> Scene:
    """A semicircular arch of ``n`` voussoirs "v00" (at +x) ... with radial joints.

    Centre-line radius ``radius``, thickness t = thickness_ratio * radius, depth along y.
    The arch springs from two support blocks "support_right"/"support_left" (t x depth x t,
    top face horizontal at z = t, exactly under the springing joints); the arch centre is at
    (0, 0, t). Continuous limit for self-weight: t/R = 0.1074 (Cocchetti & Rizzi 2020).
    """
    t = thickness_ratio * radius
    if not 0 < t < 2 * radius:
        raise ValueError(f"thickness ratio {thickness_ratio} must be in (0, 2)")
    r_in, r_out = radius - t / 2, radius + t / 2
    blocks = [_box("support_right", (r_in, -depth / 2, 0), (r_out, depth / 2, t),
                   density=density, support=True),
              _box("support_left", (-r_out, -depth / 2, 0), (-r_in, depth / 2, t),
                   density=density, support=True)]
    ids = _ids("v", n)
    blocks += _voussoirs(ids, (0, 0, t), r_in, r_out, depth, density=density)
    return make_scene(f"semicircular-arch({n}, t/R={thickness_ratio:g})", blocks,
                      sequence=_key_order(ids))


def buttressed_arch(voussoirs: int = 15, inner_radius: float = 1.0, thickness: float = 0.3,
                    depth: float = 0.5, buttress_height: float = 2.5,
                    buttress_width: float = 0.7, buttress_depth: float = 1.0,
                    buttress_courses: int = 6, springing: str = "centre",
                    density: float = 1800.0) -> Scene:
    """The semicircular arch on buttresses of Kao et al. 2021, Sec. 3.2 (after Iannuzzo et
    al. 2020): arch inner radius 1.00 m, thickness 0.30 m, depth 0.50 m, 15 voussoirs; two
    buttresses 2.5 m high, 0.70 m wide (x) and 1.00 m deep (y); 1800 kg/m^3.

    Choices the paper leaves open: the 12 buttress elements are 6 equal courses per buttress
    ("buttress_right_0" at the bottom ... "buttress_right_5"), the bottom course of each is a
    support; the buttresses stand on z = 0 and the arch springs from their tops (z = 2.5 m)
    with a horizontal joint, centred in y. ``springing="centre"``: the springing joint sits in
    the middle of the 0.70 m top (buttress from x = 0.80 to 1.50 m); ``"inner"``: the buttress's
    inner face is flush with the intrados (x = 1.00 to 1.70 m). The minimum friction is 0.309
    either way (paper 0.31); the tilting capacity is 12.1 deg with "centre" (paper 12 deg,
    lambda 0.21) and 13.5 deg with "inner"; 3 courses per buttress raise it to 14.4 / 16.2 deg.
    """
    if springing not in ("centre", "inner"):
        raise ValueError(f'springing must be "centre" or "inner", not {springing!r}')
    inner = (inner_radius if springing == "inner"
             else inner_radius + (thickness - buttress_width) / 2)
    if inner > inner_radius or inner + buttress_width < inner_radius + thickness:
        raise ValueError("the springing joint must lie on the buttress top")
    h = buttress_height / buttress_courses
    blocks, free = [], []
    for side, sign in (("right", 1.0), ("left", -1.0)):
        xs = sorted((sign * inner, sign * (inner + buttress_width)))
        for c in range(buttress_courses):
            bid = f"buttress_{side}_{c}"
            blocks.append(_box(bid, (xs[0], -buttress_depth / 2, c * h),
                               (xs[1], buttress_depth / 2, (c + 1) * h),
                               density=density, support=c == 0))
    for c in range(1, buttress_courses):                  # both buttresses, course by course
        free += [f"buttress_right_{c}", f"buttress_left_{c}"]
    ids = _ids("v", voussoirs)
    blocks += _voussoirs(ids, (0, 0, buttress_height), inner_radius, inner_radius + thickness,
                         depth, density=density)
    return make_scene("buttressed-arch", blocks, sequence=free + _key_order(ids))


def dome(slices: int = 14, courses: int = 10, radius: float = 5.0, t_base: float = 0.5,
         t_oculus: float = 0.25, oculus_radius: float = 1.0, density: float = 2000.0) -> Scene:
    """The hemispherical dome with an oculus of Kao et al. 2021, Sec. 3.3.

    Centre-line sphere of ``radius`` about the origin, from the equator (z = 0) up to the
    oculus at polar angle asin(oculus_radius / radius) from the vertical; the thickness varies
    linearly in the polar angle from ``t_base`` to ``t_oculus``. ``courses`` rings of equal
    polar angle times ``slices`` meridian slices, "course{c}_slice{s}" (course 0 at the base,
    all supports). Course joints are radial (cones through the centre, planar per block:
    each contains the centre), meridian joints are vertical planes through the axis; intrados
    and extrados are planar isosceles trapezoids through the four corners.
    """
    top = math.asin(oculus_radius / radius)
    thetas = np.linspace(math.pi / 2, top, courses + 1)             # polar angles, base first
    phis = np.linspace(0.0, 2 * math.pi, slices + 1)

    def thick(theta):
        return t_base + (t_oculus - t_base) * (math.pi / 2 - theta) / (math.pi / 2 - top)

    cw, sw = len(str(courses - 1)), max(2, len(str(slices - 1)))
    blocks, order = [], []
    for c in range(courses):
        for s in range(slices):
            corners = []
            for theta in thetas[c:c + 2]:
                r_in, r_out = radius - thick(theta) / 2, radius + thick(theta) / 2
                d0, d1 = (np.array([math.sin(theta) * math.cos(p), math.sin(theta) * math.sin(p),
                                    math.cos(theta)]) for p in phis[s:s + 2])
                corners += [r_in * d0, r_out * d0, r_out * d1, r_in * d1]
            bid = f"course{c:0{cw}d}_slice{s:0{sw}d}"
            blocks.append(_prism(bid, corners, density=density, support=c == 0))
            if c:
                order.append(bid)
    return make_scene(f"dome({slices}x{courses})", blocks, sequence=order)


def running_bond_wall(courses: int = 6, bricks_per_course: int = 5, brick=(0.4, 0.2, 0.1),
                      density: float = 2000.0) -> Scene:
    """A wall in running bond on a support "footing" (top at z = 0), along x from x = 0.

    ``brick`` is (length x, thickness y, height z). Even courses hold ``bricks_per_course``
    whole bricks; odd courses are offset by half a brick, with a half brick at each end so both
    ends of the wall are straight. Bricks "course{c}_brick{b}" counted from x = 0.
    """
    length, thick, height = (float(v) for v in brick)
    span = bricks_per_course * length
    blocks = [_box("footing", (-thick, -thick, -height), (span + thick, thick, 0.0),
                   density=density, support=True)]
    order = []
    for c in range(courses):
        if c % 2:
            cuts = [0.0] + [length * (i + 0.5) for i in range(bricks_per_course)] + [span]
        else:
            cuts = [length * i for i in range(bricks_per_course + 1)]
        for b, (x0, x1) in enumerate(zip(cuts[:-1], cuts[1:])):
            bid = f"course{c:02d}_brick{b:02d}"
            blocks.append(_box(bid, (x0, -thick / 2, c * height), (x1, thick / 2, (c + 1) * height),
                               density=density))
            order.append(bid)
    return make_scene(f"running-bond-wall({courses}x{bricks_per_course})", blocks, sequence=order)


def side_by_side(scene: Scene, copies: int, spacing: float) -> Scene:
    """``copies`` of ``scene`` along x, ``spacing`` m apart, ids prefixed "c{i}_"; built one
    after the other, each in ``scene``'s order. Nothing joins them but the supports: a scene
    of independent parts (e.g. to see a per-step check re-solve only the part it touches)."""
    def copy(i: int):
        return [replace(b, id=f"c{i}_{b.id}", position=np.asarray(b.position) + [i * spacing, 0, 0])
                for b in scene.blocks]
    return make_scene(f"{copies} x {scene.name}", [b for i in range(copies) for b in copy(i)],
                      scene.gravity, sequence=[f"c{i}_{bid}" for i in range(copies)
                                               for bid in scene.sequence])


def dome_joint_ring(block_a: str, block_b: str) -> tuple[str, str]:
    """The ring of dome joints the interface between two dome blocks belongs to: joints of one
    ring are alike by symmetry (course joints between two courses, or meridian joints in one)."""
    return block_a.split("_")[0], block_b.split("_")[0]


def convex_domes(count: int = 1, vertices: int = 10_000, rim: int = 1000, radius: float = 0.3,
                 height: float = 0.2, density: float = 2000.0, seed: int = 0) -> Scene:
    """``count`` large convex blocks side by side on a ground slab (the cost of the shape
    analysis): each the convex hull of random points on the upper half of an ellipsoid over a
    flat base, a regular ``rim``-gon of ``radius`` (triangulated by the hull into many
    coplanar triangles: one face to find), ``vertices`` vertices in all. Each copy is scaled
    by 1 + k/1000, a distinct mesh."""
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(vertices - rim, 3))
    p /= np.linalg.norm(p, axis=1)[:, None]
    p[:, 2] = np.abs(p[:, 2]) + 1e-2
    t = np.linspace(0.0, 2.0 * math.pi, rim, endpoint=False)
    points = np.vstack((p, np.column_stack((np.cos(t), np.sin(t), np.zeros(rim)))))
    points *= [radius, radius, height]
    hull = ConvexHull(points)
    a, b, c = (points[hull.simplices[:, k]] for k in range(3))
    outward = np.einsum("ij,ij->i", np.cross(b - a, c - a), hull.equations[:, :3]) > 0
    faces = np.where(outward[:, None], hull.simplices, hull.simplices[:, ::-1]).tolist()
    spacing = 2.5 * radius
    blocks = [_box("ground", (-0.5 * spacing * count, -spacing / 2, -0.1),
                   (0.5 * spacing * count, spacing / 2, 0.0), density=density, support=True)]
    for k in range(count):
        scaled = points * (1 + 1e-3 * k)
        centre = scaled.mean(axis=0)
        blocks.append(make_block(f"dome{k}", scaled - centre, faces,
                                 centre + [spacing * (k - (count - 1) / 2), 0, 0],
                                 density=density))
    return make_scene(f"convex-domes({count}x{vertices})", blocks,
                      sequence=[b.id for b in blocks[1:]])


GENERATORS = {
    "two-blocks": two_blocks,
    "stack": stack,
    "harmonic-stack": harmonic_stack,
    "semicircular-arch": semicircular_arch,
    "buttressed-arch": buttressed_arch,
    "dome": dome,
    "running-bond-wall": running_bond_wall,
    "convex-domes": convex_domes,
}
