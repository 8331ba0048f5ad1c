"""Extents of a point set along many axes: min and max of a . x over the points x.

The separating-axis tests of interpenetration and the convexity test of a block project its
vertices on face normals. Done as one product that costs vertices x axes, which for a
10,000-vertex hull against its own 20,000 face normals is 2e8 products (a second, and 1.6 GB
at once). For large sets the maximum is found instead by climbing the edges of the convex
hull (a vertex no neighbour improves on is the maximum of a linear function over a convex
polytope, as in the simplex method), each axis starting from the hull vertex of the facet
whose normal is nearest to it, which is the answer or a few edges from it: about
(vertices + axes) log(vertices) in all.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, cKDTree

from ..deadline import checkpoint

#: Below this many products (points x axes) the plain product is cheaper than a hull.
DIRECT_PRODUCTS = 200_000


def projection_extents(points: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(A, 2): the min and max of a . x over ``points`` x (n, 3), for each of ``axes`` a."""
    axes = np.asarray(axes, dtype=float).reshape(-1, 3)
    if len(points) * len(axes) <= DIRECT_PRODUCTS or len(points) < 5:
        projected = points @ axes.T
        return np.column_stack((projected.min(axis=0, initial=np.inf),
                                projected.max(axis=0, initial=-np.inf)))
    hull = _Climber(points)
    return np.column_stack((-hull.maxima(-axes), hull.maxima(axes)))


class _Climber:
    """The vertex graph of the convex hull of a point set, for maxima of linear functions."""

    def __init__(self, points: np.ndarray):
        hull = ConvexHull(points)
        checkpoint()
        self.points = points
        n = len(points)
        a, b = hull.simplices.T, hull.simplices[:, [1, 2, 0]].T
        edges = np.unique(np.concatenate(((a * n + b).ravel(), (b * n + a).ravel())))
        self.indptr = np.searchsorted(edges // n, np.arange(n + 1))
        self.neighbours = edges % n
        # one facet per distinct normal: a k-d tree slows down on many equal points (a flat
        # face is as many coplanar triangles)
        _, first = np.unique(np.round(hull.equations[:, :3], 9), axis=0, return_index=True)
        self.facet_vertex = hull.simplices[first, 0]
        self.facet_normals = cKDTree(hull.equations[first, :3])
        corners = hull.vertices
        rays = points[corners] - points[corners].mean(axis=0)
        self.ray_vertex = corners
        self.rays = cKDTree(rays / np.linalg.norm(rays, axis=1)[:, None])

    def maxima(self, axes: np.ndarray) -> np.ndarray:
        """max of a . x over the points, for each axis a (A, 3)."""
        # two starts, the better kept: the vertex of the facet whose normal is nearest to a
        # (right at once on a facet's own normal), and the vertex seen from the centre in
        # the direction nearest to a (near the answer when many facets share one normal,
        # where the first may start far round a flat face's rim)
        starts = (self.facet_vertex[self.facet_normals.query(axes)[1]],
                  self.ray_vertex[self.rays.query(axes / np.linalg.norm(axes, axis=1)[:, None])[1]])
        values = [(self.points[s] * axes).sum(axis=1) for s in starts]
        second = values[1] > values[0]
        at = np.where(second, starts[1], starts[0])
        best = np.where(second, values[1], values[0])
        active = np.arange(len(axes))
        while len(active):
            checkpoint()
            degree = self.indptr[at[active] + 1] - self.indptr[at[active]]   # >= 3 on a hull
            group = np.cumsum(degree) - degree
            owner = np.repeat(np.arange(len(active)), degree)
            candidate = self.neighbours[np.repeat(self.indptr[at[active]] - group, degree)
                                        + np.arange(len(owner))]
            value = (self.points[candidate] * axes[active][owner]).sum(axis=1)
            top = np.maximum.reduceat(value, group)
            better = top > best[active]
            # the first neighbour reaching the top value (one per axis, in axis order)
            hit = np.flatnonzero(value == top[owner])
            first = hit[np.unique(owner[hit], return_index=True)[1]]
            moved = active[better]
            at[moved] = candidate[first[better]]
            best[moved] = top[better]
            active = moved
        return best
