"""Where a plan's stability time goes: the full checks the planner makes (``check`` of a
candidate step, with a robot's grip on each held block), grouped by verdict and number of
blocks held, with their CPU time and their placement tests' steps (rbe/prestress.py's
fixed point; MAX_STEPS ends one that has not settled) and the solves they make (a held step
that stands iterates its caps too: prestress._settled); the hold search's checks beside.

A plan of the interlocking suite, planned as tests/test_interlock_suite.py plans it (at most
2 held, mu 0.55). CPU time of this process (the machine is shared: compare the rows of one
run). ``--steps``: every full check, in the order made.

    nice -n 5 python benchmarks/plan_checks.py keyed_vault_2rings [--steps]
"""
from __future__ import annotations

import argparse
import collections
import time
from dataclasses import replace
from pathlib import Path

from rbe_ros.analysis import holds, incremental, planning, verdict
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.interlock import SUITE_MU
from rbe_ros.io.scene_json import load_scene
from rbe_ros.rbe import prestress

SUITE = Path(__file__).resolve().parents[1] / "tests" / "data" / "interlock"


def plan_checks(scene, options: CheckOptions) -> tuple[planning.Plan, list[dict], float]:
    """The plan, each check it made (kind, present blocks, held, status, placement tests'
    steps and solves, CPU s) and the plan's CPU s."""
    made, steps, solves = [], [], [0]
    saved = prestress.placed, planning.check, holds.check, holds.is_stable, prestress.solve

    def solve(*args, **kwargs):
        solves[0] += 1
        return saved[4](*args, **kwargs)

    def placed(*args, **kwargs):
        found = saved[0](*args, **kwargs)
        steps.append(found.steps)
        return found

    def counted(kind, function):
        def wrapper(assembly, *args, **kwargs):
            steps.clear()
            solves[0] = 0
            start = time.process_time()
            found = function(assembly, *args, **kwargs)
            made.append({"kind": kind, "blocks": len(assembly.blocks),
                         "held": tuple(g.block for g in assembly.grips),
                         "status": ("STABLE" if found else "not stable")
                         if isinstance(found, bool) else found.status.name,
                         "placement steps": list(steps), "solves": solves[0], "cpu": time.process_time() - start})
            return found
        return wrapper

    verdict.placed = incremental.placed = placed
    prestress.solve = solve
    planning.check = counted("candidate", saved[1])
    holds.check = counted("hold search", saved[2])
    holds.is_stable = counted("hold search", saved[3])
    start = time.process_time()
    try:
        plan = planning.plan_sequence(scene, max_held=2, options=options)
    finally:
        verdict.placed = incremental.placed = saved[0]
        planning.check, holds.check, holds.is_stable, prestress.solve = saved[1:]
    return plan, made, time.process_time() - start


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("name", help="a scene of tests/data/interlock (without .json)")
    parser.add_argument("--steps", action="store_true", help="every full check, in order")
    args = parser.parse_args(argv)
    options = replace(CheckOptions(), solve=replace(CheckOptions().solve, mu=SUITE_MU))
    plan, made, cpu = plan_checks(load_scene(SUITE / f"{args.name}.json"), options)
    print(f"{args.name}: {plan.outcome}, {plan.checks} candidate checks ({plan.models}), "
          f"plan CPU {cpu:.1f} s")
    print(f"order {' '.join(plan.order)}\nheld {plan.held}")
    groups = collections.defaultdict(list)
    for c in made:
        groups[(c["kind"], c["status"], len(c["held"]))].append(c)
    print("| checks | verdict | held | count | CPU s | placement tests | their steps | most "
          "| their solves |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for (kind, status, held), group in sorted(groups.items(), key=lambda g: -sum(
            c["cpu"] for c in g[1])):
        tests = [s for c in group for s in c["placement steps"]]
        print(f"| {kind} | {status} | {held} | {len(group)} | "
              f"{sum(c['cpu'] for c in group):.1f} | {len(tests)} | {sum(tests)} | "
              f"{max(tests, default=0)} | {sum(c['solves'] for c in group)} |")
    if args.steps:
        for c in made:
            if c["kind"] == "candidate":
                print(f"{c['blocks']:3d} blocks, held {','.join(c['held']) or '-':12s} "
                      f"{c['status']:18s} {c['cpu']:6.2f} s, placement steps "
                      f"{c['placement steps']}, {c['solves']} solves")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
