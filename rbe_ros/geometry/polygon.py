"""Planar polygons in 3D: a frame on a plane, projection to and lifting from 2D."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def cross(a, b) -> np.ndarray:
    """Cross product over the last axis (size 3); numpy's np.cross costs ~20x more on the
    small arrays of per-face and per-interface work."""
    a, b = np.asarray(a), np.asarray(b)
    return np.stack((a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]), axis=-1)


def newell_normal(points: np.ndarray) -> np.ndarray:
    """Unit normal of a (possibly non-convex) planar polygon, oriented by its winding."""
    p, q = points, np.roll(points, -1, axis=0)
    n = np.array([np.sum((p[:, 1] - q[:, 1]) * (p[:, 2] + q[:, 2])),
                  np.sum((p[:, 2] - q[:, 2]) * (p[:, 0] + q[:, 0])),
                  np.sum((p[:, 0] - q[:, 0]) * (p[:, 1] + q[:, 1]))])
    length = np.linalg.norm(n)
    return n / length if length > 0 else n


def tangent_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors u, v with (u, v, normal) right-handed; deterministic for a given normal."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = cross(helper, normal)
    u /= np.linalg.norm(u)
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
    x, y = p[..., 0], p[..., 1]
    xn, yn = np.roll(x, -1, axis=-1), np.roll(y, -1, axis=-1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum(axis=-1)
    cx = ((x + xn) * cross).sum(axis=-1) / (6 * area)
    cy = ((y + yn) * cross).sum(axis=-1) / (6 * area)
    ixx = ((x * x + x * xn + xn * xn) * cross).sum(axis=-1) / 12   # int x^2 dA about the origin
    iyy = ((y * y + y * yn + yn * yn) * cross).sum(axis=-1) / 12
    ixy = ((x * yn + 2 * x * y + 2 * xn * yn + xn * y) * cross).sum(axis=-1) / 24
    j = np.stack((np.stack((ixx - area * cx * cx, ixy - area * cx * cy), axis=-1),
                  np.stack((ixy - area * cx * cy, iyy - area * cy * cy), axis=-1)), axis=-2)
    if p.ndim == 2:
        return float(area), np.array([cx, cy]), j
    return area, np.stack((cx, cy), axis=-1), j


def drop_collinear(points: np.ndarray, tol: float) -> np.ndarray:
    """The polygon without vertices within ``tol`` of the line through their neighbours
    (clipping leaves such vertices on straight edges; shapely's simplify keeps the ring's
    start point whatever it is)."""
    pts = np.asarray(points, dtype=float)
    changed = True
    while changed and len(pts) > 3:
        prev = np.concatenate((pts[-1:], pts[:-1]))
        nxt = np.concatenate((pts[1:], pts[:1]))
        chord = nxt - prev
        length = np.linalg.norm(chord, axis=1)
        cross = chord[:, 0] * (pts - prev)[:, 1] - chord[:, 1] * (pts - prev)[:, 0]
        dist = np.abs(cross) / np.where(length > 0, length, 1.0)
        worst = int(np.argmin(dist))
        changed = dist[worst] <= tol
        if changed:
            pts = np.delete(pts, worst, axis=0)
    return pts
