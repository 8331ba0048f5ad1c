#!/usr/bin/env python3
"""Repair time (issue 30): the 140-block dome (14 x 10, --max-held 2, pose uncertainty
5 mm / 3.5 deg declared) and its 0.6-thickness variant planned, built to half (63 of 126
blocks placed), the last placed block measured a few mm and degrees off: the first deviation
of a fixed list that makes a later step of the plan fail; `repair_plan` against re-planning
the remainder from scratch (the placed blocks a fixed prefix, the same K), in one run, with
the floor of any sound repair: one check of each remaining state; the repaired plan
re-checked by `check_sequence` (the oracle). Writes docs/REPAIR.md.

The plans are kept in build/repair/ (made by the first run; the 527-block dome's plan takes
hours on 2 cores): delete them to plan again.

Usage: .venv/bin/python benchmarks/repair.py [--dome527] [--thin | --only KEY] [--workers N]
[--profile] [--out PATH] (make bench-repair). ``--thin``: the 0.6-thickness dome only (the
one a deviation breaks); ``--only``: the dome of that key (dome14x10, dome14x10_thin);
``--workers``: the repairs' worker processes (default 2); ``--profile``: only where the
in-process repair's time goes (printed, nothing written); ``--out``: the document written
there (default docs/REPAIR.md).

Besides the repair alone (``rbe-ros repair``), what the node does: the look-ahead of its
window finds the failing step and hands the states it checked to the repair, which checks
none of them again (``repair_plan(..., checked=...)``); and the node's answer to the pose
message itself (~/report, then ``Execution.advance`` given it), timed to each output.
"""
from __future__ import annotations

import cProfile
import pickle
import pstats
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from machine import machine_summary  # noqa: E402
from rbe_ros import generators  # noqa: E402
from rbe_ros.analysis.lookahead import (StepRunner, as_built_plan, look_ahead,  # noqa: E402
                                        placed_count)
from rbe_ros.analysis.options import CheckOptions  # noqa: E402
from rbe_ros.analysis.pipeline import check_sequence  # noqa: E402
from rbe_ros.analysis.planning import plan_sequence  # noqa: E402
from rbe_ros.analysis.repair import repair_plan  # noqa: E402
from rbe_ros.analysis.steps import sequence_step, step_count  # noqa: E402
from rbe_ros.io.execution import (EXECUTION, LOOKAHEAD_STEPS, Execution,  # noqa: E402
                                  NodeReport, Settings)
from rbe_ros.io.inputs import load_design  # noqa: E402
from rbe_ros.io.plan_output import ProgressLines  # noqa: E402
from rbe_ros.io.poses import scene_at_poses  # noqa: E402
from rbe_ros.io.replay import asbuilt_check  # noqa: E402

UNCERTAINTY = (0.005, 3.5)
CACHE = ROOT / "build" / "repair"
DOME527 = ROOT / "tests" / "data" / "compas_assembly" / "dome_assembly.json.gz"
#: (block placed k steps before half-built, radial shift in m, tilt in deg about the
#: block's horizontal tangent or its radial axis): the last block placed, of the open course
DEVIATIONS = [(1, shift, tilt, axis) for shift in (0.004, -0.004) for tilt in (3.0, -3.0)
              for axis in ("tangent", "radial")]
#: The 14 x 10 dome of docs/SCALING.md, and the same 140 blocks at 0.6 of its thickness
DOMES = (("14 x 10 dome", "dome14x10", {}),
         ("14 x 10 dome, 0.6 of the thickness", "dome14x10_thin",
          {"t_base": 0.3, "t_oculus": 0.15}))


def planned(name: str, scene, max_held: int = 2):
    """(plan, plan time s): ``plan_sequence(scene, max_held)``, kept in
    build/repair/<name>.pkl (the 527-block dome's plan takes hours on 2 cores: its progress
    goes to stderr, as ``rbe-ros plan`` prints it)."""
    path = CACHE / f"{name}.pkl"
    if path.exists():
        with open(path, "rb") as f:
            return pickle.load(f)
    start = time.perf_counter()
    made = (plan_sequence(scene, max_held, progress=ProgressLines(sys.stderr)),
            time.perf_counter() - start)
    CACHE.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        pickle.dump(made, f)
    return made


