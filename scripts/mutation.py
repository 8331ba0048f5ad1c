"""The mutation score of the core: mutmut over rbe/, geometry/ and the verdict code.

    make mutation                     # all target modules, then docs/MUTATION.md
    .venv/bin/python scripts/mutation.py --module rbe_ros/rbe/cones.py [--module ...]
    .venv/bin/python scripts/mutation.py --report        # docs/MUTATION.md from the last runs

mutmut 3 (requirements/mutation.txt, which `make mutation` installs into .venv) works in a
scratch copy, out/mutation/ (rbe_ros/, tests/ and a pyproject.toml with its settings), so
the work tree is never touched; its results there are kept, and a rerun tests only what
changed. The targets are found when the run starts: every module of rbe_ros/rbe/ and
rbe_ros/geometry/, and the verdict code (rbe_ros/analysis/verdict.py, or check.py where the
verdict still lives). The fast test selection (FAST_TESTS less SLOW_TESTS) runs in-process
under mutmut's forks with the hypothesis profile ``mutation`` (10 examples a property);
mutmut runs, for each mutant, only the tests that reach its function, fastest first, up to
the first failure.

Equivalent mutants (no test can tell them from the original) are listed in
scripts/mutation_equivalent.txt, one ``name: reason`` a line; the score leaves them out.
"""
from __future__ import annotations

import argparse
import os
import random
import re
import shutil
import subprocess
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WORK = ROOT / "out" / "mutation"
DOC = ROOT / "docs" / "MUTATION.md"
EQUIVALENT = ROOT / "scripts" / "mutation_equivalent.txt"
SEED = 17
MUTMUT = Path(sys.executable).with_name("mutmut")

#: Tests that check answers of the core directly (no subprocess, no ROS, no bags): a few
#: seconds in all, so that a surviving mutant costs little.
FAST_TESTS = ("test_mass_properties.py", "test_oracles.py", "test_rbe_method.py",
              "test_check.py", "test_solver_results.py", "test_contacts.py",
              "test_validation.py", "test_holds.py", "test_paper.py", "test_generators.py",
              "test_properties.py", "test_core_units.py", "test_asbuilt.py")
#: Left out of the selection for speed (a surviving mutant runs every test that reaches it):
#: the slowest tests, which repeat what faster ones check (tilt bisections of the dome, the
#: brute-force hold searches, the invariance properties).
SLOW_TESTS = ("test_paper.py::test_dome_tilt_capacity_is_32_deg",
              "test_holds.py::test_minimal_holds_equal_brute_force",
              "test_properties.py::test_verdict_invariant_under_renaming_and_reordering",
              "test_properties.py::test_verdict_invariant_under_rigid_motion",
              "test_generators.py::test_dome_stands_under_self_weight",
              "test_generators.py::test_buttressed_arch_tilting_capacity_is_about_12_degrees")

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
    found += sorted(p for d in ("rbe", "geometry") for p in (pkg / d).glob("*.py")
                    if p.name != "__init__.py")
    return [str(p.relative_to(ROOT)) for p in found]


def prepare(modules: list[str]) -> None:
    """The scratch copy: current sources, tests and examples, and mutmut's settings."""
    WORK.mkdir(parents=True, exist_ok=True)
    for name in ("rbe_ros", "tests", "examples"):     # some tests read examples/
        shutil.copytree(ROOT / name, WORK / name, dirs_exist_ok=True,
                        ignore=shutil.ignore_patterns("__pycache__", "ros"))
    with open(WORK / "tests" / "conftest.py", "a") as f:
        f.write(CLEAR_CACHES)
    tests = [f"tests/{t}" for t in FAST_TESTS if (ROOT / "tests" / t).exists()]
    (WORK / "pyproject.toml").write_text(
        "[tool.mutmut]\n"
        'source_paths = ["rbe_ros"]\n'
        'also_copy = ["examples"]\n'
        f"only_mutate = {modules!r}\n".replace("'", '"')
        + f"pytest_add_cli_args_test_selection = {tests!r}\n".replace("'", '"')
        + "pytest_add_cli_args = "
        + str(["-p", "no:cacheprovider", "-q"]
              + [f"--deselect=tests/{t}" for t in SLOW_TESTS]).replace("'", '"') + "\n")


