"""The steps of a check in one place: validate, detect contacts, check the assembly or every
step of its sequence, suggest holds. :func:`check_state` is the one dispatch of a received
state, shared by ``rbe_node`` and replay, so that a replay reproduces what the node did."""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..deadline import CheckTimeout, stage, time_budget
from ..rbe.result import Report, Status
from ..scene import Scene, SceneError
from .asbuilt import declared, sensitivity
from .assembly import Assembly
from .holds import suggested_holds
from .incremental import StepChecker
from .insertion import block_insertion
from .margin import report_margin
from .options import CheckOptions
from .steps import final_grips, final_state, last_block, sequence_step, step_count
from .validate import validated_assembly
from .verdict import check


def check_scene(scene: Scene, options: CheckOptions = CheckOptions(),
                assembly: Assembly | None = None,
                on_verdict: Callable[[Report], None] | None = None) -> Report:
    """Check ``scene`` as a whole (contact detection included in the reported time);
    ``assembly``: its blocks on interfaces given instead of detected (a COMPAS file's).
    ``on_verdict(report)``: called with the report before the tolerance question is asked
    (the rest of the report is its answer: :func:`tolerance_asked`), for work that needs
    only the verdict and its forces (the node's look-ahead begins then).

    With holds, the assembly is the state after the last step: supports whose hold ends are
    taken away, free blocks held to the end are supports (``held_blocks``). An unstable
    report names the smallest set of blocks to hold (``suggested_holds``, see
    :class:`~rbe_ros.analysis.options.HoldSearch`). The whole check, geometry included, is
    bounded by the solve options' ``time_limit``: over it, the report is SOLVER_FAILED
    naming the stage (:func:`timeout_report`)."""
    start = time.perf_counter()
    options = declared(options, scene)
    try:
        with time_budget(options.solve.time_limit):
            whole = validated_assembly(scene, options.limits, options.contact, assembly)
            assembly, held = whole, ()
            if scene.holds:
                present, held = final_state(scene)
                assembly = whole.subset(present, held, final_grips(scene, held))
            with stage("solve"):
                raw = check(assembly, options)
            placed = Placed(whole, tuple(b.id for b in assembly.blocks), last_block(scene),
                            scene.approach_of(last_block(scene)))
            report = _completed(raw, assembly, held, options, placed,
                                tolerance=on_verdict is None)
            if on_verdict is not None:
                on_verdict(report)
                report = tolerance_asked(report, raw, assembly, options)
    except CheckTimeout as exc:
        report = timeout_report(exc)
    return replace(report, solve_time=time.perf_counter() - start)


def slim(report: Report) -> Report:
    """``report`` without its interfaces and near contacts: what a long sequence or plan
    keeps of each step, so that its memory grows with the steps, not with every interface
    of every partial assembly."""
    return replace(report, interfaces=(), near_contacts=())


def check_sequence(scene: Scene, options: CheckOptions = CheckOptions(), *,
                   on_step: Callable[[Report, int], None] | None = None,
                   cancelled: Callable[[], bool] | None = None,
                   keep: Callable[[Report], Report] | None = None) -> list[Report]:
    """One report per step, in order. Contacts are detected once on the whole scene.

    ``on_step(report, total)`` is called after each step with its whole report; the list
    returned holds ``keep(report)`` (e.g. :func:`slim`; default the whole report). When
    ``cancelled()`` turns true the reports so far are returned. The solve options'
    ``time_limit`` bounds each step, and the contact detection on the whole scene: a step
    over it is SOLVER_FAILED naming the stage, and the sequence goes on; contacts over it
    make every step's report SOLVER_FAILED.
    """
    start = time.perf_counter()
    options = declared(options, scene)
    total = step_count(scene)
    limit = options.solve.time_limit
    try:
        with time_budget(limit):
            full = validated_assembly(scene, options.limits, options.contact)
    except CheckTimeout as exc:
        full, geometry_timeout = None, exc
    contact_time = time.perf_counter() - start
    checker = StepChecker(options, local=not options.full_solve)
    reports = []
    for k in range(total):      # one step at a time: making them all costs the size squared
        if cancelled is not None and cancelled():
            break
        step = sequence_step(scene, k)
        step_start = time.perf_counter()
        try:
            if full is None:
                raise geometry_timeout
            assembly = full.subset(step.present, step.held, step.grips)
            with time_budget(limit):
                with stage("solve"):
                    report = checker.check(assembly)
                report = _completed(report, assembly, step.held, options,
                                    Placed(full, step.present, step.block,
                                           scene.approach_of(step.block)))
        except CheckTimeout as exc:
            report = replace(timeout_report(exc), num_blocks=len(step.present))
        # the step's time, with its share of the contact detection done once for all steps
        report = replace(report, step_index=step.index, block_placed=step.block,
                         solve_time=time.perf_counter() - step_start + contact_time / total)
        reports.append(report if keep is None else keep(report))
        if on_step is not None:
            on_step(report, total)
    return reports


