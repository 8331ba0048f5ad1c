"""The closed-form verdict of a stack of boxes under a uniform gravity (the overhang rule).

Box k stands on box k - 1 (box 0 on a support) and the contact is the overlap of their
footprints. The chain is statically determinate: the interface under box k carries the
weight of boxes k.. along gravity, through the point where the load line through their
common centroid meets the interface plane. So with no tension the stack stands iff every
such point lies inside its contact polygon (else it tips: tension is required there), and
then every interface needs |V| / N = tan(tilt), which the friction cone allows iff
tan(tilt) <= mu (times the cone's capacity in that direction); a box whose footprint misses
the one below touches nothing and floats. Only shapely and numpy: no rbe_ros code.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

#: Capacity of each cone in any direction, as a share of mu fn: (smallest, largest).
CAPACITY = {"soc": (1.0, 1.0), "pyramid8": (math.cos(math.pi / 8), 1.0),
            "pyramid8-outer": (1.0, 1.0 / math.cos(math.pi / 8)), "pyramid4": (1.0, math.sqrt(2.0))}


@dataclass(frozen=True)
class StackBox:
    id: str
    footprint: shapely.Polygon
    centre: tuple[float, float, float]
    bottom: float      # height of its bottom face
    mass: float


@dataclass(frozen=True)
class Interface:
    below: str
    above: str
    polygon: shapely.Polygon        # empty if the boxes do not touch
    normal_force: float             # N, the weight above times cos(tilt)
    point: np.ndarray               # (x, y) where the load line meets the interface
    margin: float                   # distance of the point inside (+) or outside (-) the polygon


def interfaces(boxes: list[StackBox], gravity) -> list[Interface]:
    """The interface under every box of ``boxes`` (boxes[0] is the support)."""
    g = np.asarray(gravity, dtype=float)
    out = []
    for k in range(1, len(boxes)):
        above = boxes[k:]
        mass = np.array([b.mass for b in above])
        centroid = (mass[:, None] * np.array([b.centre for b in above])).sum(0) / mass.sum()
        point = centroid[:2] + (boxes[k].bottom - centroid[2]) / g[2] * g[:2]
        polygon = boxes[k - 1].footprint.intersection(boxes[k].footprint)
        inside = polygon.contains(shapely.Point(point))
        margin = polygon.exterior.distance(shapely.Point(point)) if polygon.area > 0 else -math.inf
        out.append(Interface(boxes[k - 1].id, boxes[k].id, polygon, float(mass.sum()) * -g[2],
                             point, margin if inside else -margin))
    return out


def verdicts(boxes: list[StackBox], gravity, mu: float, cone: str, friction: str) -> set[str]:
    """The verdicts the check may give: one, or two or three where the direction of sliding
    against a pyramid's facets decides, or tan(tilt) is within 2 % of a friction limit."""
    its = interfaces(boxes, gravity)
    if any(it.polygon.area == 0 for it in its):
        return {"INFEASIBLE"}
    if any(it.margin < 0 for it in its):
        return {"TENSION_REQUIRED"}
    g = np.asarray(gravity, dtype=float)
    tan = math.hypot(g[0], g[1]) / -g[2]
    low, high = CAPACITY[cone]
    if tan < 0.98 * low * mu:
        return {"STABLE"}
    # beyond the threshold mu the post-check flags it; beyond the cone friction-net slides and
    # friction+ needs glue to raise its fn+
    over = "FRICTION_EXCEEDED" if friction == "net" else "TENSION_REQUIRED"
    if tan > 1.02 * high * mu:
        return {over}
    return {"STABLE", "FRICTION_EXCEEDED", over}
