"""A plan for a robot cell as a timeline of robot actions, every state between them checked.

Actions: ``place(robot, block)`` (the robot brings the block along its approach and keeps
its grip), then ``hold(robot, block)`` (it keeps holding) or ``release(robot, block)`` (it
lets go at once); ``hold(robot, block)`` of a block placed earlier (a robot takes a placed
block the next step needs held); ``release(robot, block)`` of a hold the plan no longer
needs. A robot is busy with a block from its place (or hold) until its release, and never
places while busy.

Between the planner's steps k-1 and k (held blocks H[k-1], then H[k] with block b placed):
the robots first take the placed blocks H[k] holds anew; b's placing robot is a free robot
that can grip it and carry it to its pose within its payload (:mod:`rbe_ros.analysis.grips`:
the nearest first); when none is free, holds of H[k-1] that H[k] drops are released first
(oldest first) - the hand-over state, b still absent, which must stand; then b is placed,
kept or released, and the other dropped holds released. Each state after an action is
checked with the robots' grips and payloads (:func:`rbe_ros.analysis.verdict.check`), so
no state between actions goes unchecked, and no state has more robots busy than the cell
has.

During the search (:class:`CellCheck`, a hook of the planner) a trial step is refused when
no free robot can grip a block it needs or the state after one of its actions falls (a
hand-over state, a robot beyond its payload at its grip); the timeline
(:func:`build_timeline`) reuses those checks.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from ..cell import Cell, Robot
from ..rbe.result import Report
from ..scene import Scene
from .assembly import Assembly
from .insertion import approach_length
from .grips import (PRE_GRIP, GripChooser, GripFrame, RobotWrench, carry_wrench, robot_grip,
                    robot_wrench)
from .options import CheckOptions
from .steps import supports_present
from .verdict import check

PLACE, HOLD, RELEASE = "place", "hold", "release"


@dataclass(frozen=True)
class Busy:
    """A robot's hold of a block: its grip."""

    robot: str
    grip: GripFrame


@dataclass(frozen=True)
class Action:
    """One action of the timeline, the state after it (``before``: the step's block not
    yet placed; ``busy``: the blocks held then, with their robots' grips) and, once built,
    its check and the acting robot's wrench (a place: what it carries to the pose)."""

    action: str
    robot: str
    block: str
    step: int
    before: bool
    busy: tuple[tuple[str, Busy], ...]
    grip: GripFrame                        # the acting robot's grip of the block
    report: Report | None = None
    wrench: RobotWrench | None = None
    #: place: from the placed pose to where the block starts its straight approach (m: the
    #: insertion direction reversed, over the insertion check's approach distance)
    approach: np.ndarray | None = None

    @property
    def stable(self) -> bool:
        return self.report is not None and self.report.stable

    def frames(self) -> dict[str, GripFrame]:
        """The TCP frames of the action: ``grip``; for a place ``pre_grip`` (backed off along
        the face normal) and ``approach`` (where the block starts its straight approach)."""
        grip = self.grip
        out = {"grip": grip}
        if self.action == PLACE:
            out["pre_grip"] = grip.shifted(grip.normal * PRE_GRIP)
            out["approach"] = grip.shifted(np.zeros(3) if self.approach is None
                                           else self.approach)
        return out


@dataclass
class Timeline:
    """The actions of a plan for ``cell``'s robots; ``feasible`` False with ``message``
    naming the action, robot and block where it fails."""

    cell: Cell
    actions: list[Action] = field(default_factory=list)
    feasible: bool = True
    message: str = ""

    @property
    def robots(self) -> tuple[str, ...]:
        return self.cell.names

    def holder(self, block: str, step: int) -> Action | None:
        """The action by which a robot took ``block`` last by ``step`` (place or hold)."""
        return next((a for a in reversed(self.actions) if a.block == block
                     and a.action in (PLACE, HOLD) and a.step <= step), None)


class _NoRobot(Exception):
    """No free robot can grip a block a step needs (the message names it and why each
    robot cannot)."""


