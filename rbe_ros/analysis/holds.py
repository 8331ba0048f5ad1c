"""The smallest set of blocks to hold so that an unstable assembly (or step) stands.

Holding a block makes it a support (a robot or a scaffold takes any force on it). The free
blocks of an assembly fall apart into *components*: sets of free blocks joined by contacts
between free blocks; supports and held blocks separate them. The equilibrium problem is
separable by component (the objective and the constraints of one component do not involve
the others), so the assembly stands exactly when every component, with the supports it
touches, stands. :class:`StabilityOracle` checks components with the plain checker
(:func:`rbe_ros.analysis.verdict.check`) and caches each verdict by (free blocks, supports
touched), so a hold that splits one component does not re-solve the others.

Exact search (:func:`minimal_holds`): iterative deepening on the number of held blocks with
a hitting-set branching rule. If holding S leaves a failing component C, every hold set
T containing S that stands must hold a block of C (a superset of S that holds nothing in C
leaves C, and the supports it touches, unchanged, so C still fails). So the search branches
on the blocks of the smallest failing component only, and prunes a set S when it leaves
more failing components (which are disjoint) than the blocks it may still add. Every
minimal set is reachable that way, so the first set found at depth d is a minimum. The
search is exact while it stays within ``HoldSearch.max_size`` blocks and
``HoldSearch.max_checks`` component checks.

With hold capacities (``CheckOptions.hold_force_max``, ``hold_torque_max``) a hold set must
also keep every robot within them: the components are no longer separable (a held block's
wrench balances the forces of every component it touches), so a set whose components all
stand is checked once more as a whole, a grip on each held block (cached). When that is
HOLD_EXCEEDED, the components touching the blocks over capacity count as one failing
component: only a hold among them can take load off those blocks.

Beyond that budget, a greedy heuristic: repeatedly hold the candidate that leaves the
fewest free blocks in failing components (ties: least tension, then candidate order),
evaluating up to ``greedy_width`` candidates: first the blocks the failed check names as
moving (``unstable_blocks``, from the friction+ explanation), then the other blocks of the
smallest failing component, each group highest first. Finally each held block whose release
keeps the assembly standing is released (the result is minimal by inclusion, not necessarily in
size). Both parts count checks, not seconds, so results do not depend on the machine.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..rbe.model import Grip
from ..rbe.result import Report, Status
from .assembly import Assembly
from .graph import ContactGraph
from .options import CheckOptions, HoldSearch
from .verdict import check, is_stable

#: Reports whose verdict a hold can change (not solver failures or bad input).
HOLDABLE = (Status.TENSION_REQUIRED, Status.FRICTION_EXCEEDED, Status.INFEASIBLE)


class _Budget(Exception):
    pass


@dataclass(frozen=True)
class HoldResult:
    """Blocks to hold (assembly order), whether the set is a proven minimum, and the
    number of component checks spent."""

    blocks: tuple[str, ...]
    exact: bool
    checks: int
    stands: bool = True        # False: even the returned set does not make it stand
    #: no set of at most this many blocks stands: proven by the exact search (each depth up
    #: to it searched whole), -1: nothing proven. A planner's proof that a step needs more
    #: than K holds.
    none_within: int = -1


class StabilityOracle:
    """Verdicts of an assembly with extra blocks held, by component, cached.

    ``cache``: a dict shared by oracles of sub-assemblies of one assembly (the steps of a
    plan): a component's problem depends only on the ids of its blocks and of the supports
    it touches, so verdicts carry over from step to step."""

    def __init__(self, assembly: Assembly, options: CheckOptions = CheckOptions(),
                 cache: dict | None = None, on_check: Callable[[], None] | None = None):
        self.assembly = assembly
        #: called before each check that is not cached (a planner counts it, and stops
        #: there by raising when its time is up)
        self.on_check = on_check
        self.options = options
        self.graph = ContactGraph(assembly)
        self.ids = self.graph.ids
        self.index = assembly.index
        self.support = self.graph.support
        self.height = np.array([-(b.centroid @ assembly.gravity) for b in assembly.blocks]) \
            if assembly.blocks else np.zeros(0)
        self.checks = 0
        self._shared = {} if cache is None else cache   # (free ids, touched ids) -> verdict
        self._cache: dict[tuple[frozenset, frozenset], Report] = {}
        #: the HOLD_EXCEEDED reports met, by the blocks held (ids): what a robot would need
        self.exceeded: dict[frozenset, Report] = {}

    def components(self, held) -> list[tuple[frozenset, frozenset]]:
        """(free blocks, supports and held blocks they touch) of each component, by index."""
        return self.graph.components(held)

    def _sub(self, component) -> Assembly:
        free, touched = component
        ids = [self.ids[k] for k in sorted(free | touched)]
        return self.assembly.subset(ids, [self.ids[k] for k in touched if not self.support[k]])

    def _key(self, component) -> tuple[frozenset, frozenset]:
        free, touched = component
        return (frozenset(self.ids[k] for k in free), frozenset(self.ids[k] for k in touched))

    def verdict(self, component: tuple[frozenset, frozenset]) -> bool:
        """Whether one component, with the supports it touches, stands (cached). The verdict
        of the plain check without its explanation: the primary solve and the post-check."""
        key = self._key(component)
        found = self._shared.get(key)
        if found is None:
            self._count()
            found = is_stable(self._sub(component), self.options)
            self._shared[key] = found
        return found

    def report(self, component: tuple[frozenset, frozenset]) -> Report:
        """The plain check of one component (cached): the explanation of a failure."""
        found = self._cache.get(component)
        if found is None:
            self._count()
            found = check(self._sub(component), self.options)
            self._cache[component] = found
            self._shared.setdefault(self._key(component), found.stable)
        return found

    def failing(self, held, *, explain: bool = True) -> list[tuple[frozenset, Report | None]]:
        """The components that do not stand with ``held`` (indices) held, smallest first,
        with their reports (``explain``) or None; when all stand but a robot's wrench is
        over its capacity, the components touching the blocks over it, as one."""
        out = []
        components = self.components(held)
        for comp in components:
            if not self.verdict(comp):
                out.append((comp[0], self.report(comp) if explain else None))
        if not out:
            over = self.capacity(held)
            if over is not None:
                blocks = {self.index[b] for b in over.unstable_blocks}
                near = frozenset().union(*(free for free, touched in components
                                           if touched & blocks))
                out.append((near, over))
        return sorted(out, key=lambda c: (len(c[0]), min(c[0], default=-1)))

    def stands(self, held) -> bool:
        return (all(self.verdict(comp) for comp in self.components(held))
                and self.capacity(held) is None)

    def capacity(self, held) -> Report | None:
        """The HOLD_EXCEEDED report of the whole assembly with a robot's grip (at the
        centroid) on each block of ``held`` (indices) and on those it holds already, when
        the options bound the wrenches and one is over; else None (cached)."""
        options = self.options
        if not held or (options.hold_force_max is None and options.hold_torque_max is None):
            return None
        names = {self.ids[k] for k in held}
        key = ("capacity", frozenset(self.ids), frozenset(names))
        if key not in self._shared:
            self._count()
            grips = [*self.assembly.grips, *(Grip(b) for b in sorted(names))]
            whole = self.assembly.subset(self.ids, names | {g.block for g in grips}, grips)
            report = check(whole, options)
            self._shared[key] = report if report.status == Status.HOLD_EXCEEDED else None
        found = self._shared[key]
        if found is not None:
            self.exceeded[frozenset(names)] = found
        return found

    def _count(self) -> None:
        self.checks += 1
        if self.on_check is not None:
            self.on_check()


def minimal_holds(assembly: Assembly, options: CheckOptions = CheckOptions(), *,
                  search: HoldSearch | None = None, prefer=(),
                  oracle: StabilityOracle | None = None, largest: int | None = None
                  ) -> HoldResult:
    """The smallest set of free blocks of ``assembly`` to hold so that it stands (empty if
    it stands). ``prefer``: block ids tried first (e.g. the blocks held at the previous
    step, so that a robot keeps its grip). ``largest``: only sets of at most this many
    blocks matter (a planner's K): the exact search goes that deep (at most
    ``search.max_size``), the greedy heuristic
    runs only when the exact search ran out of checks and stops beyond it, and none found
    is a set that does not stand, ``none_within`` saying what was proven. See the module
    docstring for the method."""
    search = options.holds if search is None else search
    oracle = oracle or StabilityOracle(assembly, options)
    first = oracle.failing(())
    if not first:
        return HoldResult((), True, oracle.checks)
    preferred = [oracle.index[b] for b in prefer if b in oracle.index
                 and not oracle.support[oracle.index[b]]]
    budget = oracle.checks + search.max_checks
    lower = len(first)            # disjoint failing components: one block each at least
    proven = lower - 1
    deepest = search.max_size if largest is None else min(search.max_size, largest)
    for depth in range(lower, deepest + 1):
        try:
            found = _deepen(oracle, frozenset(), depth, preferred, budget, set())
        except _Budget:
            break
        if found is not None:
            return HoldResult(_names(oracle, found), True, oracle.checks)
        proven = depth
    if largest is not None and proven >= largest:
        return HoldResult((), False, oracle.checks, False, proven)
    held = _greedy(oracle, preferred, search.greedy_width, largest)
    stands = (largest is None or len(held) <= largest) and oracle.stands(held)
    return HoldResult(_names(oracle, held), False, oracle.checks, stands, proven)


def _names(oracle: StabilityOracle, held) -> tuple[str, ...]:
    return tuple(oracle.ids[k] for k in sorted(held))


def _order(oracle: StabilityOracle, comp: frozenset, report: Report, preferred) -> list[int]:
    """Candidates of a failing component: preferred, then the blocks the check names as
    moving, then the rest, each group highest first."""
    def top_down(ks):
        return sorted(ks, key=lambda k: (-oracle.height[k], k))

    named = top_down(oracle.index[b] for b in report.unstable_blocks if b in oracle.index)
    rest = top_down(comp)
    out, seen = [], set()
    for k in [*preferred, *named, *rest]:
        if k in comp and k not in seen:
            seen.add(k)
            out.append(k)
    return out


def _deepen(oracle, held: frozenset, depth: int, preferred, budget: int, visited: set):
    fails = oracle.failing(held, explain=False)
    if not fails:
        return held
    if len(fails) > depth - len(held):
        return None
    comp, report = fails[0]
    if report is None:
        report = oracle.report(next(c for c in oracle.components(held) if c[0] == comp))
    for k in _order(oracle, comp, report, preferred):
        nxt = held | {k}
        if nxt in visited:
            continue
        visited.add(nxt)
        if oracle.checks >= budget:
            raise _Budget
        found = _deepen(oracle, nxt, depth, preferred, budget, visited)
        if found is not None:
            return found
    return None


def _greedy(oracle: StabilityOracle, preferred, width: int, largest: int | None = None
            ) -> frozenset:
    held: list[int] = []
    while True:
        fails = oracle.failing(held)
        if not fails or (largest is not None and len(held) > largest):
            break
        candidates: list[int] = []
        for comp, report in fails:
            for k in _order(oracle, comp, report, preferred):
                if k not in candidates:
                    candidates.append(k)
        best = _best_hold(oracle, held, candidates[:max(width, 1)])
        if best is None:        # a robot over its capacity that no other hold can relieve
            break
        held.append(best)
    return frozenset(release_unneeded(oracle, held))


def _best_hold(oracle: StabilityOracle, held: list[int], candidates: list[int]) -> int | None:
    """The candidate whose hold leaves the fewest free blocks in failing components, then
    the least tension, then the first. The tension needs each failing component's
    explanation (a check with up to two more solves): only candidates tied on the fewest
    blocks are explained, and none when they leave nothing failing (the first then wins)."""
    sizes = [sum(len(c) for c, _ in oracle.failing(held + [k], explain=False))
             for k in candidates]
    fewest = min(sizes, default=None)
    tied = [k for k, size in zip(candidates, sizes) if size == fewest]
    if len(tied) <= 1 or fewest == 0:
        return tied[0] if tied else None
    return min(tied, key=lambda k: sum(r.max_tension
                                      for _, r in oracle.failing(held + [k], explain=True)))


def release_unneeded(oracle: StabilityOracle, held: list[int]) -> list[int]:
    """``held`` without every hold whose release keeps the assembly standing, tried earliest
    hold first: minimal by inclusion."""
    for k in list(held):
        trial = [j for j in held if j != k]
        if oracle.stands(trial):
            held = trial
    return held


def suggested_holds(report: Report, assembly: Assembly, options: CheckOptions
                    ) -> tuple[str, ...]:
    """The smallest set of further blocks to hold so that ``assembly`` (the checked one,
    its held blocks as supports) stands, when ``report`` is unstable in a way a hold can
    change and the search is on; else none."""
    free = sum(not b.support for b in assembly.blocks)
    if (options.holds.enabled and not report.stable and report.status in HOLDABLE
            and free <= options.holds.max_free_blocks):
        result = minimal_holds(assembly, options)
        if result.stands:
            return result.blocks
    return ()


__all__ = ["HoldResult", "StabilityOracle", "minimal_holds", "release_unneeded",
           "suggested_holds"]
