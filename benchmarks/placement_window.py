#!/usr/bin/env python3
"""The placement tests of issue 30's repair window, trees against each other in one run: the
14 x 10 dome built to half with its last placed block off (each deviation of
benchmarks/repair.py, the plan kept by ``make bench-repair`` in build/repair/), repaired with
the 10-step look-ahead. Per top-level placement test (rbe/prestress.py ``placed``): its
processor time, and its answer (stands, blocks that move, interfaces that slide, the field's
normal resultants); each tree's answers are compared with the first tree's (resultants to
``--tol`` of the free weight W), the repairs' outcomes too.

Each measurement runs the tree's own package (PYTHONPATH) in a process of its own, the trees
alternating; read the ratios (docs/METHOD.md, "Placement test cost").

    python benchmarks/placement_window.py TREE [TREE ...] [--repeats N] [--deviations K ...]
"""
from __future__ import annotations

import os
import sys

from trees import arguments, in_tree, started

#: Run in a tree: the repair window of deviation argv[3], one JSON line.
WINDOW = """
import rbe_ros.analysis.verdict as verdict
from rbe_ros.analysis.repair import repair_plan
from rbe_ros.rbe import prestress
tests, depth, placed = [], [0], prestress.placed

def timed(model, *args, **kwargs):
    depth[0] += 1
    start = time.process_time()
    try:
        found = placed(model, *args, **kwargs)
    finally:
        depth[0] -= 1
    if not depth[0]:
        field = found.field if found.field is not None else found.beyond
        normal = None if field is None else (prestress._sums(model, field.forces[0]
                                                             - field.forces[1])
                                             / model.force_scale).tolist()
        tests.append({"cpu": time.process_time() - start, "free": len(model.free),
                      "answer": [found.stands, list(found.moving), list(found.sliding)],
                      "normal": normal})
    return found

verdict.placed = timed
scene = plan.scene
_, built = half_built(plan, int(sys.argv[3]))
r = repair_plan(scene, built, lookahead_steps=10)
print(json.dumps({"outcome": [r.kind, r.changed_step], "tests": tests}))
"""


def _differences(a: dict, b: dict, tol: float) -> list[str]:
    """Where window ``b`` answers otherwise than ``a``."""
    if a["outcome"] != b["outcome"] or len(a["tests"]) != len(b["tests"]):
        return [f"outcome {a['outcome']} {b['outcome']}, tests {len(a['tests'])} "
                f"{len(b['tests'])}"]
    out = []
    for k, (x, y) in enumerate(zip(a["tests"], b["tests"])):
        if x["answer"] != y["answer"] or (x["normal"] is None) != (y["normal"] is None):
            out.append(f"test {k}: {x['answer']} {y['answer']}")
        elif x["normal"] is not None and max(abs(p - q) for p, q in
                                             zip(x["normal"], y["normal"])) > tol:
            out.append(f"test {k}: normal resultants beyond {tol} W")
    return out


def main() -> int:
    parser = arguments(__doc__)
    parser.add_argument("--deviations", type=int, nargs="*", default=[0],
                        help="indices into benchmarks/repair.py's DEVIATIONS")
    parser.add_argument("--tol", type=float, default=1e-8,
                        help="normal resultants' difference allowed (share of W)")
    args = parser.parse_args()
    trees = started(args)
    if trees is None:
        return 1
    differ = 0
    for deviation in args.deviations:
        best = {}
        for _ in range(args.repeats):
            for t in trees:
                result = in_tree(t, WINDOW, deviation)
                if t not in best:
                    best[t] = result
                    continue
                differ += len(_differences(best[t], result, args.tol)) > 0
                for kept, new in zip(best[t]["tests"], result["tests"]):
                    kept["cpu"] = min(kept["cpu"], new["cpu"])
        first = best[trees[0]]
        for t in trees[1:]:
            for line in _differences(first, best[t], args.tol):
                differ += 1
                print(f"deviation {deviation}, {t.name} DIFFERS: {line}")
        total = {t: sum(x["cpu"] for x in best[t]["tests"]) for t in trees}
        print(f"deviation {deviation} ({first['outcome'][0]} at {first['outcome'][1]}), "
              "placement tests: " + ", ".join(f"{t.name} {total[t]:.2f} s "
                                              f"({total[t] / total[trees[0]]:.2f}x)"
                                              for t in trees),
              f"load {os.getloadavg()[0]:.1f}", flush=True)
        if args.repeats > 1 or len(args.deviations) == 1:
            for k, x in enumerate(first["tests"]):
                print(f"  {x['free']} free, {'stands' if x['answer'][0] else 'moves'}: "
                      + ", ".join(f"{best[t]['tests'][k]['cpu']:.3f} s" for t in trees))
    print(f"{differ} differences")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
