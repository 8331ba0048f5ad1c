"""Readable forms of reports: JSON for machines, an aligned table for people."""
from __future__ import annotations

import math

from ..rbe.result import InterfaceResult, Report


def json_number(x: float):
    """JSON has no infinity: unbounded ratios become null."""
    return float(x) if math.isfinite(x) else None


def interface_json(r: InterfaceResult) -> dict:
    return {"block_a": r.block_a, "block_b": r.block_b,
            "normal": r.normal.tolist(),
            "normal_force": float(r.normal_resultant),
            "shear_force": r.shear.tolist(),
            "centre_of_pressure": r.centre_of_pressure.tolist(),
            "torque": float(r.torque),
            "friction_ratio": json_number(r.friction_ratio),
            "tension": r.tension, "friction_exceeded": r.friction_exceeded,
            "polygon": r.polygon.tolist(),
            "vertex_normal_forces": r.normal_forces.tolist(),
            "kern": r.kern.tolist()}


def report_json(report: Report) -> dict:
    out = {"stable": report.stable, "status": report.status.name,
           "message": report.message, "max_tension": float(report.max_tension),
           "worst_friction_ratio": json_number(report.worst_friction_ratio),
           "solve_time": report.solve_time, "num_blocks": report.num_blocks,
           "unstable_blocks": list(report.unstable_blocks),
           "held_blocks": list(report.held_blocks),
           "suggested_holds": list(report.suggested_holds), "model": report.model,
           "dropped_states": report.dropped_states,
           "near_contacts": [{"block_a": c.block_a, "block_b": c.block_b, "gap": c.gap,
                              "overlap_area": c.overlap_area} for c in report.near_contacts],
           "verdict_sensitive": report.verdict_sensitive,
           "margin_g": report.margin_g if report.margin_g >= 0 else None,
           "margin_direction": report.margin_direction.tolist(),
           "interfaces": [interface_json(r) for r in report.interfaces]}
    if report.step_index >= 0:
        out = {"step": report.step_index, "block": report.block_placed, **out}
    return out


def hold_note(r: Report) -> str:
    """" | held: a, b | to stand, also hold: c" (empty when nothing is held or suggested)."""
    note = f" | held: {', '.join(r.held_blocks)}" if r.held_blocks else ""
    if r.suggested_holds:
        note += f" | to stand, {'also ' if r.held_blocks else ''}hold: {', '.join(r.suggested_holds)}"
    return note


def format_table(reports: list[Report]) -> str:
    """One row per report: step, block, verdict, max tension, worst |V|/N, time and reason;
    the reason notes the blocks held at the step and, when unstable, the ones to hold."""
    margin = any(r.margin_g >= 0 for r in reports)
    head = ("step", "block", "verdict", "max tension N", "worst |V|/N", "solve ms") \
        + ("margin g",) * margin + ("reason",)
    rows = [head]
    for r in reports:
        ratio = f"{r.worst_friction_ratio:.3f}" if math.isfinite(r.worst_friction_ratio) else "inf"
        rows.append((str(r.step_index) if r.step_index >= 0 else "-", r.block_placed or "-",
                     r.status.name, f"{r.max_tension:.1f}", ratio, f"{1e3 * r.solve_time:.1f}")
                    + (f"{r.margin_g:.3f}",) * margin + (r.message + hold_note(r),))
    widths = [max(len(row[i]) for row in rows) for i in range(len(head) - 1)]
    lines = ["  ".join(c.ljust(w) if i < 3 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths)))
             + "  " + row[-1] for row in rows]
    lines.insert(1, "-" * max(len(line) for line in lines))
    return "\n".join(lines)
