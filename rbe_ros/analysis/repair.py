"""Repair: the rest of a plan changed so that every remaining step passes on the as-built
state, the cheapest change first.

The as-built state is fixed: the placed blocks (a prefix of the order) at their measured
poses, the holds of the steps done as the plan had them, the robots' count K and their
capacities. The remaining steps are checked in order (the look-ahead's rules,
:mod:`rbe_ros.analysis.lookahead`); at the first step that fails:

1. **hold**: one more block held at that step (within K): first a block a robot held at
   the step before (it keeps its grip), then those the failed check suggests holding (the
   hold search found them to stand), then the block placed there (the robot that placed it
   keeps its grip; when the step releases no hold, its state is then the one before, which
   stood, with a block held still against it), then the others it names as moving; the
   hold lasts that step (a later step that needs it fails without it and is repaired the
   same way, so holds last as long as needed);
2. **swap**: the block of that step exchanged with one of the next few (holds stay with the
   steps: a robot holding the block placed at step k holds the one placed there now);

and the check goes on from that step. A change only alters that step and later ones, and
every state (blocks present, blocks held) is checked once, so a repair costs about one check
of the steps it changes beyond the look-ahead of the remainder; after the look-ahead that
found the failure (the node's) it checks none of the look-ahead's states again. When neither
saves a step,
3. **replan**: the remainder is planned again (:func:`plan_sequence` with the placed blocks
at their measured poses a fixed prefix, the same K); its steps are the planner's checks
there, none checked again (:meth:`rbe_ros.analysis.lookahead.StepRunner.adopt`).

Nothing saves it: not feasible, and the message names the step and block that cannot stand.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from ..rbe.result import Report
from ..scene import Hold, Scene, SceneError
from .lookahead import (Checked, StepAhead, StepRunner, as_built_plan, held_by_step,
                        placed_count, plan_order, where, with_plan)
from .options import CheckOptions
from .planning import plan_sequence

#: Repair kinds, cheapest first ("none": the plan stands as it is, or nothing saves it).
KINDS = ("none", "hold", "swap", "replan")
#: Blocks tried as the one more hold at a failing step.
HOLD_CANDIDATES = 4
#: A failing step's block is swapped with one of this many next blocks.
SWAP_WINDOW = 4


@dataclass
class Repair:
    """The result of :func:`repair_plan`."""

    feasible: bool
    changed: bool                          # False: the plan stands as it is (or no repair)
    order: list[str]
    held: list[tuple[str, ...]]            # free blocks held at each step (a release step)
    holds: tuple[Hold, ...]                # the same as the plan's holds (scaffolds kept)
    changed_step: int                      # first step the repair changes; -1: none
    kind: str                              # one of KINDS
    message: str
    reason: str = ""                       # the failure that asked for a repair ("" none)
    scene: Scene | None = None             # the repaired plan at the as-built poses
    steps: list[StepAhead] = field(default_factory=list)   # remaining steps, re-checked
    placed: int = 0                        # steps done (the as-built state)
    checks: int = 0                        # states checked
    time: float = 0.0                      # s
    #: the states checked (the look-ahead's handed over included), for the look-ahead of
    #: the repaired plan (:func:`rbe_ros.analysis.lookahead.look_ahead`'s ``checked``)
    checked: Checked | None = field(default=None, repr=False)


class _Stop(Exception):
    """The time limit ran out."""


def repair_plan(plan: Scene, built: Scene, options: CheckOptions = CheckOptions(), *,
                max_held: int | None = None, min_margin_g: float = 0.0,
                time_limit: float = math.inf, replan: bool = True,
                lookahead_steps: int = 0, workers: int = 0,
                checked: Checked | None = None) -> Repair:
    """Repair the rest of ``plan`` from the as-built scene ``built`` (the design's supports
    and the measured blocks, a prefix of the plan's order; :func:`rbe_ros.io.poses.
    scene_at_poses`), see the module docstring. ``max_held``: K (None: the plan's largest
    number of blocks held at a step); ``min_margin_g`` > 0: a step with a smaller margin
    fails; ``time_limit`` s bounds the repair (then not feasible, "stopped"); ``replan``
    False: hold and swap only. ``lookahead_steps`` > 0: only that many steps past the
    as-built state are checked and repaired (a node's look-ahead window: the steps beyond
    are the plan's, checked as the build reaches them); 0: every remaining step.
    ``workers`` >= 1: the states checked whole on that many processes, the plan's remaining
    states queued ahead of the scan and a failing step's hold candidates before them: the
    same verdicts, and the same repair for any number of workers (without, a failing
    step's incremental report may rank its hold candidates otherwise). ``checked``: the
    states the look-ahead that found the failure checked on the same as-built state
    (:attr:`rbe_ros.analysis.lookahead.Lookahead.checked`), none checked again: the scan
    goes on from its first failing step, the same repair as without.

    Raises SceneError for bad input (as :func:`rbe_ros.analysis.lookahead.look_ahead`)."""
    start = time.perf_counter()
    scene = as_built_plan(plan, built)
    placed = placed_count(plan, built)
    order = list(plan_order(scene))
    held = held_by_step(scene)
    k_max = max((len(h) for h in held), default=0) if max_held is None else max_held
    if k_max < 0:
        raise SceneError(f"max_held must be >= 0, not {k_max}")

    def out_of_time() -> bool:
        return time.perf_counter() - start > time_limit

    if lookahead_steps < 0:
        raise SceneError(f"lookahead_steps must be >= 0, not {lookahead_steps}")
    # the as-built state's tolerance question only when it does not stand (the message)
    runner = StepRunner(scene, options, placed, min_margin_g, out_of_time, workers,
                        tolerance=False, checked=checked)
    fixer = _Fixer(runner, scene, placed, k_max, order, held, lookahead_steps)
    try:
        try:
            result = fixer.run()
        except TimeoutError as exc:
            result = fixer.failed(f"stopped after {time_limit:g} s: {exc}")
        if result.kind == "replan" and replan:
            result = fixer.replan(options, min_margin_g, max(time_limit - (time.perf_counter()
                                                                           - start), 1e-3))
        elif result.kind == "replan":
            result = fixer.failed(f"{fixer.reason}; no hold or swap saves the rest "
                                  f"({fixer.why})")
    finally:
        runner.close()
    result.checks, result.time = runner.checks, time.perf_counter() - start
    result.checked = runner.known()
    return result


class _Fixer:
    """The scan of the remaining steps with hold and swap repairs (one repair's state)."""

    def __init__(self, runner: StepRunner, scene: Scene, placed: int, k_max: int,
                 order: list[str], held: list[tuple[str, ...]], window: int = 0):
        self.runner, self.scene, self.placed, self.k_max = runner, scene, placed, k_max
        self.window = window
        self.original = (list(order), [tuple(h) for h in held])
        self.order, self.held = list(order), list(held)
        self.reason = ""          # the first failure found
        self.why = ""             # the step that nothing saved
        self.kinds: list[str] = []

    def plan(self) -> Scene:
        return with_plan(self.scene, self.order, self.held)

    def run(self) -> Repair:
        runner = self.runner
        current = self.plan()
        checker = runner.walker(current)
        runner.prefetch(current, range(max(self.placed - 1, 0), self.stop()))
        if self.placed:
            state = runner.ahead(current, self.placed - 1, checker)
            if not state.stable:
                self.why = (f"{where(state.step, state.block)} does not stand as built: "
                            f"{runner.explained(current).message}")
                return self.failed(self.why, reason=self.why, replan=False)
        steps: list[StepAhead] = []
        k = self.placed
        while k < self.stop():
            before = runner.fork(checker)
            step = runner.ahead(current, k, checker)
            if step.passes:
                steps.append(step)
                k += 1
                continue
            self.reason = self.reason or f"{where(k, step.block)} fails at the measured " \
                                         f"poses: {step.message}"
            fixed = self._hold(step, before) or self._swap(step, before)
            if fixed is None:
                self.why = f"{where(k, step.block)} cannot stand at the measured poses: " \
                           f"{step.message}"
                return self.failed(self.why, replan=True)
            self.order, self.held = fixed[0], fixed[1]
            self.kinds.append(fixed[2])
            current = self.plan()
            self.held = held_by_step(current)       # a release step when one is needed now
            runner.prefetch(current, range(k, self.stop()), first=True)
            checker = before
        return self.result(steps)

    def stop(self) -> int:
        """One past the last step checked: the end, or the window's."""
        return len(self.held) if not self.window else min(len(self.held),
                                                          self.placed + self.window)

    def passed(self) -> str:
        """Which steps were checked and pass."""
        return ("every remaining step passes" if self.stop() == len(self.held) else
                f"steps {self.placed} to {self.stop() - 1} (the look-ahead) pass")

    def _hold(self, step: StepAhead, before) -> tuple | None:
        """(order, held, "hold") with one more block held at ``step``, or None."""
        k = step.step
        now = self.held[k]
        if len(now) + 1 > self.k_max or not step.insertable:
            return None
        present = set(self.order[:k + 1])
        kept = [b for b in (self.held[k - 1] if k else ()) if b not in now]
        report: Report = step.report
        ranked = [*kept, *report.suggested_holds, step.block, *report.unstable_blocks]
        tried = []
        for b in dict.fromkeys(ranked):
            if b and b in present and b not in now and len(tried) < HOLD_CANDIDATES:
                held = list(self.held)
                held[k] = tuple(sorted((*now, b), key=self.order.index))
                tried.append(held)
        # the candidates' states differ from the plan's at step k only: all checked at once
        for held in reversed(tried):      # each before the queue: the first ends first
            self.runner.prefetch(with_plan(self.scene, self.order, held), (k,), first=True)
        for held in tried:
            if self._passes(self.order, held, k, before):
                return self.order, held, "hold"
        return None

    def _swap(self, step: StepAhead, before) -> tuple | None:
        """(order, held, "swap") with the block of ``step`` exchanged with a later one."""
        k = step.step
        if k >= len(self.order):
            return None
        for j in range(k + 1, min(k + 1 + SWAP_WINDOW, len(self.order))):
            order = list(self.order)
            a, b = order[k], order[j]
            order[k], order[j] = b, a
            swap = {a: b, b: a}
            held = [tuple(swap.get(x, x) for x in h) if k <= s < j else h
                    for s, h in enumerate(self.held)]
            if self._passes(order, held, k, before):
                return order, held, "swap"
        return None

    def _passes(self, order, held, k: int, before) -> bool:
        plan = with_plan(self.scene, order, held)
        return self.runner.ahead(plan, k, self.runner.fork(before)).passes

    def changed_step(self) -> int:
        order, held = self.original
        n = max(len(held), len(self.held))
        for k in range(self.placed, n):
            if (k < len(order) and (k >= len(self.order) or order[k] != self.order[k])) \
                    or (held[k] if k < len(held) else ()) != \
                    (self.held[k] if k < len(self.held) else ()):
                return k
        return -1

    def result(self, steps: list[StepAhead]) -> Repair:
        plan = self.plan()
        changed = self.changed_step()
        if changed < 0:
            kind, message = "none", f"{self.passed()} at the measured poses as planned"
        else:
            kind = max(self.kinds, key=KINDS.index)
            fixes = ", ".join(dict.fromkeys(self.kinds))
            message = (f"{self.reason}; repaired ({fixes}) from step {changed}: "
                       f"{self.passed()} at the measured poses")
        return Repair(True, changed >= 0, list(plan.sequence), held_by_step(plan), plan.holds,
                      changed, kind, message, self.reason, plan, steps, self.placed)

    def failed(self, message: str, reason: str = "", replan: bool = False) -> Repair:
        order, held = self.original
        return Repair(False, False, list(order), list(held),
                      with_plan(self.scene, order, held).holds, -1,
                      "replan" if replan else "none", message, reason or self.reason,
                      None, [], self.placed)

    def replan(self, options: CheckOptions, min_margin_g: float, time_limit: float) -> Repair:
        """The remainder planned again from the as-built state, its steps taken from the
        planner's checks there (a state the planner's check is not of, by its grips or
        approach, checked step by step)."""
        n = len(self.original[0])
        prefix = self.original[0][:self.placed]
        base = with_plan(self.scene, self.original[0], self.original[1])
        fixed = Scene(base.name, base.blocks, base.gravity, tuple(prefix),
                      tuple(h for h in base.holds if self.scene.block(h.block).support),
                      base.pose_uncertainty)
        found = plan_sequence(fixed, self.k_max, options, keep_sequence=True,
                              time_limit=time_limit, min_margin=min_margin_g)
        if not found.feasible:
            return self.failed(f"{self.reason}; no hold or swap saves the rest "
                               f"({self.why}), and re-planning the remaining "
                               f"{n - self.placed} blocks failed: {found.message}")
        self.order = list(found.order)
        self.held = [*self.original[1][:self.placed], *found.held[self.placed:]]
        self.kinds = ["replan"]
        runner = self.runner
        checker = runner.fork(runner.checker)
        plan = self.plan()
        self.held = held_by_step(plan)
        self.window = 0                 # a new remainder: every step of it checked
        # the planner checked each state of its plan at the measured poses: none again
        for k in range(self.placed, len(self.held)):
            runner.adopt(plan, k, found.reports[k])
        runner.prefetch(plan, range(self.placed, len(self.held)), first=True)
        steps = runner.scan(plan, self.placed, len(self.held), checker)
        if steps and not steps[-1].passes:
            s = steps[-1]
            return self.failed(f"{self.reason}; the re-planned remainder fails at "
                               f"{where(s.step, s.block)}: {s.message}")
        result = self.result(steps)
        result.kind = "replan"
        return result


__all__ = ["HOLD_CANDIDATES", "KINDS", "Repair", "SWAP_WINDOW", "repair_plan"]
