"""Virtual (reduced) interfaces (paper Sec. 3.2.2, 3.3.2).

The contact vertices of chosen interfaces are moved onto a shrunk copy of the polygon, so
the equilibrium is written on the reduced interface. A thrust that cannot fit shows tension
in the explanation of the check (friction+), instead of merely failing.

Shrinking by a factor s in (0, 1] maps a vertex p to q + s (p - q), where q is p's projection
on an edge line (``edge``); ``kern`` replaces the polygon by its kern.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import replace

import numpy as np

from ..geometry.contacts import Interface
from ..geometry.polygon import area_moments
from .assembly import Assembly

ANALYSES = ("kern-fitting", "inner-base-fitting", "outer-base-fitting", "max-thrust")


def to_kern(it: Interface) -> Interface:
    """The interface reduced to its kern (resultants there cannot open the joint)."""
    return _with_points(it, it.kern)


def towards_edge(it: Interface, factor: float, edge: int) -> Interface:
    """Shrink towards the line through vertices ``edge`` and ``edge + 1``."""
    a, b = it.points[edge], it.points[(edge + 1) % len(it.points)]
    d = (b - a) / np.linalg.norm(b - a)
    q = a + np.outer((it.points - a) @ d, d)
    return _with_points(it, q + factor * (it.points - q))


def _with_points(it: Interface, points: np.ndarray) -> Interface:
    area, _, _ = area_moments(it.frame.to_2d(points))
    return replace(it, points=points, area=abs(area))


def shrink(assembly: Assembly, chosen: Iterable[int], how: Callable[[Interface], Interface]
           ) -> Assembly:
    """The assembly with interfaces ``chosen`` (indices) replaced by ``how(interface)``."""
    chosen = set(chosen)
    interfaces = tuple(how(it) if k in chosen else it for k, it in enumerate(assembly.interfaces))
    return replace(assembly, interfaces=interfaces)


def _edge_midpoints(it: Interface) -> np.ndarray:
    return 0.5 * (it.points + np.roll(it.points, -1, axis=0))


def _vertical_axis(assembly: Assembly) -> tuple[np.ndarray, np.ndarray]:
    """Centre of mass of the free blocks and the unit 'up' direction (against gravity)."""
    free = [b for b in assembly.blocks if not b.support]
    masses = np.array([b.mass for b in free])
    centre = (masses[:, None] * np.array([b.centroid for b in free])).sum(axis=0) / masses.sum()
    return centre, -assembly.gravity / np.linalg.norm(assembly.gravity)


def support_interfaces(assembly: Assembly) -> list[int]:
    """Indices of the interfaces on a support."""
    return [k for k, it in enumerate(assembly.interfaces)
            if assembly.blocks[it.a].support or assembly.blocks[it.b].support]


def base_fitting(assembly: Assembly, side: str, factor: float = 0.1) -> Assembly:
    """Support interfaces shrunk towards their edge nearest to (inner) or farthest from
    (outer) the vertical axis through the centre of mass of the free blocks."""
    centre, up = _vertical_axis(assembly)

    def radial(p):
        d = p - centre
        return np.linalg.norm(d - np.outer(d @ up, up), axis=1)

    def how(it):
        r = radial(_edge_midpoints(it))
        return towards_edge(it, factor, int(np.argmin(r) if side == "inner" else np.argmax(r)))

    return shrink(assembly, support_interfaces(assembly), how)


def max_thrust(assembly: Assembly, factor: float = 0.1, keystone: str | None = None) -> Assembly:
    """Interfaces of the key-stone (default: the highest free block) shrunk towards their
    lowest edge, the intrados at the crown, which maximises the thrust of an arch."""
    _, up = _vertical_axis(assembly)
    free = [k for k, b in enumerate(assembly.blocks) if not b.support]
    if keystone is None:
        key = max(free, key=lambda k: assembly.blocks[k].centroid @ up)
    else:
        key = next(k for k, b in enumerate(assembly.blocks) if b.id == keystone)
    chosen = [k for k, it in enumerate(assembly.interfaces) if key in (it.a, it.b)]
    return shrink(assembly, chosen,
                  lambda it: towards_edge(it, factor, int(np.argmin(_edge_midpoints(it) @ up))))


def virtual_assembly(assembly: Assembly, analysis: str, factor: float = 0.1) -> Assembly:
    """The assembly of one of the paper's named analyses (ANALYSES)."""
    if analysis == "kern-fitting":
        return shrink(assembly, range(len(assembly.interfaces)), to_kern)
    if analysis in ("inner-base-fitting", "outer-base-fitting"):
        return base_fitting(assembly, analysis.split("-")[0], factor)
    if analysis == "max-thrust":
        return max_thrust(assembly, factor)
    raise ValueError(f"analysis must be one of {', '.join(ANALYSES)}, not {analysis!r}")
