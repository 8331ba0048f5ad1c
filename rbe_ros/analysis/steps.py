"""The steps of an insertion sequence: step k holds the supports, the blocks present before
the sequence starts, and the first k+1 blocks of the sequence; the scene's holds make blocks
supports (held) or take temporary supports away at given steps. The one place that says
which blocks are present at a step."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..rbe.model import Grip
from ..scene import Scene


@dataclass(frozen=True)
class Step:
    """One step of a sequence: the block placed and the blocks present and held."""

    index: int
    block: str                      # "" at the release step after the last placement
    present: tuple[str, ...]
    held: tuple[str, ...] = ()      # free blocks held at this step
    grips: tuple[Grip, ...] = ()    # the robots' grips of the held blocks


def step_state(scene: Scene, order, k: int) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(present, held) at step ``k`` when the free blocks are placed in ``order`` (those not
    in it are present from the start): supports without a hold always, supports with a hold
    while it is active, and the free blocks placed by step k, of which those with an active
    hold are held (in scene order)."""
    order = list(order)
    placed = set(order)
    active = {h.block for h in scene.holds if h.active(k)}
    supports = set(supports_present(scene, k))
    base = [b.id for b in scene.blocks
            if b.id in supports or (not b.support and b.id not in placed)]
    present = tuple(base + order[:k + 1])
    here = set(present)
    held = tuple(b.id for b in scene.blocks if not b.support and b.id in active and b.id in here)
    return present, held


def supports_present(scene: Scene, k: int) -> tuple[str, ...]:
    """The support blocks present at step ``k``: those without a hold always, those with a
    hold while it is active (scene order)."""
    active = {h.block for h in scene.holds if h.active(k)}
    with_hold = {h.block for h in scene.holds}
    return tuple(b.id for b in scene.blocks
                 if b.support and (b.id not in with_hold or b.id in active))


def step_grips(scene: Scene, k: int, held) -> tuple[Grip, ...]:
    """The grips of the blocks ``held`` at step ``k``, from their active holds: the grip
    point from the block frame to the world (None: the centroid, found when the model is
    built), the capacities as the hold gives them (None: the check's options)."""
    out = []
    for h in scene.holds:
        if h.block in held and h.active(k):
            point = None
            if h.grip is not None:
                b = scene.block(h.block)
                point = Rotation.from_quat(b.orientation).apply(np.asarray(h.grip)) + b.position
            out.append(Grip(h.block, point, h.max_force, h.max_torque))
            held = [b for b in held if b != h.block]     # one grip per block
    return tuple(out)


def gripped(assembly, present, held):
    """The step of ``assembly`` with the blocks ``present``, a robot's grip at the centroid
    of each block of ``held`` (the capacities: the check's options). The planner's holds."""
    return assembly.subset(present, held, tuple(Grip(b) for b in sorted(held)))


def _final_step(scene: Scene) -> tuple[list[str], int]:
    order = [b.id for b in scene.blocks if not b.support]
    return order, len(order) + 1


def final_state(scene: Scene) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(present, held) after the last step: every block placed, holds to the end active."""
    return step_state(scene, *_final_step(scene))


def final_grips(scene: Scene, held) -> tuple[Grip, ...]:
    """The grips of the blocks ``held`` after the last step (:func:`final_state`)."""
    return step_grips(scene, _final_step(scene)[1], held)


def sequence_steps(scene: Scene) -> list[Step]:
    """The steps of ``scene.sequence`` (all free blocks in scene order when it is empty),
    and a release step (nothing placed) when a hold ends after the last placement."""
    return [sequence_step(scene, k) for k in range(step_count(scene))]


def _order(scene: Scene) -> list[str]:
    return list(scene.sequence) or [b.id for b in scene.blocks if not b.support]


def last_block(scene: Scene) -> str:
    """The block placed last: the sequence's last, else the last free block in scene order
    (what a check of the whole assembly says the insertion of)."""
    order = _order(scene)
    return order[-1] if order else ""


def step_count(scene: Scene) -> int:
    """The number of :func:`sequence_steps` (without making them: each costs the scene's
    size, all of them its square)."""
    order = _order(scene)
    return len(order) + any(h.until_step == len(order) for h in scene.holds)


def sequence_step(scene: Scene, k: int) -> Step:
    """Step ``k`` of :func:`sequence_steps` alone."""
    order = _order(scene)
    present, held = step_state(scene, order, k)
    return Step(k, order[k] if k < len(order) else "", present, held,
                step_grips(scene, k, held))
