"""Force fields that stand only by prestress: blocks squeezed between their neighbours.

RBE asks for some admissible force field. With Coulomb friction (no dilatancy) a field may
hold a block by a compression the loads never produce in rigid blocks that start unstressed:
a bar between two posts held by friction from a horizontal squeeze (Kao et al. 2022, Coupled
Rigid-Block Analysis, Fig. 2). Such a squeeze is a self-equilibrated compression s: A s = 0,
s in the friction cones, s != 0. Two steps (docs/METHOD.md, "Prestress"):

1. Gate: is there any? A virtual dilation of the blocks that opens every contact strictly
   (d_n > mu |d_t|) proves there is none (the virtual work of s on it would be positive,
   but A s = 0 makes it zero): walls, arches and domes on the ground pass in microseconds.
   Otherwise a small QP (solver.self_stress) finds the vertices a self-stress can load.
2. Non-associative test on those vertices (Panagiotopoulos' fixed point of Tresca problems):
   the elastic stick field (minimum complementary energy, the RBE QP's objective, no friction
   limit there) carries no prestress; then friction is bounded by mu times the normal
   forces of the previous field (Tresca: a bound that no squeeze can raise), and the
   minimum-energy field is solved again, until a field lies within its own Coulomb cones
   (it stands without prestress) or none exists (it stands only squeezed).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .cones import pyramid_facets
from .model import EquilibriumModel
from .solver import SolveOptions, self_stress, solve

#: Vertical stretch factors of the virtual dilations tried as a certificate of no
#: self-stress (1: a similarity about a point far below; larger ones open bed joints of
#: courses whose bricks are long against their height).
DILATIONS = (1.0, 4.0, 16.0)
#: Depth of the dilation's centre below the scene, in scene lengths.
CENTRE_DEPTH = 10.0
#: Tresca iterations before giving up (then the field is taken to need prestress).
MAX_ITERATIONS = 30
#: Relaxation of the Tresca bound after the first iteration (1: plain fixed point, which can
#: alternate between two fields on steep wedges).
RELAXATION = 0.5
#: A field lies within its Coulomb cones up to this share of mu fn (the fixed point is
#: approached, not reached), plus SHARE_TOL of the free weight per vertex.
CONE_TOL = 1e-3
SHARE_TOL = 1e-7
#: Vertices carrying less than this share of the largest self-stress are not squeezed.
SUPPORT_SHARE = 1e-4


@dataclass(frozen=True)
class Squeeze:
    """Vertices a self-stress can load (a boolean mask) and whether the loads alone hold it."""

    vertices: np.ndarray
    stands: bool


def dilation_certificate(model: EquilibriumModel, mu: float) -> bool:
    """Whether a virtual dilation of the free blocks (translations, supports fixed) opens
    every interface with d_n > mu |d_t|: then no self-equilibrated compression exists."""
    if not model.num_vertices:
        return True
    blocks = model.blocks
    centroids = np.array([b.centroid for b in blocks])
    free = np.zeros(len(blocks), dtype=bool)
    free[model.free] = True
    down = -_up(model)
    centre = centroids[free].mean(axis=0) + CENTRE_DEPTH * model.length_scale * down
    pairs = np.array([(it.a, it.b) for it in model.interfaces], dtype=int)
    first = np.searchsorted(model.vertex_interface, np.arange(len(pairs)))
    normal = model.normal[first]
    for stretch in DILATIONS:
        offset = centroids - centre
        offset += (stretch - 1.0) * (offset @ -down)[:, None] * -down[None, :]
        moved = np.where(free[:, None], offset, 0.0)
        d = moved[pairs[:, 1]] - moved[pairs[:, 0]]
        dn = np.einsum("ij,ij->i", d, normal)
        dt = np.linalg.norm(d - dn[:, None] * normal, axis=1)
        if np.all(dn > mu * dt):
            return True
    return False


def squeeze(model: EquilibriumModel, options: SolveOptions, load=None) -> Squeeze | None:
    """The squeezed vertices of ``model`` under ``load`` (scaled p; default the dead load)
    and whether a field without prestress holds them; None if no self-stress exists."""
    if not math.isfinite(options.mu):     # no friction limit: no squeeze is needed
        return None
    if dilation_certificate(model, options.mu / _capacity_of_outer(options.cone)):
        return None
    stress = self_stress(model, options)
    if stress is None:
        return None
    squeezed = stress > SUPPORT_SHARE * stress.max()
    return Squeeze(squeezed, _stands_unsqueezed(model, options, load, squeezed))


def _stands_unsqueezed(model, options: SolveOptions, load, squeezed: np.ndarray) -> bool:
    """Whether the Tresca fixed point on the ``squeezed`` vertices reaches a field within
    its own Coulomb cones."""
    options = replace(options, objective="qp", friction="net")
    bound = np.where(squeezed, math.inf, math.nan)
    tol = SHARE_TOL * model.force_scale
    for k in range(MAX_ITERATIONS):
        solution = solve(model, options, load=load, slip_bound=bound)
        if not solution.solved:
            return False
        fn, _, fu, fv = solution.forces
        limit = options.mu * fn[squeezed]
        if np.all(_tangential(fu[squeezed], fv[squeezed], options.cone)
                  <= limit * (1.0 + CONE_TOL) + tol):
            return True
        limit = np.maximum(limit, 0.0)
        bound[squeezed] = limit if k == 0 else (1.0 - RELAXATION) * bound[squeezed] \
            + RELAXATION * limit
    return False


def _tangential(fu: np.ndarray, fv: np.ndarray, cone: str) -> np.ndarray:
    """The friction force in the norm of ``cone`` (a pyramid's facets over its inradius
    factor), to compare with mu fn."""
    if cone == "soc":
        return np.hypot(fu, fv)
    angles, h = pyramid_facets(cone)
    return np.max(np.outer(fu, np.cos(angles)) + np.outer(fv, np.sin(angles)), axis=1) / h


def _capacity_of_outer(cone: str) -> float:
    """cos(pi / n) of a pyramid (its largest friction is mu fn / cos(pi / n) along an edge),
    1 for the exact cone: the certificate must hold for the cone's largest friction."""
    if cone == "soc":
        return 1.0
    angles, h = pyramid_facets(cone)
    return math.cos(math.pi / len(angles)) / h


def _up(model: EquilibriumModel) -> np.ndarray:
    """Unit vector against the model's dead load (z when it has none)."""
    load = -model.dead_load.reshape(-1, 6)[:, :3].sum(axis=0)
    norm = np.linalg.norm(load)
    return load / norm if norm > 0 else np.array([0.0, 0.0, 1.0])
