"""Insertion of the block placed at a step: from which direction it can arrive past the
blocks present (:mod:`rbe_ros.geometry.insertion`), with the interfaces of the whole
assembly, so that a held block's contacts with supports count too (a step's own assembly
drops interfaces between two supports)."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..geometry.insertion import Insertion, insertion
from ..scene import ValidationLimits
from .assembly import Assembly
from .options import CheckOptions

#: The moving block is shrunk by this many times the interpenetration the scene validation
#: accepts (its penetration_tol), so that neighbours in contact do not block its path.
CLEARANCE = 2.0

#: The approach distance when none is given: this many times the block's longest extent.
DEFAULT_APPROACH = 2.0


def interface_normals(assembly: Assembly, index: int, present: set[int]) -> np.ndarray:
    """(k, 3) normals, into block ``index``, of its interfaces with the blocks ``present``."""
    rows = [it.frame.n if it.b == index else -it.frame.n for it in assembly.interfaces
            if (it.b == index and it.a in present) or (it.a == index and it.b in present)]
    return np.array(rows, dtype=float).reshape(-1, 3)


def approach_distance(assembly: Assembly, index: int, options: CheckOptions) -> float:
    """m: the option's, else DEFAULT_APPROACH times the block's longest bounding-box edge."""
    if options.insertion.approach_distance > 0:
        return options.insertion.approach_distance
    box = assembly.blocks[index].aabb
    return DEFAULT_APPROACH * float(np.max(box[1] - box[0]))


def block_insertion(assembly: Assembly, present: Sequence[str], block: str,
                    options: CheckOptions, given=None) -> Insertion:
    """How ``block`` reaches its pose in ``assembly`` (the whole scene's) past the blocks
    ``present`` (it among them or not); ``given``: a direction to check instead of choosing."""
    ids = {b.id: k for k, b in enumerate(assembly.blocks)}
    index = ids[block]
    others = {ids[b] for b in present if b != block}
    moving = assembly.blocks[index]
    limits = options.limits or ValidationLimits()
    down = np.asarray(assembly.gravity, dtype=float)
    return insertion(moving, interface_normals(assembly, index, others),
                     [assembly.blocks[k] for k in sorted(others)], down,
                     approach_distance(assembly, index, options),
                     CLEARANCE * limits.penetration_tol * moving.size, given,
                     np.radians(options.contact.angle_tol_deg))
