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

from ..cell import Cell, CellError, Robot
from ..rbe.result import HoldWrench, Report, Status
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

    def __init__(self, cell: Cell, assembly: Assembly):
        self.cell, self.chooser = cell, GripChooser(assembly, cell)
        self.assembly = assembly

    def _take(self, block: str, busy: dict[str, Busy], present, carry: bool = False,
              hold: bool = False) -> tuple[Robot, GripFrame] | str:
        """The nearest free robot that can grip ``block`` among the blocks ``present``
        (``carry``: and carry it to its pose within its payload; ``hold``: to hold it, by
        the face of least hold torque), or why none can."""
        taken = {h.robot for h in busy.values()}
        why = []
        centroid = self.assembly.block(block).centroid
        robots = sorted(self.cell.robots, key=lambda r: float(np.linalg.norm(
            np.asarray(r.base) - centroid)))
        for r in robots:
            if r.name in taken:
                held = next(b for b, h in busy.items() if h.robot == r.name)
                why.append(f"{r.name} is busy holding {held}")
                continue
            grip, reason = self.chooser.choose(block, r, present, carry, hold)
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
                found = self._take(b, busy, present, carry, b in keep)
                if not isinstance(found, str):
                    return found
                if not drop:
                    raise _NoRobot(f"step {k}: no free robot can grip {b}: {found}")
                d = drop.pop(0)            # the hand-over: a hold let go before b is taken
                h = busy.pop(d)
                act(RELEASE, h.robot, d, True, h.grip)

        if block is not None:
            for c in sorted(keep - set(busy) - {block}, key=self.assembly.index.__getitem__):
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

    def __init__(self, cell: Cell, assembly: Assembly, scene: Scene, options: CheckOptions):
        self.steps = CellSteps(cell, assembly)
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
    """Why the state after action ``a`` of the step placing ``block`` falls: the step, the
    action, and for a payload exceeded the robots and blocks over it."""
    return f"step {a.step}: {state_fell(a, report, block)}"


def state_fell(a: Action, report: Report, block: str) -> str:
    """:func:`fell` without the step: the action, and for a payload exceeded the robots and
    blocks over it."""
    where = (f"the hand-over state after {a.robot} releases {a.block} ({block} not yet "
             f"placed)" if a.before and a.action == RELEASE
             else f"the state after {a.action}({a.robot}, {a.block})")
    return f"{where} is {report.status.name}{beyond_payload(report, dict(a.busy))}: " \
        f"{report.message}"


def beyond_payload(report: Report, busy: dict[str, Busy]) -> str:
    """The robots of ``busy`` whose hold in ``report`` is beyond their payload, in words
    (" (r1 holding b beyond its payload)"; "" when none is)."""
    over = [f"{busy[w.block].robot} holding {w.block}" for w in report.hold_wrenches
            if w.utilisation > 1.0 and w.block in busy]
    return f" ({', '.join(over)} beyond its payload)" if over else ""


def carried(report: Report, robot: Robot, grip: GripFrame, assembly: Assembly) -> Report:
    """``report`` (the state after ``robot`` places ``grip.block``), or HOLD_EXCEEDED when
    what the robot carried to the pose, the block's whole weight and its gripper's
    (:func:`rbe_ros.analysis.grips.carry_wrench`), is beyond its payload: the report names
    the robot, the block, the wrench (the torque in the tool frame) and the payload."""
    w = carry_wrench(robot, grip, assembly.block(grip.block), assembly.gravity)
    if w.utilisation <= 1.0:
        return report
    torque = ", ".join(f"{x:.4g}" for x in w.torque_tool)
    return replace(report, status=Status.HOLD_EXCEEDED, unstable_blocks=(grip.block,),
                   hold_wrenches=(HoldWrench(grip.block, w.force_world, w.torque_world,
                                             grip.point, w.utilisation),),
                   message=f"hold exceeded: {robot.name} carrying block {grip.block} to its "
                           f"pose needs |F| {np.linalg.norm(w.force_robot):.4g} N (payload "
                           f"{robot.payload_force:g} N) and |M| "
                           f"{np.linalg.norm(w.torque_robot):.4g} N m (payload "
                           f"{robot.payload_torque:g} N m), torque ({torque}) N m in the "
                           "tool frame, its gripper's weight included")


def plan_actions(steps: CellSteps, scene: Scene, order, held
                 ) -> tuple[list[Action], str, int]:
    """The actions of a plan (``order``, ``held`` by step, a release step last when
    ``held`` is one longer), unchecked, and "" and -1, or why no robot can do step k and k
    (the actions then end before it). ``scene``: the plan's supports."""
    order = tuple(order)
    busy: dict[str, Busy] = {}
    out: list[Action] = []
    for k, now in enumerate(held):
        block = order[k] if k < len(order) else None
        try:
            acts, busy = steps.step(k, block, busy, now,
                                    supports_present(scene, k) + order[:k])
        except _NoRobot as exc:
            return out, str(exc), k
        out += acts
    return out, "", -1


