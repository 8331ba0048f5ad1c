"""Look-ahead: the steps of a plan still to come, checked on the as-built state.

A plan is a planned scene (blocks at design, ``sequence`` the order, ``holds`` by step). While
it is built, the blocks placed so far (a prefix of the order) are where the camera measured
them; the look-ahead checks the next steps as ``check --sequence`` checks them, with the
placed blocks at their measured poses, the rest at design, the holds as the plan has them,
under the declared pose uncertainty. A step fails when it does not stand (a hold beyond a
robot's capacity included: HOLD_EXCEEDED), when its block cannot reach its pose (not
insertable: a deviated block may be in its way), or when its margin is below
``min_margin_g``.

:class:`StepRunner` checks steps of plans over one as-built geometry: contacts are detected
once, each step through the incremental checker (:class:`StepChecker`), and each state
(blocks present, blocks held with their grips, the block placed: :func:`state_key`) is
checked once, whichever plan it belongs to: a repair's candidates share most of their states
with the plan (:mod:`rbe_ros.analysis.repair`). With
workers, each state is checked whole in a worker process (:class:`StepPool`), the states
asked for first, then those queued ahead (:meth:`StepRunner.prefetch`): the verdicts are
those of the whole steps, as the incremental checker's are. A look-ahead hands what it checked
to the repair that follows it on the same as-built state (:class:`Checked`; the node's repair
runs in a process of its own): the repair checks none of those states again and walks on from
the look-ahead's first failing step with the look-ahead's checker there, as it would have
walked to it; the repair hands its states back to the look-ahead of the repaired plan.
"""
from __future__ import annotations

import collections
import copy
import math
import time
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, wait
from dataclasses import dataclass, field, replace

import numpy as np

from ..rbe.result import NOT_COMPUTED, Report, Status
from ..scene import Hold, Scene, SceneError, make_scene
from .asbuilt import declared
from .assembly import Assembly
from .executors import StepPool
from .incremental import StepChecker
from .margin import DEFAULT_DIRECTIONS
from .options import CheckOptions
from .pipeline import Placed, _completed, slim, tolerance_asked
from .steps import Step, sequence_step, step_count, step_state
from .validate import validated_assembly
from .verdict import check

#: Look-ahead steps of the node by default (its ``lookahead_steps`` parameter).
DEFAULT_LOOKAHEAD = 10


def plan_order(plan: Scene) -> tuple[str, ...]:
    """The order of ``plan``: its sequence, which must place every free block (SceneError:
    a scene that is not a plan)."""
    free = [b.id for b in plan.blocks if not b.support]
    if not plan.sequence:
        raise SceneError(f"{plan.name!r} is not a plan: it has no sequence (rbe-ros plan -o "
                         "writes one)")
    missing = [b for b in free if b not in set(plan.sequence)]
    if missing:
        raise SceneError(f"{plan.name!r} is not a whole plan: its sequence does not place "
                         f"{', '.join(missing[:5])}{' ...' if len(missing) > 5 else ''}")
    return plan.sequence


def placed_count(plan: Scene, built: Scene) -> int:
    """How many steps of ``plan`` are done in the as-built scene ``built`` (the design's
    supports and the measured blocks, :func:`rbe_ros.io.poses.scene_at_poses`): its free
    blocks, which must be the first of the plan's order (SceneError naming a block that is
    not in the plan, or one measured out of order)."""
    order = plan_order(plan)
    ids = {b.id for b in plan.blocks}
    unknown = [b.id for b in built.blocks if b.id not in ids]
    if unknown:
        raise SceneError(f"measured poses name {'a block' if len(unknown) == 1 else 'blocks'} "
                         f"not in the plan {plan.name!r}: "
                         f"{', '.join(repr(i) for i in unknown[:5])}")
    free = set(order)
    placed = {b.id for b in built.blocks if b.id in free}
    count = len(placed)
    if set(order[:count]) != placed:
        first = next(k for k, b in enumerate(order) if b not in placed)
        early = next(b for b in order[first:] if b in placed)
        raise SceneError(f"measured blocks are not a prefix of the plan's order: {early!r} "
                         f"(step {order.index(early)}) is measured but {order[first]!r} "
                         f"(step {first}) is not")
    return count


