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

import json
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

from trees import PYTHON, ROOT, arguments, in_tree, started

#: Run in a tree: the repair of the half-built dome with look-ahead argv[3], its processor
#: time and outcome as one JSON line.
REPAIR = """
from rbe_ros.analysis.repair import repair_plan
scene = plan.scene
_, built = half_built(plan, 0)
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


def main() -> int:
    parser = arguments(__doc__)
    args = parser.parse_args()
    trees = started(args)
    if trees is None:
        return 1
    with tempfile.TemporaryDirectory() as folder:
        scene = Path(folder) / "dome14.json"
        subprocess.run([str(PYTHON), "-m", "rbe_ros.cli", "generate", "dome", "-o", str(scene)],
                       cwd=ROOT, env=os.environ | {"PYTHONPATH": str(ROOT)}, check=True,
                       capture_output=True)
        cases = (("check --sequence", lambda t: _sequence(t, scene)),
                 ("repair, 10-step look-ahead", lambda t: in_tree(t, REPAIR, 10)),
                 ("repair, to the end", lambda t: in_tree(t, REPAIR, 0)))
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
