"""Sequence planning: an insertion order in which every step stands with at most K blocks
held, found by depth-first search that backs up on a dead end (its first descent is the
greedy plan), or by beam search (width > 1, without backing up).

Steps: every free block of the scene is placed once (blocks "present from the start" do
not exist in a plan). With ``keep_sequence`` the scene's sequence is a fixed prefix of the
order (a partial order: those blocks first, in that order; the planner orders the rest).
Holds of free blocks in the scene are ignored (the planner chooses them); holds of support
blocks (a scaffold, a centring present for some steps) apply by step index as in a check.

At each step, the candidates of a partial plan are the unplaced blocks that rest on a
present block (an interface whose normal into the candidate points up, against gravity),
then those that only touch one, each group lowest first (centroid along gravity), then the
largest contact area with present blocks, then scene order; of these those (the first
``candidates`` when set) that can reach their pose past the present blocks (insertion, see
:mod:`rbe_ros.analysis.insertion`; those that cannot are named when the step fails). For a
candidate the holds are
found as a robot would keep them: nothing, if the step stands so; else the blocks held at
the previous step plus the new block, less every hold whose release keeps the step
standing (oldest first); when none can go and the set does not stand, one more block is
held (the highest the failed check names as moving first) and the releases are tried again;
if that ends with more than K (the repair stops there), the exact minimal hold search up
to K holds (:func:`rbe_ros.analysis.holds.minimal_holds`, within its check budget), whose
end without a set proves that the step needs more than K. A held block has a
robot's grip at its centroid, as ``check --sequence`` checks the planned scene: a candidate
is feasible with at most K holds, each robot within the hold capacities of the options
(``hold_force_max``, ``hold_torque_max``); when no candidate is, the message names the
wrench the best one needs.

The search (:meth:`_Planner.expand`: the children of a partial plan, its candidates in rank
order each tried by :meth:`_Planner.trial`, the one feasibility test of a step): depth
first, the first feasible child first, so that the first descent is the greedy plan and
costs what it did. A partial plan with no further child is dead: the set of its blocks goes
into a memo and the search backs up to try the next child of its parent. Whether the
remaining blocks can be placed depends on that set only, since any blocks may be held at a
step (K holds plus one placing robot): a state reached again by another order is skipped
unchecked. Each state checked (a partial plan and the block it places) counts against the
budget (``search_budget``; by default the first descent is free and :func:`backup_budget`
states follow its first dead end, and a search stuck at a step, a candidate refused there,
that makes no deeper partial plan in :data:`STALL` candidate checks, or :data:`STALL_STEPS`
times the most it took to go a step deeper, ends: the default goes on while the search gets
deeper and answers in bounded time when a step no candidate can take stops it; counted in
checks, not seconds, so that where it ends does not depend on the machine or its load);
``time_limit`` and ``should_stop`` end it too.

The outcome (:attr:`Plan.outcome`): ``planned``; ``no_plan`` when the search is exhausted
and every refusal is a proof (a candidate that the insertion check refuses, or whose exact
hold search up to K holds ran to its end without its check budget running out, and no
``candidates`` limit cut a step short): no order exists in which every block touches a
placed one when placed, as the checks see it (a path is the insertion check's: its
directions, and a part's convex hull where it has no exact decomposition);
``budget_exhausted`` (the budget, or an exhausted search with an unproven refusal);
``stopped``. A failed plan is the deepest partial plan the search made,
with why no block could follow it: the best candidate, the holds it needs, and with hold
capacities the wrench each robot would need against them.
With ``beam`` > 1, each partial plan keeps the first ``beam`` feasible candidates; of all
children the ``beam`` best survive (fewest hold-steps so far, then fewest holds now, then
candidate rank); no child at a step: the plan fails there (``dead_end``).

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

For a robot cell (``cell``), a candidate that stands must also be one its robots can do
(:class:`rbe_ros.analysis.timeline.CellCheck`: a free robot that can grip each block the step
takes, every state between its actions standing with the robots' grips and payloads), and
the plan carries the timeline of their actions.
``prefer`` "margin": the children of a partial plan are tried by the weakest margin of their
plan so far (largest first), then as above (fewest hold-steps, fewest held now, candidate
rank); with ``robust`` N samples first by the weakest p_stable so far (the share of N samples
of the declared pose uncertainty in which the step stands, :class:`StepSamples`), then by
margin. They come in exactly the order of scoring every feasible child and sorting, but made
lazily (:meth:`_Planner._best_first`): a score part never exceeds the partial plan's weakest,
so a child whose parts are known and whose key no unscored or untried child can beat comes
first, and the trials, margins and p_stable of the rest are made only if the search backs up
to them (the budget counts the candidates tried: a search that found its plan within the
budget finds the same one).
``min_margin`` > 0: a step stands only with a margin of at least that (the hold search
holds more until it does). With either, or when the options ask for margins, every step's
margin is computed (about one whole solve per direction) and the plan names its weakest step.
"""
from __future__ import annotations

import collections
import copy
import heapq
import itertools
import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from ..cell import Cell
from ..rbe.result import Report, Status
from ..scene import Hold, Scene, SceneError, make_scene
from .asbuilt import declared
from .assembly import Assembly
from .holds import StabilityOracle, minimal_holds, release_unneeded
from .incremental import StepChecker
from .insertion import block_insertion
from .margin import DEFAULT_DIRECTIONS, Margin, report_margin
from .options import CheckOptions
from .pipeline import check_sequence, slim
from .robust import StepSamples
from .steps import gripped, supports_present
from .timeline import CellCheck, Timeline, build_timeline, scene_with_grips
from .verdict import UNEXPLAINED, check

