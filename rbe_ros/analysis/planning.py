"""Sequence planning: an insertion order in which every step stands with at most K blocks
held, found by beam search (width 1: greedy).

Steps: every free block of the scene is placed once (blocks "present from the start" do
not exist in a plan). With ``keep_sequence`` the scene's sequence is a fixed prefix of the
order (a partial order: those blocks first, in that order; the planner orders the rest).
Holds of free blocks in the scene are ignored (the planner chooses them); holds of support
blocks (a scaffold, a centring present for some steps) apply by step index as in a check.

At each step, the candidates of a partial plan are the unplaced blocks that rest on a
present block (an interface whose normal into the candidate points up, against gravity),
then those that only touch one, each group lowest first (centroid along gravity), then the
largest contact area with present blocks, then scene order; of these the first
``candidates`` that can reach their pose past the present blocks (insertion, see
:mod:`rbe_ros.analysis.insertion`; those that cannot are named when the step fails). For a
candidate the holds are
found as a robot would keep them: nothing, if the step stands so; else the blocks held at
the previous step plus the new block, less every hold whose release keeps the step
standing (oldest first); when none can go and the set does not stand, one more block is
held (the highest the failed check names as moving first) and the releases are tried again;
if that ends with more than K, the exact minimal hold search
(:func:`rbe_ros.analysis.holds.minimal_holds`, within its budget). A held block has a
robot's grip at its centroid, as ``check --sequence`` checks the planned scene: a candidate
is feasible with at most K holds, each robot within the hold capacities of the options
(``hold_force_max``, ``hold_torque_max``); when no candidate is, the message names the
wrench the best one needs.
Each partial plan keeps the first ``beam`` feasible candidates; of all children the ``beam``
best survive (fewest hold-steps so far, then fewest holds now, then candidate rank).
No child at a step: the plan fails there.

A candidate step is the partial plan's last standing state plus one block, so it is checked
as :func:`check_sequence` checks a step (:class:`StepChecker`: the kept forces of that state,
a local region around the blocks that changed, the component only when no region settles
it), and the verdict is the full problem's. With blocks held, a smaller model only proves a
failure (a relaxation, the held blocks rigid); a step that may stand is checked whole, with
the robots' grips, since their wrenches are the report's. The report of the accepted
candidate is the step's report (no second check of the plan); ``full_candidates`` checks
every trial whole instead (to compare with).

The finished assembly must stand with nothing held; if the last step holds blocks, a release
step follows (its report: the finished assembly's check).

``prefer`` "margin": every feasible candidate among the first ``candidates`` is a child,
ranked by the weakest margin of its plan so far (largest first), then as above.
``min_margin`` > 0: a step stands only with a margin of at least that (the hold search
holds more until it does). With either, or when the options ask for margins, every step's
margin is computed (about one whole solve per direction) and the plan names its weakest step.
"""
from __future__ import annotations

import collections
import copy
import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from ..rbe.result import Report
from ..scene import Hold, Scene, SceneError, make_scene
from .asbuilt import declared
from .assembly import Assembly
from .holds import StabilityOracle, minimal_holds, release_unneeded
from .incremental import StepChecker
from .insertion import block_insertion
from .margin import DEFAULT_DIRECTIONS, Margin, report_margin
from .options import CheckOptions
from .pipeline import check_sequence, slim
from .steps import gripped, supports_present
from .verdict import UNEXPLAINED, check

#: How the message of a plan stopped by ``should_stop`` begins (a time limit, a cancel).
STOPPED = "stopped after"
#: What ``PlanOptions.prefer`` may be.
PREFER = ("holds", "margin")
#: A contact carries a block when its normal into the block points up by at least this
#: cosine (87 deg from vertical).
RESTS_ON = 0.05


