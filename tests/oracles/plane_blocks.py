"""Rigid-block equilibrium of plane assemblies (arches on buttresses), from their dimensions.

An independent reference for the steps, holds and plans of arch scenes (it shares no code
with rbe_ros, and builds the blocks and joints from the generators' documented dimensions,
not from their meshes or rbe_ros' contact detection). A scene whose blocks are prisms over
polygons in the xz-plane, loaded in that plane, stands if and only if its plane section
does (a 3D solution averaged with its mirror image is plane; a plane one is a 3D one).

Blocks are polygons (weight = area x depth x density x g, at the centroid); a joint is a
segment (p, q) between two blocks, with unit normal n pointing from block a into block b.
In the plane, the forces a segment joint can carry are those of two compressive forces at
its ends, N_p n and N_q n, and a shear V along it with |V| <= mu (N_p + N_q) (exact for
the per-point Coulomb cones: the shear acts along the joint's line, so it adds no moment
about any point of it). Feasibility of the equilibrium of every free block is one LP
(scipy linprog, HiGHS). Supports and held blocks are fixed.

A robot's hold (:func:`smallest_hold_force`) is a bounded external force instead: the held
block stays free with a force (F_x, F_z) at its centroid (and with ``torque`` a moment M
about it), and the LP minimises the largest |F| over the holds, with |F| bounded by a
polygon of HOLD_DIRECTIONS facets around the circle (a relaxation by at most
1 / cos(pi / HOLD_DIRECTIONS) - 1, 4e-5: the force found is a lower bound within that).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog

from .arch_limit import area_centroid_x

G = 9.81


@dataclass(frozen=True)
class Block:
    polygon: np.ndarray        # (k, 2) x, z
    weight: float              # N


@dataclass(frozen=True)
class Joint:
    a: str
    b: str
    p: np.ndarray
    q: np.ndarray


def stands(blocks: dict[str, Block], joints: list[Joint], present: set[str],
           fixed: set[str], mu: float = 0.6) -> bool:
    """Whether the blocks of ``present`` that are not ``fixed`` are in equilibrium under
    their weights on the joints among ``present`` blocks (fixed blocks: supports, held)."""
    free = sorted(present - fixed)
    if not free:
        return True
    a_eq, b_eq, a_ub, b_ub, bounds = _system(blocks, joints, present, free, mu)
    res = linprog(np.zeros(a_eq.shape[1]), A_ub=np.array(a_ub) if a_ub else None,
                  b_ub=np.array(b_ub) if b_ub else None, A_eq=a_eq, b_eq=b_eq,
                  bounds=bounds, method="highs")
    return res.status == 0


HOLD_DIRECTIONS = 360


def smallest_hold_force(blocks: dict[str, Block], joints: list[Joint], present: set[str],
                        fixed: set[str], held: set[str], mu: float = 0.6,
                        torque: bool = False) -> float:
    """The smallest largest |F| (N) over the robots holding the blocks of ``held`` (free,
    each with a force at its centroid and with ``torque`` a free moment) for which the
    blocks of ``present`` not ``fixed`` are in equilibrium; math.inf when none is."""
    free = sorted(present - fixed)
    a_eq, b_eq, a_ub, b_ub, bounds = _system(blocks, joints, present, free, mu)
    n = a_eq.shape[1]
    per = 3 if torque else 2
    extra = per * len(held) + 1                      # the holds' F_x, F_z (, M), and t
    a_eq = np.hstack([a_eq, np.zeros((a_eq.shape[0], extra))])
    a_ub = [np.concatenate([r, np.zeros(extra)]) for r in a_ub]
    angles = 2 * np.pi * np.arange(HOLD_DIRECTIONS) / HOLD_DIRECTIONS
    for h, bid in enumerate(sorted(held)):
        r, col = 3 * free.index(bid), n + per * h
        cx, cz = _centroid(blocks[bid].polygon)
        a_eq[r, col] = a_eq[r + 1, col + 1] = 1.0            # F at the centroid
        a_eq[r + 2, col], a_eq[r + 2, col + 1] = -cz, cx       # its moment about the origin
        if torque:
            a_eq[r + 2, col + 2] = 1.0
        for angle in angles:                                   # d . F <= t for every d
            row = np.zeros(n + extra)
            row[col], row[col + 1], row[-1] = math.cos(angle), math.sin(angle), -1.0
            a_ub.append(row)
    b_ub = list(b_ub) + [0.0] * (len(a_ub) - len(b_ub))
    cost = np.zeros(n + extra)
    cost[-1] = 1.0
    res = linprog(cost, A_ub=np.array(a_ub), b_ub=np.array(b_ub), A_eq=a_eq, b_eq=b_eq,
                  bounds=bounds + [(None, None)] * (extra - 1) + [(0, None)], method="highs")
    return float(res.x[-1]) if res.status == 0 else math.inf


def _centroid(poly: np.ndarray) -> tuple[float, float]:
    """Centroid (x, z) of a polygon: the abscissa of it and of its mirror about x = z."""
    return area_centroid_x(poly)[1], area_centroid_x(poly[:, ::-1])[1]


def _system(blocks, joints, present, free, mu):
    """A_eq x = b_eq (equilibrium of the blocks of ``free``), A_ub x <= b_ub (friction) and
    the bounds of the joint forces x (N_p, N_q, V per joint among ``present`` blocks)."""
    row = {b: 3 * k for k, b in enumerate(free)}
    active = [j for j in joints if j.a in present and j.b in present
              and (j.a in row or j.b in row)]
    a_eq = np.zeros((3 * len(free), 3 * len(active)))
    b_eq = np.zeros(3 * len(free))
    for b in free:
        weight, cx = blocks[b].weight, area_centroid_x(blocks[b].polygon)[1]
        # weight (0, -W) at the centroid: sum of forces + (0, -W) = 0, moments about the origin
        b_eq[row[b] + 1] = weight
        b_eq[row[b] + 2] = cx * weight
    a_ub, b_ub = [], []
    for k, j in enumerate(active):
        t = (j.q - j.p) / np.linalg.norm(j.q - j.p)
        n = np.array([-t[1], t[0]])
        for side, sign in ((j.b, 1.0), (j.a, -1.0)):       # a pushes b along n
            if side not in row:
                continue
            r = row[side]
            for col, point, direction in ((3 * k, j.p, n), (3 * k + 1, j.q, n),
                                          (3 * k + 2, j.p, t)):
                f = sign * direction
                a_eq[r:r + 2, col] += f
                a_eq[r + 2, col] += point[0] * f[1] - point[1] * f[0]
        if math.isfinite(mu):           # |V| <= mu (N_p + N_q)
            a_ub += [_row(len(active), k, (-mu, -mu, 1.0)),
                     _row(len(active), k, (-mu, -mu, -1.0))]
            b_ub += [0.0, 0.0]
    return a_eq, b_eq, a_ub, b_ub, [(0, None), (0, None), (None, None)] * len(active)


def _row(n: int, k: int, coefs) -> np.ndarray:
    r = np.zeros(3 * n)
    r[3 * k:3 * k + 3] = coefs
    return r


def smallest_holds(blocks, joints, present: set[str], supports: set[str], mu: float = 0.6,
                   largest: int = 2) -> list[set[str]]:
    """Every smallest set of at most ``largest`` free blocks whose holding makes ``present``
    stand (brute force over the subsets; [set()] when it stands as it is, [] when none)."""
    free = sorted(present - supports)
    for size in range(largest + 1):
        found = [set(c) for c in itertools.combinations(free, size)
                 if stands(blocks, joints, present, supports | set(c), mu)]
        if found:
            return found
    return []


def _voussoirs(n, centre, r_in, r_out, depth, density, blocks, joints, springing):
    """Voussoirs "v00" (angle 0, +x) ... of a semicircular arch about ``centre``: radial
    joints, planar intrados and extrados; the end joints on ``springing`` (right, left)."""
    c = np.asarray(centre, dtype=float)
    ids = [f"v{i:02d}" for i in range(n)]
    for i, bid in enumerate(ids):
        a0, a1 = math.pi * i / n, math.pi * (i + 1) / n
        d0, d1 = (np.array([math.cos(a), math.sin(a)]) for a in (a0, a1))
        poly = np.array([c + r_in * d0, c + r_out * d0, c + r_out * d1, c + r_in * d1])
        blocks[bid] = Block(poly, area_centroid_x(poly)[0] * depth * density * G)
        if i + 1 < n:
            joints.append(Joint(bid, ids[i + 1], c + r_in * d1, c + r_out * d1))
    right, left = springing
    joints.append(Joint(right, ids[0], c + np.array([r_in, 0.0]), c + np.array([r_out, 0.0])))
    joints.append(Joint(left, ids[-1], c + np.array([-r_out, 0.0]), c + np.array([-r_in, 0.0])))
    return ids


def semicircular_arch(n: int = 15, thickness_ratio: float = 0.15, radius: float = 1.0,
                      depth: float = 1.0, density: float = 2000.0):
    """generators.semicircular_arch as documented: the arch centre at (0, t), two supports
    t wide under the springings. Returns (blocks, joints, supports)."""
    t = thickness_ratio * radius
    r_in, r_out = radius - t / 2, radius + t / 2
    blocks = {"support_right": Block(np.array([[r_in, 0], [r_out, 0], [r_out, t], [r_in, t]]), 0),
              "support_left": Block(np.array([[-r_out, 0], [-r_in, 0], [-r_in, t],
                                              [-r_out, t]]), 0)}
    joints: list[Joint] = []
    _voussoirs(n, (0.0, t), r_in, r_out, depth, density, blocks, joints,
               ("support_right", "support_left"))
    return blocks, joints, {"support_right", "support_left"}


def buttressed_arch(voussoirs: int = 15, inner_radius: float = 1.0, thickness: float = 0.3,
                    depth: float = 0.5, buttress_height: float = 2.5,
                    buttress_width: float = 0.7, buttress_depth: float = 1.0,
                    courses: int = 6, density: float = 1800.0):
    """generators.buttressed_arch as documented (springing "centre"): buttresses of
    ``courses`` equal courses, the bottom ones supports, the springing joint in the middle
    of each buttress top. Returns (blocks, joints, supports)."""
    inner = inner_radius + (thickness - buttress_width) / 2
    h = buttress_height / courses
    blocks, joints, supports = {}, [], set()
    for side, sign in (("right", 1.0), ("left", -1.0)):
        x0, x1 = sorted((sign * inner, sign * (inner + buttress_width)))
        for c in range(courses):
            bid = f"buttress_{side}_{c}"
            poly = np.array([[x0, c * h], [x1, c * h], [x1, (c + 1) * h], [x0, (c + 1) * h]])
            blocks[bid] = Block(poly, buttress_width * h * buttress_depth * density * G)
            if c:
                joints.append(Joint(f"buttress_{side}_{c - 1}", bid, poly[0], poly[1]))
            else:
                supports.add(bid)
    top = f"buttress_right_{courses - 1}", f"buttress_left_{courses - 1}"
    _voussoirs(voussoirs, (0.0, buttress_height), inner_radius, inner_radius + thickness,
               depth, density, blocks, joints, top)
    return blocks, joints, supports


def key_order(n: int) -> list[str]:
    """Voussoirs alternately from both springings to the key-stone."""
    ids = [f"v{i:02d}" for i in range(n)]
    return [ids[k // 2] if k % 2 == 0 else ids[n - 1 - k // 2] for k in range(n)]
