"""The mutation score of the core: mutmut over rbe/, geometry/ and the verdict code.

    make mutation                     # every mutant not run yet, then docs/MUTATION.md
    .venv/bin/python scripts/mutation.py --module rbe_ros/rbe/cones.py [--module ...]
    .venv/bin/python scripts/mutation.py --sample 0.1    # a fixed-seed sample of each module
    .venv/bin/python scripts/mutation.py --rerun         # the mutants not killed, again
    .venv/bin/python scripts/mutation.py --report        # docs/MUTATION.md from the last runs

mutmut 3 (requirements/mutation.txt, which `make mutation` installs into .venv) works in a
scratch copy, out/mutation/ (rbe_ros/, tests/ and a pyproject.toml with its settings), so
the work tree is never touched; its results there are kept, and a rerun tests only what
changed. The targets are found when the run starts: every module of rbe_ros/rbe/ and
rbe_ros/geometry/, and the verdict code (rbe_ros/analysis/verdict.py, or check.py where the
verdict still lives). mutmut is always told to mutate every target and a run picks its
mutants by name: a module left out of ``only_mutate`` is copied over its mutated file, which
then looks up to date to the next run (mutmut compares mtimes) and runs none of its mutants.
The fast test selection (FAST_TESTS less SLOW_TESTS) runs in-process
under mutmut's forks with the hypothesis profile ``mutation`` (10 examples a property);
mutmut runs, for each mutant, only the tests that reached its function in the clean run
(so geometry mutants run the tests that build geometry, the verdict's the tests that check),
fastest first, up to the first failure. Each run's output goes to out/mutation/mutmut.log and
its size, wall time and rate to out/mutation/runs.json (the table of runs in the report).

Equivalent mutants (no test can tell them from the original) are listed in
scripts/mutation_equivalent.txt, one ``name: reason`` a line; the score leaves them out.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import random
import re
import shutil
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WORK = ROOT / "out" / "mutation"
DOC = ROOT / "docs" / "MUTATION.md"
EQUIVALENT = ROOT / "scripts" / "mutation_equivalent.txt"
LOG = WORK / "mutmut.log"
RUNS = WORK / "runs.json"
SEED = 17
MUTMUT = Path(sys.executable).with_name("mutmut")

#: Tests that check answers of the core directly (no subprocess, no ROS, no bags): about 15 s
#: in all, so that a surviving mutant costs little.
FAST_TESTS = ("test_mass_properties.py", "test_oracles.py", "test_rbe_method.py",
              "test_check.py", "test_solver_results.py", "test_contacts.py",
              "test_validation.py", "test_holds.py", "test_paper.py", "test_generators.py",
              "test_properties.py", "test_core_units.py", "test_asbuilt.py",
              "test_bounded_checks.py", "test_geometry_oracles.py", "test_rbe_oracles.py")
#: Left out of the selection: the slowest tests, which repeat what faster ones check (tilt
#: bisections of the dome, the brute-force hold searches, the invariance properties), since a
#: surviving mutant runs every test that reaches it; and the time bounds, which measure the
#: machine (two mutants at a time, niced) rather than the answer.
SLOW_TESTS = ("test_paper.py::test_dome_tilt_capacity_is_32_deg",
              "test_holds.py::test_minimal_holds_equal_brute_force",
              "test_properties.py::test_verdict_invariant_under_renaming_and_reordering",
              "test_properties.py::test_verdict_invariant_under_rigid_motion",
              "test_generators.py::test_dome_stands_under_self_weight",
              "test_generators.py::test_buttressed_arch_tilting_capacity_is_about_12_degrees",
              "test_bounded_checks.py::test_a_10000_vertex_convex_mesh_is_checked_in_under_2_s",
              "test_bounded_checks.py::test_a_time_limit_bounds_the_geometry_stage",
              "test_bounded_checks.py::test_a_time_limit_bounds_each_step_of_a_sequence")

#: Appended to the scratch copy's tests/conftest.py: mutmut forks every mutant from a process
#: whose caches its first run of the tests filled (rbe_ros.geometry.block._shape), and a
#: mutated function behind a cache would never run.
CLEAR_CACHES = """

import sys as _sys

import pytest as _pytest