def deviated(block, shift: float, tilt: float, axis: str):
    """(position, orientation) of ``block`` moved ``shift`` m radially (horizontal) and
    turned ``tilt`` deg about its horizontal tangent or its radial axis."""
    c = np.asarray(block.position, dtype=float)
    radial = np.array([c[0], c[1], 0.0]) / (np.hypot(c[0], c[1]) or 1.0)
    tangent = np.cross([0.0, 0.0, 1.0], radial)
    turn = Rotation.from_rotvec(np.radians(tilt) * (tangent if axis == "tangent" else radial))
    q = (turn * Rotation.from_quat(block.orientation)).as_quat()
    return (c + shift * radial).tolist(), q.tolist()


def half_built(plan, deviation: int) -> tuple[str, object]:
    """(the block measured off, the as-built scene): ``plan`` (a Plan) built to half at
    design, then the ``deviation``-th of DEVIATIONS applied to one of its last placed
    blocks (this bench's state, and that of the benchmarks that time its repair)."""
    scene = plan.scene
    half = len(plan.order) // 2
    k, shift, tilt, axis = DEVIATIONS[deviation]
    block = plan.order[half - k]
    design = {b: (scene.block(b).position.tolist(), scene.block(b).orientation.tolist())
              for b in plan.order[:half]}
    return block, scene_at_poses(scene, {**design, block: deviated(scene.block(block), shift,
                                                                   tilt, axis)})


def remainder(plan_scene, placed: int):
    """``plan_scene`` from step ``placed`` on: its first ``placed`` blocks present from the
    start, the holds shifted (those ended before dropped); step k of it is step
    ``placed + k`` of ``plan_scene``, the same blocks present and held."""
    holds = tuple(replace(h, from_step=max(h.from_step - placed, 0),
                          until_step=None if h.until_step is None else h.until_step - placed)
                  for h in plan_scene.holds if h.until_step is None or h.until_step > placed)
    out = replace(plan_scene, sequence=tuple(plan_scene.sequence[placed:]), holds=holds,
                  approach=tuple(plan_scene.approach[placed:]))
    for k in range(step_count(out)):
        ours, theirs = sequence_step(out, k), sequence_step(plan_scene, placed + k)
        assert (set(ours.present), ours.held) == (set(theirs.present), theirs.held), k
    return out


def floor(plan_scene, built, window: int, local: bool) -> tuple[float, int, float, int]:
    """(s, states, CPU s of this process, states a region settled): one check of each
    remaining state of the plan at the measured poses (the as-built state first), in order,
    in process: ``local`` by the repair's checker (:class:`StepChecker`, as ``check
    --sequence`` walks a sequence: each state from the one before's forces, a region
    re-solved where that settles it), else each state whole. The least any sound repair
    checks, every state it guarantees once."""
    scene = as_built_plan(plan_scene, built)
    placed = placed_count(plan_scene, built)
    start, cpu = time.perf_counter(), time.process_time()
    runner = StepRunner(scene, CheckOptions(full_solve=not local), placed)
    total = step_count(scene)
    stop = total if not window else min(total, placed + window)
    steps = runner.scan(scene, placed - 1, stop, runner.checker, until_failure=False)
    regions = sum(s.report.model.startswith(("local", "relaxed")) for s in steps)
    return time.perf_counter() - start, runner.checks, time.process_time() - cpu, regions


def gripped_states(plan_scene, built, window: int) -> int:
    """How many remaining states hold a block with a grip (the incremental checker solves
    those whole: a robot's wrench is the whole problem's)."""
    scene = as_built_plan(plan_scene, built)
    placed = placed_count(plan_scene, built)
    total = step_count(scene)
    stop = total if not window else min(total, placed + window)
    return sum(bool(sequence_step(scene, k).grips) for k in range(placed - 1, stop))


