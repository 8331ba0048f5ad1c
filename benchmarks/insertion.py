"""Cost of the insertion check against the stability check of each step: docs/INSERTION.md.

Per step of the 140-block dome's sequence and of a 1,000-block running-bond wall (every step,
in sequence order), the time of the step's stability check (``StepChecker.check``, as
``check_sequence`` makes it) and of the placed block's insertion (cone and swept path,
:func:`rbe_ros.analysis.insertion.block_insertion`), measured in the same loop so both see
the same load, in CPU time of this process (``time.process_time``: the machine is shared, and
wall time counts the other users' load). The bar of issue 22: insertion at most 0.5x the stability check.

Per plan of non-convex assemblies (walls of T tetrominoes, a row of bars in a comb cradle
under inverted U caps: exact paths of the true shapes), ``plan_sequence`` with at most 2
held, the time in the path checks (every ``block_insertion`` the planner asks) against the
time in its stability checks (``StepChecker.attempt`` and ``check`` as the planner calls
them; the hold search's own checks are left out, so the ratio is if anything too high).
The bar of issue 28: at most 1x.

    python benchmarks/insertion.py [--out docs] [--interlock-only]
                                     (make bench-insertion, part of make bench)

The interlocking suite (tests/data/interlock), each assembly planned as its test plans it,
with the plan's time and holds: docs/INTERLOCK.md (:func:`interlock_suite`).
"""
from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from machine import machine_summary

from rbe_ros import generators as gen
from rbe_ros.analysis import planning
from rbe_ros.analysis.incremental import StepChecker
from rbe_ros.analysis.insertion import block_insertion
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.steps import sequence_step, step_count
from rbe_ros.analysis.validate import validated_assembly
from rbe_ros.analysis.verdict import check
from rbe_ros.interlock import SUITE_MU, log_cabin
from rbe_ros.io.scene_json import load_scene

ROOT = Path(__file__).resolve().parents[1]


def step_times(scene, options: CheckOptions) -> tuple[np.ndarray, np.ndarray, int]:
    """(stability s, insertion s) per step, and the steps whose block is insertable."""
    full = validated_assembly(scene, options.limits, options.contact)
    checker = StepChecker(options, local=not options.full_solve)
    stability, insertion, insertable = [], [], 0
    for k in range(step_count(scene)):
        step = sequence_step(scene, k)
        assembly = full.subset(step.present, step.held)
        start = time.process_time()
        checker.check(assembly)
        middle = time.process_time()
        found = block_insertion(full, step.present, step.block, options)
        stability.append(middle - start)
        insertion.append(time.process_time() - middle)
        insertable += found.insertable
    return np.array(stability), np.array(insertion), insertable


def plan_times(scene, max_held: int = 2, options: CheckOptions = CheckOptions()
               ) -> tuple[float, float, int, int, planning.Plan]:
    """(stability s, path checks s, stability checks, path checks, the plan) of one plan."""
    spent = {"stability": 0.0, "insertion": 0.0}
    calls = {"stability": 0, "insertion": 0}

    def timed(kind, function):
        def wrapper(*args, **kwargs):
            start = time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                spent[kind] += time.process_time() - start
                calls[kind] += 1
        return wrapper

    saved = planning.block_insertion, planning.check, StepChecker.attempt
    planning.block_insertion = timed("insertion", saved[0])
    planning.check = timed("stability", saved[1])
    StepChecker.attempt = timed("stability", saved[2])
    try:
        plan = planning.plan_sequence(scene, max_held=max_held, options=options)
    finally:
        planning.block_insertion, planning.check, StepChecker.attempt = saved
    return (spent["stability"], spent["insertion"], calls["stability"], calls["insertion"],
            plan)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs")
    parser.add_argument("--interlock-only", action="store_true",
                        help="only the interlocking suite (docs/INTERLOCK.md)")
    args = parser.parse_args(argv)
    if args.interlock_only:
        interlock_suite(args.out)
        return 0
    rows = []
    for name, scene in (("dome 14x10 (140 blocks)", gen.dome()),
                        ("wall 40x25 running bond (1,020 blocks)",
                         gen.running_bond_wall(courses=40, bricks_per_course=25))):
        stability, insertion, insertable = step_times(scene, CheckOptions())
        ratio = insertion / stability
        rows.append(f"| {name} | {len(stability)} | {insertable} | {1e3 * stability.sum():.0f} "
                    f"| {1e3 * insertion.sum():.0f} | {insertion.sum() / stability.sum():.3f} "
                    f"| {np.median(ratio):.3f} | {np.percentile(ratio, 95):.3f} |")
        print(rows[-1], flush=True)
    plans = []
    for name, scene in (("T tetromino wall 3x2 squares (24 pieces)", gen.tetromino_wall(3, 2)),
                        ("T tetromino wall 4x3 squares (48 pieces)", gen.tetromino_wall(4, 3)),
                        ("cradle row, 8 bars and 8 caps (17 blocks)", gen.cradle_row(8))):
        stability, insertion, n_stability, n_insertion, plan = plan_times(scene)
        plans.append(f"| {name} | {'yes' if plan.feasible else 'no'} | {n_stability} | "
                     f"{1e3 * stability:.0f} | {n_insertion} | {1e3 * insertion:.0f} | "
                     f"{insertion / stability:.3f} |")
        print(plans[-1], flush=True)
    load = os.getloadavg()[0]
    text = "\n".join([
        "# Insertion check: cost against the stability check",
        "",
        "Made by `python benchmarks/insertion.py` (`make bench-insertion`, part of `make bench`).",
        "Per step, in sequence order: the step's stability check (`StepChecker.check`, local",
        "models as `check_sequence` uses them) and the placed block's insertion (cone of its",
        "interface normals, swept path from where it is clear of every present block, python-fcl after a",
        "bounding-box broad phase), timed in the same loop in CPU time of the process. Bar",
        "(issue 22): insertion <= 0.5x. Step ratios are of single steps (a step whose stability",
        "check is answered locally in about a millisecond makes a large ratio of a small time).",
        "",
        "| sequence | steps | insertable | stability ms | insertion ms | total ratio "
        "| median step ratio | 95th pct step ratio |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
        *rows,
        "",
        "## Plans of non-convex assemblies",
        "",
        "Per plan (`plan_sequence`, at most 2 held; the interlocking suite of",
        "tests/data/interlock/ as its tests plan it: docs/INTERLOCK.md), the time in its path checks (every",
        "`block_insertion` the planner asks: cone, candidate directions, the swept convex",
        "pieces of the true shapes until clear of every present block) against the time in",
        "its stability checks (`StepChecker.attempt` and `check` as the planner calls them),",
        "in CPU time of the process, in the same run. Bar (issue 28): path checks <= 1x.",
        "",
        "| assembly | planned | stability checks | stability ms | path checks | path ms "
        "| ratio |",
        "| --- | --- | ---: | ---: | ---: | ---: | ---: |",
        *plans,
        "",
        f"Load average at the end of the run: {load:.1f} (a shared machine: ratios, not times).",
        "",
        machine_summary(),
        ""])
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "INSERTION.md").write_text(text)
    print(f"wrote {args.out / 'INSERTION.md'}")
    interlock_suite(args.out)
    return 0