@dataclass(frozen=True)
class Placed:
    """The block placed at a checked state, for its insertion: the whole scene's assembly
    (its interfaces with supports too), the blocks present, the block ("" none) and the
    scene's given approach of it (None: choose one)."""

    whole: Assembly
    present: tuple[str, ...]
    block: str
    approach: np.ndarray | None = None


def insertion_fields(placed: Placed | None, options: CheckOptions) -> dict:
    """The report fields of the placed block's insertion (none when not checked)."""
    if placed is None or not placed.block or not options.insertion.enabled:
        return {}
    found = block_insertion(placed.whole, placed.present, placed.block, options,
                            placed.approach)
    return {"insertable": found.insertable, "insertion_direction": found.direction,
            "insertion_reason": found.reason}


def _completed(report: Report, assembly: Assembly, held, options: CheckOptions,
               placed: Placed | None = None, *, tolerance: bool = True) -> Report:
    """The verdict of ``assembly`` completed in one place, each part in its stage of the
    time budget: the near contacts and whether the verdict is sensitive to the contact
    tolerance (why, in the message; ``tolerance`` False: not asked, one or two solves saved
    for a state not built yet), the blocks held, the suggested holds, the margin, and from
    where the placed block can arrive (a block that cannot: why, in the message)."""
    with stage("sensitivity"):
        near, sensitive = sensitivity(report, assembly, options) if tolerance else ((), "")
    with stage("hold search"):
        suggested = suggested_holds(report, assembly, options)
    with stage("margin"):
        found = report_margin(report, assembly, options.deciding, options.margin_directions)
    extra = {} if found is None else {"margin_g": found.margin_g,
                                      "margin_direction": found.direction}
    with stage("insertion"):
        extra.update(insertion_fields(placed, options))
    why = extra.pop("insertion_reason", "")
    return replace(report, near_contacts=near, verdict_sensitive=bool(sensitive),
                   message=report.message + _sensitive(sensitive)
                   + ("" if extra.get("insertable", True)
                      else f" | not insertable: {placed.block}: {why}"),
                   held_blocks=tuple(held), suggested_holds=suggested, **extra)


def _sensitive(why: str) -> str:
    """The message's part saying why a verdict is sensitive to the contact tolerance."""
    return f" | sensitive: {why}" if why else ""


def tolerance_asked(completed: Report, report: Report, assembly: Assembly,
                    options: CheckOptions) -> Report:
    """``completed`` (:func:`_completed` of ``report``, the check of ``assembly``, with
    ``tolerance`` False) as :func:`_completed` makes it with the tolerance question: asked
    now, after other work that was wanted first."""
    with stage("sensitivity"):
        near, sensitive = sensitivity(report, assembly, options)
    cut = len(report.message)
    return replace(completed, near_contacts=near, verdict_sensitive=bool(sensitive),
                   message=completed.message[:cut] + _sensitive(sensitive)
                   + completed.message[cut:])


def first_failing_step(reports: list[Report]) -> int:
    """The step index of the first report that is not stable; -1 when all are."""
    return next((r.step_index for r in reports if not r.stable), -1)


def timeout_report(exc: CheckTimeout) -> Report:
    """The report of a check stopped at its time limit."""
    return Report(Status.SOLVER_FAILED, f"solver failed: {exc}")


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
                cancelled: Callable[[], bool] | None = None,
                on_verdict: Callable[[Report], None] | None = None) -> StateCheck:
    """Check one received state; never raises.

    ``read_scene(sequence)`` makes the scene of the state (with its sequence, or without it
    for a check of the whole assembly); ``sequence``: check every step, else the whole.
    ``on_step(report, scene, total)`` is called for each report of the check as soon as it
    is made; ``on_verdict``: a whole check's, as :func:`check_scene`'s. A state that cannot
    be read or checked ends with :func:`error_report` (in ``reports`` and ``error``, not
    passed to ``on_step``)."""
    reports: list[Report] = []
    scene = None
    total = 0

    def step(report: Report, _total: int) -> None:
        reports.append(report)
        if on_step is not None:
            on_step(report, scene, total)

    try:
        scene = read_scene(sequence)
        total = step_count(scene) if sequence else 1
        if sequence:
            check_sequence(scene, options, on_step=step, cancelled=cancelled)
        else:
            step(check_scene(scene, options, on_verdict=on_verdict), 1)
    except Exception as exc:        # a failed check is a report, never a crash
        error = error_report(exc)
        return StateCheck([*reports, error], scene, total, error)
    return StateCheck(reports, scene, total)
