"""``rbe-ros view``: one self-contained HTML report of checked states (a scene, or a bag).

The page holds plotly.js (the copy the plotly package ships, inlined: nothing is fetched
when it is viewed), the data as JSON, and a small script: a 3D view of the assembly at the
chosen step (the blocks in the colours of :mod:`rbe_ros.io.markers`, the force segments,
interface outlines and kerns of the same :func:`~rbe_ros.io.markers.line_markers`), a step
slider, the table of steps (verdict, max tension, worst |V|/N, model, margin_g where the
report has one: ``--margin``, or a bag recorded with it; approach; reason), the placed
block's insertion direction as an arrow, and the check options. Why
plotly and not three.js: docs/VIEW.md.
"""
from __future__ import annotations

import html
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from plotly.offline import get_plotlyjs
from scipy.spatial.transform import Rotation

from ..analysis.options import CheckOptions
from ..cell import Cell
from ..rbe.result import Status
from .markers import (ARROW, CUBE, CYLINDER, LINE_LEGEND, ROLE_COLOURS, ROLES,
                      TEXT_VIEW_FACING, approach_markers, cell_markers, hold_markers,
                      line_markers, run_roles, wrench_text)
from .messages import report_from_dict
from .replay import Run, options_to_json, replay_run
from .table import approach_text, largest_hold_force

#: Coordinates in the page are rounded to 0.1 mm.
DECIMALS = 4


@dataclass
class ViewRun:
    """One checked state: its AssemblyState dict and StabilityReport dicts."""

    label: str
    state: dict
    reports: list[dict]
    cell: Cell | None = None           # a plan for a cell: its robots
    timeline: list[dict] = field(default_factory=list)   # and its RobotAction dicts


def checked_runs(states: Sequence[tuple[str, dict]], options: CheckOptions) -> list[ViewRun]:
    """Check each (label, AssemblyState dict) as the node does."""
    return [ViewRun(label, state, replay_run(Run(state, 0), options)) for label, state in states]


def _coords(points) -> list[list[float]]:
    """x, y and z lists of (n, 3) points, rounded."""
    rows = np.round(np.asarray(points, dtype=float).reshape(-1, 3), DECIMALS)
    return rows.T.tolist()


def _segments(points) -> list[list]:
    """x, y and z lists of LINE_LIST points, each segment followed by a gap (None)."""
    rows = np.round(np.asarray(points, dtype=float).reshape(-1, 2, 3), DECIMALS)
    gaps = np.full((len(rows), 1, 3), np.nan)
    flat = np.concatenate([rows, gaps], axis=1).reshape(-1, 3).T
    return [[None if np.isnan(v) else v for v in axis] for axis in flat.tolist()]


def _rgba(colour) -> str:
    r, g, b, a = colour
    return f"rgba({round(255 * r)},{round(255 * g)},{round(255 * b)},{a:g})"


def _number(value):
    """A JSON number, or the text of an infinite one."""
    value = float(value)
    return value if np.isfinite(value) else str(value)


def _margin(report: dict) -> float | None:
    """margin_g of a report dict, None where it was not computed (-1, or an older bag)."""
    margin = float(report.get("margin_g", -1.0))
    return None if margin < 0 else margin


def _arrow(meshes, report, d: dict) -> dict | None:
    """The insertion arrow of a report (:func:`approach_markers`): tail, tip, colour."""
    for m in approach_markers(meshes, report, d["header"]):
        tail, tip = np.asarray(m["points"], dtype=float)
        return {"tail": tail.tolist(), "tip": tip.tolist(),
                "colour": _rgba(tuple(m["color"][k] for k in "rgba"))}
    return None


#: The 12 edges of a box by corner index (corners: the signs of x, y, z as bits).
_BOX_EDGES = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]