@dataclass(frozen=True)
class PlanOptions:
    """The planner's search: the holds it may use, the width of its beam, and how a
    candidate is checked."""

    max_held: int = 2            # K: blocks held at any step
    beam: int = 1                # partial plans kept per step (1: greedy)
    candidates: int = 8          # insertable candidates tried per partial plan and step
    keep_sequence: bool = False  # the scene's sequence is a fixed prefix of the order
    #: every trial of a candidate checked whole, without the incremental checks (to
    #: compare with)
    full_candidates: bool = False
    time_limit: float = math.inf  # s: then the best partial plan is returned
    #: which feasible candidate a partial plan keeps: "holds" (fewest hold-steps) or
    #: "margin" (the largest weakest margin so far, then fewest hold-steps)
    prefer: str = "holds"
    min_margin: float = 0.0      # g: a step with a smaller margin does not stand (0: off)

    def __post_init__(self):
        for name, low in (("max_held", 0), ("beam", 1), ("candidates", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError(f"{name} must be an integer >= {low}, not {value!r}")
        if not self.time_limit > 0:
            raise ValueError(f"time_limit must be > 0 s, not {self.time_limit!r}")
        if self.prefer not in PREFER:
            raise ValueError(f"prefer must be one of {', '.join(PREFER)}, not {self.prefer!r}")
        if not 0 <= self.min_margin < math.inf:
            raise ValueError(f"min_margin must be a number >= 0 (g), not {self.min_margin!r}")

    @property
    def greedy(self) -> bool:
        """One candidate per step: the first feasible one is the plan's step."""
        return self.beam == 1 and self.prefer == "holds"


@dataclass(frozen=True)
class PlanProgress:
    """Where a running plan is: after each placed step of its best partial plan."""

    placed: int                  # blocks placed
    total: int                   # blocks to place
    step: int                    # the step just placed
    block: str
    held: tuple[str, ...]        # blocks held at that step
    elapsed: float               # s since the search started
    estimate: float              # s left, from the mean time per block so far


@dataclass
class Plan:
    """The result of :func:`plan_sequence`. ``held[k]``: blocks held at step k (one more
    entry than ``order`` when a release step follows the last placement). ``reports``: the
    step reports of the search, without their interfaces (the full ones are streamed to
    ``on_report``): memory stays linear in the blocks."""

    feasible: bool
    order: list[str]
    held: list[tuple[str, ...]]
    message: str
    failed_step: int = -1                  # first step no candidate can be placed at
    scene: Scene | None = None             # the planned scene (sequence, holds)
    reports: list[Report] = field(default_factory=list)   # one per step (interfaces dropped)
    checks: int = 0                        # candidate checks spent by the search
    time: float = 0.0                      # s
    models: dict[str, int] = field(default_factory=dict)   # checks answered per model
    #: the (slim) report of the step with the smallest margin (the first of equals)
    weakest: Report | None = None

    @property
    def max_held(self) -> int:
        return max((len(h) for h in self.held), default=0)


class LookAhead(Protocol):
    """Full checks (:func:`check`) of steps of the planner's assembly, a robot's grip on each
    held block, run by ``workers`` workers: ``submit(present, held)`` returns a future of
    the report."""

    workers: int

    def submit(self, present: tuple[str, ...], held: frozenset): ...

    def close(self) -> None: ...


class _Stopped(Exception):
    """The time limit ran out or ``should_stop`` asked to stop."""


@dataclass(frozen=True)
class _Partial:
    order: tuple[str, ...]
    held: tuple[tuple[str, ...], ...]
    score: tuple
    reports: tuple[Report, ...] = ()           # slim step reports
    checker: StepChecker | None = None         # the kept forces of its last step


class _Trial:
    """One candidate step (the partial plan's blocks and the candidate) checked with sets of
    held blocks: through the partial plan's kept forces (:class:`StepChecker`, local
    regions first; with holds, failures only), else the full check with the robots' grips
    (sent ahead to the look-ahead's workers, or made here); each set once. ``options``:
    the check's (the planner's, or with unbounded robots for the capacity note)."""

    def __init__(self, planner: _Planner, partial: _Partial, block: str,
                 options: CheckOptions | None = None):
        self.planner, self.checker = planner, partial.checker
        self.options = options or planner.options
        self.order = (*partial.order, block)
        self.previous = partial.held[-1] if partial.held else ()
        unheld = max((j for j, h in enumerate(partial.held) if not h), default=-1)
        self.open_course = partial.order[unheld + 1:]   # placed since it stood unheld
        # a release of a hold that the last step could only prove by the full problem: the
        # forces of the open course and below all move (friction at its limit, docs/
        # SCALING.md), so such a trial only tries to prove a failure before the full check
        self.direct = (len(partial.held) >= 2 and bool(set(partial.held[-2]) - set(self.previous))
                       and partial.reports[-1].model == "full")
        self.present = planner.present(self.order, len(self.order) - 1)
        self.assembly = planner.full.subset(self.present)   # each set of holds from it
        self.free = {b for b in self.present if b in planner.free_set}
        self.reports: dict[frozenset, tuple[Assembly, Report]] = {}
        self.margins: dict[frozenset, Margin] = {}

    def result(self, held) -> tuple[Assembly, Report]:
        key = frozenset(held)
        found = self.reports.get(key)
        if found is None:
            planner = self.planner
            planner.poll()
            restrict = not (key or (self.direct and self.previous))
            assembly = self.assembly.subset(self.present, key)
            report = None if (planner.plan.full_candidates
                              or (self.present, key) in planner.submitted) \
                else self.checker.attempt(assembly, self.open_course, restrict=restrict)
            if report is None or (key and report.stable):
                # with holds only a failure is taken from a smaller model (a relaxation): the
                # verdict is that of the robots' grips, and the report needs their wrenches
                assembly = gripped(self.assembly, self.present, key)
                report = ((planner.ahead(self.present, key) if self.options is planner.options
                           else None) or check(assembly, self.options))
            planner.counted(report)
            found = self.reports[key] = (assembly, report)
        return found

    def stands(self, held) -> bool:
        """Whether the step stands with ``held``, with a margin of at least the plan's
        ``min_margin`` (when set)."""
        least = self.planner.plan.min_margin
        return self.result(held)[1].stable and (not least or self.margin(held).margin_g >= least)

    def margin(self, held) -> Margin:
        """The margin of the step with ``held`` (the held blocks rigid, as a check's
        margin), computed once."""
        key = frozenset(held)
        if key not in self.margins:
            assembly, report = self.result(held)
            self.margins[key] = report_margin(report, assembly, self.options.deciding,
                                              self.options.margin_directions
                                              or DEFAULT_DIRECTIONS)
        return self.margins[key]

    def next_hold(self, held) -> str | None:
        """The block to hold next when ``held`` is not enough: the highest the failed check
        names as moving, else the highest free one (None: nothing left to hold)."""
        assembly, report = self.result(held)
        if report.message == UNEXPLAINED:
            report = check(assembly, self.options)
        left = self.free - set(held)
        named = [b for b in report.unstable_blocks if b in left]
        pool = named or left
        return max(pool, key=lambda b: (self.planner.height[b], -self.planner.position[b]),
                   default=None)


class _Planner:
    def __init__(self, scene: Scene, options: CheckOptions, plan: PlanOptions,
                 progress, should_stop, on_report):
        self.scene, self.options, self.plan = scene, options, plan
        self.progress, self.should_stop, self.on_report = progress, should_stop, on_report
        self.pool: LookAhead | None = None
        self.submitted: dict[tuple, object] = {}     # (present, held) -> future
        # holds of free blocks are the planner's; those of supports stay (scaffolds)
        supports = {b.id for b in scene.blocks if b.support}
        self.base = make_scene(scene.name, scene.blocks, scene.gravity, (),
                               [h for h in scene.holds if h.block in supports])
        self.full = Assembly.from_scene(self.base, options.contact)
        self.ids = [b.id for b in self.full.blocks]
        self.position = {bid: k for k, bid in enumerate(self.ids)}
        self.free = [b.id for b in self.full.blocks if not b.support]
        self.free_set = set(self.free)
        up = -np.asarray(self.full.gravity, dtype=float)
        up = up / (np.linalg.norm(up) or 1.0)
        self.height = {b.id: float(b.centroid @ up) for b in self.full.blocks}
        # contacts by block: (other block, area, rests on it)
        self.contacts: dict[str, list[tuple[str, float, bool]]] = {i: [] for i in self.ids}
        for it in self.full.interfaces:
            a, b = self.ids[it.a], self.ids[it.b]
            n_up = float(it.frame.n @ up)           # n points from a into b
            self.contacts[b].append((a, it.area, n_up >= RESTS_ON))
            self.contacts[a].append((b, it.area, -n_up >= RESTS_ON))
        self.cache: dict = {}
        # each step's margin (its weakest reported): asked for, or needed by the plan's choice
        self.margins = bool(options.margin_directions or plan.prefer == "margin"
                            or plan.min_margin)
        self.insertions: dict = {}              # order -> insertion of its last block
        self.checks = 0
        self.models: collections.Counter = collections.Counter()
        self.start = time.perf_counter()

    def poll(self) -> None:
        """Raise _Stopped when the time limit ran out or the caller asks to stop."""
        if (time.perf_counter() - self.start > self.plan.time_limit
                or (self.should_stop is not None and self.should_stop())):
            raise _Stopped

    def counted(self, report: Report) -> None:
        self.checks += 1
        self.models[report.model.split()[0]] += 1

    def present(self, order, k: int) -> tuple[str, ...]:
        """The supports present at step ``k`` (those with holds while active) and ``order``."""
        return supports_present(self.base, k) + tuple(order)

    def candidates(self, order: tuple[str, ...], blocked: dict[str, str]) -> Iterator[str]:
        """The first ``candidates`` blocks, in rank order, that can reach their pose (each
        found when asked for: the search mostly takes the first); those that cannot go into
        ``blocked`` with the reason."""
        k = len(order)
        prefix = self.scene.sequence if self.plan.keep_sequence else ()
        if k < len(prefix):
            return self.insertable(order, [prefix[k]], blocked)
        placed = set(order)
        present = set(self.present(order, k))
        left = [b for b in self.free if b not in placed and b not in prefix[k:]]
        resting, touching = [], []
        for b in left:
            near = [(area, rests) for other, area, rests in self.contacts[b] if other in present]
            if not near:
                continue
            key = (round(self.height[b], 6), -round(sum(a for a, _ in near), 9), self.position[b])
            (resting if any(r for _, r in near) else touching).append((key, b))
        # blocks that only touch (a key-stone's neighbour against the crown) come after:
        # tried when no resting one fits, held as they are placed
        return self.insertable(order, [b for _, b in sorted(resting) + sorted(touching)],
                               blocked)

    def insertable(self, order, ranked, blocked: dict[str, str]) -> Iterator[str]:
        """The first ``candidates`` of ``ranked`` that can reach their pose after ``order``."""
        found = 0
        for b in ranked:
            why = self.blocked((*order, b))
            if why:
                blocked.setdefault(b, why)
                continue
            yield b
            found += 1
            if found == self.plan.candidates:
                return

    def insertion(self, order: tuple[str, ...]):
        """How ``order[-1]`` reaches its pose past the blocks present (None when insertion
        is not checked); kept for the step (the search and the step report ask again)."""
        if not self.options.insertion.enabled:
            return None
        found = self.insertions.get(order)
        if found is None:
            found = self.insertions[order] = block_insertion(
                self.full, self.present(order, len(order) - 1), order[-1], self.options,
                self.scene.approach_of(order[-1]))
        return found

    def blocked(self, order: tuple[str, ...]) -> str:
        """Why ``order[-1]`` cannot reach its pose past the blocks present ("" when it can,
        or when insertion is not checked)."""
        found = self.insertion(order)
        return "" if found is None or found.insertable else found.reason

    def holds_for(self, partial: _Partial, block: str):
        """(held blocks, within K, step report or None, its assembly) for the step that
        places ``block`` after ``partial``."""
        trial = _Trial(self, partial, block)
        held = self._holds(trial, partial.held[-1] if partial.held else ())
        ok = len(held) <= self.plan.max_held and trial.stands(held)
        assembly, report = trial.result(held) if ok else (None, None)
        if ok and self.margins:
            margin = trial.margin(held)
            report = replace(report, margin_g=margin.margin_g,
                             margin_direction=margin.direction)
        return held, ok, report, assembly

    def _holds(self, trial: _Trial, previous) -> tuple[str, ...]:
        """The holds of ``trial``'s step as a robot would keep them (the module docstring):
        the repair, else the exact search when that needs more than K or fails."""
        block = trial.order[-1]
        held = self._repair(trial, block, previous)
        if len(held) > self.plan.max_held or not trial.stands(held):
            self.poll()
            oracle = StabilityOracle(trial.assembly, trial.options, self.cache)
            result = minimal_holds(trial.assembly, trial.options, prefer=(*previous, block),
                                   oracle=oracle)
            self.checks += oracle.checks
            if result.stands and (len(result.blocks) < len(held) or not trial.stands(held)):
                held = result.blocks
        return held

    def _repair(self, trial: _Trial, new: str, previous) -> tuple[str, ...]:
        """Nothing held if the step stands so; else the previous holds and the new block,
        less every hold whose release keeps the step standing (oldest first); if none can
        go and the set does not stand, one more hold and the releases again. (A set is
        checked only when no release settles it: a step held by the previous holds and
        the new block that stands with fewer needs no proof that it stands with all.)"""
        if trial.stands(()):
            return ()
        held = [b for b in previous if b in trial.free] + [new]
        while True:
            fewer = release_unneeded(trial, held)
            if len(fewer) < len(held) or trial.stands(held):
                held = fewer
                break
            more = trial.next_hold(held)
            if more is None:
                break
            held.append(more)
        return tuple(sorted(held, key=self.position.__getitem__))

    def _capacity_note(self, partial: _Partial, block: str) -> str:
        """What the robots would need beyond their capacities at the step that places
        ``block`` after ``partial``, held as the plan would hold it with unbounded robots
        ("" when the capacities are unbounded, or that needs more than K holds or is within
        them)."""
        if self.options.hold_force_max is None and self.options.hold_torque_max is None:
            return ""
        unbounded = replace(self.options, hold_force_max=None, hold_torque_max=None)
        trial = _Trial(self, partial, block, unbounded)
        held = self._holds(trial, partial.held[-1] if partial.held else ())
        if len(held) > self.plan.max_held or not trial.stands(held):
            return ""
        oracle = StabilityOracle(trial.assembly, self.options, self.cache)
        over = oracle.capacity([oracle.index[b] for b in held])
        return (f"; with {', '.join(held)} held (fewest with unbounded robots), {over.message}"
                if over is not None else "")

    def step_report(self, order, held, report: Report, assembly: Assembly) -> Report:
        """The report of the step placing ``order[-1]`` with ``held``: the accepted trial's
        ``report`` of ``assembly`` as a step of the plan, with how the block arrives."""
        found = self.insertion(order)
        extra = {} if found is None else {"insertable": found.insertable,
                                          "insertion_direction": found.direction}
        return replace(report, step_index=len(order) - 1, block_placed=order[-1],
                       held_blocks=tuple(held),
                       num_blocks=len(assembly.blocks), **extra)

    def run(self) -> Plan:
        n = len(self.free)
        final = self.full.subset(self.present(self.free, n + 1))
        self.final = check(final, self.options)
        if not self.final.stable:
            return Plan(False, [], [], "the finished assembly does not stand without holds "
                        "(rbe-ros check names why): no build order can end stable",
                        failed_step=n)
        margin = report_margin(self.final, final, self.options.deciding,
                               self.options.margin_directions or DEFAULT_DIRECTIONS) \
            if self.margins else None
        if margin is not None:
            self.final = replace(self.final, margin_g=margin.margin_g,
                                 margin_direction=margin.direction)
        if margin is not None and margin.margin_g < self.plan.min_margin:
            return Plan(False, [], [], f"the finished assembly's margin is "
                        f"{margin.margin_g:.4f} g, below the minimum {self.plan.min_margin:g} g: "
                        "no build order can end with it", failed_step=n)
        beam = [_Partial((), (), (0, 0, 0), (), StepChecker(self.options, explain=False))]
        for k in range(n):
            blocked: dict[str, str] = {}
            self.insertions = {o: f for o, f in self.insertions.items() if len(o) > k}
            try:
                children, best_rejected = self._children(beam, blocked)
            except _Stopped:
                return self._finish(beam[0], False, k, f"{STOPPED} {k} of {n} blocks "
                                    f"(time limit or asked to stop); step {k} not placed")
            if not children:
                count = len(best_rejected[1]) if best_rejected else 0
                best = beam[0]
                why = (f"; the best candidate, {best_rejected[0]}, needs {count} held "
                       f"block{'' if count == 1 else 's'} ({', '.join(best_rejected[1])})"
                       + self._capacity_note(best, best_rejected[0])
                       if best_rejected else
                       "; no unplaced block touches the placed ones" if not blocked else "")
                why += "".join(f"; {b} cannot be inserted: {r}" for b, r in blocked.items())
                return self._finish(beam[0], False, k, f"no block can be placed at step {k} "
                                    f"with at most {self.plan.max_held} held{why}")
            beam = sorted(children.values(), key=lambda p: (p.score, p.order))[:self.plan.beam]
            self._placed(beam[0], n)
            if self.pool is not None and self.plan.greedy:
                self._look_ahead(beam[0])
        best = beam[0]
        return self._finish(best, True, -1, f"every step stands with at most "
                            f"{max((len(h) for h in best.held), default=0)} held blocks "
                            f"(limit {self.plan.max_held})")

    def _children(self, beam: list[_Partial], blocked: dict[str, str]):
        """The feasible children of the partial plans of ``beam`` (by the set of blocks
        placed), and the rejected candidate needing the fewest holds; candidates that cannot
        be inserted go into ``blocked``."""
        children: dict[frozenset, _Partial] = {}
        best_rejected = None
        for partial in beam:
            found = 0
            for rank, b in enumerate(self.candidates(partial.order, blocked)):
                start = time.perf_counter()
                order = (*partial.order, b)
                held, ok, report, assembly = self.holds_for(partial, b)
                if not ok:
                    if best_rejected is None or len(held) < len(best_rejected[1]):
                        best_rejected = (b, held)
                    continue
                total, _, ranks = partial.score[-3:]
                report = self.step_report(order, held, report, assembly)
                report = replace(report, solve_time=time.perf_counter() - start)
                checker = copy.copy(partial.checker)
                checker.advance(assembly, report)
                score = (total + len(held), len(held), ranks + rank)
                if self.plan.prefer == "margin":        # the weakest step so far first
                    score = (-min((r.margin_g for r in (*partial.reports, report)),
                                  default=0.0), *score)
                child = _Partial(order, (*partial.held, held), score,
                                 (*partial.reports, slim(report)), checker)
                if self.plan.greedy and self.on_report is not None:
                    self.on_report(report)          # greedy: this step is the plan's
                key = frozenset(order)
                if key not in children or child.score < children[key].score:
                    children[key] = child
                found += 1
                if found >= self.plan.beam and self.plan.prefer == "holds":
                    break
        return children, best_rejected

    def _look_ahead(self, partial: _Partial) -> None:
        """Full checks of the next steps as a held course goes on (the first hold kept, the
        newest block held instead of the one before: a trial that only the full problem
        settles, docs/SCALING.md), sent to the pool before the search reaches them: the
        first candidate of each, as many steps ahead as the pool has workers. Results are
        used by (blocks, holds), never by arrival, so the plan is the one process's."""
        order, held = partial.order, partial.held[-1]
        wanted = set()
        for _ in range(self.pool.workers):
            if not held or order[-1] not in held:
                break
            following = next(self.candidates(order, {}), None)
            if following is None:
                break
            order = (*order, following)
            held = tuple(sorted({*held} - {order[-2]} | {order[-1]},
                                key=self.position.__getitem__))
            key = (self.present(order, len(order) - 1), frozenset(held))
            wanted.add(key)
            if key not in self.submitted:
                self.submitted[key] = self.pool.submit(*key)
        for key in set(self.submitted) - wanted:     # off the path taken: not needed
            self.submitted.pop(key).cancel()

    def ahead(self, present: tuple[str, ...], held: frozenset) -> Report | None:
        """The look-ahead's full check of this step with ``held``, if it was sent."""
        future = self.submitted.pop((present, held), None)
        return None if future is None else future.result()

    def _placed(self, best: _Partial, n: int) -> None:
        if self.progress is None:
            return
        k = len(best.order)
        elapsed = time.perf_counter() - self.start
        self.progress(PlanProgress(k, n, k - 1, best.order[-1], best.held[-1], elapsed,
                                   elapsed / k * (n - k)))

    def _finish(self, partial: _Partial, feasible: bool, failed: int, message: str) -> Plan:
        order, held = list(partial.order), list(partial.held)
        reports = list(partial.reports)
        n = len(order)
        release = feasible and held and held[-1]
        if release:
            held.append(())                          # release step
            report = replace(self.final, step_index=n, block_placed="")
            reports.append(slim(report))
            if self.plan.greedy and self.on_report is not None:
                self.on_report(report)
        holds = []
        for block in self.free:
            k = 0
            while k < n:
                if block in held[k]:
                    start = k
                    while k < n and block in held[k]:
                        k += 1
                    # a failed plan's last holds stay (no release step after it)
                    holds.append(Hold(block, start, k if feasible or k < n else None))
                k += 1
        placed = set(order) | {b.id for b in self.base.blocks if b.support}
        keep = [h for h in self.base.holds if h.until_step is None or h.until_step <= n]
        try:
            scene = make_scene(self.scene.name, [b for b in self.scene.blocks if b.id in placed],
                               self.scene.gravity, order, [*keep, *holds],
                               _planned_under(self.options)) if order else None
        except SceneError:
            scene = None
        if scene is not None and self.options.insertion.enabled:
            # each step's direction, as checked (a given one kept), for a robot to follow
            scene = replace(scene, approach=tuple(
                r.insertion_direction if r.insertable else None for r in reports[:n]))
        if not self.plan.greedy and self.on_report is not None and scene is not None:
            # a beam's steps are the plan's only once it is chosen: its reports are re-made
            check_sequence(scene, self.options, on_step=lambda r, _total: self.on_report(r))
        weakest = min((r for r in reports if r.margin_g >= 0),
                      key=lambda r: r.margin_g, default=None)
        return Plan(feasible, order, held, message, failed, scene, reports, self.checks,
                    models=dict(self.models), weakest=weakest)


def _planned_under(options: CheckOptions) -> tuple[float, float] | None:
    """The pose uncertainty the plan was checked under, for the planned scene to keep (a scene
    file's, or the command line's, which wins over it)."""
    contact = options.contact
    return ((contact.pose_uncertainty_m, contact.pose_uncertainty_deg) if contact.uncertain
            else None)


def plan_sequence(scene: Scene, max_held: int = 2, options: CheckOptions = CheckOptions(), *,
                  beam: int = 1, candidates: int = 8, keep_sequence: bool = False,
                  full_candidates: bool = False, time_limit: float = math.inf,
                  progress: Callable[[PlanProgress], None] | None = None,
                  should_stop: Callable[[], bool] | None = None,
                  on_report: Callable[[Report], None] | None = None,
                  look_ahead: Callable[[Assembly, CheckOptions], LookAhead] | None = None,
                  prefer: str = "holds", min_margin: float = 0.0) -> Plan:
    """An insertion order of every free block of ``scene`` in which each step stands with at
    most ``max_held`` blocks held (see the module docstring), or where none was found.

    ``progress`` is called after each placed step; ``should_stop`` is polled between
    candidate checks, and when it returns True (or ``time_limit`` s have passed) the best
    partial plan is returned (not feasible, "stopped after K of N blocks"). ``on_report``
    receives each step's full report as the plan makes it (greedy; a beam's after the
    search). ``look_ahead(assembly, options)``: workers for the full checks of the steps
    ahead (:mod:`rbe_ros.analysis.executors`), closed when the plan is made; the plan is
    the same with and without. ``prefer`` and ``min_margin``: :class:`PlanOptions`."""
    start = time.perf_counter()
    planner = _Planner(scene, declared(options, scene),
                       PlanOptions(max_held, beam, candidates, keep_sequence, full_candidates,
                                   time_limit, prefer, min_margin),
                       progress, should_stop, on_report)
    if look_ahead is not None and not full_candidates:
        planner.pool = look_ahead(planner.full, planner.options)
    try:
        result = planner.run()
    finally:
        if planner.pool is not None:
            planner.pool.close()
    result.time = time.perf_counter() - start
    return result


__all__ = ["LookAhead", "Plan", "PlanOptions", "PlanProgress", "STOPPED", "plan_sequence"]