def as_built_plan(plan: Scene, built: Scene) -> Scene:
    """``plan`` with the blocks of the as-built scene ``built`` (measured blocks and
    supports) at their poses there, the others at design; sequence and holds kept."""
    placed_count(plan, built)
    at = {b.id: b for b in built.blocks}
    return replace(plan, blocks=tuple(at.get(b.id, b) for b in plan.blocks))


def as_built_state(plan: Scene, built: Scene) -> Scene:
    """The as-built scene ``built`` as ``plan`` has it at its step (the state of the
    look-ahead's as-built check: :func:`look_ahead`'s ``as_built``), to check as a whole:
    the blocks present at the step placed last (the placed ones at their measured poses, the
    supports the plan keeps then) with the holds active then, held to the end (their grips
    kept). ``built`` itself when nothing is placed. SceneError as :func:`placed_count`."""
    placed = placed_count(plan, built)
    if not placed:
        return built
    scene = as_built_plan(plan, built)
    step = sequence_step(scene, placed - 1)
    present = set(step.present)
    return replace(scene, blocks=tuple(b for b in scene.blocks if b.id in present),
                   sequence=plan_order(plan)[:placed], approach=scene.approach[:placed],
                   holds=tuple(replace(h, from_step=0, until_step=None) for h in scene.holds
                               if h.active(placed - 1) and h.block in present))


def check_plan_design(plan: Scene, design: Scene) -> None:
    """SceneError unless ``plan`` is a plan of ``design``: the same blocks (ids, supports,
    shapes and masses); poses may differ (a plan may be written at measured poses)."""
    ours, theirs = ({b.id: b for b in s.blocks} for s in (plan, design))
    if set(ours) != set(theirs):
        differ = sorted(set(ours) ^ set(theirs))
        raise SceneError(f"the plan {plan.name!r} does not match the design {design.name!r}: "
                         f"blocks {', '.join(repr(i) for i in differ[:5])} are in only one")
    for i, b in ours.items():
        d = theirs[i]
        if (b.support != d.support or b.vertices.shape != d.vertices.shape
                or not np.allclose(b.vertices, d.vertices) or b.faces != d.faces
                or not math.isclose(b.mass, d.mass) or not math.isclose(b.density, d.density)):
            raise SceneError(f"the plan {plan.name!r} does not match the design "
                             f"{design.name!r}: block {i!r} differs (shape, mass or support)")


@dataclass(frozen=True)
class StepAhead:
    """One step checked ahead (the fields of ``rbe_msgs/LookaheadStep``)."""

    step: int
    block: str                      # "" at a release step
    stable: bool
    status: Status
    insertable: bool
    margin_g: float                 # NOT_COMPUTED (-1) when no margin was asked for
    max_hold_force: float           # N; 0 when nothing is held
    held: tuple[str, ...]
    message: str                    # why it fails ("" when it passes)
    report: Report = field(repr=False, default=None)   # the step's report (slim)

    @property
    def passes(self) -> bool:
        return not self.message


@dataclass(frozen=True)
class Lookahead:
    """The as-built state and the steps ahead of it (``rbe_msgs/ExecutionState``)."""

    current_step: int               # blocks placed; the next step to place
    total_steps: int                # steps of the plan (a release step included)
    as_built: Report | None         # the as-built state's check (None: nothing placed)
    steps: list[StepAhead]
    first_failing_step: int         # -1: every step checked passes
    message: str                    # why the plan cannot go on as planned ("" fine)
    time: float = 0.0               # s
    #: a cell's plan: its timeline at the measured poses, the actions of the step done
    #: last whose state is the as-built one with its check (:meth:`rbe_ros.analysis.
    #: cell_execution.CellAhead.timeline`)
    timeline: object = None
    #: the states checked, for the repair that follows (:func:`rbe_ros.analysis.repair.
    #: repair_plan`'s ``checked``)
    checked: Checked | None = field(default=None, repr=False)

    @property
    def failing(self) -> StepAhead | None:
        return next((s for s in self.steps if not s.passes), None)


