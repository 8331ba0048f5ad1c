"""Stability margin: the smallest horizontal acceleration, as a fraction of g, that topples or
slides an assembly, over N horizontal directions.

A horizontal acceleration of the ground acts on every free block as a horizontal body force
lambda m g d; we report the direction d of that body force (gravity tilts towards d, as in
the tilting test). For direction d the margin is the largest lambda with the load
p_dead + lambda p_d carried without tension: the load-multiplier problem of the tilting test.
A box of half-width b along d, centroid height h above a flat support: min(b / h, mu).

Two things keep the N directions cheap (docs/MARGIN.md has the measurements):

* one solver for all of them (rbe.solver.LoadMultipliers): stated with s = 1 / lambda, the
  directions differ only in the right-hand side, and Clarabel keeps its factorisation's
  ordering and symbolic analysis across them;
* convexity: the horizontal accelerations an assembly withstands form a convex set that
  holds 0 (it stands) and every solved point lambda_i d_i, so the convex hull of the solved
  points bounds every other direction's margin from below. A direction whose bound already
  reaches the smallest margin found cannot be the minimum and is not solved: a wall needs
  its four axis directions only.

Tried and dropped (docs/MARGIN.md): HiGHS's dual simplex kept warm across right-hand sides on
the pyramid LP (thousands of pivots per direction on the degenerate LP of a dome), SCS with
warm starts and its factorisation kept (thousands of iterations per direction), and cutting
planes for the exact cone (they wander over degenerate faces).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rbe.model import build_model
from ..rbe.result import Report
from ..rbe.solver import MULTIPLIER_TOL, LoadMultipliers, SolveOptions
from .assembly import Assembly

DEFAULT_DIRECTIONS = 8


#: Margins within this share of the least are ties (ten times the solver's tolerance on
#: the load multiplier).
TIE = 10 * MULTIPLIER_TOL


@dataclass(frozen=True)
class Margin:
    """The smallest margin over the directions and where it is; per direction too."""

    margin_g: float                 # fraction of g; 0 when the assembly does not stand
    direction: np.ndarray           # (3,) unit horizontal body-force direction of the minimum
    directions: np.ndarray          # (N, 3)
    per_direction: np.ndarray       # (N,) margins; NaN where convexity proved it >= margin_g


def horizontal_directions(gravity, count: int = DEFAULT_DIRECTIONS) -> np.ndarray:
    """``count`` unit vectors perpendicular to gravity, evenly spaced from +x (projected)."""
    if count < 1:
        raise ValueError(f"margin directions must be at least 1, not {count}")
    down = np.asarray(gravity, dtype=float) / np.linalg.norm(gravity)
    e1 = np.array([1.0, 0.0, 0.0]) if abs(down[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = e1 - (e1 @ down) * down
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(-down, e1)
    angles = _angles(count)
    return np.cos(angles)[:, None] * e1 + np.sin(angles)[:, None] * e2


def _angles(count: int) -> np.ndarray:
    return 2 * np.pi * np.arange(count) / count


def not_standing(count: int = DEFAULT_DIRECTIONS, gravity=(0.0, 0.0, -9.81)) -> Margin:
    """The margin of an assembly that does not stand: 0, no direction."""
    return Margin(0.0, np.zeros(3), horizontal_directions(gravity, count), np.zeros(count))


def stability_margin(assembly: Assembly, options: SolveOptions = SolveOptions(),
                     directions: int = DEFAULT_DIRECTIONS, every_direction: bool = False
                     ) -> Margin:
    """Margin of ``assembly``, which stands (the check's verdict says so), under ``options``'
    friction cone and mu (no tension allowed). Directions that cannot hold the minimum are
    skipped (NaN in per_direction) unless ``every_direction``.

    Only for a standing assembly does 0 belong to the set of accelerations it withstands, and
    with it the hull bound; the verdict comes from the check, not from here."""
    dirs = horizontal_directions(assembly.gravity, directions)
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    multipliers = LoadMultipliers(model, options)
    g = float(np.linalg.norm(assembly.gravity))
    margins = np.full(directions, np.nan)
    for k in _first_directions(directions):
        margins[k] = _multiplier(multipliers, model.load(g * dirs[k]))
    while np.isnan(margins).any():
        bounds = hull_bounds(margins)
        left = np.flatnonzero(np.isnan(margins) & (every_direction
                                                   | (bounds < np.nanmin(margins))))
        if not len(left):
            break
        k = int(left[np.argmin(bounds[left])])
        margins[k] = _multiplier(multipliers, model.load(g * dirs[k]))
    # Directions whose margins tie within the solver's tolerance on lambda (a symmetric
    # dome's) are one minimum: the first of them in direction order is reported, so that
    # rounding never picks the direction.
    least = float(np.nanmin(margins))
    k = int(np.flatnonzero(margins <= least + TIE * max(least, 1.0))[0])
    return Margin(float(margins[k]), dirs[k], dirs, margins)


def _first_directions(count: int) -> list[int]:
    """Directions solved before any bound can help: +x, then -x, +y, -y (as close as the
    count allows), so that the hull of their points surrounds 0."""
    return list(dict.fromkeys(round(count * f) % count for f in (0.0, 0.5, 0.25, 0.75)))


def hull_bounds(margins: np.ndarray) -> np.ndarray:
    """Lower bound of every direction's margin (evenly spaced angles, as
    horizontal_directions) from the solved ones (not NaN): how far its ray runs inside the
    convex hull of 0 and the points margin_i d_i, which the convex set of accelerations the
    assembly withstands contains. Solved directions get their own margin."""
    angles = _angles(len(margins))
    rays = np.stack((np.cos(angles), np.sin(angles)), axis=1)
    solved = np.flatnonzero(~np.isnan(margins))
    points = margins[solved, None] * rays[solved]
    bounds = np.where(np.isnan(margins), 0.0, margins)
    i, j = np.triu_indices(len(solved), 1)
    e = points[i] - points[j]                # segments p_j + t e, 0 <= t <= 1
    for ray_index in np.flatnonzero(np.isnan(margins)):
        d = rays[ray_index]
        # rho d = p_j + t e: where the ray meets each segment
        det = e[:, 0] * -d[1] + d[0] * e[:, 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (points[j, 0] * d[1] - points[j, 1] * d[0]) / det
            rho = (e[:, 1] * points[j, 0] - e[:, 0] * points[j, 1]) / det
        ok = (np.abs(det) > 1e-12) & (t >= 0) & (t <= 1) & (rho > 0)
        if ok.any():
            bounds[ray_index] = rho[ok].max()
    return bounds


def _multiplier(multipliers: LoadMultipliers, live: np.ndarray) -> float:
    solution = multipliers(live)
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