#: How the message of a plan stopped by ``should_stop`` begins (a time limit, a cancel).
STOPPED = "stopped after"
#: The default search budget after the first dead end: about this many block-states (states
#: checked times blocks to place: a state's checks grow with the blocks), at least
#: MIN_BACKUP states.
BACKUP_BLOCK_STATES, MIN_BACKUP = 2000, 10
#: The default budget also ends a search stuck at a step (a candidate of its deepest
#: partial plan refused, or a dead end backed out of) that made no deeper partial plan in
#: this many candidate checks (each hold search's included), or STALL_STEPS times the most
#: it took to go one step deeper before, whichever is more (checks, not seconds: the same
#: input ends at the same step on any machine; a search that gets deeper goes on).
STALL, STALL_STEPS = 100, 3
#: s between two progress heartbeats while the search checks candidates.
HEARTBEAT = 1.0
#: The last steps of the first descent whose mean time estimates the time left.
RECENT = 10
#: Partial plans of the search's path (the deepest) that keep their step's forces for the
#: incremental checks of their children.
KEPT = 3
#: What ``PlanOptions.prefer`` may be.
PREFER = ("holds", "margin")
#: A contact carries a block when its normal into the block points up by at least this
#: cosine (87 deg from vertical).
RESTS_ON = 0.05


