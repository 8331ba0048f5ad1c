"""Stability margin: the smallest horizontal acceleration, as a fraction of g, that topples or
slides an assembly, over N horizontal directions.

A horizontal acceleration of the ground acts on every free block as a horizontal body force
lambda m g d; we report the direction d of that body force (gravity tilts towards d, as in
the tilting test). For direction d the margin is the largest lambda with the load
p_dead + lambda p_d carried without tension: the load-multiplier problem of the tilting test.
A box of half-width b along d, centroid height h above a flat support: min(b / h, mu).

The N directions share the constraint matrix and differ only in the load. Each is one
load-multiplier solve (Clarabel, exact for every cone). Two ways to make the N solves cheaper
were tried and measured slower on the dome and wall (docs/MARGIN.md): HiGHS's dual simplex
kept warm across right-hand sides (with s = 1 / lambda the directions differ only in the
right-hand side), whose cold start on the degenerate LP of a dome takes minutes; and cutting
planes for the exact cone on that LP, which wander over degenerate faces without converging.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rbe.model import build_model
from ..rbe.result import Report
from ..rbe.solver import SolveOptions, solve
from .assembly import Assembly

DEFAULT_DIRECTIONS = 8


@dataclass(frozen=True)
class Margin:
    """The smallest margin over the directions and where it is; per direction too."""

    margin_g: float                 # fraction of g; 0 when the assembly does not stand
    direction: np.ndarray           # (3,) unit horizontal body-force direction of the minimum
    directions: np.ndarray          # (N, 3)
    per_direction: np.ndarray       # (N,) margins


def horizontal_directions(gravity, count: int = DEFAULT_DIRECTIONS) -> np.ndarray:
    """``count`` unit vectors perpendicular to gravity, evenly spaced from +x (projected)."""
    if count < 1:
        raise ValueError(f"margin directions must be at least 1, not {count}")
    down = np.asarray(gravity, dtype=float) / np.linalg.norm(gravity)
    e1 = np.array([1.0, 0.0, 0.0]) if abs(down[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = e1 - (e1 @ down) * down
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(-down, e1)
    angles = 2 * np.pi * np.arange(count) / count
    return np.cos(angles)[:, None] * e1 + np.sin(angles)[:, None] * e2


def not_standing(count: int = DEFAULT_DIRECTIONS, gravity=(0.0, 0.0, -9.81)) -> Margin:
    """The margin of an assembly that does not stand: 0, no direction."""
    return Margin(0.0, np.zeros(3), horizontal_directions(gravity, count), np.zeros(count))


def stability_margin(assembly: Assembly, options: SolveOptions = SolveOptions(),
                     directions: int = DEFAULT_DIRECTIONS) -> Margin:
    """Margin of ``assembly``, which stands (the check's verdict says so), under ``options``'
    friction cone and mu (no tension allowed).

    Only for a standing assembly is the set of s >= 0 that carry the load unbounded above, so
    that its smallest element is the margin; the verdict comes from the check, not from here."""
    dirs = horizontal_directions(assembly.gravity, directions)
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    loads = [model.load(float(np.linalg.norm(assembly.gravity)) * d) for d in dirs]
    margins = np.array([_multiplier(model, options, p) for p in loads])
    k = int(np.argmin(margins))
    return Margin(float(margins[k]), dirs[k], dirs, margins)


def _multiplier(model, options: SolveOptions, live: np.ndarray) -> float:
    solution = solve(model, options, live_load=live)
    if solution.status == "failed":
        raise RuntimeError(f"margin: solver failed: {solution.solver_status}")
    return float(solution.multiplier) if solution.solved else 0.0


def report_margin(report: Report, assembly: Assembly, options: SolveOptions,
                  directions: int) -> Margin | None:
    """The margin of ``assembly`` (checked in ``report``) over ``directions`` directions
    (0: None, the report's margin_g stays NOT_COMPUTED); an assembly that does not stand has
    margin 0."""
    if directions <= 0:
        return None
    return (stability_margin(assembly, options, directions) if report.stable
            else not_standing(directions, assembly.gravity))
