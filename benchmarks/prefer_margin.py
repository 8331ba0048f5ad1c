#!/usr/bin/env python3
"""`rbe-ros plan --prefer margin` against the default (--prefer holds) on the 7-voussoir arch
and the 8 x 5 and 14 x 10 domes (--max-held 2, every step's margin over 8 directions): the
weakest step (index, block, margin) and the hold-steps of both plans, their times in one run.
Writes docs/PREFER_MARGIN.md.

Usage: .venv/bin/python benchmarks/prefer_margin.py   (make bench-prefer; minutes)
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from machine import machine_summary  # noqa: E402
from rbe_ros import generators  # noqa: E402
from rbe_ros.analysis.options import CheckOptions  # noqa: E402
from rbe_ros.analysis.planning import plan_sequence  # noqa: E402

#: (name, scene, candidates tried per step by --prefer margin: each feasible one costs its
#: margin, about one whole solve per direction)
SCENES = (("7-voussoir arch (t/R 0.15)", lambda: generators.semicircular_arch(n=7), 8),
          ("8 x 5 dome", lambda: generators.dome(slices=8, courses=5), 8),
          ("14 x 10 dome", generators.dome, 3))
OPTIONS = CheckOptions(margin_directions=8)


def row(name: str, prefer: str, scene, candidates: int = 8) -> tuple[str, float]:
    start = time.perf_counter()
    plan = plan_sequence(scene, 2, OPTIONS, prefer=prefer, candidates=candidates)
    took = time.perf_counter() - start
    w = plan.weakest
    weakest = f"{w.step_index} ({w.block_placed or 'release'}) | {w.margin_g:.4f}" \
        if w is not None else "- | -"
    hold_steps = sum(len(h) for h in plan.held)
    print(f"{name} {prefer}: {took:.1f} s, weakest {weakest}", flush=True)
    return (f"| {name} | {prefer} (--candidates {candidates}) | {plan.feasible} | {weakest} | {hold_steps} | "
            f"{plan.max_held} | {took:.1f} |", w.margin_g if w is not None else float("nan"))


def main() -> int:
    lines = ["# Planning for the largest margin", "",
             "Made by `make bench-prefer` (benchmarks/prefer_margin.py); machine: "
             f"{machine_summary()}.", "",
             "`rbe-ros plan SCENE --max-held 2 --margin` (prefer holds, the default) against "
             "`--prefer margin`: the weakest step (its index, block and margin in g, the "
             "smallest horizontal acceleration that topples or slides it over 8 directions) "
             "and the hold-steps (blocks held, summed over the steps). Times in one run.", "",
             "| scene | prefer | feasible | weakest step | weakest margin g | hold-steps | "
             "largest hold count | time s |", "|---|---|---|---|---|---|---|---|"]
    verdicts = []
    for name, make, candidates in SCENES:
        scene = make()
        default, m0 = row(name, "holds", scene)
        better, m1 = row(name, "margin", scene, candidates)
        lines += [default, better]
        verdicts.append(f"{name}: {m1:.4f} g against {m0:.4f} g: "
                        + ("met" if m1 >= m0 - 1e-9 else "NOT met"))
    lines += ["", "The weakest step's margin of --prefer margin at least the default's:", "",
              *[f"- {v}" for v in verdicts], ""]
    (ROOT / "docs" / "PREFER_MARGIN.md").write_text("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
