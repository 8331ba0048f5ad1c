"""The verdict of one assembly: solve, and when it fails, say why; and the named predicates.

The verdict follows RBE_NOTES: friction-net decides (a vertex can carry no net tension
under it, so an assembly that needs glue makes it infeasible). When it is infeasible, up to two
more solves explain the failure: the same equilibrium without any friction limit tells
sliding (it stands with more friction: FRICTION_EXCEEDED, its forces show where) from tipping
(it still needs tension: TENSION_REQUIRED), and then friction+ (always feasible while every
block is connected to a support) shows where tension is needed.

A held block with a grip (``Assembly.grips``) is a free block with the robot's wrench, bounded
by the grip's capacities (the check's ``hold_force_max`` and ``hold_torque_max`` unless the
hold gives its own). When the capped problem is infeasible, one more solve without the
capacities tells HOLD_EXCEEDED (it stands with a larger wrench: the report names the block,
the wrench needed and the capacity) from the other failures (explained as above).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..rbe.cones import cone_capacity
from ..rbe.model import EquilibriumModel, Grip, build_model, finite
from ..rbe.prestress import Placement, placed
from ..rbe.result import HoldWrench, InterfaceResult, Report, Status
from ..rbe.resultants import interface_results
from ..rbe.solver import Solution, solve
from .assembly import Assembly
from .graph import ContactGraph
from .options import CheckOptions


def check(assembly: Assembly, options: CheckOptions = CheckOptions()) -> Report:
    """Verdict, forces and reason for ``assembly`` under its gravity (no time: the pipeline
    measures the whole check)."""
    return replace(_verdict(assembly, options), num_blocks=len(assembly.blocks))


def _deciding(assembly: Assembly, options: CheckOptions):
    """The report of floating blocks, else (model, solution of the deciding problem)."""
    floating = ContactGraph(assembly).floating_blocks()
    if floating:
        return Report(Status.INFEASIBLE,
                      f"no equilibrium: {_names(floating)} not connected to a support by any"
                      f" contact", unstable_blocks=floating)
    model = model_of(assembly, options)
    return model, solve(model, options.deciding)


def model_of(assembly: Assembly, options: CheckOptions, *, bounded: bool = True
             ) -> EquilibriumModel:
    """The equilibrium model of ``assembly``, its grips with their capacities (a grip's own,
    else the option's; ``bounded`` False: unbounded, except a capacity 0, which says what
    the grip cannot apply at all, as a pin grip no torque)."""
    centroid = {b.id: b.centroid for b in assembly.blocks}
    grips = tuple(replace(g, point=centroid[g.block] if g.point is None else g.point,
                          max_force=_capacity(g.max_force, options.hold_force_max, bounded),
                          max_torque=_capacity(g.max_torque, options.hold_torque_max, bounded))
                  for g in assembly.grips)
    return build_model(assembly.blocks, assembly.interfaces, assembly.gravity, grips)


def _capacity(own: float | None, option: float | None, bounded: bool) -> float:
    value = option if own is None else own
    if value is None or (not bounded and value > 0):
        return math.inf
    return float(value)


def _verdict(assembly: Assembly, options: CheckOptions) -> Report:
    deciding = _deciding(assembly, options)
    if isinstance(deciding, Report):
        return deciding
    model, primary = deciding
    if primary.solved:
        report = _report(model, primary, options)
        if not report.stable:
            return report
        placement = placed(model, options.deciding, solution=primary)
        if placement.stands:        # its field: RBE's where that one needs no squeeze
            own = (report if placement.field is primary
                   else _report(model, placement.field, options))
            # a ratio at mu to the solver's rounding: RBE's report, with the wrenches of the
            # field that stands (RBE's least hold may rest a held block on its neighbours)
            return own if own.stable else replace(report, hold_wrenches=own.hold_wrenches)
        if placement.beyond is not None:
            return _exceeded(_report(model_of(assembly, options, bounded=False),
                                     placement.beyond, options), model.grips)
        return _placement_report(model, report, placement, options)
    if primary.status == "failed":
        return _failed(primary)
    if _capped(model):
        unbounded = model_of(assembly, options, bounded=False)
        needed = solve(unbounded, options.deciding)
        if needed.solved:
            report = _report(unbounded, needed, options)
            if not report.stable:
                return report
            placement = placed(model, options.deciding, solution=needed)
            if placement.beyond is not None:
                return _exceeded(_report(unbounded, placement.beyond, options), model.grips)
            return _placement_report(unbounded, report, placement, options)
        if needed.status == "failed":
            return _failed(needed)
        model = unbounded
    return _explain(model, options)


def _capped(model: EquilibriumModel) -> bool:
    return any(finite(g.max_force) or finite(g.max_torque) for g in model.grips)


def _exceeded(report: Report, grips: tuple[Grip, ...]) -> Report:
    """HOLD_EXCEEDED: ``report`` stands with the wrenches it names, beyond ``grips``."""
    wrenches = hold_wrenches(grips, [np.concatenate((w.force, w.torque))
                                     for w in report.hold_wrenches])
    over = [w for w in wrenches if w.utilisation > 1.0] or \
        [max(wrenches, key=lambda w: w.utilisation)]
    what = "; ".join(
        f"block {w.block} needs |F| {np.linalg.norm(w.force):.4g} N"
        f" (capacity {_shown(g.max_force, 'N')}) and |M| {np.linalg.norm(w.torque):.4g} N m"
        f" (capacity {_shown(g.max_torque, 'N m')}) at its grip"
        f" ({', '.join(f'{x:.4g}' for x in w.grip_point)})"
        for w, g in ((w, next(g for g in grips if g.block == w.block)) for w in over))
    return replace(report, status=Status.HOLD_EXCEEDED, hold_wrenches=wrenches,
                   unstable_blocks=tuple(w.block for w in over),
                   message=f"hold exceeded: stands only with more than the robot can apply:"
                           f" {what}")


def _shown(capacity: float, unit: str) -> str:
    return f"{capacity:.4g} {unit}" if math.isfinite(capacity) else "unbounded"


def hold_wrenches(grips, wrenches) -> tuple[HoldWrench, ...]:
    """The HoldWrench of each grip from its wrench (force, torque about the grip: 6 numbers),
    with its utilisation of the grip's capacities (a capacity of 0 counts any wrench above
    rounding, 1e-9 N or N m, as infinite use)."""
    out = []
    for g, w in zip(grips, wrenches):
        force, torque = np.array(w[:3], dtype=float), np.array(w[3:], dtype=float)
        use = max((_use(np.linalg.norm(x), cap) for x, cap in ((force, g.max_force),
                                                               (torque, g.max_torque))
                   if finite(cap)), default=0.0)
        out.append(HoldWrench(g.block, force, torque, np.array(g.point, dtype=float), use))
    return tuple(out)


def _use(size: float, capacity: float) -> float:
    if capacity > 0:
        return float(size / capacity)
    return math.inf if size > ZERO_WRENCH else 0.0


#: A wrench below this (N or N m) is none: the solver's rounding on a zero-capacity grip.
ZERO_WRENCH = 1e-9


def infeasible_report(assembly: Assembly, options: CheckOptions = CheckOptions(), *,
                      explain: bool = True) -> Report | None:
    """The report of ``assembly`` if its deciding problem is infeasible (it cannot stand,
    whatever else is checked), None if that problem has a solution or the solver failed.
    ``explain`` False: an INFEASIBLE report without the solves that say why."""
    deciding = _deciding(assembly, options)
    if isinstance(deciding, Report):
        return deciding
    model, primary = deciding
    if primary.solved or primary.status == "failed":
        return None
    return _explain(model, options) if explain else Report(Status.INFEASIBLE, UNEXPLAINED)


#: The message of an infeasible report whose explanation was not asked for.
UNEXPLAINED = "no equilibrium (not explained)"


def _explain(model: EquilibriumModel, options: CheckOptions) -> Report:
    """Why the deciding problem is infeasible: sliding (it stands with unlimited friction),
    or where tension is needed (friction+)."""
    if options.solve.friction == "plus":
        return Report(Status.INFEASIBLE, "no equilibrium even with tension")
    unlimited = solve(model, replace(options.solve, mu=math.inf, allow_tension=False))
    if unlimited.solved:
        report = _report(model, unlimited, options, sliding=True)
        placement = placed(model, options.deciding)
        if placement.stands or not placement.moving:
            return report
        return replace(_sliding_report(model, report, placement), message=(
            f"friction exceeded: {_motion(model, placement)}{_beyond(report, placement, options)}"))
    glued = solve(model, replace(options.solve, friction="plus"))
    if not glued.solved:
        return (_failed(glued) if glued.status == "failed" else
                Report(Status.INFEASIBLE, "no equilibrium even with tension"))
    return _report(model, glued, options)


def _beyond(report: Report, placement: Placement, options: CheckOptions) -> str:
    """What the sliding blocks need beyond the cone: the |V|/N of the field with unlimited
    friction at the first interface they slide across when it is beyond the cone there;
    else that field's ratios say nothing about it (the pressed shelf's board slides down a
    wall where its field needs |V|/N 0.32 at mu 0.6: it is held by shear without normal
    force on the block above), so no number."""
    capacity = options.deciding.mu * cone_capacity(options.solve.cone)
    first = report.interfaces[placement.sliding[0]] if placement.sliding else None
    if first is not None and capacity < first.friction_ratio < math.inf:
        return f": |V|/N = {first.friction_ratio:.3g} there, more than {_limit(options, True)}"
    return f": standing needs more friction than {_limit(options, True)}"


def is_stable(assembly: Assembly, options: CheckOptions = CheckOptions()) -> bool:
    """The verdict of :func:`check` (stable or not) without the explanation solves: the
    deciding problem is solved, no interface needs tension and every one is within the
    friction threshold."""
    if ContactGraph(assembly).floating_blocks():
        return False
    return stable_forces(model_of(assembly, options), options) is not None


def stable_forces(model: EquilibriumModel, options: CheckOptions, load=None
                  ) -> tuple[Solution, list[InterfaceResult]] | None:
    """The solution and interface results of the deciding problem under ``load`` (scaled p;
    default the dead load) when they pass the criterion of :func:`check`: solved, no
    tension, every interface within the friction threshold, and the placement test. None
    otherwise."""
    found = admissible_forces(model, options, load)
    if found is None or not placed(model, options.deciding, load, found[0]).stands:
        return None
    return found


def admissible_forces(model: EquilibriumModel, options: CheckOptions, load=None
                      ) -> tuple[Solution, list[InterfaceResult]] | None:
    """:func:`stable_forces` before the placement test (whose solves a caller may know to
    be needless: a field that needs friction where the test cannot give it)."""
    solution = solve(model, options.deciding, load=load)
    if not solution.solved:
        return None
    results = interface_results(model, solution, mu_threshold=options.threshold,
                                tension_tol=options.tension_tol, mu=options.deciding.mu)
    if any(r.tension or (r.friction_exceeded and counts)
           for r, counts in zip(results, _loaded(model, results, options))):
        return None
    return solution, results


def _placement_report(model, report: Report, placement: Placement,
                      options: CheckOptions) -> Report:
    """FRICTION_EXCEEDED for a field that blocks set in place without pre-load do not get:
    the interfaces across which they slide flagged, the blocks that move named."""
    return replace(_sliding_report(model, report, placement), message=(
        f"friction exceeded without prestress: {_motion(model, placement)} (set in place"
        f" from rest, with the friction of each contact up to mu {options.deciding.mu:.3g}"
        f" times the normal force the loads produce there; RBE's field needs a squeeze)"))


def _sliding_report(model, report: Report, placement: Placement) -> Report:
    """``report`` FRICTION_EXCEEDED, its interfaces flagged and blocks named from
    ``placement``'s motion: those across which the moving blocks slide (if none slides, the
    report's own flags), those that move."""
    hit = set(placement.sliding)
    flagged = [replace(r, friction_exceeded=k in hit) for k, r in enumerate(report.interfaces)] \
        if hit else report.interfaces        # they tip or turn: the field's own flags
    moving = tuple(sorted(model.blocks[j].id for j in placement.moving))
    return replace(report, status=Status.FRICTION_EXCEEDED, interfaces=flagged,
                   unstable_blocks=moving)