@_pytest.fixture(autouse=True)
def _clear_rbe_ros_caches():
    for name, module in list(_sys.modules.items()):
        if name.startswith("rbe_ros"):
            for value in list(vars(module).values()):
                if callable(getattr(value, "cache_clear", None)):
                    value.cache_clear()
"""


def targets() -> list[str]:
    """The modules to mutate, as they are in this tree now, in the order they are run: the
    verdict, then rbe/, then geometry/ (a run cut short has scored the verdict first)."""
    pkg = ROOT / "rbe_ros"
    verdict = pkg / "analysis" / "verdict.py"
    found = [verdict if verdict.exists() else pkg / "analysis" / "check.py"]
    for d in ("rbe", "geometry"):
        found += sorted(p for p in (pkg / d).glob("*.py") if p.name != "__init__.py")
    return [str(p.relative_to(ROOT)) for p in found]


def prepare() -> None:
    """The scratch copy: current sources, tests and examples, and mutmut's settings."""
    WORK.mkdir(parents=True, exist_ok=True)
    for name in ("rbe_ros", "tests", "examples"):     # some tests read examples/
        shutil.copytree(ROOT / name, WORK / name, dirs_exist_ok=True,
                        ignore=shutil.ignore_patterns("__pycache__", "ros"))
    with open(WORK / "tests" / "conftest.py", "a") as f:
        f.write(CLEAR_CACHES)
    configure()


def configure() -> None:
    """mutmut's settings in the scratch copy: every target module, the test selection."""
    tests = [f"tests/{t}" for t in FAST_TESTS if (ROOT / "tests" / t).exists()]
    (WORK / "pyproject.toml").write_text(
        "[tool.mutmut]\n"
        'source_paths = ["rbe_ros"]\n'
        'also_copy = ["examples"]\n'
        f"only_mutate = {targets()!r}\n".replace("'", '"')
        + f"pytest_add_cli_args_test_selection = {tests!r}\n".replace("'", '"')
        + "pytest_add_cli_args = "
        + str(["-p", "no:cacheprovider", "-q"]
              + [f"--deselect=tests/{t}" for t in SLOW_TESTS]).replace("'", '"') + "\n")


def mutmut(args: list[str], what: str, children: int) -> None:
    """One ``mutmut run``: output appended to out/mutation/mutmut.log, its size and time to
    out/mutation/runs.json; a failed run (clean tests failing, say) stops here."""
    env = {**os.environ, "HYPOTHESIS_PROFILE": "mutation", "OPENBLAS_NUM_THREADS": "1",
           "OMP_NUM_THREADS": "1"}
    before = sum(v != "not checked" for v in results().values())
    date, start = time.strftime("%Y-%m-%d %H:%M"), time.monotonic()
    with open(LOG, "a") as log:
        log.write(f"\n=== mutmut run {what}\n")
        log.flush()
        done = subprocess.run([str(MUTMUT), "run", "--max-children", str(children), *args],
                              cwd=WORK, env=env, stdout=log, stderr=subprocess.STDOUT)
    seconds = time.monotonic() - start
    named = args and not any("*" in a for a in args)
    ran = len(args) if named else sum(v != "not checked" for v in results().values()) - before
    runs = json.loads(RUNS.read_text()) if RUNS.exists() else []
    runs.append({"date": date, "what": what, "children": children,
                 "mutants": ran, "seconds": round(seconds)})
    RUNS.write_text(json.dumps(runs, indent=1))
    if done.returncode:
        raise SystemExit(f"mutmut run {what} failed (exit {done.returncode}): see {LOG}")