def action_present(scene: Scene, order, a: Action) -> tuple[str, ...]:
    """The blocks present in the state after action ``a`` of a plan placing ``order``: the
    supports present at its step and the blocks placed by then (its step's block once it is
    placed; every block at the release step)."""
    k = a.step
    placed = order if k >= len(order) else order[:k] if a.before else order[:k + 1]
    return supports_present(scene, k) + tuple(placed)


def check_action(a: Action, order, states: "StateChecks", approach=(),
                 report: Report | None = None) -> Action:
    """``a`` with the check of the state after it (``states``: its assembly, the robots'
    grips and payloads; ``report``: that check made already), the acting robot's wrench
    and, for a place with an insertion direction (``approach``, by step), where the block
    starts its straight approach."""
    if report is None:
        report = states(action_present(states.scene, order, a), a.busy)
    a = with_report(a, report, states.cell, states.assembly)
    direction = None
    k = a.step
    if a.action == PLACE and k < len(approach) and approach[k] is not None:
        unit = np.asarray(approach[k], dtype=float)
        direction = -unit * approach_length(
            states.assembly, states.present(order, k, True), a.block, states.options, unit)
    return replace(a, approach=direction)


def with_report(a: Action, report: Report, cell: Cell, assembly: Assembly) -> Action:
    """``a`` with ``report``, the check of the state after it, and the acting robot's
    wrench: a place's what it carries to the pose (not the settled hold), else from the
    report (for the block it holds then)."""
    wrench = None
    busy_now = dict(a.busy)
    gravity = assembly.gravity
    if a.action == PLACE:
        wrench = carry_wrench(cell.robot(a.robot), a.grip, assembly.block(a.block), gravity)
    elif a.block in busy_now and report.hold_wrenches:
        hw = next((w for w in report.hold_wrenches if w.block == a.block), None)
        if hw is not None:
            wrench = robot_wrench(cell.robot(a.robot), busy_now[a.block].grip, hw.force,
                                  hw.torque, gravity)
    return replace(a, report=report, wrench=wrench)


def build_timeline(cell: Cell, assembly: Assembly, scene: Scene, order, held,
                   options: CheckOptions, approach=(), states: StateChecks | None = None
                   ) -> Timeline:
    """The timeline of a plan (``order``, ``held`` by step, a release step last when
    ``held`` is one longer) for ``cell``, every state after an action checked; the robots'
    wrenches from the checks. ``assembly``: the finished assembly (the grips' faces);
    ``scene``: the planned scene's supports; ``approach``: each step's insertion direction;
    ``states``: the checks the planner's :class:`CellCheck` made (reused)."""
    states = states or StateChecks(cell, assembly, scene, options)
    order = tuple(order)
    actions, error, _ = plan_actions(CellSteps(cell, assembly), scene, order, held)
    timeline = Timeline(cell)
    for a in actions:
        a = check_action(a, order, states, approach)
        timeline.actions.append(a)
        if not a.report.stable and timeline.feasible:
            block = order[a.step] if a.step < len(order) else ""
            timeline.feasible, timeline.message = False, fell(a, a.report, block)
    if error:
        timeline.feasible, timeline.message = False, error
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
    release) gripped where the action says, within that robot's payload; a place also
    within the placing robot's payload as it carries the block (:func:`carried`). A payload
    exceeded is HOLD_EXCEEDED naming the robot."""
    assembly = assembly or Assembly.from_scene(scene, options.contact)
    states = StateChecks(cell, assembly, scene, options)
    placed: list[str] = []
    busy: dict[str, Busy] = {}
    out = []
    for i, a in enumerate(actions):
        if a.block not in assembly.index:
            raise CellError(f"timeline[{i}]: block {a.block!r} is not in the scene")
        if a.action == PLACE:
            placed.append(a.block)
        if a.action in (PLACE, HOLD):
            busy[a.block] = Busy(a.robot, a.grip)
        else:
            busy.pop(a.block, None)
        present = supports_present(scene, a.step) + tuple(placed)
        report = states(present, tuple(busy.items()))
        if report.status == Status.HOLD_EXCEEDED:
            report = replace(report, message=f"{report.message}{beyond_payload(report, busy)}")
        if a.action == PLACE:
            report = carried(report, cell.robot(a.robot), a.grip, assembly)
        out.append(report)
    return out


__all__ = ["Action", "Busy", "CellCheck", "CellSteps", "HOLD", "PLACE", "RELEASE",
           "StateChecks", "Timeline", "action_present", "beyond_payload", "build_timeline",
           "busy_robots", "carried", "check_action", "fell", "plan_actions", "recheck_timeline",
           "scene_with_grips", "state_fell", "with_report"]