def _robot_lines(run: ViewRun, step: int, size: float
                 ) -> tuple[list[dict], list[dict], list[dict]]:
    """(lines, arrows, labels) of the robots at ``step`` of a cell's plan (the state after
    each of its actions, :func:`rbe_ros.io.markers.cell_markers`): robot bases, gripper
    boxes, the robots' forces with their hover text (robot, block, force, torque), the
    robots' names above their bases."""
    lines, arrows, labels, seen = [], [], [], set()
    for index, action in enumerate(run.timeline):
        if action["step"] != step:
            continue
        for m in cell_markers(run.cell, run.timeline, index, action["grip"]["header"],
                              0.3 * size):
            key = (m["ns"], m["id"], m["text"], json.dumps(m["pose"]))
            if key in seen:
                continue
            seen.add(key)
            colour = _rgba(tuple(m["color"][k] for k in "rgba"))
            centre = np.array([m["pose"]["position"][k] for k in "xyz"])
            if m["type"] == CUBE:
                half = np.array([m["scale"][k] for k in "xyz"]) / 2
                rot = Rotation.from_quat([m["pose"]["orientation"][k] for k in "xyzw"])
                corners = centre + rot.apply([[(-1) ** (1 - (c >> i & 1)) * half[i]
                                               for i in range(3)] for c in range(8)])
                points = [corners[i] for edge in _BOX_EDGES for i in edge]
                name, width = f"gripper of {action['robot']}", 6
            elif m["type"] == CYLINDER:
                points = [centre - [0, 0, 0.25], centre + [0, 0, 0.25]]
                name = f"base of {run.cell.robots[m['id']].name}"
                width = 16                  # a post as thick as the base, seen from afar
            elif m["type"] == ARROW:
                tail, tip = np.asarray(m["points"], dtype=float)
                arrows.append({"tail": tail.tolist(), "tip": tip.tolist(), "colour": colour,
                               "name": wrench_text(action)})
                continue
            elif m["type"] == TEXT_VIEW_FACING and m["ns"] == "robot_names":
                labels.append({"text": m["text"], **{k: round(float(v), DECIMALS)
                                                     for k, v in zip("xyz", centre)}})
                continue
            else:
                continue
            x, y, z = _segments(np.asarray(points, dtype=float))
            lines.append({"name": name, "colour": colour, "width": width, "x": x, "y": y,
                          "z": z})
    return lines, arrows, labels


def robot_table(run: ViewRun) -> dict:
    """Per step of a cell's plan, what each robot does (its actions, in order)."""
    names = list(run.cell.names) if run.cell is not None else []
    rows: dict[int, dict[str, list[str]]] = {}
    for a in run.timeline:
        rows.setdefault(a["step"], {n: [] for n in names})[a["robot"]].append(
            f"{a['action']} {a['block']}")
    return {"robots": names, "rows": [[k, *("; ".join(v[n]) or "-" for n in names)]
                                      for k, v in sorted(rows.items())]}


def view_data(runs: Sequence[ViewRun], options: CheckOptions, title: str) -> dict:
    """The page's data: per run the block meshes, per report its row, block roles and lines."""
    out_runs, steps = [], []
    for r, run in enumerate(runs):
        reports = [report_from_dict(d) for d in run.reports]
        meshes, roles = run_roles(run.state, reports, options)
        blocks = []
        for i, bid in enumerate(meshes.ids):
            x, y, z = _coords(meshes.triangles[meshes.start[i]:meshes.end[i]])
            blocks.append({"id": bid, "x": x, "y": y, "z": z})
        out_runs.append({"label": run.label, "blocks": blocks})
        size = (float(np.ptp(meshes.triangles.reshape(-1, 3), axis=0).max())
                if len(meshes.triangles) else 1.0)
        for d, report, role in zip(run.reports, reports, roles):
            lines, robot_arrows, labels = (_robot_lines(run, report.step_index, size)
                                           if run.timeline else ([], [], []))
            for m in (line_markers(report, d["header"])
                      + hold_markers(report, d["header"], 0.3 * size)):
                x, y, z = _segments(m["points"])
                lines.append({"name": f"{m['ns']} {m['id']}",
                              "colour": _rgba(tuple(m["color"][k] for k in "rgba")),
                              "width": _WIDTHS.get(m["ns"], 3), "x": x, "y": y, "z": z})
            steps.append({
                "run": r, "step": report.step_index, "block": report.block_placed,
                "status": report.status.name, "stable": report.stable,
                "max_tension": _number(report.max_tension),
                "worst_friction_ratio": _number(report.worst_friction_ratio),
                "model": report.model, "margin": _margin(d),
                "max_hold": largest_hold_force(report) if report.hold_wrenches else None,
                "message": report.message,
                "approach": approach_text(report), "arrow": _arrow(meshes, report, d),
                "robot_arrows": robot_arrows, "labels": labels,
                "roles": {bid: ROLES.index(role) for bid, role in role.items()},
                "lines": lines})
    drawn = {c["colour"] for s in steps for c in (*s["lines"], *s["robot_arrows"],
                                                  *([s["arrow"]] if s["arrow"] else []))}
    return {"title": title, "runs": out_runs, "steps": steps,
            "roles": [{"name": n, "colour": _rgba(ROLE_COLOURS[n][:3] + (1.0,)),
                       "opacity": ROLE_COLOURS[n][3]} for n in ROLES],
            "line_legend": [{"name": n, "colour": _rgba(c)} for n, c in LINE_LEGEND
                            if _rgba(c) in drawn],
            "options": json.loads(options_to_json(options)),
            "statuses": {s.name: s.value for s in Status},
            "robot_tables": [dict(robot_table(run), label=run.label) for run in runs
                             if run.timeline]}


