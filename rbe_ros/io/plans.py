"""The one dispatch of a plan request, shared by ``rbe-ros plan``, the node's ``~/plan``
action and replay: :func:`plan_state` reads the scene, applies the request's limits (hold
capacities over the options, a time limit over ``should_stop``) and plans; it never raises,
so that a goal that cannot be planned is a result, not a crash."""
from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

from ..analysis.option_spec import BY_PARAM, from_outer
from ..analysis.options import CheckOptions
from ..analysis.grips import validate_cell
from ..analysis.planning import Plan, PlanOptions, PlanProgress, plan_sequence
from ..cell import Cell, CellError
from ..scene import Scene, SceneError, validate_scene
from .cell_file import parse_cell

#: Hold capacities a request may set over the options: the node parameters of those names
#: (outer values, N and N m; <= 0: the options' own).
HOLD_CAPACITIES = ("hold_force_max", "hold_torque_max")
#: How the message of a plan whose cell is refused begins (the node aborts such a goal).
INVALID_CELL = "invalid input: cell:"


@dataclass(frozen=True)
class PlanLimits:
    """What a plan request bounds: the search (:class:`PlanOptions`' fields, checked by
    :func:`plan_state`), the hold capacities, the wall time."""

    max_held: int = 2
    beam: int = 1
    candidates: int = 0             # 0: every insertable candidate
    keep_sequence: bool = False
    hold_force_max: float = 0.0     # N; <= 0: the options'
    hold_torque_max: float = 0.0    # N m; <= 0: the options'
    time_limit: float = 0.0         # s; <= 0: none
    search_budget: int = 0          # states checked; <= 0: the default (planning.backup_budget)
    cell: str = ""                  # the robot cell, JSON or YAML text; "": none
    prefer: str = "holds"           # "holds" or "margin" (PlanOptions.prefer; "": holds)
    min_margin: float = 0.0         # g; <= 0: off
    robust_samples: int = 0         # with prefer margin: p_stable over N samples; <= 0: off

    def search(self) -> PlanOptions:
        """The planner's search (ValueError naming a limit out of its range)."""
        return PlanOptions(self.max_held, self.beam, self.candidates, self.keep_sequence,
                           search_budget=max(self.search_budget, 0),
                           prefer=self.prefer or "holds", min_margin=max(self.min_margin, 0.0),
                           robust=max(self.robust_samples, 0))


def plan_options(options: CheckOptions, limits: PlanLimits) -> CheckOptions:
    """``options`` with the hold capacities of ``limits`` that are set (SceneError when this
    build has no such option: a capacity asked for is never silently dropped)."""
    for name in HOLD_CAPACITIES:
        value = getattr(limits, name)
        if value > 0:
            option = BY_PARAM.get(name)
            if option is None:
                raise SceneError(f"{name} {value:g} asked for, but this rbe_ros has no hold "
                                 "capacities: plan without it (0)")
            try:
                options = from_outer({option: value}, options)
            except ValueError as exc:
                raise SceneError(str(exc)) from None
    return options


def robots_held(cell: Cell, max_held: int) -> int:
    """The blocks a plan for ``cell`` may hold after a placement: ``max_held`` (0: as many
    as leave one robot free to place, N - 1), never more (CellError)."""
    free = len(cell.robots) - 1
    if max_held > free:
        raise CellError(f"cell: max_held {max_held} needs {max_held + 1} robots ({max_held} "
                        f"holding, one placing); the cell has {len(cell.robots)}")
    return max_held or free


#: The outcome of a request that could not be planned: bad input, or an error of the planner
#: (beside :data:`rbe_ros.analysis.planning.OUTCOMES`).
INVALID, ERROR = "invalid", "error"


def _failed(message: str, outcome: str = INVALID) -> Plan:
    """The plan of a request that could not be planned (nothing placed)."""
    return Plan(False, [], [], message, failed_step=0, outcome=outcome)


def plan_state(read_scene: Callable[[], Scene], limits: PlanLimits,
               options: CheckOptions = CheckOptions(), *,
               progress: Callable[[PlanProgress], None] | None = None,
               should_stop: Callable[[], bool] | None = None, **extra) -> Plan:
    """Plan the scene ``read_scene()`` makes within ``limits``; never raises: bad input (a
    limit out of range, a scene outside the options' validation limits, as a check would
    refuse it) is a plan that failed with "invalid input: ...", any other error "plan failed:
    ...".
    A cell (``limits.cell``) that cannot be used is a plan that failed with
    "invalid input: cell: ..." (:data:`INVALID_CELL`).
    ``should_stop`` and the time limit stop the search between candidate checks (the best
    partial plan, "stopped after K of N blocks"). ``extra``: further keywords of
    :func:`plan_sequence` (``on_report``, ``look_ahead``, ``full_candidates``)."""
    deadline = time.monotonic() + limits.time_limit if limits.time_limit > 0 else None

    def stop() -> bool:
        return (should_stop is not None and should_stop()) or \
            (deadline is not None and time.monotonic() > deadline)

    try:
        search = limits.search()
    except ValueError as exc:
        return _failed(f"invalid input: {exc}")
    try:
        scene = read_scene()
        if options.limits is not None:
            validate_scene(scene, options.limits)
        cell = None
        if limits.cell.strip():
            cell = parse_cell(limits.cell)
            validate_cell(cell, scene)
            search = replace(search, max_held=robots_held(cell, search.max_held))
        return plan_sequence(scene, search.max_held, plan_options(options, limits), cell=cell,
                             beam=search.beam, candidates=search.candidates,
                             keep_sequence=search.keep_sequence,
                             search_budget=search.search_budget,
                             # also the planner's own, for its progress to show what is left
                             time_limit=limits.time_limit if limits.time_limit > 0
                             else math.inf, prefer=search.prefer,
                             min_margin=search.min_margin, robust=search.robust,
                             progress=progress,
                             should_stop=stop, **extra)
    except SceneError as exc:
        return _failed(f"invalid input: {exc}")
    except Exception as exc:        # a failed plan is a result, never a crash
        return _failed(f"plan failed: {type(exc).__name__}: {exc}", ERROR)


__all__ = ["ERROR", "HOLD_CAPACITIES", "INVALID", "INVALID_CELL", "PlanLimits", "plan_options",
           "plan_state", "robots_held"]