def run(modules: list[str], children: int, sample: float = 1.0) -> None:
    """mutmut over ``modules``, one module after another (results kept as each finishes);
    with ``sample`` < 1 over that share of each module's mutants, drawn with a fixed seed
    from those not run yet (mutant sampling: an unbiased estimate of the score)."""
    prepare(modules)
    env = {**os.environ, "HYPOTHESIS_PROFILE": "mutation", "OPENBLAS_NUM_THREADS": "1",
           "OMP_NUM_THREADS": "1"}
    mutmut = [str(MUTMUT), "run", "--max-children", str(children)]
    smallest = min(modules, key=lambda m: (ROOT / m).stat().st_size)
    if sample < 1.0 and not _module_names(smallest):   # the mutants are made by a first run
        subprocess.run(mutmut + [names_pattern(smallest)], cwd=WORK, env=env, check=False,
                       stdout=subprocess.DEVNULL)
    for module in modules:
        print(f"[mutation] {module}", flush=True)
        chosen = [names_pattern(module)]
        if sample < 1.0:
            todo = sorted(k for k, v in _module_names(module).items() if v == "not checked")
            chosen = random.Random(SEED).sample(todo, round(sample * len(todo)))
            if not chosen:
                continue
        subprocess.run(mutmut + chosen, cwd=WORK, env=env, check=False, stdout=subprocess.DEVNULL)


def names_pattern(module: str) -> str:
    return module[:-3].replace("/", ".") + ".*"


def _module_names(module: str) -> dict[str, str]:
    prefix = module[:-3].replace("/", ".") + "."
    try:
        return {k: v for k, v in results().items() if k.startswith(prefix)}
    except subprocess.CalledProcessError:
        return {}


def results() -> dict[str, str]:
    """mutant name -> status (killed, survived, no tests, timeout, ...) of every mutant."""
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
    """The mutated line of a mutant (its diff's + line)."""
    out = subprocess.run([str(MUTMUT), "show", name], cwd=WORK, text=True, capture_output=True).stdout
    plus = [ln[1:].strip() for ln in out.splitlines() if ln.startswith("+") and not ln.startswith("+++")]
    return plus[0] if plus else "?"


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


def report(modules: list[str]) -> tuple[int, int]:
    """Write docs/MUTATION.md; returns (killed, non-equivalent mutants)."""
    status = results()
    wanted = {m[:-3].replace("/", ".") for m in modules}
    status = {k: v for k, v in status.items() if module_of(k) in wanted}
    equiv = equivalents()
    counts: dict[str, Counter] = {}
    for name, s in status.items():
        kind = "equivalent" if name in equiv and s != "killed" else s
        counts.setdefault(module_of(name), Counter())[kind] += 1
    total = Counter()
    for c in counts.values():
        total.update(c)
    scored = sum(total.values()) - total["equivalent"] - total["not checked"]
    killed = total["killed"]
    lines = [
        "# Mutation score",
        "",
        "Generated by `make mutation` (`scripts/mutation.py`: mutmut 3 over the modules below, in",
        "a scratch copy, with the fast test selection "
        + ", ".join(f"`{t}`" for t in FAST_TESTS) + ").",
        "A mutant is killed when a test fails on it; `no tests` means no test of the selection",
        "reaches its function (counted as not killed); equivalent mutants",
        "(`scripts/mutation_equivalent.txt`) cannot be told from the original and are left out.",
        "",
        f"**Killed: {killed} of {scored} non-equivalent mutants ({100 * killed / max(scored, 1):.1f} %)**;"
        f" {total['equivalent']} equivalent"
        + (f"; {total['not checked']} not run yet (the run was cut short; left out)."
           if total["not checked"] else "."),
        "",
        "| module | mutants | killed | survived | no tests | timeout | equivalent | not run | score |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for mod in sorted(counts):
        c = counts[mod]
        n = sum(c.values())
        s = n - c["equivalent"] - c["not checked"]
        lines.append(f"| {mod} | {n} | {c['killed']} | {c['survived']} | {c['no tests']}"
                     f" | {c['timeout']} | {c['equivalent']} | {c['not checked']}"
                     f" | {100 * c['killed'] / max(s, 1):.1f} % |")
    open_ = sorted(k for k, v in status.items()
                   if v not in ("killed", "not checked") and k not in equiv)
    lines += ["", "## Not killed", "",
              "Each with its mutated line (`mutmut show NAME` in out/mutation/ gives the diff).", ""]
    lines += [f"- `{k}` ({status[k]}): `{diff_line(k)}`" for k in open_] or ["none"]
    lines += ["", "## Equivalent", ""]
    lines += [f"- `{k}`: {equiv[k]}" for k in sorted(equiv) if k in status and status[k] != "killed"] \
        or ["none"]
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
                        help="run this share of each module's mutants not run yet (seed 17)")
    args = parser.parse_args()
    modules = args.module or targets()
    if not args.report:
        run(modules, args.children, args.sample)
    killed, scored = report(targets())
    print(f"[mutation] killed {killed} of {scored} non-equivalent mutants"
          f" ({100 * killed / max(scored, 1):.1f} %): {DOC.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