def failure(report: Report, min_margin_g: float = 0.0) -> str:
    """Why a step's ``report`` fails the look-ahead ("" when it passes): it does not stand
    (a hold beyond capacity is HOLD_EXCEEDED), its block is not insertable, or its margin is
    below ``min_margin_g`` (> 0)."""
    if not report.stable:
        return f"{report.status.name}: {report.message}"
    if not report.insertable:
        return f"not insertable: {report.message}"
    if min_margin_g > 0 and report.margin_g != NOT_COMPUTED and report.margin_g < min_margin_g:
        return f"margin {report.margin_g:.4f} g below the minimum {min_margin_g:g} g"
    return ""


def where(step: int, block: str) -> str:
    """"step 12 (v05)", or "step 12 (release)" for a release step."""
    return f"step {step} ({block or 'release'})"


def _basis(scene: Scene, options: CheckOptions, placed: int, min_margin_g: float) -> tuple:
    """What the reports of a :class:`StepRunner` are of, whichever plan: the blocks at
    their poses (the placed ones measured), the options, the steps done and the margin
    asked for (a plan's part is in each state's key: :func:`state_key`)."""
    poses = tuple((b.id, b.support, b.position.tobytes(), b.orientation.tobytes())
                  for b in scene.blocks)
    return poses, options, placed, min_margin_g


def _bytes(a) -> bytes | None:
    return None if a is None else np.asarray(a, dtype=float).tobytes()


def state_key(plan: Scene, step: Step) -> tuple:
    """The key of the state of ``step`` of ``plan`` (a plan over a runner's blocks): all of
    the plan its report depends on: the blocks present and held, the held blocks' grips
    and capacities, the block placed and its approach."""
    grips = tuple((g.block, _bytes(g.point), g.max_force, g.max_torque) for g in step.grips)
    return step.present, step.held, grips, step.block, _bytes(plan.approach_of(step.block))


@dataclass(frozen=True)
class Checked:
    """What a :class:`StepRunner` checked (a look-ahead's), for another on the same as-built
    state (the repair that follows it): each state's report, and the walk of the plan up to
    its first failing step (not included), with the incremental checker there."""

    basis: tuple                        # :func:`_basis` of the runner's scene
    reports: dict[tuple, Report]        # :func:`state_key` -> report, slim
    walk: tuple[tuple, ...]             # the states walked, from the as-built one, in order
    checker: StepChecker                # the checker after the walk

    def answered(self, by: "Checked") -> "Checked":
        """These states with the reports ``by`` has of them: a repair that began on a
        look-ahead's states before the as-built state's tolerance question was answered
        (:func:`look_ahead`'s ``on_failing``) hands back that state's report as it had it;
        ``by``, the look-ahead's own, has the answer."""
        return replace(self, reports={k: by.reports.get(k, r) for k, r in self.reports.items()})


@dataclass(frozen=True)
class Given:
    """The as-built state's check made elsewhere as a whole (the node's ~/report, made on
    its check thread while the look-ahead runs), each part waited for when the look-ahead
    needs it: ``verdict()``, its report before the tolerance question is asked (with its
    interfaces: taken as the look-ahead's check), then ``asked()``, the report with it
    (None, either: no report to take). ``waiting``: the verdict is still being made (the
    look-ahead solves the first step ahead meanwhile: :meth:`StepRunner.early`)."""

    verdict: Callable[[], Report | None]
    asked: Callable[[], Report | None]
    waiting: bool = False

    @classmethod
    def made(cls, report: Report | None) -> "Given":
        """A check made before, its tolerance question asked (a replay's ~/report)."""
        return cls(lambda: report, lambda: report)


