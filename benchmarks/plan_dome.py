#!/usr/bin/env python3
"""Plan the full dome of Kao et al. 2021 (14 slices x 10 courses, 126 blocks to place) with
at most K held blocks and re-check every step of the plan with the plain checker (the held
blocks as supports). Writes docs/plan_dome.json: the order, the blocks held at each step,
the search's checks and times, and the plain re-check of every step.

Usage: .venv/bin/python benchmarks/plan_dome.py [--max-held 2] [--beam 1] [-o docs/plan_dome.json]
(a few minutes: the plan, then one full check per step).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rbe_ros import generators  # noqa: E402
from rbe_ros.analysis.assembly import Assembly  # noqa: E402
from rbe_ros.analysis.verdict import check  # noqa: E402
from rbe_ros.analysis.planning import plan_sequence  # noqa: E402
from rbe_ros.analysis.steps import sequence_steps  # noqa: E402
from rbe_ros.io.scene_json import scene_to_dict  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-held", type=int, default=2)
    parser.add_argument("--beam", type=int, default=1)
    parser.add_argument("-o", "--output", default=str(ROOT / "docs" / "plan_dome.json"))
    args = parser.parse_args(argv)
    dome = generators.dome()
    plan = plan_sequence(dome, args.max_held, beam=args.beam)
    print(f"{dome.name}: {'feasible' if plan.feasible else 'NOT feasible'}: {plan.message} "
          f"({plan.checks} candidate checks, {plan.time:.1f} s)")
    start = time.perf_counter()
    rechecked = []
    if plan.scene is not None:
        full = Assembly.from_scene(plan.scene)
        for step in sequence_steps(plan.scene):
            r = check(full.subset(step.present, step.held))
            rechecked.append({"step": step.index, "block": step.block, "held": list(step.held),
                              "status": r.status.name})
    recheck_time = time.perf_counter() - start
    stable = sum(s["status"] == "STABLE" for s in rechecked)
    print(f"plain re-check: {stable}/{len(rechecked)} steps stable ({recheck_time:.1f} s)")
    held_steps = [s for s in rechecked if s["held"]]
    print(f"steps with holds: {len(held_steps)}, at most {plan.max_held} held at once")
    out = {"scene": dome.name, "max_held_limit": args.max_held, "beam": args.beam,
           "feasible": plan.feasible, "message": plan.message, "failed_step": plan.failed_step,
           "max_held": plan.max_held, "search_checks": plan.checks,
           "plan_time_s": round(plan.time, 1), "recheck_time_s": round(recheck_time, 1),
           "order": plan.order,
           "holds": scene_to_dict(plan.scene).get("holds", []) if plan.scene else [],
           "steps": rechecked}
    Path(args.output).parent.mkdir(parents=True, exist_ok=True)
    Path(args.output).write_text(json.dumps(out, indent=1) + "\n")
    print(f"written to {args.output}")
    return 0 if plan.feasible and stable == len(rechecked) else 1


if __name__ == "__main__":
    sys.exit(main())
