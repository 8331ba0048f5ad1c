"""What ``rbe-ros plan`` writes while and after it searches: progress lines, the full step
reports as JSON Lines (streamed as made, so a stopped plan keeps what it had), and one
summary per step for ``--json`` (its size grows with the steps, not with the interfaces of
every partial assembly)."""
from __future__ import annotations

import json
import time
from typing import IO

from ..analysis.planning import PlanProgress
from ..rbe.result import Report
from .messages import json_safe, report_json

#: Seconds between two progress lines (the first and the last step are always printed).
PROGRESS_EVERY = 2.0


def step_summary(report: Report) -> dict:
    """One step of a plan: status, holds, margin, worst friction ratio, time, model."""
    return json_safe({"step": report.step_index, "block": report.block_placed,
                      "status": report.status.name, "stable": report.stable,
                      "held_blocks": list(report.held_blocks), "margin_g": report.margin_g,
                      "worst_friction_ratio": report.worst_friction_ratio,
                      "max_tension": report.max_tension, "time": report.solve_time,
                      "model": report.model})


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
