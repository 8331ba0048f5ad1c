"""Executing a plan from measured poses: the node's (``~/execution``, ``~/plan_update``) and
the replay's one definition of what a pose message means for the plan.

The plan is a planned scene (the design with a sequence and holds: ``design_file``, a
design sent with a sequence on ``~/design``). The measured free blocks must be a prefix of
its order: they are the steps done, and the next step is the first block not measured. The
next ``lookahead_steps`` steps are checked with the placed blocks at their measured poses
and the rest at design (the look-ahead of the core); when one fails (not stable, not
insertable, a hold beyond capacity, a margin below ``min_margin_g``) the rest of the plan
is repaired from the as-built state (the repair of the core), the repaired plan is sent,
and the look-ahead is made again on it. Poses that do not fit the plan (a block out of the
plan's order, a block not in the design) make the state inactive with the reason; the
as-built check goes on as always.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

from ..analysis.margin import DEFAULT_DIRECTIONS
from ..analysis.options import CheckOptions
from ..analysis.pipeline import check_sequence, slim
from ..analysis.planning import plan_sequence
from ..rbe.result import Report
from ..scene import Hold, Scene, SceneError, make_block
from .messages import execution_to_dict, lookahead_step_to_dict, plan_update_to_dict

#: Defaults of the node's parameters (and of a bag recorded before them).
LOOKAHEAD_STEPS = 10
MIN_MARGIN_G = 0.0
#: Kinds of output of one as-built state, in order: an ExecutionState, a PlanUpdate.
EXECUTION, PLAN_UPDATE = "execution", "plan_update"


@dataclass(frozen=True)
class Repair:
    """A repair of the rest of a plan: the whole order and holds (the placed prefix kept)."""

    feasible: bool
    kind: str                    # "hold", "swap", "replan" or "none"
    order: tuple[str, ...]
    holds: tuple[Hold, ...]
    message: str


# --- the core's look-ahead and repair (rbe_ros.analysis) ------------------------------------
# TODO(repair core): the two calls below go to the repair engineer's look-ahead and repair
# once they land; until then the existing step check and planner stand in for them.

def look_ahead(plan: Scene, current: int, count: int, options: CheckOptions) -> list[Report]:
    """Reports of the steps ``current`` .. ``current + count - 1`` (to the end: count 0) of
    ``plan`` (placed blocks already at their measured poses)."""
    end = len(plan.sequence) if count <= 0 else min(len(plan.sequence), current + count)
    done = [0]

    def enough() -> bool:
        return done[0] >= end

    def step(_report: Report, _total: int) -> None:
        done[0] += 1

    reports = check_sequence(plan, options, on_step=step, cancelled=enough, keep=slim)
    return [r for r in reports if current <= r.step_index < end]


def repair_plan(plan: Scene, current: int, options: CheckOptions) -> Repair:
    """The rest of ``plan`` after its first ``current`` steps repaired (as many holds at a
    step as the plan has at most)."""
    held = max((sum(h.active(k) and h.block in plan.sequence[:k + 1] for h in plan.holds)
                for k in range(len(plan.sequence))), default=0)
    found = plan_sequence(replace(plan, sequence=plan.sequence[:current], holds=()),
                          max(held, 1), options, keep_sequence=True)
    holds = found.scene.holds if found.scene is not None else ()
    return Repair(found.feasible, "replan" if found.feasible else "none", tuple(found.order),
                  tuple(holds), found.message)


# --- the execution tracker -----------------------------------------------------------------

def at_measured(plan: Scene, measured: Scene) -> Scene:
    """``plan`` with each block the as-built scene ``measured`` has at its measured pose."""
    posed = {b.id: b for b in measured.blocks}
    return replace(plan, blocks=tuple(
        make_block(b.id, b.vertices, b.faces, posed[b.id].position, posed[b.id].orientation,
                   density=b.density, mass=b.mass, support=b.support)
        if b.id in posed and posed[b.id] is not b else b for b in plan.blocks))


def plan_mismatch(plan: Scene, design: Scene) -> str:
    """Why ``plan`` is not a plan of ``design`` ("" when it is): other blocks."""
    ours, theirs = {b.id for b in plan.blocks}, {b.id for b in design.blocks}
    if ours == theirs:
        return ""
    extra, missing = sorted(ours - theirs), sorted(theirs - ours)
    return (f"the plan does not match the design {design.name!r}: "
            + "; ".join(p for p in (f"blocks not in the design: {', '.join(extra[:5])}"
                                    if extra else "",
                                    f"design blocks not in the plan: {', '.join(missing[:5])}"
                                    if missing else "") if p))


@dataclass
class Settings:
    """The node's execution parameters."""

    lookahead_steps: int = LOOKAHEAD_STEPS
    min_margin_g: float = MIN_MARGIN_G

    @classmethod
    def of(cls, recorded: dict | None) -> "Settings":
        recorded = recorded or {}
        return cls(int(recorded.get("lookahead_steps", LOOKAHEAD_STEPS)),
                   float(recorded.get("min_margin_g", MIN_MARGIN_G)))


