"""A cell's plan under execution: the states between its robots' actions at the measured
poses.

A plan for a cell (an order and holds by step) has one timeline, the planner's
(:func:`rbe_ros.analysis.timeline.plan_actions` over the design's finished assembly): the
timeline ``rbe-ros plan --cell`` exported, and that of a repaired order made the same way,
the steps done keeping their robots and grips. While the plan is built, a robot grips a
placed block where it landed: each grip moves with its block to the measured pose. A step
ahead passes the look-ahead when, beyond its own check (:class:`rbe_ros.analysis.lookahead.
StepRunner`), a free robot can do each of its actions and the state after each stands at the
measured poses with the robots' grips and payloads, the hand-over state after a release (the
step's block absent) included, as the planner checked them at design.

A repair (:func:`repair_cell`) is :func:`rbe_ros.analysis.repair.repair_plan`'s within the
cell's K (its robots less the one that places); its timeline is then checked the same way;
when a state of it falls, the remainder is planned again for the cell (the planner checks
the states between actions) and checked so.
"""
from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from ..cell import Cell
from ..rbe.model import Grip
from ..rbe.result import Report
from ..scene import Scene, make_scene
from .assembly import Assembly
from .grips import GripFrame, robot_grip
from .lookahead import (Checked, StepAhead, StepRunner, held_by_step, plan_order,
                        state_key, where, with_plan)
from .options import CheckOptions
from .planning import plan_sequence
from .repair import Repair, repair_plan
from .steps import sequence_step, step_count
from .timeline import (Action, Busy, CellSteps, StateChecks, Timeline, action_present,
                       check_action, plan_actions, scene_with_grips, state_fell)


#: Seconds a re-plan of the remainder for a cell may take.
REPLAN_TIME_LIMIT = 60.0


class CellPlan:
    """A cell and the design its plans are for: the timeline of any order of its blocks,
    derived as the planner derives it (grip choices kept across orders)."""

    def __init__(self, cell: Cell, design: Scene, options: CheckOptions):
        supports = {b.id for b in design.blocks if b.support}
        self.cell, self.contact = cell, options.contact
        # as the planner has it: no sequence, the holds of supports (scaffolds) only
        self.base = make_scene(design.name, design.blocks, design.gravity, (),
                               [h for h in design.holds if h.block in supports])
        self.assembly = Assembly.from_scene(self.base, options.contact)
        self.steps = CellSteps(cell, self.assembly)
        self._actions: dict[tuple, tuple[list[Action], str, int]] = {}

    def actions(self, plan: Scene) -> tuple[list[Action], str, int]:
        """The actions of ``plan`` (a scene over the design's blocks: sequence and holds),
        unchecked, and why no robot can do step k and k ("" and -1 when every step can be
        done)."""
        order = tuple(plan_order(plan))
        held = tuple(held_by_step(plan))
        key = (order, held)
        found = self._actions.get(key)
        if found is None:
            found = self._actions[key] = plan_actions(self.steps, self.base, order, held)
        return found

    def ahead(self, runner: StepRunner) -> "CellAhead":
        """The cell's checks at the as-built state of ``runner``."""
        return CellAhead(self, runner)


