"""How the cost of a check grows, and what the per-step checks of a sequence cost
(issue 6): writes docs/SCALING.md and docs/bench/check_scaling.png.

    .venv/bin/python benchmarks/scaling.py [--quick]      (or: make scaling)

Every figure is a ratio measured in this one run, on this machine (stated in the output):
- one check of running-bond walls of about 100 to 1000 blocks: total time, time inside the
  conic solver (Clarabel), the StabilityReport message the node publishes (its message dict
  encoded to CDR bytes), the share outside the solver (check + message), the RViz markers
  apart, and the log-log slope of the check time against n;
- the 140-block dome built block by block: every step checked with the local model
  (rbe_ros.analysis.incremental) and with the full re-solve, against one check of the whole
  dome, the steps where the two verdicts differ (there must be none), where the time of
  the local run goes (by the model that answered each step), and what the steps only the
  full model answers cost at the least;
- two such domes side by side, built one after the other: the second dome's steps re-solve
  only its own blocks (components), against the per-step checks of one dome.
"""
from __future__ import annotations

import argparse
import collections
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from machine import machine_summary
from plan_bench import MARK as PLANNER_MARK

from rbe_ros.io import cdr
from rbe_ros import generators as gen
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.verdict import check
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.analysis.incremental import MIN_LOCAL_BLOCKS, StepChecker
from rbe_ros.analysis.steps import sequence_steps
from rbe_ros.io.bag import typestore
from rbe_ros.io.messages import header_dict, report_to_dict
from rbe_ros.rbe.solver import solver_timing

DOCS = Path(__file__).resolve().parents[1] / "docs"


def best_of(repeats: int, fn):
    """The fastest of ``repeats`` runs (the machine is shared): (value, seconds, solver s)."""
    best = None
    for _ in range(repeats):
        with solver_timing() as spent:
            start = time.perf_counter()
            value = fn()
            elapsed = time.perf_counter() - start
        if best is None or elapsed < best[1]:
            best = (value, elapsed, spent[0])
    return best


def walls(sizes, repeats):
    """Per wall: (blocks, interfaces, verdict, check s, solver s, message s, markers s)."""
    from rbe_ros.io.markers import MARKER_TYPE, step_markers

    encode = cdr.encoder(typestore(), "rbe_msgs/msg/StabilityReport")    # as the node does
    encode_markers = cdr.encoder(typestore(), MARKER_TYPE)
    rows = []
    for courses, bricks in sizes:
        scene = gen.running_bond_wall(courses=courses, bricks_per_course=bricks)
        report, total, solver = best_of(repeats, lambda: check_scene(scene))
        header = header_dict("world", 0)
        _, message, _ = best_of(repeats,
                                lambda: encode(report_to_dict(report, header, arrays=True)))
        _, markers, _ = best_of(repeats, lambda: encode_markers(step_markers(scene, report,
                                                                             header)))
        rows.append((len(scene.blocks), len(report.interfaces), report.status.name, total, solver,
                     message, markers))
        print(f"wall {len(scene.blocks)} blocks: {total:.3f} s, solver {solver:.3f} s, message"
              f" {message:.3f} s, markers {markers:.3f} s", flush=True)
    return rows


def per_step(scene, local: bool = True):
    """(reports, s, solver s) of every step of ``scene``'s sequence checked (contacts once)."""
    def run():
        start = time.perf_counter()
        full = Assembly.from_scene(scene)
        checker = StepChecker(local=local)
        reports = []
        for s in sequence_steps(scene):
            # StepChecker leaves solve_time to the pipeline: each step timed here, so that
            # the table by model has each step's own time
            at = time.perf_counter()
            report = checker.check(full.subset(s.present, s.held))
            reports.append(replace(report, solve_time=time.perf_counter() - at))
        return reports, time.perf_counter() - start
    (reports, elapsed), _, solver = best_of(1, run)
    return reports, elapsed, solver


