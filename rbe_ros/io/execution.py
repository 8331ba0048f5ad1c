"""Executing a plan from measured poses: the node's (``~/execution``, ``~/plan_update``) and
the replay's one definition of what a design or a pose message means for the plan.

The plan is a planned scene (the design with a sequence and holds: ``design_file``, or a
design sent with a sequence on ``~/design``). After each as-built state the node checked,
:meth:`Execution.advance` looks ahead (:func:`rbe_ros.analysis.lookahead.look_ahead`: the
placed blocks, a prefix of the plan's order, at their measured poses, the next
``lookahead_steps`` steps with the rest at design) step by step and sends in stages, what
the robot needs first first: the ExecutionState at the first step that fails (its
look-ahead the steps up to it), then the repair of that step
(:func:`rbe_ros.analysis.repair.repair_plan` with a window that ends there, in the node a
process of its own), then the look-ahead of the repaired plan over the whole window, which
repairs again at a later failing step the same way. The node begins as it checks the
as-built state (:class:`NodeReport`): the look-ahead solves the first step ahead while the
node solves the state, takes the state's verdict as its check of it, and begins the repair
of a failing step while the node asks the state's tolerance question; the ExecutionState
goes out with ~/report's answer, its outputs those of an execution given the finished
report (the replay's). Poses that do not fit the plan (a block
out of the plan's order, a block not in the design, a design that is not the plan's) make
the state inactive with the reason, the step reached and its look-ahead kept.

A plan for a robot cell (a ``~/plan`` goal with a cell, a planned scene that ``rbe-ros plan
--cell -o`` wrote) is executed as its timeline: each step ahead also checks the states
between the robots' actions at the measured poses, a repair keeps within the cell and its
PlanUpdate carries the repaired timeline (:mod:`rbe_ros.analysis.cell_execution`); not in
stages: its look-ahead covers the window before it goes out, its repair the window (a cell's
repair re-plans for the cell when a state between actions falls, over the steps it covers);
:attr:`Execution.timeline` is the timeline at the last as-built state, for its markers.
"""
from __future__ import annotations

import collections
import functools
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace

from ..analysis.cell_execution import CellPlan, repair_cell
from ..analysis.lookahead import (DEFAULT_LOOKAHEAD, Checked, Given, approaches,
                                  as_built_state, check_plan_design, look_ahead, placed_count)
from ..analysis.options import CheckOptions
from ..analysis.repair import Repair, repair_plan
from ..analysis.timeline import Timeline
from ..cell import Cell
from ..scene import Scene, SceneError
from ..rbe.result import Report
from .messages import (execution_to_dict, lookahead_step_to_dict, plan_update_to_dict,
                       report_from_dict, report_to_dict, timeline_to_dicts)

#: The node's parameter defaults (and a bag's recorded before them).
LOOKAHEAD_STEPS = DEFAULT_LOOKAHEAD
MIN_MARGIN_G = 0.0
#: Kinds of output of one as-built state, in order: an ExecutionState, a PlanUpdate.
EXECUTION, PLAN_UPDATE = "execution", "plan_update"


@dataclass(frozen=True)
class Settings:
    """The node's execution parameters (recorded with its settings for replay)."""

    lookahead_steps: int = LOOKAHEAD_STEPS
    min_margin_g: float = MIN_MARGIN_G

    @classmethod
    def of(cls, recorded: dict | None) -> "Settings":
        recorded = recorded or {}
        return cls(int(recorded.get("lookahead_steps", LOOKAHEAD_STEPS)),
                   float(recorded.get("min_margin_g", MIN_MARGIN_G)))


#: How a repair is made: ``repair(plan, built, options, settings, cell, checked)`` -> the
#: repair and, for a cell, the repaired plan's timeline.
Repairer = Callable[[Scene, Scene, CheckOptions, Settings, Cell | None, Checked | None],
                    tuple[Repair, Timeline | None]]


def repair(plan: Scene, built: Scene, options: CheckOptions, settings: Settings,
           cell: Cell | None = None, checked: Checked | None = None
           ) -> tuple[Repair, Timeline | None]:
    """The core's repair with the node's settings: within its look-ahead window, its
    minimum margin, the plan's cell, the states its look-ahead ``checked`` not checked
    again (a function of its own: the node runs it in another process)."""
    if cell is not None:
        return repair_cell(plan, built, options, CellPlan(cell, plan, options),
                           min_margin_g=settings.min_margin_g,
                           lookahead_steps=settings.lookahead_steps, checked=checked)
    return repair_plan(plan, built, options, min_margin_g=settings.min_margin_g,
                       lookahead_steps=settings.lookahead_steps, checked=checked), None


