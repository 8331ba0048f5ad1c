"""Validation of a scene before a check: limits, mass consistency, interpenetration.

:func:`validated_assembly` is the geometry stage of every check with validation on: the
scene's limits (:func:`rbe_ros.scene.validate_scene`), then the posed blocks (closed,
positive-volume meshes), the densities implied by given masses, and no two blocks overlapping
beyond the penetration tolerance plus what a declared pose uncertainty explains. Each
problem raises one :class:`SceneError` naming it. A block that touches nothing is not
invalid: the check's verdict says so (INFEASIBLE).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..deadline import stage
from ..geometry.contacts import ContactOptions, detect_contacts
from ..geometry.block import PosedBlock
from ..geometry.overlap import find_penetration
from ..geometry.uncertainty import allowances, contact_angle_deg
from ..scene import Scene, SceneError, ValidationLimits, validate_scene
from .assembly import Assembly


def validate_assembly(assembly: Assembly, limits: ValidationLimits = ValidationLimits(),
                      contact: ContactOptions = ContactOptions()) -> None:
    """Implied densities of mass-given blocks, and interpenetration (raises SceneError)."""
    for b in assembly.blocks:
        density = b.mass / b.volume
        if not limits.min_density <= density <= limits.max_density:
            raise SceneError(
                f"block {b.id!r}: mass {b.mass:.6g} kg in {b.volume:.6g} m^3 is a density of "
                f"{density:.6g} kg/m^3, outside the sane range [{limits.min_density:g}, "
                f"{limits.max_density:g}] kg/m^3", [b.id])
    blocks = list(assembly.blocks)
    hit = find_penetration(blocks, max(limits.penetration_tol, contact.distance_tol),
                           allowances(blocks, contact.pose_uncertainty_m,
                                      contact.pose_uncertainty_deg) if contact.uncertain
                           else None)
    if hit is not None:
        a, b = assembly.blocks[hit.a], assembly.blocks[hit.b]
        tol = max(limits.penetration_tol, contact.distance_tol) * min(a.size, b.size)
        position, angle, tilt = accepting_uncertainty(a, b, hit.depth, tol, contact)
        turned = f", their faces {tilt:.3g} deg from opposite (the contact angle " \
            f"{contact_angle_deg(contact.angle_tol_deg, contact.pose_uncertainty_deg):g} deg)" \
            if angle > contact.pose_uncertainty_deg else ""
        raise SceneError(f"blocks {a.id!r} and {b.id!r} interpenetrate: they overlap by "
                         f"{hit.depth:.4g} m, more than the tolerance {hit.tol:.4g} m"
                         + (" (with the declared pose uncertainty)" if contact.uncertain else "")
                         + f"{turned}; --pose-uncertainty {position:g}"
                         + (f",{angle:g}" if angle > 0 else "")
                         + " would make it a contact (if the poses are measured that well)",
                         [a.id, b.id])


def facing_angle(a: PosedBlock, b: PosedBlock) -> float:
    """Degrees: how far from opposite the faces of ``a`` and ``b`` that meet are: of the
    facing pairs (normals more than 90 deg apart), the one whose planes are nearest (each
    face's origin from the other's plane)."""
    dot = a.face_normals @ b.face_normals.T
    apart = np.abs(np.einsum("ik,jk->ij", a.face_normals, b.face_origins)
                   - a.face_offsets[:, None]) + \
        np.abs(np.einsum("jk,ik->ij", b.face_normals, a.face_origins)
               - b.face_offsets[None, :])
    i, j = np.unravel_index(np.argmin(np.where(dot < 0, apart, np.inf)), dot.shape)
    return math.degrees(math.acos(float(np.clip(-dot[i, j], -1.0, 1.0))))


def accepting_uncertainty(a: PosedBlock, b: PosedBlock, depth: float, tol: float,
                          contact: ContactOptions) -> tuple[float, float, float]:
    """(position m, angle deg, the faces' angle from opposite in deg): the smallest
    ``--pose-uncertainty POS_M,ANGLE_DEG`` (the position rounded up to 0.1 mm, the angle to
    0.1 deg; a declared one kept if enough) under which blocks ``a`` and ``b``, overlapping
    by ``depth`` beyond the validation's ``tol``, are valid and in contact. The angle first:
    faces meet when their normals are within the angle tolerance plus twice it of opposite.
    Then the position: at that angle the contact detection measures the two faces' largest
    gap over their interface on the mid-plane (a tilted face rises off the other), and
    accepts it within its distance tolerance plus both blocks' allowances (the position
    plus the angle times the block's radius); the validation accepts ``depth`` within
    ``tol`` plus the same allowances."""
    tilt = facing_angle(a, b)
    angle = contact.pose_uncertainty_deg
    if tilt >= contact_angle_deg(contact.angle_tol_deg, angle):
        # the least multiple of 0.1 deg with tolerance + 2 angle > tilt (the test is strict)
        angle = (math.floor((tilt - contact.angle_tol_deg) * 5) + 1) / 10
    gap = depth
    if angle > 0:   # the faces' interface at that angle: the nearest face pair detected
        probe = replace(contact, pose_uncertainty_m=depth, pose_uncertainty_deg=angle)
        found = [abs(i.gap) for group in detect_contacts([a, b], probe) for i in group]
        gap = min(found, default=depth)
    have = float(allowances([a, b], 0.0, angle).sum())
    base = contact.distance_tol * min(a.size, b.size)
    needed = max(contact.pose_uncertainty_m, 0.5 * (gap - base - have),
                 0.5 * (depth - tol - have))
    # a hair more, so that the gap, computed with rounding, is within the suggestion
    position = math.ceil(needed * 1e4 * (1 + 1e-6)) / 1e4
    return position, angle, tilt


def validated_assembly(scene: Scene, limits: ValidationLimits | None = ValidationLimits(),
                       contact: ContactOptions = ContactOptions(),
                       assembly: Assembly | None = None) -> Assembly:
    """The assembly of ``scene`` after every validation (none with ``limits=None``).
    ``assembly``: the scene's blocks on interfaces found elsewhere (stored in a COMPAS
    file), validated instead of detecting them."""
    if limits is not None:
        with stage("validation"):
            validate_scene(scene, limits)
    with stage("geometry"):
        assembly = assembly or Assembly.from_scene(scene, contact)
        if limits is not None:
            validate_assembly(assembly, limits, contact)
    return assembly