class CellSteps:
    """The robots' actions step by step (no checks): which robot places, holds and releases
    what, for a cell and the finished assembly's grips."""

    def __init__(self, cell: Cell, assembly: Assembly, position: dict[str, int]):
        self.cell, self.chooser = cell, GripChooser(assembly, cell)
        self.position = position
        self.centroid = {b.id: b.centroid for b in assembly.blocks}

    def _take(self, block: str, busy: dict[str, Busy], present, carry: bool = False
              ) -> tuple[Robot, GripFrame] | str:
        """The nearest free robot that can grip ``block`` among the blocks ``present``
        (``carry``: and carry it to its pose within its payload), or why none can."""
        taken = {h.robot for h in busy.values()}
        why = []
        robots = sorted(self.cell.robots, key=lambda r: float(np.linalg.norm(
            np.asarray(r.base) - self.centroid[block])))
        for r in robots:
            if r.name in taken:
                held = next(b for b, h in busy.items() if h.robot == r.name)
                why.append(f"{r.name} is busy holding {held}")
                continue
            grip, reason = self.chooser.choose(block, r, present, carry)
            if grip is not None:
                return r, grip
            why.append(reason)
        return "; ".join(why)

    def step(self, k: int, block: str, busy: dict[str, Busy], held_after, present=()
             ) -> tuple[list[Action], dict[str, Busy]]:
        """The actions from the state after step k-1 (``busy``, the blocks ``present``) to
        that after step k, placing ``block`` (None: the release step) with ``held_after``
        held; _NoRobot when a block needed cannot be gripped by a free robot, or the block
        would land on a hold's grip that must stay."""
        busy = dict(busy)
        keep = set(held_after)
        drop = [b for b in busy if b not in keep]
        acts: list[Action] = []

        def act(kind, robot, b, before, grip):
            acts.append(Action(kind, robot, b, k, before, tuple(busy.items()), grip))

        def taken(b, carry=False):
            while True:
                found = self._take(b, busy, present, carry)
                if not isinstance(found, str):
                    return found
                if not drop:
                    raise _NoRobot(f"step {k}: no free robot can grip {b}: {found}")
                d = drop.pop(0)            # the hand-over: a hold let go before b is taken
                h = busy.pop(d)
                act(RELEASE, h.robot, d, True, h.grip)

        if block is not None:
            for c in sorted(keep - set(busy) - {block}, key=self.position.__getitem__):
                robot, grip = taken(c)
                busy[c] = Busy(robot.name, grip)
                act(HOLD, robot.name, c, True, grip)
            robot, grip = taken(block, carry=True)
            for c, h in list(busy.items()):
                if self.chooser.in_the_way(block, self.cell.robot(h.robot), h.grip):
                    if c not in drop:
                        raise _NoRobot(f"step {k}: {block} would land on {h.robot}'s grip of "
                                       f"{c}, which the step holds")
                    drop.remove(c)         # let go first: a hand-over state
                    busy.pop(c)
                    act(RELEASE, h.robot, c, True, h.grip)
            busy[block] = Busy(robot.name, grip)
            act(PLACE, robot.name, block, False, grip)
            if block in keep:
                act(HOLD, robot.name, block, False, grip)
            else:
                h = busy.pop(block)
                act(RELEASE, h.robot, block, False, h.grip)
        for d in drop:
            h = busy.pop(d)
            act(RELEASE, h.robot, d, False, h.grip)
        return acts, busy