class CellAhead:
    """The cell's checks of a plan's steps at one as-built state (the scene and options of a
    :class:`StepRunner`): each state after an action once."""

    def __init__(self, plan: CellPlan, runner: StepRunner):
        self.plan = plan
        self.states = StateChecks(plan.cell, runner.full, plan.base, runner.options)
        self.memo = runner.memo
        design = {b.id: b for b in plan.base.blocks}
        # block -> (rotation, design position, measured position) of the blocks moved
        self.moves: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        for b in runner.scene.blocks:
            d = design[b.id]
            if not (np.allclose(b.position, d.position, atol=1e-12)
                    and np.allclose(b.orientation, d.orientation, atol=1e-12)):
                turn = Rotation.from_quat(b.orientation) * Rotation.from_quat(d.orientation).inv()
                self.moves[b.id] = (turn.as_matrix(), d.position, b.position)

    def grip(self, g: GripFrame) -> GripFrame:
        """``g`` moved with its block to the block's measured pose."""
        move = self.moves.get(g.block)
        if move is None:
            return g
        turn, before, after = move
        return GripFrame(g.block, g.face, turn @ (g.point - before) + after, turn @ g.rotation,
                         turn @ g.normal)

    def moved(self, a: Action) -> Action:
        """``a`` with every grip moved with its block."""
        return replace(a, grip=self.grip(a.grip),
                       busy=tuple((b, Busy(h.robot, self.grip(h.grip))) for b, h in a.busy))

    def known(self, plan: Scene, a: Action) -> tuple[Report | None, bool]:
        """The check the step runner made of a step state of ``plan`` with the blocks present
        after ``a`` and a subset of its holds at the same grips (None: none such), and
        whether it is the same state. A state that stands stands with more held: a hold may
        apply nothing; so the state after a robot places (before it lets go) and after a
        robot takes a placed block are known from the step states, a hand-over is not."""
        k = a.step - 1 if a.before else a.step
        if k < 0 or k >= step_count(plan):
            return None, False
        step = sequence_step(plan, k)
        report = self.memo.get(state_key(plan, step))
        if report is None or set(step.present) != set(
                action_present(self.plan.base, plan.sequence, a)):
            return None, False
        busy = {b: robot_grip(h.grip, self.plan.cell.robot(h.robot)) for b, h in a.busy}
        given = {g.block: g for g in step.grips}
        if not all(b in busy and _same_grip(busy[b], given.get(b)) for b in step.held):
            return None, False
        return report, set(busy) == set(step.held)

    def __call__(self, plan: Scene, step: StepAhead) -> StepAhead:
        """``step`` of ``plan`` with the cell's checks of it: it fails when no free robot can
        do it or the state after one of its actions falls (the first, named; a state known
        to stand from the step states is not checked again); its largest hold force over
        those states."""
        actions, error, failed = self.plan.actions(plan)
        if error and step.step >= failed:
            return step if not step.passes else replace(step, message=error)
        order = plan.sequence
        force = step.max_hold_force
        for a in actions:
            if a.step != step.step:
                continue
            a = self.moved(a)
            known, _ = self.known(plan, a)
            if known is not None and known.stable:
                continue
            a = check_action(a, order, self.states)
            report = a.report
            force = max([force, *(float(np.linalg.norm(w.force))
                                  for w in report.hold_wrenches)])
            if not report.stable and step.passes:
                return replace(step, stable=False, status=report.status, report=report,
                               max_hold_force=force,
                               message=state_fell(a, report, step.block))
        return replace(step, max_hold_force=force)

    def timeline(self, plan: Scene, checked: range, known_only: bool = False) -> Timeline:
        """The timeline of ``plan`` at the measured poses, the actions of the steps
        ``checked`` checked (their robots' wrenches with them; ``known_only``: only those
        whose state is a step state checked already), infeasible at the first of them that
        falls or no robot can do."""
        actions, error, failed = self.plan.actions(plan)
        order = plan.sequence
        out = Timeline(self.plan.cell)
        for a in actions:
            a = self.moved(a)
            known, same = self.known(plan, a) if a.step in checked else (None, False)
            if same or (a.step in checked and not known_only):
                a = check_action(a, order, self.states, plan.approach, known if same else None)
            if a.report is not None:
                if not a.report.stable and out.feasible:
                    block = order[a.step] if a.step < len(order) else ""
                    out.feasible = False
                    out.message = f"{where(a.step, block)} fails at the measured poses: " \
                                  f"{state_fell(a, a.report, block)}"
            out.actions.append(a)
        if error and failed in checked and out.feasible:
            out.feasible, out.message = False, error
        return out


