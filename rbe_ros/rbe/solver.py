"""The RBE optimisation problem (paper Eq. 15-17), stated once and solved with Clarabel.

    minimise    1/2 x^T H x   (QP)   or   c^T x   (LP)
    subject to  A_eq x = -p                       equilibrium of the free blocks
                fn+ >= 0, fn- >= 0                penalty (Whiting) decomposition of fn
                (mu fn_eff, fu, fv) in friction cone, fn_eff = fn+ - fn- (net) or fn+ (plus)

H = diag(c) weights compression, tension (the penalty) and friction. The LP measures friction
through auxiliary magnitudes t >= ||(fu, fv)|| (in the cone's own norm). With a live load the
problem becomes the load-multiplier LP: maximise lambda with p = p_dead + lambda p_live and no
tension allowed. For many live loads on one model, LoadMultipliers states it with the live load
on the right-hand side (s = 1 / lambda), so that one solver serves them all.

Holds (the model's grips) add the robot's wrench (z, y) = (F / W, M / (W l)) per held block,
bounded by second-order cones |F| <= max_force, |M| <= max_torque, and the term
HOLD_WEIGHT / 2 (|z|^2 + |y|^2) to the objective: the robot carries only what it must.
"""
from __future__ import annotations

import math
import time
from array import array
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import clarabel
import numpy as np
import scipy.sparse as sp

from ..deadline import checkpoint, remaining
from .cones import CONES, FRICTION_MODELS, pyramid_facets
from .model import EquilibriumModel, finite

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
#: Weight of the hold wrenches' squared size (z = F / W, y = M / (W l), l the held block's
#: size) against the paper's objective g (weight 1 on the scaled vertex forces), divided by
#: the number of interface vertices nv: the objective is g + w/2 (|z|^2 + |y|^2) with
#: w = HOLD_WEIGHT / nv, one problem whose wrench is the smallest that lets the step stand,
#: to a bound. With z* the smallest wrench and z_w the one found, w/2 |z_w|^2 + g(z_w) <=
#: w/2 |z*|^2 + g(z*) and g >= 0 give |z_w|^2 - |z*|^2 <= 2 g(z*) / w, and the wrench is
#: exactly z* when its own cost w z* exceeds what g saves per unit of it: the lexicographic
#: optimum (the smallest wrench first, then the paper's objective) to O(g / w). A load
#: spread over nv vertices makes g of order 1 / (2 nv), hence the division: the bound is
#: then of the same share of the wrench on one block or a dome. The single block of
#: tests/test_hold_wrench.py (4 vertices) is off by 0.1%. Why not more: the weight costs
#: interior-point iterations (a fixed 1e4 without the division: +65% on the 14 x 10 dome's
#: held steps; as it is, none there and +15% on the 8 x 5 dome's), and a second,
#: lexicographic solve costs a whole solve (docs/HOLD_WRENCH.md). (An epigraph cone
#: r >= |(z, y)| with a linear weight cost +95% and is no more exact: the least size is
#: smooth along the set of wrenches that let a step stand.) A block that needs no hold
#: carries a sliver, of order g' / w.
HOLD_WEIGHT = 1e4


@dataclass(frozen=True)
class Weights:
    """Entries of c for compression fn+, tension fn- (the penalty) and friction fu, fv; the
    factor on HOLD_WEIGHT of the grips' wrenches (0: they cost nothing, the reactions of the
    grips' kinematic constraints, as the placement test takes a pin, rbe/prestress.py)."""

    compression: float = 1.0
    tension: float = 1e6
    friction: float = 1.0
    hold: float = 1.0


@dataclass(frozen=True)
class SolveOptions:
    """The problem solved: objective, friction model and cone, mu, weights, time limit."""

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
    #: (grips, 6): per grip of the model its force (N) and torque about the grip (N m)
    wrenches: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    #: (6 m,): under ``inertia``, the net wrench left on each free block (force in N, moment
    #: about its centroid in N m; m a and the rate of its angular momentum); else empty
    unbalanced: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def unsolved(cls, status: str, solver_status: str, nv: int, time: float,
                 **extra) -> "Solution":
        """A solve that found no forces ("infeasible" or "failed"): NaN at every vertex."""
        return cls(status, solver_status, np.full((4, nv), np.nan), time, **extra)

    @property
    def solved(self) -> bool:
        return self.status == "solved"