class StateChecks:
    """Checks of the states of a timeline: the blocks present, the held ones with their
    robots' grips and payloads; each distinct state once."""

    def __init__(self, cell: Cell, assembly: Assembly, scene: Scene, options: CheckOptions):
        self.cell, self.assembly, self.scene, self.options = cell, assembly, scene, options
        self.cache: dict = {}

    def present(self, order, k: int, before: bool) -> tuple[str, ...]:
        placed = order[:k] if before else order[:k + 1]
        return supports_present(self.scene, k) + tuple(placed)

    def __call__(self, present: tuple[str, ...], busy) -> Report:
        key = (present, tuple(sorted((b, h.robot, h.grip.face) for b, h in busy)))
        found = self.cache.get(key)
        if found is None:
            grips = tuple(robot_grip(h.grip, self.cell.robot(h.robot)) for _, h in busy)
            sub = self.assembly.subset(present, [b for b, _ in busy], grips)
            found = self.cache[key] = check(sub, self.options)
        return found


class CellCheck:
    """The planner's hook for a cell: a trial step is refused (the reason returned) when a
    block it needs held or placed has no free robot that can grip it, or a hand-over state
    (holds let go before the block is placed) does not stand. The robots' state after each
    partial plan is kept by its order."""

    def __init__(self, cell: Cell, assembly: Assembly, scene: Scene, options: CheckOptions,
                 position: dict[str, int]):
        self.steps = CellSteps(cell, assembly, position)
        self.states = StateChecks(cell, assembly, scene, options)
        self.after: dict[tuple[str, ...], dict[str, Busy]] = {(): {}}

    def _busy(self, order: tuple[str, ...], held) -> dict[str, Busy]:
        found = self.after.get(order)
        if found is None:           # a partial plan not seen step by step: replayed
            busy = self._busy(order[:-1], held[:-1])
            k = len(order) - 1
            _, found = self.steps.step(k, order[-1], busy, held[-1],
                                       self.states.present(order, k, True))
            self.after[order] = found
        return found

    def __call__(self, order: tuple[str, ...], held: tuple, block: str, new_held) -> str:
        """Why the step placing ``block`` after ``order`` (held ``held`` by step) with
        ``new_held`` held cannot be done by the cell ("" when it can): no free robot can grip
        a block it needs, or the state after one of its actions falls (with the robots'
        grips and payloads: the hand-over state, or a robot's payload exceeded)."""
        busy = self._busy(order, held)
        k = len(order)
        full = (*order, block)
        try:
            acts, after = self.steps.step(k, block, busy, new_held,
                                          self.states.present(full, k, True))
        except _NoRobot as exc:
            return str(exc)
        for a in acts:
            report = self.states(self.states.present(full, k, a.before), a.busy)
            if not report.stable:
                return fell(a, report, block)
        self.after[full] = after
        return ""


def fell(a: Action, report: Report, block: str) -> str:
    """Why the state after action ``a`` of the step placing ``block`` falls: the action, and
    for a payload exceeded the robots and blocks over it."""
    where = (f"the hand-over state after {a.robot} releases {a.block} ({block} not yet "
             f"placed)" if a.before and a.action == RELEASE
             else f"the state after {a.action}({a.robot}, {a.block})")
    holders = dict(a.busy)
    over = [f"{holders[w.block].robot} holding {w.block}" for w in report.hold_wrenches
            if w.utilisation > 1.0 and w.block in holders]
    who = f" ({', '.join(over)} beyond its payload)" if over else ""
    return f"step {a.step}: {where} is {report.status.name}{who}: {report.message}"


