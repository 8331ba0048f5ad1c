"""Per-step checks that model no more of the assembly than the step needs.

A step adds blocks to an assembly that stood, at an earlier step, with admissible forces.
Two small problems on a region R of free blocks around the new ones often settle the verdict
without the full problem:

* restriction (sufficient, by the safe theorem): keep the earlier forces on every interface
  outside R, apply those on R's boundary as known loads, and solve R alone. Feasible: an
  admissible state of the whole assembly exists. It stands (STABLE, model "local N") when
  that state needs no friction (beyond the noise floor, or mu is infinite): the placement
  test (rbe/prestress.py) does not compose over regions, since the kept friction on R's
  boundary is friction the whole, set in place from rest, must build up again; a state
  that needs friction goes on to the relaxation and the full problems. So friction is
  tested first: kept outside R (then R is not even solved), then in R's field, and only
  a state without it meets the placement test (passed at its first step, without a solve).
* relaxation (necessary): solve R with every neighbour outside it made rigid (a support).
  Infeasible: the whole assembly is infeasible too, so it does not stand (model "relaxed N").

Free blocks joined by contacts form components (supports cut them apart), whose problems
share no variable and no constraint. R starts as the new blocks, their free neighbours and a
shortest chain of contacts down to a support, and grows by layers of neighbours until one of
the two answers, up to MAX_LOCAL_SHARE of the components holding the new blocks (no regions
when those have fewer than MIN_LOCAL_BLOCKS free blocks). Then those components are solved in
full and the others keep their forces (they stood at the last stable step and nothing about
them changed): exact both ways, "local N" when they stand, "relaxed N" when not. Only when
the new blocks' components hold every free block is the full problem solved. The verdict
(stable or not) is therefore always the full problem's; a local report's forces are one
admissible state, not the full QP optimum, and a relaxed report's interfaces are those of the
region only.
"""
from __future__ import annotations

import collections
import math
from dataclasses import replace

import numpy as np

from ..geometry.polygon import cross
from ..rbe.model import build_model, free_weight
from ..rbe.prestress import no_caps_bound, placed
from ..rbe.result import InterfaceResult, Report, Status
from .assembly import Assembly
from .graph import ContactGraph
from .options import CheckOptions
from .verdict import admissible_forces, check, infeasible_report

#: Local regions larger than this share of the free blocks joined to the new ones (their
#: component) go to the component's full problem: every failed local attempt costs two
#: solves, so regions stay small.
MAX_LOCAL_SHARE = 0.3
#: Below this many free blocks in the component its full problem is as cheap as the local
#: ones, and its report (all its interfaces, the QP optimum) is the more useful: no regions.
MIN_LOCAL_BLOCKS = 20


def _key(assembly: Assembly, it) -> tuple:
    return assembly.blocks[it.a].id, assembly.blocks[it.b].id, it.frame.origin.tobytes()


