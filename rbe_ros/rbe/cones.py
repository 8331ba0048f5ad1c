"""Mohr-Coulomb friction cones at the interface vertices, exact or linearised.

friction-net bounds the tangential force by the net normal force, friction+ by its
compressive part only (paper Eq. 13-14). The exact cone ||(fu, fv)|| <= mu fn is a
second-order cone; the pyramids replace the circle of radius mu fn by a polygon with facet
normals at angles theta_k and inradius h * mu fn: circumscribed (h = 1, overstates capacity
up to 1/cos(pi/n)) or inscribed (h = cos(pi/n), understates it up to cos(pi/n)).
"""
from __future__ import annotations

import numpy as np

CONES = ("soc", "pyramid8", "pyramid8-outer", "pyramid4")
FRICTION_MODELS = ("net", "plus")


def pyramid_facets(cone: str) -> tuple[np.ndarray, float]:
    """Facet normal angles (rad, in the interface's (u, v) frame) and inradius factor h."""
    if cone == "pyramid8":
        return np.arange(8) * np.pi / 4, float(np.cos(np.pi / 8))
    if cone == "pyramid8-outer":
        return np.arange(8) * np.pi / 4, 1.0
    if cone == "pyramid4":
        return np.arange(4) * np.pi / 2, 1.0
    raise ValueError(f"not a pyramid cone: {cone!r}")


def cone_capacity(cone: str) -> float:
    """Smallest friction capacity of the cone in any direction, as a share of mu fn."""
    return 1.0 if cone == "soc" else pyramid_facets(cone)[1]
