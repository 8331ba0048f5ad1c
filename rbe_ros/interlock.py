"""Interlocking assemblies of non-convex parts: the scenes of tests/data/interlock.

Each part is a polycube (:func:`rbe_ros.generators.polycube`: a union of grid cubes, its
boundary their exposed faces, merged into one face per plane by the shape analysis) or an
extruded polygon (a voussoir with a shear key); every part is non-convex, so that a convex
hull would cover a neighbour's notch. Conventions as in :mod:`rbe_ros.generators`: SI
units, gravity along -z, supports named, a block's frame at its centre, a deterministic
output, and ``sequence`` a build order (bottom up) that the planner may replace. The
friction coefficient of the suite is 0.55 (``SUITE_MU``).

- :func:`polyomino_wall`: a planar wall of tetrominoes (L, J, T, S, Z) one cell thick; in the
  wall's plane the pieces interlock, so a piece locked by its neighbours comes in along the
  wall's normal (built bottom up, each comes down through the notches of the others).
- :func:`log_cabin`: a 3D interlock: logs with notched ends, crossing at the corners.
- :func:`cradle`: a non-convex support base with slots; T-pieces set into them and pairs of
  L-pieces on top.
- :func:`keyed_vault`: an arch of voussoirs with shear keys (a tongue on one joint, a groove
  on the other), the key stone grooved on both sides.
- :func:`greedy_trap`: a cup with two pieces in it: the lower one, which a greedy planner
  places first, hooks over the other's foot and leaves no second step; the other order works.
- :func:`sealed_pocket`: a part that can leave its pocket only through a wall of the support:
  no plan exists.
"""
from __future__ import annotations

import math

import numpy as np
import shapely

from .generators import polycube
from .geometry.block import signed_volume
from .scene import Block, Scene, box_block, make_block, make_scene

#: The friction coefficient the interlocking suite is planned with.
SUITE_MU = 0.55


def extruded_block(block_id: str, profile, y0: float, y1: float, *, density: float = 2000.0,
                   support: bool = False) -> Block:
    """A prism of the simple polygon ``profile`` ((x, z) points, either orientation) in the
    xz-plane, between y = y0 and y = y1; its frame at the mean of its vertices. The caps
    are given as triangles (a constrained Delaunay triangulation of the profile), so that a
    non-convex profile is no face any fan would fold over; the shape analysis merges them."""
    p = np.asarray(profile, dtype=float)
    n = len(p)
    vertices = np.vstack((np.column_stack((p[:, 0], np.full(n, y0), p[:, 1])),
                          np.column_stack((p[:, 0], np.full(n, y1), p[:, 1]))))
    index = {tuple(np.round(q, 12)): k for k, q in enumerate(p)}
    # the front cap's triangles turn as the profile does (the sides hold its edges reversed)
    turn = float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]))
    cap = []
    for triangle in shapely.constrained_delaunay_triangles(shapely.Polygon(p)).geoms:
        a, b, c = (index[tuple(np.round(q, 12))] for q in triangle.exterior.coords[:3])
        (ux, uz), (vx, vz) = p[b] - p[a], p[c] - p[a]
        area2 = float(ux * vz - uz * vx)
        cap.append((a, b, c) if (area2 > 0) == (turn > 0) else (a, c, b))
    faces = cap + [(n + a, n + c, n + b) for a, b, c in cap]
    faces += [(i, n + i, n + (i + 1) % n, (i + 1) % n) for i in range(n)]
    if signed_volume(vertices, faces) < 0:      # the profile ran the other way: turn out
        faces = [f[::-1] for f in faces]
    centre = vertices.mean(axis=0)
    return make_block(block_id, vertices - centre, faces, centre, density=density,
                      support=support)


# ----------------------------------------------------------------------------- tetrominoes

#: The non-convex tetrominoes in the (x, z) grid, one orientation each.
_TETROMINOES = {"L": ((0, 0), (0, 1), (0, 2), (1, 0)), "J": ((0, 0), (1, 0), (1, 1), (1, 2)),
                "T": ((0, 0), (1, 0), (2, 0), (1, 1)), "S": ((0, 0), (1, 0), (1, 1), (2, 1)),
                "Z": ((1, 0), (2, 0), (0, 1), (1, 1))}