def _motion(model, placement: Placement) -> str:
    """'block X would slide at interface a|b' from a placement's motion."""
    moving = [model.blocks[j].id for j in placement.moving]
    # two blocks may meet at several interfaces (faces in different planes): named once
    pairs = list(dict.fromkeys(f"{model.blocks[it.a].id}|{model.blocks[it.b].id}"
                               for it in (model.interfaces[k] for k in placement.sliding)))
    where = pairs[:3]
    if not moving:
        return "no equilibrium"
    if not where:
        return f"{_names(moving)} would move"
    more = f" and {len(pairs) - 3} more" if len(pairs) > 3 else ""
    return (f"{_names(moving)} would slide at interface {where[0]}"
            + (f" (and {', '.join(where[1:])}{more})" if len(where) > 1 else ""))


def feasible_without_tension(model: EquilibriumModel, options: CheckOptions, load=None) -> bool:
    """Whether the solve of ``options`` is feasible without tension under ``load`` (scaled p;
    default the dead load); the friction threshold post-check is not applied. The criterion
    of the tilting test and of the minimum friction, whose subject is the cone itself."""
    solution = solve(model, options.solve, load=load)
    if not solution.solved:
        return False
    return not any(r.tension for r in interface_results(
        model, solution, mu_threshold=math.inf, tension_tol=options.tension_tol))