def planned_note(scene: Scene, report: Report) -> str:
    """What ~/report adds to the message of its check of an as-built state under a plan
    (``scene``: :meth:`Execution.holding`'s, with the plan's holds): the step and the blocks
    held."""
    held = ", ".join(report.held_blocks) or "nothing"
    return f" | as the plan has it at step {len(scene.sequence) - 1}: held {held}"


NO_PLAN = "no plan: set design_file to a planned scene, or send a design with a sequence"


class NodeReport:
    """~/report of an as-built state while the node makes it (on its check thread), for
    the execution that begins with it: the check's report before the tolerance question
    is asked (:func:`rbe_ros.io.replay.asbuilt_check`'s ``on_verdict``), then the report
    sent, each a report dict (None: no report) made when the execution first needs it (a
    node without a plan converts no report: its interfaces may number thousands) and
    waited for until then. Whoever makes it calls :meth:`send` whatever happens (a
    ``finally``): the execution never waits for ever."""

    def __init__(self) -> None:
        self._verdict: Future = Future()
        self._sent: Future = Future()

    @classmethod
    def made(cls, report: dict | None) -> "NodeReport":
        """A report made before (a replay's, or none)."""
        made = cls()
        made._send(lambda: report)
        return made

    @staticmethod
    def _of(report: Report | None, header: dict) -> Callable[[], dict | None]:
        return functools.cache(lambda: None if report is None else
                               report_to_dict(report, header))

    def decide(self, report: Report | None, header: dict) -> None:
        """The check's report, its tolerance question not asked yet."""
        if not self._verdict.done():
            self._verdict.set_result(self._of(report, header))

    def send(self, report: Report | None, header: dict) -> None:
        """The report sent (its verdict too, if not given before)."""
        self._send(self._of(report, header))

    def _send(self, made: Callable[[], dict | None]) -> None:
        if not self._verdict.done():
            self._verdict.set_result(made)
        self._sent.set_result(made)

    @property
    def waiting(self) -> bool:
        """Whether the check's report is still being made."""
        return not self._verdict.done()

    def verdict(self) -> dict | None:
        return self._verdict.result()()

    def sent(self) -> dict | None:
        return self._sent.result()()

    def slim(self) -> dict | None:
        """The report sent, as the outputs carry it (its interfaces are ~/report's)."""
        sent = self.sent()
        return None if sent is None else {**sent, "interfaces": [], "near_contacts": []}


