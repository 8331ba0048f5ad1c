"""Force fields that stand only by prestress: blocks squeezed between their neighbours.

RBE asks for some admissible force field. With Coulomb friction (no dilatancy) a field may
hold a block by a compression the loads never produce in rigid blocks that start unstressed:
a bar between two posts held by friction from a horizontal squeeze (Kao et al. 2022, Coupled
Rigid-Block Analysis). The test (docs/METHOD.md, "Prestress"):

1. Gate: a virtual dilation of the blocks that opens an interface with d_n > mu |d_t| leaves
   it no share in any self-equilibrated compression (its virtual work on the dilation would
   be positive). Walls, arches and domes on the ground have every interface opened: no test.
2. On the interfaces left closed: the stick field (elastic contacts sticking, unstressed at
   the start: the minimum of the RBE QP's complementary energy without friction limit)
   carries no prestress. If it lies within the vertex cones, the blocks stand. Otherwise
   the RBE problem is solved again with the friction resultant of every closed interface
   capped at mu times the stick field's normal resultant there (a Tresca bound, fixed before
   the solve, that no squeeze can raise: one step of Panagiotopoulos' fixed point). No
   field: they stand only squeezed. A field with no friction on the closed interfaces is
   within every such cap: tried first, it decides most steps beside a held block in one
   solve, without the stick field.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .cones import pyramid_facets
from .model import EquilibriumModel
from .solver import Solution, SolveOptions, solve

#: Vertical stretch factors of the virtual dilations tried (1: a similarity about a point far
#: below; larger ones open the bed joints of courses whose bricks are long against their
#: height); the one that leaves fewest interfaces closed is used.
DILATIONS = (1.0, 4.0, 16.0)
#: Depth of the dilation's centre below the scene, in scene lengths.
CENTRE_DEPTH = 10.0
#: The stick field lies within a vertex cone up to this share of mu fn, plus SHARE_TOL of
#: the free weight (the solver's accuracy); the caps are raised by the same share.
CONE_TOL = 1e-3
SHARE_TOL = 1e-7


@dataclass(frozen=True)
class Squeeze:
    """The vertices (a boolean mask) of the squeezed blocks' closed interfaces where the
    stick field needed more friction than its normal forces give, when no field within the
    caps exists; none when the loads alone hold the blocks."""

    vertices: np.ndarray

    @property
    def stands(self) -> bool:
        return not self.vertices.any()


def unopened(model: EquilibriumModel, mu: float) -> np.ndarray:
    """The interfaces (a boolean mask) that the best of the virtual dilations (translations
    of the free blocks away from a point far below, supports and held blocks fixed: the
    robots' wrenches then do no virtual work) does not open with
    d_n > mu |d_t|. None unopened: no self-equilibrated compression exists (its virtual work
    on the dilation would be positive, yet A s = 0 makes it zero)."""
    if not len(model.interfaces):
        return np.zeros(0, dtype=bool)
    blocks = model.blocks
    centroids = np.array([b.centroid for b in blocks])
    free = np.zeros(len(blocks), dtype=bool)
    free[model.free] = True
    held = {g.block for g in model.grips}          # a robot keeps a held block in place
    free[[j for j, b in enumerate(blocks) if b.id in held]] = False
    if not free.any():          # every free block held: nothing to squeeze
        return np.zeros(len(model.interfaces), dtype=bool)
    up = _up(model)
    centre = centroids[free].mean(axis=0) - CENTRE_DEPTH * model.length_scale * up
    pairs = np.array([(it.a, it.b) for it in model.interfaces], dtype=int)
    normal = model.normal[np.searchsorted(model.vertex_interface, np.arange(len(pairs)))]
    best = None
    for stretch in DILATIONS:
        offset = centroids - centre
        offset += (stretch - 1.0) * (offset @ up)[:, None] * up[None, :]
        moved = np.where(free[:, None], offset, 0.0)
        d = moved[pairs[:, 1]] - moved[pairs[:, 0]]
        dn = np.einsum("ij,ij->i", d, normal)
        shut = dn <= mu * np.linalg.norm(d - dn[:, None] * normal, axis=1)
        if best is None or shut.sum() < best.sum():
            best = shut
    return best


def squeeze(model: EquilibriumModel, options: SolveOptions, solution: Solution,
            load=None) -> Squeeze | None:
    """Whether the loads (scaled p; default the dead load) alone hold ``model``'s blocks,
    of which ``solution`` is an RBE field: None when a dilation opens every interface (no
    squeeze can arise), else the result of the test on the interfaces it leaves closed."""
    shut = closed_interfaces(model, options)
    if not shut.any():
        return None
    return _unsqueezed(model, options, solution, load, shut)


def closed_interfaces(model: EquilibriumModel, options: SolveOptions) -> np.ndarray:
    """The interfaces (a boolean mask) where a squeeze could arise under ``options``'
    friction: those the gate's dilations leave closed; none without a friction limit (no
    squeeze is needed then)."""
    if not math.isfinite(options.mu):
        return np.zeros(len(model.interfaces), dtype=bool)
    return unopened(model, options.mu / _capacity_of_outer(options.cone))


def _least_caps(model: EquilibriumModel, shut: np.ndarray) -> np.ndarray:
    """Friction caps (N per interface, inf: none) no larger than any cap of the test on the
    ``shut`` interfaces (the additive tolerance alone): a field within them passes it
    whatever the stick field, so it stands without that solve."""
    return np.where(shut, SHARE_TOL * model.force_scale, math.inf)


def _unsqueezed(model, options: SolveOptions, solution: Solution, load,
                shut: np.ndarray) -> Squeeze:
    """Caps on the friction resultant of every ``shut`` interface: mu times the normal
    resultant of the stick field (no friction limit) there, a Tresca bound no squeeze can
    raise. They stand if the RBE problem has a field within the least caps (none needs the
    stick field), or ``solution`` keeps the caps, or the stick field lies within the vertex
    cones, or the RBE problem solved with the caps has a field."""
    options = replace(options, objective="qp", friction="net")
    if solve(model, options, load=load, friction_cap=_least_caps(model, shut)).solved:
        return Squeeze(np.zeros(model.num_vertices, dtype=bool))
    stick = solve(model, replace(options, mu=math.inf), load=load)
    if not stick.solved:
        return Squeeze(shut[model.vertex_interface])
    cap = options.mu * np.maximum(_sums(model, stick.forces[0]), 0.0) * (1.0 + CONE_TOL) \
        + SHARE_TOL * model.force_scale
    none = np.zeros(model.num_vertices, dtype=bool)
    friction = _tangential(*(_sums(model, solution.forces[k]) for k in (2, 3)), options.cone)
    if np.all(friction[shut] <= cap[shut]):
        return Squeeze(none)
    fn, _, fu, fv = stick.forces
    over = (_tangential(fu, fv, options.cone)
            > options.mu * np.maximum(fn, 0.0) * (1.0 + CONE_TOL) + SHARE_TOL * model.force_scale)
    if not over.any():
        return Squeeze(none)
    if solve(model, options, load=load, friction_cap=np.where(shut, cap, math.inf)).solved:
        return Squeeze(none)
    named = shut[model.vertex_interface] & over      # where the stick field needed more
    return Squeeze(named if named.any() else shut[model.vertex_interface])


def _sums(model: EquilibriumModel, values: np.ndarray) -> np.ndarray:
    """Per-vertex values summed per interface."""
    return np.bincount(model.vertex_interface, values, minlength=len(model.interfaces))


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
