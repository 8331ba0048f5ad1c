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
    pts = np.asarray(poly2d, dtype=float)
    hull = pts[ConvexHull(pts).vertices]          # counter-clockwise in 2D
    area, g, j = area_moments(hull)
    edges = np.roll(hull, -1, axis=0) - hull
    normals = np.column_stack((edges[:, 1], -edges[:, 0]))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    dist = np.einsum("ij,ij->i", hull - g, normals)
    return g - (normals @ j) / (area * dist)[:, None]
