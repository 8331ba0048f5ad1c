"""Insertion of the block placed at a step: from which direction it can arrive past the
blocks present (:mod:`rbe_ros.geometry.insertion`), with the interfaces of the whole
assembly, so that a held block's contacts with supports count too (a step's own assembly
drops interfaces between two supports). Under a declared pose uncertainty the path and the
cone accept what the contact detection accepts as a contact: every block shrunk by its
allowance, the cone's angle tolerance that of facing faces
(:mod:`rbe_ros.geometry.uncertainty`)."""
from __future__ import annotations

import threading
import weakref
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..geometry.contacts import ContactOptions
from ..geometry.insertion import Insertion, PathCheck, insertion
from ..geometry.uncertainty import allowances, contact_angle_deg
from ..scene import ValidationLimits
from .assembly import Assembly
from .options import CheckOptions

#: The moving block is shrunk by this many times the interpenetration the scene validation
#: accepts (its penetration_tol), so that neighbours in contact do not block its path.
CLEARANCE = 2.0

@dataclass(frozen=True)
class _Index:
    """What every step's insertion asks of one assembly, as arrays: block ids, bounding
    boxes, the interfaces' blocks and normals (from a into b)."""

    ids: dict[str, int]
    boxes: np.ndarray       # (n, 2, 3)
    a: np.ndarray           # (m,)
    b: np.ndarray
    normals: np.ndarray     # (m, 3)
    allow: dict = field(default_factory=dict)   # (m, deg) -> per block allowance (m)

    @classmethod
    def of(cls, assembly: Assembly) -> "_Index":
        its = assembly.interfaces
        return cls(assembly.index,
                   np.array([blk.aabb for blk in assembly.blocks]).reshape(-1, 2, 3),
                   np.array([it.a for it in its], dtype=int),
                   np.array([it.b for it in its], dtype=int),
                   np.array([it.frame.n for it in its], dtype=float).reshape(-1, 3))


_LOCK = threading.Lock()
_LAST: list = [None, None]      # (weak reference to the assembly, its _Index)


def _index(assembly: Assembly) -> _Index:
    """The :class:`_Index` of ``assembly`` (kept for the last assembly asked: a sequence or
    a plan asks of one assembly at every step)."""
    with _LOCK:
        ref, index = _LAST
        if ref is not None and ref() is assembly:
            return index
    index = _Index.of(assembly)
    with _LOCK:
        _LAST[:] = [weakref.ref(assembly), index]
    return index


def block_allowances(assembly: Assembly, contact: ContactOptions) -> np.ndarray:
    """Per block of ``assembly``, its allowance (m) under ``contact``'s declared pose
    uncertainty (zeros without one), computed once per assembly and declaration."""
    index = _index(assembly)
    key = (contact.pose_uncertainty_m, contact.pose_uncertainty_deg)
    if key not in index.allow:
        index.allow[key] = allowances(list(assembly.blocks), *key)
    return index.allow[key]


def interface_normals(assembly: Assembly, block: int, present: np.ndarray) -> np.ndarray:
    """(k, 3) normals, into block ``block``, of its interfaces with the blocks ``present``
    (a boolean mask over the assembly's blocks)."""
    index = _index(assembly)
    into = (index.b == block) & present[index.a]
    out = (index.a == block) & present[index.b]
    return np.concatenate([index.normals[into], -index.normals[out]])


def approach_distance(options: CheckOptions) -> float | None:
    """m over which a path must be free: the option's, else None (from where the block is
    clear of every present block's bounding box, see
    :class:`rbe_ros.geometry.insertion.PathCheck`)."""
    return options.insertion.approach_distance or None


def _path(assembly: Assembly, present: Sequence[str], block: str, options: CheckOptions
          ) -> tuple[int, np.ndarray, PathCheck]:
    """(index of ``block``, mask of the blocks present but it, the path check of ``block``
    past them)."""
    index = _index(assembly)
    k = index.ids[block]
    mask = np.zeros(len(assembly.blocks), dtype=bool)
    mask[[index.ids[b] for b in present]] = True
    mask[k] = False
    others = np.flatnonzero(mask)
    moving = assembly.blocks[k]
    limits = options.limits or ValidationLimits()
    allow = block_allowances(assembly, options.contact)
    return k, mask, PathCheck(moving, [assembly.blocks[j] for j in others],
                              approach_distance(options),
                              CLEARANCE * limits.penetration_tol * moving.size + allow[k],
                              index.boxes[others], allow[others])


def approach_length(assembly: Assembly, present: Sequence[str], block: str,
                    options: CheckOptions, direction) -> float:
    """m ``block`` travels along unit ``direction`` into its pose past ``present``, as its
    insertion check sweeps it (where a robot's straight approach starts)."""
    return _path(assembly, present, block, options)[2].length(np.asarray(direction, float))


def block_insertion(assembly: Assembly, present: Sequence[str], block: str,
                    options: CheckOptions, given=None) -> Insertion:
    """How ``block`` reaches its pose in ``assembly`` (the whole scene's) past the blocks
    ``present`` (it among them or not); ``given``: a direction to check instead of choosing."""
    k, mask, path = _path(assembly, present, block, options)
    angle = contact_angle_deg(options.contact.angle_tol_deg, options.contact.pose_uncertainty_deg)
    return insertion(interface_normals(assembly, k, mask), path,
                     np.asarray(assembly.gravity, dtype=float), given, np.radians(angle),
                     np.radians(options.insertion.approach_max_angle))