def _orientations(cells) -> list[tuple[tuple[int, int], ...]]:
    """The distinct rotations of a 2D piece (no mirror images: L and J are listed apart),
    each shifted to its lowest row, then leftmost cell, at the origin."""
    out = []
    pts = np.array(cells)
    for _ in range(4):
        pts = np.column_stack((-pts[:, 1], pts[:, 0]))
        shape = sorted(map(tuple, (pts - pts.min(axis=0)).tolist()))
        if shape not in out:
            out.append(shape)
    return [tuple(tuple(int(v) for v in c) for c in s) for s in out]


def tetromino_tiling(width: int, height: int, seed: int = 0) -> list[tuple[str, tuple]]:
    """A tiling of the width x height grid (x, z) by non-convex tetrominoes, found by
    backtracking from the lowest, leftmost empty cell, the pieces tried in an order drawn
    from ``seed``: [(kind, cells)]; ValueError when there is none."""
    if width * height % 4:
        raise ValueError(f"a {width} x {height} wall has {width * height} cells, not a "
                         "multiple of 4")
    rng = np.random.default_rng(seed)
    shapes = [(k, o) for k, cells in _TETROMINOES.items() for o in _orientations(cells)]
    grid = np.zeros((width, height), dtype=bool)
    placed: list[tuple[str, tuple]] = []
    budget = [200_000]

    def fill() -> bool:
        empty = np.argwhere(~grid.T)        # (z, x), row by row
        if not len(empty):
            return True
        z, x = (int(v) for v in empty[0])
        budget[0] -= 1
        if budget[0] < 0:
            return False
        for i in rng.permutation(len(shapes)):
            kind, shape = shapes[i]
            # the shape's first cell in row order goes on (x, z)
            first = min(shape, key=lambda c: (c[1], c[0]))
            cells = [(x + cx - first[0], z + cz - first[1]) for cx, cz in shape]
            if all(0 <= cx < width and 0 <= cz < height and not grid[cx, cz]
                   for cx, cz in cells):
                for c in cells:
                    grid[c] = True
                placed.append((kind, tuple(cells)))
                if fill():
                    return True
                placed.pop()
                for c in cells:
                    grid[c] = False
        return False

    if not fill():
        raise ValueError(f"no tiling of a {width} x {height} wall by L, J, T, S, Z found "
                         f"(seed {seed})")
    return placed


def _ground(lo, hi, *, density: float) -> Block:
    """The support slab "ground" between the corners ``lo`` and ``hi``."""
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    return box_block("ground", hi - lo, (lo + hi) / 2, density=density, support=True)


def _tetrominoes(width: int, height: int, seed: int, cell: float,
                 density: float) -> list[Block]:
    """The pieces "p00", ... of :func:`tetromino_tiling` in the xz-plane, one cell thick."""
    return [polycube(f"p{k:02d}", [(x, 0, z) for x, z in cells], cell, density=density)
            for k, (_, cells) in enumerate(tetromino_tiling(width, height, seed))]


def _bottom_up(blocks: list[Block]) -> list[str]:
    """Free block ids, lowest centroid first (then by id): a build order."""
    free = [b for b in blocks if not b.support]
    return [b.id for b in sorted(free, key=lambda b: (round(float(b.position[2]), 9), b.id))]