def run(modules: list[str] | None, children: int, sample: float, rerun: bool) -> None:
    """mutmut over the mutants not run yet: all of them, those of ``modules``, or with
    ``sample`` < 1 that share of each module's mutants not run yet, drawn with a fixed seed
    (a stratified sample: an unbiased estimate of each module's score); with ``rerun`` the
    mutants run, not killed and not listed as equivalent, again (after new tests)."""
    prepare()
    if not results():                      # the mutants and the stats are made by a first run
        mutmut([names_pattern(min(targets(), key=lambda m: (ROOT / m).stat().st_size))],
               "(mutants made)", children)
    status = results()
    if rerun:
        equiv, wanted = equivalents(), {dotted(m) for m in modules or targets()}
        chosen = sorted(k for k, v in status.items() if v not in ("killed", "not checked")
                        and k not in equiv and module_of(k) in wanted)
        what = f"rerun of {len(chosen)} not killed"
    elif sample < 1.0:
        chosen = []
        for module in modules or targets():
            todo = sorted(k for k, v in status.items()
                          if module_of(k) == dotted(module) and v == "not checked")
            chosen += random.Random(f"{SEED}:{module}").sample(todo, math.ceil(sample * len(todo)))
        what = f"sample {sample:g} (seed {SEED})"
    elif modules:
        chosen = [k for k, v in status.items()
                  if v == "not checked" and module_of(k) in {dotted(m) for m in modules}]
        what = "modules " + ", ".join(modules)
    else:
        chosen, what = [], "all not run"
    if chosen or not (rerun or sample < 1.0 or modules):
        mutmut(chosen, what, children)


def dotted(module: str) -> str:
    return module[:-3].replace("/", ".")


def names_pattern(module: str) -> str:
    return dotted(module) + ".*"


def results() -> dict[str, str]:
    """mutant name -> status (killed, survived, no tests, timeout, ...) of every mutant;
    empty before the first run."""
    if not (WORK / "mutants").exists():
        return {}
    out = subprocess.run([str(MUTMUT), "results", "--all", "true"], cwd=WORK, text=True,
                         capture_output=True, check=True).stdout
    return {m.group(1): m.group(2) for m in re.finditer(r"^\s+(\S+): (.+)$", out, re.M)}


def equivalents() -> dict[str, str]:
    if not EQUIVALENT.exists():
        return {}
    pairs = (line.split(":", 1) for line in EQUIVALENT.read_text().splitlines()
             if line.strip() and not line.startswith("#"))
    return {k.strip(): v.strip() for k, v in pairs}


