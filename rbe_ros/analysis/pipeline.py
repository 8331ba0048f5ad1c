"""The steps of a check in one place: validate, detect contacts, check the assembly or every
step of its sequence, suggest holds. :func:`check_state` is the one dispatch of a received
state, shared by ``rbe_node`` and replay, so that a replay reproduces what the node did."""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace

from ..rbe.result import Report, Status
from ..scene import Scene, SceneError
from .asbuilt import declared, sensitivity
from .assembly import Assembly
from .holds import suggested_holds
from .incremental import StepChecker
from .options import CheckOptions
from .steps import final_state, sequence_steps
from .validate import validated_assembly
from .verdict import check


def check_scene(scene: Scene, options: CheckOptions = CheckOptions(),
                assembly: Assembly | None = None) -> Report:
    """Check ``scene`` as a whole (contact detection included in the reported time);
    ``assembly``: its blocks on interfaces given instead of detected (a COMPAS file's).

    With holds, the assembly is the state after the last step: supports whose hold ends are
    taken away, free blocks held to the end are supports (``held_blocks``). An unstable
    report names the smallest set of blocks to hold (``suggested_holds``, see
    :class:`~rbe_ros.analysis.options.HoldSearch`)."""
    start = time.perf_counter()
    options = declared(options, scene)
    assembly = validated_assembly(scene, options.limits, options.contact, assembly)
    held: tuple[str, ...] = ()
    if scene.holds:
        present, held = final_state(scene)
        assembly = assembly.subset(present, held)
    return _finished(check(assembly, options), assembly, held, options, start)


def check_sequence(scene: Scene, options: CheckOptions = CheckOptions(), *,
                   on_step: Callable[[Report, int], None] | None = None,
                   cancelled: Callable[[], bool] | None = None) -> list[Report]:
    """One report per step, in order. Contacts are detected once on the whole scene.

    ``on_step(report, total)`` is called after each step; when ``cancelled()`` turns true
    the reports so far are returned.
    """
    start = time.perf_counter()
    options = declared(options, scene)
    full = validated_assembly(scene, options.limits, options.contact)
    contact_time = time.perf_counter() - start
    steps = sequence_steps(scene)
    checker = StepChecker(options, local=not options.full_solve)
    reports = []
    for step in steps:
        if cancelled is not None and cancelled():
            break
        step_start = time.perf_counter() - contact_time / len(steps)
        assembly = full.subset(step.present, step.held)
        report = _finished(checker.check(assembly), assembly, step.held, options, step_start,
                           step_index=step.index, block_placed=step.block)
        reports.append(report)
        if on_step is not None:
            on_step(report, len(steps))
    return reports


def _finished(report: Report, assembly: Assembly, held, options: CheckOptions, start: float,
              **step) -> Report:
    """The report as the pipeline gives it: the near contacts and whether the verdict is
    sensitive to the contact tolerance (why, in the message), the blocks held, the
    suggested holds, the step (``step_index``, ``block_placed``) and the time since
    ``start``, the one place where a check's time is taken."""
    near, sensitive = sensitivity(report, assembly, options)
    message = report.message + (f" | sensitive: {sensitive}" if sensitive else "")
    suggested = suggested_holds(report, assembly, options)
    return replace(report, message=message, near_contacts=near,
                   verdict_sensitive=bool(sensitive), held_blocks=tuple(held),
                   suggested_holds=suggested, solve_time=time.perf_counter() - start, **step)


def first_failing_step(reports: list[Report]) -> int:
    """The step index of the first report that is not stable; -1 when all are."""
    return next((r.step_index for r in reports if not r.stable), -1)


def error_report(exc: Exception) -> Report:
    """The report of a state that could not be checked: INVALID_INPUT naming the problem
    for bad input, SOLVER_FAILED with the exception for anything else."""
    if isinstance(exc, SceneError):
        return Report(Status.INVALID_INPUT, f"invalid input: {exc}")
    return Report(Status.SOLVER_FAILED, f"check failed: {type(exc).__name__}: {exc}")


@dataclass(frozen=True)
class StateCheck:
    """What :func:`check_state` made of one state."""

    reports: list[Report]       # in order; a failure's report last
    scene: Scene | None          # None: the state could not be read
    total: int                   # reports of the complete check (steps; 1 for the whole)
    error: Report | None = None  # the report of a state that could not be checked

    @property
    def finished(self) -> bool:
        """Every report of the check made (not cancelled, no error)."""
        return self.error is None and len(self.reports) == self.total


def check_state(read_scene: Callable[[bool], Scene], sequence: bool,
                options: CheckOptions = CheckOptions(), *,
                on_step: Callable[[Report, Scene, int], None] | None = None,
                cancelled: Callable[[], bool] | None = None) -> StateCheck:
    """Check one received state; never raises.

    ``read_scene(sequence)`` makes the scene of the state (with its sequence, or without it
    for a check of the whole assembly); ``sequence``: check every step, else the whole.
    ``on_step(report, scene, total)`` is called for each report of the check as soon as it
    is made. A state that cannot be read or checked ends with :func:`error_report` (in
    ``reports`` and ``error``, not passed to ``on_step``)."""
    reports: list[Report] = []
    scene = None
    total = 0

    def step(report: Report, _total: int) -> None:
        reports.append(report)
        if on_step is not None:
            on_step(report, scene, total)

    try:
        scene = read_scene(sequence)
        total = len(sequence_steps(scene)) if sequence else 1
        if sequence:
            check_sequence(scene, options, on_step=step, cancelled=cancelled)
        else:
            step(check_scene(scene, options), 1)
    except Exception as exc:        # a failed check is a report, never a crash
        error = error_report(exc)
        return StateCheck([*reports, error], scene, total, error)
    return StateCheck(reports, scene, total)