#: Line widths in the page by marker namespace (others 3): forces and the robots' holds.
_WIDTHS = {"forces": 6, "holds": 10}


def write_html(path, runs: Sequence[ViewRun], options: CheckOptions, title: str) -> Path:
    """Write the report page of ``runs`` to ``path``; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = json.dumps(view_data(runs, options, title), separators=(",", ":"))
    page = (_PAGE.replace("@TITLE@", html.escape(title))
            .replace("@PLOTLY@", get_plotlyjs())
            .replace("@DATA@", data.replace("</", "<\\/"))
            .replace("@SCRIPT@", _SCRIPT))
    path.write_text(page, encoding="utf-8")
    return path


_PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>@TITLE@</title>
<style>
body { font-family: sans-serif; margin: 0.8em; color: #222; }
#top { display: flex; gap: 1em; align-items: center; flex-wrap: wrap; }
#plot { width: 100%; height: 560px; border: 1px solid #ccc; }
#slider { width: 40em; }
#caption { font-weight: bold; }
table { border-collapse: collapse; font-size: 0.85em; margin-top: 0.6em; }
td, th { border: 1px solid #ccc; padding: 2px 6px; text-align: left; vertical-align: top; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
tr.current { background: #ffe9a8; }
tr.bad td.verdict { color: #b00; font-weight: bold; }
tr { cursor: pointer; }
.legend span { display: inline-block; width: 0.9em; height: 0.9em; margin: 0 0.3em 0 0.8em;
  vertical-align: middle; border: 1px solid #888; }
.legend span.line { width: 1.4em; height: 0.3em; border: none; }
</style>
<script>@PLOTLY@</script>
</head><body>
<h2>@TITLE@</h2>
<div id="top"><label>step <input id="slider" type="range" min="0" value="0" step="1"></label>
<span id="caption"></span></div>
<div class="legend" id="legend"></div>
<div id="plot"></div>
<table id="steps"><thead><tr><th>run</th><th>step</th><th>block</th><th>verdict</th>
<th>max tension N</th><th>worst |V|/N</th><th>model</th><th>margin g</th><th>max hold N</th>
<th>approach</th><th>reason</th>
</tr></thead><tbody></tbody></table>
<div id="robots"></div>
<h3>Check options</h3><table id="options"><tbody></tbody></table>
<script id="data" type="application/json">@DATA@</script>
<script>@SCRIPT@</script>
</body></html>
"""