@dataclass(frozen=True)
class PlanOptions:
    """The planner's search: the holds it may use, the width of its beam, how a candidate
    is checked, and what bounds the search."""

    max_held: int = 2            # K: blocks held at any step
    beam: int = 1                # partial plans kept per step (1: depth-first, greedy first)
    #: insertable candidates tried per partial plan and step (0: all; a limit makes a search
    #: that runs out of candidates no proof that no plan exists)
    candidates: int = 0
    keep_sequence: bool = False  # the scene's sequence is a fixed prefix of the order
    #: every trial of a candidate checked whole, without the incremental checks (to
    #: compare with)
    full_candidates: bool = False
    time_limit: float = math.inf  # s: then the deepest partial plan is returned
    #: states the search may check (a state: a partial plan and the block it places, checked
    #: for its holds); 0: the first descent, then :func:`backup_budget` states more, and no
    #: more than :data:`STALL` candidate checks without a deeper partial plan
    search_budget: int = 0
    #: which feasible candidate a partial plan keeps: "holds" (fewest hold-steps) or
    #: "margin" (the largest weakest margin so far, then fewest hold-steps)
    prefer: str = "holds"
    min_margin: float = 0.0      # g: a step with a smaller margin does not stand (0: off)
    #: with prefer "margin": rank by p_stable over this many samples of the declared pose
    #: uncertainty first, then by margin (0: by margin only)
    robust: int = 0

    def __post_init__(self):
        for name, low in (("max_held", 0), ("beam", 1), ("candidates", 0),
                          ("search_budget", 0), ("robust", 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError(f"{name} must be an integer >= {low}, not {value!r}")
        if not self.time_limit > 0:
            raise ValueError(f"time_limit must be > 0 s, not {self.time_limit!r}")
        if self.prefer not in PREFER:
            raise ValueError(f"prefer must be one of {', '.join(PREFER)}, not {self.prefer!r}")
        if not 0 <= self.min_margin < math.inf:
            raise ValueError(f"min_margin must be a number >= 0 (g), not {self.min_margin!r}")
        if self.robust and self.prefer != "margin":
            raise ValueError(f"robust {self.robust} ranks candidates by p_stable, which only "
                             "prefer margin does (prefer holds takes the first that fits)")

    @property
    def greedy(self) -> bool:
        """One candidate per step: the first feasible one is the plan's step."""
        return self.beam == 1 and self.prefer == "holds"


def backup_budget(blocks: int) -> int:
    """The states the search may check after its first dead end by default, with ``blocks``
    blocks to place: :data:`BACKUP_BLOCK_STATES` / blocks, at least :data:`MIN_BACKUP` (the
    first descent, today's greedy plan, is never cut short by the default). A state of a
    larger assembly costs more (its checks are larger, and more candidates fail at a dead
    end): the default keeps a plan that backs up within about a minute from 10 to 100
    blocks (docs/SEARCH.md)."""
    return max(MIN_BACKUP, BACKUP_BLOCK_STATES // max(blocks, 1))


@dataclass(frozen=True)
class PlanProgress:
    """Where a running plan is: after each placed step, and at least every
    :data:`HEARTBEAT` s while it checks candidates (``placing`` False)."""

    placed: int                  # blocks placed on the current partial plan
    total: int                   # blocks to place
    step: int                    # the step last placed (-1: none)
    block: str
    held: tuple[str, ...]        # blocks held at that step
    elapsed: float               # s since the search started
    #: s left: from the mean time per block of the last steps while the search goes down
    #: without stalling; else what the budget (states left at the mean time per state so far,
    #: or the default's stall bound) or the time limit leaves, whichever is less; -1: unknown
    estimate: float
    checks: int = 0              # candidate checks so far (each hold search's included)
    states: int = 0              # states checked of ``budget``
    budget: int = 0              # 0: not yet known (the default, before the first dead end)
    backups: int = 0             # dead ends backed out of
    deepest: int = 0             # most blocks placed by any partial plan so far
    placing: bool = True         # a step was just placed (False: a heartbeat)
    bound: str = "steps"         # what ``estimate`` comes from: steps, budget, time limit


#: What a plan's search ended with (:attr:`Plan.outcome`).
PLANNED = "planned"                  # every block placed
NO_PLAN = "no_plan"                  # the search was exhausted: no plan with at most K held
BUDGET_EXHAUSTED = "budget_exhausted"  # the budget ran out (or a part could not be proven)
HALTED = "stopped"                   # the time limit, a cancel or a newer goal
DEAD_END = "dead_end"                # a beam (width > 1, it does not back up) found no child
OUTCOMES = (PLANNED, NO_PLAN, BUDGET_EXHAUSTED, HALTED, DEAD_END)


@dataclass
class Plan:
    """The result of :func:`plan_sequence`. ``held[k]``: blocks held at step k (one more
    entry than ``order`` when a release step follows the last placement). ``reports``: the
    step reports of the search, without their interfaces (the full ones are streamed to
    ``on_report``): memory stays linear in the blocks. Not feasible: the deepest partial
    plan the search made, ``failed_step`` its length, ``failure`` why no block could follow
    it."""

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
    outcome: str = ""                      # one of OUTCOMES ("": not planned, bad input)
    states: int = 0                        # states checked by the search
    backups: int = 0                       # dead ends backed out of
    #: the deepest partial plan's failure: the best candidate ("block"), the holds it
    #: needs ("held"), and when a robot's capacity is what fails, the wrench it needs and
    #: the capacity ("force", "torque", N and N m; "force_max", "torque_max")
    failure: dict = field(default_factory=dict)
    timeline: Timeline | None = None       # planned for a cell: the robots' actions
    #: the (slim) report of the step with the smallest margin (the first of equals)
    weakest: Report | None = None
    #: with ``robust``: each report's p_stable (the release step's included)
    p_stable: list[float] = field(default_factory=list)

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


class _Budget(Exception):
    """The search checked as many states as its budget allows."""


@dataclass(frozen=True)
class TrialResult:
    """Whether a candidate step can be placed (:meth:`_Planner.trial`): the blocks held
    at it, its report and checked assembly when it can (``ok``), and when it cannot, whether
    that is proven (no set of at most K holds stands: a search that runs out of states
    refused only by proofs has shown that no plan exists)."""

    held: tuple[str, ...]
    ok: bool
    report: Report | None = None
    assembly: Assembly | None = None
    proven: bool = True
    refusal: str = ""       # why the cell's robots cannot do a step that stands
    margin: Margin | None = None    # when the trial made it (min_margin, --margin)
    #: refused: a set of at most K holds it stands with only beyond a robot's capacity, and
    #: that HOLD_EXCEEDED report (the wrenches needed), as :meth:`_Trial.exceeded` picks it
    exceeded: tuple[tuple[str, ...], Report] | None = None


@dataclass
class _Failure:
    """Why no (further) block could follow a partial plan: the candidates that cannot be
    inserted (with the reason), the refused candidate needing the fewest holds, and whether
    every refusal is proven."""

    blocked: dict[str, str] = field(default_factory=dict)
    best: tuple[str, tuple[str, ...]] | None = None
    proven: bool = True
    dead: int = 0           # candidates whose state the search found dead before
    cell: dict[str, str] = field(default_factory=dict)     # block -> why the robots cannot
    #: block -> the set of at most K holds it stands with only beyond a robot's capacity,
    #: and that HOLD_EXCEEDED report (:meth:`_Trial.exceeded`)
    exceeded: dict[str, tuple[tuple[str, ...], Report]] = field(default_factory=dict)

    def refused(self, block: str, found: TrialResult) -> None:
        if self.best is None or len(found.held) < len(self.best[1]):
            self.best = (block, found.held)
        self.proven = self.proven and found.proven
        if found.refusal:
            self.cell[block] = found.refusal
        if found.exceeded is not None:
            self.exceeded[block] = found.exceeded

    @property
    def capacity(self) -> tuple[str, tuple[str, ...], Report] | None:
        """The refused candidate a robot's capacity refused: the best one (fewest holds) if
        it is, else the one that comes closest (:func:`_exceeding`); (block, holds, its
        HOLD_EXCEEDED report), None when no capacity refused any."""
        if self.best is not None and self.best[0] in self.exceeded:
            return (self.best[0], *self.exceeded[self.best[0]])
        return min(((b, *e) for b, e in self.exceeded.items()),
                   key=lambda f: _exceeding(*f[1:]), default=None)


def _exceeding(held: tuple[str, ...], report: Report) -> tuple:
    """How close a HOLD_EXCEEDED set of holds comes: fewest holds, then the least use of a
    capacity, then the blocks."""
    return len(held), max((w.utilisation for w in report.hold_wrenches), default=0.0), held


@dataclass
class _Partial:
    order: tuple[str, ...]
    held: tuple[tuple[str, ...], ...]
    score: tuple
    reports: tuple[Report, ...] = ()           # slim step reports
    checker: StepChecker | None = None         # the kept forces of its last step
    p_stable: tuple[float, ...] = ()           # with robust: per step


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
        self.oracle: StabilityOracle | None = None     # the exact hold search's, if it ran

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

    def exceeded(self, most: int) -> tuple[tuple[str, ...], Report] | None:
        """Of the sets of at most ``most`` holds this trial checked (its own and its hold
        search's), the one it stands with only beyond a robot's capacity (HOLD_EXCEEDED)
        that comes closest (:func:`_exceeding`), with its report: what the robots would
        need, found without another check. None: no capacity was what failed."""
        met = [(k, r) for k, (_, r) in self.reports.items() if r.status == Status.HOLD_EXCEEDED]
        if self.oracle is not None:
            met += list(self.oracle.exceeded.items())
        position = self.planner.position.__getitem__
        return min(((tuple(sorted(k, key=position)), r) for k, r in met if len(k) <= most),
                   key=lambda f: _exceeding(*f), default=None)

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
                 progress, should_stop, on_report, cell: Cell | None = None):
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
        self.position = self.full.index
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
        self.lazy = plan.prefer == "margin"     # children scored by _best_first
        if plan.robust and not options.contact.uncertain:
            raise SceneError(f"robust {plan.robust}: p_stable samples the declared pose "
                             "uncertainty, and none is declared (--pose-uncertainty-m / -deg, "
                             "or the scene's pose_uncertainty)")
        self.samples = StepSamples(scene, options, plan.robust) if plan.robust else None
        self.insertions: dict = {}              # order -> insertion of its last block
        # a cell's robots: who grips what, and the hand-over states (analysis/timeline.py)
        self.cell_check = (CellCheck(cell, self.full, self.base, options)
                           if cell is not None else None)
        self.checks = 0
        self.models: collections.Counter = collections.Counter()
        self.dead: set[frozenset] = set()       # the memo: sets of blocks with no completion
        self.states = self.backups = 0          # states checked, dead ends backed out of
        self.streamed = 0                       # steps of the path streamed to on_report
        self.streaming = False                  # the stream is the path's so far
        self.start = self.beat = time.perf_counter()
        self.stopping = False                   # stopped: the failure's message is made
        self.descent = 0.0                      # s to the last step of the first descent
        self.backed = (0.0, 0)                  # (s, states) at the first dead end
        self.recent: collections.deque = collections.deque(maxlen=RECENT)   # s of steps
        # the default budget's stall bound: the checks when the search last went deeper (and
        # when, for the progress estimate), and the most it took to go one step deeper
        self.deeper = self.slowest = 0
        self.deeper_at = self.start
        self.stalled = False
        self.failure = _Failure()               # why no block followed the deepest so far

    def poll(self) -> None:
        """Raise _Stopped when the time limit ran out or the caller asks to stop; a
        progress heartbeat at most every :data:`HEARTBEAT` s."""
        now = time.perf_counter()
        if not self.stopping and (now - self.start > self.plan.time_limit
                or (self.should_stop is not None and self.should_stop())):
            raise _Stopped
        if not self.stopping and self.stuck and self.checks - self.deeper > self.stall:
            self.stalled = True
            raise _Budget
        if now - self.beat >= HEARTBEAT:
            self._progress(False)

    @property
    def stuck(self) -> bool:
        """Whether the default budget's stall bound applies: a candidate of the deepest
        partial plan refused, or a dead end backed out of."""
        return not self.plan.search_budget and bool(self.backups or self.failure.best)

    @property
    def stall(self) -> int:
        """Checks without a deeper partial plan after which the default budget ends the
        search."""
        return max(STALL, STALL_STEPS * self.slowest)

    def went_deeper(self) -> None:
        """The search made a partial plan deeper than any before (the stall bound restarts)."""
        self.slowest = max(self.slowest, self.checks - self.deeper)
        self.deeper, self.deeper_at = self.checks, time.perf_counter()

    def checked(self) -> None:
        """A check of a hold search (StabilityOracle.on_check): counted, then a poll."""
        self.checks += 1
        self.poll()

    def counted(self, report: Report) -> None:
        self.checks += 1
        self.models[report.model.split()[0]] += 1

    def present(self, order, k: int) -> tuple[str, ...]:
        """The supports present at step ``k`` (those with holds while active) and ``order``."""
        return supports_present(self.base, k) + tuple(order)

    def candidates(self, order: tuple[str, ...], blocked: dict[str, str]) -> Iterator[str]:
        """The blocks that may be placed after ``order``, in rank order, that can reach
        their pose (each found when asked for: the search mostly takes the first; at most
        ``candidates`` when set); those that cannot go into ``blocked`` with the reason."""
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
        """The first ``candidates`` (all: 0) of ``ranked`` that can reach their pose after
        ``order``."""
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

    def trial(self, partial: _Partial, trial: _Trial) -> TrialResult:
        """Whether ``trial``'s block can be placed after ``partial`` with at most K held, and
        how (:class:`TrialResult`): the one feasibility test of a candidate step."""
        block = trial.order[-1]
        held, proven = self._holds(trial, partial.held[-1] if partial.held else ())
        if len(held) > self.plan.max_held or not trial.stands(held):
            return TrialResult(held, False, proven=proven,
                               exceeded=trial.exceeded(self.plan.max_held))
        why = (self.cell_check(partial.order, partial.held, block, held)
               if self.cell_check is not None else "")
        if why:
            # it stands with its holds, the cell cannot do it; a robot's state depends on the
            # order, not only on the set placed: no proof
            return TrialResult(held, False, proven=False, refusal=why)
        assembly, report = trial.result(held)
        found = TrialResult(held, True, report, assembly,
                            margin=trial.margins.get(frozenset(held)))
        # prefer margin makes a child's margin only when its rank needs it (_best_first)
        return self.with_margin(found) if self.margins and not self.lazy else found

    def with_margin(self, found: TrialResult) -> TrialResult:
        """``found`` with its step's margin in its report (made now unless the trial made
        it)."""
        margin = found.margin or report_margin(found.report, found.assembly,
                                               self.options.deciding,
                                               self.options.margin_directions
                                               or DEFAULT_DIRECTIONS)
        return replace(found, margin=margin, report=replace(
            found.report, margin_g=margin.margin_g, margin_direction=margin.direction))

    def _holds(self, trial: _Trial, previous) -> tuple[tuple[str, ...], bool]:
        """The holds of ``trial``'s step as a robot would keep them (the module docstring):
        the repair, else the exact search for at most K; and whether no set of at most K
        stands is proven (the exact search searched every one)."""
        block, k = trial.order[-1], self.plan.max_held
        held = self._repair(trial, block, previous)
        if len(held) <= k and trial.stands(held):
            return held, False
        self.poll()
        oracle = trial.oracle = StabilityOracle(trial.assembly, trial.options, self.cache,
                                                self.checked)
        result = minimal_holds(trial.assembly, trial.options, prefer=(*previous, block),
                               oracle=oracle, largest=k)
        if result.stands:
            return result.blocks, False
        return held, result.none_within >= k

    def _repair(self, trial: _Trial, new: str, previous) -> tuple[str, ...]:
        """Nothing held if the step stands so; else the previous holds and the new block,
        less every hold whose release keeps the step standing (oldest first); if none can
        go and the set does not stand, one more hold and the releases again, up to K + 1
        holds (beyond, the exact search decides). (A set is checked only when no release
        settles it: a step held by the previous holds and the new block that stands with
        fewer needs no proof that it stands with all.)"""
        if trial.stands(()):
            return ()
        held = [b for b in previous if b in trial.free] + [new]
        while True:
            fewer = release_unneeded(trial, held)
            if len(fewer) < len(held) or trial.stands(held):
                held = fewer
                break
            if len(held) > self.plan.max_held:
                break
            more = trial.next_hold(held)
            if more is None:
                break
            held.append(more)
        return tuple(sorted(held, key=self.position.__getitem__))

    def _need(self, partial: _Partial, block: str) -> tuple[str, dict]:
        """What the robots would need beyond their capacities at the step that places
        ``block`` after ``partial``, held as the plan would hold it with unbounded robots:
        a message tail and the wrenches ("" and {} when the capacities are unbounded, or
        that needs more than K holds)."""
        force_max, torque_max = self.options.hold_force_max, self.options.hold_torque_max
        if force_max is None and torque_max is None:
            return "", {}
        unbounded = replace(self.options, hold_force_max=None, hold_torque_max=None)
        trial = _Trial(self, partial, block, unbounded)
        held, _ = self._holds(trial, partial.held[-1] if partial.held else ())
        if len(held) > self.plan.max_held or not trial.stands(held):
            return "", {}
        shown, need = self._wrenches(held, trial.result(held)[1])
        bounded = _Trial(self, partial, block).result(held)[1]
        return (f"; with {', '.join(held)} held (fewest with unbounded robots) it needs "
                f"{shown}; with the robots bounded: {bounded.status.name}, "
                f"{bounded.message}"), need

    def _exceeded(self, block: str, held: tuple[str, ...], report: Report) -> tuple[str, dict]:
        """What the robots would need at the step placing ``block`` with ``held``, which the
        search found standing only beyond a capacity (``report``, HOLD_EXCEEDED): a message
        tail and the wrenches (those of the report: the least with those holds)."""
        shown, need = self._wrenches(held, report)
        return (f"; {block} stands with {', '.join(held)} held only beyond the robots' "
                f"capacity: it needs {shown} ({report.message})"), {"block": block, **need}

    def _wrenches(self, held, report: Report) -> tuple[str, dict]:
        """The hold wrenches of ``report`` (each held block's robot) against the options'
        capacities, in words and as the failure's details."""
        force_max, torque_max = self.options.hold_force_max, self.options.hold_torque_max
        need = {"held": list(held), "force_max": force_max, "torque_max": torque_max,
                "wrenches": [{"block": w.block, "force": float(np.linalg.norm(w.force)),
                              "torque": float(np.linalg.norm(w.torque))}
                             for w in report.hold_wrenches]}
        shown = ", ".join(f"the robot on {w['block']} |F| {w['force']:.4g} N, |M| "
                          f"{w['torque']:.4g} N m" for w in need["wrenches"])
        caps = " and ".join(f"{value:.4g} {unit}" for value, unit in
                            ((force_max, "N"), (torque_max, "N m")) if value is not None)
        return f"{shown}, against a capacity of {caps} per robot", need

    def step_report(self, order, held, report: Report, assembly: Assembly) -> Report:
        """The report of the step placing ``order[-1]`` with ``held``: the accepted trial's
        ``report`` of ``assembly`` as a step of the plan, with how the block arrives."""
        found = self.insertion(order)
        extra = {} if found is None else {"insertable": found.insertable,
                                          "insertion_direction": found.direction}
        return replace(report, step_index=len(order) - 1, block_placed=order[-1],
                       held_blocks=tuple(held),
                       num_blocks=len(assembly.blocks), **extra)

    def expand(self, partial: _Partial, failure: _Failure) -> Iterator[_Partial]:
        """The feasible children of ``partial`` in the order the search tries them: rank order,
        lazily (:meth:`feasible`); with ``prefer`` "margin" by their score
        (:meth:`_best_first`)."""
        if self.lazy:
            return self._best_first(partial, failure)
        return (child for child, _ in self.feasible(partial, failure))

    def _best_first(self, partial: _Partial, failure: _Failure) -> Iterator[_Partial]:
        """The feasible children of ``partial`` in the order of their key (score, order), as
        trying and scoring them all, then sorting, would give; each trial, p_stable and
        margin made only when a child could still come before those known.

        A key with each unknown part at a bound below it is a lower bound: the scored parts
        (-p_stable, -margin: the weakest of the plan so far) are never below the partial
        plan's (its weakest); the held blocks of a candidate not yet tried are never fewer
        than 0, of one that does not stand with none held than 1; its rank is never below
        the next untried rank. Of a heap of candidates and children, keyed so, and the next
        untried candidate's bound, the least is taken: a child with every part known comes
        next (nothing left can come before it); else its next part is made (for an untried
        candidate: whether it stands with none held; then its trial; then p_stable; then
        margin) and it goes back."""
        lows = []                       # the best each scored part can be: the weakest so far
        if self.samples is not None:
            lows.append(-min(partial.p_stable, default=math.inf))
        lows.append(-min((r.margin_g for r in partial.reports), default=math.inf))
        total, _, ranks = partial.score[-3:]
        untried = self._states(partial, failure)
        # (key, tie, entry, payload, parts, rank): a candidate that does not stand unheld
        # (its _Trial, s spent on it, None), or a child (its TrialResult until its margin is
        # made, its scored parts so far)
        heap: list = []
        seq = itertools.count()
        after = 0                       # no untried candidate has a rank below this

        def push(entry, payload, parts: list | None, held: int = 0, rank: int = 0) -> None:
            if parts is None:           # a candidate
                key = (*lows, total + held, held, ranks + rank), entry.order
            else:
                known = [max(low, part) for low, part in zip(lows, parts)]
                key = (*known, *lows[len(known):], *entry.score[-3:]), entry.order
            heapq.heappush(heap, (key, next(seq), entry, payload, parts, rank))

        def tried(trial: _Trial, start: float, rank: int) -> None:
            made = self._tried(partial, trial, rank, start, failure)
            if made is not None:
                push(made[0], made[1], [])

        while True:
            bound = ((*lows, total, 0, ranks + after), ()) if untried is not None else None
            if bound is not None and (not heap or bound <= heap[0][0]):
                taken = next(untried, None)
                if taken is None:
                    untried = None
                    continue
                rank, block = taken
                after = rank + 1
                start = time.perf_counter()
                trial = _Trial(self, partial, block)
                if trial.stands(()):
                    tried(trial, start, rank)       # nothing held: its trial is made
                else:
                    push(trial, time.perf_counter() - start, None, 1, rank)
                continue
            if not heap:
                return
            _, _, entry, payload, parts, rank = heapq.heappop(heap)
            if parts is None:
                tried(entry, time.perf_counter() - payload, rank)
                continue
            child, found = entry, payload
            if len(parts) == len(lows):
                child.score = (*(max(low, p) for low, p in zip(lows, parts)),
                               *child.score[-3:])
                yield child
                continue
            if self.samples is not None and not parts:
                p = self.samples.p_stable(self.present(child.order, len(child.order) - 1),
                                          found.held)
                child.p_stable = (*partial.p_stable, p)
                parts.append(-p)
            else:
                found = self.with_margin(found)
                child.reports = (*partial.reports, replace(
                    child.reports[-1], margin_g=found.report.margin_g,
                    margin_direction=found.report.margin_direction))
                parts.append(-found.report.margin_g)
                found = None    # a suspended search keeps no full report or assembly
            push(child, found, parts)

    def _states(self, partial: _Partial, failure: _Failure) -> Iterator[tuple[int, str]]:
        """The candidates (:meth:`candidates`) of ``partial`` in rank order, (rank, block),
        lazily, as the search asks for the next: one whose state is known dead (the memo) is
        skipped unchecked; each other is a state of the budget."""
        tried = 0
        for rank, b in enumerate(self.candidates(partial.order, failure.blocked)):
            tried += 1
            if frozenset((*partial.order, b)) in self.dead:
                failure.dead += 1
                continue
            if self.states >= self.budget:
                raise _Budget
            self.states += 1
            yield rank, b
        if tried and tried == self.plan.candidates:
            failure.proven = False              # candidates beyond the limit not tried

    def feasible(self, partial: _Partial, failure: _Failure
                 ) -> Iterator[tuple[_Partial, TrialResult]]:
        """The feasible children of ``partial`` in rank order, with their trials: its
        candidates (:meth:`_states`) each tried (:meth:`trial`), lazily, as the search asks
        for the next. ``failure`` collects why candidates were refused."""
        for rank, b in self._states(partial, failure):
            start = time.perf_counter()
            made = self._tried(partial, _Trial(self, partial, b), rank, start, failure)
            if made is not None:
                yield made
                made = None     # a suspended search keeps no full report or assembly

    def _tried(self, partial: _Partial, trial: _Trial, rank: int, start: float,
               failure: _Failure) -> tuple[_Partial, TrialResult] | None:
        """The child that ``trial`` (:meth:`trial`) makes of ``partial``, with the trial's
        result; None when it is refused (into ``failure``)."""
        found = self.trial(partial, trial)
        if not found.ok:
            failure.refused(trial.order[-1], found)
            return None
        return self._child(partial, trial.order, found, rank, start), found

    def _child(self, partial: _Partial, order, found: TrialResult, rank: int,
               start: float) -> _Partial:
        """The partial plan ``order`` that ``found`` extends ``partial`` to (its report
        streamed when it is the path's next step)."""
        total, _, ranks = partial.score[-3:]
        report = self.step_report(order, found.held, found.report, found.assembly)
        report = replace(report, solve_time=time.perf_counter() - start)
        checker = copy.copy(partial.checker)
        checker.advance(found.assembly, report)
        if self.streaming and len(partial.order) == self.streamed:
            self.on_report(report)          # the next step of the path: streamed
            self.streamed += 1
        # prefer margin: the scored parts go before it (_best_first)
        score = (total + len(found.held), len(found.held), ranks + rank)
        return _Partial(order, (*partial.held, found.held), score,
                        (*partial.reports, slim(report)), checker)

    def run(self) -> Plan:
        n = self.n = len(self.free)
        # the default budget: the first descent, then backup_budget states more
        self.budget = self.plan.search_budget or math.inf
        final = self.full.subset(self.present(self.free, n + 1))
        self.final = check(final, self.options)
        if not self.final.stable:
            return Plan(False, [], [], "the finished assembly does not stand without holds"
                        f" ({self.final.status.name}: {self.final.message}): no build order"
                        " can end stable", failed_step=n, outcome=NO_PLAN)
        margin = report_margin(self.final, final, self.options.deciding,
                               self.options.margin_directions or DEFAULT_DIRECTIONS) \
            if self.margins else None
        if margin is not None:
            self.final = replace(self.final, margin_g=margin.margin_g,
                                 margin_direction=margin.direction)
        if margin is not None and margin.margin_g < self.plan.min_margin:
            return Plan(False, [], [], f"the finished assembly's margin is "
                        f"{margin.margin_g:.4f} g, below the minimum {self.plan.min_margin:g} g: "
                        "no build order can end with it", failed_step=n, outcome=NO_PLAN)
        root = _Partial((), (), (0, 0, 0), (), StepChecker(self.options, explain=False))
        self.top = self.deepest = root
        self.streaming = self.on_report is not None and self.plan.greedy
        return self._beam(root) if self.plan.beam > 1 else self._depth_first(root)

    def _depth_first(self, root: _Partial) -> Plan:
        """Depth-first search, each partial plan's children in rank order (the first descent
        is the greedy plan). A partial plan with no further child is dead: the set of its
        blocks goes into the memo (whether the rest can be placed depends on that set only:
        any blocks may be held at a step), and the search backs up. Exhausted, with every
        refusal proven: no plan exists."""
        failure = self.failure = _Failure()
        path = [(root, self.expand(root, failure), failure)]
        proven = True
        try:
            while path:
                partial, children, failure = path[-1]
                child = next(children, None)
                if child is None:           # dead: every child tried
                    path.pop()
                    if self.cell_check is None or failure.proven:
                        # a cell's robots depend on the order too: a refusal of theirs
                        # does not make the set of blocks dead
                        self.dead.add(frozenset(partial.order))
                    proven = proven and failure.proven
                    if path:
                        self._backed_up(len(path[-1][0].order))
                    continue
                failure = _Failure()
                if len(child.order) > len(self.deepest.order):
                    self.deepest, self.failure = child, failure
                    self.went_deeper()
                self._pushed(child)
                if len(child.order) == self.n:
                    return self._finish(child, True, -1, f"every step stands with at most "
                                        f"{max(len(h) for h in child.held)} held blocks "
                                        f"(limit {self.plan.max_held})", PLANNED)
                path.append((child, self.expand(child, failure), failure))
                if len(path) > KEPT:
                    # memory linear in the blocks: the kept forces of the last KEPT partial
                    # plans of the path only; a back-up beyond checks its trials whole
                    path[-KEPT - 1][0].checker = StepChecker(self.options, explain=False)
        except _Stopped:
            return self._stopped()
        except _Budget:
            return self._failed(BUDGET_EXHAUSTED, self._over_budget())
        if proven:
            return self._failed(NO_PLAN, f"no plan with at most {self.plan.max_held} held "
                                "exists (every order searched)")
        return self._failed(BUDGET_EXHAUSTED, "no plan found: the search was exhausted, but "
                            "not every refusal is proven (a hold search over its check "
                            "budget, or --candidates)")

    def _beam(self, root: _Partial) -> Plan:
        """Beam search (width > 1): at each step the first ``beam`` children of each partial
        plan, of which the ``beam`` best survive; it does not back up."""
        beam = [root]
        for k in range(self.n):
            self.failure = _Failure()
            self.insertions = {o: f for o, f in self.insertions.items() if len(o) > k}
            children: dict[frozenset, _Partial] = {}
            try:
                for partial in beam:
                    for child in itertools.islice(self.expand(partial, self.failure),
                                                  self.plan.beam):
                        key = frozenset(child.order)
                        if key not in children or child.score < children[key].score:
                            children[key] = child
            except _Stopped:
                return self._stopped()
            except _Budget:
                return self._failed(BUDGET_EXHAUSTED, self._over_budget())
            if not children:
                return self._failed(DEAD_END, f"no plan found by a beam of {self.plan.beam} "
                                    "(it does not back up: --beam 1 does)")
            beam = sorted(children.values(), key=lambda p: (p.score, p.order))[:self.plan.beam]
            self.deepest = beam[0]
            self.went_deeper()
            self._pushed(beam[0])
        best = beam[0]
        return self._finish(best, True, -1, f"every step stands with at most "
                            f"{max((len(h) for h in best.held), default=0)} held blocks "
                            f"(limit {self.plan.max_held})", PLANNED)

    def _over_budget(self) -> str:
        """How the budget ended the search (its states, or the default's stall bound)."""
        if self.stalled:
            return (f"no plan found within the budget (the default's: no deeper partial plan "
                    f"in {self.stall} checks, {self.states} states checked; --search-budget N "
                    "checks N states)")
        return f"no plan found within the budget ({self.budget} states checked; --search-budget N)"

    def _pushed(self, partial: _Partial) -> None:
        """The search went down to ``partial``: its look-ahead, progress."""
        k = len(partial.order)
        self.top = partial
        if self.plan.greedy:
            self.insertions = {o: f for o, f in self.insertions.items() if len(o) > k}
            if self.pool is not None:
                self._look_ahead(partial)
        if not self.backups:
            self.descent = time.perf_counter() - self.start
            self.recent.append(self.descent)
        self._progress(True)

    def _backed_up(self, k: int) -> None:
        """The search backed up to a partial plan of ``k`` blocks: steps streamed beyond it
        are no longer the path's (the plan's reports are re-made at the end)."""
        self.backups += 1
        if self.backups == 1:
            self.backed = (time.perf_counter() - self.start, self.states)
        if not math.isfinite(self.budget):
            self.budget = self.states + backup_budget(self.n)
        if self.streaming and self.streamed > k:
            self.streaming, self.streamed = False, k

    def _progress(self, placing: bool) -> None:
        now = time.perf_counter()
        self.beat = now
        if self.progress is None:
            return
        top, k = self.top, len(self.top.order)
        estimate, bound = self._estimate(now - self.start, k)
        self.progress(PlanProgress(k, self.n, k - 1, top.order[-1] if k else "",
                                   top.held[-1] if k else (), now - self.start, estimate,
                                   self.checks, self.states,
                                   self.budget if math.isfinite(self.budget) else 0,
                                   self.backups,
                                   len(self.deepest.order), placing, bound))

    def _estimate(self, elapsed: float, k: int) -> tuple[float, str]:
        """(s left, what it comes from; -1 and "unknown" when nothing bounds it): see
        :attr:`PlanProgress.estimate`."""
        found = []
        if k and not self.backups:
            # s per block of the first descent, over its last steps (steps grow dearer)
            times = self.recent
            mean = ((times[-1] - times[0]) / (len(times) - 1) if len(times) > 1
                    else self.descent / k)
            if elapsed - self.descent <= 2 * mean + HEARTBEAT:      # not stalled
                found.append((mean * (self.n - k), "steps"))
        if math.isfinite(self.budget):
            # states left at the mean time per state since the first dead end (backing up
            # costs more per state than going down), or since the start before one
            at, since = self.backed if self.backups else (0.0, 0)
            if self.states > since:
                found.append(((self.budget - self.states) * (elapsed - at)
                              / (self.states - since), "budget"))
        if math.isfinite(self.plan.time_limit):
            found.append((max(self.plan.time_limit - elapsed, 0.0), "time limit"))
        done = self.checks - self.deeper
        if self.stuck and done and not any(b == "steps" for _, b in found):
            # the default budget's stall bound (unless it gets deeper first): the checks left
            # at the mean time per check since the search last went deeper
            found.append((max(self.stall - done, 0) * (self.start + elapsed - self.deeper_at)
                          / done, "budget"))
        return min(found, default=(-1.0, "unknown"))

    def _stopped(self) -> Plan:
        """The deepest partial plan, and when candidates of its next step were refused before
        the stop, why the best of them was (as a failed plan says: the holds it needs, a
        robot's wrench against the capacity; the one trial with unbounded robots that this
        takes runs past the stop)."""
        partial, failure = self.deepest, self.failure
        k = len(partial.order)
        head = (f"{STOPPED} {k} of {self.n} blocks (time limit or asked to stop); step {k} "
                "not placed")
        if failure.best is None:
            return self._finish(partial, False, k, head, HALTED)
        self.stopping = True
        why, details = self._why(partial, failure)
        return self._finish(partial, False, k, head + why, HALTED, details)

    def _failed(self, outcome: str, head: str) -> Plan:
        """The plan that failed with ``outcome``: the deepest partial plan, and why no block
        could follow it (its best candidate, the holds it needs, a robot's wrench against
        the capacity)."""
        partial, failure = self.deepest, self.failure
        k = len(partial.order)
        self.stopping = True        # the failure's note is made whatever the bounds
        why, details = self._why(partial, failure)
        message = (f"{head}: the deepest partial plan places {k} of {self.n} blocks "
                   f"({self.states} states checked, {self.backups} dead ends backed out of); "
                   f"no block can be placed at step {k} with at most {self.plan.max_held} "
                   f"held{why}")
        return self._finish(partial, False, k, message, outcome, details)

    def _why(self, partial: _Partial, failure: _Failure) -> tuple[str, dict]:
        """Why no block followed ``partial`` (a message tail) and the failure's details."""
        details = {}
        if failure.best is not None:
            block, held = failure.best
            why = (f"; the best candidate, {block}, needs {len(held)} held "
                   f"block{'' if len(held) == 1 else 's'} ({', '.join(held)})")
            if block in failure.cell:   # it stands with its holds; the cell cannot do it
                why = (f"; the best candidate, {block}, held {', '.join(held) or 'nothing'}: "
                       f"{failure.cell[block]}")
                note, need = "", {}
            elif failure.capacity is not None and (self.options.hold_force_max is not None
                                                   or self.options.hold_torque_max is not None):
                # a robot's capacity refused it: the search's own check names the need
                note, need = self._exceeded(*failure.capacity)
            else:
                try:
                    note, need = self._need(partial, block)
                except _Stopped:
                    note, need = "", {}
            why += note
            details = {"block": block, "held": list(held), **need}   # need's block wins
        elif failure.dead:
            why = (f"; {failure.dead} candidate{'' if failure.dead == 1 else 's'} lead to "
                   "partial plans found dead before")
        else:
            why = "; no unplaced block touches the placed ones" if not failure.blocked else ""
        why += "".join(f"; {b} cannot be inserted: {r}" for b, r in failure.blocked.items())
        return why, details

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

    def _finish(self, partial: _Partial, feasible: bool, failed: int, message: str,
                outcome: str, failure: dict | None = None) -> Plan:
        order, held = list(partial.order), list(partial.held)
        reports, p_stable = list(partial.reports), list(partial.p_stable)
        n = len(order)
        release = feasible and held and held[-1]
        if release:
            held.append(())                          # release step
            if self.samples is not None:        # the finished assembly's
                p_stable.append(self.samples.p_stable(self.present(self.free, n + 1)))
            report = replace(self.final, step_index=n, block_placed="")
            reports.append(slim(report))
            if self.streaming:
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
        if not self.streaming and self.on_report is not None and scene is not None:
            # a beam's steps, and those a search backed up over, are the plan's only once it
            # is chosen: their reports are re-made (those streamed before stay)
            check_sequence(scene, self.options, on_step=lambda r, _total: (
                self.on_report(r) if r.step_index >= self.streamed else None))
        weakest = min((r for r in reports if r.margin_g >= 0),
                      key=lambda r: r.margin_g, default=None)
        return Plan(feasible, order, held, message, failed, scene, reports, self.checks,
                    models=dict(self.models), weakest=weakest, outcome=outcome, states=self.states,
                    backups=self.backups, failure=failure or {}, p_stable=p_stable)


def _with_timeline(plan: Plan, planner: _Planner, cell: Cell) -> Plan:
    """``plan`` with its cell timeline, every state between actions checked; infeasible when
    one falls (the message names the action, robot and block)."""
    scene = plan.scene if plan.scene is not None else planner.base
    timeline = build_timeline(cell, planner.full, planner.base, plan.order, plan.held,
                              planner.options, scene.approach, planner.cell_check.states)
    if plan.feasible and not timeline.feasible:
        plan = replace(plan, feasible=False, message=f"timeline: {timeline.message}",
                       failed_step=timeline.actions[-1].step if timeline.actions else 0)
    elif not plan.feasible and not plan.message.startswith(STOPPED):
        n = len(cell.robots)
        plan = replace(plan, message=f"{plan.message} (a cell of {n} robot{'s' * (n > 1)}: "
                       f"at most {n - 1} hold while one places)")
    return replace(plan, timeline=timeline,
                   scene=scene_with_grips(plan.scene, timeline) if plan.scene else None)


def _planned_under(options: CheckOptions) -> tuple[float, float] | None:
    """The pose uncertainty the plan was checked under, for the planned scene to keep (a scene
    file's, or the command line's, which wins over it)."""
    contact = options.contact
    return ((contact.pose_uncertainty_m, contact.pose_uncertainty_deg) if contact.uncertain
            else None)


def plan_sequence(scene: Scene, max_held: int = 2, options: CheckOptions = CheckOptions(), *,
                  beam: int = 1, candidates: int = 0, keep_sequence: bool = False,
                  full_candidates: bool = False, time_limit: float = math.inf,
                  search_budget: int = 0,
                  progress: Callable[[PlanProgress], None] | None = None,
                  should_stop: Callable[[], bool] | None = None,
                  on_report: Callable[[Report], None] | None = None,
                  look_ahead: Callable[[Assembly, CheckOptions], LookAhead] | None = None,
                  cell: Cell | None = None, prefer: str = "holds",
                  min_margin: float = 0.0, robust: int = 0) -> Plan:
    """An insertion order of every free block of ``scene`` in which each step stands with at
    most ``max_held`` blocks held (see the module docstring), or where none was found.

    ``progress`` is called after each placed step and at least every :data:`HEARTBEAT` s
    while candidates are checked; ``should_stop`` is polled between checks, and when it
    returns True (or ``time_limit`` s have passed) the deepest partial plan is returned (not
    feasible, "stopped after K of N blocks"). ``search_budget``: the states the search may
    check (0: the first descent, then :func:`backup_budget` states, ending a search stuck
    at a step for :data:`STALL` checks). :attr:`Plan.outcome`
    says how the search ended.
    ``on_report`` receives each step's full report as the plan makes it (those of steps
    the search backed up over, and a beam's, after the search). ``look_ahead(assembly,
    options)``: workers for the full checks of the steps ahead
    (:mod:`rbe_ros.analysis.executors`), closed when the plan is made; the plan is the same
    with and without. ``cell``: plan for its robots (at most as many busy as it has, each grip
    within reach, the hand-over states standing) and make the timeline of their actions,
    every state checked (:mod:`rbe_ros.analysis.timeline`). ``prefer``, ``min_margin`` and
    ``robust``: :class:`PlanOptions`."""
    start = time.perf_counter()
    planner = _Planner(scene, declared(options, scene),
                       PlanOptions(max_held, beam, candidates, keep_sequence, full_candidates,
                                   time_limit, search_budget, prefer, min_margin, robust),
                       progress, should_stop, on_report, cell)
    if look_ahead is not None and not full_candidates:
        planner.pool = look_ahead(planner.full, planner.options)
    try:
        result = planner.run()
    finally:
        if planner.pool is not None:
            planner.pool.close()
    if cell is not None:
        result = _with_timeline(result, planner, cell)
    result.time = time.perf_counter() - start
    return result


__all__ = ["BUDGET_EXHAUSTED", "DEAD_END", "HALTED", "LookAhead", "NO_PLAN", "OUTCOMES",
           "PLANNED", "Plan", "PlanOptions", "PlanProgress", "STOPPED", "TrialResult",
           "backup_budget", "plan_sequence"]
