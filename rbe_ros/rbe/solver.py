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
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field, replace
from typing import NamedTuple

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
#: Numerical trouble worth one more attempt, with this static regularisation (default 1e-8).
_RETRY = {"InsufficientProgress", "NumericalError"}
RETRY_REGULARIZATION = 1e-7
_DEFAULT_REGULARIZATION = clarabel.DefaultSettings().static_regularization_constant
_INFEASIBLE = {"PrimalInfeasible", "AlmostPrimalInfeasible"}


_SOLVER_TIME: ContextVar[list[float] | None] = ContextVar("rbe_solver_time", default=None)


@contextmanager
def solver_timing():
    """Time spent inside the conic solver during the block (``with solver_timing() as t``:
    ``t[0]`` in s), per thread: to tell solver time from the rest of a check."""
    spent = [0.0]
    token = _SOLVER_TIME.set(spent)
    try:
        yield spent
    finally:
        _SOLVER_TIME.reset(token)


def solve(model: EquilibriumModel, options: SolveOptions = SolveOptions(), *,
          load: np.ndarray | None = None, live_load: np.ndarray | None = None) -> Solution:
    """Solve the RBE problem of ``model`` under ``load`` (scaled p; default: dead load)."""
    nv = model.num_vertices
    p = model.dead_load if load is None else load
    multiplier = live_load is not None
    lp = options.objective == "lp" and not multiplier
    # Under friction-net fn- is redundant: any fn- > 0 can be cancelled against fn+ at lower
    # cost with the same net force and cone, so it is left out (and with it the 1e6 penalty
    # weight, which only slows the solver down).
    tension = options.allow_tension and not multiplier and options.friction == "plus"
    v = _Variables(nv, tension, lp, multiplier)
    rows = _Rows(v.count)

    # equilibrium A_eq f (+ lambda p_live) = -p_dead: the zero cone
    a_eq = model.a_eq.tocoo()
    keep = np.isin(a_eq.col // max(nv, 1), (0, 2, 3) if not tension else (0, 1, 2, 3))
    kind, vertex = a_eq.col[keep] // max(nv, 1), a_eq.col[keep] % max(nv, 1)
    rows.add_matrix(a_eq.row[keep], v.index(kind, vertex), a_eq.data[keep], -p)
    if multiplier:
        rows.add_matrix(np.arange(len(p)), np.full(len(p), v.lam), np.asarray(live_load), None,
                        same_rows=True)
    cones = [clarabel.ZeroConeT(rows.count)]

    # nonnegative rows (s = b - A x >= 0): normal parts, the multiplier bound, pyramid facets
    first = rows.count
    for k in (0, 1) if tension else (0,):
        rows.add_rows([(v.index(k, np.arange(nv)), -1.0)], 0.0)
    if multiplier:
        rows.add_rows([(np.array([v.lam]), 1.0)], MAX_MULTIPLIER)
    fn_eff = [(v.index(0, np.arange(nv)), 1.0)]
    if tension and options.friction == "net":
        fn_eff.append((v.index(1, np.arange(nv)), -1.0))
    finite_mu = math.isfinite(options.mu)
    fu, fv = v.index(2, np.arange(nv)), v.index(3, np.arange(nv))
    if options.cone != "soc":
        angles, h = pyramid_facets(options.cone)
        for theta in angles:
            tangential = [(fu, math.cos(theta)), (fv, math.sin(theta))]
            if finite_mu:
                rows.add_rows(tangential + [(c, -h * options.mu * w) for c, w in fn_eff], 0.0)
            if lp:
                rows.add_rows(tangential + [(v.t, -1.0)], 0.0)
    cones.append(clarabel.NonnegativeConeT(rows.count - first))

    # second-order cones (t_i, fu_i, fv_i), rows interleaved per vertex
    if options.cone == "soc":
        for head in ([(c, -options.mu * w) for c, w in fn_eff] if finite_mu else None,
                     [(v.t, -1.0)] if lp else None):
            if head is not None:
                rows.add_cones(head, fu, fv)
                cones.extend(clarabel.SecondOrderConeT(3) for _ in range(nv))

    a, b = rows.matrix()
    p_diag, q = _objective(options, v, lp, multiplier)
    if lp:
        offsets = (model.points - model.points.mean(axis=0)) @ _TIE_DIRECTION
        tie = 1.0 + LP_TIE_BREAK * (offsets / model.length_scale) ** 2
        for k in (0, 1) if tension else (0,):
            q[v.index(k, np.arange(nv))] *= tie
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.max_iter = MAX_ITER
    if math.isfinite(options.time_limit):
        settings.time_limit = float(options.time_limit)
    start = time.perf_counter()
    # Numerical trouble (InsufficientProgress, NumericalError, or AlmostSolved short of
    # equilibrium) hits about one friction+ problem in 300 among random stacks whose top needs
    # glue: the 1e6 tension penalty makes them ill-conditioned (found by the property tests).
    # Retry with a stronger static regularisation of the KKT system, then with the penalty
    # 10x lower (the tension found differs by < 0.1%), within what is left of the time limit.
    retries = [_Retry(RETRY_REGULARIZATION, 1.0)] + ([_Retry(None, 0.1)] if tension else [])
    problem = [sp.diags(p_diag).tocsc(), q, a, b, cones]
    while True:
        result = clarabel.DefaultSolver(*problem, settings).solve()
        status = str(result.status)
        x = np.asarray(result.x)
        accepted = None
        if status in _SOLVED:
            forces = np.zeros((4, nv))
            for k in range(4):
                if k != 1 or tension:
                    forces[k] = x[v.index(k, np.arange(nv))]
            lam_value = x[v.lam] if multiplier else 0.0
            residual = model.a_eq @ forces.ravel() + p
            if multiplier:
                residual = residual + lam_value * np.asarray(live_load)
            residual = float(np.abs(residual).max(initial=0.0))
            if residual <= RESIDUAL_TOL:   # AlmostSolved can stop short of equilibrium
                accepted = Solution("solved", status, forces * model.force_scale, 0.0, residual,
                                    float(lam_value) if multiplier else math.nan)
        if accepted is not None or not (status in _RETRY or status in _SOLVED) or not retries:
            break
        retry = retries.pop(0)
        settings.static_regularization_constant = retry.regularization or _DEFAULT_REGULARIZATION
        if retry.tension_scale != 1.0:
            fn_neg = v.index(1, np.arange(nv))
            p_retry, q_retry = p_diag.copy(), q.copy()
            (q_retry if lp else p_retry)[fn_neg] *= retry.tension_scale
            problem[:2] = [sp.diags(p_retry).tocsc(), q_retry]
        if math.isfinite(options.time_limit):
            settings.time_limit = max(options.time_limit - (time.perf_counter() - start), 1e-9)
    elapsed = time.perf_counter() - start
    spent = _SOLVER_TIME.get()
    if spent is not None:
        spent[0] += elapsed
    if accepted is not None:
        return replace(accepted, time=elapsed)
    kind = "infeasible" if status in _INFEASIBLE else "failed"
    return Solution(kind, status, np.full((4, nv), np.nan), elapsed)


class _Retry(NamedTuple):
    regularization: float | None    # static regularisation (None: Clarabel's default)
    tension_scale: float            # factor on the tension penalty weight


class _Variables:
    """Column layout: fn+, [fn-], fu, fv (nv each), [t (nv), LP friction magnitudes], [lambda]."""

    def __init__(self, nv: int, tension: bool, lp: bool, multiplier: bool):
        kinds = (0, 1, 2, 3) if tension else (0, 2, 3)
        self.base = np.full(4, -1)
        self.base[list(kinds)] = np.arange(len(kinds)) * nv
        self.t = len(kinds) * nv + np.arange(nv if lp else 0)
        self.lam = len(kinds) * nv + len(self.t)
        self.count = self.lam + int(multiplier)
        self.nv = nv

    def index(self, kind, vertex) -> np.ndarray:
        return self.base[kind] + vertex


class _Rows:
    """Rows of A x + s = b collected as coordinates, in cone order."""

    def __init__(self, columns: int):
        self.columns = columns
        self.count = 0
        self.r, self.c, self.v, self.b = [], [], [], []

    def add_matrix(self, rows, cols, vals, rhs, same_rows: bool = False) -> None:
        """Entries of a block of rows starting at the current row (``rhs`` its b)."""
        self.r.append(np.asarray(rows) + (self.count - (len(self.b[-1]) if same_rows else 0)))
        self.c.append(np.asarray(cols))
        self.v.append(np.asarray(vals, dtype=float))
        if not same_rows:
            self.b.append(np.asarray(rhs, dtype=float))
            self.count += len(rhs)

    def add_rows(self, terms, rhs: float) -> None:
        """One row per vertex: sum of coefficient * variable over ``terms`` (cols, coef)."""
        n = len(terms[0][0])
        for cols, coef in terms:
            self.r.append(self.count + np.arange(n))
            self.c.append(cols)
            self.v.append(np.full(n, coef))
        self.b.append(np.full(n, rhs))
        self.count += n

    def add_cones(self, head, fu, fv) -> None:
        """Rows (head, -fu, -fv) of each vertex's 3-cone, interleaved (s = -A x, b = 0)."""
        n = len(fu)
        base = self.count + 3 * np.arange(n)
        for cols, coef in head:
            self.r.append(base)
            self.c.append(cols)
            self.v.append(np.full(n, coef))
        for offset, cols in ((1, fu), (2, fv)):
            self.r.append(base + offset)
            self.c.append(cols)
            self.v.append(np.full(n, -1.0))
        self.b.append(np.zeros(3 * n))
        self.count += 3 * n

    def matrix(self) -> tuple[sp.csc_matrix, np.ndarray]:
        a = sp.csc_matrix((np.concatenate(self.v), (np.concatenate(self.r), np.concatenate(self.c))),
                          shape=(self.count, self.columns))
        return a, np.concatenate(self.b)


def _objective(options: SolveOptions, v: _Variables, lp: bool, multiplier: bool):
    """Diagonal of H (QP) and linear term c (LP or load multiplier)."""
    w, nv = options.weights, v.nv
    p_diag = np.zeros(v.count)
    q = np.zeros(v.count)
    if multiplier:
        q[v.lam] = -1.0
        return p_diag, q
    target = q if lp else p_diag
    for kind, weight in ((0, w.compression), (1, w.tension), (2, w.friction), (3, w.friction)):
        if v.base[kind] >= 0 and not (lp and kind >= 2):
            target[v.base[kind]:v.base[kind] + nv] = weight
    if lp:
        q[v.t] = w.friction
    return p_diag, q
