"""The default RBE problem of rbe_ros stated in cvxpy, to measure modelling overhead.

The same QP that ``rbe_ros.rbe.solver.solve`` hands to Clarabel as matrices (objective
``qp``, friction-net, exact cone, weights 1 / 1 on compression and friction; fn- is
redundant under friction-net and fixed at 0 there, so it is left out here), over the
equilibrium matrix of ``rbe_ros.rbe.model.build_model``:

    minimise    1/2 (||fn||^2 + ||fu||^2 + ||fv||^2)
    subject to  A_n fn + A_u fu + A_v fv = -p,   fn >= 0,   ||(fu_i, fv_i)|| <= mu fn_i

solved with Clarabel through cvxpy. The load p is a cvxpy Parameter, so a tilting test
re-solves without re-stating the problem (cvxpy caches the compiled problem). A solution
is accepted as rbe_ros accepts one: solved (or almost) with an equilibrium residual of at
most ``RESIDUAL_TOL`` of the free weight.
"""
from __future__ import annotations

import time

import cvxpy as cp
import numpy as np

RESIDUAL_TOL = 1e-6


class CvxpyRBE:
    """The problem for one model; ``stands(load)`` solves it for a scaled load vector."""

    def __init__(self, model, mu: float):
        nv = model.num_vertices
        a = model.a_eq.tocsc()
        self.a_n, self.a_u, self.a_v = a[:, :nv], a[:, 2 * nv:3 * nv], a[:, 3 * nv:4 * nv]
        self.fn = cp.Variable(nv, nonneg=True)
        self.fu = cp.Variable(nv)
        self.fv = cp.Variable(nv)
        self.p = cp.Parameter(a.shape[0])
        constraints = [self.a_n @ self.fn + self.a_u @ self.fu + self.a_v @ self.fv == -self.p,
                       cp.SOC(mu * self.fn, cp.vstack([self.fu, self.fv]), axis=0)]
        objective = cp.Minimize(0.5 * (cp.sum_squares(self.fn) + cp.sum_squares(self.fu)
                                       + cp.sum_squares(self.fv)))
        self.problem = cp.Problem(objective, constraints)
        self.model = model

    def stands(self, load=None) -> bool:
        p = self.model.dead_load if load is None else load
        self.p.value = np.asarray(p, dtype=float)
        try:
            self.problem.solve(solver=cp.CLARABEL)
        except cp.error.SolverError:
            return False
        if self.problem.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or self.fn.value is None:
            return False
        residual = (self.a_n @ self.fn.value + self.a_u @ self.fu.value + self.a_v @ self.fv.value
                    + p)
        return float(np.abs(residual).max(initial=0.0)) <= RESIDUAL_TOL


def check_scene(scene, mu: float, contact=None) -> tuple[bool, float]:
    """Verdict and wall time of one full check: contact detection and the equilibrium matrix
    by rbe_ros (as in ours), then the problem stated, compiled and solved by cvxpy."""
    from rbe_ros.analysis.assembly import Assembly
    from rbe_ros.analysis.graph import ContactGraph
    from rbe_ros.geometry.contacts import ContactOptions
    from rbe_ros.rbe.model import build_model

    start = time.perf_counter()
    assembly = Assembly.from_scene(scene, contact or ContactOptions())
    if ContactGraph(assembly).floating_blocks():
        return False, time.perf_counter() - start
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    ok = CvxpyRBE(model, mu).stands()
    return ok, time.perf_counter() - start
