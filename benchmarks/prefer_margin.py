#!/usr/bin/env python3
"""`rbe-ros plan --prefer margin` against the default (--prefer holds) on the 7-voussoir arch
and the 8 x 5 and 14 x 10 domes (--max-held 2, every step's margin over 8 directions): the
weakest step (index, block, margin) and the hold-steps of both plans, their times in one run
(section "margin"). Section "robust": --prefer margin with and without --robust N on scenes
with a declared pose uncertainty, each plan's weakest p_stable by `robust --sequence` of it.
Section "lazy": the children of --prefer margin ranked lazily (this tree) against scoring every
one (the commit before, BEFORE, unpacked by git archive), each in its own process, in one run.
Writes docs/PREFER_MARGIN.md; a section run alone replaces only its part of the file.

Usage: .venv/bin/python benchmarks/prefer_margin.py [--quick] [margin] [robust] [lazy]
       (make bench-prefer: all three; the margin section takes most of an hour, with --quick
       without the 14 x 10 dome)
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(1, str(ROOT / "tests"))

from machine import machine_summary  # noqa: E402
from rbe_ros import generators  # noqa: E402
from rbe_ros.analysis.options import CheckOptions  # noqa: E402
from rbe_ros.analysis.perturb import PoseNoise  # noqa: E402
from rbe_ros.analysis.planning import plan_sequence  # noqa: E402
from rbe_ros.analysis.robust import DECLARED_SIGMAS, RobustJob, estimate  # noqa: E402

from helpers import ledge  # noqa: E402

DOC = ROOT / "docs" / "PREFER_MARGIN.md"
#: The commit whose --prefer margin scored every feasible child before sorting.
BEFORE = "051aa55"

#: (name, scene, candidates tried per step by --prefer margin: each feasible one costs its
#: margin, about one whole solve per direction)
SCENES = (("7-voussoir arch (t/R 0.15)", lambda: generators.semicircular_arch(n=7), 8),
          ("8 x 5 dome", lambda: generators.dome(slices=8, courses=5), 8),
          ("14 x 10 dome", generators.dome, 3))
OPTIONS = CheckOptions(margin_directions=8)
#: Samples of --robust, and the declared pose uncertainty of the robust section (m, deg).
SAMPLES = 32
UNCERTAINTY = (0.006, 1.5)


def row(name: str, prefer: str, scene, candidates: int = 8) -> tuple[str, float]:
    start = time.perf_counter()
    plan = plan_sequence(scene, 2, OPTIONS, prefer=prefer, candidates=candidates)
    took = time.perf_counter() - start
    w = plan.weakest
    weakest = f"{w.step_index} ({w.block_placed or 'release'}) | {w.margin_g:.4f}" \
        if w is not None else "- | -"
    hold_steps = sum(len(h) for h in plan.held)
    print(f"{name} {prefer}: {took:.1f} s, weakest {weakest}", flush=True)
    return (f"| {name} | {prefer} (--candidates {candidates}) | {plan.feasible} | {weakest} | "
            f"{hold_steps} | {plan.max_held} | {took:.1f} |",
            w.margin_g if w is not None else float("nan"))


def margin_section(quick: bool = False) -> str:
    scenes = SCENES[:2] if quick else SCENES
    lines = ["# Planning for the largest margin", "",
             "Made by `make bench-prefer` (benchmarks/prefer_margin.py"
             + (" margin --quick: without the 14 x 10 dome" if quick else "") + "); machine: "
             f"{machine_summary()}; load average {os.getloadavg()[0]:.1f} at the start.", "",
             "`rbe-ros plan SCENE --max-held 2 --margin` (prefer holds, the default) against "
             "`--prefer margin`: the weakest step (its index, block and margin in g, the "
             "smallest horizontal acceleration that topples or slides it over 8 directions) "
             "and the hold-steps (blocks held, summed over the steps). Times in one run.", "",
             "| scene | prefer | feasible | weakest step | weakest margin g | hold-steps | "
             "largest hold count | time s |", "|---|---|---|---|---|---|---|---|"]
    verdicts = []
    for name, make, candidates in scenes:
        scene = make()
        default, m0 = row(name, "holds", scene)
        better, m1 = row(name, "margin", scene, candidates)
        lines += [default, better]
        verdicts.append(f"{name}: {m1:.4f} g against {m0:.4f} g: "
                        + ("met" if m1 >= m0 - 1e-9 else "NOT met"))
    return "\n".join([*lines, "", f"Load average {os.getloadavg()[0]:.1f} at the end.", "",
                      "The weakest step's margin of --prefer margin at least the default's:",
                      "", *[f"- {v}" for v in verdicts], ""])


def robust_section() -> str:
    m, deg = UNCERTAINTY
    options = replace(OPTIONS, contact=replace(OPTIONS.contact, pose_uncertainty_m=m,
                                               pose_uncertainty_deg=deg))
    noise = PoseNoise(m / DECLARED_SIGMAS, deg / DECLARED_SIGMAS)
    lines = ["## --robust N", "",
             f"`rbe-ros plan SCENE --max-held 2 --prefer margin [--robust {SAMPLES}] "
             f"--pose-uncertainty-m {m} --pose-uncertainty-deg {deg}` (noise sigma a third of "
             "it): the weakest step by margin and by p_stable (each plan's steps re-estimated "
             f"by `rbe-ros robust --sequence --samples {SAMPLES}` of the planned scene, the "
             "same samples), the order, the time in one run. The ledge: tests/helpers.py's.", "",
             "| scene | ranked by | order | weakest margin g (step) | weakest p_stable (step) "
             "| time s |", "|---|---|---|---|---|---|"]
    for name, scene in (("ledge", ledge()),
                        ("7-voussoir arch (t/R 0.15)", generators.semicircular_arch(n=7))):
        for robust in (0, SAMPLES):
            start = time.perf_counter()
            plan = plan_sequence(scene, 2, options, prefer="margin", robust=robust)
            took = time.perf_counter() - start
            steps = estimate(RobustJob(plan.scene, noise, 0, options, True), SAMPLES).steps
            weak = min(steps, key=lambda s: s["p_stable"])
            w = plan.weakest
            ranked = f"p_stable ({robust} samples), margin" if robust else "margin"
            lines.append(f"| {name} | {ranked} | {', '.join(plan.order)} | {w.margin_g:.4f} "
                         f"({w.step_index}) | {weak['p_stable']:.3f} ({weak['step']}) | "
                         f"{took:.1f} |")
            print(lines[-1], flush=True)
    return "\n".join([*lines, ""])


LAZY_SCENES = {"7-voussoir arch": (lambda: generators.semicircular_arch(n=7), 8),
               "8 x 5 dome": (lambda: generators.dome(slices=8, courses=5), 8)}


def lazy_one(tree: str, scene: str) -> None:
    """In a child process: plan ``scene`` with the package of ``tree``; one JSON line."""
    sys.path.insert(0, tree)
    for name in [n for n in sys.modules if n == "rbe_ros" or n.startswith("rbe_ros.")]:
        del sys.modules[name]
    from rbe_ros import generators as g  # noqa: F401  (the tree's own)
    from rbe_ros.analysis.planning import plan_sequence as plan_of
    make, candidates = LAZY_SCENES[scene]
    start = time.perf_counter()
    plan = plan_of(make(), 2, OPTIONS, prefer="margin", candidates=candidates)
    print(json.dumps({"time": time.perf_counter() - start, "order": plan.order,
                      "held": [list(h) for h in plan.held], "states": plan.states,
                      "checks": plan.checks, "weakest": plan.weakest.margin_g}))


def lazy_section() -> str:
    with tempfile.TemporaryDirectory() as before:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", BEFORE, "rbe_ros"],
                                 check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", before], input=archive, check=True)
        lines = ["## Ranking lazily", "",
                 "`--prefer margin --candidates 8` ranked lazily (after: a child's trial, "
                 "margin and p_stable made only when it could still come first, "
                 "planning.py's _best_first) against scoring every feasible child, then "
                 f"sorting (before: commit {BEFORE}); each in its own process, in one run "
                 f"(load average at its start {os.getloadavg()[0]:.1f}).", "",
                 "| scene | before s | after s | after / before | same plan | states before "
                 "/ after | checks before / after |", "|---|---|---|---|---|---|---|"]
        for scene in LAZY_SCENES:
            runs = {}
            for label, tree in (("before", before), ("after", str(ROOT))):
                out = subprocess.run([sys.executable, __file__, "--lazy-one", tree, scene],
                                     check=True, capture_output=True, text=True).stdout
                runs[label] = json.loads(out.strip().splitlines()[-1])
                print(scene, label, runs[label]["time"], flush=True)
            b, a = runs["before"], runs["after"]
            same = all(b[k] == a[k] for k in ("order", "held", "weakest"))
            lines.append(f"| {scene} | {b['time']:.1f} | {a['time']:.1f} | "
                         f"{a['time'] / b['time']:.2f} | {same} | {b['states']} / "
                         f"{a['states']} | {b['checks']} / {a['checks']} |")
    return "\n".join([*lines, ""])


SECTIONS = {"margin": margin_section, "robust": robust_section, "lazy": lazy_section}


def write(name: str, text: str) -> None:
    """Replace section ``name`` of the doc (margin: the part before the first "## ")."""
    doc = DOC.read_text() if DOC.exists() else ""
    parts = re.split(r"(?m)^(?=## )", doc)
    head, rest = (parts[0], parts[1:]) if parts and not parts[0].startswith("## ") \
        else ("", parts)
    titles = {"robust": "## --robust N", "lazy": "## Ranking lazily"}
    head = (text if name == "margin" else head).rstrip() + "\n\n"
    if name != "margin":
        kept = [p for p in rest if not p.startswith(titles[name])]
        rest = [*kept, text.rstrip() + "\n\n"]
        rest.sort(key=lambda p: list(titles.values()).index(p.split("\n")[0])
                  if p.split("\n")[0] in titles.values() else -1)
    DOC.write_text((head + "".join(rest)).rstrip() + "\n")


def main(argv: list[str]) -> int:
    if argv[:1] == ["--lazy-one"]:
        lazy_one(*argv[1:3])
        return 0
    quick = "--quick" in argv
    for name in [a for a in argv if a != "--quick"] or list(SECTIONS):
        write(name, margin_section(quick) if name == "margin" else SECTIONS[name]())
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