class StepRunner:
    """Checks steps of plans on one as-built scene (the blocks at their poses; a plan is a
    sequence and holds over these blocks), each state once.

    ``options``: the check's (the scene's declared pose uncertainty applied); a margin is
    computed when they ask for one or ``min_margin_g`` > 0. The as-built state (supports and
    the placed blocks) is validated as a check validates a scene; blocks not placed are at
    design and may overlap a deviated one: their step is then not insertable. ``workers``
    >= 1: states checked whole on that many processes (:meth:`close` them), not by
    ``checker``. ``tolerance`` False: whether the as-built state's verdict hangs on the
    contact tolerance is not asked with its check but when :meth:`explained` asks it (a
    repair needs only whether it stands: it asks it of a state that does not; a
    look-ahead after the steps ahead, which the robot needs first). ``checked``: a
    look-ahead's states on the same as-built state, known (ValueError when they are of
    another)."""

    def __init__(self, scene: Scene, options: CheckOptions, placed: int,
                 min_margin_g: float = 0.0,
                 should_stop: Callable[[], bool] | None = None, workers: int = 0, *,
                 tolerance: bool = True, checked: Checked | None = None):
        options = declared(options, scene)
        if min_margin_g > 0 and not options.margin_directions:
            options = replace(options, margin_directions=DEFAULT_DIRECTIONS)
        self.scene, self.options, self.min_margin_g = scene, options, min_margin_g
        self.placed, self.tolerance = placed, tolerance
        self.should_stop = should_stop
        self.basis = _basis(scene, options, placed, min_margin_g)
        if checked is not None and checked.basis != self.basis:
            raise ValueError("the states handed over were checked on another as-built state "
                             "or with other options")
        self.handed = checked
        order = plan_order(scene)
        built = {*order[:placed]} | {b.id for b in scene.blocks if b.support}
        validated_assembly(scene.subset(built), options.limits, options.contact)
        self.full = Assembly.from_scene(scene, options.contact)
        self.memo: dict[tuple, Report] = dict(checked.reports) if checked else {}
        #: states solved whole before the walk reached them (:meth:`early`)
        self._early: dict[tuple, Report] = {}
        #: as-built states the tolerance was not asked of: their check (whole) and assembly
        self._unasked: dict[tuple, tuple[Report, Assembly]] = {}
        self.checks = 0
        self.checker = self._new_checker()
        #: further checks of each step ahead (a cell's: :mod:`rbe_ros.analysis.
        #: cell_execution`): ``extra(plan, step)`` -> the step, failing or not
        self.extra: Callable[[Scene, StepAhead], StepAhead] | None = None
        self.pool = StepPool(self.full, options, workers) if workers else None
        self._pending: dict[tuple, object] = {}        # state -> its future, running
        self._queue: collections.deque = collections.deque()    # (state, task) to run next

    def _new_checker(self) -> StepChecker:
        """A checker that has walked no step yet (the options' full solve: no regions)."""
        return StepChecker(self.options, local=not self.options.full_solve)

    def close(self) -> None:
        """Stop the workers (a check under way is dropped)."""
        if self.pool is not None:
            self.pool.close()

    def _task(self, plan: Scene, step: Step) -> tuple[tuple, tuple]:
        """(state, the arguments of its whole check in a worker) of ``step`` of ``plan``."""
        return state_key(plan, step), (step.present, step.held, step.grips, step.block,
                                           plan.approach_of(step.block),
                                           step.index < self.placed)

    def prefetch(self, plan: Scene, steps: Iterable[int], first: bool = False) -> None:
        """Queue the states of ``steps`` of ``plan`` for the workers (no workers: nothing),
        after those queued already or, ``first``, before them."""
        if self.pool is None:
            return
        tasks = [t for t in (self._task(plan, sequence_step(plan, k)) for k in steps)
                 if t[0] not in self.memo and t[0] not in self._pending]
        if first:
            self._queue.extendleft(reversed(tasks))
        else:
            self._queue.extend(tasks)
        self._top_up()

    def _top_up(self) -> None:
        while self._queue and len(self._pending) < self.pool.workers:
            key, task = self._queue.popleft()
            if key not in self.memo and key not in self._pending:
                self._pending[key] = self.pool.submit(*task)

    def _pooled(self, plan: Scene, step: Step) -> Report:
        """The report of the state of ``step`` of ``plan`` from the workers (submitted now
        unless it is under way), the others that finish meanwhile kept."""
        key, task = self._task(plan, step)
        if key not in self._pending:
            self._pending[key] = self.pool.submit(*task)
        while key not in self.memo:
            if self.should_stop is not None and self.should_stop():
                raise TimeoutError(f"stopped at {where(step.index, step.block)}")
            wait(list(self._pending.values()), timeout=0.5, return_when=FIRST_COMPLETED)
            for state, future in list(self._pending.items()):
                if future.done():
                    self.memo[state] = future.result()
                    del self._pending[state]
                    self.checks += 1
            self._top_up()
        return self.memo[key]

    def report(self, plan: Scene, k: int, checker: StepChecker) -> Report:
        """The report of step ``k`` of ``plan`` (a scene over these blocks: sequence and
        holds), slim; ``checker`` is advanced when the state is new."""
        step = sequence_step(plan, k)
        found = self.memo.get(state_key(plan, step))
        if found is None and self.pool is not None:
            found = self._pooled(plan, step)
        if found is None:
            found = self._check(plan, step, checker)
        return replace(found, step_index=k, block_placed=step.block)

    def early(self, plan: Scene, k: int) -> None:
        """Solve step ``k`` of ``plan`` whole now, before the walk reaches it (the node's
        look-ahead solves the first step ahead while the node checks the as-built state on
        its own thread): its check is then that solve wherever the regions around the new
        block do not settle the step (:meth:`StepChecker.check`'s ``whole``), every report
        the one the walk would have made."""
        if self.pool is not None or k >= step_count(plan):
            return
        step = sequence_step(plan, k)
        key = state_key(plan, step)
        if key not in self.memo:
            self._early[key] = check(self.full.subset(step.present, step.held, step.grips),
                                     self.options)

    def _check(self, plan: Scene, step: Step, checker: StepChecker) -> Report:
        """The check of ``step`` of ``plan`` by ``checker``, kept (slim)."""
        if self.should_stop is not None and self.should_stop():
            raise TimeoutError(f"stopped before {where(step.index, step.block)}")
        assembly = self.full.subset(step.present, step.held, step.grips)
        key = state_key(plan, step)
        raw = checker.check(assembly, self._early.pop(key, None))
        # whether a verdict hangs on the contact tolerance is asked of the state built
        # (placed blocks only), not of the steps ahead: one or two solves each
        found = _completed(raw, assembly, step.held, self.options,
                           Placed(self.full, step.present, step.block,
                                  plan.approach_of(step.block)),
                           tolerance=self.tolerance and step.index < self.placed)
        if not self.tolerance and step.index < self.placed:
            self._unasked[key] = (raw, assembly)
        found = self.memo[key] = slim(found)
        self.checks += 1
        return found

    def adopt(self, plan: Scene, k: int, report: Report) -> None:
        """Keep ``report``, the planner's of step ``k`` (past the as-built state) of
        ``plan`` on these blocks (:attr:`rbe_ros.analysis.planning.Plan.reports`: slim, each
        held block gripped at its centroid within the check's capacities, the placed block's
        approach its own choice, a margin when one is asked for), as that state's, which is
        then not checked again: when it is that state's check, i.e. the same blocks held
        with those grips, no approach given or the one the planner chose, and the margin
        made when these options ask for it. Else the state is checked when it is asked for."""
        step = sequence_step(plan, k)
        given = plan.approach_of(step.block)
        if (k < self.placed or set(report.held_blocks) != set(step.held)
                or any(g.point is not None or g.max_force is not None
                       or g.max_torque is not None for g in step.grips)
                or (given is not None and self.options.insertion.enabled
                    and not (report.insertable
                             and np.array_equal(given, report.insertion_direction)))
                or (self.options.margin_directions and report.margin_g == NOT_COMPUTED)):
            return
        self.memo.setdefault(state_key(plan, step), replace(report, held_blocks=step.held))

    def take(self, plan: Scene, checker: StepChecker, report: Report,
             options: CheckOptions) -> bool:
        """Take ``report`` as the as-built state's of ``plan`` (its step ``placed - 1``),
        checked elsewhere as a whole under ``options`` with its tolerance question asked
        and its interfaces (the node's ~/report): kept as this runner's check of it, and
        ``checker`` advanced by it as by that check, so that the steps ahead get the same
        reports. False (nothing taken) when the state is known already, or the report is
        not of a check this runner would make: other options (a margin asked for by
        ``min_margin_g``), no verdict, other interfaces."""
        step = sequence_step(plan, self.placed - 1)
        key = state_key(plan, step)
        if key in self.memo or declared(options, self.scene) != self.options \
                or report.status in (Status.SOLVER_FAILED, Status.INVALID_INPUT):
            return False
        assembly = self.full.subset(step.present, step.held, step.grips)
        ids = [b.id for b in assembly.blocks]
        if [(ids[it.a], ids[it.b]) for it in assembly.interfaces] != \
                [(r.block_a, r.block_b) for r in report.interfaces]:
            return False
        checker.advance(assembly, report)
        self.memo[key] = slim(report)
        return True

    def explained(self, plan: Scene, asked: Callable[[], Report | None] | None = None
                  ) -> Report:
        """The report of the as-built state of ``plan`` (its step ``placed - 1``) with
        whether its verdict hangs on the contact tolerance, asked now if it was not (of
        the state's check: the same report as a check that asked it). ``asked``: the
        state's report was taken (:meth:`take`) before its question was answered
        elsewhere, and this gives it with the answer (None: the report as taken)."""
        key = self._key(plan, self.placed - 1)
        answered = asked() if asked is not None else None
        if answered is not None:
            self.memo[key] = slim(answered)
        elif key in self._unasked:
            raw, assembly = self._unasked.pop(key)
            self.memo[key] = slim(tolerance_asked(self.memo[key], raw, assembly,
                                                  self.options))
        return self.report(plan, self.placed - 1, self.checker)

    def ahead(self, plan: Scene, k: int, checker: StepChecker) -> StepAhead:
        """Step ``k`` of ``plan`` as a look-ahead step."""
        report = self.report(plan, k, checker)
        force = max((float(np.linalg.norm(w.force)) for w in report.hold_wrenches),
                    default=0.0)
        step = StepAhead(k, report.block_placed, report.stable, report.status,
                         report.insertable, report.margin_g, force, report.held_blocks,
                         failure(report, self.min_margin_g), report)
        return step if self.extra is None else self.extra(plan, step)

    def scan(self, plan: Scene, start: int, stop: int, checker: StepChecker,
             until_failure: bool = True, forks: list | None = None) -> list[StepAhead]:
        """Steps ``start`` .. ``stop - 1`` of ``plan``, in order (up to the first that fails
        with ``until_failure``); ``checker`` is advanced through them (``forks``: given, a
        copy of it before each step appended)."""
        out = []
        for k in range(start, stop):
            if forks is not None:
                forks.append(self.fork(checker))
            out.append(self.ahead(plan, k, checker))
            if until_failure and not out[-1].passes:
                break
        return out

    def fork(self, checker: StepChecker) -> StepChecker:
        """A copy of ``checker`` to go on from where it is (its kept state is shared, never
        changed in place)."""
        return copy.copy(checker)

    def _key(self, plan: Scene, k: int) -> tuple:
        return state_key(plan, sequence_step(plan, k))

    def walker(self, plan: Scene) -> StepChecker:
        """The checker to walk ``plan``'s steps with from the as-built state: where the
        handed-over walk stopped when its states are ``plan``'s first ones (each of them
        known: the walk goes on as if it had made them), else :attr:`checker`."""
        walk = self.handed.walk if self.handed is not None else ()
        first = max(self.placed - 1, 0)
        if self.handed is not None and first + len(walk) <= step_count(plan) and all(
                self._key(plan, first + i) == key for i, key in enumerate(walk)):
            return self.fork(self.handed.checker)
        return self.checker

    def handover(self, plan: Scene, steps: list[StepAhead], forks: list[StepChecker],
                 checker: StepChecker, fresh: StepChecker) -> Checked:
        """What this runner checked, for a runner on the same as-built state: the walk of
        ``plan`` from the as-built state through ``steps`` (scanned with ``forks``, from
        ``fresh``: the checker before the as-built state; ``checker`` after them) up to the
        first state whose own check fails (a cell's failing action is not its state's)."""
        first = max(self.placed - 1, 0)
        walk = []
        for k in range(first, first + len(steps) + bool(self.placed)):
            key = self._key(plan, k)
            report = self.memo[key]
            # the as-built state fails a walk when it does not stand (the repair's test)
            if not report.stable if k < self.placed else failure(report, self.min_margin_g):
                at = fresh if k < self.placed else forks[k - self.placed]
                return Checked(self.basis, dict(self.memo), tuple(walk), self.fork(at))
            walk.append(key)
        return Checked(self.basis, dict(self.memo), tuple(walk), self.fork(checker))

    def known(self) -> Checked:
        """The states this runner checked, for a look-ahead on the same as-built state (of
        another plan: the repaired one), no walk handed over (those whose tolerance
        question was not asked left out: a look-ahead's as-built report has it)."""
        return Checked(self.basis, {k: r for k, r in self.memo.items() if k not in self._unasked},
                       (), self._new_checker())


