#!/usr/bin/env python3
"""The planner at scale (issue 23): `rbe-ros plan` of compas_assembly's 527-block dome
(496 blocks to place, --pose-uncertainty 0.005,2.5 --max-held 2) with its time, peak memory
and --json size, against the plan's own re-check (`rbe-ros check --sequence` of the planned
scene, in the same run); the paper's 14 x 10 dome planned by the incremental candidate checks
and with every trial checked whole (--full-candidates); --beam 2 against greedy.
Each run is a separate process (peak RSS from wait4). Writes the planner section of
docs/SCALING.md (the rest is benchmarks/scaling.py's).

Usage: .venv/bin/python benchmarks/plan_bench.py [--quick]   (make plan-bench; minutes)
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from machine import machine_summary  # noqa: E402
from rbe_ros import generators  # noqa: E402
from rbe_ros.io.scene_json import scene_to_dict  # noqa: E402

DOME527 = ROOT / "tests" / "data" / "compas_assembly" / "dome_assembly.json.gz"
UNCERTAIN = ["--pose-uncertainty", "0.005,2.5"]
#: The section of docs/SCALING.md this script owns, from this line to the end of the file.
MARK = "<!-- planner section: made by benchmarks/plan_bench.py (make plan-bench) -->"
#: Why the time bar is missed: what a step costs that no region settles.
LEVER = ("Each step of a held course (robots at its first and at its newest block) is "
         "a full check of the partial dome with the robots' grips: the RBE field (the "
         "report's forces and wrenches) and the prestress test's field without friction at "
         "the held blocks' closed contacts, two solves of the whole partial dome, whose cost "
         "grows with it; those steps are most of the time, one after the other. The "
         "look-ahead runs the next steps' checks on the workers while the search does the "
         "rest, so on 2 cores shared with the search the gain stays below 2.")
#: The issue's figures of the planner before (not re-run: 11 minutes and 10 GB).
TODAY_527 = "11.5 min (608 s of planning), 10.7 GB peak, 1.03 GB JSON (issue 23)"


#: The commit on which issue 23 was filed: the planner before it ("today's").
BEFORE = "670975d"


def run(args: list[str], code: Path = ROOT) -> dict:
    """`rbe-ros ARGS` in its own process (the package of ``code``): wall time, peak RSS,
    stdout size and JSON."""
    start = time.perf_counter()
    with tempfile.TemporaryFile() as out:
        proc = subprocess.Popen([sys.executable, "-m", "rbe_ros.cli", *args], stdout=out,
                                stderr=subprocess.DEVNULL, cwd=code,
                                env={**os.environ, "PYTHONPATH": str(code)})
        _pid, status, usage = os.wait4(proc.pid, 0)
        elapsed = time.perf_counter() - start
        size = out.tell()
        out.seek(0)
        text = out.read().decode()
    try:
        data = json.loads(text)
    except json.JSONDecodeError:
        data = None
    return {"time": elapsed, "rss_mb": usage.ru_maxrss / 1024, "bytes": size, "json": data,
            "status": os.waitstatus_to_exitcode(status)}


def plan(scene: Path, *extra: str, out: Path | None = None, code: Path = ROOT) -> dict:
    args = ["plan", str(scene), "--max-held", "2", "--json", *extra]
    return run(args + (["-o", str(out)] if out else []), code)


def checkout(commit: str, where: Path) -> Path:
    """A work tree of ``commit`` at ``where`` (this repository's history)."""
    subprocess.run(["git", "worktree", "add", "--detach", "--force", str(where), commit],
                   cwd=ROOT, check=True, capture_output=True)
    return where


def hold_steps(result: dict) -> tuple[int, int]:
    """(total hold-steps, largest hold count) of a plan's --json."""
    held = [len(s["held_blocks"]) for s in result["json"]["steps"]]
    return sum(held), max(held, default=0)


def same(a: dict, b: dict) -> bool:
    return (a["json"]["order"] == b["json"]["order"]
            and [s["held_blocks"] for s in a["json"]["steps"]]
            == [s["held_blocks"] for s in b["json"]["steps"]])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="the 14 x 10 dome and the arch only (no 527-block dome)")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="plan_bench_"))
    arch, dome = work / "arch.json", work / "dome.json"
    arch.write_text(json.dumps(scene_to_dict(generators.semicircular_arch(15))))
    dome.write_text(json.dumps(scene_to_dict(generators.dome())))
    load = os.getloadavg()
    lines = [MARK, "", "## Planning at scale", "",
             "Made by `benchmarks/plan_bench.py` (`make plan-bench`); every run a separate "
             "`rbe-ros plan ... --json` process, ratios measured in one run. Machine: "
             + machine_summary() + f"; load average at the start {load[0]:.1f} (shared).", ""]

    if not args.quick:
        planned = work / "planned527.json"
        big = plan(DOME527, *UNCERTAIN, out=planned)
        print(f"527-block dome: {big['time']:.1f} s, {big['rss_mb']:.0f} MB", flush=True)
        recheck = run(["check", str(planned), "--sequence", "--strict"])
        print(f"re-check: {recheck['time']:.1f} s ({recheck['status']})", flush=True)
        solved = run(["check", str(planned), "--sequence", "--strict", "--full-solve"])
        print(f"full-solve re-check: {solved['time']:.1f} s ({solved['status']})", flush=True)
        pool = plan(DOME527, *UNCERTAIN, "--workers", "2")
        print(f"pool: {pool['time']:.1f} s", flush=True)
        on_ray = plan(DOME527, *UNCERTAIN, "--workers", "2", "--ray", "local")
        print(f"ray: {on_ray['time']:.1f} s", flush=True)
        info = big["json"]
        lines += ["### compas_assembly's 527-block dome (496 blocks to place)", "",
                  "`rbe-ros plan dome_assembly.json.gz --pose-uncertainty 0.005,2.5 "
                  "--max-held 2 --json -o planned.json`, then `rbe-ros check planned.json "
                  "--sequence --strict` (the plan's own re-check, incremental as by default):", "",
                  "| run | time [s] | peak RSS [MB] | stdout [MB] | result |",
                  "|---|---|---|---|---|",
                  f"| plan | {big['time']:.1f} | {big['rss_mb']:.0f} | {big['bytes'] / 1e6:.2f} |"
                  f" {'feasible' if info['feasible'] else 'NOT feasible'}, "
                  f"{sum(hold_steps(big)[:1])} hold-steps, at most {hold_steps(big)[1]} held |",
                  f"| re-check (`check --sequence`) | {recheck['time']:.1f} | "
                  f"{recheck['rss_mb']:.0f} | {recheck['bytes'] / 1e6:.2f} | "
                  f"{'every step stable' if recheck['status'] == 0 else 'a step NOT stable'} |",
                  f"| re-check with full solves (`--full-solve`) | {solved['time']:.1f} | "
                  f"{solved['rss_mb']:.0f} | {solved['bytes'] / 1e6:.2f} | "
                  f"{'every step stable' if solved['status'] == 0 else 'a step NOT stable'} |",
                  "", f"Plan / re-check: **{big['time'] / recheck['time']:.2f}**. Candidate "
                  f"checks: {info['search_checks']}, answered by "
                  + ", ".join(f"{k} {v}" for k, v in sorted(info["models"].items()))
                  + f". The planner before, on the same command: {TODAY_527}.", "",
                  "Scaled out (`--workers 2`: the full checks of the next steps of a held "
                  "course on 2 spawned processes; `--ray local --workers 2`: as Ray tasks on a "
                  "new local 2-CPU instance, its start included; peak RSS of the planning "
                  "process, the workers apart):", "",
                  "| executor | time [s] | peak RSS [MB] | ratio to one process | "
                  "same order and holds |", "|---|---|---|---|---|"]
        for name, r in (("one process", big), ("pool, 2 workers", pool),
                        ("Ray, local 2 CPUs", on_ray)):
            lines.append(f"| {name} | {r['time']:.1f} | {r['rss_mb']:.0f} | "
                         f"{big['time'] / r['time']:.2f} | {'yes' if same(r, big) else 'NO'} |")
        lines += ["", f"Ray / pool: {on_ray['time'] / pool['time']:.2f}.", "",
                  "Issue 23's bars: " + "; ".join(
                      f"{what} {'met' if ok else 'NOT met'}" for what, ok in (
                          ("plan <= 60 s", big["time"] <= 60),
                          ("peak RSS <= 1.5 GB", big["rss_mb"] <= 1536),
                          ("--json < 20 MB", big["bytes"] < 20e6),
                          ("pool >= 1.6x one process", big["time"] / pool["time"] >= 1.6),
                          ("Ray within 20% of the pool", on_ray["time"] <= 1.2 * pool["time"]),
                          ("the same order and holds from all three",
                           same(pool, big) and same(on_ray, big)))) + ". "
                  + LEVER, ""]

    incremental = plan(dome)
    whole = plan(dome, "--full-candidates")
    try:
        before = plan(dome, code=checkout(BEFORE, work / "before"))
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(work / "before")],
                       cwd=ROOT, capture_output=True)
    print(f"14 x 10 dome: {incremental['time']:.1f} s, every trial whole "
          f"{whole['time']:.1f} s, the planner of {BEFORE} {before['time']:.1f} s", flush=True)
    lines += ["### The paper's 14 x 10 dome (126 blocks to place)", "",
              "| planner | time [s] | peak RSS [MB] | candidate checks |",
              "|---|---|---|---|"]
    for name, r in (("incremental (default)", incremental),
                    ("every trial whole (`--full-candidates`)", whole),
                    (f"the planner before issue 23 ({BEFORE})", before)):
        lines.append(f"| {name} | {r['time']:.1f} | {r['rss_mb']:.0f} | "
                     f"{r['json']['search_checks']} |")
    lines += ["", f"Ratios: **{before['time'] / incremental['time']:.1f}x** the planner "
              f"before (issue 23's bar: 5x), {whole['time'] / incremental['time']:.1f}x every "
              f"trial whole; the same order as before: "
              f"{'yes' if before['json']['order'] == incremental['json']['order'] else 'NO'}; "
              f"the same order and holds with every trial whole: "
              f"{'yes' if same(incremental, whole) else 'NO'}. The planner before had no "
              "prestress test (issue 24): beside a held block, a step now also asks for a "
              "field without friction on the contacts a squeeze could load.", ""]

    lines += ["### --beam 2 against greedy", "",
              "| scene | beam | time [s] | hold-steps | largest hold count |",
              "|---|---|---|---|---|"]
    # the 527-block dome's beam is not run: a beam of 2 cost 35 times greedy on the 14 x 10
    for name, path in (("semicircular arch, 15 voussoirs", arch), ("14 x 10 dome", dome)):
        for beam in (1, 2):
            r = plan(path, "--beam", str(beam))
            total, largest = hold_steps(r)
            lines.append(f"| {name} | {beam} | {r['time']:.1f} | {total} | {largest} |")
            print(lines[-1], flush=True)
    lines += ["", "The 527-block dome's `--beam 2` is not run: on the 14 x 10 dome it costs "
              "the time above against greedy (each partial plan looks for two feasible "
              "candidates, the second often a block that needs the full problem).", "",
              "Which candidate checks still need a full solve: those the incremental "
              "checks cannot settle from the partial plan's kept forces, as for a sequence "
              "(above): a ring that closes, and every set of held blocks that may stand: with "
              "holds a smaller model only proves a failure (a relaxation, the held blocks "
              "rigid), and a step that may stand is checked whole with the robots' grips, "
              "whose wrenches its report carries. While a course is open and held at its "
              "first and its newest block, each step releases the previous newest block: the "
              "open course then carries its weight into the lower courses at the friction "
              "limit, and no region short of most of the dome keeps the earlier forces "
              "admissible.", ""]
    lines[4] = lines[4].replace(" (shared).", f", at the end {os.getloadavg()[0]:.1f} (shared).")
    text = (ROOT / "docs" / "SCALING.md").read_text()
    head = text.split(MARK)[0].rstrip("\n")
    (ROOT / "docs" / "SCALING.md").write_text(head + "\n\n" + "\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