def _report(model, solution, options: CheckOptions, *, sliding: bool = False) -> Report:
    """Report of a solved problem. ``sliding``: the solution needed more friction than the
    cone allows, so the interfaces that ask most of it are flagged."""
    mu = options.deciding.mu
    results = interface_results(model, solution, mu_threshold=options.threshold,
                                tension_tol=options.tension_tol, mu=mu)
    loaded = _loaded(model, results, options)
    if sliding:
        results = _flag_sliding(results, mu * cone_capacity(options.solve.cone))
    elif not all(loaded):
        results = [r if keep or not r.friction_exceeded else replace(r, friction_exceeded=False)
                   for r, keep in zip(results, loaded)]
    tension = [r for r in results if r.tension]
    friction = [r for r in results if r.friction_exceeded]
    max_tension = float(max(solution.forces[1].max(initial=0.0), 0.0))
    worst = max((r.friction_ratio for r, keep in zip(results, loaded) if keep), default=0.0)
    unstable = sorted({_moving_block(model, r) for r in tension + friction})
    if tension:
        worst_it = max(tension, key=lambda r: -r.normal_forces.min())
        status = Status.TENSION_REQUIRED
        message = (f"tension required: {max_tension:.4g} N at interface {_iface(worst_it)}"
                   f" ({_names(unstable)} would tip or open)")
    elif friction:
        worst_it = max(friction, key=lambda r: r.friction_ratio)
        status = Status.FRICTION_EXCEEDED
        message = (f"friction exceeded: |V|/N = {worst_it.friction_ratio:.3g} at interface"
                   f" {_iface(worst_it)}, more than {_limit(options, sliding)}"
                   f" ({_names(unstable)} would slide)")
    else:
        status = Status.STABLE
        message = (f"stable: {len(results)} interface{'s' * (len(results) != 1)} in compression,"
                   f" worst |V|/N {worst:.3f} (mu {options.solve.mu:.3g}"
                   + (f", threshold {mu:.3g})" if mu < options.solve.mu else ")"))
    return Report(status, message, max_tension, worst, num_blocks=len(model.blocks),
                  interfaces=results, unstable_blocks=unstable,
                  hold_wrenches=hold_wrenches(model.grips, solution.wrenches))


