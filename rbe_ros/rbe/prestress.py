"""Whether blocks set one at a time, without pre-load, stand: the test after RBE's field.

RBE asks for some admissible force field. With Coulomb friction (sliding does not dilate a
joint) a field may hold a block by normal forces the loads never produce in rigid blocks set
in place unstressed: a bar between two posts held by a horizontal squeeze, a flat arch with
vertical joints held by an arching thrust, a block on an incline pressed by a bar above it.
A block is placed from rest and its weight comes on from zero: a contact gets a normal force
only where the motion the loads would start closes it, and friction only up to mu times that
(docs/METHOD.md, "Placement without pre-load").

The test is Panagiotopoulos' fixed point (*Inequality Problems in Mechanics*, 1985) on the
step from rest of non-smooth contact dynamics (Moreau-Jean, as LMGC90 takes it, impulses
from zero), each step a convex problem:

1. Tresca caps g_I on the friction resultant of every interface I, first 0 (no friction).
2. The step from rest under the caps: the motion the contact forces leave, the least
   kinetic energy 1/2 e^T M^-1 e with e = A f + p the net wrench on each free block (M its
   mass and inertia), with the vertex cones and the caps; then the forces of that motion:
   the least 1/2 |f|^2 (the check's objective) with A f + p = e (no self-stress: it would
   cost and do nothing), e's rounding absorbed by the same kinetic term. Two solves: one
   with both terms would judge the forces to the solver's relative accuracy on the far
   larger kinetic term of a falling block.
3. If it leaves no motion (e = 0 to the solver's accuracy: the RBE problem with the caps has
   a field), the blocks stand: that field is reached from rest. Else the caps become mu
   times the step's normal resultants, and 2 again, until they no longer change: then the
   blocks fall, those left with an acceleration are the ones that move, and the interfaces
   across which they slide are named. They fall too when, from the third step on, the
   caps change by more than they changed at the step before: friction is then making the
   normal forces that raise its own caps, ever faster, a loop through the contacts that
   only a squeeze closes (a block sliding out of a self-locking groove, which the caps
   would otherwise creep into).

Blocks that a step leaves still stand only on friction from normal forces of their own
(:func:`_own_caps`): a cap from an earlier step's motion can hold a normal force that
friction takes away (a shelf's board slides into the wall only without friction), and where
the field within the caps rubs beyond mu times its own normal force, the step from rest
without friction there gives the caps instead.

A normal force that only a squeeze gives never enters a cap: the step from rest has no
reason to produce it, and a cap fixed before a step cannot grow with the squeeze of that
step. Normal forces that the load's moment produces (a block turning onto a face) enter.

Pins. A robot that holds its block still makes it a support (:func:`_held_still`). A pin
grip (torque capacity 0) fixes its grip point p and lets the block turn about it: in every
solve of the steps its force is a free variable that costs nothing, the reaction of the
constraint v + omega x (p - c) = 0 (the least 1/2 e^T M^-1 e over it leaves the point no
acceleration, Gauss's least constraint). Its block then presses a neighbour only where
the turn its loads start about the pin closes the contact; a costed force would rather
rest its weight on the neighbours, a squeeze that gives them friction. The field that
stands is the least |f|^2 with the pin's reaction; the least wrench (the check's) decides
the capacities only (:func:`_settled`). Beside a grip that holds its block still, the pin
keeps that reaction, a known load in the least of the still grips' wrenches
(:func:`_least_still_hold`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import clarabel
import numpy as np
import scipy.sparse as sp

from .cones import pyramid_facets
from .model import EquilibriumModel, build_model
from .resultants import exceeds, friction_ratios
from .solver import Kept, Solution, SolveOptions, Weights, solve

#: Weight of the kinetic energy of the motion against the check's objective 1/2 |f|^2 (both
#: in units of the free weight W): the step's forces are those of the motion to about
#: 1 / INERTIA_WEIGHT of W.
INERTIA_WEIGHT = 1e6
#: A step that leaves no free block a net force above this share of its weight (a moment
#: above it times its weight and size) may have left no motion: the RBE problem with the
#: step's caps decides (the kinetic term's weight against the check's objective and the
#: robots' wrenches leaves about 1e-3 of a held block's weight unbalanced).
STILL = 1e-2
#: A step whose motion leaves no free block more than this share of its weight (as STILL)
#: makes the next step try the RBE problem with its caps before its motion: the cross
#: vault's second step leaves 0.13, its third none (its first 2.0; a block that falls
#: freely: 1).
NEAR_STILL = 0.25
#: The caps no longer change when none moves by more than this share of W.
CONVERGED = 1e-4
#: Normal resultants below this share of the lighter free block's weight at an interface
#: give no cap (see _noise_floor): the solver's offset from a cone's apex (1e-4 of the block
#: weight, measured) would otherwise grow, step by step, into friction no load produced.
NOISE_SHARE = 1e-2
#: At most this many steps: the fixed point's caps converge geometrically; a case that has
#: not converged by then is judged on its last step.
MAX_STEPS = 40
#: From this step on, caps that change by more than at the step before are friction
#: feeding its own normal forces: the first change is the frictionless step's normal
#: forces, the second those of the contacts that the first friction closes, the loads'.
FEEDS_FROM = 3
#: A block moves when its acceleration (|a| + |alpha| times its size) exceeds this share of
#: the largest one and MOVING_G of g; an interface slides when its blocks' relative
#: tangential acceleration at its centre exceeds the same share and the normal one.
MOVING_SHARE = 1e-2
MOVING_G = 1e-4
#: Digits (of the largest) to which the moving blocks and sliding interfaces are ranked.
RANK_DIGITS = 6
#: The caps hold the test's field within mu N (1 + CONE_TOL) + SHARE_TOL W (the accuracy
#: of the solver's normal forces).
CONE_TOL = 1e-6
SHARE_TOL = 1e-7
#: A vertex whose friction is within this share of mu fn binds its cone (an interior-point
#: solution comes no closer to a cone it sits on than about 1e-4).
CONE_SLACK = 1e-2
#: Clarabel's tolerances (gap and feasibility) on the least normal forces' programs: with
#: its default (1e-8) a partial dome's least is up to 1e-6 W off the optimum, with this one
#: within 1e-10 W of HiGHS' at the same tolerances, for a step or two more.
LEAST_TOL = 1e-10
#: Clarabel's iterations on one of them: a partial dome's take 31-33; those it does not
#: solve (a shelf's, with caps at the solver's tolerance) it fails after some 170.
LEAST_MAX_ITER = 50
#: A program cut off there still converging, twice as many with iterative refinement of its
#: KKT solves, then HiGHS: the 527-block dome's open course (over 2000 vertices) stalls
#: without refinement short of 1e-10 and is solved with it in some 50 iterations, where
#: HiGHS' simplex takes over 10000 (docs/METHOD.md, Sequences).
LEAST_REFINED_ITER = 100
#: More rubbing interfaces than this: the least of their sum first (LeastNormals). It
#: pays where it spares at least one program: a few rubbing interfaces mostly each need a
#: normal force, a partial dome's open course mostly none (docs/METHOD.md, Sequences).
SUM_FIRST = 5
#: The least hold within the settled caps (the wrench needed beyond the capacities): the
#: check's objective scaled by this against the robots' wrenches, so that
#: solver.HOLD_WEIGHT's bound on how far the wrench is from the least, O(g / w), is this
#: much tighter.
LEAST_HOLD = 1e-3


@dataclass(frozen=True)
class Placement:
    """The answer of the test: the field that stands (None when the blocks move), else the
    free blocks that move (indices into the model's blocks, the fastest first) and the
    interfaces they slide across (indices, the most loaded first)."""

    field: Solution | None
    moving: tuple[int, ...] = ()
    sliding: tuple[int, ...] = ()
    steps: int = 0
    #: a field that stands with more than the grips' capacities (their wrenches needed)
    beyond: Solution | None = None
    #: the last step from rest (its net wrenches: the motion), when the blocks move
    motion: Solution | None = None
    #: the friction caps (N per interface) within which ``field`` stands (None: no bound)
    caps: np.ndarray | None = None

    @property
    def stands(self) -> bool:
        return self.field is not None


def placed(model: EquilibriumModel, options: SolveOptions, load=None,
           solution: Solution | None = None) -> Placement:
    """The test on ``model`` under ``load`` (scaled p; default its dead load) with the
    friction of ``options`` (a check's deciding problem). ``solution``: a field of the RBE
    problem already solved (of ``model`` or of it without the grips' capacities); where it
    keeps a step's caps it is the field that stands, without that step's solves (a wall on
    level ground needs no friction: no solve at all), or beyond the capacities (not with a
    pin, whose field is its reaction's: module docstring, Pins). The first
    step's caps, none, it keeps to the noise floor: friction below 1% of the lighter
    block's weight is the solver's rounding there (a running-bond wall's QP field: 1e-3 of
    a brick's weight)."""
    if any(_still_grip(g) for g in model.grips):
        # its block a support, then its wrench: at mu = inf as at finite mu (the least the
        # test admits, not the check's field's, which rests the block on its neighbours)
        return _held_still(model, options, load)
    if model.grips:
        # a pin (its block may turn about it) fixes what it can apply, the grip point's
        # position, its wrench the reaction of that, free of cost: the steps' motion is
        # then the one with the point still (module docstring, Pins); the check's field,
        # the least hold, is not the one that stands
        options, solution = replace(options, weights=replace(options.weights, hold=0.0)), None
    if not math.isfinite(options.mu) or not len(model.free):    # nothing can slide
        field = solution if solution is not None and solution.solved else \
            solve(model, options, load=load)
        return Placement(field if field.solved else None)
    # the check's field is the least |f|^2 of the steps' problem (see _own_caps)
    least = options.objective == "qp" and options.friction == "net" and not model.grips
    options = replace(options, objective="qp", friction="net")
    metric = inertia_metric(model)
    # a robot keeps its grip where it is (its arm is position-controlled): during the
    # steps its wrench is what holding it takes; the capacities bound the field that stands
    rigid = replace(model, grips=tuple(replace(g, max_force=_unless_none(g.max_force),
                                               max_torque=_unless_none(g.max_torque))
                                       for g in model.grips))
    load = model.dead_load if load is None else np.asarray(load, dtype=float)
    caps = np.zeros(len(model.interfaces))
    floor = _noise_floor(model.blocks, model.interfaces, model.free, model.force_scale)
    motion, change_before, tried = None, math.inf, 2 * NEAR_STILL
    # the solvers kept for the steps' problems, which differ only in load and caps: the
    # motion's with and without friction, and the RBE problem within the caps
    motions, within = {True: Kept(), False: Kept()}, Kept()
    own_solvers = _OwnSolvers(motions[False], within)
    for count in range(1, MAX_STEPS + 1):
        bound = caps * (1.0 + CONE_TOL) + SHARE_TOL * model.force_scale
        kept = bound if caps.any() else bound + floor
        if solution is not None and solution.solved and _within(
                model, solution, kept, options.cone):
            own = _own_caps(model, rigid, options, load, caps, floor, metric,
                            solution if least else None, own_solvers)
            if own is None:
                return (Placement(solution, steps=count - 1, caps=kept)
                        if _held(model, solution)
                        else Placement(None, steps=count - 1, beyond=solution))
            caps, motion = own
            bound = caps * (1.0 + CONE_TOL) + SHARE_TOL * model.force_scale
        # the last step's motion near rest: this one likely leaves none, which the RBE
        # problem with the caps decides alone (it has a field exactly when no motion is
        # left), without the motion's solve; tried first (again only once the motion has
        # halved since: caps that creep leave a motion near rest step after step)
        early = motion is not None and _unbalance(model, motion) <= tried / 2
        settled = _settled(model, rigid, options, load, caps, within) if early else None
        if early and settled is None:
            tried = _unbalance(model, motion)
        if settled is None:
            frictionless = not caps.any()       # the first step: no variables of friction
            kept = motions[frictionless]        # the motion's solver, for its least forces
            motion = solve(rigid, options, load=load, friction_cap=bound, inertia=metric,
                           frictionless=frictionless, keep=kept)
            if not motion.solved:
                break
            if not early and _still(model, motion):
                settled = _settled(model, rigid, options, load, caps, within)
        if settled is not None:     # no motion left: stands, unless it rubs on caps it lacks
            own = _own_caps(model, rigid, options, load, caps, floor, metric,
                            None if model.grips else settled.field, own_solvers)
            if own is None:
                return replace(settled, steps=count)
            caps, motion = own
            continue
        # the least forces that leave the motion found: its normal forces, none by squeeze
        forces = solve(rigid, options, load=load - _scaled(model, motion.unbalanced),
                       friction_cap=bound, inertia=metric, frictionless=frictionless, keep=kept)
        if not forces.solved:
            break
        normal = options.mu * _above_noise(_sums(model, forces.forces[0]), floor)
        change = np.abs(normal - caps).max(initial=0.0)
        if change <= CONVERGED * model.force_scale or (
                count >= FEEDS_FROM and change > change_before + CONVERGED * model.force_scale):
            break       # converged, or friction raising its own caps ever faster: a squeeze
        caps, change_before = normal, change
    return _moved(model, motion, count)


def _still_grip(grip) -> bool:
    """Whether a grip keeps its block still: it can apply a force and a torque (a pin grip,
    torque capacity 0, lets its block turn about the grip: module docstring, Pins)."""
    return grip.max_force != 0 and grip.max_torque != 0


def _held_still(model: EquilibriumModel, options: SolveOptions, load) -> Placement:
    """The test with the blocks of grips that keep them still (:func:`_still_grip`) as
    supports, then each robot's wrench: what its block's weight and contact forces leave
    (:func:`_with_wrenches`) in the field of least wrenches the test accepts
    (:func:`_least_still_hold`), checked against the capacities (beyond them: ``beyond``,
    that field). A robot that holds its block still (position-
    controlled) does not pre-load: its block presses a neighbour only where the motion the
    loads start closes the contact, as a fixed block's does. As a free block whose wrench
    costs (the least hold), the held block's own weight would rest on its neighbours and its
    friction hold them, a squeeze by the robot: a box on a slope under an equal held box
    stood up to tan 1.5 at mu 0.5, not 0.5 (tests/test_prestress.py); the 8 x 5 dome's
    plan, step 18 (docs/METHOD.md, Holds)."""
    still_ids = {g.block for g in model.grips if _still_grip(g)}
    blocks = tuple(replace(b, support=True) if b.id in still_ids else b for b in model.blocks)
    still = build_model(blocks, model.interfaces, model.gravity,
                        tuple(g for g in model.grips if not _still_grip(g)))
    load = model.dead_load if load is None else np.asarray(load, dtype=float)
    keep = np.isin(model.free, still.free)
    rows = load.reshape(-1, 6)[keep] * (model.force_scale / still.force_scale)
    first = solve(still, options, load=rows.ravel())
    found = placed(still, options, rows.ravel(), first if first.solved else None)
    if not found.stands:
        return replace(found, field=None, beyond=None)
    field = _least_still_hold(model, options, load, found, still_ids)
    return Placement(field, steps=found.steps, caps=found.caps) if _held(model, field) else \
        Placement(None, steps=found.steps, beyond=field)


def _least_still_hold(model: EquilibriumModel, options: SolveOptions, load, found: Placement,
                      still_ids: set[str]) -> Solution:
    """Of the fields the held-still test accepts, the one whose robots' wrenches are least
    (the solver's hold term, the forces' objective scaled by LEAST_HOLD a tie-break), within
    the capacities where one is. Accepted: the free blocks' forces within the settled caps
    (``found.caps``), a still-held block pressing a free neighbour no more than in the field
    that stands (``found.field``) and no support or other held block at all: it presses
    only where the motion from rest closed a contact, and a robot cannot relieve itself by
    resting its block on what it holds still (the squeeze of the least hold, _held_still).
    A held block's contact pressed below the noise floor in the field that stands carries
    nothing (left out: the solver's rounding there would read as friction beyond the cone).
    The field that stands, its wrenches what it leaves (:func:`_with_wrenches`), is kept
    where that least is not within the cones to the report's tolerance; a load leaning on a
    held block and on a support moves to the support as far as the support's caps let it
    (tests/test_prestress.py). A pin's wrench stays its reaction in the field that stands
    (module docstring, Pins)."""
    field = _with_wrenches(model, found.field, load)
    held = np.zeros(len(model.blocks), dtype=bool)
    held[[model.index[b] for b in still_ids]] = True
    bearing = held | ~np.isin(np.arange(len(model.blocks)), model.free)
    pairs = np.array([(it.a, it.b) for it in model.interfaces], dtype=int).reshape(-1, 2)
    pressed = np.where(bearing[pairs].all(axis=1), 0.0,
                       _sums(model, found.field.forces[0] - found.field.forces[1]))
    touching = held[pairs].any(axis=1)
    floor = _noise_floor(model.blocks, model.interfaces, model.free, model.force_scale)
    kept = ~touching | (pressed > floor)
    normal_cap = np.where(touching, pressed * (1.0 + CONE_TOL)
                          + SHARE_TOL * model.force_scale, np.inf)[kept]
    caps = None if found.caps is None else found.caps[kept]
    # a pin's wrench a known load on its block: a cost, the least would shed it onto the
    # block's neighbours
    still = [k for k, g in enumerate(model.grips) if _still_grip(g)]
    pinned, blocks = {}, model.blocks
    if len(still) < len(model.grips):
        for g, wrench in zip(model.grips, field.wrenches):
            if not _still_grip(g):
                j = model.index[g.block]
                arm = np.asarray(g.point) - model.blocks[j].centroid
                pinned[j] = pinned.get(j, 0.0) + np.concatenate(
                    (wrench[:3], wrench[3:] + np.cross(arm, wrench[:3])))
        blocks = tuple(replace(b, support=False) if j in pinned else b
                       for j, b in enumerate(model.blocks))
    least_model = build_model(blocks, tuple(it for it, k in zip(model.interfaces, kept) if k),
                              model.gravity, tuple(model.grips[k] for k in still))
    if pinned:
        load = load + least_model.wrench_load(pinned)
    w = options.weights
    least_options = replace(options, objective="qp", friction="net", weights=Weights(
        w.compression * LEAST_HOLD, w.tension * LEAST_HOLD, w.friction * LEAST_HOLD))
    rigid = replace(least_model, grips=tuple(replace(g, max_force=_unless_none(g.max_force),
                                                     max_torque=_unless_none(g.max_torque))
                                             for g in least_model.grips))
    least = solve(rigid, least_options, load=load, friction_cap=caps, normal_cap=normal_cap)
    if least.solved and not _held(least_model, least):
        # the least in the solver's measure (force and torque together) is beyond a
        # capacity: another accepted field may be within them all
        capped = solve(least_model, least_options, load=load, friction_cap=caps,
                       normal_cap=normal_cap)
        least = capped if capped.solved else least
    if not least.solved or not _in_cones(least_model, least, options.mu):
        return field
    forces = np.zeros_like(field.forces)
    forces[:, kept[model.vertex_interface]] = least.forces
    wrenches = field.wrenches.copy()
    wrenches[still] = least.wrenches
    return replace(least, forces=forces, wrenches=wrenches)


def _in_cones(model: EquilibriumModel, field: Solution, mu: float) -> bool:
    """Whether no interface of ``field`` exceeds mu by the report's friction test
    (rbe/resultants.py): |V| in the Euclidean norm whatever the cone. Not the check's cone:
    the least is solved within it, so its resultants are too (a pyramid's facets, summed
    over an interface's vertices, bound its resultant), and an outer pyramid's corner (|V|
    up to sqrt 2 mu N for pyramid4) is a field the report flags: the check would show RBE's
    forces with the wrenches of another field (tests/test_prestress.py)."""
    normal = _sums(model, field.forces[0] - field.forces[1])
    shear = np.hypot(_sums(model, field.forces[2]), _sums(model, field.forces[3]))
    return not exceeds(friction_ratios(shear, normal, model.force_scale), mu).any()


def _with_wrenches(model: EquilibriumModel, field: Solution, load: np.ndarray) -> Solution:
    """``field`` (of the model with the still-held blocks as supports) as a field of
    ``model``: each still-held block's grip takes what its weight and contact forces leave
    (force F at the grip p, torque M about it: F = -R, M = -(M_c + (p - c) x F) for their
    resultant R and moment M_c about the centroid c); the other grips keep their wrenches
    in ``field``."""
    row = {int(j): r for r, j in enumerate(model.free)}
    rest = (model.a_eq @ field.forces.ravel() / model.force_scale + load).reshape(-1, 6)
    others = iter(field.wrenches)
    wrenches = np.zeros((len(model.grips), 6))
    for k, g in enumerate(model.grips):
        if not _still_grip(g):
            wrenches[k] = next(others)
            continue
        j = model.index[g.block]
        force = -rest[row[j], :3] * model.force_scale
        moment = rest[row[j], 3:] * model.force_scale * model.length_scale
        wrenches[k, :3] = force
        wrenches[k, 3:] = -(moment + np.cross(np.asarray(g.point) - model.blocks[j].centroid,
                                              force))
    return replace(field, wrenches=wrenches, unbalanced=np.zeros(0))


class _OwnSolvers:
    """The solvers :func:`_own_caps` keeps across one test's calls, whose problems differ
    only in load and caps (its least normal forces' programs also in their costs): the
    step's motion and the RBE problem within caps (shared with the steps), the field within
    the caps alone, and the least normal forces' program (:class:`LeastNormals`)."""

    def __init__(self, motion: Kept, within: Kept):
        self.motion, self.within, self.alone, self.least = motion, within, Kept(), LeastNormals()


def _own_caps(model: EquilibriumModel, rigid: EquilibriumModel, options: SolveOptions, load,
              caps: np.ndarray, floor: np.ndarray, metric, field: Solution | None,
              solvers: _OwnSolvers):
    """None when the blocks, still under ``caps``, get their friction from normal forces
    the loads make; else lower caps for the next step and the motion they leave. The caps
    came from a step's motion, the frictionless one above all, and a normal force there can
    be one that friction takes away (a board that slides on its corbel without friction
    presses the wall; with the corbel's friction it tips away from it, and the shelf falls
    for any mu). Where the least field within the caps alone (no cones: they would make the
    normal forces that friction asks for, a squeeze) rubs beyond mu times its normal
    resultant, the step from rest without friction there tells: the blocks stand without
    it, or the least normal forces of its motion there (those the loads press there: type-b
    turned about y, whose load's moment presses the upper face) give at least the caps, or
    those become the caps. ``field``: the least field within the caps and the cones, if
    known (skips the solves when no cone binds it). ``solvers``: those kept (the RBE problem
    within caps, when its solver was kept, tried first: the step leaves no motion exactly
    when it has a field)."""
    if not caps.any():          # friction within the noise floor: nothing leans on caps
        return None
    if field is not None and not _at_cone(model, field, options):
        return None             # the least field within the caps alone: the same one
    bound = caps * (1.0 + CONE_TOL) + SHARE_TOL * model.force_scale
    field = solve(rigid, replace(options, mu=math.inf), load=load, friction_cap=bound,
                  keep=solvers.alone)
    if not field.solved:
        return None
    friction = _tangential(*(_sums(model, field.forces[k]) for k in (2, 3)), options.cone)
    # friction below the floor is rounding (not mu x the floor: at mu 13 a shelf's wall
    # would carry 13% of a block's weight on no normal force)
    rubbing = friction > options.mu * _above_noise(_sums(model, field.forces[0]), floor) \
        * (1.0 + CONE_TOL) + floor + SHARE_TOL * model.force_scale
    if not rubbing.any():
        return None
    without = np.where(rubbing, 0.0, caps) * (1.0 + CONE_TOL) + SHARE_TOL * model.force_scale
    field = solvers.within.solve(rigid, options, load, without / model.force_scale)
    if field is not None and field.solved:
        return None             # by the kept solver only: a fresh one costs the motion's
    step = solve(rigid, options, load=load, friction_cap=without, inertia=metric,
                 keep=solvers.motion)
    if not step.solved:
        return np.where(rubbing, 0.0, caps), None
    if _still(model, step):
        return None
    least = solvers.least(rigid, options, load - _scaled(model, step.unbalanced),
                          without, np.flatnonzero(rubbing))
    if least is None:
        return np.where(rubbing, 0.0, caps), step
    pressed = np.where(rubbing, options.mu * _above_noise(least, floor), caps)
    short = rubbing & (pressed < caps - CONVERGED * model.force_scale)
    return (np.where(short, pressed, caps), step) if short.any() else None


def _at_cone(model: EquilibriumModel, field: Solution, options: SolveOptions) -> bool:
    """Whether a vertex of ``field`` rubs within CONE_SLACK of its cone. When none does, the
    cones do not bind the least |f|^2 within the caps, and without them its least is the
    same field: its normal forces are its own."""
    friction = _tangential(field.forces[2], field.forces[3], options.cone)
    return bool(np.any((friction >= (1.0 - CONE_SLACK) * options.mu * field.forces[0])
                       & (friction > SHARE_TOL * model.force_scale)))


class LeastNormals:
    """The least normal forces of _own_caps, one instance per placement test (its calls'
    programs kept: :meth:`__call__`)."""

    def __init__(self):
        self.model = self.solver = None

    def __call__(self, model: EquilibriumModel, options: SolveOptions, load, caps: np.ndarray,
                 interfaces: np.ndarray) -> np.ndarray | None:
        """Per interface of ``interfaces`` (N, per interface of the model, 0 elsewhere) the
        least normal resultant of the forces that leave the net wrenches of ``load`` (a step's
        motion taken out of it): the normal force the motion makes there, not a share of one
        that friction elsewhere could make as well (the least |f|^2 splits a force between
        them). A linear program each, in cones relaxed to their circumscribed octagon (the soc)
        and caps likewise: the least is never above the exact one. Solved by Clarabel, one
        solver whose cost alone changes from one interface to the next, its least the lower of
        its primal and dual objectives (HiGHS' simplex, even kept warm from one interface's
        optimal basis to the next, takes thousands of iterations each: docs/METHOD.md); where
        its iterations run out still converging, by the same solver with iterative refinement
        (LEAST_REFINED_ITER); by HiGHS where neither solves it (a cap of the solver's
        tolerance makes the program nearly infeasible for an interior point: type-b turned
        about y). With more than
        SUM_FIRST interfaces, the least sum of their normal resultants first: an interface
        whose normal resultant is within SHARE_TOL W of 0 at that point (one that
        :func:`_satisfies` accepts) gets 0 without a program of its own: a lower bound of its
        least (fn >= 0), and the least is within the point's accuracy of 0, far below the
        noise floor under which _own_caps takes any least as none, so the caps are the same (a
        partial dome's open course: most of its rubbing interfaces need no normal force).
        None when a grip or a failed program leaves it open.

        The program's matrix and its Clarabel solver are kept from one call to the next on the
        same model, friction and capped interfaces (one test's calls): only the costs and the
        right-hand side (load, caps) differ, which Clarabel's data update takes as solver.Kept
        does (the cost's scale stays the first cost's, as between one call's interfaces).
        A call that asks what the one before it asked gets its answer again: the test's next
        step asks it again when the caps it lowered were only those of the rubbing interfaces,
        which the program leaves out (the 527-block dome's open course, step after step)."""
        if model.grips:
            return None
        capped = np.flatnonzero(np.isfinite(caps))
        if self.model is not model or (self.mu, self.cone) != (options.mu, options.cone) \
                or not np.array_equal(capped, self.capped):
            self._program(model, options, capped)
        asked = (np.array(load, dtype=float), np.array(caps, dtype=float),
                 np.array(interfaces))
        if self.asked is not None and all(np.array_equal(a, b)
                                          for a, b in zip(asked, self.asked)):
            return None if self.answer is None else self.answer.copy()
        self.asked, self.answer = asked, self._least(model, options, *asked)
        return None if self.answer is None else self.answer.copy()

    def _least(self, model: EquilibriumModel, options: SolveOptions, load: np.ndarray,
               caps: np.ndarray, interfaces: np.ndarray) -> np.ndarray | None:
        """:meth:`__call__`'s answer, its program made."""
        from scipy.optimize import linprog
        nv = model.num_vertices
        capped = self.capped
        up = np.concatenate([np.zeros(self.facet_rows)]
                            + ([np.tile(self.h * caps[capped] / model.force_scale,
                                        self.facets)] if len(capped) else []))
        rhs = -np.asarray(load, dtype=float)
        b = np.concatenate([rhs, up, np.zeros(nv)])
        matrix, solver = self.matrix, None      # this call's solver

        def least_of(cost: np.ndarray):
            nonlocal solver
            if solver is None and self.solver is not None:
                solver = self.solver
                solver.update(q=cost, b=b)
            elif solver is None:
                solver = clarabel.DefaultSolver(sp.csc_matrix((3 * nv, 3 * nv)), cost, matrix,
                                                b, self.cones, self.settings)
                if solver.is_data_update_allowed():
                    self.solver = solver
            else:
                solver.update(q=cost)
            first = solver.solve()
            if _cut_off(first):
                solver.update(settings=self.refined)
                found = _solved(solver.solve())
                solver.update(settings=self.settings)
                return found
            return _solved(first)

        def _solved(result):
            x = np.array(result.x)
            return result if str(result.status) == "Solved" and _satisfies(matrix, rhs, up, x) \
                else None, x

        out = np.zeros(len(model.interfaces))
        free = np.zeros(len(model.interfaces), dtype=bool)     # 0 in a point of the program
        if len(interfaces) > SUM_FIRST:
            result, x = least_of(np.concatenate([np.isin(model.vertex_interface, interfaces)
                                                 .astype(float), np.zeros(2 * nv)]))
            if result is not None:
                free = _sums(model, x[:nv]) <= SHARE_TOL
        for k in interfaces:
            if free[k]:
                continue
            cost = np.concatenate([(model.vertex_interface == k).astype(float),
                                   np.zeros(2 * nv)])
            result, _ = least_of(cost)
            if result is not None:
                least = min(result.obj_val, result.obj_val_dual)
            else:
                res = linprog(cost, A_ub=self.upper, b_ub=up if self.upper is not None else None,
                              A_eq=self.equal, b_eq=rhs,
                              bounds=[(0, None)] * nv + [(None, None)] * (2 * nv),
                              method="highs")
                if res.status != 0:
                    return None
                least = res.fun
            out[k] = max(least, 0.0) * model.force_scale
        return out

    def _program(self, model: EquilibriumModel, options: SolveOptions, capped: np.ndarray):
        """The program's matrix, cones and settings for ``model``, the friction of
        ``options`` and caps on ``capped``; no solver yet."""
        nv = model.num_vertices
        angles, h = pyramid_facets("pyramid8-outer" if options.cone == "soc" else options.cone)
        c, s = np.cos(angles), np.sin(angles)
        rows = []
        if math.isfinite(options.mu):       # c fu + s fv - h mu fn <= 0 per vertex and facet
            eye = sp.identity(nv, format="csr")
            rows += [sp.hstack([-h * options.mu * eye, ck * eye, sk * eye])
                     for ck, sk in zip(c, s)]
        facet_rows = len(rows) * nv
        if len(capped):                     # c sum fu + s sum fv <= h cap per capped interface
            member = sp.csr_matrix((np.ones(nv), (model.vertex_interface, np.arange(nv))),
                                   shape=(len(model.interfaces), nv))[capped]
            zero = sp.csr_matrix((len(capped), nv))
            rows += [sp.hstack([zero, ck * member, sk * member]) for ck, sk in zip(c, s)]
        a = model.a_eq
        equal = sp.hstack([a[:, :nv], a[:, 2 * nv:4 * nv]]).tocsc()
        upper = sp.vstack(rows).tocsc() if rows else None
        # Clarabel's rows: the equilibrium, then G x <= g: the rows above and -fn <= 0
        signs = sp.hstack([-sp.identity(nv), sp.csr_matrix((nv, 2 * nv))])
        self.matrix = sp.vstack([equal] + ([upper] if rows else []) + [signs]).tocsc()
        rows_up = facet_rows + len(capped) * len(angles)
        self.cones = [clarabel.ZeroConeT(equal.shape[0]),
                      clarabel.NonnegativeConeT(rows_up + nv)]
        # no iterative refinement of the KKT solves at first (as solver.py's first attempt):
        # Clarabel ends on its iterates' residuals, so the least stays within LEAST_TOL (moved
        # by 1.2e-10 W at most on a partial dome's, for half the time: docs/METHOD.md)
        self.settings, self.refined = (_least_settings(LEAST_MAX_ITER, refine=False),
                                       _least_settings(LEAST_REFINED_ITER, refine=True))
        self.equal, self.upper = equal, upper
        self.model, self.mu, self.cone, self.capped = model, options.mu, options.cone, capped
        self.h, self.facets, self.facet_rows = h, len(angles), facet_rows
        self.solver = self.asked = None


def _least_settings(max_iter: int, refine: bool) -> clarabel.DefaultSettings:
    """Clarabel's settings for the least normal forces' programs."""
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = LEAST_TOL
    settings.max_iter = max_iter
    settings.iterative_refinement_enable = refine
    return settings


def _cut_off(result) -> bool:
    """Whether Clarabel's first attempt at a least normal force's program ran into
    LEAST_MAX_ITER still converging (not a program it finds (almost) infeasible, nor one it
    ends on early for lack of progress: those go to HiGHS, as the shelves' do)."""
    return result.iterations >= LEAST_MAX_ITER and \
        str(result.status) in ("AlmostSolved", "MaxIterations")


def _satisfies(matrix, rhs: np.ndarray, up: np.ndarray, x: np.ndarray) -> bool:
    """Whether ``x`` meets _least_normals' equalities and inequalities to SHARE_TOL W
    absolutely: Clarabel's tolerances are relative to x, and on a program with no field
    near the caps it has called "solved" a least normal force of 1.8e5 W (a variant of the
    squeeze suite's 50 deg pressed incline, at mu 1.0217; HiGHS: infeasible)."""
    residual = matrix @ x - np.concatenate([rhs, up, np.zeros(len(x) // 3)])
    n = len(rhs)
    return bool(np.abs(residual[:n]).max(initial=0.0) <= SHARE_TOL
                and residual[n:].max(initial=0.0) <= SHARE_TOL)


def _settled(model: EquilibriumModel, rigid: EquilibriumModel, options: SolveOptions, load,
             caps: np.ndarray, within: Kept) -> Placement | None:
    """The field that stands once a step leaves no motion: the least one within the caps
    (None if there is none), the grips' wrenches reactions as in the steps (their caps
    come from the steps alone: a field's own normal forces include those a grip's force
    makes, a squeeze). Beyond the grips' capacities, the least field within the caps and
    them if there is one, else ``beyond``: the least wrench that a field within the caps
    needs (_least_hold). ``within``: the solver kept for the problem."""
    bound = caps * (1.0 + CONE_TOL) + SHARE_TOL * model.force_scale
    field = solve(rigid, options, load=load, friction_cap=bound, keep=within)
    if not field.solved:
        return None
    if _held(model, field):
        return Placement(field, caps=bound)
    capped = solve(model, options, load=load, friction_cap=bound)
    return Placement(capped, caps=bound) if capped.solved else \
        Placement(None, beyond=_least_hold(rigid, options, load, bound, field))


def _least_hold(rigid: EquilibriumModel, options: SolveOptions, load, bound: np.ndarray,
                field: Solution) -> Solution:
    """The field within ``bound`` whose robots' wrenches are least (the solver's hold term,
    the check's objective only a tie-break): a robot's wrench is whatever the contacts leave
    it, and any field within the settled caps is one the test accepts (a capped check takes
    it), so the wrench a robot needs beyond its capacity is the least of them. ``field``
    if the solve fails."""
    w = options.weights
    least = solve(rigid, replace(options, weights=Weights(
        w.compression * LEAST_HOLD, w.tension * LEAST_HOLD, w.friction * LEAST_HOLD, 1.0)),
        load=load, friction_cap=bound)
    return least if least.solved else field


def _held(model: EquilibriumModel, solution: Solution) -> bool:
    """Whether the grips' wrenches in ``solution`` are within their capacities."""
    return all(np.linalg.norm(w[:3]) <= g.max_force * (1.0 + CONE_TOL) + SHARE_TOL *
               model.force_scale and np.linalg.norm(w[3:]) <= g.max_torque * (1.0 + CONE_TOL)
               + SHARE_TOL * model.force_scale * model.length_scale
               for g, w in zip(model.grips, solution.wrenches))


def _unless_none(capacity: float) -> float:
    """A grip's capacity made unbounded, unless it is 0 (what the grip cannot apply)."""
    return capacity if capacity == 0 else math.inf


def _within(model: EquilibriumModel, solution: Solution, bound: np.ndarray, cone: str) -> bool:
    """Whether every interface's friction resultant in ``solution`` is within ``bound``."""
    friction = _tangential(*(_sums(model, solution.forces[k]) for k in (2, 3)), cone)
    return bool(np.all(friction <= bound))


def no_caps_bound(blocks, interfaces, free, force_scale: float) -> np.ndarray:
    """Per interface the friction resultant (N) up to which a field keeps the test's first
    caps (none), so that it stands with that field at its first step, wherever the field
    came from: the noise floor and the solver's tolerance. ``free``: the indices of the free
    blocks, weighing ``force_scale`` (W) in all. A field that needs more proves nothing
    unless the test runs on the whole model: a region loaded by kept forces, friction
    included, gets the friction that the whole, set in place from rest, would have to
    build up again (thin domes' open courses)."""
    return _noise_floor(blocks, interfaces, free, force_scale) + SHARE_TOL * force_scale


def _noise_floor(blocks, interfaces, free, force_scale: float) -> np.ndarray:
    """Per interface NOISE_SHARE of the weight of its lighter free block (of the free
    weight W, ``force_scale``, when it joins no free block's weight): a normal resultant
    below it is the interior-point solver's offset from the cone's apex, not a force of the
    motion. ``free``: the indices of the free blocks."""
    weight = np.full(len(blocks), np.inf)
    weight[free] = [blocks[j].mass for j in free]
    weight *= force_scale / max(sum(blocks[j].mass for j in free), 1e-300)
    pairs = np.array([(it.a, it.b) for it in interfaces], dtype=int).reshape(-1, 2)
    lighter = np.minimum(weight[pairs[:, 0]], weight[pairs[:, 1]])
    return NOISE_SHARE * np.where(np.isfinite(lighter), lighter, force_scale)


def _above_noise(normal: np.ndarray, floor: np.ndarray) -> np.ndarray:
    return np.where(normal > floor, normal, 0.0)


def _scaled(model: EquilibriumModel, wrenches: np.ndarray) -> np.ndarray:
    """Net wrenches (N, N m per free block row) in the model's scaled units."""
    e = wrenches.reshape(-1, 6) / model.force_scale
    e[:, 3:] /= model.length_scale
    return e.ravel()


def inertia_metric(model: EquilibriumModel) -> sp.csc_matrix:
    """INERTIA_WEIGHT x the inverse of the free blocks' mass matrix on the scaled
    equilibrium rows (force / W, moment / (W L)), relative to the mean free mass: block
    diagonal, as an upper triangle (what the solver reads). A block's inertia about its
    centroid is that of its vertices as point masses, over 3 (exact for a parallelepiped,
    whose vertices' second moment is 3 times the solid's)."""
    blocks = [model.blocks[j] for j in model.free]
    if not blocks:
        return sp.csc_matrix((0, 0))
    mass = np.array([b.mass for b in blocks], dtype=float)
    mean = float(mass.mean()) or 1.0
    mass = np.where(mass > 0, mass, mean)
    second = np.array([(b.vertices - b.centroid).T @ (b.vertices - b.centroid) / len(b.vertices)
                       for b in blocks])
    size = np.array([b.size for b in blocks])
    eye = np.eye(3)
    inertia = (mass / 3.0)[:, None, None] * (np.trace(second, axis1=1, axis2=2)[:, None, None]
                                             * eye - second)
    inertia += (1e-9 * mass * size ** 2)[:, None, None] * eye     # a flat or linear block
    rotation = mean * model.length_scale ** 2 * np.linalg.inv(inertia)
    m = len(blocks)
    # per block 6 columns: 3 of the force (one diagonal entry each), 3 of the moment (the
    # upper triangle of the 3 x 3 block: 1, 2, 3 entries)
    first = 6 * np.arange(m)
    rows = [first + k for k in range(3)] + [first + 3, first + 3, first + 4, first + 3,
                                            first + 4, first + 5]
    data = [mean / mass] * 3 + [rotation[:, 0, 0], rotation[:, 0, 1], rotation[:, 1, 1],
                                rotation[:, 0, 2], rotation[:, 1, 2], rotation[:, 2, 2]]
    counts = np.array([1, 1, 1, 1, 2, 3])
    indptr = np.concatenate(([0], np.cumsum(np.tile(counts, m))))
    return sp.csc_matrix((INERTIA_WEIGHT * np.column_stack(data).ravel(),
                          np.column_stack(rows).ravel(), indptr), shape=(6 * m, 6 * m))


def _still(model: EquilibriumModel, step: Solution) -> bool:
    """Whether no free block is left with a net force above STILL of its weight (or a net
    moment above STILL of its weight times its size)."""
    return _unbalance(model, step) <= STILL


def _unbalance(model: EquilibriumModel, step: Solution) -> float:
    """The largest net force a step leaves a free block, as a share of its weight (or net
    moment, of its weight times its size)."""
    e = step.unbalanced.reshape(-1, 6)
    weight = np.array([model.blocks[j].mass for j in model.free]) * (
        model.force_scale / sum(model.blocks[j].mass for j in model.free))
    size = np.array([model.blocks[j].size for j in model.free])
    return float(max(np.max(np.linalg.norm(e[:, :3], axis=1) / weight, initial=0.0),
                     np.max(np.linalg.norm(e[:, 3:], axis=1) / (weight * size), initial=0.0)))


def accelerations(model: EquilibriumModel, step: Solution) -> tuple[np.ndarray, np.ndarray]:
    """Per free block (rows of model.free) its acceleration (m/s^2) and angular
    acceleration (rad/s^2) from the step's net wrenches."""
    e = step.unbalanced.reshape(-1, 6)
    upper = inertia_metric(model) / INERTIA_WEIGHT
    metric = upper + sp.triu(upper, 1).T
    scaled = np.column_stack((e[:, :3] / model.force_scale,
                              e[:, 3:] / (model.force_scale * model.length_scale)))
    rate = (metric @ scaled.ravel()).reshape(-1, 6)
    mean = np.mean([model.blocks[j].mass for j in model.free])
    return (rate[:, :3] * model.force_scale / mean,
            rate[:, 3:] * model.force_scale / (mean * model.length_scale))


def _moved(model: EquilibriumModel, step: Solution | None, count: int) -> Placement:
    """The blocks that move at the last step and the interfaces they slide across."""
    if step is None or not step.solved:
        return Placement(None, tuple(int(j) for j in model.free), (), count)
    moved = _motion_of(model, step)
    return Placement(None, *moved, count, motion=step)


def _motion_of(model: EquilibriumModel, step: Solution):
    """(moving blocks, sliding interfaces) of a step: see :class:`Placement`."""
    linear, angular = accelerations(model, step)
    sizes = np.array([model.blocks[j].size for j in model.free])
    rate = np.linalg.norm(linear, axis=1) + np.linalg.norm(angular, axis=1) * sizes
    g = float(np.linalg.norm(model.gravity))
    moving = np.flatnonzero((rate > MOVING_SHARE * rate.max(initial=0.0))
                            & (rate > MOVING_G * g))
    order = moving[np.argsort(-_tied(rate[moving]), kind="stable")]
    row = np.full(len(model.blocks), -1)
    row[model.free] = np.arange(len(model.free))
    normal = _tied(_sums(model, step.forces[0]))
    slide = []
    for k, it in enumerate(model.interfaces):
        ra, rb = row[it.a], row[it.b]
        if not ((ra >= 0 and ra in moving) or (rb >= 0 and rb in moving)):
            continue
        x = it.frame.origin
        va = _velocity(linear, angular, ra, x, model.blocks[it.a].centroid)
        vb = _velocity(linear, angular, rb, x, model.blocks[it.b].centroid)
        d = vb - va
        n = it.frame.n
        dn = float(d @ n)
        dt = float(np.linalg.norm(d - dn * n))
        if dt > MOVING_SHARE * rate.max() and dn <= dt:     # sliding, not lifting off
            slide.append((-normal[k], -_tied(dt, rate.max()), k))
    return (tuple(int(model.free[r]) for r in order), tuple(k for _, _, k in sorted(slide)))


def _tied(values, largest=None):
    """``values`` rounded to RANK_DIGITS of the largest: equal in a symmetric scene to
    the solver's rounding, they rank in scene order, whatever solver made them."""
    values = np.asarray(values, dtype=float)
    unit = float(np.abs(values).max(initial=0.0)) if largest is None else float(largest)
    return np.round(values / unit, RANK_DIGITS) * unit if unit > 0 else values


def _velocity(linear, angular, r: int, x, centre) -> np.ndarray:
    if r < 0:
        return np.zeros(3)
    return linear[r] + np.cross(angular[r], x - centre)


def _sums(model: EquilibriumModel, values: np.ndarray) -> np.ndarray:
    """Per-vertex values summed per interface."""
    return np.bincount(model.vertex_interface, values, minlength=len(model.interfaces))


def _tangential(fu: np.ndarray, fv: np.ndarray, cone: str) -> np.ndarray:
    """The friction force in the norm of ``cone`` (a pyramid's facets over its inradius
    factor), to compare with mu fn."""
    if cone == "soc":
        return np.hypot(fu, fv)
    angles, h = pyramid_facets(cone)
    return np.max(np.outer(fu, np.cos(angles)) + np.outer(fv, np.sin(angles)), axis=1) / h