def dome_sequence():
    scene = gen.dome()
    _, whole, _ = best_of(3, lambda: check_scene(scene))
    out = {}
    for local in (True, False):
        out[local] = per_step(scene, local)
        print(f"dome sequence ({'local' if local else 'full'}): {out[local][1]:.2f} s", flush=True)
    mismatches = [k for k, (a, b) in enumerate(zip(out[True][0], out[False][0]))
                  if a.stable != b.stable]
    return scene, whole, out, mismatches


def full_model_floor(scene, reports) -> float:
    """Time of the full check alone (no local attempt before it) at every step the full model
    answered: what those steps cost at the least, as long as they need the full problem."""
    full = Assembly.from_scene(scene)
    partial = [full.subset(s.present, s.held)
               for s, r in zip(sequence_steps(scene), reports) if r.model == "full"]
    return sum(best_of(1, lambda a=a: check(a))[1] for a in partial)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller walls, one repeat")
    args = parser.parse_args()
    sizes = ([(10, 10), (20, 15)] if args.quick else
             [(10, 10), (14, 14), (20, 20), (28, 25), (40, 25)])
    rows = walls(sizes, 1 if args.quick else 5)
    n = np.array([r[0] for r in rows], dtype=float)
    t = np.array([r[3] for r in rows])
    slope = float(np.polyfit(np.log(n), np.log(t), 1)[0]) if len(rows) > 1 else float("nan")
    dome, whole, seq, mismatches = dome_sequence()
    floor = full_model_floor(dome, seq[True][0])
    copies = gen.side_by_side(dome, 2, 12.0)
    two, two_time, _ = per_step(copies)
    second = two[len(dome.sequence):]
    print(f"two domes: {two_time:.2f} s", flush=True)

    lines = ["# Scaling and per-step cost", "",
             "Made by `benchmarks/scaling.py` (`make scaling`"
             + ("; --quick: two walls, one repeat" if args.quick else "")
             + "); ratios measured in one run.",
             "Machine: " + machine_summary(), "",
             "## One check of a running-bond wall", "",
             "Check: validation, contacts, model, solve, results (`check_scene`). Message: the"
             " StabilityReport the node publishes, from the report to its message dict to CDR"
             " bytes (`rbe_ros.io.cdr`). Outside the solver:"
             " the share of the check, and of check + message, not spent in the solver (Clarabel's"
             " set-up and iterations). Markers (RViz, published with every report) apart.", "",
             "| blocks | interfaces | verdict | check [s] | in the solver [s] | message [s] |"
             " outside the solver: check | check + message | markers [s] |",
             "|---|---|---|---|---|---|---|---|---|"]
    lines += [f"| {b} | {i} | {v} | {tt:.3f} | {s:.3f} | {m:.3f} | {1 - s / tt:.0%} |"
              f" {1 - s / (tt + m):.0%} | {mk:.3f} |" for b, i, v, tt, s, m, mk in rows]
    lines += ["", f"Log-log slope of the check time against blocks: **{slope:.2f}** "
              "(target: no faster than about 1.3).", "", "![time per check](bench/check_scaling.png)", "",
              "## The 140-block dome, every step checked", "",
              f"One check of the whole dome (contacts included): {whole:.3f} s.", "",
              "| per-step model | time [s] | ratio to one whole check | in the solver [s] | models used |",
              "|---|---|---|---|---|"]
    for local in (True, False):
        reports, elapsed, solver = seq[local]
        used = collections.Counter(r.model.split()[0] for r in reports)
        lines.append(f"| {'local (default)' if local else 'full re-solve'} | {elapsed:.2f} |"
                     f" {elapsed / whole:.1f} | {solver:.2f} | "
                     f"{', '.join(f'{k} {v}' for k, v in sorted(used.items()))} |")
    lines += ["", f"Steps where the local and the full verdicts differ: {mismatches or 'none'}.",
              f"Unstable steps: {sum(not r.stable for r in seq[False][0])} of {len(seq[False][0])}.", "",
              "Where the local run's time goes, by the model that answered each step (a step's time"
              " includes its failed local attempts):", "",
              "| answered by | steps | time [s] | ratio to one whole check |", "|---|---|---|---|"]
    by_model = collections.defaultdict(list)
    for r in seq[True][0]:
        by_model[r.model.split()[0]].append(r.solve_time)
    lines += [f"| {k} | {len(v)} | {sum(v):.2f} | {sum(v) / whole:.1f} |" for k, v in sorted(by_model.items())]
    full_steps = sum(by_model.get("full", []))
    lines += ["", "Steps answered by the full model are those of fewer than"
              f" {MIN_LOCAL_BLOCKS} free blocks, and those where no local region settles the"
              " verdict: a ring that closes (its course stands only once complete, so the blocks"
              " placed since the last stable step have no kept forces, and its weight must reach"
              " every support: any region that could carry it is most of the dome), and the"
              " partial rings that stand by friction at its limit (|V|/N = mu), where fixing the"
              " earlier forces on the boundary of any region up to the size limit left no"
              " admissible state. A restriction (the boundary forces fixed) cannot answer a ring"
              " closure by construction, and did not answer the others: the full-model steps"
              f" cost {full_steps / whole:.1f} times one whole check here, and their full checks"
              f" alone (without the local attempts before them) {floor / whole:.1f} times:"
              " while those steps need the full problem, no choice of regions brings the"
              " sequence under 5 times one whole check; a full solve warm-started from the last"
              " step's (Clarabel, an interior-point method, has none) would be the lever.", "",
              "## Independent parts: only the one a step touches is solved", "",
              f"Two such domes 12 m apart, built one after the other ({len(copies.blocks)} blocks,"
              " `generators.side_by_side`): no contact joins them, so once a local region"
              " outgrows its limit the components (free blocks joined by contacts) holding the"
              " new blocks are solved in full and the other dome keeps its forces.", "",
              f"- per-step checks of both domes: {two_time:.2f} s, {two_time / seq[True][1]:.2f}"
              " times the per-step checks of one dome;",
              "- the second dome's steps: verdicts equal to those of the dome alone at"
              f" {sum(a.stable == b.stable for a, b in zip(second, seq[True][0]))} of"
              f" {len(second)} steps; models used: "
              + ", ".join(f"{k} {v}" for k, v in sorted(collections.Counter(
                  r.model.split()[0] for r in second).items())) + ".", "",
              "The second dome's steps solve the same problems as the dome's alone; what grows"
              " with the scene is the rest of a step: its report lists every interface of the"
              " partial assembly (kept forces included), and the kept state is looked up and"
              " stored by interface.", ""]
    # the planner's section (benchmarks/plan_bench.py) stays as it was made
    old = (DOCS / "SCALING.md").read_text() if (DOCS / "SCALING.md").exists() else ""
    planner = old[old.index(PLANNER_MARK):] if PLANNER_MARK in old else ""
    (DOCS / "SCALING.md").write_text("\n".join(lines) + ("\n" + planner if planner else ""))
    plot(rows, DOCS / "bench" / "check_scaling.png")
    print("\n".join(lines))
    return 0


def plot(rows, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    n = [r[0] for r in rows]
    fig, ax = plt.subplots(figsize=(5.5, 4), dpi=120)
    ax.loglog(n, [r[3] for r in rows], "o-", label="whole check")
    ax.loglog(n, [r[4] for r in rows], "s--", label="inside Clarabel")
    ax.loglog(n, [r[5] for r in rows], "^:", label="report message (dict, CDR)")
    ax.loglog(n, [r[6] for r in rows], "v:", label="RViz markers")
    ax.set(xlabel="blocks (running-bond wall)", ylabel="time per check [s]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