def polyomino_wall(width: int = 8, height: int = 6, cell: float = 0.1, seed: int = 0,
                   framed: bool = False, density: float = 2000.0) -> Scene:
    """A wall in the xz-plane, ``width`` x ``height`` cells of ``cell`` m, one cell thick
    (y), tiled by non-convex tetrominoes (:func:`tetromino_tiling`), on a support slab
    "ground" (top at z = 0). Pieces "p00", ... in tiling order; in the wall's plane a piece
    is locked by its neighbours, so one whose neighbours above are present can only come in
    along the wall's normal (+-y). ``framed``: an infill panel, the wall in a support frame
    present from the start (posts "post_left" and "post_right", a beam "beam" on them
    touching the top course), so that every piece comes in along the wall's normal."""
    blocks = [_ground((-2 * cell, -cell, -cell), ((width + 2) * cell, 2 * cell, 0.0),
                      density=density)] + _tetrominoes(width, height, seed, cell, density)
    if framed:
        posts = [("post_left", -1), ("post_right", width)]
        blocks += [polycube(bid, [(x, 0, z) for z in range(height)], cell, density=density,
                            support=True) for bid, x in posts]
        blocks.append(polycube("beam", [(x, 0, height) for x in range(-1, width + 1)], cell,
                               density=density, support=True))
    name = f"polyomino-wall({width}x{height}, seed {seed}{', framed' if framed else ''})"
    return make_scene(name, blocks, sequence=_bottom_up(blocks))


def log_cabin(levels: int = 6, length: int = 5, width: int = 5, cell: float = 0.1,
              density: float = 600.0) -> Scene:
    """A log cabin of ``levels`` courses, each of two logs along x ("x{level}_{0|1}") and,
    half a course higher, two along y ("y{level}_{0|1}"), crossing at the four corners with
    half-lap notches: at a corner column the courses alternate cell by cell, so every log
    is two cells high along its length and one at its ends (notched on top), and hooks over
    the crossing log below. ``length`` x ``width`` cells in plan; on a support "ground"."""
    if levels < 1 or min(length, width) < 3:
        raise ValueError(f"log-cabin needs levels >= 1 and length, width >= 3 cells, got "
                         f"{levels}, {length}, {width}")
    blocks = [_ground((-cell, -cell, -cell), ((length + 1) * cell, (width + 1) * cell, 0.0),
                      density=2000.0)]
    for level in range(levels):
        z = 2 * level
        for side, y in enumerate((0, width - 1)):
            cells = [(0, y, z), (length - 1, y, z)]
            cells += [(x, y, zz) for x in range(1, length - 1) for zz in (z, z + 1)]
            blocks.append(polycube(f"x{level}_{side}", cells, cell, density=density))
        for side, x in enumerate((0, length - 1)):
            cells = [(x, 0, z + 1), (x, width - 1, z + 1)]
            cells += [(x, y, zz) for y in range(1, width - 1) for zz in (z + 1, z + 2)]
            blocks.append(polycube(f"y{level}_{side}", cells, cell, density=density))
    return make_scene(f"log-cabin({levels} levels)", blocks, sequence=_bottom_up(blocks))


def cradle(slots: int = 8, depth: int = 2, cell: float = 0.1, density: float = 2000.0) -> Scene:
    """Blocks set into a non-convex support "base": a slab with ``slots`` slots one cell
    wide and deep, three cells apart (x), ``depth`` cells long (y) and open at both ends.
    Into each slot a T-piece "t{i}" (stem in the slot, its flange on the ribs either side:
    it comes in from above or along the slot, +-y); on each T a pair of L-pieces "l{i}a"
    (lower, its upturn at +x) and "l{i}b" (upper, hooked into the lower one's notch)
    filling three cells by two."""
    if slots < 1 or depth < 1:
        raise ValueError(f"cradle needs slots >= 1 and depth >= 1, got {slots}, {depth}")
    n = 3 * slots
    base = [(x, y, 0) for x in range(n) for y in range(depth)]
    base += [(x, y, 1) for x in range(n) for y in range(depth) if x % 3 != 1]
    blocks = [polycube("base", base, cell, density=density, support=True)]
    for i in range(slots):
        x = 3 * i
        ys = range(depth)
        t = [(x + 1, y, 1) for y in ys] + [(x + dx, y, 2) for dx in range(3) for y in ys]
        la = [(x + dx, y, 3) for dx in range(3) for y in ys] + [(x + 2, y, 4) for y in ys]
        lb = [(x + dx, y, 4) for dx in range(2) for y in ys]
        lb += [(x + dx, y, 5) for dx in range(3) for y in ys]
        for bid, cells in ((f"t{i}", t), (f"l{i}a", la), (f"l{i}b", lb)):
            blocks.append(polycube(bid, cells, cell, density=density))
    return make_scene(f"cradle({slots} slots)", blocks, sequence=_bottom_up(blocks))