#: With a declared pose uncertainty, the friction ratio counts (worst_friction_ratio, the
#: threshold post-check) on interfaces carrying at least this share of the mean free block's
#: weight: the uncertainty makes and breaks contacts that carry next to nothing, and the
#: |V|/N of a nearly unloaded one is the solver's rounding, up to the cone's limit.
LOADED_SHARE = 0.01


def _loaded(model, results: list[InterfaceResult], options: CheckOptions) -> list[bool]:
    """Whether each interface's |V|/N counts: all of them on design geometry; with a
    declared pose uncertainty those with N >= LOADED_SHARE of the mean free block's weight."""
    if not options.contact.uncertain or not len(model.free):
        return [True] * len(results)
    least = LOADED_SHARE * model.force_scale / len(model.free)
    return [r.normal_resultant >= least for r in results]


def _limit(options: CheckOptions, sliding: bool) -> str:
    """What a sliding interface needs more than: the cone (the deciding problem had no
    field) or the threshold (a field within the cone, over it)."""
    mu = options.deciding.mu
    if sliding and mu == options.solve.mu:
        return f"the {options.solve.cone} cone allows with mu {mu:.3g}"
    return f"the threshold {options.threshold:.3g}"


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
    upper, lower = ((r.block_b, r.block_a) if r.normal @ model.gravity <= 0
                    else (r.block_a, r.block_b))
    return lower if upper in support else upper


def _failed(solution) -> Report:
    return Report(Status.SOLVER_FAILED, f"solver failed: {solution.solver_status}")


def _iface(r: InterfaceResult) -> str:
    return f"{r.block_a}|{r.block_b}"


def _names(ids) -> str:
    ids = list(ids)
    shown = ", ".join(ids[:5]) + (f" and {len(ids) - 5} more" if len(ids) > 5 else "")
    return ("block " if len(ids) == 1 else "blocks ") + shown