def interlock_suite(out: Path) -> None:
    """docs/INTERLOCK.md: every planned assembly of tests/data/interlock planned as its test
    plans it (insertion on, at most 2 held, mu 0.55), with the plan's wall time, its path
    checks' CPU time against its stability checks' and the holds it uses."""
    options = replace(CheckOptions(), solve=replace(CheckOptions().solve, mu=SUITE_MU))
    rows = []
    suite = [(path.stem, load_scene(path))
             for path in sorted((ROOT / "tests" / "data" / "interlock").glob("*.json"))
             if path.stem != "sealed_pocket"]   # no plan exists: not a plan's cost
    # the size of the largest published assembly the issue names (148 parts)
    suite.append(("log_cabin, 37 levels (generated, not a file)", log_cabin(levels=37)))
    for name, scene in suite:
        # one check of the finished assembly, the unit of the plan's CPU time (load-free)
        start = time.process_time()
        check(validated_assembly(scene, options.limits, options.contact), options)
        unit = time.process_time() - start
        start = time.process_time()
        stability, insertion, n_stability, n_insertion, plan = plan_times(scene, 2, options)
        cpu = time.process_time() - start
        held = max((len(h) for h in plan.held), default=0)
        rows.append(f"| {name} | {sum(not b.support for b in scene.blocks)} | "
                    f"{'yes' if plan.feasible else 'no'} | {plan.time:.1f} | {cpu:.1f} | "
                    f"{cpu / unit:.0f} | {n_stability} | "
                    f"{1e3 * stability:.0f} | {n_insertion} | {1e3 * insertion:.0f} | "
                    f"{insertion / stability:.3f} | {held} | "
                    f"{sum(len(h) for h in plan.held)} |")
        print(rows[-1], flush=True)
    text = "\n".join([
        "# The interlocking suite: plans and their cost",
        "",
        "Made by `python benchmarks/insertion.py` (`make bench-insertion`). The assemblies of",
        "tests/data/interlock (non-convex parts, tests/data/interlock/README.md), each planned",
        "with insertion on, at most 2 held, mu 0.55 (`plan_sequence`, as `rbe-ros plan",
        "--max-held 2 --mu 0.55`). Plan s: the plan's wall time (bar, issue 28: under 60 s);",
        "plan CPU s: the process's CPU time in it; x check: that over the CPU time of one check",
        "of the finished assembly in the same run (the plan's cost in checks, whatever the load).",
        "Path checks (every `block_insertion` the planner asks: the swept convex pieces of the",
        "true shapes) against stability checks (`StepChecker.attempt` and `check`), CPU time of",
        "the process in the same run; ratio: path / stability (bar: at most 1). Holds: the most",
        "blocks held at one step, and block-steps held in all. tests/test_interlock_suite.py",
        "re-checks every plan with `check --sequence` and sweeps every path with trimesh.",
        "The sealed pocket, which has no plan, is left out (its proof costs a search of every",
        "order: `rbe-ros plan sealed_pocket.json --max-held 2 --mu 0.55 --search-budget 3000`).",
        "The last row is a scale point: a log cabin of 148 logs, the size of the largest",
        "published assembly of issue 28 (`rbe-ros generate log-cabin -p levels=37`).",
        "",
        "| assembly | parts | planned | plan s | plan CPU s | x check | stability checks "
        "| stability ms | path checks | path ms | ratio | most held | held block-steps |",
        "| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: "
        "| ---: |",
        *rows,
        "",
        f"Load average at the end of the run: {os.getloadavg()[0]:.1f} (a shared machine: "
        "ratios, not times).",
        "",
        machine_summary(),
        ""])
    out.mkdir(parents=True, exist_ok=True)
    (out / "INTERLOCK.md").write_text(text)
    print(f"wrote {out / 'INTERLOCK.md'}")


if __name__ == "__main__":
    raise SystemExit(main())
