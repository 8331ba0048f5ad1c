"""Planar polygons in 3D: a frame on a plane, projection to and lifting from 2D."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def cross(a, b) -> np.ndarray:
    """Cross product over the last axis (size 3); numpy's np.cross has a large fixed cost on
    the small arrays of per-face and per-interface work."""
    a, b = np.asarray(a), np.asarray(b)
    return np.stack((a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]), axis=-1)


def tangent_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors u, v with (u, v, normal) right-handed; deterministic for a given normal.
    Normals (..., 3) give bases (..., 3)."""
    normal = np.asarray(normal, dtype=float)
    helper = np.where(np.abs(normal[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    u = cross(helper, normal)
    u = u / np.sqrt((u * u).sum(axis=-1, keepdims=True))
    return u, cross(normal, u)


@dataclass(frozen=True)
class PlaneFrame:
    """Origin and right-handed axes (u, v, n) of a plane."""

    origin: np.ndarray
    u: np.ndarray
    v: np.ndarray
    n: np.ndarray

    def to_2d(self, points: np.ndarray) -> np.ndarray:
        d = np.asarray(points) - self.origin
        return np.column_stack((d @ self.u, d @ self.v))

    def to_3d(self, points2d: np.ndarray) -> np.ndarray:
        p = np.asarray(points2d)
        return self.origin + p[:, :1] * self.u + p[:, 1:2] * self.v


def area_moments(poly2d: np.ndarray):
    """Area A, centroid G and second-moment tensor J_G = int (r-G)(r-G)^T dA of a simple polygon
    (k, 2), or of a batch of polygons with k vertices each (..., k, 2).

    Counter-clockwise vertices give a positive area (the Green's-theorem sums of paper Eq. 1-5).
    """
    p = np.asarray(poly2d, dtype=float)
    # the vertex axis first: numpy sums a batch fastest over its first axis
    x, y = np.moveaxis(p[..., 0], -1, 0), np.moveaxis(p[..., 1], -1, 0)
    xn, yn = np.concatenate((x[1:], x[:1])), np.concatenate((y[1:], y[:1]))
    cross = x * yn - xn * y
    area = 0.5 * cross.sum(axis=0)
    cx = ((x + xn) * cross).sum(axis=0) / (6 * area)
    cy = ((y + yn) * cross).sum(axis=0) / (6 * area)
    ixx = ((x * x + x * xn + xn * xn) * cross).sum(axis=0) / 12   # int x^2 dA about the origin
    iyy = ((y * y + y * yn + yn * yn) * cross).sum(axis=0) / 12
    ixy = ((x * yn + 2 * x * y + 2 * xn * yn + xn * y) * cross).sum(axis=0) / 24
    j = np.stack((np.stack((ixx - area * cx * cx, ixy - area * cx * cy), axis=-1),
                  np.stack((ixy - area * cx * cy, iyy - area * cy * cy), axis=-1)), axis=-2)
    if p.ndim == 2:
        return float(area), np.array([cx, cy]), j
    return area, np.stack((cx, cy), axis=-1), j


def ring_neighbours(counts) -> tuple[np.ndarray, np.ndarray]:
    """For rings stored one after another (``counts[r]`` vertices each, no closing vertex), the
    index of each vertex's previous and next vertex in its ring."""
    counts = np.asarray(counts, dtype=np.intp)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    last = first + np.repeat(counts, counts) - 1
    idx = np.arange(len(first))
    return np.where(idx == first, last, idx - 1), np.where(idx == last, first, idx + 1)


def first_argmin(values: np.ndarray, counts) -> np.ndarray:
    """Per group of ``counts`` consecutive values (each count > 0), the index (into
    ``values``) of its first smallest value, as np.argmin picks it."""
    counts = np.asarray(counts, dtype=np.intp)
    starts = np.cumsum(counts) - counts
    low = np.minimum.reduceat(values, starts)
    idx = np.arange(len(values))
    pick = np.minimum.reduceat(np.where(values == np.repeat(low, counts), idx, len(values)), starts)
    return np.where(pick < len(values), pick, starts)        # NaN groups: their first value


def ring_widths(points: np.ndarray, counts) -> np.ndarray:
    """Thickness of each ring (``counts[r]`` 2D vertices each, stored one after another): the
    smallest extent of the ring perpendicular to one of its edges. For a convex polygon this
    is its minimum width (the narrowest slot it passes through). Vectorised: the rings of
    each vertex count form one array, in which every edge is tested against every vertex."""
    pts = np.asarray(points, dtype=float)
    counts = np.asarray(counts, dtype=np.intp)
    starts = np.cumsum(counts) - counts
    out = np.empty(len(counts))
    for k in np.unique(counts):
        members = np.flatnonzero(counts == k)
        p = pts[starts[members][:, None] + np.arange(k)]
        p = p - p[:, :1]                                                   # (m, k, 2)
        edge = np.concatenate((p[:, 1:], p[:, :1]), axis=1) - p
        length = np.sqrt(edge[..., 0] ** 2 + edge[..., 1] ** 2)
        safe = np.where(length > 0, length, 1.0)
        nx, ny = -edge[..., 1] / safe, edge[..., 0] / safe                 # (m, k) per edge
        proj = p[:, None, :, 0] * nx[:, :, None] + p[:, None, :, 1] * ny[:, :, None]
        extent = proj.max(axis=2) - proj.min(axis=2)                       # (m, k) per edge
        extent[length == 0] = np.inf
        out[members] = extent.min(axis=1)
    return out


def drop_collinear_rings(points: np.ndarray, counts, tol) -> tuple[np.ndarray, np.ndarray]:
    """Rings (``counts[r]`` 2D vertices each, stored one after another) without the vertices
    closer than ``tol`` (one value, or one per ring) to the line through their neighbours:
    greedily, the least significant vertex of each ring first, re-measured after each drop,
    down to 3 vertices. Returns the kept points and counts. All rings at once: each round
    drops at most one vertex per ring, from the rings that dropped one in the round before."""
    pts = np.asarray(points, dtype=float)
    counts = np.asarray(counts, dtype=np.intp)
    cur = counts.copy()
    tol = np.broadcast_to(np.asarray(tol, dtype=float), cur.shape)
    alive = np.ones(len(pts), dtype=bool)
    owner = np.repeat(np.arange(len(cur)), cur)
    active = cur > 3
    while active.any():
        sel = np.flatnonzero(alive & active[owner])
        rings = np.flatnonzero(active)
        c = cur[rings]
        p = pts[sel]
        prev_i, next_i = ring_neighbours(c)
        prev = p[prev_i]
        chord = p[next_i] - prev
        cx, cy = chord[:, 0], chord[:, 1]
        length = np.sqrt(cx * cx + cy * cy)
        rel = p - prev
        dist = np.abs(cx * rel[:, 1] - cy * rel[:, 0]) / np.where(length > 0, length, 1.0)
        worst = first_argmin(dist, c)
        drop = dist[worst] < tol[rings]
        alive[sel[worst[drop]]] = False
        cur[rings[drop]] -= 1
        active[rings] = drop & (cur[rings] > 3)
    return pts[alive], cur