def look_ahead(plan: Scene, built: Scene, options: CheckOptions = CheckOptions(), *,
               lookahead_steps: int = DEFAULT_LOOKAHEAD, min_margin_g: float = 0.0,
               until_failure: bool = False, cell=None, checked: Checked | None = None,
               as_built: Report | Given | None = None,
               on_failing: Callable[[int, Checked], None] | None = None) -> Lookahead:
    """Check the as-built state of ``plan`` (the free blocks of the as-built scene ``built``
    placed, a prefix of its order, at their measured poses) and its next ``lookahead_steps``
    steps (0: to the end) with the rest at design and the plan's holds, under ``options`` and
    the plan's declared pose uncertainty. ``until_failure``: stop at the first step that fails.
    ``cell``: the plan's cell (a :class:`rbe_ros.analysis.cell_execution.CellPlan`): each
    step's states between the robots' actions checked too, and the timeline kept.
    ``checked``: states known on the same as-built state (the repair's, for the look-ahead
    of the repaired plan), not checked again; the states known and checked are handed on
    (:attr:`Lookahead.checked`: to a repair of the repaired plan). ``as_built``: the
    report of the as-built state (:func:`as_built_state`) checked as a whole under
    ``options``, with its interfaces (the node's ~/report): neither checked nor asked its
    tolerance question again (:meth:`StepRunner.take`; checked when it is not of the same
    check); :class:`Given` while it is made elsewhere.
    ``on_failing(step, checked)``: called as soon as a step ahead fails on an as-built
    state that stands, with the states checked, before the as-built state's tolerance
    question is answered (the repair may begin: the robot needs it first).

    Raises SceneError for bad input: measured blocks not in the plan, or not a prefix of its
    order, a plan that is not one (no whole sequence), measured blocks that interpenetrate."""
    start = time.perf_counter()
    if lookahead_steps < 0:
        raise SceneError(f"lookahead_steps must be >= 0, not {lookahead_steps}")
    scene = as_built_plan(plan, built)
    placed = placed_count(plan, built)
    # the as-built state's tolerance question after the steps ahead: whether they stand
    # is what the robot needs first
    runner = StepRunner(scene, options, placed, min_margin_g, tolerance=False,
                        checked=checked)
    if cell is not None:
        runner.extra = cell.ahead(runner)
    checker = runner.walker(scene)
    fresh = runner.fork(checker)
    total = step_count(scene)
    given = Given.made(as_built) if isinstance(as_built, Report) else as_built
    taken = False
    if placed:
        if given is not None:
            if given.waiting:
                runner.early(scene, placed)
            verdict = given.verdict()
            taken = verdict is not None and runner.take(scene, checker, verdict, options)
        if not taken:
            runner.report(scene, placed - 1, checker)
    stop = total if lookahead_steps == 0 else min(total, placed + lookahead_steps)
    forks: list[StepChecker] = []
    steps = runner.scan(scene, placed, stop, checker, until_failure, forks)
    failing = next((s for s in steps if not s.passes), None)
    if on_failing is not None and failing is not None and (
            not placed or runner.report(scene, placed - 1, checker).stable):
        on_failing(failing.step, runner.handover(scene, steps, forks, checker, fresh))
    as_built = runner.explained(scene, given.asked if taken else None) if placed else None
    message = ""
    if as_built is not None and not as_built.stable:
        message = f"as built, {where(placed - 1, as_built.block_placed)} does not stand: " \
                  f"{as_built.message}"
    elif failing is not None:
        message = f"{where(failing.step, failing.block)} fails at the measured poses: " \
                  f"{failing.message}"
    timeline = None if cell is None else \
        runner.extra.timeline(scene, range(placed - 1, placed), known_only=True)
    return Lookahead(placed, total, as_built, steps,
                     -1 if failing is None else failing.step, message,
                     time.perf_counter() - start, timeline,
                     runner.handover(scene, steps, forks, checker, fresh))


