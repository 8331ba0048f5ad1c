"""Tilting test (paper Sec. 3.2.3, 3.3.3): the largest tilt of gravity the assembly stands.

Gravity of magnitude g is turned by alpha towards a horizontal direction h:
g(alpha) = g (cos(alpha) down + sin(alpha) h). Two independent answers:

* bisection on alpha, one RBE solve per trial (as in the paper), to ``tol_deg``;
* one load-multiplier problem, which the paper does not state: maximise lambda with the load
  p_dead + lambda p_live, p_live = m g h. Since the cone constraints are homogeneous, scaling
  g(alpha) by 1/cos(alpha) shows lambda = tan(alpha) at the limit.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..rbe.model import build_model
from ..rbe.solver import solve
from .assembly import Assembly
from .options import CheckOptions
from .verdict import feasible_without_tension

DIRECTIONS = {"x": (1, 0, 0), "-x": (-1, 0, 0), "y": (0, 1, 0), "-y": (0, -1, 0)}


@dataclass(frozen=True)
class TiltResult:
    """The tilt capacity by both methods, in one direction."""

    direction: str
    tilt_deg: float            # by bisection
    multiplier: float          # lambda of the load-multiplier problem
    tilt_deg_multiplier: float  # atan(lambda)
    trials: int                # solves of the bisection
    time_bisection: float      # s
    time_multiplier: float     # s


def horizontal(direction: str, gravity: np.ndarray) -> np.ndarray:
    """Unit vector of ``direction`` (x, y, -x, -y) made perpendicular to gravity."""
    if direction not in DIRECTIONS:
        raise ValueError(f"direction must be one of {', '.join(DIRECTIONS)}, not {direction!r}")
    down = gravity / np.linalg.norm(gravity)
    h = np.array(DIRECTIONS[direction], dtype=float)
    h = h - (h @ down) * down
    if np.linalg.norm(h) < 1e-9:
        raise ValueError(f"direction {direction} is parallel to gravity")
    return h / np.linalg.norm(h)


def tilt_capacity(assembly: Assembly, options: CheckOptions = CheckOptions(),
                  direction: str = "x", tol_deg: float = 0.01) -> TiltResult:
    """The largest tilt of gravity towards ``direction`` the assembly stands, by bisection
    to ``tol_deg`` and by the load-multiplier problem."""
    g = np.asarray(assembly.gravity, dtype=float)
    h = horizontal(direction, g)
    down, magnitude = g / np.linalg.norm(g), float(np.linalg.norm(g))
    model = build_model(assembly.blocks, assembly.interfaces, g)

    start = time.perf_counter()
    trials = 0

    def stands_at(alpha_deg: float) -> bool:
        nonlocal trials
        trials += 1
        a = math.radians(alpha_deg)
        load = model.load(magnitude * (math.cos(a) * down + math.sin(a) * h))
        return feasible_without_tension(model, options, load)

    lo, hi = 0.0, 90.0
    if not stands_at(lo):
        lo = hi = math.nan
    while hi - lo > tol_deg:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stands_at(mid) else (lo, mid)
    t_bisection = time.perf_counter() - start

    start = time.perf_counter()
    solution = solve(model, options.solve, live_load=model.load(magnitude * h))
    lam = solution.multiplier if solution.solved else math.nan
    t_multiplier = time.perf_counter() - start
    return TiltResult(direction, lo, lam, math.degrees(math.atan(lam)), trials,
                      t_bisection, t_multiplier)
