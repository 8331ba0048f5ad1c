"""Reports as an aligned table for people; for machines, the message dict
(:func:`rbe_ros.io.messages.report_json`)."""
from __future__ import annotations

import math

import numpy as np

from ..rbe.result import Report

_AXES = {(1, 0, 0): "+x", (-1, 0, 0): "-x", (0, 1, 0): "+y", (0, -1, 0): "-y"}


def approach_text(r: Report) -> str:
    """The table's approach of a report: "down", "side +x" (and the other horizontal axes),
    the direction "(x, y, z)", "none" when the block cannot get in, "-" when not checked."""
    if not r.insertable:
        return "none"
    d = np.asarray(r.insertion_direction, dtype=float)
    if not np.any(d):
        return "-"
    # an axis to the solver's rounding (an exported mesh's faces: 3e-7 off) is that axis
    rounded = tuple(int(x) for x in np.round(d)) if np.allclose(d, np.round(d), atol=1e-6) else ()
    if rounded == (0, 0, -1):
        return "down"
    if rounded in _AXES:
        return f"side {_AXES[rounded]}"
    return "(" + ", ".join(f"{x:.3g}" for x in d + 0.0) + ")"


def hold_note(r: Report) -> str:
    """" | held: a, b | to stand, also hold: c" (empty when nothing is held or suggested)."""
    note = f" | held: {', '.join(r.held_blocks)}" if r.held_blocks else ""
    if r.suggested_holds:
        also = "also " if r.held_blocks else ""
        note += f" | to stand, {also}hold: {', '.join(r.suggested_holds)}"
    return note


def largest_hold_force(r: Report) -> float:
    """The largest |F| a robot applies to a held block in ``r`` (N; 0 when none is held)."""
    return max((float(np.linalg.norm(w.force)) for w in r.hold_wrenches), default=0.0)


def format_table(reports: list[Report]) -> str:
    """One row per report: step, block, verdict, max tension, worst |V|/N, time, margin
    (when computed), the largest hold force (when a report has hold wrenches), approach (when
    checked: :func:`approach_text`) and reason; the reason notes the blocks held at the step
    and, when unstable, the ones to hold."""
    margin = any(r.margin_g >= 0 for r in reports)
    hold = any(r.hold_wrenches for r in reports)
    approach = any(not r.insertable or np.any(r.insertion_direction) for r in reports)
    head = ("step", "block", "verdict", "max tension N", "worst |V|/N", "solve ms") \
        + ("margin g",) * margin + ("max hold N",) * hold + ("approach",) * approach \
        + ("reason",)
    rows = [head]
    for r in reports:
        ratio = f"{r.worst_friction_ratio:.3f}" if math.isfinite(r.worst_friction_ratio) else "inf"
        rows.append((str(r.step_index) if r.step_index >= 0 else "-", r.block_placed or "-",
                     r.status.name, f"{r.max_tension:.1f}", ratio, f"{1e3 * r.solve_time:.1f}")
                    + (f"{r.margin_g:.3f}",) * margin
                    + (f"{largest_hold_force(r):.1f}" if r.hold_wrenches else "-",) * hold
                    + (approach_text(r),) * approach
                    + (r.message + hold_note(r),))
    widths = [max(len(row[i]) for row in rows) for i in range(len(head) - 1)]
    lines = ["  ".join(c.ljust(w) if i < 3 else c.rjust(w)
                       for i, (c, w) in enumerate(zip(row, widths)))
             + "  " + row[-1] for row in rows]
    lines.insert(1, "-" * max(len(line) for line in lines))
    return "\n".join(lines)
