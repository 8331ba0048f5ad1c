#!/usr/bin/env python3
"""Rule 4's cost on partial domes (docs/METHOD.md, "Sequences"), trees against each other in
one run: the processor time of ``rbe-ros check dome14.json --sequence --json`` (the 14 x 10
dome of ``rbe-ros generate dome``; the command's own process, imports included) and of
``repair_plan`` of the 14 x 10 dome built to half with the last placed block off by
benchmarks/repair.py's first deviation, with the 10-step look-ahead and to the end (the
plan kept by ``make bench-repair`` in build/repair/; the repair alone timed).

Each measurement runs the tree's own package (PYTHONPATH) in a process of its own, the trees
alternating, so that the load of a shared machine falls on all of them alike; read the
ratios.

    python benchmarks/rule4_cost.py TREE [TREE ...] [--repeats N]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

from machine import machine_summary

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
PYTHON = ROOT / ".venv" / "bin" / "python"
PLAN = ROOT / "build" / "repair" / "dome14x10.pkl"
#: Run in a tree: the repair of the half-built dome with look-ahead argv[3], its processor
#: time and outcome as one JSON line.
REPAIR = """
import json, os, pickle, sys, time
import rbe_ros
from rbe_ros.analysis.repair import repair_plan
from rbe_ros.io.poses import scene_at_poses
sys.path.insert(0, sys.argv[1])
from repair import DEVIATIONS, deviated     # after rbe_ros: it puts its own tree first
assert rbe_ros.__file__.startswith(os.getcwd()), rbe_ros.__file__
plan, _ = pickle.load(open(sys.argv[2], "rb"))
scene = plan.scene
half = len(plan.order) // 2
design = {b: (scene.block(b).position.tolist(), scene.block(b).orientation.tolist())
          for b in plan.order[:half]}
k, shift, tilt, axis = DEVIATIONS[0]
block = plan.order[half - k]
built = scene_at_poses(scene, {**design, block: deviated(scene.block(block), shift, tilt, axis)})
start = time.process_time()
r = repair_plan(scene, built, lookahead_steps=int(sys.argv[3]))
print(json.dumps({"cpu": time.process_time() - start, "outcome": [r.kind, r.changed_step]}))
"""


def _sequence(tree: Path, scene: Path) -> dict:
    """``check --sequence`` of ``scene`` by ``tree``: its processor time (user + system of
    the child) and its statuses."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = subprocess.run([str(PYTHON), "-m", "rbe_ros.cli", "check", str(scene), "--sequence",
                          "--json"], capture_output=True, text=True, cwd=tree,
                         env=os.environ | {"PYTHONPATH": str(tree)})
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    return {"cpu": cpu, "outcome": [r["status"] for r in json.loads(out.stdout)["reports"]]}


def _repair(tree: Path, lookahead: int) -> dict:
    out = subprocess.run([str(PYTHON), "-c", REPAIR, str(HERE), str(PLAN), str(lookahead)],
                         capture_output=True, text=True, cwd=tree,
                         env=os.environ | {"PYTHONPATH": str(tree)}, check=True)
    return json.loads(out.stdout.splitlines()[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("trees", nargs="+", type=Path, help="checkouts of rbe_ros")
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args()
    if not PLAN.exists():
        print(f"no plan at {PLAN}: run make bench-repair first", file=sys.stderr)
        return 1
    trees = [t.resolve() for t in args.trees]
    print(machine_summary(), flush=True)
    with tempfile.TemporaryDirectory() as folder:
        scene = Path(folder) / "dome14.json"
        subprocess.run([str(PYTHON), "-m", "rbe_ros.cli", "generate", "dome", "-o", str(scene)],
                       cwd=ROOT, env=os.environ | {"PYTHONPATH": str(ROOT)}, check=True,
                       capture_output=True)
        cases = (("check --sequence", lambda t: _sequence(t, scene)),
                 ("repair, 10-step look-ahead", lambda t: _repair(t, 10)),
                 ("repair, to the end", lambda t: _repair(t, 0)))
        for name, run in cases:
            best = {t: None for t in trees}
            for _ in range(args.repeats):
                for t in trees:
                    result = run(t)
                    if best[t] is None or result["cpu"] < best[t]["cpu"]:
                        best[t] = result
            first = best[trees[0]]
            print(f"{name}: " + ", ".join(
                f"{t.name} {best[t]['cpu']:.2f} s ({best[t]['cpu'] / first['cpu']:.2f}x)"
                f"{'' if best[t]['outcome'] == first['outcome'] else ' OUTCOME DIFFERS'}"
                for t in trees), f"load {os.getloadavg()[0]:.1f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
