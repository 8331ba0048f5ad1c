"""Plant the small, plausible bugs of issue 17 one at a time and name the tests that catch them.

    .venv/bin/python scripts/planted_bugs.py [--bug NAME ...]

Each bug is a text patch found by its text (not by file, so that moved modules are followed)
and applied to a scratch copy of rbe_ros/ and tests/ (never to the work tree); the test
selection of scripts/mutation.py (no bags, no ROS, no subprocess) runs on that copy with the
``ci`` hypothesis profile of ``make test``. The table goes into docs/MUTATION.md, between
the markers of its section "Planted bugs".
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mutation import DOC, FAST_TESTS, ROOT, replace_section

#: name: (what it does, original text, planted text)
BUGS = {
    "base-fitting-swapped": (
        "inner and outer base fitting swapped (virtual interfaces)",
        'np.argmin(r) if side == "inner" else np.argmax(r)',
        'np.argmax(r) if side == "inner" else np.argmin(r)'),
    "centroid-vertex-mean": (
        "block centroid taken as the mean of the vertices",
        "    volume, centroid = _volume_centroid(_centre_fans(vertices, ragged, centres))\n",
        "    volume, centroid = _volume_centroid(_centre_fans(vertices, ragged, centres))\n"
        "    centroid = vertices.mean(axis=0)\n"),
    "cone-0.9-mu": (
        "exact friction cone built with 0.9 mu",
        "for head in ([(fn, -options.mu)]",
        "for head in ([(fn, -0.9 * options.mu)]"),
    "tangential-sign": (
        "sign of one tangential axis flipped in the resultants",
        "tangential = fu[:, None] * model.u + fv[:, None] * model.v",
        "tangential = fu[:, None] * model.u - fv[:, None] * model.v"),
    "clip-drops-vertex": (
        "one vertex lost per polygon clip",
        "    keep = dx * dx + dy * dy > tol * tol                  # merge near duplicates, the closing too\n",
        "    keep = dx * dx + dy * dy > tol * tol                  # merge near duplicates, the closing too\n"
        "    keep[np.cumsum(cnt)[cnt > 0] - 1] = False\n"),
}
SECTION = "planted-bugs"


def plant(tree: Path, original: str, planted: str) -> str:
    """Apply one patch in ``tree``; returns the file it changed (relative)."""
    hits = [p for p in (tree / "rbe_ros").rglob("*.py") if original in p.read_text()]
    if len(hits) != 1 or hits[0].read_text().count(original) != 1:
        raise SystemExit(f"the text to patch must occur exactly once, found in {hits}: {original!r}")
    hits[0].write_text(hits[0].read_text().replace(original, planted))
    return str(hits[0].relative_to(tree))


def catching_tests(name: str) -> tuple[str, list[str]]:
    """The file patched and the tests of the selection that fail with bug ``name``."""
    _, original, planted = BUGS[name]
    with tempfile.TemporaryDirectory(prefix="rbe-planted-") as tmp:
        tree = Path(tmp)
        for d in ("rbe_ros", "tests"):
            shutil.copytree(ROOT / d, tree / d, ignore=shutil.ignore_patterns("__pycache__"))
        where = plant(tree, original, planted)
        tests = [f"tests/{t}" for t in FAST_TESTS if (tree / "tests" / t).exists()]
        env = {k: v for k, v in os.environ.items() if k != "HYPOTHESIS_PROFILE"}
        # python -m pytest puts the scratch copy first on sys.path: its rbe_ros is imported
        out = subprocess.run([sys.executable, "-m", "pytest", *tests, "-q", "-rf",
                              "-p", "no:cacheprovider"], cwd=tree, env=env, text=True,
                             capture_output=True).stdout
    return where, sorted(set(re.findall(r"^FAILED (\S+?)(?: - |$)", out, re.M)))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bug", action="append", choices=sorted(BUGS), help="only this bug")
    args = parser.parse_args()
    rows = ["| planted bug | file | tests that fail | e.g. |", "|---|---|---|---|"]
    missed = []
    for name in args.bug or BUGS:
        where, failed = catching_tests(name)
        print(f"[planted] {name}: {len(failed)} failing tests", flush=True)
        files = sorted({f.split("::")[0].removeprefix("tests/") for f in failed})
        example = ", ".join(f"`{f.split('::', 1)[1]}`" for f in failed[:2])
        rows.append(f"| {BUGS[name][0]} | `{where}` | {len(failed)} in {', '.join(files) or 'none'}"
                    f" | {example or 'NOT CAUGHT'} |")
        missed += [name] if not failed else []
    text = ["Each planted as a patch on a scratch copy by `scripts/planted_bugs.py`, with the test",
            "selection above (no bag replays) and the hypothesis profile of `make test`:", "", *rows]
    replace_section(SECTION, "\n".join(text))
    print(f"[planted] {DOC.relative_to(ROOT)}: {len(BUGS) - len(missed)} caught"
          + (f", not caught: {', '.join(missed)}" if missed else ""))
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
