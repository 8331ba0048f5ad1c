"""The stability check of one assembly: solve, and when it fails, say why.

The verdict follows RBE_NOTES: friction-net decides (a vertex can carry no net tension
under it, so an assembly that needs glue makes it infeasible). When it is infeasible, up to two
more solves explain the failure: the same equilibrium without any friction limit tells
sliding (it stands with more friction: FRICTION_EXCEEDED, its forces show where) from tipping
(it still needs tension: TENSION_REQUIRED), and then friction+ (always feasible while every
block is connected to a support) shows where tension is needed.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

from ..geometry.contacts import ContactOptions
from ..rbe.cones import cone_capacity
from ..rbe.model import build_model
from ..rbe.result import InterfaceResult, Report, Status
from ..rbe.resultants import interface_results
from ..rbe.solver import SolveOptions, solve
from ..scene import Scene, ValidationLimits
from .assembly import Assembly
from .margin import annotate_margin
from .validate import validated_assembly


@dataclass(frozen=True)
class HoldSearch:
    """How an unstable check looks for the smallest set of blocks to hold (suggested_holds;
    :mod:`rbe_ros.analysis.holds`): exact by increasing size up to ``max_size`` blocks while
    at most ``max_checks`` sub-assembly checks are spent, then a greedy heuristic that
    evaluates up to ``greedy_width`` candidates per added block. Counted in checks, not
    seconds, so that a replay suggests the same holds on any machine. Each trial checks the
    whole assembly, so assemblies of more than ``max_free_blocks`` free blocks are not searched
    (a 399-block vault would take minutes)."""

    enabled: bool = True
    max_size: int = 3
    max_checks: int = 40
    greedy_width: int = 4
    max_free_blocks: int = 60

    def __post_init__(self):
        for name in ("max_size", "max_checks", "greedy_width", "max_free_blocks"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"hold search {name} must be an integer >= 0, not {value!r}")


@dataclass(frozen=True)
class CheckOptions:
    solve: SolveOptions = field(default_factory=SolveOptions)
    mu_threshold: float | None = None   # post-check |V| <= mu_threshold N; None: the solve's mu
    tension_tol: float = 1e-5           # tension counts above this share of the free weight
    contact: ContactOptions = field(default_factory=ContactOptions)
    full_solve: bool = False            # sequences: always solve the whole partial assembly
    holds: HoldSearch = field(default_factory=HoldSearch)   # suggested holds of unstable checks
    #: Horizontal directions of the stability margin (margin.py); 0: no margin computed.
    margin_directions: int = 0
    #: Sane ranges checked before the geometry stage (None: no validation); see validate.py.
    limits: ValidationLimits | None = field(default_factory=ValidationLimits)

    @property
    def threshold(self) -> float:
        return self.solve.mu if self.mu_threshold is None else self.mu_threshold


def check_scene(scene: Scene, options: CheckOptions = CheckOptions()) -> Report:
    """Check ``scene`` as a whole (contact detection included in the reported time).

    With holds, the assembly is the state after the last step: supports whose hold ends are
    taken away, free blocks held to the end are supports (``held_blocks``). An unstable
    report names the smallest set of blocks to hold (``suggested_holds``, see
    :class:`HoldSearch`)."""
    from .holds import annotate_holds            # deferred: holds imports this module
    from .sequence import final_state

    start = time.perf_counter()
    assembly = validated_assembly(scene, options.limits, options.contact)
    held: tuple[str, ...] = ()
    if scene.holds:
        present, held = final_state(scene)
        assembly = assembly.subset(present, held)
    report = check(assembly, options)
    annotate_holds(report, assembly, held, options)
    annotate_margin(report, assembly, options.solve, options.margin_directions)
    report.solve_time = time.perf_counter() - start
    return report


def check(assembly: Assembly, options: CheckOptions = CheckOptions()) -> Report:
    """Verdict, forces and reason for ``assembly`` under its gravity."""
    start = time.perf_counter()
    report = _verdict(assembly, options)
    report.num_blocks = len(assembly.blocks)
    report.solve_time = time.perf_counter() - start
    return report


def infeasible_report(assembly: Assembly, options: CheckOptions = CheckOptions()) -> Report | None:
    """The report of ``assembly`` if its deciding problem is infeasible (it cannot stand,
    whatever else is checked), None if that problem has a solution."""
    return _verdict(assembly, options, only_infeasible=True)


def _verdict(assembly: Assembly, options: CheckOptions, only_infeasible: bool = False
             ) -> Report | None:
    floating = assembly.floating_blocks()
    if floating:
        return Report(False, Status.INFEASIBLE,
                      f"no equilibrium: {_names(floating)} not connected to a support by any"
                      f" contact", unstable_blocks=floating)
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    primary = solve(model, options.solve)
    if primary.solved:
        return None if only_infeasible else _report(model, primary, options)
    if primary.status == "failed":
        return None if only_infeasible else _failed(primary)
    if options.solve.friction == "plus":
        return Report(False, Status.INFEASIBLE, "no equilibrium even with tension")
    unlimited = solve(model, replace(options.solve, mu=math.inf, allow_tension=False))
    if unlimited.solved:
        return _report(model, unlimited, options, sliding=True)
    glued = solve(model, replace(options.solve, friction="plus"))
    if not glued.solved:
        return (_failed(glued) if glued.status == "failed" else
                Report(False, Status.INFEASIBLE, "no equilibrium even with tension"))
    return _report(model, glued, options)


def stands(model, options: CheckOptions, load=None) -> bool:
    """Whether the solve of ``options`` is feasible without tension under ``load`` (scaled p;
    default the dead load). The criterion of the tilting test and of the minimum friction;
    the friction threshold post-check is not part of it."""
    solution = solve(model, options.solve, load=load)
    if not solution.solved:
        return False
    return not any(r.tension for r in interface_results(
        model, solution, mu_threshold=math.inf, tension_tol=options.tension_tol))


def _report(model, solution, options: CheckOptions, *, sliding: bool = False) -> Report:
    """Report of a solved problem. ``sliding``: the solution needed more friction than the
    cone allows, so the interfaces that ask most of it are flagged."""
    mu = options.solve.mu
    results = interface_results(model, solution, mu_threshold=options.threshold,
                                tension_tol=options.tension_tol, mu=mu)
    if sliding:
        results = _flag_sliding(results, mu * cone_capacity(options.solve.cone))
    tension = [r for r in results if r.tension]
    friction = [r for r in results if r.friction_exceeded]
    max_tension = float(max(solution.forces[1].max(initial=0.0), 0.0))
    worst = max((r.friction_ratio for r in results), default=0.0)
    unstable = sorted({_moving_block(model, r) for r in tension + friction})
    if tension:
        worst_it = max(tension, key=lambda r: -r.normal_forces.min())
        status = Status.TENSION_REQUIRED
        message = (f"tension required: {max_tension:.4g} N at interface {_iface(worst_it)}"
                   f" ({_names(unstable)} would tip or open)")
    elif friction:
        worst_it = max(friction, key=lambda r: r.friction_ratio)
        status = Status.FRICTION_EXCEEDED
        limit = (f"the {options.solve.cone} cone allows with mu {mu:.3g}" if sliding
                 else f"the threshold {options.threshold:.3g}")
        message = (f"friction exceeded: |V|/N = {worst_it.friction_ratio:.3g} at interface"
                   f" {_iface(worst_it)}, more than {limit} ({_names(unstable)} would slide)")
    else:
        status = Status.STABLE
        message = (f"stable: {len(results)} interface{'s' * (len(results) != 1)} in compression,"
                   f" worst |V|/N {worst:.3f} (mu {mu:.3g})")
    return Report(status == Status.STABLE, status, message, max_tension, worst, 0.0,
                  len(model.blocks), results, unstable)


def _flag_sliding(results: list[InterfaceResult], capacity: float) -> list[InterfaceResult]:
    """Flag interfaces whose resultant exceeds ``capacity``; if none does (the vertex cones
    failed through torsion), the one with the highest |V|/N."""
    over = {i for i, r in enumerate(results) if r.friction_ratio > capacity}
    if not over and results:
        over = {max(range(len(results)), key=lambda i: results[i].friction_ratio)}
    return [replace(r, friction_exceeded=True) if i in over else r for i, r in enumerate(results)]


def _moving_block(model, r: InterfaceResult) -> str:
    """The block that would move at a failing interface: the upper one, unless it is a support."""
    support = {b.id for b in model.blocks if b.support}
    upper, lower = ((r.block_b, r.block_a) if r.normal @ _load_direction(model) <= 0
                    else (r.block_a, r.block_b))
    return lower if upper in support else upper


def _load_direction(model):
    """Direction of the dead load of the model (the weight of its free blocks)."""
    return model.dead_load.reshape(-1, 6)[:, :3].sum(axis=0)


def _failed(solution) -> Report:
    return Report(False, Status.SOLVER_FAILED, f"solver failed: {solution.solver_status}")


def _iface(r: InterfaceResult) -> str:
    return f"{r.block_a}|{r.block_b}"


def _names(ids) -> str:
    ids = list(ids)
    shown = ", ".join(ids[:5]) + (f" and {len(ids) - 5} more" if len(ids) > 5 else "")
    return ("block " if len(ids) == 1 else "blocks ") + shown
