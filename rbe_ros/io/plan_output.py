"""What ``rbe-ros plan`` writes while and after it searches: progress lines, the full step
reports as JSON Lines (streamed as made, so a stopped plan keeps what it had), and one
summary per step for ``--json`` (its size grows with the steps, not with the interfaces of
every partial assembly)."""
from __future__ import annotations

import json
import time
from typing import IO

from ..analysis.planning import Plan, PlanProgress
from ..analysis.repair import Repair
from ..rbe.result import Report
from .messages import json_safe, report_json
from .scene_json import scene_to_dict

#: Seconds between two progress lines (the first and the last step are always printed).
PROGRESS_EVERY = 2.0


def step_summary(report: Report) -> dict:
    """One step of a plan: status, holds and their wrenches (force N and torque N m about
    the grip, world axes), margin, worst friction ratio, time, model."""
    return json_safe({"step": report.step_index, "block": report.block_placed,
                      "status": report.status.name, "stable": report.stable,
                      "held_blocks": list(report.held_blocks), "margin_g": report.margin_g,
                      "worst_friction_ratio": report.worst_friction_ratio,
                      "max_tension": report.max_tension, "time": report.solve_time,
                      "model": report.model,
                      "hold_wrenches": [{"block": w.block, "force": w.force.tolist(),
                                         "torque": w.torque.tolist(),
                                         "grip_point": w.grip_point.tolist(),
                                         "utilisation": w.utilisation}
                                        for w in report.hold_wrenches]})


def step_summaries(plan: Plan) -> list[dict]:
    """A plan's :func:`step_summary` rows, each with its p_stable when planned with
    ``--robust``."""
    rows = [step_summary(r) for r in plan.reports]
    for row, p in zip(rows, plan.p_stable):
        row["p_stable"] = p
    return rows


def weakest_p(plan: Plan) -> int:
    """The index of the plan's step with the smallest p_stable (the first of equals; -1:
    not planned with ``--robust``)."""
    return min(range(len(plan.p_stable)), key=plan.p_stable.__getitem__, default=-1)


def weakest_p_json(plan: Plan) -> dict:
    """A plan's weakest step by p_stable for ``--json``: step, block, p_stable, margin_g
    (step -1, p_stable -1 without ``--robust``)."""
    k = weakest_p(plan)
    if k < 0:
        return {"step": -1, "block": "", "p_stable": -1.0, "margin_g": -1.0}
    r = plan.reports[k]
    return json_safe({"step": r.step_index, "block": r.block_placed,
                      "p_stable": plan.p_stable[k], "margin_g": r.margin_g})


def weakest_p_line(plan: Plan, samples: int) -> str:
    """A plan's weakest step by p_stable as a line of text."""
    k = weakest_p(plan)
    r = plan.reports[k]
    return (f"weakest step by p_stable: {r.step_index} ({r.block_placed or 'release'}), "
            f"p_stable {plan.p_stable[k]:.3f} over {samples} samples, margin "
            f"{r.margin_g:.4f} g")


def weakest_json(report: Report | None) -> dict:
    """A plan's weakest step for ``--json``: step, block, margin_g, direction (step -1 and
    margin_g -1 when no margin was computed)."""
    if report is None:
        return {"step": -1, "block": "", "margin_g": -1.0, "direction": [0.0, 0.0, 0.0]}
    return json_safe({"step": report.step_index, "block": report.block_placed,
                      "margin_g": report.margin_g,
                      "direction": [float(x) for x in report.margin_direction]})


def weakest_line(report: Report | None) -> str:
    """A plan's weakest step as a line of text."""
    if report is None:
        return ("weakest step: not computed (--margin, --prefer margin or --min-margin "
                "compute every step's margin)")
    d = ", ".join(f"{x:.2f}" for x in report.margin_direction)
    return (f"weakest step: {report.step_index} ({report.block_placed or 'release'}), margin "
            f"{report.margin_g:.4f} g, body force towards ({d})")


def repair_json(result: Repair) -> dict:
    """``rbe-ros repair --json``: the repaired plan (order, holds), whether it is feasible
    and changed, the kind of repair and the step it changes, and the remaining steps."""
    holds = scene_to_dict(result.scene).get("holds", []) if result.scene is not None else \
        [{"block": h.block, "from_step": h.from_step, "until_step": h.until_step}
         for h in result.holds]
    return json_safe({"feasible": result.feasible, "changed": result.changed,
                      "order": result.order, "holds": holds, "message": result.message,
                      "repair": result.kind, "changed_step": result.changed_step,
                      "reason": result.reason, "placed": result.placed,
                      "held": [list(h) for h in result.held], "checks": result.checks,
                      "time": result.time,
                      "steps": [step_summary(s.report) for s in result.steps]})


def repair_text(result: Repair) -> str:
    """``rbe-ros repair``'s lines: the verdict, the change, the order from the as-built
    state."""
    head = ("repair: NOT feasible" if not result.feasible
            else f"repair: {result.kind}, from step {result.changed_step}" if result.changed
            else "repair: none needed")
    rest = result.order[result.placed:]
    return (f"{head}: {result.message}\n{result.placed} blocks placed; order from step "
            f"{result.placed}: {', '.join(rest)}")


class ProgressLines:
    """Plain progress lines on ``stream``, at most one every ``every`` seconds (a placed
    first or last step always): blocks placed, candidate checks and states so far, and the
    time left as far as it is known (:attr:`PlanProgress.estimate`)."""

    def __init__(self, stream: IO[str], every: float = PROGRESS_EVERY):
        self.stream, self.every = stream, every
        self.last = time.monotonic()        # a heartbeat line only after ``every`` s

    def __call__(self, p: PlanProgress) -> None:
        now = time.monotonic()
        if now - self.last < self.every and not (p.placing and p.placed in (1, p.total)):
            return
        self.last = now
        held = ", ".join(p.held) or "none"
        search = f"{p.checks} candidate checks, {p.states} states"
        if p.budget:
            search += f" of {p.budget}"
        if p.backups:
            search += f", {p.backups} dead ends backed out of (deepest {p.deepest})"
        left = ("time left unknown" if p.estimate < 0 else
                f"about {p.estimate:.0f} s left" if p.bound == "steps" else
                f"at most about {p.estimate:.0f} s left ({p.bound})")
        print(f"plan: {p.placed}/{p.total} blocks placed, held: {held}, {search}, "
              f"{p.elapsed:.1f} s, {left}", file=self.stream, flush=True)


class ReportLines:
    """Full step reports as JSON Lines (the CLI's report JSON, one line each), flushed as
    written."""

    def __init__(self, path):
        self.file = open(path, "w", encoding="utf-8")   # closed by close()

    def __call__(self, report: Report) -> None:
        self.file.write(json.dumps(report_json(report)) + "\n")
        self.file.flush()

    def close(self) -> None:
        self.file.close()