def profiled(plan_scene, built, window: int) -> list[str]:
    """Where the in-process repair's time goes (cProfile): its states, the convex solves
    and the placement test's share."""
    profile = cProfile.Profile()
    start = time.perf_counter()
    profile.enable()
    found = repair_plan(plan_scene, built, lookahead_steps=window)
    profile.disable()
    took = time.perf_counter() - start
    # (file, line, function) -> (calls, primitive calls, own s, cumulative s, callers)
    stats = pstats.Stats(profile).stats
    solves = sum(v[1] for f, v in stats.items() if "'solve' of 'builtins." in f[2])
    placement = next(v[3] for f, v in stats.items()
                     if f[0].endswith("rbe/prestress.py") and f[2] == "placed")
    line = (f"Profiled (`--profile`): the in-process repair, {took:.1f} s under cProfile, "
            f"{found.checks} states checked, {solves} convex solves (Clarabel) "
            f"({solves / found.checks:.1f} a state), {placement / took:.0%} of the time in "
            "the placement test (`rbe_ros/rbe/prestress.py`, `placed`).")
    print(" ", line, flush=True)
    return [line, ""]


def staged(plan_scene, built, window: int) -> list[tuple[str, float, str]]:
    """Rows of the node's answer to the pose message, in process (the repair too), as the
    node makes it: its check of the as-built state with the plan's holds (~/report,
    ``asbuilt_check``) on a thread of its own, handed to ``Execution.advance`` as it is made
    (``NodeReport``: the look-ahead solves the first step ahead meanwhile, the repair begins
    while the state's tolerance question is asked); the time from the pose message to each
    output, in stages: the ExecutionState with the failing step, the PlanUpdate, the
    verified window. Then the same answer with ``advance`` given ~/report only once it is
    made (one after the other, the node before this change), for the ratio."""
    options, settings = CheckOptions(), Settings(lookahead_steps=window)

    def advance(beside: bool) -> tuple[float, list]:
        execution = Execution()
        execution.set_design(plan_scene)
        sent, made, checked = [], NodeReport(), []
        start = time.perf_counter()
        held = execution.holding(built)

        def check() -> None:
            report = None
            try:
                decided = (lambda verdict: made.decide(verdict, {})) if beside else None
                report = asbuilt_check(held, options, on_verdict=decided).reports[0]
                checked.append(time.perf_counter() - start)
            finally:
                made.send(report, {})

        thread = threading.Thread(target=check)
        thread.start()
        if not beside:
            thread.join()
        execution.advance(built, made, {}, options, settings,
                          on_output=lambda kind, message: sent.append(
                              (kind, message, time.perf_counter() - start)))
        thread.join()
        return checked[0], sent

    checked, sent = advance(True)
    which = f"the node's answer to the pose message (the next {window} steps, in process)"
    print(f"  {which}: ~/report {checked:.2f} s, "
          + ", ".join(f"{k} {t:.2f} s" for k, _, t in sent), flush=True)
    rows = [("~/report, the node's check of the as-built state with the plan's holds (whole, "
             "its tolerance question asked): pose -> ~/report", checked,
             "handed to `Execution.advance` as it is made, with its interfaces")]
    states = [(m, t) for k, m, t in sent if k == EXECUTION]
    first, took = states[0]
    rows.append((f"{which}: pose -> ~/report -> the ExecutionState with the failing step", took,
                 f"first failing step {first['first_failing_step']}, "
                 f"{len(first['lookahead'])} steps looked ahead"))
    updates = [(m, t) for k, m, t in sent if k != EXECUTION]
    if updates:
        update, took = updates[0]
        rows.append((f"{which}: pose -> ~/report -> ... -> the PlanUpdate", took,
                     f"{update['repair']}, feasible {update['feasible']}, changed step "
                     f"{update['changed_step']}"))
    last, took = states[-1]
    rows.append((f"{which}: pose -> ~/report -> ... -> the verified window (the last "
                 "ExecutionState)", took,
                 f"{len(sent)} outputs, first failing step {last['first_failing_step']}, "
                 f"{len(last['lookahead'])} steps looked ahead"))
    _, after = advance(False)

    def outputs(sent: list) -> list:
        return [{**m, "as_built": {**m["as_built"], "solve_time": 0.0}} if k == EXECUTION
                else m for k, m, _ in sent]

    if updates:
        took = next(t for k, _, t in after if k != EXECUTION)
        rows.append((f"{which}, `Execution.advance` given ~/report once it is made (one "
                     "after the other): pose -> ~/report -> ... -> the PlanUpdate", took,
                     "the same outputs (but the as-built check's time)"
                     if outputs(sent) == outputs(after) else "OTHER OUTPUTS"))
    return rows