class Execution:
    """The plan under execution and what the last as-built state made of it."""

    def __init__(self) -> None:
        self.plan: Scene | None = None
        self.cell: Cell | None = None       # the plan's robot cell (None: K holds)
        self._cell_plan: CellPlan | None = None
        #: a cell's plan: its timeline at the last as-built state (RobotAction dicts) and
        #: the index of the last action done (-1: none)
        self.timeline: list[dict] = []
        self.timeline_done = -1
        self.error = NO_PLAN
        self.last: dict | None = None       # the last ExecutionState of accepted poses
        # (as-built scene, plan, settings, options) of the last outputs
        self._seen: tuple = ()
        self._outputs: list[tuple[str, dict]] = []
        self._repaired = None               # the as-built scene a repair was last tried at
        #: the last few (built, plan, holding(built)): the node checks the next state while
        #: the execution advances one it checked before
        self._held: collections.deque = collections.deque(maxlen=4)
        self._checked: Checked | None = None  # the states the last look-ahead checked

    def set_design(self, design: Scene | None, cell: Cell | None = None) -> None:
        """A new design: its sequence (and holds) is the plan, for ``cell``'s robots when
        given; a design without one keeps the plan held (and its cell) if it is a plan of the
        design, else says why not."""
        self.timeline, self.timeline_done = [], -1
        if design is None:
            self.plan, self.error = None, "no plan: the design is invalid"
        elif design.sequence:
            self.plan, self.error = design, ""
            self.cell, self._cell_plan = cell, None
        elif self.plan is not None:
            try:
                check_plan_design(self.plan, design)
                self.error = ""
            except SceneError as exc:
                self.error = str(exc)
        self.last, self._seen, self._repaired = None, (), None

    @property
    def idle(self) -> bool:
        """Whether no plan was ever given: a state means nothing for one (a node that only
        checks says nothing on ~/execution)."""
        return self.plan is None and self.error == NO_PLAN

    def holding(self, built: Scene | SceneError) -> Scene | SceneError:
        """The as-built scene ``built`` as ~/report checks it: with the holds the plan under
        execution has at its step (:func:`rbe_ros.analysis.lookahead.as_built_state`, the
        state of ExecutionState's ``as_built``); ``built`` itself without a plan, with
        nothing placed, or with poses that do not fit the plan (~/execution says why). The
        same scene object for the same ``built`` and plan (a state is checked once)."""
        plan = self.plan
        if plan is None or self.error or isinstance(built, SceneError):
            return built
        held = self._held_of(built, plan)
        if held is not None:
            return held
        try:
            held = as_built_state(plan, built)
        except SceneError:
            held = built
        self._held.append((built, plan, held))
        return held

    def _held_of(self, built: Scene, plan: Scene) -> Scene | None:
        """:meth:`holding`'s scene of ``built`` under ``plan`` if it made one lately (of a
        copy: the node's check thread appends while its execution thread reads)."""
        return next((h for b, p, h in tuple(self._held) if b is built and p is plan), None)

    def advance(self, built: Scene | SceneError, as_built: dict | NodeReport | None,
                header: dict, options: CheckOptions, settings: Settings,
                repairer: Repairer = repair,
                on_output: Callable[[str, dict], None] | None = None
                ) -> list[tuple[str, dict]]:
        """The outputs of one as-built state (``built``, or why the poses were refused;
        ``as_built``: the node's report of it, with its interfaces: of :meth:`holding`'s
        state, the look-ahead checks it not again; a :class:`NodeReport` while the node
        makes it): an ExecutionState, and when a step ahead fails a PlanUpdate and the
        ExecutionState of the repaired plan, again while a later step of the window fails
        (in stages: see the module docstring); each passed to ``on_output(kind, message)``
        as soon as it is made (the failing step goes out before the repair's plan; the
        repair begins as the step fails, beside the rest of the ExecutionState's work).
        The same state again gives its last ExecutionState with the new header (a cell
        sends the same poses at 10 Hz: a PlanUpdate is an event, sent once per repair);
        nothing while no plan was ever given (a node that only checks says nothing on
        ~/execution); never raises."""
        out: list[tuple[str, dict]] = []

        def emit(kind: str, message: dict) -> None:
            out.append((kind, message))
            if on_output is not None:
                on_output(kind, message)

        if self.idle:
            return out
        seen = (built, self.plan, settings, options)
        if self._seen and all(a is b or a == b for a, b in zip(self._seen[2:], seen[2:])) \
                and self._seen[0] is built and self._seen[1] is self.plan:
            last = next((m for k, m in reversed(self._outputs) if k == EXECUTION), None)
            if last is not None:
                emit(EXECUTION, {**last, "header": header})
            return out
        report = as_built if isinstance(as_built, NodeReport) else NodeReport.made(as_built)
        try:
            self._advance(built, report, header, options, settings, repairer, emit)
        except Exception as exc:        # an answer, never a crash
            emit(EXECUTION, self._refused(header, report.slim(),
                                          f"execution failed: {type(exc).__name__}: {exc}"))
        # the plan a repair made is the one the same state again finds: its state again
        self._seen, self._outputs = (built, self.plan, settings, options), out
        return out

    def _refused(self, header: dict, as_built: dict | None, why: str) -> dict:
        """The last accepted state (its step and look-ahead), inactive, with the reason."""
        kept = self.last or execution_to_dict(
            header, active=False, current_step=0,
            total_steps=len(self.plan.sequence) if self.plan is not None else 0,
            as_built=as_built, lookahead=[], first_failing_step=-1, message="")
        return {**kept, "header": header, "active": False, "message": why,
                **({"as_built": as_built} if as_built is not None else {})}

    def _known(self, built: Scene | SceneError, as_built: dict | None) -> Report | None:
        """The node's report ``as_built`` as the look-ahead's check of the as-built state
        makes it (the note of the plan's step taken off) when it is of :meth:`holding`'s
        state of ``built`` under the plan now (not one a repair has replaced since); else
        None (the look-ahead checks the state)."""
        held = self._held_of(built, self.plan)
        if as_built is None or held is None:
            return None
        report = report_from_dict(as_built)
        note = planned_note(held, report) if held.holds else ""
        if not report.message.endswith(note):
            return None
        return replace(report, message=report.message[:len(report.message) - len(note)])

    def _advance(self, built, report: NodeReport, header, options, settings, repairer,
                 emit) -> None:
        if self.plan is None or self.error:
            return emit(EXECUTION, self._refused(header, report.slim(), self.error))
        if isinstance(built, SceneError):
            return emit(EXECUTION, self._refused(header, report.slim(),
                                                 f"poses not accepted: {built}"))
        # a plan of K holds is executed in stages: the look-ahead goes out at the first
        # failing step and its repair right after it (a cell's repair keeps to the window)
        staged = self.cell is None
        # the node's report as the look-ahead takes it, part by part as the node makes it
        given = Given(lambda: self._known(built, report.verdict()),
                      lambda: self._known(built, report.sent()), report.waiting)
        tried, failing, checked = self._repaired is built, -1, None
        begun: list[Future] = []        # the repair of this round's failing step

        def window(step: int) -> Settings:
            # staged, the repair's window ends at the failing step (the look-ahead of the
            # repaired plan checks the rest, and repairs again from a later failing step);
            # a cell's repair keeps to the look-ahead's
            return replace(settings, lookahead_steps=step + 1 - placed_count(
                self.plan, built)) if staged else settings

        def begin(step: int, handed: Checked) -> None:
            # the repair begun as the step fails (the ExecutionState still waits for the
            # as-built state's tolerance question), the look-ahead's states handed over:
            # it checks none of them again
            if step > failing:
                begun.append(beside.submit(repairer, self.plan, built, options,
                                           window(step), None, handed))

        with ThreadPoolExecutor(1) as beside:
            while True:
                begun.clear()
                try:
                    state = self._state(built, report.slim, header, options, settings,
                                        checked, until_failure=staged,
                                        known=given if checked is None else None,
                                        on_failing=begin if staged and not tried else None)
                except SceneError as exc:       # out of the plan's order, not of the plan
                    return emit(EXECUTION, self._refused(header, report.slim(), str(exc)))
                emit(EXECUTION, state)
                # each round's repair makes the steps up to its failing one pass: the next
                # failing step is later, or the loop ends (bounded by the window)
                if state["first_failing_step"] <= failing or tried or (
                        checked is not None and not staged):
                    return None
                failing = state["first_failing_step"]
                self._repaired = built          # tried once per as-built state
                found, timeline = begun[0].result() if begun else repairer(
                    self.plan, built, options, window(failing), self.cell, self._checked)
                emit(PLAN_UPDATE, plan_update_to_dict(
                    header, reason=found.reason or state["message"],
                    changed_step=found.changed_step, feasible=found.feasible,
                    repair=found.kind, order=found.order, holds=found.holds,
                    message=found.message, timeline=timeline_to_dicts(timeline, header)))
                if not (found.feasible and found.changed):
                    return None
                # a block's approach stays its own when the repair reorders the steps
                self.plan = replace(self.plan, sequence=tuple(found.order),
                                    holds=tuple(found.holds),
                                    approach=approaches(self.plan, found.order))
                # the repair's states (the look-ahead's with them) not checked again; one
                # begun before the as-built state's tolerance question was answered hands
                # back that state's report without the answer, the look-ahead's has it
                checked = found.checked.answered(self._checked) if begun else found.checked

    def _cell(self, options: CheckOptions) -> CellPlan | None:
        """The plan's cell with its design's assembly (made again for other contact
        options)."""
        if self.cell is None:
            return None
        if self._cell_plan is None or self._cell_plan.contact != options.contact:
            self._cell_plan = CellPlan(self.cell, self.plan, options)
        return self._cell_plan

    def _state(self, built: Scene, as_built: Callable[[], dict | None], header, options,
               settings, checked: Checked | None = None, until_failure: bool = False,
               known: Given | None = None,
               on_failing: Callable[[int, Checked], None] | None = None) -> dict:
        ahead = look_ahead(self.plan, built, options, lookahead_steps=settings.lookahead_steps,
                           min_margin_g=settings.min_margin_g, cell=self._cell(options),
                           until_failure=until_failure, checked=checked, as_built=known,
                           on_failing=on_failing)
        self._checked = ahead.checked
        if ahead.timeline is not None:
            self.timeline = timeline_to_dicts(ahead.timeline, header)
            self.timeline_done = max((i for i, a in enumerate(ahead.timeline.actions)
                                      if a.step < ahead.current_step), default=-1)
        self.last = execution_to_dict(
            header, active=True, current_step=ahead.current_step,
            total_steps=ahead.total_steps,
            # the as-built state with the plan's holds at its step (nothing placed: the
            # node's check of the supports)
            as_built=report_to_dict(ahead.as_built, header) if ahead.as_built is not None
            else as_built(), lookahead=[lookahead_step_to_dict(s) for s in ahead.steps],
            first_failing_step=ahead.first_failing_step, message=ahead.message)
        return self.last


__all__ = ["EXECUTION", "Execution", "LOOKAHEAD_STEPS", "MIN_MARGIN_G", "NO_PLAN",
           "NodeReport", "PLAN_UPDATE", "Repairer", "Settings", "planned_note", "repair"]
