"""Equilibrium of the free blocks in terms of the interface vertex forces (paper Eq. 8-10).

Every interface vertex i carries f_i = (fn+_i - fn-_i) n + fu_i u + fv_i v, the force that
block a exerts on block b there. For every free block j (supports are left unbalanced):

    sum_k s_jk f_k                    = -w_j         (forces)
    sum_k s_jk (x_k - c_j) x f_k      =  0           (moments about the centroid c_j)

with s = +1 where j is side b and -1 where it is side a. The variables are stored by kind,
x = [fn+, fn-, fu, fv] (nv each), and the system is scaled to forces in units of the total
free weight W and lever arms in units of the scene length L, so that the solver works on
numbers of order one whatever the units of the scene.

A held free block (a :class:`Grip`) stays free with one more load, the robot's wrench: an
unknown force F at the grip point p and a torque M about it, stored after the vertex forces
as columns of ``hold_columns`` (z = F / W and y = M / (W l), l the block's size), so that its
rows read F + ... = -w and (p - c) x F + M + ... = 0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from ..geometry.block import PosedBlock
from ..geometry.contacts import Interface
from ..geometry.polygon import cross

#: Variable kinds in the order they are stacked.
KINDS = ("fn_pos", "fn_neg", "fu", "fv")


@dataclass(frozen=True)
class Grip:
    """A robot's hold of a free block: an unknown force at ``point`` (world) and a torque
    about it, bounded by ``max_force`` (N) and ``max_torque`` (N m). math.inf: unbounded (the
    block is held like a support); 0: none (a pin grip carries no torque). None, the point:
    the block's centroid; a capacity: the check's option (both resolved before a model is
    built, by :func:`rbe_ros.analysis.verdict.model_of`)."""

    block: str
    point: np.ndarray | None = None
    max_force: float | None = None
    max_torque: float | None = None


@dataclass(frozen=True)
class EquilibriumModel:
    """A_eq x = b_eq for the scaled vertex forces x, with what is needed to read x back."""

    blocks: tuple[PosedBlock, ...]
    interfaces: tuple[Interface, ...]
    free: np.ndarray             # indices of the free blocks (rows 6r..6r+5 are block free[r])
    a_eq: sp.csc_matrix          # (6 m, 4 nv)
    dead_load: np.ndarray        # (6 m,) scaled p for gravity: b_eq = -p
    vertex_interface: np.ndarray  # (nv,) interface index of each vertex
    points: np.ndarray           # (nv, 3) world
    normal: np.ndarray           # (nv, 3) per-vertex n, u, v of its interface
    u: np.ndarray
    v: np.ndarray
    force_scale: float           # W in N
    length_scale: float          # L in m
    gravity: np.ndarray          # (3,) m/s^2, of which dead_load is the free blocks' weights
    grips: tuple[Grip, ...] = ()
    #: (6 m, number of hold variables): the equilibrium columns of the grips' wrenches
    hold_columns: sp.csc_matrix = field(default_factory=lambda: sp.csc_matrix((0, 0)))
    #: per grip: first column of its force (-1: none), of its torque (-1: none), its length l
    hold_layout: tuple[tuple[int, int, float], ...] = ()

    @property
    def num_vertices(self) -> int:
        return len(self.points)

    @cached_property
    def index(self) -> dict[str, int]:
        """Each block's position in ``blocks`` by its id (grips name their block by id)."""
        return {b.id: j for j, b in enumerate(self.blocks)}

    def wrench_load(self, wrenches: dict[int, np.ndarray]) -> np.ndarray:
        """Scaled load vector p of known wrenches (force, moment about the centroid; 6 numbers
        in N and N m) on free blocks, by block index: e.g. the fixed forces of interfaces
        left out of a local model."""
        row_of = {int(j): r for r, j in enumerate(self.free)}
        p = np.zeros((len(self.free), 6))
        for j, w in wrenches.items():
            p[row_of[j], :3] = w[:3] / self.force_scale
            p[row_of[j], 3:] = w[3:] / (self.force_scale * self.length_scale)
        return p.ravel()

    def load(self, acceleration: np.ndarray) -> np.ndarray:
        """Scaled load vector p of the free blocks' weights under ``acceleration`` (m/s^2)."""
        return _weights(self.blocks, self.free, acceleration, self.force_scale)


def _weights(blocks, free, acceleration, force_scale) -> np.ndarray:
    """Weights m_j a of the free blocks, acting at their centroids (so no moment)."""
    masses = np.array([blocks[j].mass for j in free])
    p = np.zeros((len(free), 6))
    p[:, :3] = masses[:, None] * np.asarray(acceleration)[None, :] / force_scale
    return p.ravel()


def free_weight(blocks, free, gravity) -> float:
    """W, the weight (N) of the blocks ``free`` (indices) under ``gravity``: the model's unit
    of force (1 when they weigh nothing)."""
    weight = float(sum(blocks[j].mass for j in free)) * float(np.linalg.norm(gravity))
    return weight if weight > 0 else 1.0