_SOLVED = {"Solved", "AlmostSolved"}
#: Numerical trouble worth another attempt (see _attempts).
_RETRY = {"InsufficientProgress", "NumericalError"}
RETRY_REGULARIZATION = 1e-7
_DEFAULT_REGULARIZATION = clarabel.DefaultSettings().static_regularization_constant
_INFEASIBLE = {"PrimalInfeasible", "AlmostPrimalInfeasible"}
#: Clarabel's "auto" switches to faer above some KKT size (the 1021-block wall): there its
#: ordering fills more and each solve costs more than with QDLDL (the cost against size is
#: in docs/SCALING.md, ``make scaling``). Below that size "auto" is QDLDL already. (QDLDL
#: panics on an empty KKT system, as when all blocks are supports: "auto" takes those.)
DIRECT_SOLVE_METHOD = "qdldl"
# Left at Clarabel's defaults: a looser tol_gap saves an iteration or two on walls only and
# moves the forces further from a tightly solved answer; equilibration off costs iterations;
# fewer equilibration steps, presolve off and the faer solver gain nothing measurable.


class _Attempt(NamedTuple):
    refine: bool                    # iterative refinement of every KKT solve
    regularization: float | None    # static regularisation (None: Clarabel's default)
    tension_scale: float            # factor on the tension penalty weight


def _attempts(tension: bool) -> list[_Attempt]:
    """Settings of the successive attempts at one problem, each made only if the one before
    ended in numerical trouble or short of equilibrium (and the first also after MaxIterations).

    The first skips iterative refinement, the larger part of the cost of the KKT solves, with
    the same iterations and verdicts, forces as close to a tightly solved answer, and an
    equilibrium residual still below 1e-10, since Clarabel judges termination on the
    residuals of its iterates, not on the accuracy of the KKT solves. The second is Clarabel's
    default (with refinement). Numerical trouble that remains (InsufficientProgress,
    NumericalError, or AlmostSolved short of equilibrium) hits about one friction+ problem in
    300 among random stacks whose top needs glue: the 1e6 tension penalty makes them
    ill-conditioned (found by the property tests). Then a stronger static regularisation of
    the KKT system, then the penalty 10x lower (the tension found differs by < 0.1%), then
    100x lower (< 0.01% on glued stacks, blocks and the dome; a random stack of the long
    property run needed it), within
    what is left of the time limit."""
    return ([_Attempt(False, None, 1.0), _Attempt(True, None, 1.0),
             _Attempt(True, RETRY_REGULARIZATION, 1.0)]
            + ([_Attempt(True, None, 0.1), _Attempt(True, None, 0.01)] if tension else []))


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


def _spent_since(start: float) -> float:
    """Seconds since ``start`` (perf_counter), added to the block's solver_timing if any."""
    elapsed = time.perf_counter() - start
    spent = _SOLVER_TIME.get()
    if spent is not None:
        spent[0] += elapsed
    return elapsed


