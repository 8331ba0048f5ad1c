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

from ..deadline import stage
from ..geometry.contacts import ContactOptions
from ..geometry.block import PosedBlock
from ..geometry.overlap import find_penetration
from ..geometry.uncertainty import allowances
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
        raise SceneError(f"blocks {a.id!r} and {b.id!r} interpenetrate: they overlap by "
                         f"{hit.depth:.4g} m, more than the tolerance {hit.tol:.4g} m"
                         + (" (with the declared pose uncertainty)" if contact.uncertain else "")
                         + f"; --pose-uncertainty {accepting_uncertainty(a, b, hit.depth, contact)}"
                         " would make it a contact (if the poses are measured that well)",
                         [a.id, b.id])


def accepting_uncertainty(a: PosedBlock, b: PosedBlock, depth: float,
                          contact: ContactOptions) -> str:
    """The smallest ``--pose-uncertainty POS_M[,ANGLE_DEG]`` (the position rounded up to
    0.1 mm, a declared angle kept) under which blocks ``a`` and ``b`` overlapping by
    ``depth`` are in contact: the contact detection accepts a gap of -(its distance
    tolerance plus both blocks' allowances), and each allowance grows by the added position
    uncertainty (then the validation, whose tolerance is larger, accepts it too)."""
    have = float(allowances([a, b], contact.pose_uncertainty_m,
                            contact.pose_uncertainty_deg).sum())
    base = contact.distance_tol * min(a.size, b.size)
    needed = contact.pose_uncertainty_m + 0.5 * (depth - base - have)
    # a hair more, so that the gap, computed with rounding, is within the suggestion
    position = math.ceil(needed * 1e4 * (1 + 1e-6)) / 1e4
    angle = contact.pose_uncertainty_deg
    return f"{position:g}" + (f",{angle:g}" if angle > 0 else "")


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
