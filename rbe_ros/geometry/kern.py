"""Kern (core) of a planar interface (paper Sec. 2.2, Eq. 1-7).

For the convex hull with area A, centroid G and second-moment tensor J_G, every hull edge line
with outward normal n_a at distance d_a from G has the pole p = G - J_G n_a / (A d_a).
The poles are the kern's vertices: a compressive resultant inside it causes no tension.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

from .polygon import area_moments, ring_neighbours


def kern(poly2d: np.ndarray) -> np.ndarray:
    """Kern vertices (counter-clockwise) of a polygon given by its 2D vertices."""
    return kerns([poly2d])[0]


def kerns(polygons) -> list[np.ndarray]:
    """Kerns of many polygons (see :func:`kerns_ragged`), one array each."""
    polys = [np.asarray(p, dtype=float).reshape(-1, 2) for p in polygons]
    if not polys:
        return []
    pts, counts = kerns_ragged(np.concatenate(polys), [len(p) for p in polys])
    return np.split(pts, np.cumsum(counts)[:-1])


def kerns_ragged(points: np.ndarray, counts) -> tuple[np.ndarray, np.ndarray]:
    """Kerns of polygons stored one after another (``counts[r]`` 2D vertices each): their
    vertices, stored the same way, and their counts (a hull's, which is the polygon's own
    when it is convex). Convexity is tested for all polygons at once, the few non-convex ones
    get their hull from scipy, and the poles are computed in one array per vertex count."""
    pts = np.asarray(points, dtype=float)
    counts = np.asarray(counts, dtype=np.intp)
    if not len(counts):
        return np.zeros((0, 2)), counts
    convex = _convex_ccw(pts, counts)
    if not convex.all():
        starts = np.cumsum(counts) - counts
        rings = [pts[s:s + c] if ok else pts[s:s + c][ConvexHull(pts[s:s + c]).vertices]
                 for s, c, ok in zip(starts, counts, convex)]
        counts = np.array([len(r) for r in rings], dtype=np.intp)
        pts = np.concatenate(rings)
    starts = np.cumsum(counts) - counts
    out = np.empty_like(pts)
    for k in np.unique(counts):
        idx = starts[counts == k][:, None] + np.arange(k)
        out[idx] = _poles(pts[idx])
    return out, counts


def _convex_ccw(pts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Per polygon: every turn is strictly to the left (convex and counter-clockwise)."""
    _, nxt = ring_neighbours(counts)
    edges = pts[nxt] - pts
    after = edges[nxt]
    left = edges[:, 0] * after[:, 1] - edges[:, 1] * after[:, 0] > 0
    return np.logical_and.reduceat(left, np.cumsum(counts) - counts)


def _poles(hulls: np.ndarray) -> np.ndarray:
    """Poles of the edge lines of counter-clockwise convex polygons (m, k, 2)."""
    area, g, j = area_moments(hulls)
    x, y = hulls[..., 0].T, hulls[..., 1].T                      # (k, m): vertex axis first
    nx = np.concatenate((y[1:], y[:1])) - y                      # outward edge normals
    ny = x - np.concatenate((x[1:], x[:1]))
    length = np.sqrt(nx * nx + ny * ny)
    nx, ny = nx / length, ny / length
    gx, gy = g[:, 0], g[:, 1]
    scale = area * ((x - gx) * nx + (y - gy) * ny)               # A times the edge distance
    px = gx - (nx * j[:, 0, 0] + ny * j[:, 1, 0]) / scale
    py = gy - (nx * j[:, 0, 1] + ny * j[:, 1, 1]) / scale
    return np.stack((px.T, py.T), axis=-1)

