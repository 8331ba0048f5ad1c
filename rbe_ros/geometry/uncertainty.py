"""Contacts of measured (imperfect) geometry under a declared pose uncertainty.

A pose known to within ``delta`` (m) and ``theta`` (rad) about the block's centre (the mean
of its vertices: a measured block turns about itself, whatever the origin of its mesh's frame,
which for a mesh given in scene coordinates may be metres away) puts every point of the block
within ``delta + theta * R`` of where the pose says, R being the point's distance from that
centre. Two faces measured apart by a gap g may therefore touch when
|g| <= tol + allowance(a) + allowance(b), with the block's allowance taken over its farthest
vertex (``R`` the block's radius about its centre), and two blocks overlapping by that much
are a contact, not an interpenetration. Their normals may be off opposite by the
design angle tolerance plus ``2 theta``.

Such faces are no longer coplanar, so neither face's plane is the interface: as compas_model
(one best-fit frame for both faces) and 3DEC (a common plane between the two surfaces) do,
the interface lies on the mid-plane (normal the bisector of the two face normals, halfway
between the planes), both outlines are projected onto it along its normal and the polygon is
their overlap; the gap is measured along that normal at every vertex of the polygon.
:func:`rbe_ros.geometry.contacts.detect_contacts` applies these rules; without a declared
uncertainty it keeps the design rule (plane of one face, gap at the other face's origin).

Face pairs beyond the tolerance but within NEAR_FACTOR times it are *near contacts*: reported,
and used to tell whether the verdict depends on the tolerance (see
:mod:`rbe_ros.analysis.asbuilt`).
"""
from __future__ import annotations

import math

import numpy as np

from .block import PosedBlock
from .polygon import cross

#: Face pairs within this many times their contact tolerance are near contacts.
NEAR_FACTOR = 3.0


def allowances(blocks: list[PosedBlock], pose_uncertainty_m: float,
               pose_uncertainty_deg: float) -> np.ndarray:
    """Per block, how far (m) any point of it may be from where its pose puts it:
    ``delta + theta R``, R its largest vertex distance from its centre, the vertex mean
    (zeros when nothing is declared)."""
    if not (pose_uncertainty_m > 0 or pose_uncertainty_deg > 0):
        return np.zeros(len(blocks))
    radius = np.array([np.sqrt(((b.vertices - b.vertices.mean(axis=0)) ** 2).sum(axis=1)).max()
                       for b in blocks])
    return pose_uncertainty_m + math.radians(pose_uncertainty_deg) * radius


def contact_angle_deg(angle_tol_deg: float, pose_uncertainty_deg: float) -> float:
    """Degrees: how far from opposite two faces' normals may be in contact (the design
    tolerance plus ``2 theta``, each face turned by up to theta), at most 90."""
    return min(angle_tol_deg + 2 * pose_uncertainty_deg, 90.0)


def mid_frames(n_a: np.ndarray, d_a: np.ndarray, o_a: np.ndarray, n_b: np.ndarray,
               d_b: np.ndarray, o_b: np.ndarray):
    """Row by row, the mid-plane of face a (normal n_a, plane n_a . x = d_a, a point o_a) and
    the opposed face b: normal n = (n_a - n_b) / |n_a - n_b| (from a into b), through the
    point halfway between the planes along n at the midpoint of o_a and o_b; with in-plane
    axes u, v ((u, v, n) right-handed). Returns origin, u, v, n, each (m, 3)."""
    n = n_a - n_b
    n /= np.sqrt(np.einsum("ij,ij->i", n, n))[:, None]
    centre = 0.5 * (o_a + o_b)
    origin = centre + 0.5 * (_along(centre, n, n_a, d_a) + _along(centre, n, n_b, d_b))[:, None] * n
    helper = np.where((np.abs(n[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    u = cross(helper, n)
    u /= np.sqrt(np.einsum("ij,ij->i", u, u))[:, None]
    return origin, u, cross(n, u), n


def gaps(points: np.ndarray, n: np.ndarray, n_a: np.ndarray, d_a: np.ndarray,
         n_b: np.ndarray, d_b: np.ndarray) -> np.ndarray:
    """Per row, the distance along n from face a's plane to face b's plane through the point
    (positive: apart, negative: overlapping)."""
    return _along(points, n, n_b, d_b) - _along(points, n, n_a, d_a)


def _along(points, n, normal, offset):
    """t with normal . (points + t n) = offset, row by row."""
    return (offset - np.einsum("ij,ij->i", normal, points)) / np.einsum("ij,ij->i", normal, n)