def build_model(blocks, interfaces, gravity, grips=()) -> EquilibriumModel:
    """Assemble the scaled equilibrium matrix of the free blocks (vectorised over vertices);
    the blocks of ``grips`` (capacities resolved, not None) are free blocks with a wrench,
    whether or not they are flagged as supports."""
    blocks, interfaces, grips = tuple(blocks), tuple(interfaces), tuple(grips)
    gravity = np.asarray(gravity, dtype=float)
    gripped = {g.block for g in grips}
    free = np.array([j for j, b in enumerate(blocks) if not b.support or b.id in gripped],
                    dtype=int)
    row_of = np.full(len(blocks), -1)
    row_of[free] = np.arange(len(free))

    counts = [len(it.points) for it in interfaces]
    vi = np.repeat(np.arange(len(interfaces)), counts).astype(int)
    nv = len(vi)
    if nv:
        points = np.concatenate([it.points for it in interfaces])
        frames = [it.frame for it in interfaces]
        n, u, v = (np.repeat(np.array([getattr(f, k) for f in frames]), counts, axis=0)
                   for k in "nuv")
    else:
        points = n = u = v = np.zeros((0, 3))

    force_scale = free_weight(blocks, free, gravity)
    centroids = np.array([b.centroid for b in blocks]) if blocks else np.zeros((0, 3))
    extent = np.ptp(centroids, axis=0).max() if len(blocks) > 1 else 0.0
    length_scale = float(max(extent, max((b.size for b in blocks), default=1.0)))

    # Built column by column in CSC: every variable of vertex i has the same rows, 6 per free
    # side (block a's with the sign -1, block b's with +1), taken in increasing row order:
    # the same matrix as through coordinates and scipy's conversion, without the sort.
    basis = np.stack((n, -n, u, v))                                    # (4, nv, 3)
    sides = np.array([(it.a, it.b) for it in interfaces], dtype=int).reshape(-1, 2)[vi]
    r = row_of[sides]                                                  # (nv, 2)
    swap = r[:, 1] < r[:, 0]                                           # b's rows come first
    order = np.stack((swap.astype(int), 1 - swap.astype(int)), axis=1)
    sides, r = (np.take_along_axis(x, order, axis=1) for x in (sides, r))
    sign = np.where(order == 0, -1.0, 1.0)                             # (nv, 2)
    arm = (points[:, None, :] - centroids[sides]) / length_scale       # (nv, 2, 3)
    force = sign[None, :, :, None] * basis[:, :, None, :]              # (4, nv, 2, 3)
    moment = cross(arm[None], force)
    entries = np.concatenate((force, moment), axis=3)                  # (4, nv, 2, 6)
    on = r >= 0
    rows = np.broadcast_to(6 * r[:, :, None] + np.arange(6), (4, nv, 2, 6))
    keep = np.broadcast_to(on[None, :, :, None], rows.shape)
    indptr = np.zeros(4 * nv + 1, dtype=np.int64)
    np.cumsum(np.tile(6 * on.sum(axis=1), 4), out=indptr[1:])
    a_eq = sp.csc_matrix((entries[keep], rows[keep], indptr), shape=(6 * len(free), 4 * nv))
    hold_columns, layout = _hold_columns(blocks, grips, row_of, 6 * len(free), length_scale)
    return EquilibriumModel(blocks, interfaces, free, a_eq,
                            _weights(blocks, free, gravity, force_scale), vi,
                            points, n, u, v, force_scale, length_scale, gravity, grips,
                            hold_columns, layout)


def _hold_columns(blocks, grips, row_of, rows: int, length_scale: float):
    """The equilibrium columns of the grips' wrenches: per grip 3 of the force z = F / W
    (unless its force capacity is 0) and 3 of the torque y = M / (W l) (unless its torque
    capacity is 0), with l the block's size; and the layout of each grip's columns. Built
    as coordinates: a column of the force has its 1 in a force row and the lever arm's
    cross product in the moment rows, one of the torque l / L in a moment row."""
    index = {b.id: j for j, b in enumerate(blocks)}
    r_idx, c_idx, values, layout = [], [], [], []
    count = 0
    for g in grips:
        j = index[g.block]
        r = 6 * int(row_of[j])
        size = float(blocks[j].size) or 1.0
        first_force = first_torque = -1
        if g.max_force != 0:
            first_force, count = count, count + 3
            arm = _cross_matrix((np.asarray(g.point, dtype=float) - blocks[j].centroid)
                                / length_scale)            # column k: arm x e_k
            for k in range(3):
                r_idx += [r + k, r + 3, r + 4, r + 5]
                c_idx += [first_force + k] * 4
                values += [1.0, *arm[:, k]]
        if g.max_torque != 0:
            first_torque, count = count, count + 3
            r_idx += [r + 3, r + 4, r + 5]
            c_idx += [first_torque, first_torque + 1, first_torque + 2]
            values += [size / length_scale] * 3
        layout.append((first_force, first_torque, size))
    matrix = sp.csc_matrix((values, (r_idx, c_idx)), shape=(rows, count))
    return matrix, tuple(layout)


def _cross_matrix(a: np.ndarray) -> np.ndarray:
    """[a]_x: the matrix of x -> a x x."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def finite(value: float | None) -> bool:
    """Whether a grip capacity bounds its wrench."""
    return value is not None and math.isfinite(value)