def keyed_vault(voussoirs: int = 15, radius: float = 1.0, thickness: float = 0.25,
                depth: float = 0.4, span_deg: float = 120.0, key_ratio: float = 0.25,
                rings: int = 1, density: float = 2000.0) -> Scene:
    """A segmental arch ("vault", extruded along y) of ``voussoirs`` "v00" (at +x) ...
    over ``span_deg`` degrees of a circle of centre-line ``radius``, with shear keys: every
    joint carries a tongue (``key_ratio`` of the thickness wide, half that deep, mid thickness)
    of the voussoir nearer its springing in a groove of the one nearer the key, so the key
    stone is grooved on both sides and can only come in along y. On supports
    "springing_right" and "springing_left", whose tops are the springing joints.
    ``rings`` > 1: a barrel vault of that many rings along +y, ``depth`` each, in bond (ring
    r's voussoirs "r{r}_v00", ...; every other ring's joints halfway between the first
    ring's, a half voussoir at each springing)."""
    half = math.radians(span_deg) / 2
    angles = np.linspace(math.pi / 2 - half, math.pi / 2 + half, voussoirs + 1)
    r_in, r_out = radius - thickness / 2, radius + thickness / 2
    w = h = key_ratio * thickness / 2        # half its width, its depth
    # the key stone's two grooves must leave it material between them, a half voussoir's
    # one groove too
    step = angles[1] - angles[0]
    if not (voussoirs >= 3 and rings >= 1 and 0 < span_deg < 180 and 0 < thickness < radius
            and 0 < key_ratio < 1 and 2 * h < (radius - w) * step):
        raise ValueError("keyed-vault needs voussoirs >= 3, rings >= 1, span in (0, 180) deg,"
                         " thickness in (0, radius) and keys (key_ratio in (0, 1)) shallower "
                         "than half a voussoir")

    def joint(a: float, sign: int):
        """Points across the joint at angle a from intrados to extrados, the key bulging by
        sign * h towards growing angle (tongue +1, groove -1, flat 0)."""
        d = np.array([math.cos(a), math.sin(a)])
        t = np.array([-math.sin(a), math.cos(a)])
        pts = [r_in * d, (radius - w) * d, (radius - w) * d + sign * h * t,
               (radius + w) * d + sign * h * t, (radius + w) * d, r_out * d]
        return pts if sign else [pts[0], pts[-1]]

    y0, y1 = -depth / 2, depth / 2 + (rings - 1) * depth
    blocks = []
    for side, a in (("right", angles[0]), ("left", angles[-1])):
        # below the springing joint, down to 0.3 m under its lower end, vertical sides
        d = np.array([math.cos(a), math.sin(a)])
        low = min(r_in * d[1], r_out * d[1]) - 0.3
        profile = [r_in * d, r_out * d, (r_out * d[0], low), (r_in * d[0], low)]
        blocks.append(extruded_block(f"springing_{side}", profile, y0, y1, density=density,
                                     support=True))
    order = []
    for ring in range(rings):
        joints = angles if ring % 2 == 0 else \
            np.concatenate(([angles[0]], angles[:-1] + step / 2, [angles[-1]]))
        count = len(joints) - 1
        # a joint's key bulges towards growing angle (+1) when the voussoir at the smaller
        # angle is the nearer its springing (right half), else back (-1); none at springings
        signs = [0] + [1 if k <= count / 2 else -1 for k in range(1, count)] + [0]
        ids = [f"v{i:02d}" if ring == 0 else f"r{ring}_v{i:02d}" for i in range(count)]
        for i, bid in enumerate(ids):
            profile = joint(joints[i], signs[i]) + joint(joints[i + 1], signs[i + 1])[::-1]
            blocks.append(extruded_block(bid, profile, y0 + ring * depth,
                                         y0 + (ring + 1) * depth, density=density))
        left, right = 0, count - 1
        while left <= right:            # from both springings to the key
            order.append(ids[left])
            if left != right:
                order.append(ids[right])
            left, right = left + 1, right - 1
    name = f"keyed-vault({voussoirs}{f' x {rings} rings' if rings > 1 else ''})"
    return make_scene(name, blocks, sequence=order)


