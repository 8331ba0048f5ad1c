"""Per-step checks of an insertion sequence: step k holds the supports, the blocks present
before the sequence starts, and the first k+1 blocks of the sequence."""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from ..rbe.result import Report
from ..scene import Scene
from .assembly import Assembly
from .check import CheckOptions, check


@dataclass(frozen=True)
class Step:
    index: int
    block: str
    present: tuple[str, ...]


def sequence_steps(scene: Scene) -> list[Step]:
    """The steps of ``scene.sequence`` (all free blocks in scene order when it is empty)."""
    free = [b.id for b in scene.blocks if not b.support]
    order = list(scene.sequence) or free
    placed = set(order)
    base = [b.id for b in scene.blocks if b.support or b.id not in placed]
    return [Step(k, bid, tuple(base + order[:k + 1])) for k, bid in enumerate(order)]


def check_sequence(scene: Scene, options: CheckOptions = CheckOptions(), *,
                   on_step: Callable[[Report, int], None] | None = None,
                   cancelled: Callable[[], bool] | None = None) -> list[Report]:
    """One report per step, in order. Contacts are detected once on the whole scene.

    ``on_step(report, total)`` is called after each step; when ``cancelled()`` turns true
    the reports so far are returned.
    """
    start = time.perf_counter()
    full = Assembly.from_scene(scene, options.contact)
    contact_time = time.perf_counter() - start
    steps = sequence_steps(scene)
    reports = []
    for step in steps:
        if cancelled is not None and cancelled():
            break
        report = check(full.subset(step.present), options)
        report.step_index, report.block_placed = step.index, step.block
        report.solve_time += contact_time / len(steps)
        reports.append(report)
        if on_step is not None:
            on_step(report, len(steps))
    return reports


def first_failing_step(reports: list[Report]) -> int:
    return next((r.step_index for r in reports if not r.stable), -1)