def held_by_step(plan: Scene) -> list[tuple[str, ...]]:
    """The free blocks held at each step of ``plan`` (a release step included)."""
    order = plan_order(plan)
    return [step_state(plan, order, k)[1] for k in range(step_count(plan))]


def holds_of(plan: Scene, order, held: list[tuple[str, ...]]) -> tuple[Hold, ...]:
    """The holds of ``plan`` with its free blocks held at step k as ``held[k]`` says (one
    hold per run of steps; a run to the last entry of ``held`` ends there when a release
    step follows, else never), grips and capacities as the plan's hold of that block gives
    them; the plan's holds of supports (scaffolds) kept."""
    supports = {b.id for b in plan.blocks if b.support}
    given = {}
    for h in plan.holds:
        given.setdefault(h.block, h)
    out = [h for h in plan.holds if h.block in supports]
    for block in order:
        k = 0
        while k < len(held):
            if block in held[k]:
                first = k
                while k < len(held) and block in held[k]:
                    k += 1
                h = given.get(block)
                out.append(Hold(block, first, k if k < len(held) else None,
                                *((h.grip, h.max_force, h.max_torque) if h else ())))
            k += 1
    return tuple(out)


def with_plan(scene: Scene, order, held: list[tuple[str, ...]]) -> Scene:
    """``scene`` with the order ``order`` and the free blocks held as ``held`` (by step; a
    release step appended when the last placement holds blocks)."""
    held = list(held[:len(order)])
    if held and held[-1]:
        held.append(())
    return make_scene(scene.name, scene.blocks, scene.gravity, order,
                      holds_of(scene, order, held), scene.pose_uncertainty,
                      approaches(scene, order))


def approaches(scene: Scene, order) -> tuple:
    """The approaches of ``scene`` (one per step of its sequence) for the steps of
    ``order``: each block's its own, whatever its step (none given: none)."""
    if not scene.approach:
        return ()
    given = dict(zip(scene.sequence, scene.approach))
    return tuple(given.get(b) for b in order)


__all__ = ["Checked", "DEFAULT_LOOKAHEAD", "Given", "Lookahead", "StepAhead", "StepRunner",
           "approaches", "as_built_plan", "as_built_state", "check_plan_design", "failure",
           "held_by_step", "holds_of", "look_ahead", "placed_count", "plan_order", "state_key",
           "where", "with_plan"]