def one_dome(name: str, key: str, scene, window: int = 0, whole: bool = True,
             workers: int = 1, profile: bool = False) -> list[str]:
    """The section of docs/REPAIR.md of one dome; ``window`` > 0: deviations looked for and
    repaired within the next ``window`` steps only (a node's look-ahead). ``whole`` False:
    no re-planning from scratch and no oracle (the 527-block dome: each takes hours)."""
    plan, plan_time = planned(key, scene)
    planned_scene = plan.scene
    half = len(plan.order) // 2
    print(f"{name}: plan {plan_time:.1f} s, feasible {plan.feasible}; half-built {half}",
          flush=True)
    lines = [f"## {name}", "", f"`plan --max-held 2` ({plan_time:.1f} s when made; feasible "
             f"{plan.feasible}; pose uncertainty {UNCERTAINTY[0] * 1e3:g} mm / "
             f"{UNCERTAINTY[1]:g} deg declared), built to half ({half} of {len(plan.order)} "
             "blocks placed at design), then the last placed block measured off (4 mm "
             "radially, turned 3 deg about its tangent or radial axis: the deviations of "
             "`DEVIATIONS`, in order).", ""]
    if not plan.feasible:
        return lines + [f"No plan: {plan.message}", ""]
    chosen, first, tried = None, None, 0
    for deviation, (_, shift, tilt, axis) in enumerate(DEVIATIONS):
        block, built = half_built(plan, deviation)
        ahead = look_ahead(planned_scene, built, lookahead_steps=window, until_failure=True)
        tried += 1
        what = f"{block} {shift * 1e3:+.0f} mm, {tilt:+.0f} deg about its {axis}"
        print(f"  {what}: as built stands {ahead.as_built.stable}, first failing step "
              f"{ahead.first_failing_step} ({ahead.time:.1f} s)", flush=True)
        first = first or (what, built, ahead)
        if ahead.first_failing_step >= half and ahead.as_built.stable:
            chosen = (what, built, ahead)
            break
    what, built, ahead = chosen or first
    if chosen is None:
        lines += [f"None of the {tried} deviations makes a step of the rest fail (each "
                  "checked " + (f"over the next {window} steps" if window else
                                "to the end of the plan") + f"); timed: the first ({what}), "
                  "whose repair changes nothing: its cost is the re-check of the steps.", ""]
    else:
        lines += [f"Deviation: {what} (the first of the list that makes a later step fail; "
                  f"{tried} tried): {ahead.message[:300]}", ""]
    if profile:
        return lines + profiled(planned_scene, built, window)
    rows = []
    gripped = gripped_states(planned_scene, built, window)
    for local in (False, True):
        took, states, cpu, regions = floor(planned_scene, built, window, local)
        how = ("walked by the incremental checker (`check --sequence`'s)" if local
               else "each whole")
        print(f"  floor, {how}: {took:.2f} s ({cpu:.1f} CPU s), {states} states, "
              f"{regions} settled by a region", flush=True)
        rows.append((f"one check of each remaining state of the plan (the floor), {how}",
                     took, f"{states} states checked, {cpu:.1f} CPU s (one thread)"
                     + (f", {regions} settled by a region ({gripped} hold a block with a "
                        "grip: solved whole)" if local else "")))
    found = {}
    for steps in (window,) if window else (0, 10):
        which = "every remaining step" if not steps else f"the next {steps} steps"
        for n in (0, workers) if workers else (0,):
            start = time.perf_counter()
            found[steps, n] = r = repair_plan(planned_scene, built, lookahead_steps=steps,
                                              workers=n)
            took = time.perf_counter() - start
            label = f"repair, {which}, " + (f"{n} worker processes" if n else "in process")
            print(f"  {label}: {took:.2f} s, {r.kind}: {r.message[:200]}", flush=True)
            rows.append((label, took, f"{r.kind}, feasible {r.feasible}, changed step "
                         f"{r.changed_step}, {r.checks} states checked"))
    for steps in (window,) if window else (0, 10):
        # what the node does: the look-ahead (every step of its window, as ~/execution
        # reports them) finds the failing step, the repair takes over the states it checked
        which = "every remaining step" if not steps else f"the next {steps} steps"
        start = time.perf_counter()
        ahead = look_ahead(planned_scene, built, lookahead_steps=steps)
        looked = time.perf_counter() - start
        start = time.perf_counter()
        found[steps, "node"] = r = repair_plan(planned_scene, built, lookahead_steps=steps,
                                               checked=ahead.checked)
        took = time.perf_counter() - start
        print(f"  look-ahead {looked:.2f} s + repair {took:.2f} s, {which}: {r.kind}, "
              f"{r.checks} states checked", flush=True)
        rows.append((f"look-ahead of {which} that finds the failing step, then the repair "
                     "(the node, in process)", looked + took,
                     f"look-ahead {looked:.2f} s ({len(ahead.checked.reports)} states), "
                     f"repair {took:.2f} s"))
        rows.append((f"repair after that look-ahead, {which}, its states handed over", took,
                     f"{r.kind}, feasible {r.feasible}, changed step {r.changed_step}, "
                     f"{r.checks} states checked"))
    rows += staged(planned_scene, built, window or LOOKAHEAD_STEPS)
    same = len({(r.kind, tuple(r.order), tuple(r.held)) for (steps, _), r in found.items()
                if steps == window}) == 1
    found = found[window, workers]
    replan_time = None
    if whole:
        # every block (the placed ones at their measured poses), the placed ones a fixed prefix
        fixed = replace(as_built_plan(planned_scene, built), sequence=tuple(plan.order[:half]),
                        holds=(), approach=())
        start = time.perf_counter()
        again = plan_sequence(fixed, 2, keep_sequence=True)
        replan_time = time.perf_counter() - start
        print(f"  re-plan: {replan_time:.2f} s, feasible {again.feasible}", flush=True)
        rows.append(("re-planning the remainder from scratch (the placed blocks a fixed "
                     "prefix)", replan_time, f"feasible {again.feasible}"))
    lines += ["| | time s | ratio to re-planning | result |", "|---|---|---|---|"]
    for label, took, result in rows:
        ratio = f"{took / replan_time:.2f}" if replan_time else "not re-planned"
        lines.append(f"| {label} | {took:.2f} | {ratio} | {result} |")
    if replan_time:
        bars = "; ".join(f"{label}: {took:.2f} s, {took / replan_time:.2f} x, "
                         + ("met" if took <= 2.0 and took <= 0.2 * replan_time else "not met")
                         for label, took, _ in rows
                         if label.startswith(("repair", "look", "the node's answer")))
        lines += ["", "Issue 30's bar (a one-block deviation repaired in at most 2 s and at "
                  f"most 0.2 x re-planning the remainder): {bars}."]
    lines += ["", "The repairs with and without workers, and after the look-ahead, are " + (
        "the same (kind, order, holds)." if same else "NOT the same."), ""]
    if found.scene is not None and whole:
        # the oracle: the repaired plan at the measured poses, every step checked on its own
        start = time.perf_counter()
        reports = check_sequence(remainder(found.scene, half))
        last = half + (min(len(reports), window) if window else len(reports)) - 1
        failing = [half + r.step_index for r in reports[:last + 1 - half] if not r.stable]
        lines += [f"Oracle: `check_sequence` of the repaired plan's remaining steps at the "
                  f"measured poses (the placed blocks present from the start; "
                  f"{time.perf_counter() - start:.1f} s): steps {half} to {last} "
                  + ("all stand." if not failing else f"fail at {failing}."), ""]
    return lines


