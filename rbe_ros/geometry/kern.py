"""Kern (core) of a planar interface (paper Sec. 2.2, Eq. 1-7).

For the convex hull with area A, centroid G and second-moment tensor J_G, every hull edge line
with outward normal n_a at distance d_a from G has the pole p = G - J_G n_a / (A d_a).
The poles are the kern's vertices: a compressive resultant inside it causes no tension.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

from .polygon import area_moments


def kern(poly2d: np.ndarray) -> np.ndarray:
    """Kern vertices (counter-clockwise) of a polygon given by its 2D vertices."""
    return kerns([poly2d])[0]


def kerns(polygons) -> list[np.ndarray]:
    """Kerns of many polygons: their hulls are grouped by vertex count and computed as arrays."""
    hulls = [_hull(np.asarray(p, dtype=float)) for p in polygons]
    out: list[np.ndarray | None] = [None] * len(hulls)
    for k in sorted({len(h) for h in hulls}):
        members = [i for i, h in enumerate(hulls) if len(h) == k]
        for i, poles in zip(members, _poles(np.stack([hulls[i] for i in members]))):
            out[i] = poles
    return out


def _poles(hulls: np.ndarray) -> np.ndarray:
    """Poles of the edge lines of counter-clockwise convex polygons (m, k, 2)."""
    area, g, j = area_moments(hulls)
    edges = np.roll(hulls, -1, axis=1) - hulls
    normals = np.stack((edges[..., 1], -edges[..., 0]), axis=-1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    dist = np.einsum("mkc,mkc->mk", hulls - g[:, None, :], normals)
    return g[:, None, :] - np.einsum("mkc,mcd->mkd", normals, j) / (area[:, None] * dist)[..., None]


def _hull(pts: np.ndarray) -> np.ndarray:
    """The polygon itself when it is convex and counter-clockwise, else its convex hull."""
    edges = np.concatenate((pts[1:], pts[:1])) - pts
    nxt = np.concatenate((edges[1:], edges[:1]))
    if np.all(edges[:, 0] * nxt[:, 1] - edges[:, 1] * nxt[:, 0] > 0):
        return pts
    return pts[ConvexHull(pts).vertices]
