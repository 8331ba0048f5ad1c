"""Exact limits of the semicircular arch of ``generators.semicircular_arch``, by a thrust line.

An independent reference for the benchmark (it shares no code with rbe_ros): the plane
arch of n voussoirs (radial joints at phi_j = pi j / n, intrados and extrados planar chords
between radii R - t/2 and R + t/2, self-weight) stands on rigid springings if and only if a
line of thrust exists that passes through every joint between its intrados and extrados
ends, with |shear| <= mu x normal force at every joint (the rigid-block equilibrium of the
plane arch; forces spread over a joint's vertices as the resultant needs, so the per-vertex
exact cones and the joint's resultant give the same condition). The feasible set is convex
and the arch symmetric, so if any solution exists a symmetric one does: a horizontal thrust
H at the crown section, at height z0. With an even n the crown section is a joint and z0
must lie within it; with an odd n it cuts the rigid crown voussoir, which carries the
thrust at any height (z0 is free). With m = z0 H the conditions at each joint of the right
half are linear in (H, m):

    part between the crown section and joint j: weight W (area), centroid abscissa xg;
    resultant through the joint R = (-H, W) at distance s from the centre along d_j,
    s (W cos phi + H sin phi) = m + W xg,   R_in <= s <= R_out;
    |W sin phi - H cos phi| <= mu (W cos phi + H sin phi).

Feasibility is one small LP (scipy ``linprog``, HiGHS); the minimum thickness is a bisection
on t/R (monotone: a thicker arch holds every thrust line of a thinner one) and the minimum
friction a bisection on mu. As n grows the minimum thickness tends to the continuous
t/R = 0.107426 (Cocchetti & Rizzi 2020).
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from scipy.optimize import linprog


def area_centroid_x(poly: np.ndarray) -> tuple[float, float]:
    """Area and centroid abscissa of a simple polygon (counter-clockwise or not)."""
    x, z = poly[:, 0], poly[:, 1]
    x1, z1 = np.roll(x, -1), np.roll(z, -1)
    cross = x * z1 - x1 * z
    a = 0.5 * cross.sum()
    cx = ((x + x1) * cross).sum() / (6.0 * a)
    return abs(a), float(cx)


def _clip_right(poly: np.ndarray) -> np.ndarray:
    """The part of a convex polygon with x >= 0 (Sutherland-Hodgman against one line)."""
    out = []
    n = len(poly)
    for i in range(n):
        p, q = poly[i], poly[(i + 1) % n]
        pin, qin = p[0] >= 0, q[0] >= 0
        if pin:
            out.append(p)
        if pin != qin:
            t = p[0] / (p[0] - q[0])
            out.append(p + t * (q - p))
    return np.array(out)


@lru_cache(maxsize=None)
def _joints(n: int, ratio: float):
    """Per joint of the right half, from the crown down to the springing: (phi, W, W xg);
    and the crown section's height range (relative to the arch centre)."""
    r_in, r_out = 1.0 - ratio / 2, 1.0 + ratio / 2

    def quad(i):
        a0, a1 = math.pi * i / n, math.pi * (i + 1) / n
        d0, d1 = np.array([math.cos(a0), math.sin(a0)]), np.array([math.cos(a1), math.sin(a1)])
        return np.array([r_in * d0, r_out * d0, r_out * d1, r_in * d1])

    if n % 2:                      # the crown voussoir is cut at x = 0
        k = (n - 1) // 2
        half = _clip_right(quad(k))
        crown = None               # a section through a rigid block: any height (see below)
        a, cx = area_centroid_x(half)
        w, wx = a, a * cx
        below = range(k - 1, -1, -1)   # voussoirs under the crown one, down to v0
        first_joint = k                # joint at phi = pi k / n bounds the crown voussoir
    else:
        k = n // 2
        crown = (r_in, r_out)
        w = wx = 0.0
        below = range(k - 1, -1, -1)
        first_joint = k
    out = []
    j = first_joint
    if n % 2:
        out.append((math.pi * j / n, w, wx))
    for i in below:
        a, cx = area_centroid_x(quad(i))
        w, wx = w + a, wx + a * cx
        j = i
        out.append((math.pi * j / n, w, wx))
    return tuple(out), crown, (r_in, r_out)


def feasible(n: int, ratio: float, mu: float = math.inf, band: float = 1.0) -> bool:
    """Whether the arch of n voussoirs with t/R = ``ratio`` stands with friction ``mu``, the
    thrust line confined to the middle ``band`` of every joint (1: the whole joint; 1/3: its
    middle third, the kern of a rectangular joint, as kern-fitting asks)."""
    joints, crown, _ = _joints(n, float(ratio))
    r_in, r_out = 1.0 - band * ratio / 2, 1.0 + band * ratio / 2
    if crown is not None:
        crown = (r_in, r_out)
    rows, rhs = [], []
    if crown is not None:          # crown joint (n even): z_lo H <= m <= z_hi H
        rows += [[crown[0], -1.0], [-crown[1], 1.0]]
        rhs += [0.0, 0.0]
    for phi, w, wx in joints:
        c, s = math.cos(phi), math.sin(phi)
        # r_in (W c + H s) <= m + wx <= r_out (W c + H s)
        rows.append([r_in * s, -1.0])
        rhs.append(wx - r_in * w * c)
        rows.append([-r_out * s, 1.0])
        rhs.append(r_out * w * c - wx)
        if math.isfinite(mu):
            # |W s - H c| <= mu (W c + H s)
            rows.append([-c - mu * s, 0.0])
            rhs.append(mu * w * c - w * s)
            rows.append([c - mu * s, 0.0])
            rhs.append(mu * w * c + w * s)
    res = linprog(np.zeros(2), A_ub=np.array(rows), b_ub=np.array(rhs),
                  bounds=[(0, None), (None, None)], method="highs")
    return res.status == 0


def minimum_thickness(n: int, mu: float = math.inf, tol: float = 1e-9, band: float = 1.0) -> float:
    """Smallest t/R (to ``tol``) at which the arch of n voussoirs stands (nan if none < 1.9),
    the thrust line in the middle ``band`` of every joint (see :func:`feasible`)."""
    lo, hi = 1e-6, 1.9
    if not feasible(n, hi, mu, band):
        return math.nan
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if feasible(n, mid, mu, band) else (mid, hi)
    return hi


def minimum_friction(n: int, ratio: float, tol: float = 1e-9) -> float:
    """Smallest mu (to ``tol``) at which the arch stands (inf if it needs tension)."""
    if not feasible(n, ratio):
        return math.inf
    lo, hi = 0.0, 4.0
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if feasible(n, ratio, mid) else (mid, hi)
    return hi


if __name__ == "__main__":
    for n in (5, 8, 10, 12, 15, 20, 40, 100, 1000):
        print(n, round(minimum_thickness(n), 7), round(minimum_friction(n, 0.15), 5))
