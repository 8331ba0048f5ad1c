"""Per-interface resultants of a solution: N, V, centre of pressure, torque, flags."""
from __future__ import annotations

import math

import numpy as np

from ..geometry.polygon import cross
from .model import EquilibriumModel
from .result import InterfaceResult
from .solver import Solution


#: Forces below this share of the free weight are numerically zero.
NEGLIGIBLE = 1e-7


def interface_results(model: EquilibriumModel, solution: Solution, *, mu_threshold: float,
                      tension_tol: float, mu: float = math.inf) -> list[InterfaceResult]:
    """Resultants of every interface of ``model`` (``solution`` must be solved).

    A vertex carries tension when its penalty part fn- exceeds ``tension_tol`` times the
    free weight. An interface exceeds friction when |V| > mu_threshold N, or when its shear
    exceeds mu times its net normal force (it would slide; only possible under friction+).
    """
    fn_pos, fn_neg, fu, fv = solution.forces
    fn = fn_pos - fn_neg
    tangential = fu[:, None] * model.u + fv[:, None] * model.v
    tension_limit = tension_tol * model.force_scale
    out = []
    start = 0
    for it in model.interfaces:
        k = slice(start, start + len(it.points))
        start = k.stop
        pts, n = it.points, it.frame.n
        big_n = float(fn[k].sum())
        shear = tangential[k].sum(axis=0)
        shear_norm = float(np.linalg.norm(shear))
        if abs(big_n) > 1e-12 * model.force_scale:
            cop = (fn[k, None] * pts).sum(axis=0) / big_n
        else:
            cop = it.frame.origin.copy()
        forces = fn[k, None] * n + tangential[k]
        torque = float(cross(pts - cop, forces).sum(axis=0) @ n)
        if big_n > NEGLIGIBLE * model.force_scale:
            ratio = shear_norm / big_n
        else:   # no normal force to speak of: any shear needs unbounded friction
            ratio = math.inf if shear_norm > NEGLIGIBLE * model.force_scale else 0.0
        tension = bool(fn_neg[k].max(initial=0.0) > tension_limit)
        slides = shear_norm > mu * big_n + 1e-9 * model.force_scale
        out.append(InterfaceResult(
            block_a=model.blocks[it.a].id, block_b=model.blocks[it.b].id, normal=n.copy(),
            polygon=pts.copy(), normal_forces=fn[k].copy(), tangential_forces=tangential[k].copy(),
            resultant=big_n * n + shear, normal_resultant=big_n, shear=shear,
            centre_of_pressure=cop, torque=torque, kern=it.kern, friction_ratio=ratio,
            tension=tension, friction_exceeded=bool(ratio > mu_threshold * (1 + 1e-6) or slides)))
    return out