@dataclass
class Execution:
    """The plan under execution and what the last as-built state made of it."""

    plan: Scene | None = None
    error: str = "no plan: set design_file to a planned scene or send a design with a sequence"
    last: dict | None = None            # the last ExecutionState made from accepted poses
    _seen: tuple = ()                   # (as-built scene, plan) of the last outputs
    _outputs: list = field(default_factory=list)
    _repaired: object = None            # the as-built scene the last repair was tried at

    def set_design(self, design: Scene | None) -> None:
        """A new design: its sequence (and holds) is the plan; without one, a plan held
        stays if it is a plan of the design."""
        if design is None:
            self.plan, self.error = None, "no plan: the design is invalid"
        elif design.sequence:
            self.plan, self.error = design, ""
        elif self.plan is not None:
            self.error = plan_mismatch(self.plan, design)
        self.last, self._seen, self._repaired = None, (), None

    def set_plan(self, plan: Scene, design: Scene | None) -> None:
        """A plan made elsewhere (a ~/plan result): refused when not of ``design``."""
        self.plan = plan
        self.error = plan_mismatch(plan, design) if design is not None else ""
        self.last, self._seen, self._repaired = None, (), None

    def advance(self, asbuilt: Scene | SceneError, as_built: dict | None, header: dict,
                options: CheckOptions, settings: Settings,
                repair: Callable[[Scene, int, CheckOptions], Repair] = repair_plan,
                on_output: Callable[[str, dict], None] | None = None
                ) -> list[tuple[str, dict]]:
        """The outputs of one as-built state (``as_built``: its report dict): an
        ExecutionState, and when a look-ahead step fails a PlanUpdate and the
        ExecutionState of the repaired plan; each passed to ``on_output(kind, message)``
        as soon as it is made (the failing step is sent before the repair starts). The same
        state again gives the same outputs (a cell sends the same poses at 10 Hz), new
        headers; never raises."""
        out: list[tuple[str, dict]] = []

        def emit(kind: str, message: dict) -> None:
            out.append((kind, message))
            if on_output is not None:
                on_output(kind, message)

        if self._seen and self._seen[0] is asbuilt and self._seen[1] is self.plan:
            for kind, d in self._outputs:
                emit(kind, {**d, "header": header, **(
                    {"as_built": as_built} if kind == EXECUTION and as_built else {})})
            return out
        try:
            self._advance(asbuilt, as_built, header, options, settings, repair, emit)
        except Exception as exc:        # an output, never a crash
            emit(EXECUTION, self._refused(header, as_built,
                                          f"execution failed: {type(exc).__name__}: {exc}"))
        self._seen, self._outputs = (asbuilt, self.plan), out
        return out

    def _refused(self, header: dict, as_built: dict | None, why: str) -> dict:
        """The last accepted state (its step and look-ahead), inactive, with the reason."""
        kept = self.last or execution_to_dict(
            header, active=False, current_step=0,
            total_steps=len(self.plan.sequence) if self.plan is not None else 0,
            as_built=as_built, lookahead=[], first_failing_step=-1, message="")
        return {**kept, "header": header, "active": False, "message": why,
                **({"as_built": as_built} if as_built else {})}

    def _advance(self, asbuilt, as_built, header, options, settings, repair, emit) -> None:
        if self.plan is None or self.error:
            return emit(EXECUTION, self._refused(header, as_built, self.error))
        if isinstance(asbuilt, SceneError):
            return emit(EXECUTION, self._refused(header, as_built,
                                                 f"poses not accepted: {asbuilt}"))
        order = self.plan.sequence
        placed = [b.id for b in asbuilt.blocks if not b.support]
        current = next((k for k, b in enumerate(order) if b not in placed), len(order))
        wrong = sorted(set(placed) - set(order[:current]), key=order.index)
        if wrong:
            return emit(EXECUTION, self._refused(
                header, as_built, f"block {wrong[0]!r} measured out of order: the plan places "
                f"it at step {order.index(wrong[0])}, after step {current} "
                f"({order[current]!r}), which is not measured"))
        if settings.min_margin_g > 0 and not options.margin_directions:
            options = replace(options, margin_directions=DEFAULT_DIRECTIONS)
        state = self._state(asbuilt, as_built, header, options, settings, current)
        emit(EXECUTION, state)
        failing = state["first_failing_step"]
        if failing < 0 or self._repaired is asbuilt:
            return None
        self._repaired = asbuilt
        step = next(s for s in state["lookahead"] if s["step"] == failing)
        reason = f"step {failing} ({step['block']}): {_why(step, settings)}"
        found = repair(at_measured(self.plan, asbuilt), current, options)
        changed = next((k for k in range(current, len(order)) if k >= len(found.order)
                        or found.order[k] != order[k]
                        or _held(found.holds, k) != _held(self.plan.holds, k)), current)
        emit(PLAN_UPDATE, plan_update_to_dict(
            header, reason=reason, changed_step=changed, feasible=found.feasible,
            repair=found.kind, order=found.order if found.feasible else order,
            holds=found.holds if found.feasible else self.plan.holds,
            message=found.message))
        if found.feasible:
            self.plan = replace(self.plan, sequence=found.order, holds=found.holds)
            emit(EXECUTION, self._state(asbuilt, as_built, header, options, settings, current))
        return None

    def _state(self, asbuilt: Scene, as_built, header, options, settings, current) -> dict:
        reports = look_ahead(at_measured(self.plan, asbuilt), current,
                             settings.lookahead_steps, options)
        steps = [lookahead_step_to_dict(r) for r in reports]
        failing = next((s["step"] for s in steps if _why(s, settings)), -1)
        self.last = execution_to_dict(
            header, active=True, current_step=current, total_steps=len(self.plan.sequence),
            as_built=as_built, lookahead=steps, first_failing_step=failing,
            message="" if failing < 0 else
            f"step {failing} ({steps[failing - current]['block']}) fails at the measured "
            f"poses: {_why(steps[failing - current], settings)}")
        return self.last


def _held(holds, k: int) -> set[str]:
    return {h.block for h in holds if h.active(k)}


def _why(step: dict, settings: Settings) -> str:
    """Why a look-ahead step fails ("" when it stands)."""
    if not step["stable"]:
        return step["message"] or "does not stand"
    if not step["insertable"]:
        return "not insertable"
    if settings.min_margin_g > 0 and 0 <= step["margin_g"] < settings.min_margin_g:
        return f"margin {step['margin_g']:.3g} g below min_margin_g {settings.min_margin_g:g}"
    return ""


__all__ = ["EXECUTION", "Execution", "LOOKAHEAD_STEPS", "MIN_MARGIN_G", "PLAN_UPDATE", "Repair",
           "Settings", "at_measured", "look_ahead", "plan_mismatch", "repair_plan"]