def main() -> int:
    workers = int(sys.argv[sys.argv.index("--workers") + 1]) if "--workers" in sys.argv \
        else 2
    command = " ".join(["benchmarks/repair.py", *sys.argv[1:]])
    lines = ["# Repair time", "", f"Made by `{command}` (`make bench-repair`: both domes); "
             f"machine: {machine_summary()}; times of one run, on a machine shared with other work "
             "(compare the ratios).", "",
             "A repair guarantees every remaining step it covers, so it checks each of their "
             "states (blocks present, blocks held) at least once. In process it walks them "
             "as `check --sequence` walks a sequence, with the same incremental checker "
             "(`StepChecker`): each state from the forces of the one before (the as-built "
             "state whole), a region around the new block re-solved with the forces "
             "outside it kept where that settles the state, the whole state where not; a "
             "failing step's candidates (a hold, a swap) from the forces of the state "
             "before it. A region settles a state only when the state holds no block with "
             "a grip (a robot's wrench is the whole problem's) and the region's field "
             "needs no friction (the placement test does not compose over regions: kept "
             "friction on a region's boundary is friction the whole, set in place from "
             "rest, must build up again; on the 0.6-thickness dome below, step 63 stands "
             "as a region under the plan's forces and fails whole). The two floor rows "
             "are one check of each remaining state, in order: each whole, and by that "
             "walk (how many states a region settled, and how many hold a block). The "
             "repair stops at the first failing step, tries its candidates, and goes on "
             "from there; every state is checked once whichever candidate it belongs to. "
             "With worker processes (`repair_plan(..., workers=N)`, `repair --workers N`) "
             "the states are checked whole on N processes, the plan's remaining states "
             "queued ahead of the scan and a failing step's hold candidates before them: "
             "the same verdicts, the time the processes' start (a second or more each, "
             "importing the core) and the checks spread over the cores. On a machine whose "
             "other work keeps its cores busy, N processes also take N shares of them: the "
             "speed-up there is not the cores'. The node's repair follows its look-ahead "
             "on the same as-built state (the look-ahead found the failing step): the "
             "look-ahead hands over the states it checked and its checker at the failing "
             "step, and the repair checks none of them again (the look-ahead rows: both "
             "timed, in process; the node runs the repair in a process of its own). The "
             "repair alone does not ask whether the as-built state's verdict hangs on the "
             "contact tolerance (a solve of its near contacts) unless it does not stand; a "
             "failing step's hold candidates are tried kept grips first, then the hold "
             "search's, then the block placed there, then the other blocks that move. The "
             "rows of the node's answer time it from the pose message to each output, in "
             "process (its repair too), as the node does it: ~/report (the as-built state "
             "with the plan's holds checked whole, its tolerance question asked: a row of "
             "its own) on a thread of its own, handed to `Execution.advance` as it is made "
             "(`NodeReport`): the look-ahead solves the first step ahead while the state "
             "is solved, takes the state's verdict as its check of it (not checked again), "
             "and begins the repair of a failing step while the state's tolerance question "
             "is asked; in stages: the ExecutionState as soon as a step of the window fails "
             "(the steps up to it) and ~/report is made, the PlanUpdate of the repair of "
             "the steps up to it, then the ExecutionState of the repaired plan over the "
             "whole window (repairing again at a later failing step); the last row is the "
             "same answer with `Execution.advance` given ~/report only once it is made (one "
             "after the other, as before).", ""]
    if "--dome527" in sys.argv:
        # its re-check to the end costs many minutes (docs/SCALING.md): a node's window only
        scene, _ = load_design(DOME527)
        lines = one_dome("compas_assembly's 527-block dome (as built, 5 mm / 3.5 deg "
                         "declared)", "dome527", replace(scene, pose_uncertainty=UNCERTAINTY),
                         window=10, whole=False, workers=workers)
        lines[1:1] = ["", f"Made by `benchmarks/repair.py --dome527`, one run; machine: "
                      f"{machine_summary()}."]
        (ROOT / "docs" / "REPAIR_527.md").write_text("\n".join(lines))
        return 0
    domes = [d for d in DOMES if d[1] == sys.argv[sys.argv.index("--only") + 1]] \
        if "--only" in sys.argv else DOMES[1:] if "--thin" in sys.argv else DOMES
    for name, key, params in domes:
        lines += one_dome(name, key, replace(generators.dome(**params),
                                             pose_uncertainty=UNCERTAINTY), workers=workers,
                          profile="--profile" in sys.argv)
    if "--profile" in sys.argv:
        return 0
    lines += ["compas_assembly's 527-block dome: [docs/REPAIR_527.md](REPAIR_527.md) "
              "(`benchmarks/repair.py --dome527`: its plan takes hours on 2 cores).", ""]
    out = Path(sys.argv[sys.argv.index("--out") + 1]) if "--out" in sys.argv else \
        ROOT / "docs" / "REPAIR.md"
    out.write_text("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
