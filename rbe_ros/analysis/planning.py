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
the previous step plus the new block, with more blocks added greedily while the step does
not stand (those the failed check names as moving first), then every hold whose release
keeps the step standing is released, oldest first; if that leaves more than K, the exact
minimal hold search (:func:`rbe_ros.analysis.holds.minimal_holds`, within its budget). A
candidate is feasible with at most K holds, each robot within the hold capacities of the
options (``hold_force_max``, ``hold_torque_max``: see :class:`~rbe_ros.analysis.holds.
StabilityOracle`); when no candidate is, the message names the wrench the best one needs.
Each partial plan keeps the first ``beam`` feasible candidates; of all children the ``beam``
best survive (fewest hold-steps so far, then fewest holds now, then candidate rank).
No child at a step: the plan fails there.

The finished assembly must stand with nothing held; if the last step holds blocks, a release
step follows. The planned scene (sequence = order, holds = the runs of steps each block is
held) is finally checked step by step with :func:`check_sequence`.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..rbe.result import Report
from ..scene import Hold, Scene, SceneError, make_scene
from .asbuilt import declared
from .assembly import Assembly
from .holds import StabilityOracle, minimal_holds, release_unneeded
from .insertion import block_insertion
from .options import CheckOptions
from .pipeline import check_sequence
from .steps import supports_present

#: How the message of a plan stopped by ``should_stop`` begins (a time limit, a cancel).
STOPPED = "stopped after"
#: A contact carries a block when its normal into the block points up by at least this
#: cosine (87 deg from vertical).
RESTS_ON = 0.05


