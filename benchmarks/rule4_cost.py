#!/usr/bin/env python3
"""Rule 4's cost on partial domes (docs/METHOD.md, "Sequences"), trees against each other in
one run: the processor time of ``rbe-ros check dome14.json --sequence --json`` (the 14 x 10
dome of ``rbe-ros generate dome``; the command's own process, imports included) and of
``repair_plan`` of the 14 x 10 dome built to half with the last placed block off by
benchmarks/repair.py's first deviation, with the 10-step look-ahead and to the end (the
plan kept by ``make bench-repair`` in build/repair/; the repair alone timed); and with
``--dome527``, compas_assembly's 527-block dome planned by the first tree until 134 blocks are
placed (``plan_sequence`` stopped there: its first descent, the same in every tree that makes
the same verdicts), the state after its last step checked whole by each (``verdict.check``,
the check of a planner's candidate; its open course's programs), and its states of the
248-260 lowest blocks (half of it built course by course, then the next course open, nothing
held: states like those a repair's window at half-built checks, which no plan made on this
machine within a session reaches).

Each measurement runs the tree's own package (PYTHONPATH) in a process of its own, the trees
alternating, so that the load of a shared machine falls on all of them alike; read the
ratios.

    python benchmarks/rule4_cost.py TREE [TREE ...] [--repeats N] [--only WORD] [--dome527]
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

#: Run in a tree: the 527-block dome planned until argv[4] blocks are placed, kept in the
#: file argv[3] (as the plans of build/repair/ are).
PARTIAL = """
from dataclasses import replace
from rbe_ros.analysis.planning import plan_sequence
from rbe_ros.io.inputs import load_design
from repair import DOME527, UNCERTAINTY
scene, _ = load_design(DOME527)
placed = [0]
partial = plan_sequence(replace(scene, pose_uncertainty=UNCERTAINTY), 2,
                        progress=lambda p: placed.__setitem__(0, p.placed),
                        should_stop=lambda: placed[0] >= int(sys.argv[4]))
pickle.dump((partial, 0.0), open(sys.argv[3], "wb"))
print(json.dumps({"placed": len(partial.order)}))
"""
#: The end of the snippets that check one state of the 527-block dome: ``assembly`` checked
#: whole with ``options``, its processor time and status as one JSON line.
CHECKED = """
start = time.process_time()
report = check(assembly, options)
print(json.dumps({"cpu": time.process_time() - start, "outcome": report.status.name}))
"""
#: Run in a tree: the state after the last step of the plan (a partial one) checked whole.
PLANNED_STATE = """
from rbe_ros.analysis.asbuilt import declared
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.steps import sequence_step
from rbe_ros.analysis.verdict import check
options = declared(CheckOptions(), plan.scene)       # the pose uncertainty, as planned
step = sequence_step(plan.scene, len(plan.order) - 1)
assembly = Assembly.from_scene(plan.scene, options.contact).subset(step.present, step.held,
                                                                   step.grips)
""" + CHECKED
#: Run in a tree: the 527-block dome's supports and its argv[3] lowest free blocks (by
#: position: course by course, as a plan's candidates go) checked whole, nothing held.
LOWEST_STATE = """
from dataclasses import replace
from rbe_ros.analysis.asbuilt import declared
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.verdict import check
from rbe_ros.io.inputs import load_design
from repair import DOME527, UNCERTAINTY
scene, _ = load_design(DOME527)
scene = replace(scene, pose_uncertainty=UNCERTAINTY)
options = declared(CheckOptions(), scene)
free = sorted((b for b in scene.blocks if not b.support), key=lambda b: (b.position[2], b.id))
ids = [b.id for b in scene.blocks if b.support] + [b.id for b in free[:int(sys.argv[3])]]
assembly = Assembly.from_scene(scene, options.contact).subset(ids)
""" + CHECKED
#: The 527-block dome's blocks placed by its partial plan before its state is checked (its
#: open course), and the numbers of its lowest blocks whose states are checked: half of its
#: 496 (a course closed) and the next course open
DOME527_PLACED = 134
DOME527_LOWEST = (248, 252, 256, 260)


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
    parser.add_argument("--only", default="", help="the cases whose name holds this")
    parser.add_argument("--dome527", action="store_true",
                        help="also the 527-block dome's states (a partial plan's, its "
                        "lowest blocks')")
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
        if args.dome527:
            partial = Path(folder) / "dome527_partial.pkl"

            def planned_state(t: Path) -> dict:
                if not partial.exists():        # planned by the first tree, once
                    in_tree(trees[0], PARTIAL, partial, DOME527_PLACED)
                return in_tree(t, PLANNED_STATE, plan=partial)

            cases += ((f"527-block dome, the state of {DOME527_PLACED} blocks placed (plan "
                       "order), whole", planned_state),) + tuple(
                (f"527-block dome, its {n} lowest blocks, whole",
                 lambda t, n=n: in_tree(t, LOWEST_STATE, n)) for n in DOME527_LOWEST)
        for name, run in (c for c in cases if args.only in c[0]):
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