def diff_line(name: str) -> str:
    """The mutated line of a mutant: its diff's - and + lines (a line mutmut deleted: - only)."""
    done = subprocess.run([str(MUTMUT), "show", name], cwd=WORK, text=True, capture_output=True)
    if done.returncode:
        raise SystemExit(f"mutmut show {name} failed: {done.stderr.strip().splitlines()[-1:]}")
    lines = done.stdout.splitlines()
    minus = [ln[1:].strip() for ln in lines if ln.startswith("-") and not ln.startswith("---")]
    plus = [ln[1:].strip() for ln in lines if ln.startswith("+") and not ln.startswith("+++")]
    return " -> ".join("`" + " ".join(side) + "`" for side in (minus, plus) if side)


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The Wilson score interval (95 %) of a share k/n."""
    if not n:
        return 0.0, 1.0
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def machine() -> str:
    cpu = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo")
                if ln.startswith("model name")), platform.processor())
    return f"{os.cpu_count()} cores ({cpu}), Python {platform.python_version()}"


def _section(text: str, name: str) -> str | None:
    m = re.search(rf"<!-- {name} -->\n.*?<!-- /{name} -->\n", text, re.S)
    return m.group(0) if m else None


def replace_section(name: str, body: str, title: str = "Planted bugs") -> None:
    """Put ``body`` between the markers of section ``name`` of docs/MUTATION.md (appended
    under ``title`` if it is not there yet); the rest of the file is kept."""
    text = DOC.read_text() if DOC.exists() else "# Mutation score\n"
    block = f"<!-- {name} -->\n{body}\n<!-- /{name} -->\n"
    old = _section(text, name)
    text = text.replace(old, block) if old else text.rstrip("\n") + f"\n\n## {title}\n\n{block}"
    DOC.write_text(text)


def module_of(name: str) -> str:
    return name.rsplit(".", 1)[0]


def report() -> tuple[int, int]:
    """Write docs/MUTATION.md; returns (killed, non-equivalent mutants run)."""
    wanted = {dotted(m) for m in targets()}
    status = {k: v for k, v in results().items() if module_of(k) in wanted}
    equiv = equivalents()
    counts: dict[str, Counter] = {}
    for name, s in status.items():
        kind = "equivalent" if name in equiv and s not in ("killed", "not checked") else s
        counts.setdefault(module_of(name), Counter())[kind] += 1
    total = sum(counts.values(), Counter())
    scored = sum(total.values()) - total["equivalent"] - total["not checked"]
    killed = total["killed"]
    low, high = wilson(killed, scored)
    runs = json.loads(RUNS.read_text()) if RUNS.exists() else []
    lines = [
        "# Mutation score",
        "",
        "Generated by `make mutation` (`nice -n 19 .venv/bin/python scripts/mutation.py`: mutmut 3",
        "over the modules below, in a scratch copy, with the fast test selection "
        + ", ".join(f"`{t}`" for t in FAST_TESTS) + ", less its slowest tests"
        " (`SLOW_TESTS` in the script); each mutant runs only the tests that reach its function).",
        "A mutant is killed when a test fails on it; `no tests` means no test of the selection",
        "reaches its function (counted as not killed); equivalent mutants",
        "(`scripts/mutation_equivalent.txt`) cannot be told from the original and are left out.",
        "",
        f"**Killed: {killed} of {scored} non-equivalent mutants ({100 * killed / max(scored, 1):.1f} %)**;"
        f" {total['equivalent']} equivalent; "
        + (f"{total['not checked']} not run: the score is over the mutants run, Wilson 95 %"
           f" interval {100 * low:.1f}-{100 * high:.1f} %. A module with mutants not run was not"
           " run in full: a run cut short (mutmut runs the mutants with the fastest tests"
           " first), and a fixed-seed random share of its remaining mutants (`--sample`, seed"
           f" {SEED}; see the runs below)." if total["not checked"] else "every mutant run."),
        "",
        "| module | mutants | killed | survived | no tests | timeout | equivalent | not run | score |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for mod in sorted(counts):
        c = counts[mod]
        n = sum(c.values())
        s = n - c["equivalent"] - c["not checked"]
        score = f"{100 * c['killed'] / s:.1f} %" if s else "-"
        lines.append(f"| {mod} | {n} | {c['killed']} | {c['survived']} | {c['no tests']}"
                     f" | {c['timeout']} | {c['equivalent']} | {c['not checked']} | {score} |")
    lines += ["", f"Runs on {machine()}, {runs[-1]['children'] if runs else 2} mutants at a time,"
              " niced (`out/mutation/runs.json`):", "",
              "| date | run | mutants | wall s | mutants/s |", "|---|---|---|---|---|"]
    lines += [f"| {r['date']} | {r['what']} | {r['mutants']} | {r['seconds']}"
              f" | {r['mutants'] / max(r['seconds'], 1):.2f} |" for r in runs]
    open_ = sorted(k for k, v in status.items()
                   if v not in ("killed", "not checked") and k not in equiv)
    lines += ["", "## Not killed", "",
              "Each with its line before and after the mutation (`mutmut show NAME` in"
              " out/mutation/ gives the diff).", ""]
    lines += [f"- `{k}` ({status[k]}): {diff_line(k)}" for k in open_] or ["none"]
    lines += ["", "## Equivalent", ""]
    lines += [f"- `{k}`: {equiv[k]}" for k in sorted(equiv)
              if status.get(k, "killed") not in ("killed", "not checked")] or ["none"]
    planted = _section(DOC.read_text(), "planted-bugs") if DOC.exists() else None
    if planted:
        lines += ["", "## Planted bugs", "", planted.rstrip("\n")]
    DOC.write_text("\n".join(lines) + "\n")
    return killed, scored


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--module", action="append", help="only this module (repeatable)")
    parser.add_argument("--report", action="store_true", help="only write docs/MUTATION.md")
    parser.add_argument("--children", type=int, default=2, help="parallel mutant runs")
    parser.add_argument("--sample", type=float, default=1.0,
                        help=f"run this share of each module's mutants not run yet (seed {SEED})")
    parser.add_argument("--rerun", action="store_true",
                        help="run the mutants not killed again (after new tests)")
    args = parser.parse_args()
    if not args.report:
        run(args.module, args.children, args.sample, args.rerun)
    configure()
    killed, scored = report()
    print(f"[mutation] killed {killed} of {scored} non-equivalent mutants"
          f" ({100 * killed / max(scored, 1):.1f} %): {DOC.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