_SCRIPT = r"""
"use strict";
const DATA = JSON.parse(document.getElementById("data").textContent);
const plot = document.getElementById("plot");
const slider = document.getElementById("slider");
const rows = [];

function fmt(v, digits) {
  if (v === null || v === undefined) return "-";
  return typeof v === "number" ? v.toFixed(digits) : String(v);
}

function cell(tr, text, cls) {
  const td = document.createElement("td");
  td.textContent = text;
  if (cls) td.className = cls;
  tr.appendChild(td);
}

function meshTraces(step) {
  const run = DATA.runs[step.run];
  return DATA.roles.map((role, r) => {
    const x = [], y = [], z = [], text = [];
    for (const block of run.blocks) {
      if (step.roles[block.id] !== r) continue;
      for (let k = 0; k < block.x.length; k++) {
        x.push(block.x[k]); y.push(block.y[k]); z.push(block.z[k]); text.push(block.id);
      }
    }
    const n = x.length / 3, i = [], j = [], kk = [];
    for (let t = 0; t < n; t++) { i.push(3 * t); j.push(3 * t + 1); kk.push(3 * t + 2); }
    return {type: "mesh3d", name: role.name, x: x, y: y, z: z, i: i, j: j, k: kk,
            color: role.colour, opacity: role.opacity, flatshading: true, text: text,
            hoverinfo: "text+name", showlegend: false};
  });
}

function lineTraces(step) {
  return step.lines.map(l => ({type: "scatter3d", mode: "lines", name: l.name, x: l.x,
    y: l.y, z: l.z, line: {color: l.colour, width: l.width}, hoverinfo: "name",
    showlegend: false}));
}

function arrowTrace(a, name) {
  const d = a.tip.map((v, k) => v - a.tail[k]);
  return [{type: "scatter3d", mode: "lines", name: name, hoverinfo: "name",
           x: [a.tail[0], a.tip[0]], y: [a.tail[1], a.tip[1]], z: [a.tail[2], a.tip[2]],
           line: {color: a.colour, width: 8}, showlegend: false},
          {type: "cone", name: name, x: [a.tip[0]], y: [a.tip[1]], z: [a.tip[2]],
           u: [d[0]], v: [d[1]], w: [d[2]], anchor: "tip", sizemode: "absolute",
           sizeref: 0.2 * Math.hypot(d[0], d[1], d[2]), showscale: false,
           colorscale: [[0, a.colour], [1, a.colour]], hoverinfo: "name"}];
}

function labelTraces(step) {
  if (!step.labels.length) return [];
  return [{type: "scatter3d", mode: "text", name: "robots", hoverinfo: "none",
           x: step.labels.map(l => l.x), y: step.labels.map(l => l.y),
           z: step.labels.map(l => l.z), text: step.labels.map(l => l.text),
           textfont: {size: 16, color: "#333"}, showlegend: false}];
}

function arrowTraces(step) {
  const out = step.arrow ? arrowTrace(step.arrow, "insertion") : [];
  for (const a of step.robot_arrows) out.push(...arrowTrace(a, a.name));
  return out;
}

function show(index) {
  const step = DATA.steps[index];
  slider.value = index;
  document.body.dataset.step = index;
  const where = step.step >= 0 ? "step " + step.step + " (" + (step.block || "release") + ")"
                               : "whole assembly";
  document.getElementById("caption").textContent = DATA.runs[step.run].label + ", " + where +
    ": " + step.status + ": " + step.message;
  rows.forEach((tr, k) => tr.classList.toggle("current", k === index));
  const layout = {margin: {l: 0, r: 0, t: 0, b: 0}, uirevision: "keep", showlegend: false,
                  scene: {aspectmode: "data", xaxis: {title: "x [m]"}, yaxis: {title: "y [m]"},
                          zaxis: {title: "z [m]"}, camera: {eye: {x: 1.4, y: -1.6, z: 0.9}}}};
  // data-drawn: the step on screen, once plotly has drawn it (the browser test waits for it)
  return Plotly.react(plot, meshTraces(step).concat(lineTraces(step), arrowTraces(step),
                                                    labelTraces(step)), layout,
                      {displaylogo: false, responsive: true})
    .then(() => { document.body.dataset.drawn = index; });
}

function build() {
  const body = document.querySelector("#steps tbody");
  DATA.steps.forEach((s, k) => {
    const tr = document.createElement("tr");
    if (!s.stable) tr.classList.add("bad");
    cell(tr, DATA.runs[s.run].label);
    cell(tr, s.step >= 0 ? String(s.step) : "whole");
    cell(tr, s.block || "-");
    cell(tr, s.status, "verdict");
    cell(tr, fmt(s.max_tension, 1), "num");
    cell(tr, fmt(s.worst_friction_ratio, 3), "num");
    cell(tr, s.model);
    cell(tr, fmt(s.margin, 3), "num");
    cell(tr, fmt(s.max_hold, 1), "num");
    cell(tr, s.approach);
    cell(tr, s.message);
    tr.addEventListener("click", () => show(k));
    body.appendChild(tr);
    rows.push(tr);
  });
  const options = document.querySelector("#options tbody");
  (function walk(o, prefix) {
    for (const [key, value] of Object.entries(o)) {
      if (value !== null && typeof value === "object") {
        walk(value, prefix + key + "."); continue;
      }
      const tr = document.createElement("tr");
      cell(tr, prefix + key); cell(tr, JSON.stringify(value));
      options.appendChild(tr);
    }
  })(DATA.options, "");
  for (const t of DATA.robot_tables) {
    const h = document.createElement("h3");
    h.textContent = "Robots: " + t.label;
    const table = document.createElement("table");
    const head = document.createElement("tr");
    ["step"].concat(t.robots).forEach(n => { const th = document.createElement("th");
      th.textContent = n; head.appendChild(th); });
    table.appendChild(head);
    for (const row of t.rows) {
      const tr = document.createElement("tr");
      row.forEach(v => cell(tr, String(v)));
      table.appendChild(tr);
    }
    document.getElementById("robots").append(h, table);
  }
  const legend = document.getElementById("legend");
  DATA.roles.forEach(r => {
    const box = document.createElement("span");
    box.style.background = r.colour;
    legend.appendChild(box);
    legend.appendChild(document.createTextNode(r.name));
  });
  // the colours of the lines and arrows drawn on the page, as short thick lines
  DATA.line_legend.forEach(r => {
    const line = document.createElement("span");
    line.className = "line";
    line.style.background = r.colour;
    legend.appendChild(line);
    legend.appendChild(document.createTextNode(r.name));
  });
  slider.max = DATA.steps.length - 1;
  slider.addEventListener("input", () => show(Number(slider.value)));
  show(0);
}

build();
"""


__all__ = ["ViewRun", "checked_runs", "robot_table", "view_data", "write_html"]
