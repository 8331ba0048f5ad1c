"""Minimum friction (paper Sec. 3.2, Fig. 10a): the smallest mu for which the friction-net
problem is feasible without tension, by bisection on mu."""
from __future__ import annotations

import math
from dataclasses import replace

from ..rbe.model import build_model
from .assembly import Assembly
from .options import CheckOptions
from .verdict import feasible_without_tension

MU_MAX = 100.0


def minimum_friction(assembly: Assembly, options: CheckOptions = CheckOptions(),
                     tol: float = 1e-4) -> float:
    """Smallest mu (to ``tol``) at which the assembly stands; inf if no friction suffices."""
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)

    def stands_with(mu: float) -> bool:
        with_mu = replace(options, solve=replace(options.solve, mu=mu))
        return feasible_without_tension(model, with_mu)

    if not stands_with(math.inf):
        return math.inf
    hi = 1.0
    while not stands_with(hi):
        hi *= 2.0
        if hi > MU_MAX:
            return math.inf
    lo = 0.0
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if stands_with(mid) else (mid, hi)
    return hi