class Kept:
    """The Clarabel solver of a solve() (``keep``), for the same problem under another load
    or other friction caps: only the right-hand side b differs (-p on the equilibrium rows,
    the caps on theirs), so Clarabel's data update keeps its equilibration (made from the
    problem's matrices, not b: a kept solve is a fresh one's to rounding,
    tests/test_placement_solves.py), KKT ordering and symbolic factorisation, and
    none of the problem's arrays is built again (the placement test's least forces of a
    motion, whose problem is the motion's with p - e; its steps under new caps). A solver is
    kept from a first attempt that solves or proves the problem infeasible (the placement
    test's RBE problem within caps is, step after step, before it has a field)."""

    def __init__(self):
        self.solver = self.v = None
        self.size = 0               # of the KKT system
        self.capped = None          # the interfaces capped, and where b holds their caps
        self.cap_rows = self.cap_factors = None

    def solve(self, model: EquilibriumModel, options: SolveOptions, p: np.ndarray,
              cap: np.ndarray | None = None) -> Solution | None:
        """The solution under ``p`` and ``cap`` (both scaled), or None if there is no solver
        kept, its caps are not on the same interfaces, or its first attempt is neither
        accepted nor infeasible (solve() then makes the problem anew; infeasible, a fresh
        solve's first attempt would end there too, and no other attempt follows it)."""
        if self.solver is None or not np.array_equal(_capped(cap), self.capped):
            return None
        start = time.perf_counter()
        b = np.asarray(p, dtype=float)
        caps = np.zeros(0) if cap is None else \
            np.tile(cap[self.capped], len(self.cap_rows) // max(len(self.capped), 1))
        rows = np.concatenate((np.arange(len(b)), self.cap_rows))
        values = np.concatenate((-b, self.cap_factors * caps))
        settings = _settings(options, _attempts(False)[0], 0.0, self.size)
        self.solver.update(b=(rows, values), settings=settings)
        result = self.solver.solve()
        status = str(result.status)
        accepted = _accept(model, self.v, np.array(result.x), b, None, status) \
            if status in _SOLVED else None
        elapsed = _spent_since(start)
        if status in _INFEASIBLE:   # where a fresh solve's first attempt ends too (no retry)
            return Solution.unsolved("infeasible", status, self.v.nv, elapsed)
        return None if accepted is None else replace(accepted, time=elapsed)


def _capped(cap: np.ndarray | None) -> np.ndarray:
    """The interfaces that ``cap`` bounds (finite)."""
    return np.array([], dtype=int) if cap is None else np.flatnonzero(np.isfinite(cap))


def solve(model: EquilibriumModel, options: SolveOptions = SolveOptions(), *,
          load: np.ndarray | None = None, live_load: np.ndarray | None = None,
          friction_cap: np.ndarray | None = None, normal_cap: np.ndarray | None = None,
          inertia: sp.spmatrix | None = None, frictionless: bool = False,
          keep: Kept | None = None) -> Solution:
    """Solve the RBE problem of ``model`` under ``load`` (scaled p; default: dead load).
    ``friction_cap`` (N per interface, inf: none) bounds the resultant of each interface's
    friction forces in the cone's norm, as well as the vertex cones (Tresca bounds of the
    placement test, rbe/prestress.py). ``normal_cap`` (N per interface, inf: none) bounds
    the resultant of each interface's normal forces (a block held still presses its
    neighbours no more than the field that stands: the least hold of rbe/prestress.py; no
    solver is kept with it). ``inertia`` (a positive definite (6 m, 6 m) matrix
    on the scaled equilibrium rows) turns equilibrium into the step from rest: the rows'
    imbalance e = A x + p is free, at the cost 1/2 e^T inertia e added to the objective
    (the kinetic energy of the motion it starts, rbe/prestress.py). ``frictionless``: no
    friction variables at all (fn >= 0 only; a third of the variables and no cones).
    Within a check's time budget (:mod:`rbe_ros.deadline`) the solver gets what is left of it,
    and a solve that runs out of it raises CheckTimeout. ``keep``: a solve of the same
    problem under another load kept its solver there (solved with it, unless its first
    attempt fails), else this one keeps its solver there (no live load, no tension)."""
    checkpoint()
    nv = model.num_vertices
    p = model.dead_load if load is None else load
    cap = None if friction_cap is None else np.asarray(friction_cap, float) / model.force_scale
    if frictionless:            # fn >= 0 rows, no cones (as with no friction limit)
        options, cap = replace(options, mu=math.inf), None
    normal = None if normal_cap is None else \
        np.asarray(normal_cap, float) / model.force_scale
    if normal is not None:
        keep = None
    if keep is not None and live_load is None:
        again = keep.solve(model, options, p, cap)
        if again is not None:
            return again
    multiplier = live_load is not None
    lp = options.objective == "lp" and not multiplier
    # Under friction-net fn- is redundant: any fn- > 0 can be cancelled against fn+ at lower
    # cost with the same net force and cone, so it is left out (and with it the 1e6 penalty
    # weight, which only slows the solver down).
    tension = options.allow_tension and not multiplier and options.friction == "plus"
    v = _Variables(nv, tension, lp, multiplier, model.hold_columns.shape[1],
                   0 if inertia is None else model.a_eq.shape[0], not frictionless)
    a, b, cones, at_caps = _constraints(model, options, v, p, live_load, (1.0, MAX_MULTIPLIER),
                                        cap, normal)
    p_diag, q = _objective(options, v, lp, multiplier)
    p_matrix = _Csc.diagonal(p_diag) if inertia is None else _with_inertia(p_diag, v, inertia)
    if lp and nv:
        offsets = (model.points - model.points.mean(axis=0)) @ _TIE_DIRECTION
        tie = 1.0 + LP_TIE_BREAK * (offsets / model.length_scale) ** 2
        for k in (0, 1) if tension else (0,):
            q[v.base[k]:v.base[k] + nv] *= tie
    data = [p_matrix, _floats(q), a, _floats(b), cones]
    start = time.perf_counter()
    status, accepted = "", None
    for k, attempt in enumerate(_attempts(tension)):
        if k and not (status in _RETRY or status in _SOLVED
                      or (k == 1 and status == "MaxIterations")):
            break
        if attempt.tension_scale != 1.0:
            p_retry, q_retry = p_diag.copy(), q.copy()
            (q_retry if lp else p_retry)[v.base[1]:v.base[1] + nv] *= attempt.tension_scale
            data[:2] = [_Csc.diagonal(p_retry) if inertia is None else
                        _with_inertia(p_retry, v, inertia), _floats(q_retry)]
        settings = _settings(options, attempt, time.perf_counter() - start, a.shape[0] + v.count)
        solver = clarabel.DefaultSolver(*data, settings)
        result = solver.solve()
        status = str(result.status)
        if status in _SOLVED:
            accepted = _accept(model, v, np.array(result.x), p, live_load, status)
        if keep is not None and not k and not multiplier and not tension and \
                keep.solver is None and (accepted is not None or status in _INFEASIBLE) \
                and solver.is_data_update_allowed():
            keep.solver, keep.v, keep.size = solver, v, a.shape[0] + v.count
            keep.capped = _capped(cap)
            keep.cap_rows, keep.cap_factors = at_caps
        if accepted is not None:
            break
    elapsed = _spent_since(start)
    if accepted is not None:
        return replace(accepted, time=elapsed)
    kind = "infeasible" if status in _INFEASIBLE else "failed"
    if kind == "failed":
        checkpoint()
    return Solution.unsolved(kind, status, nv, elapsed)


def _settings(options: SolveOptions, attempt: _Attempt, spent: float, kkt_size: int):
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.max_iter = MAX_ITER
    if kkt_size:
        settings.direct_solve_method = DIRECT_SOLVE_METHOD
    settings.iterative_refinement_enable = attempt.refine
    settings.static_regularization_constant = attempt.regularization or _DEFAULT_REGULARIZATION
    limit = min(float(options.time_limit) - spent, remaining())
    if math.isfinite(limit):
        settings.time_limit = max(limit, 1e-9)
    return settings


#: Gap and feasibility tolerances of LoadMultipliers' solves: lambda to about 1e-6 of itself,
#: two or three interior-point iterations fewer than Clarabel's 1e-8.
MULTIPLIER_TOL = 1e-6


class LoadMultipliers:
    """The load-multiplier problem of one model for many live loads (``multipliers(p_live)``).

    With s = 1 / lambda and f' = f / lambda (friction cones are cones: f' in K iff f in K):

        minimise s   subject to   A_eq f' + s p_dead = -p_live,   f' in K,   s >= 1 / MAX_MULTIPLIER

    The live load is now the right-hand side, the only data that differs between loads, so
    one Clarabel solver serves them all: its KKT ordering, symbolic factorisation and
    equilibration are made once (Clarabel's data update). No tension is allowed. A load whose
    solve ends in numerical trouble is solved again by solve(), with its attempts."""

    def __init__(self, model: EquilibriumModel, options: SolveOptions = SolveOptions()):
        self.model, self.options = model, options
        nv, self._neq = model.num_vertices, model.a_eq.shape[0]
        self._v = _Variables(nv, False, False, True, model.hold_columns.shape[1])
        self._a, b, self._cones, _ = _constraints(model, options, self._v, np.zeros(self._neq),
                                               model.dead_load, (-1.0, -1.0 / MAX_MULTIPLIER))
        self._b = np.array(b)
        self._q = -_objective(options, self._v, False, True)[1]
        self._rows = np.arange(self._neq)
        self._solver = None

    def __call__(self, live_load: np.ndarray) -> Solution:
        checkpoint()
        start = time.perf_counter()
        b = -np.asarray(live_load, dtype=float)
        settings = _settings(self.options, _attempts(False)[0], 0.0, len(self._b) + self._v.count)
        settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = MULTIPLIER_TOL
        if self._solver is None:
            self._b[:self._neq] = b
            self._solver = clarabel.DefaultSolver(
                _Csc.diagonal(np.zeros(self._v.count)), _floats(self._q), self._a,
                _floats(self._b), self._cones, settings)
        else:
            self._solver.update(b=(self._rows, b), settings=settings)
        result = self._solver.solve()
        status = str(result.status)
        elapsed = _spent_since(start)
        if status in _INFEASIBLE:       # no lambda > 0: the smallest live load topples it
            return Solution.unsolved("infeasible", status, self._v.nv, elapsed,
                                     multiplier=0.0)
        if status in _SOLVED:
            x = np.array(result.x)
            s = x[self._v.lam]
            x /= s                              # (f', s) -> (f, lambda) = (f' / s, 1 / s)
            x[self._v.lam] = 1.0 / s
            accepted = _accept(self.model, self._v, x, self.model.dead_load, live_load, status)
            if accepted is not None:
                return replace(accepted, time=elapsed)
        return solve(self.model, self.options, live_load=live_load)


def _accept(model: EquilibriumModel, v: _Variables, x: np.ndarray, p, live_load,
            status: str) -> Solution | None:
    """The solution read from a solved x, unless it misses equilibrium by more than
    RESIDUAL_TOL (AlmostSolved can stop short of it)."""
    nv = v.nv
    forces = np.zeros((4, nv))
    for k in range(4):
        if v.base[k] >= 0:
            forces[k] = x[v.base[k]:v.base[k] + nv]
    z = x[v.hold]
    e = x[v.res]
    residual = model.a_eq @ forces.ravel() + (model.hold_columns @ z if len(z) else 0.0) + p \
        - (e if len(e) else 0.0)
    lam = float(x[v.lam]) if live_load is not None else math.nan
    if live_load is not None:
        residual = residual + lam * np.asarray(live_load)
    residual = float(np.abs(residual).max(initial=0.0))
    if residual > RESIDUAL_TOL:
        return None
    unbalanced = e.reshape(-1, 6) * model.force_scale if len(e) else e
    if len(e):
        unbalanced[:, 3:] *= model.length_scale
    return Solution("solved", status, forces * model.force_scale, 0.0, residual, lam,
                    _wrenches(model, z), unbalanced.ravel())


def _wrenches(model: EquilibriumModel, z: np.ndarray) -> np.ndarray:
    """(grips, 6): force (N) and torque about the grip (N m) of each grip from its variables."""
    out = np.zeros((len(model.grips), 6))
    for k, (force, torque, size) in enumerate(model.hold_layout):
        if force >= 0:
            out[k, :3] = z[force:force + 3] * model.force_scale
        if torque >= 0:
            out[k, 3:] = z[torque:torque + 3] * model.force_scale * size
    return out


def _constraints(model: EquilibriumModel, options: SolveOptions, v: _Variables, p, column,
                 bound: tuple[float, float], cap: np.ndarray | None = None,
                 normal: np.ndarray | None = None):
    """A, b and the cones of A x + s = b, s in K, in Clarabel's order: zero cone, nonnegative
    cone, second-order cones; and where b holds the caps (rows, factor on the cap: the caps
    of the capped interfaces in order, once per pyramid facet or once for the soc).
    ``column`` (a load, or None) is the equilibrium column of the multiplier variable,
    bounded by the row ``bound[0] * x <= bound[1]``. ``cap`` (scaled, per interface; see
    solve) adds a cone on each capped interface's friction resultant, ``normal`` (likewise)
    a row on its normal resultant. The equilibrium rows
    are taken as columns of model.a_eq's CSC arrays and stacked on the other rows, not
    rebuilt through coordinates (no sort)."""
    nv = v.nv
    neq = model.a_eq.shape[0]
    rows = _Rows(v.count, neq)
    finite_mu = math.isfinite(options.mu)
    # The cones bound the tangential force by mu fn+: friction+ by its definition, and
    # friction-net too, as solve leaves fn- out under it (fn+ is then the net force).
    fn = v.index(0, np.arange(nv))
    # nonnegative rows (s = b - A x >= 0): normal parts, the multiplier bound, pyramid facets.
    # fn+ >= 0 is left out where the friction cone implies it (a pyramid too: its opposite
    # facets sum to 2 h mu fn+ >= 0): the redundant rows are ~10% of the vault's KKT system
    # and cost it an interior-point iteration.
    for k in ((0,) if not finite_mu else ()) + ((1,) if v.base[1] >= 0 else ()):
        rows.add_rows([(v.index(k, np.arange(nv)), -1.0)], 0.0)
    if column is not None:
        rows.add_rows([(np.array([v.lam]), bound[0])], bound[1])
    bounded = np.array([], dtype=int) if normal is None else np.flatnonzero(np.isfinite(normal))
    if len(bounded):                # sum of (fn+ - fn-) over the interface <= normal
        within = np.full(len(model.interfaces), -1)
        within[bounded] = np.arange(len(bounded))
        within = within[model.vertex_interface]
        rows.add_sums(within, [(fn, 1.0)] + ([(v.index(1, np.arange(nv)), -1.0)]
                                            if v.base[1] >= 0 else []), normal[bounded])
    lp = len(v.t) > 0
    fu, fv = v.index(2, np.arange(nv)), v.index(3, np.arange(nv))
    capped = np.array([], dtype=int) if cap is None else np.flatnonzero(np.isfinite(cap))
    if len(capped):                 # the cap row of each vertex's interface, or -1
        group = np.full(len(model.interfaces), -1)
        group[capped] = np.arange(len(capped))
        group = group[model.vertex_interface]
    if options.cone != "soc":
        angles, h = pyramid_facets(options.cone)
        for theta in angles:
            tangential = [(fu, math.cos(theta)), (fv, math.sin(theta))]
            if finite_mu:
                rows.add_rows(tangential + [(fn, -h * options.mu)], 0.0)
            if lp:
                rows.add_rows(tangential + [(v.t, -1.0)], 0.0)
            if len(capped):
                rows.caps_at(rows.count + np.arange(len(capped)), h)
                rows.add_sums(group, tangential, h * cap[capped])
    cones = [clarabel.ZeroConeT(neq)] + ([clarabel.NonnegativeConeT(rows.count - neq)]
                                         if rows.count > neq else [])
    # second-order cones (t_i, fu_i, fv_i), rows interleaved per vertex
    if options.cone == "soc":
        for head in ([(fn, -options.mu)] if finite_mu else None,
                     [(v.t, -1.0)] if lp else None):
            if head is not None:
                rows.add_cones(head, fu, fv)
                cones += [clarabel.SecondOrderConeT(3)] * nv
        if len(capped):
            rows.caps_at(rows.count + 3 * np.arange(len(capped)), 1.0)
            rows.add_sum_cones(group, fu, fv, cap[capped])
            cones += [clarabel.SecondOrderConeT(3)] * len(capped)
    cones += _capacities(model, v, rows)
    a = _Csc.stack(_equilibrium_columns(model, v, column), rows.matrix())
    return a, _floats(np.concatenate([-np.asarray(p, dtype=float)] + rows.b)), cones, \
        (np.concatenate(rows.cap_rows or [np.zeros(0, dtype=int)]),
         np.concatenate(rows.cap_factors or [np.zeros(0)]))


def _capacities(model: EquilibriumModel, v: _Variables, rows: _Rows) -> list:
    """The second-order cones |F| <= max_force, |M| <= max_torque of the grips with a finite
    capacity (rows (bound, -x) of 4-cones), in the scaled variables."""
    cones = []
    for g, (force, torque, size) in zip(model.grips, model.hold_layout):
        for first, bound, unit in ((force, g.max_force, model.force_scale),
                                   (torque, g.max_torque, model.force_scale * size)):
            if first >= 0 and finite(bound):
                rows.add_capacity(v.hold[first:first + 3], bound / unit)
                cones.append(clarabel.SecondOrderConeT(4))
    return cones


def _equilibrium_columns(model: EquilibriumModel, v: _Variables, column) -> _Arrays:
    """The rows A_eq x (+ lambda column) of the zero cone in the column layout of ``v``: the
    columns of model.a_eq (stored by kind) without those of fn- unless v has them, empty
    columns for t, a dense column for the multiplier."""
    a_eq, nv = model.a_eq, v.nv
    if not sp.isspmatrix_csc(a_eq):
        a_eq = sp.csc_matrix(a_eq)
    if not a_eq.has_canonical_format:
        a_eq = a_eq.copy()
        a_eq.sum_duplicates()
    indptr, indices, data = a_eq.indptr, a_eq.indices, a_eq.data
    if v.base[1] < 0:       # drop the fn- columns nv..2nv-1
        lo, hi = indptr[nv], indptr[2 * nv]
        indptr = np.concatenate((indptr[:nv + 1], indptr[2 * nv + 1:] - (hi - lo)))
        indices = np.concatenate((indices[:lo], indices[hi:]))
        data = np.concatenate((data[:lo], data[hi:]))
    if v.base[2] < 0:       # frictionless: drop the fu, fv columns (the last 2 nv)
        kept = (len(indptr) - 1) - 2 * nv
        indptr = indptr[:kept + 1]
        indices, data = indices[:indptr[-1]], data[:indptr[-1]]
    extra = [np.full(len(v.t), indptr[-1])]
    holds = model.hold_columns
    if holds.shape[1]:
        holds = sp.csc_matrix(holds)
        extra.append(indptr[-1] + holds.indptr[1:])
        indices = np.concatenate((indices, holds.indices))
        data = np.concatenate((data, holds.data))
    if len(v.res):
        extra.append(indices.size + 1 + np.arange(len(v.res)))
        indices = np.concatenate((indices, np.arange(len(v.res))))
        data = np.concatenate((data, -np.ones(len(v.res))))
    if column is not None:
        values = np.asarray(column, dtype=float)
        extra.append([indices.size + len(values)])
        indices = np.concatenate((indices, np.arange(len(values))))
        data = np.concatenate((data, values))
    indptr = np.concatenate([np.asarray(indptr, dtype=np.int64)]
                            + [np.asarray(x, dtype=np.int64) for x in extra])
    return _Arrays(data, indices, indptr, (a_eq.shape[0], v.count))


class _Variables:
    """Column layout: fn+, [fn-], [fu, fv] (nv each), [t (nv), LP friction magnitudes], [hold
    wrenches], [imbalance e of the equilibrium rows, under inertia], [lambda]."""

    def __init__(self, nv: int, tension: bool, lp: bool, multiplier: bool, holds: int = 0,
                 rows: int = 0, friction: bool = True):
        kinds = ((0, 1) if tension else (0,)) + ((2, 3) if friction else ())
        self.base = np.full(4, -1)
        self.base[list(kinds)] = np.arange(len(kinds)) * nv
        self.t = len(kinds) * nv + np.arange(nv if lp else 0)
        self.hold = len(kinds) * nv + len(self.t) + np.arange(holds)
        self.res = len(kinds) * nv + len(self.t) + holds + np.arange(rows)
        self.lam = len(kinds) * nv + len(self.t) + holds + rows
        self.count = self.lam + int(multiplier)
        self.nv = nv

    def index(self, kind, vertex) -> np.ndarray:
        return self.base[kind] + vertex


class _Rows:
    """Rows of A x + s = b below the equilibrium rows, collected as coordinates in cone order."""

    def __init__(self, columns: int, first: int):
        self.columns = columns
        self.first = self.count = first
        self.r, self.c, self.v, self.b = [], [], [], []
        self.cap_rows, self.cap_factors = [], []     # where b holds caps (add_sums, _cones)

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

    def add_capacity(self, cols: np.ndarray, bound: float) -> None:
        """Rows (bound, -x) of one second-order cone ||x|| <= bound over the columns ``cols``."""
        self.r.append(self.count + 1 + np.arange(len(cols)))
        self.c.append(cols)
        self.v.append(np.full(len(cols), -1.0))
        self.b.append(np.concatenate(([bound], np.zeros(len(cols)))))
        self.count += 1 + len(cols)

    def add_sums(self, group, terms, rhs) -> None:
        """One row per group k: the sum over its vertices (group == k) of coefficient *
        variable over ``terms`` (cols per vertex, coef), at most rhs[k]."""
        on = group >= 0
        for cols, coef in terms:
            self.r.append(self.count + group[on])
            self.c.append(cols[on])
            self.v.append(np.full(int(on.sum()), coef))
        self.b.append(np.asarray(rhs, dtype=float))
        self.count += len(rhs)

    def caps_at(self, rows: np.ndarray, factor: float) -> None:
        """Record that b's ``rows`` hold the caps (in order) times ``factor``."""
        self.cap_rows.append(rows)
        self.cap_factors.append(np.full(len(rows), factor))

    def add_sum_cones(self, group, fu, fv, rhs) -> None:
        """Rows (rhs_k, -sum fu, -sum fv) of one 3-cone per group k (its vertices: group ==
        k): the resultant of their friction at most rhs_k."""
        on = group >= 0
        base = self.count + 3 * group[on]
        for offset, cols in ((1, fu[on]), (2, fv[on])):
            self.r.append(base + offset)
            self.c.append(cols)
            self.v.append(np.full(len(cols), -1.0))
        b = np.zeros((len(rhs), 3))
        b[:, 0] = rhs
        self.b.append(b.ravel())
        self.count += 3 * len(rhs)

    def matrix(self) -> _Arrays:
        """The rows collected (numbered from 0), canonical CSC: sorted by column, then row
        (scipy's conversion from coordinates, without its checks; no two terms of the rows
        share an entry, which it would sum)."""
        r = np.concatenate(self.r) - self.first
        c = np.concatenate(self.c)
        order = np.lexsort((r, c))
        indptr = np.zeros(self.columns + 1, dtype=np.int64)
        np.cumsum(np.bincount(c, minlength=self.columns), out=indptr[1:])
        return _Arrays(np.concatenate(self.v)[order], r[order], indptr,
                       (self.count - self.first, self.columns))


class _Arrays(NamedTuple):
    """A canonical CSC matrix as its arrays (what _Csc.stack reads): scipy's constructor
    checks them at a cost comparable to a small problem's solve."""

    data: np.ndarray
    indices: np.ndarray
    indptr: np.ndarray
    shape: tuple[int, int]

    @property
    def nnz(self) -> int:
        return int(self.indptr[-1])


def _floats(x: np.ndarray) -> array:
    """A vector as Clarabel reads it fastest (see _Csc)."""
    return array("d", np.ascontiguousarray(x, dtype=float).tobytes())


class _Csc:
    """A CSC matrix as Clarabel's constructor reads it: any object with data, indices, indptr,
    shape and has_canonical_format. Clarabel copies each array element by element through the
    Python sequence protocol, and numpy arrays make a scalar object per element: array.array
    fields give it plain numbers."""

    has_canonical_format = True

    def __init__(self, data, indices, indptr, shape):
        self.data = _floats(data)
        self.indices = array("q", np.asarray(indices, dtype=np.int64).tobytes())
        self.indptr = array("q", np.asarray(indptr, dtype=np.int64).tobytes())
        self.shape = tuple(int(n) for n in shape)

    @classmethod
    def diagonal(cls, d: np.ndarray) -> _Csc:
        """diag(d) without its zero entries."""
        nz = np.flatnonzero(d)
        indptr = np.zeros(len(d) + 1, dtype=np.int64)
        indptr[nz + 1] = 1
        return cls(d[nz], nz, np.cumsum(indptr), (len(d), len(d)))

    @classmethod
    def stack(cls, top: sp.csc_matrix, bottom: sp.csc_matrix) -> _Csc:
        """[top; bottom] of two canonical CSC matrices with the same columns (canonical too:
        in every column the rows of top come first)."""
        n_top, n_bottom = np.diff(top.indptr), np.diff(bottom.indptr)
        indptr = top.indptr.astype(np.int64) + bottom.indptr
        at_top = np.arange(top.nnz) + np.repeat(bottom.indptr[:-1], n_top)
        at_bottom = np.arange(bottom.nnz) + np.repeat(top.indptr[1:], n_bottom)
        data = np.empty(indptr[-1])
        indices = np.empty(indptr[-1], dtype=np.int64)
        data[at_top], data[at_bottom] = top.data, bottom.data
        indices[at_top], indices[at_bottom] = top.indices, bottom.indices + top.shape[0]
        return cls(data, indices, indptr, (top.shape[0] + bottom.shape[0], top.shape[1]))

    def tocsc(self) -> sp.csc_matrix:
        return sp.csc_matrix((np.array(self.data), np.array(self.indices), np.array(self.indptr)),
                             shape=self.shape)


def _with_inertia(p_diag: np.ndarray, v: _Variables, inertia: sp.spmatrix) -> _Csc:
    """The objective's matrix: diag(p_diag) and ``inertia`` (upper triangular CSC) on the
    imbalance variables, which carry no diagonal entry of their own; as Clarabel reads it."""
    first, rows = int(v.res[0]), len(v.res)
    upper = inertia if sp.isspmatrix_csc(inertia) else sp.csc_matrix(inertia)
    before, after = p_diag[:first], p_diag[first + rows:]
    nz_before, nz_after = np.flatnonzero(before), np.flatnonzero(after)
    counts = np.concatenate(((before != 0).astype(np.int64), np.diff(upper.indptr),
                             (after != 0).astype(np.int64)))
    indptr = np.concatenate(([0], np.cumsum(counts)))
    indices = np.concatenate((nz_before, upper.indices + first, nz_after + first + rows))
    data = np.concatenate((before[nz_before], upper.data, after[nz_after]))
    return _Csc(data, indices, indptr, (v.count, v.count))


def _objective(options: SolveOptions, v: _Variables, lp: bool, multiplier: bool):
    """Diagonal of H (QP) and linear term c (LP or load multiplier)."""
    w, nv = options.weights, v.nv
    p_diag = np.zeros(v.count)
    q = np.zeros(v.count)
    if multiplier:
        q[v.lam] = -1.0
        return p_diag, q
    p_diag[v.hold] = w.hold * HOLD_WEIGHT / max(nv, 1)
    target = q if lp else p_diag
    for kind, weight in ((0, w.compression), (1, w.tension), (2, w.friction), (3, w.friction)):
        if v.base[kind] >= 0 and not (lp and kind >= 2):
            target[v.base[kind]:v.base[kind] + nv] = weight
    if lp:
        q[v.t] = w.friction
    return p_diag, q