def repair_cell(plan: Scene, built: Scene, options: CheckOptions, cell: CellPlan, *,
                min_margin_g: float = 0.0, lookahead_steps: int = 0,
                max_held: int | None = None, replan: bool = True,
                time_limit: float = REPLAN_TIME_LIMIT, checked: Checked | None = None
                ) -> tuple[Repair, Timeline | None]:
    """Repair ``plan`` from the as-built scene ``built`` for ``cell`` (see the module
    docstring): the repair, its holds at the robots' grips, and the repaired plan's timeline
    at the measured poses (None when no repair was found). When the hold, swap or re-plan
    of :func:`repair_plan` (blind to the states between actions) leaves a state of the
    timeline falling, the remainder is planned again for the cell (within ``time_limit``
    s; not with ``replan`` False) and checked the same way. ``max_held``: K, at most the
    cell's robots less one (None: that). ``checked``: as :func:`repair_plan`'s."""
    robots = len(cell.cell.robots) - 1
    k_max = robots if max_held is None else min(max_held, robots)
    start = time.perf_counter()
    found = repair_plan(plan, built, options, max_held=k_max, min_margin_g=min_margin_g,
                        lookahead_steps=lookahead_steps, replan=replan, time_limit=time_limit,
                        checked=checked)
    if not found.feasible or found.scene is None:
        return found, None
    # the repair's states known: a state after an action that is a step state it checked
    # is not checked again
    runner = StepRunner(found.scene, options, found.placed, min_margin_g,
                        checked=found.checked)
    total = len(held_by_step(found.scene))
    stop = total if not lookahead_steps else min(total, found.placed + lookahead_steps)
    timeline = cell.ahead(runner).timeline(found.scene, range(found.placed, stop))
    if timeline.feasible:
        holds = scene_with_grips(found.scene, timeline).holds
        return replace(found, holds=holds, scene=replace(found.scene, holds=holds)), timeline
    reason = found.reason or timeline.message
    what = f"the repaired plan ({found.kind})" if found.changed else "the plan"
    if timeline.message != reason:
        what += f" ({timeline.message})"
    replanned = "no re-plan asked for" if not replan else \
        _replan(plan, found, options, cell, reason, k_max, min_margin_g,
                max(time_limit - (time.perf_counter() - start), 1e-3))
    if isinstance(replanned, tuple):
        return replanned
    return replace(found, feasible=False, changed=False, changed_step=-1, kind="none",
                   scene=None, order=list(plan_order(plan)), held=held_by_step(plan),
                   holds=plan.holds, reason=reason,
                   message=f"{reason}; {what} fails for the cell's robots, and {replanned}"), \
        None


def _replan(plan: Scene, found: Repair, options: CheckOptions, cell: CellPlan, reason: str,
            k_max: int, min_margin_g: float, time_limit: float
            ) -> tuple[Repair, Timeline] | str:
    """The remainder of ``plan`` planned again for the cell from the as-built state of
    ``found`` (the placed blocks a fixed prefix, at their measured poses; the holds of the
    steps done kept), every remaining step and state between actions re-checked; or why
    not."""
    start = time.perf_counter()
    placed = found.placed
    original = (list(plan_order(plan)), held_by_step(plan))
    scene = found.scene
    supports = {b.id for b in scene.blocks if b.support}
    fixed = Scene(scene.name, scene.blocks, scene.gravity, tuple(original[0][:placed]),
                  tuple(h for h in scene.holds if h.block in supports), scene.pose_uncertainty)
    new = plan_sequence(fixed, k_max, options, keep_sequence=True,
                        cell=cell.cell, time_limit=time_limit, min_margin=min_margin_g)
    if not new.feasible:
        return f"re-planning the remaining {len(original[0]) - placed} blocks for the cell " \
               f"failed: {new.message}"
    repaired = with_plan(scene, new.order, [*original[1][:placed], *new.held[placed:]])
    runner = StepRunner(repaired, options, placed, min_margin_g)
    runner.extra = cell.ahead(runner)
    total = len(held_by_step(repaired))
    steps = runner.scan(repaired, placed, total, runner.checker)
    if steps and not steps[-1].passes:
        s = steps[-1]
        return f"the re-planned remainder fails at {where(s.step, s.block)}: {s.message}"
    timeline = runner.extra.timeline(repaired, range(placed, total))
    holds = scene_with_grips(repaired, timeline).holds
    held = held_by_step(repaired)
    changed = next((k for k in range(placed, max(len(held), len(original[1])))
                    if (original[0][k:k + 1], original[1][k:k + 1])
                    != (list(repaired.sequence[k:k + 1]), held[k:k + 1])), -1)
    return Repair(True, changed >= 0, list(repaired.sequence), held, holds, changed, "replan",
                  f"{reason}; re-planned for the cell from step {changed}: every remaining "
                  "step and state between the robots' actions passes at the measured poses",
                  reason, replace(repaired, holds=holds), steps, placed, runner.checks,
                  time.perf_counter() - start), timeline


def _same_grip(a: Grip, b: Grip | None) -> bool:
    """Whether two grips of a block are one: the same point and capacities."""
    return b is not None and b.point is not None and np.allclose(a.point, b.point, atol=1e-9) \
        and all(math.isclose(x, y, rel_tol=1e-9) if x is not None and y is not None else x is y
                for x, y in ((a.max_force, b.max_force), (a.max_torque, b.max_torque)))


__all__ = ["CellAhead", "CellPlan", "REPLAN_TIME_LIMIT", "repair_cell"]