@dataclass(frozen=True)
class PlanOptions:
    """The planner's search: the holds it may use and the width of its beam."""

    max_held: int = 2            # K: blocks held at any step
    beam: int = 1                # partial plans kept per step (1: greedy)
    candidates: int = 8          # insertable candidates tried per partial plan and step
    keep_sequence: bool = False  # the scene's sequence is a fixed prefix of the order

    def __post_init__(self):
        for name, low in (("max_held", 0), ("beam", 1), ("candidates", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError(f"{name} must be an integer >= {low}, not {value!r}")


@dataclass
class Plan:
    """The result of :func:`plan_sequence`. ``held[k]``: blocks held at step k (one more
    entry than ``order`` when a release step follows the last placement)."""

    feasible: bool
    order: list[str]
    held: list[tuple[str, ...]]
    message: str
    failed_step: int = -1                  # first step no candidate can be placed at
    scene: Scene | None = None             # the planned scene (sequence, holds)
    reports: list[Report] = field(default_factory=list)   # check_sequence of ``scene``
    checks: int = 0                        # component checks spent by the search
    time: float = 0.0                      # s

    @property
    def max_held(self) -> int:
        return max((len(h) for h in self.held), default=0)


@dataclass(frozen=True)
class PlanProgress:
    """Where a running plan is, after a placed step: blocks placed of ``total``, the step
    (0-based), the block placed there and the blocks held at it, seconds since the start."""

    placed: int
    total: int
    step: int
    block: str
    held: tuple[str, ...]
    elapsed: float


@dataclass(frozen=True)
class _Partial:
    order: tuple[str, ...]
    held: tuple[tuple[str, ...], ...]
    score: tuple


class _Planner:
    def __init__(self, scene: Scene, options: CheckOptions, plan: PlanOptions,
                 progress: Callable[[PlanProgress], None] | None = None,
                 should_stop: Callable[[], bool] | None = None):
        self.scene, self.options, self.plan = scene, options, plan
        self.progress, self.should_stop = progress, should_stop
        self.start = time.perf_counter()
        # holds of free blocks are the planner's; those of supports stay (scaffolds)
        supports = {b.id for b in scene.blocks if b.support}
        self.base = make_scene(scene.name, scene.blocks, scene.gravity, (),
                               [h for h in scene.holds if h.block in supports])
        self.full = Assembly.from_scene(self.base, options.contact)
        self.ids = [b.id for b in self.full.blocks]
        self.position = {bid: k for k, bid in enumerate(self.ids)}
        self.free = [b.id for b in self.full.blocks if not b.support]
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
        self.checks = 0

    def present(self, order, k: int) -> tuple[str, ...]:
        """The supports present at step ``k`` (those with holds while active) and ``order``."""
        return supports_present(self.base, k) + tuple(order)

    def candidates(self, order: tuple[str, ...], blocked: dict[str, str]) -> list[str]:
        """The first ``candidates`` blocks, in rank order, that can reach their pose; those
        that cannot go into ``blocked`` with the reason."""
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

    def insertable(self, order, ranked, blocked: dict[str, str]) -> list[str]:
        """The first ``candidates`` of ``ranked`` that can reach their pose after ``order``."""
        found = []
        for b in ranked:
            why = self.blocked((*order, b))
            if why:
                blocked.setdefault(b, why)
                continue
            found.append(b)
            if len(found) == self.plan.candidates:
                break
        return found

    def blocked(self, order: tuple[str, ...]) -> str:
        """Why ``order[-1]`` cannot reach its pose past the blocks present ("" when it can,
        or when insertion is not checked)."""
        if not self.options.insertion.enabled:
            return ""
        found = block_insertion(self.full, self.present(order, len(order) - 1), order[-1],
                                self.options, self.scene.approach_of(order[-1]))
        return "" if found.insertable else found.reason

    def holds_for(self, order: tuple[str, ...], previous: tuple[str, ...], options=None):
        """(held blocks, within K) for the step that places ``order[-1]`` (under ``options``,
        default the plan's)."""
        k = len(order) - 1
        options = options or self.options
        assembly = self.full.subset(self.present(order, k))
        oracle = StabilityOracle(assembly, options, self.cache)
        try:
            held = self._repair(oracle, order[-1], previous)
            if len(held) > self.plan.max_held or not oracle.stands(self._indices(oracle, held)):
                result = minimal_holds(assembly, options, prefer=(*previous, order[-1]),
                                       oracle=oracle)
                if result.stands and (len(result.blocks) < len(held)
                                      or not oracle.stands(self._indices(oracle, held))):
                    held = result.blocks
            ok = len(held) <= self.plan.max_held and oracle.stands(self._indices(oracle, held))
        finally:
            self.checks += oracle.checks
        return held, ok

    @staticmethod
    def _indices(oracle: StabilityOracle, held) -> list[int]:
        return [oracle.index[b] for b in held]

    def _capacity_note(self, order: tuple[str, ...], previous) -> str:
        """What the robots would need beyond their capacities at the step that places
        ``order[-1]``, held as the plan would hold it with unbounded robots ("" when the
        capacities are unbounded, or that needs more than K holds or is within them)."""
        if self.options.hold_force_max is None and self.options.hold_torque_max is None:
            return ""
        unbounded = replace(self.options, hold_force_max=None, hold_torque_max=None)
        held, ok = self.holds_for(order, previous, unbounded)
        oracle = StabilityOracle(self.full.subset(self.present(order, len(order) - 1)),
                                 self.options, self.cache)
        over = oracle.capacity(self._indices(oracle, held)) if ok else None
        return (f"; with {', '.join(held)} held (fewest with unbounded robots), {over.message}"
                if over is not None else "")

    def _repair(self, oracle: StabilityOracle, new: str, previous) -> tuple[str, ...]:
        if oracle.stands(()):
            return ()
        held = [oracle.index[b] for b in previous if b in oracle.index] + [oracle.index[new]]
        while True:
            fails = oracle.failing(held)
            if not fails:
                break
            comp, report = fails[0]
            if not comp:            # a robot over its capacity that no other hold can relieve
                break
            named = [oracle.index[b] for b in report.unstable_blocks
                     if b in oracle.index and oracle.index[b] in comp]
            held.append(sorted(named or comp, key=lambda j: (-oracle.height[j], j))[0])
        held = release_unneeded(oracle, held)
        return tuple(oracle.ids[j] for j in sorted(held))

    def run(self) -> Plan:
        n = len(self.free)
        beam = [_Partial((), (), (0, 0, 0))]
        final = self.full.subset(self.present(self.free, n + 1))
        if not StabilityOracle(final, self.options, self.cache).stands(()):
            return Plan(False, [], [], "the finished assembly does not stand without holds "
                        "(rbe-ros check names why): no build order can end stable",
                        failed_step=n)
        for k in range(n):
            children: dict[frozenset, _Partial] = {}
            best_rejected = None
            blocked: dict[str, str] = {}
            for partial in beam:
                found = 0
                previous = partial.held[-1] if partial.held else ()
                for rank, b in enumerate(self.candidates(partial.order, blocked)):
                    if self.should_stop is not None and self.should_stop():
                        return self._finish(beam[0], False, k,
                                            f"{STOPPED} {k} of {n} blocks")
                    order = (*partial.order, b)
                    held, ok = self.holds_for(order, previous)
                    if not ok:
                        if best_rejected is None or len(held) < len(best_rejected[1]):
                            best_rejected = (b, held)
                        continue
                    total, worst, ranks = partial.score
                    child = _Partial(order, (*partial.held, held),
                                     (total + len(held), len(held), ranks + rank))
                    key = frozenset(order)
                    if key not in children or child.score < children[key].score:
                        children[key] = child
                    found += 1
                    if found >= self.plan.beam:
                        break
            if not children:
                best = beam[0]
                count = len(best_rejected[1]) if best_rejected else 0
                why = (f"; the best candidate, {best_rejected[0]}, needs {count} held "
                       f"block{'' if count == 1 else 's'} ({', '.join(best_rejected[1])})"
                       + self._capacity_note((*best.order, best_rejected[0]),
                                             best.held[-1] if best.held else ())
                       if best_rejected else
                       "; no unplaced block touches the placed ones" if not blocked else "")
                why += "".join(f"; {b} cannot be inserted: {r}" for b, r in blocked.items())
                return self._finish(best, False, k, f"no block can be placed at step {k} with "
                                    f"at most {self.plan.max_held} held{why}")
            beam = sorted(children.values(), key=lambda p: (p.score, p.order))[:self.plan.beam]
            if self.progress is not None:
                self.progress(PlanProgress(k + 1, n, k, beam[0].order[-1], beam[0].held[-1],
                                           time.perf_counter() - self.start))
        best = beam[0]
        return self._finish(best, True, -1, f"every step stands with at most "
                            f"{max((len(h) for h in best.held), default=0)} held blocks "
                            f"(limit {self.plan.max_held})")

    def _finish(self, partial: _Partial, feasible: bool, failed: int, message: str) -> Plan:
        order, held = list(partial.order), list(partial.held)
        n = len(order)
        if feasible and held and held[-1]:
            held.append(())                          # release step
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
        reports = check_sequence(scene, self.options) if scene is not None else []
        if feasible and not all(r.stable and r.insertable for r in reports):
            bad = next(r for r in reports if not (r.stable and r.insertable))
            feasible, failed = False, bad.step_index
            message = f"the plan does not re-check stable at step {failed}: {bad.message}"
        if scene is not None and self.options.insertion.enabled:
            # each step's direction, as checked (a given one kept), for a robot to follow
            scene = replace(scene, approach=tuple(
                r.insertion_direction if r.insertable else None for r in reports[:n]))
        return Plan(feasible, order, held, message, failed, scene, reports, self.checks)


def _planned_under(options: CheckOptions) -> tuple[float, float] | None:
    """The pose uncertainty the plan was checked under, for the planned scene to keep (a scene
    file's, or the command line's, which wins over it)."""
    contact = options.contact
    return ((contact.pose_uncertainty_m, contact.pose_uncertainty_deg) if contact.uncertain
            else None)


def plan_sequence(scene: Scene, max_held: int = 2, options: CheckOptions = CheckOptions(), *,
                  beam: int = 1, candidates: int = 8, keep_sequence: bool = False,
                  progress: Callable[[PlanProgress], None] | None = None,
                  should_stop: Callable[[], bool] | None = None) -> Plan:
    """An insertion order of every free block of ``scene`` in which each step stands with at
    most ``max_held`` blocks held (see the module docstring), or where none was found.
    ``progress`` is called after each placed step; ``should_stop`` is polled between
    candidate checks: when true, the best partial plan so far is returned (not feasible,
    "stopped after K of N blocks", ``failed_step`` K: the first step not planned)."""
    start = time.perf_counter()
    result = _Planner(scene, declared(options, scene),
                      PlanOptions(max_held, beam, candidates, keep_sequence),
                      progress, should_stop).run()
    result.time = time.perf_counter() - start
    return result


__all__ = ["Plan", "PlanOptions", "PlanProgress", "STOPPED", "plan_sequence"]
