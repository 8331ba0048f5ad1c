"""Small scenes of the kinds issue 29 names, with the closed forms of their verdicts (rigid
blocks set one at a time from rest, Coulomb friction mu): prisms 1 m deep (y) over polygons
in the xz plane, density 2000 kg/m^3, gravity -z."""
from __future__ import annotations

import math

import numpy as np

from rbe_ros.generators import _box, _prism, two_blocks
from rbe_ros.scene import make_scene

DENSITY = 2000.0


def quad(block_id, corners_xz, support=False, depth=1.0):
    """A prism ``depth`` deep (y) over a polygon in the xz plane."""
    return _prism(block_id, [(x, y, z) for y in (-depth / 2, depth / 2) for x, z in corners_xz],
                  density=DENSITY, support=support)


def bar_between_posts(base: bool = False):
    """A bar touching two support posts only on their vertical faces (on a base: resting on
    it). Falls for any mu without the base (no load presses its faces), stands on it."""
    blocks = [quad("left", [(-0.7, 0), (-0.5, 0), (-0.5, 1), (-0.7, 1)], True),
              quad("right", [(0.5, 0), (0.7, 0), (0.7, 1), (0.5, 1)], True),
              quad("bar", [(-0.5, 0.4), (0.5, 0.4), (0.5, 0.6), (-0.5, 0.6)])]
    if base:
        blocks.append(quad("base", [(-0.5, 0.0), (0.5, 0.0), (0.5, 0.4), (-0.5, 0.4)], True))
    return make_scene("bar between posts", blocks)


def bar_between_free_pillars():
    """A bar held only by friction between two free pillars on the ground: falls for any mu
    (nothing presses the pillars onto it)."""
    blocks = [_box("ground", (-1.5, -0.5, -0.2), (1.5, 0.5, 0.0), density=DENSITY, support=True),
              quad("left", [(-0.8, 0), (-0.5, 0), (-0.5, 1.2), (-0.8, 1.2)]),
              quad("right", [(0.5, 0), (0.8, 0), (0.8, 1.2), (0.5, 1.2)]),
              quad("bar", [(-0.5, 0.9), (0.5, 0.9), (0.5, 1.1), (-0.5, 1.1)])]
    return make_scene("bar between free pillars", blocks, sequence=["left", "right", "bar"])


def bar_between_leaning_posts(lean_deg: float = 20.0):
    """Two support posts leaning the same way (faces at ``lean_deg`` from the vertical) and
    a parallelogram bar between them: it rests on the lower post's face, which is an
    incline of 90 - lean deg, pressed by nothing (the upper post's face is parallel):
    stands iff mu >= tan(90 - lean)."""
    t = math.tan(math.radians(lean_deg))
    z0, z1 = 0.4, 0.6

    def x(x0, z):
        return x0 + t * z
    blocks = [quad("left", [(x(-0.7, 0), 0), (x(-0.5, 0), 0), (x(-0.5, 1), 1), (x(-0.7, 1), 1)],
                   True),
              quad("right", [(x(0.5, 0), 0), (x(0.7, 0), 0), (x(0.7, 1), 1), (x(0.5, 1), 1)],
                   True),
              quad("bar", [(x(-0.5, z0), z0), (x(0.5, z0), z0), (x(0.5, z1), z1),
                           (x(-0.5, z1), z1)])]
    return make_scene("bar between leaning posts", blocks)


def flat_arch(gap: float = 0.0):
    """A flat arch of three blocks with vertical joints between two support abutments:
    every joint vertical, so the three fall together for any mu (no load closes a joint)."""
    blocks = [quad("left", [(-1.0, 0), (-0.6, 0), (-0.6, 1), (-1.0, 1)], True),
              quad("right", [(0.6, 0), (1.0, 0), (1.0, 1), (0.6, 1)], True),
              quad("a", [(-0.6, 0.6), (-0.2, 0.6), (-0.2, 1.0), (-0.6, 1.0)]),
              quad("b", [(-0.2, 0.6), (0.2, 0.6), (0.2, 1.0), (-0.2, 1.0)]),
              quad("c", [(0.2, 0.6), (0.6, 0.6), (0.6, 1.0), (0.2, 1.0)])]
    return make_scene("flat arch", blocks, sequence=["a", "c", "b"])