def greedy_trap(levels: int = 5, cell: float = 0.1, density: float = 2000.0) -> Scene:
    """A support "cup" with a closed pocket 3 x 2 x 2 cells (x, y, z), open only upward, and
    in it two pieces: "hook" (y = 0: a bar on the floor rising to a lip that hangs over
    (0, 0, 0)) and "keel" (its foot at (0, 0, 0), the rest of the pocket at y = 1, a
    platform on the cup's rim carrying a stack of ``levels`` courses of two L-trominoes,
    "c{level}a"/"c{level}b"). The hook's centroid is lower, so a greedy planner places it
    first; then the keel's foot cannot pass its lip, nothing else touches a present block,
    and the plan dead-ends at step 1. Keel first, then hook, then the stack, works."""
    cup = [(x, y, z) for x in range(-1, 4) for y in range(-1, 3) for z in range(-1, 2)
           if not (0 <= x < 3 and 0 <= y < 2 and z >= 0)]
    blocks = [polycube("cup", cup, cell, density=density, support=True)]
    hook = [(1, 0, 0), (2, 0, 0), (0, 0, 1), (1, 0, 1), (2, 0, 1)]
    keel = [(0, 0, 0), (0, 1, 0), (1, 1, 0), (2, 1, 0), (0, 1, 1), (1, 1, 1), (2, 1, 1)]
    keel += [(x, y, 2) for x in range(3) for y in (1, 2)]
    blocks += [polycube("hook", hook, cell, density=density),
               polycube("keel", keel, cell, density=density)]
    for level in range(levels):
        z = 3 + level
        a = [(0, 1, z), (1, 1, z), (0, 2, z)]
        b = [(2, 1, z), (2, 2, z), (1, 2, z)]
        if level % 2:                   # mirrored in x: the courses' seams cross
            a, b = ([(2 - x, y, zz) for x, y, zz in a], [(2 - x, y, zz) for x, y, zz in b])
        blocks += [polycube(f"c{level}a", a, cell, density=density),
                   polycube(f"c{level}b", b, cell, density=density)]
    order = ["keel", "hook"] + [f"c{level}{s}" for level in range(levels) for s in "ab"]
    return make_scene(f"greedy-trap({levels} levels)", blocks, sequence=order)


def sealed_pocket(width: int = 10, height: int = 4, cell: float = 0.1,
                  density: float = 2000.0) -> Scene:
    """No plan exists: a support "housing" with a pocket open only at +x, closed there by
    the support "wall", holds the piece "trapped" (an L in the pocket: the only way out is
    through the wall; up, its bar meets the housing's roof); beside it a tetromino wall
    ``width`` x ``height`` cells (:func:`polyomino_wall`'s pieces, "p00", ...)."""
    blocks = [_ground((-cell, -cell, -cell), ((width + 6) * cell, 2 * cell, 0.0),
                      density=density)]
    x0 = width + 1
    pocket = [(x0 + 1, 0, 1), (x0 + 2, 0, 1), (x0 + 3, 0, 1), (x0 + 3, 0, 2)]
    housing = [(x, y, z) for x in range(x0, x0 + 4) for y in range(-1, 2) for z in range(3)
               if (x, y, z) not in pocket]
    blocks.append(polycube("housing", housing, cell, density=density, support=True))
    wall = [(x0 + 4, y, z) for y in range(-1, 2) for z in range(3)]
    blocks.append(polycube("wall", wall, cell, density=density, support=True))
    blocks.append(polycube("trapped", pocket, cell, density=density))
    blocks += _tetrominoes(width, height, 0, cell, density)
    return make_scene(f"sealed-pocket({width}x{height})", blocks, sequence=_bottom_up(blocks))


INTERLOCK_GENERATORS = {
    "polyomino-wall": polyomino_wall,
    "log-cabin": log_cabin,
    "cradle": cradle,
    "keyed-vault": keyed_vault,
    "greedy-trap": greedy_trap,
    "sealed-pocket": sealed_pocket,
}
