"""Per-step checks of an insertion sequence: step k holds the supports, the blocks present
before the sequence starts, and the first k+1 blocks of the sequence; the scene's holds make
blocks supports (held) or take temporary supports away at given steps."""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from ..rbe.result import Report
from ..scene import Scene
from .check import CheckOptions
from .validate import validated_assembly
from .holds import annotate_holds
from .margin import annotate_margin
from .incremental import StepChecker


@dataclass(frozen=True)
class Step:
    index: int
    block: str                      # "" at the release step after the last placement
    present: tuple[str, ...]
    held: tuple[str, ...] = ()      # free blocks checked as supports at this step


def step_state(scene: Scene, order, k: int) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(present, held) at step ``k`` when the free blocks are placed in ``order`` (those not
    in it are present from the start): supports without a hold always, supports with a hold
    while it is active, and the free blocks placed by step k, of which those with an active
    hold are held (in scene order)."""
    order = list(order)
    placed = set(order)
    active = {h.block for h in scene.holds if h.active(k)}
    with_hold = {h.block for h in scene.holds}
    base = [b.id for b in scene.blocks
            if (b.support and (b.id not in with_hold or b.id in active))
            or (not b.support and b.id not in placed)]
    present = tuple(base + order[:k + 1])
    here = set(present)
    held = tuple(b.id for b in scene.blocks if not b.support and b.id in active and b.id in here)
    return present, held


def final_state(scene: Scene) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(present, held) after the last step: every block placed, holds to the end active."""
    order = [b.id for b in scene.blocks if not b.support]
    return step_state(scene, order, len(order) + 1)


def sequence_steps(scene: Scene) -> list[Step]:
    """The steps of ``scene.sequence`` (all free blocks in scene order when it is empty),
    and a release step (nothing placed) when a hold ends after the last placement."""
    free = [b.id for b in scene.blocks if not b.support]
    order = list(scene.sequence) or free
    release = any(h.until_step == len(order) for h in scene.holds)
    return [Step(k, order[k] if k < len(order) else "", *step_state(scene, order, k))
            for k in range(len(order) + release)]


def check_sequence(scene: Scene, options: CheckOptions = CheckOptions(), *,
                   on_step: Callable[[Report, int], None] | None = None,
                   cancelled: Callable[[], bool] | None = None) -> list[Report]:
    """One report per step, in order. Contacts are detected once on the whole scene.

    ``on_step(report, total)`` is called after each step; when ``cancelled()`` turns true
    the reports so far are returned.
    """
    start = time.perf_counter()
    full = validated_assembly(scene, options.limits, options.contact)
    contact_time = time.perf_counter() - start
    steps = sequence_steps(scene)
    checker = StepChecker(options, local=not options.full_solve)
    reports = []
    for step in steps:
        if cancelled is not None and cancelled():
            break
        assembly = full.subset(step.present, step.held)
        report = checker.check(assembly)
        report.step_index, report.block_placed = step.index, step.block
        annotate_holds(report, assembly, step.held, options)
        annotate_margin(report, assembly, options.solve, options.margin_directions)
        report.solve_time += contact_time / len(steps)
        reports.append(report)
        if on_step is not None:
            on_step(report, len(steps))
    return reports


def first_failing_step(reports: list[Report]) -> int:
    return next((r.step_index for r in reports if not r.stable), -1)