def wedged_flat_arch(angle_deg: float = 15.0):
    """A flat arch of three blocks whose joints fan out from a point below (a jack arch):
    the key narrows downward and wedges; stands for mu above a small limit."""
    t = math.tan(math.radians(angle_deg))
    h0, h1 = 0.6, 1.0

    def joint(x0):           # a joint through (x0, h0) leaning out by angle * x0 / 0.6
        s = t * x0 / 0.6
        return (x0, h0), (x0 + s * (h1 - h0), h1)
    j = [joint(x0) for x0 in (-0.6, -0.2, 0.2, 0.6)]
    blocks = [quad("left", [(-1.2, 0), j[0][0], j[0][1], (-1.2, h1)], True),
              quad("right", [j[3][0], (1.2, 0), (1.2, h1), j[3][1]], True),
              quad("a", [j[0][0], j[1][0], j[1][1], j[0][1]]),
              quad("b", [j[1][0], j[2][0], j[2][1], j[1][1]]),
              quad("c", [j[2][0], j[3][0], j[3][1], j[2][1]])]
    return make_scene("wedged flat arch", blocks, sequence=["a", "c", "b"])


def incline_with_bar(incline_deg: float, parallel: bool = False):
    """two_blocks' block on an incline and a support bar touching its top: horizontal (the
    block's top) or, ``parallel``, a block with a top parallel to the incline and a bar
    along it. Stands iff mu >= tan(incline) (the bar presses nothing)."""
    if not parallel:
        blocks = list(two_blocks(incline_deg=incline_deg).blocks)
        blocks.append(_box("bar", (-0.8, -0.5, 1.0), (0.8, 0.5, 1.2), density=DENSITY,
                           support=True))
        return make_scene("incline with bar", blocks)
    t = math.tan(math.radians(incline_deg))
    c, s = math.cos(math.radians(incline_deg)), math.sin(math.radians(incline_deg))

    def on(u, w):           # u along the slope, w across it, from the origin
        return (u * c - w * s, u * s + w * c)
    blocks = [quad("incline", [(-1.0, -1.0 * t - 0.3), (1.0, 1.0 * t - 0.3), on(1.0 / c, 0),
                               on(-1.0 / c, 0)], True),
              quad("block", [on(-0.3, 0), on(0.3, 0), on(0.3, 0.3), on(-0.3, 0.3)]),
              quad("bar", [on(-0.8, 0.3), on(0.8, 0.3), on(0.8, 0.5), on(-0.8, 0.5)], True)]
    return make_scene("incline pressed by a parallel bar", blocks)


def leaning_block(wall_mu_case: bool = True):
    """A slab leaning on a support wall, its foot on the ground: its foot slides on the
    ground at small mu."""
    blocks = [_box("ground", (-1.0, -0.5, -0.2), (1.5, 0.5, 0.0), density=DENSITY, support=True),
              _box("wall", (1.0, -0.5, 0.0), (1.5, 0.5, 2.0), density=DENSITY, support=True),
              quad("leaner", [(0.2, 0.0), (0.4, 0.0), (1.0, 1.5), (1.0, 1.7)])]
    return make_scene("leaner", blocks)


def rotated(scene, axis, degrees: float):
    """``scene`` turned about ``axis`` through the origin (as compas_cra's example scripts
    turn a sample before solving it)."""
    from dataclasses import replace
    from scipy.spatial.transform import Rotation
    turn = Rotation.from_rotvec(np.radians(degrees) * np.asarray(axis, dtype=float)
                                / np.linalg.norm(axis))
    return replace(scene, blocks=tuple(
        replace(b, position=turn.apply(b.position),
                orientation=(turn * Rotation.from_quat(b.orientation)).as_quat())
        for b in scene.blocks))


def lmgc90_cases():
    """(name, scene, mu) of the cases benchmarks/placement_lmgc90.py runs through LMGC90:
    the issue's kinds on both sides of their limits."""
    from rbe_ros.io.compas import compas_samples_dir, load_compas_assembly
    for mu in (0.6, 0.84):
        yield "bar between free pillars", bar_between_free_pillars(), mu
    for mu in (0.84, 1.2):
        yield "flat arch", flat_arch(), mu
    yield "wedged flat arch", wedged_flat_arch(), 0.84
    for mu in (0.2, 0.5, 0.7):
        yield "incline 30 pressed by a parallel bar", incline_with_bar(30.0, True), mu
    for mu in (0.6, 3.0):
        yield "bar between leaning posts", bar_between_leaning_posts(20.0), mu
    for mu in (0.1, 0.6):
        yield "leaner", leaning_block(), mu
    samples = compas_samples_dir()
    if samples is not None:
        type_b = load_compas_assembly(samples / "type-b.json", supports=["0", "1"])
        for mu in (0.6, 0.84):
            yield "type-b rotated 90 about y", rotated(type_b, (0, 1, 0), 90.0), mu
