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
#: A friction ratio exceeds its threshold when above it by more than this share (the solver's
#: rounding of a field at its cone).
RATIO_TOL = 1e-6


def interface_results(model: EquilibriumModel, solution: Solution, *, mu_threshold: float,
                      tension_tol: float, mu: float = math.inf) -> list[InterfaceResult]:
    """Resultants of every interface of ``model`` (``solution`` must be solved).

    A vertex carries tension when its penalty part fn- exceeds ``tension_tol`` times the
    free weight. An interface exceeds friction when |V| > mu_threshold N, or when its shear
    exceeds mu times its net normal force (it would slide; only possible under friction+).

    Computed for all interfaces at once by segment sums over the vertices, only the results
    made one by one (a loop over interfaces costs numpy's overhead per interface). The
    arrays of each result are views into arrays made here (one slice each), never into the
    model or the solution.
    """
    fn_pos, fn_neg, fu, fv = solution.forces
    scale = model.force_scale
    interfaces = model.interfaces
    m = len(interfaces)
    vi = model.vertex_interface
    counts = np.bincount(vi, minlength=m)
    bounds = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(counts, out=bounds[1:])
    if counts.all():    # every interface's n, as repeated per vertex
        n = model.normal[bounds[:-1]]
    else:
        n = np.array([it.frame.n for it in interfaces], dtype=float).reshape(m, 3)

    fn = fn_pos - fn_neg
    tangential = fu[:, None] * model.u + fv[:, None] * model.v
    big_n = _segment_sum(fn[:, None], vi, m)[:, 0]
    shear = _segment_sum(tangential, vi, m)
    shear_norm = np.linalg.norm(shear, axis=1)
    cop = _segment_sum(fn[:, None] * model.points, vi, m)
    carries = np.abs(big_n) > 1e-12 * scale
    cop[carries] /= big_n[carries, None]
    for i in np.flatnonzero(~carries):
        cop[i] = interfaces[i].frame.origin
    forces = fn[:, None] * model.normal + tangential
    torque = (_segment_sum(cross(model.points - cop[vi], forces), vi, m) * n).sum(axis=1)
    ratio = friction_ratios(shear_norm, big_n, scale)
    tension = np.zeros(m, dtype=bool)
    tension_limit = tension_tol * scale
    tension[vi[fn_neg > tension_limit]] = True
    tension |= 0.0 > tension_limit          # max(fn-, initial=0) > limit
    # Sliding under friction+ (whose cones bound the shear by the compressive part fn+ only):
    # shear beyond mu times the net compression, with the tolerances of the ratio test, so
    # that a ratio at or below the threshold (the cone's own limit included) is never
    # flagged, nor an interface whose net force is a rounding-level tension with no shear.
    with np.errstate(invalid="ignore"):     # mu = inf with N = 0: no sliding, as inf * 0 = nan
        slides = shear_norm > mu * np.maximum(big_n, 0.0) * (1 + RATIO_TOL) + NEGLIGIBLE * scale
    exceeded = exceeds(ratio, mu_threshold) | slides
    resultant = big_n[:, None] * n + shear

    polygon = model.points.copy()
    ids = [b.id for b in model.blocks]
    out = []
    for it, lo, hi, normal, res, big, sh, c, t, r, tens, exc in zip(
            interfaces, bounds[:-1].tolist(), bounds[1:].tolist(), n, resultant, big_n.tolist(),
            shear, cop, torque.tolist(), ratio.tolist(), tension.tolist(), exceeded.tolist()):
        out.append(InterfaceResult(
            block_a=ids[it.a], block_b=ids[it.b], normal=normal, polygon=polygon[lo:hi],
            normal_forces=fn[lo:hi], tangential_forces=tangential[lo:hi], resultant=res,
            normal_resultant=big, shear=sh, centre_of_pressure=c, torque=t, kern=it.kern,
            friction_ratio=r, tension=tens, friction_exceeded=exc))
    return out


def _segment_sum(x: np.ndarray, segment: np.ndarray, count: int) -> np.ndarray:
    """Sums of the rows of ``x`` (k, c) by ``segment`` index, in order: (count, c) floats."""
    out = np.zeros((count, x.shape[1]))
    for j in range(x.shape[1]):
        out[:, j] = np.bincount(segment, weights=x[:, j], minlength=count)
    return out


def friction_ratios(shear: np.ndarray, normal: np.ndarray, scale: float) -> np.ndarray:
    """|V|/N per interface from its shear |V| (the Euclidean norm, whatever the cone: the
    report's friction test) and normal resultant N: inf where N is negligible and |V| is
    not, 0 where neither is (negligible: NEGLIGIBLE of the free weight ``scale``)."""
    loaded = normal > NEGLIGIBLE * scale
    ratio = np.where(shear > NEGLIGIBLE * scale, math.inf, 0.0)
    ratio[loaded] = shear[loaded] / normal[loaded]
    return ratio


def exceeds(ratio: np.ndarray, threshold: float) -> np.ndarray:
    """Whether each friction ratio exceeds ``threshold`` (to RATIO_TOL)."""
    return ratio > threshold * (1 + RATIO_TOL)
