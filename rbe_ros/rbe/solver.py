"""The RBE optimisation problem (paper Eq. 15-17), stated once and solved with Clarabel.

    minimise    1/2 x^T H x   (QP)   or   c^T x   (LP)
    subject to  A_eq x = -p                       equilibrium of the free blocks
                fn+ >= 0, fn- >= 0                penalty (Whiting) decomposition of fn
                (mu fn_eff, fu, fv) in friction cone, fn_eff = fn+ - fn- (net) or fn+ (plus)

H = diag(c) weights compression, tension (the penalty) and friction. The LP measures friction
through auxiliary magnitudes t >= ||(fu, fv)|| (in the cone's own norm). With a live load the
problem becomes the load-multiplier LP: maximise lambda with p = p_dead + lambda p_live and no
tension allowed.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import clarabel
import numpy as np
import scipy.sparse as sp

from .cones import CONES, FRICTION_MODELS, pyramid_facets
from .model import EquilibriumModel

OBJECTIVES = ("qp", "lp")
#: Bound on the load multiplier, so that an assembly no live load can topple stays bounded.
MAX_MULTIPLIER = 1e3
#: Interior-point iterations; LPs close to their feasibility limit need more than the default 200.
MAX_ITER = 1000
#: Largest equilibrium residual (share of the free weight) of an accepted solution.
RESIDUAL_TOL = 1e-6
#: Relative tie-break of the LP objective: an LP has a face of optimal solutions and an
#: interior-point solver returns its centre (the symmetric, QP-like spread). Perturbing the
#: normal-force weights by the squared offset of each vertex along a fixed generic direction
#: picks one vertex of that face, the "rigid" basic solution a simplex solver (as in the
#: paper) returns. (A perturbation linear in position would not do: the self-equilibrated
#: modes that make the face are orthogonal to linear functions of position.)
LP_TIE_BREAK = 1e-3
_TIE_DIRECTION = np.array([1.0, math.sqrt(2.0), math.sqrt(3.0)]) / math.sqrt(6.0)


@dataclass(frozen=True)
class Weights:
    """Entries of c for compression fn+, tension fn- (the penalty) and friction fu, fv."""

    compression: float = 1.0
    tension: float = 1e6
    friction: float = 1.0


@dataclass(frozen=True)
class SolveOptions:
    objective: str = "qp"
    friction: str = "net"
    cone: str = "soc"
    mu: float = 0.6                  # math.inf: no friction limit
    weights: Weights = field(default_factory=Weights)
    allow_tension: bool = True       # False fixes fn- = 0
    time_limit: float = math.inf     # s, per solve

    def __post_init__(self):
        for name, value, allowed in (("objective", self.objective, OBJECTIVES),
                                     ("friction", self.friction, FRICTION_MODELS),
                                     ("cone", self.cone, CONES)):
            if value not in allowed:
                raise ValueError(f"{name} must be one of {', '.join(allowed)}, not {value!r}")
        if not self.mu > 0:
            raise ValueError(f"friction coefficient mu must be positive, not {self.mu}")


@dataclass(frozen=True)
class Solution:
    """Vertex forces in N (rows fn+, fn-, fu, fv) or why there are none."""

    status: str                      # "solved", "infeasible" or "failed"
    solver_status: str
    forces: np.ndarray               # (4, nv)
    time: float                      # s in the solver
    residual: float = math.nan       # max |A f + p| relative to the free weight
    multiplier: float = math.nan     # lambda of the load-multiplier problem

    @property
    def solved(self) -> bool:
        return self.status == "solved"


_SOLVED = {"Solved", "AlmostSolved"}
_INFEASIBLE = {"PrimalInfeasible", "AlmostPrimalInfeasible"}


def solve(model: EquilibriumModel, options: SolveOptions = SolveOptions(), *,
          load: np.ndarray | None = None, live_load: np.ndarray | None = None) -> Solution:
    """Solve the RBE problem of ``model`` under ``load`` (scaled p; default: dead load)."""
    nv = model.num_vertices
    p = model.dead_load if load is None else load
    multiplier = live_load is not None
    lp = options.objective == "lp" and not multiplier
    n_t = nv if lp else 0
    n_x = 4 * nv + n_t + int(multiplier)
    col = {k: np.arange(nv) + i * nv for i, k in enumerate(("fn_pos", "fn_neg", "fu", "fv"))}
    col["t"] = 4 * nv + np.arange(n_t)
    lam = 4 * nv + n_t

    blocks: list[tuple[sp.spmatrix, np.ndarray]] = []
    cones: list = []

    # equilibrium: A_eq f + lambda p_live = -p_dead   (zero cone), and fn- = 0 if no tension
    a_eq = sp.hstack([model.a_eq, sp.csc_matrix((model.a_eq.shape[0], n_t))])
    if multiplier:
        a_eq = sp.hstack([a_eq, sp.csc_matrix(np.asarray(live_load)[:, None])])
    eq_rows = [a_eq]
    eq_rhs = [-p]
    # Under friction-net fn- is redundant: any fn- > 0 can be cancelled against fn+ at lower
    # cost with the same net force and cone, so it is fixed at 0 (and the 1e6 penalty weight,
    # which only slows the solver down, drops out of the problem).
    if not options.allow_tension or multiplier or options.friction == "net":
        eq_rows.append(_select(col["fn_neg"], n_x))
        eq_rhs.append(np.zeros(nv))
    blocks.append((sp.vstack(eq_rows), np.concatenate(eq_rhs)))
    cones.append(clarabel.ZeroConeT(sum(len(r) for r in eq_rhs)))

    # nonnegative rows: fn+ >= 0, fn- >= 0, then pyramid facets (s = b - A x >= 0)
    nonneg = [(-_select(np.concatenate((col["fn_pos"], col["fn_neg"])), n_x), np.zeros(2 * nv))]
    if multiplier:
        nonneg.append((_select(np.array([lam]), n_x), np.array([MAX_MULTIPLIER])))
    fn_eff = _fn_effective(options.friction, col, nv, n_x)
    soc_rows = []
    finite_mu = math.isfinite(options.mu)
    if options.cone == "soc":
        if finite_mu:
            soc_rows.append(_soc(-options.mu * fn_eff, col, nv, n_x))
        if lp:
            soc_rows.append(_soc(-_select(col["t"], n_x), col, nv, n_x))
    else:
        angles, h = pyramid_facets(options.cone)
        for theta in angles:
            tangential = (math.cos(theta) * _select(col["fu"], n_x)
                          + math.sin(theta) * _select(col["fv"], n_x))
            if finite_mu:
                nonneg.append((tangential - h * options.mu * fn_eff, np.zeros(nv)))
            if lp:
                nonneg.append((tangential - _select(col["t"], n_x), np.zeros(nv)))
    blocks.append((sp.vstack([a for a, _ in nonneg]), np.concatenate([b for _, b in nonneg])))
    cones.append(clarabel.NonnegativeConeT(sum(len(b) for _, b in nonneg)))
    for rows in soc_rows:
        blocks.append((rows, np.zeros(rows.shape[0])))
        cones.extend(clarabel.SecondOrderConeT(3) for _ in range(nv))

    a = sp.vstack([m for m, _ in blocks]).tocsc()
    b = np.concatenate([r for _, r in blocks])
    p_diag, q = _objective(options, nv, n_t, n_x, lp, multiplier)
    if lp:
        offsets = (model.points - model.points.mean(axis=0)) @ _TIE_DIRECTION
        q[:2 * nv] *= np.tile(1.0 + LP_TIE_BREAK * (offsets / model.length_scale) ** 2, 2)
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.max_iter = MAX_ITER
    if math.isfinite(options.time_limit):
        settings.time_limit = float(options.time_limit)
    start = time.perf_counter()
    result = clarabel.DefaultSolver(sp.diags(p_diag).tocsc(), q, a, b, cones, settings).solve()
    elapsed = time.perf_counter() - start
    status = str(result.status)
    x = np.asarray(result.x)
    if status in _SOLVED:
        forces = x[:4 * nv].reshape(4, nv)
        lam_value = x[lam] if multiplier else 0.0
        residual = model.a_eq @ x[:4 * nv] + p + (lam_value * np.asarray(live_load) if multiplier else 0)
        residual = float(np.abs(residual).max(initial=0.0))
        if residual <= RESIDUAL_TOL:   # AlmostSolved can stop short of equilibrium at a limit
            return Solution("solved", status, forces * model.force_scale, elapsed, residual,
                            float(lam_value) if multiplier else math.nan)
    kind = "infeasible" if status in _INFEASIBLE else "failed"
    return Solution(kind, status, np.full((4, nv), np.nan), elapsed)


def _select(cols: np.ndarray, n_x: int) -> sp.csr_matrix:
    """Rows picking the variables ``cols`` (one row each)."""
    return sp.csr_matrix((np.ones(len(cols)), (np.arange(len(cols)), cols)), shape=(len(cols), n_x))


def _fn_effective(friction: str, col, nv: int, n_x: int) -> sp.csr_matrix:
    """Rows giving fn+ - fn- (friction-net) or fn+ (friction+) at each vertex."""
    rows = _select(col["fn_pos"], n_x)
    return rows - _select(col["fn_neg"], n_x) if friction == "net" else rows


def _soc(first: sp.csr_matrix, col, nv: int, n_x: int) -> sp.csr_matrix:
    """Rows of the cones (t_i, fu_i, fv_i), interleaved per vertex, with s = -A x (b = 0).

    ``first`` holds -t_i as rows; the tangential rows are -fu, -fv.
    """
    stacked = sp.vstack([first, -_select(col["fu"], n_x), -_select(col["fv"], n_x)]).tocsr()
    order = (np.arange(3)[None, :] * nv + np.arange(nv)[:, None]).ravel()
    return stacked[order]


def _objective(options: SolveOptions, nv: int, n_t: int, n_x: int, lp: bool, multiplier: bool):
    """Diagonal of H (QP) and linear term c (LP or load multiplier)."""
    w = options.weights
    per_kind = np.repeat([w.compression, w.tension, w.friction, w.friction], nv)
    p_diag = np.zeros(n_x)
    q = np.zeros(n_x)
    if multiplier:
        q[-1] = -1.0
    elif lp:
        q[:2 * nv] = per_kind[:2 * nv]
        q[4 * nv:4 * nv + n_t] = w.friction
    else:
        p_diag[:4 * nv] = per_kind
    return p_diag, q