class StepChecker:
    """Checks successive, growing assemblies, reusing the last admissible state.

    A free block is *balanced* by the kept state when it was free then and every one of its
    interfaces now was kept (no new contact, no support taken away, not released from a
    hold); the blocks that are not form the step's new blocks. A hold added since (a free
    block made a support) keeps the others balanced: its kept forces stay as loads on them.
    """

    def __init__(self, options: CheckOptions = CheckOptions(), *, local: bool = True,
                 explain: bool = True):
        self.options = options
        self.local = local
        self.explain = explain      # False: a relaxation's failure is not explained
        self._results: dict[tuple, InterfaceResult] | None = None   # last admissible state
        self._free: frozenset[str] = frozenset()          # free blocks it balanced
        self._count: dict[str, int] = {}                  # their interfaces then
        self._previous: frozenset[str] = frozenset()     # blocks of the last step checked
        self._last_failed = False

    def check(self, assembly: Assembly, whole: Report | None = None) -> Report:
        """The verdict of ``assembly``, the next step after the ones checked before.
        ``whole``: the full problem's report of it (:func:`check` under these options),
        made before: the one taken where the regions do not settle the step."""
        report = self.attempt(assembly) if self.local else None
        if report is None:
            report = whole if whole is not None else check(assembly, self.options)
        self.advance(assembly, report)
        return replace(report, num_blocks=len(assembly.blocks))

    def attempt(self, assembly: Assembly, around=(), *, restrict: bool = True
                ) -> Report | None:
        """The verdict of ``assembly`` from the kept state and models smaller than the whole
        (None when only the full problem settles it); nothing is remembered. ``around``:
        ids of blocks whose forces the change likely moves too (the planner's open course,
        carried between two holds), tried first as a region with the new blocks.
        ``restrict`` False: only the relaxations of those two regions (when a restriction is
        known not to settle such a step, only a failure is worth proving)."""
        # held blocks with grips: their wrenches come from the whole problem (a local one
        # would take them as supports)
        if self._results is None or assembly.grips:
            return None
        graph = ContactGraph(assembly)
        new = self._new_blocks(assembly, graph)
        if not new:                       # nothing changed for any free block
            return self._kept_elsewhere(assembly, assembly, [], 0, 0.0, "no block moved")
        first = set(new) | {k for k in graph.free if assembly.blocks[k].id in set(around)}
        if not restrict:
            return next(filter(None, (self._relaxed(assembly, graph, region)
                                      for region in (set(new), first))), None)
        # a restriction's region passes the placement test (rbe/prestress.py) under the
        # kept forces of the rest as loads: the step from the previous step's forces
        return self._local(assembly, graph, new, first)

    def advance(self, assembly: Assembly, report: Report) -> None:
        """Take ``report`` (of ``assembly``) as the step reached: kept if it stands."""
        self._last_failed = not report.stable
        self._previous = frozenset(b.id for b in assembly.blocks)
        if report.stable:
            self._remember(assembly, report)

    def _new_blocks(self, assembly: Assembly, graph: ContactGraph) -> list[int]:
        """Free blocks the kept state does not balance (see the class docstring)."""
        count = [0] * len(assembly.blocks)
        missing = set()
        for it in assembly.interfaces:
            count[it.a] += 1
            count[it.b] += 1
            if _key(assembly, it) not in self._results:
                missing.update((it.a, it.b))
        return [k for k in graph.free
                if k in missing or assembly.blocks[k].id not in self._free
                or count[k] != self._count[assembly.blocks[k].id]]

    def _remember(self, assembly: Assembly, report: Report) -> None:
        self._results = {_key(assembly, it): r for it, r in zip(assembly.interfaces,
                                                                report.interfaces)}
        count = collections.Counter()
        for it in assembly.interfaces:
            count[it.a] += 1
            count[it.b] += 1
        self._free = frozenset(b.id for b in assembly.blocks if not b.support)
        self._count = {b.id: count[k] for k, b in enumerate(assembly.blocks) if not b.support}

    def _local(self, assembly: Assembly, graph: ContactGraph, new: list[int],
               first: set[int] = frozenset()) -> Report | None:
        component = graph.component(set(new) | graph.free_neighbours(new))
        report = self._region(assembly, graph, new, component, first) \
            if len(component) >= MIN_LOCAL_BLOCKS else None
        if report is None and len(component) < len(graph.free):
            report = self._component(assembly, graph, component)
        return report

    def _region(self, assembly: Assembly, graph: ContactGraph, new: list[int],
                component: set[int], first: set[int] = frozenset()) -> Report | None:
        """The report of the first region around ``new`` that settles the step, up to
        MAX_LOCAL_SHARE of ``component`` (the free blocks joined to the new ones); ``first``
        (with ``new``) is tried before."""
        # after a failure the next step tends to fail too: then try the cheap proofs of that
        # first, the block placed now on rigid neighbours (one block: a tiny problem), then
        # every block placed since the last stable step; after a success, the proof of stability
        if self._last_failed:
            placed = {k for k in new if assembly.blocks[k].id not in self._previous}
            for region in ([placed] if placed and len(placed) < len(new) else []) + [set(new)]:
                report = self._relaxed(assembly, graph, region)
                if report is not None:
                    return report
        no_caps = self._no_caps(assembly)
        if len(first) > len(new):
            report = (self._restricted(assembly, graph, first, no_caps)
                      or self._relaxed(assembly, graph, first))
            if report is not None:
                return report
        region = set(new) | graph.free_neighbours(new) | graph.path_to_support(new)
        limit = MAX_LOCAL_SHARE * len(component)
        while len(region) <= limit and not component <= region:
            report = (self._restricted(assembly, graph, region, no_caps)
                      or self._relaxed(assembly, graph, region))
            if report is not None:
                return report
            region = region | graph.free_neighbours(region)
        return None

    def _no_caps(self, assembly: Assembly) -> tuple[dict[tuple, float], set[tuple]] | None:
        """For a finite mu, per interface key of ``assembly`` the friction up to which a
        field keeps the placement test's first caps (none: prestress.no_caps_bound), and the
        keys of the kept interfaces that carry more: a region that keeps one of them settles
        nothing. Made once per step for all its regions. None for an infinite mu (nothing
        can slide)."""
        if not math.isfinite(self.options.deciding.mu):
            return None
        free = [k for k, b in enumerate(assembly.blocks) if not b.support]
        bound = no_caps_bound(assembly.blocks, assembly.interfaces, free,
                              free_weight(assembly.blocks, free, assembly.gravity))
        limits = {_key(assembly, it): limit for it, limit in zip(assembly.interfaces, bound)}
        return limits, {key for key, limit in limits.items()
                        if key in self._results
                        and np.linalg.norm(self._results[key].shear) > limit}

    def _restricted(self, assembly: Assembly, graph: ContactGraph, region: set[int],
                    no_caps: tuple[dict[tuple, float], set[tuple]] | None) -> Report | None:
        """Stable report if R alone, loaded by the kept forces on its boundary, stands with
        no friction beyond the floor anywhere (``no_caps``: see :meth:`_no_caps`; None: mu
        is infinite). Friction is tested first, kept then solved, so that a region whose
        field needs it costs no placement test, or no solve at all."""
        ids = {assembly.blocks[k].id for k in region | graph.support_neighbours(region)}
        local = assembly.subset(ids)
        if no_caps is not None and not no_caps[1] <= {_key(local, it) for it in local.interfaces}:
            return None                       # kept friction outside R: kept in the whole
        wrenches: dict[int, np.ndarray] = {}
        for it in assembly.interfaces:
            inside_a, inside_b = it.a in region, it.b in region
            if inside_a == inside_b or (assembly.blocks[it.b if inside_a else it.a].support):
                continue                      # internal, outside, or to a support (in the model)
            kept = self._results.get(_key(assembly, it))
            if kept is None:
                return None                   # a new contact to the outside: not this region
            j, sign = (it.b, 1.0) if inside_b else (it.a, -1.0)
            wrench = wrenches.setdefault(local.index[assembly.blocks[j].id], np.zeros(6))
            forces = sign * (kept.normal_forces[:, None] * kept.normal + kept.tangential_forces)
            wrench[:3] += forces.sum(axis=0)
            wrench[3:] += cross(kept.polygon - assembly.blocks[j].centroid, forces).sum(axis=0)
        model = build_model(local.blocks, local.interfaces, local.gravity)
        load = model.dead_load + model.wrench_load(wrenches)
        found = admissible_forces(model, self.options, load)
        if found is None:
            return None
        solution, results = found
        if no_caps is not None and any(np.linalg.norm(r.shear) > no_caps[0][_key(local, it)]
                                       for it, r in zip(local.interfaces, results)):
            return None
        # stable_forces' placement test, after the friction that makes it needless (a
        # field without friction passes at its first step, without a solve)
        if not placed(model, self.options.deciding, load, solution).stands:
            return None
        return self._kept_elsewhere(assembly, local, results, len(region),
                                    max(float(solution.forces[1].max(initial=0.0)), 0.0),
                                    f"{_blocks(len(region))} around the new one re-solved")

    def _component(self, assembly: Assembly, graph: ContactGraph,
                   component: set[int]) -> Report | None:
        """The exact verdict from the components holding the new blocks, solved in full; no
        contact joins them to the other components, whose kept forces stay admissible. None
        if the solver failed (the full problem is tried then)."""
        local = assembly.subset({assembly.blocks[k].id
                                 for k in component | graph.support_neighbours(component)})
        report = check(local, self.options)
        if report.status == Status.SOLVER_FAILED:
            return None
        which = (f"the {len(component)} blocks joined to the new one by contacts"
                 if len(component) > 1 else "the new block alone (it touches no other free block)")
        if report.stable:
            return self._kept_elsewhere(assembly, local, report.interfaces, len(component),
                                        report.max_tension, f"{which} solved in full")
        return replace(report, message=f"{report.message} [{which}, solved in full]",
                       model=f"relaxed {len(component)}")

    def _kept_elsewhere(self, assembly: Assembly, local: Assembly, results, size: int,
                        max_tension: float, how: str) -> Report | None:
        """Stable report of the forces ``results`` on the interfaces of ``local`` (``size``
        blocks re-solved, ``how`` says which) and the kept ones everywhere else (None if one
        is not kept)."""
        solved = {_key(local, it): r for it, r in zip(local.interfaces, results)}
        merged = [solved.get(key) or self._results.get(key)
                  for key in (_key(assembly, it) for it in assembly.interfaces)]
        if None in merged:
            return None
        worst = max((r.friction_ratio for r in merged), default=0.0)
        return Report(Status.STABLE,
                      f"stable: {how}, the forces elsewhere kept; worst |V|/N {worst:.3f}"
                      f" (mu {self.options.solve.mu:.3g})",
                      max_tension, worst, interfaces=merged, model=f"local {size}")

    def _relaxed(self, assembly: Assembly, graph: ContactGraph, region: set[int]) -> Report | None:
        """Unstable report if R cannot stand even with every neighbour rigid."""
        rigid = graph.neighbours(region)
        ids = {assembly.blocks[k].id for k in region | rigid}
        relaxed = assembly.subset(ids, held={assembly.blocks[k].id for k in rigid})
        report = infeasible_report(relaxed, self.options, explain=self.explain)
        if report is None or report.status == Status.SOLVER_FAILED:
            return None
        return replace(report, message=f"{report.message} [even with the blocks around it rigid]",
                       model=f"relaxed {len(region)}")


def _blocks(n: int) -> str:
    return f"{n} block" if n == 1 else f"{n} blocks"
