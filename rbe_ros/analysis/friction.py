"""Minimum friction (paper Sec. 3.2, Fig. 10a): the smallest mu at which the assembly stands
by the criterion of ``check`` (the friction-net problem feasible without tension, and the
blocks standing as set in place without pre-load, rbe/prestress.py), by bisection on mu."""
from __future__ import annotations

import math
from dataclasses import replace

from .assembly import Assembly
from .options import CheckOptions
from .verdict import model_of, stable_forces

MU_MAX = 100.0


def minimum_friction(assembly: Assembly, options: CheckOptions = CheckOptions(),
                     tol: float = 1e-4) -> float:
    """Smallest mu (to ``tol``) at which the assembly stands; inf if no friction suffices."""
    model = model_of(assembly, options)

    def stands_with(mu: float) -> bool:
        with_mu = replace(options, solve=replace(options.solve, mu=mu), mu_threshold=None)
        return stable_forces(model, with_mu) is not None

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