def build_timeline(cell: Cell, assembly: Assembly, scene: Scene, order, held,
                   options: CheckOptions, approach=(), states: StateChecks | None = None
                   ) -> Timeline:
    """The timeline of a plan (``order``, ``held`` by step, a release step last when
    ``held`` is one longer) for ``cell``, every state after an action checked; the robots'
    wrenches from the checks. ``assembly``: the finished assembly (the grips' faces);
    ``scene``: the planned scene's supports; ``approach``: each step's insertion direction;
    ``states``: the checks the planner's :class:`CellCheck` made (reused)."""
    position = {b.id: k for k, b in enumerate(assembly.blocks)}
    steps = CellSteps(cell, assembly, position)
    states = states or StateChecks(cell, assembly, scene, options)
    order = tuple(order)
    timeline = Timeline(cell)
    busy: dict[str, Busy] = {}
    for k, now in enumerate(held):
        block = order[k] if k < len(order) else None
        try:
            acts, busy = steps.step(k, block, busy, now, states.present(order, k, True))
        except _NoRobot as exc:
            timeline.feasible, timeline.message = False, str(exc)
            return timeline
        for a in acts:
            if block is None:
                present = states.present(order, len(order), False)
            else:
                present = states.present(order, k, a.before)
            report = states(present, a.busy)
            wrench = None
            busy_now = dict(a.busy)
            if a.action == PLACE:       # what it carries to the pose, not the settled hold
                wrench = carry_wrench(cell.robot(a.robot), a.grip,
                                      assembly.blocks[position[a.block]], assembly.gravity)
            elif a.block in busy_now and report.hold_wrenches:
                hw = next((w for w in report.hold_wrenches if w.block == a.block), None)
                if hw is not None:
                    wrench = robot_wrench(cell.robot(a.robot), busy_now[a.block].grip,
                                          hw.force, hw.torque, assembly.gravity)
            direction = None
            if a.action == PLACE and k < len(approach) and approach[k] is not None:
                unit = np.asarray(approach[k], dtype=float)
                direction = -unit * approach_length(
                    assembly, states.present(order, k, True), a.block, options, unit)
            timeline.actions.append(replace(a, report=report, wrench=wrench,
                                             approach=direction))
            if not report.stable and timeline.feasible:
                timeline.feasible, timeline.message = False, fell(a, report, block or "")
    return timeline


def scene_with_grips(scene: Scene, timeline: Timeline) -> Scene:
    """``scene`` (a plan's) with each hold of a free block at its robot's grip (block
    frame) and within its robot's payload less its tool's share, as the timeline holds it."""
    holds = []
    for h in scene.holds:
        taken = timeline.holder(h.block, h.from_step)
        if taken is not None and not scene.block(h.block).support:
            grip = robot_grip(taken.grip, timeline.cell.robot(taken.robot))
            block = scene.block(h.block)
            local = Rotation.from_quat(block.orientation).inv().apply(
                taken.grip.point - block.position)
            h = replace(h, grip=tuple(float(x) for x in local), max_force=grip.max_force,
                        max_torque=grip.max_torque)
        holds.append(h)
    return replace(scene, holds=tuple(holds))


def busy_robots(actions) -> list[int]:
    """The robots busy in the state after each of ``actions`` (from a place or hold of a
    block until its release)."""
    busy: set[str] = set()
    out = []
    for a in actions:
        (busy.discard if a.action == RELEASE else busy.add)(a.robot)
        out.append(len(busy))
    return out


def recheck_timeline(cell: Cell, scene: Scene, actions, options: CheckOptions,
                     assembly: Assembly | None = None) -> list[Report]:
    """The check of the state after each of ``actions`` (an exported timeline: records with
    ``action``, ``robot``, ``block``, ``step`` and ``grip``, a :class:`GripFrame`), the
    states made from the actions alone: the blocks placed so far (and the supports present
    at the action's step), the blocks a robot holds (from its place or hold until its
    release) gripped where the action says, within that robot's payload."""
    assembly = assembly or Assembly.from_scene(scene, options.contact)
    states = StateChecks(cell, assembly, scene, options)
    placed: list[str] = []
    busy: dict[str, Busy] = {}
    out = []
    for a in actions:
        if a.action == PLACE:
            placed.append(a.block)
        if a.action in (PLACE, HOLD):
            busy[a.block] = Busy(a.robot, a.grip)
        else:
            busy.pop(a.block, None)
        present = supports_present(scene, a.step) + tuple(placed)
        out.append(states(present, tuple(busy.items())))
    return out


__all__ = ["Action", "Busy", "CellCheck", "CellSteps", "HOLD", "PLACE", "RELEASE",
           "StateChecks", "Timeline", "build_timeline", "busy_robots",
           "recheck_timeline", "scene_with_grips"]
