"""Overlaps of convex polygons, many pairs at once (Sutherland-Hodgman in numpy).

Contact detection clips every pair of coplanar, opposed faces; shapely's intersection (a GEOS
overlay per pair, called from Python) costs a call per pair, this one numpy pass. Polygons
are stored padded, x and y as (m, k) arrays with a vertex count per row
(:func:`padded_rings` makes them from ragged coordinates), or one after another while they
are cut.
"""
from __future__ import annotations

import numpy as np

from .polygon import ring_neighbours


def padded_rings(coords, index, rows, size):
    """The outlines ``rows`` as polygons for :func:`clip_convex`, from their coordinates and
    the outline of each (as shapely.get_coordinates gives them; the first ring of each is
    read): x and y (m, k), padded by repeating the last vertex (no area, no turn),
    counter-clockwise (rings reversed where clockwise), vertex counts without the closing
    vertex, and whether each is convex (no clockwise turn beyond rounding, 1e-12 of size^2,
    and at least 3 vertices)."""
    count = np.maximum(np.bincount(index, minlength=int(rows.max()) + 1)[rows] - 1, 0)
    start = np.minimum(np.searchsorted(index, rows), len(index) - 1)
    j = np.arange(max(int(count.max()), 1))
    last = np.maximum(count - 1, 0)[:, None]
    take = start[:, None] + np.minimum(j, last)
    x, y = coords[take, 0], coords[take, 1]
    xn, yn = np.roll(x, -1, axis=1), np.roll(y, -1, axis=1)
    ccw = ((x - x[:, :1]) * (yn - y[:, :1]) - (xn - x[:, :1]) * (y - y[:, :1])).sum(axis=1) >= 0
    if not ccw.all():
        take = np.where(ccw[:, None], take, start[:, None] + np.maximum(last - j, 0))
        x, y = coords[take, 0], coords[take, 1]
        xn, yn = np.roll(x, -1, axis=1), np.roll(y, -1, axis=1)
    ex, ey = xn - x, yn - y                                           # edge i: vertex i to i+1
    turn = np.roll(ex, 1, axis=1) * ey - np.roll(ey, 1, axis=1) * ex
    convex = np.all(turn >= -1e-12 * size[:, None] ** 2, axis=1) & (count >= 3)
    return x, y, count, convex


def clip_convex(ax, ay, na, bx, by, nb, eps):
    """The overlaps of convex polygons a and b, row by row (x and y padded (m, k), ``na`` and
    ``nb`` vertices, counter-clockwise): Sutherland-Hodgman, all rows at once. Polygon a is
    cut by the half-plane left of each edge of b in turn (edge j of every row in one pass,
    the cut polygons stored one after another; see :func:`_clip_half_plane`). With ``eps``
    (per row) as the tolerance throughout, shared and collinear edges (the common case: the
    faces of a box wall meet along whole edges) add no vertex. Afterwards consecutive
    vertices closer than ``eps`` merge, and overlaps of no area (below 3 vertices, or
    thinner than ``eps``: edge and corner contacts) are dropped.

    Returns the rings (counter-clockwise, one after another), their vertex counts, the row
    of each, areas and centroids (shoelace sums about each ring's first vertex).

    Why: shapely's intersection, one GEOS overlay per pair, was about half of
    Assembly.from_scene."""
    m = len(na)
    valid = np.arange(ax.shape[1]) < na[:, None]
    x, y, cnt = ax[valid], ay[valid], na.copy()
    every = np.arange(m)
    for j in range(int(nb.max(initial=0))):
        nxt = np.where(j + 1 < nb, j + 1, 0)
        px, py = bx[:, j], by[:, j]
        ex, ey = bx[every, nxt] - px, by[every, nxt] - py
        length = np.sqrt(ex * ex + ey * ey)
        cut = (j < nb) & (length > 0)
        length = np.where(cut, length, np.inf)                  # no cut: direction (0, 0)
        x, y, cnt = _clip_half_plane(x, y, cnt, px, py, ex / length, ey / length, eps)
    row, prev = _rows_and_previous(cnt)
    dx, dy, tol = x - x[prev], y - y[prev], eps[row]
    keep = dx * dx + dy * dy > tol * tol                  # merge near duplicates, the closing too
    x, y, row = x[keep], y[keep], row[keep]
    cnt = np.bincount(row, minlength=m)
    first = np.cumsum(cnt) - cnt
    _, nxt = ring_neighbours(cnt)
    u, v = x - x[first[row]], y - y[first[row]]
    turn = u * v[nxt] - u[nxt] * v
    area = 0.5 * np.bincount(row, turn, minlength=m)
    cx = np.bincount(row, (u + u[nxt]) * turn, minlength=m)
    cy = np.bincount(row, (v + v[nxt]) * turn, minlength=m)
    span = np.zeros((m, 2))
    some = np.flatnonzero(cnt)
    if len(some):
        pts = np.column_stack((x, y))
        span[some] = (np.maximum.reduceat(pts, first[some])
                      - np.minimum.reduceat(pts, first[some]))
    good = np.flatnonzero((cnt >= 3) & (area > eps * np.sqrt((span ** 2).sum(axis=1))))
    base = first[good]
    centroid = np.column_stack((cx[good] / (6 * area[good]) + x[base],
                                cy[good] / (6 * area[good]) + y[base]))
    keep = np.zeros(m, dtype=bool)
    keep[good] = True
    keep = keep[row]
    return np.column_stack((x[keep], y[keep])), cnt[good], good, area[good], centroid


def _clip_half_plane(x, y, cnt, px, py, ux, uy, eps):
    """One Sutherland-Hodgman step: the polygons (vertices x, y one polygon after another,
    ``cnt`` each) cut by the half-plane left of the line through (px, py) along the unit
    vector (ux, uy), per polygon (ux = uy = 0: uncut). A vertex at most ``eps`` right of the
    line is kept, and an edge's crossing is added only if the edge crosses strictly (from
    more than ``eps`` on one side to more than ``eps`` on the other): per vertex, the
    crossing of its incoming edge, then the vertex, in one flat array compressed at once."""
    row, prev = _rows_and_previous(cnt)
    d = ux[row] * y - uy[row] * x - (ux * py - uy * px)[row]        # left of the line: > 0
    e = eps[row]
    dp, xp, yp = d[prev], x[prev], y[prev]
    inside = d >= -e
    crossing = ((dp > e) & (d < -e)) | ((dp < -e) & (d > e))
    t = dp / np.where(crossing, dp - d, 1.0)
    n = len(x)
    out_x, out_y, mask = np.empty(2 * n), np.empty(2 * n), np.empty(2 * n, dtype=bool)
    out_x[0::2], out_x[1::2] = xp + t * (x - xp), x
    out_y[0::2], out_y[1::2] = yp + t * (y - yp), y
    mask[0::2], mask[1::2] = crossing, inside
    count = np.bincount(row, crossing.view(np.int8) + inside.view(np.int8), minlength=len(cnt))
    return out_x[mask], out_y[mask], count.astype(np.intp)


def _rows_and_previous(cnt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For polygons stored one after another (``cnt`` vertices each), the polygon of each
    vertex and the index of the vertex before it in its polygon (cyclically)."""
    row = np.repeat(np.arange(len(cnt)), cnt)
    prev = np.arange(-1, len(row) - 1)
    ends = np.cumsum(cnt)[cnt > 0]
    prev[ends - cnt[cnt > 0]] = ends - 1
    return row, prev
