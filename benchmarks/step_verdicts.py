"""Per-step verdicts of two trees on the same scenes, and the processor time each took: the
oracle of a change that must alter no verdict, only the cost.

Each case is run by each tree in a process of its own (the tree's own package on
PYTHONPATH, as prestress_cost.py runs its old tree): ``check --sequence``'s statuses (the
default options, holds searched at failing steps), or one ``check`` for a scene without a
sequence. Cases: the generators' 14 x 10 dome, the thin one (t_base 0.25, t_oculus 0.125) at
mu 0.8, the 8 x 5 dome, the semicircular and buttressed arches, the keyed vault, issue 31's
10 x 8 dome, and every scene of the squeeze suite and its variants at its manifest's mu (a
sequence, and one check of the whole).

    python benchmarks/step_verdicts.py --tree PATH --out A.json [--only WORD ...]
    python benchmarks/step_verdicts.py --compare A.json B.json

``--compare`` prints the steps whose status differs (exit 1 if any) and the ratio of the
processor times, case by case (B / A), measured in the runs that wrote the files.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SQUEEZE = ROOT / "tests" / "data" / "squeeze"
#: Run in a tree: for each case (name, scene file, mu, whole) of the JSON list in argv[1],
#: the statuses (its sequence's, or one check's) and the processor time, one JSON line each.
RUNNER = """
import json, sys, time
from dataclasses import replace
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.pipeline import check_scene, check_sequence, slim
from rbe_ros.io.scene_json import load_scene
from rbe_ros.rbe.solver import SolveOptions
for name, path, mu, whole in json.loads(sys.argv[1]):
    scene = load_scene(path)
    options = replace(CheckOptions(), solve=SolveOptions(mu=mu))
    start = time.process_time()
    reports = [check_scene(scene, options)] if whole else check_sequence(scene, options,
                                                                          keep=slim)
    print(json.dumps({"name": name, "cpu": time.process_time() - start,
                      "statuses": [r.status.name for r in reports]}), flush=True)
"""


def cases(folder: Path):
    """(name, scene file, mu, whole: one check instead of the sequence)."""
    sys.path.insert(0, str(ROOT))
    from rbe_ros import generators as gen
    from rbe_ros.interlock import keyed_vault
    from rbe_ros.io.scene_json import scene_to_dict
    for name, scene, mu in (("dome 14x10", gen.dome(), 0.6),
                            ("dome 8x5", gen.dome(slices=8, courses=5), 0.6),
                            ("semicircular arch", gen.semicircular_arch(), 0.6),
                            ("buttressed arch", gen.buttressed_arch(), 0.6),
                            ("keyed vault", keyed_vault(), 0.6),
                            ("keyed vault 2 rings", keyed_vault(rings=2), 0.6)):
        path = folder / f"{name.replace(' ', '_')}.json"
        path.write_text(json.dumps(scene_to_dict(scene)))
        yield name, path, mu, False
        if name == "dome 8x5":
            yield ("issue31 dome10x8", ROOT / "tests" / "data" / "issue31" / "dome10x8.json",
                   0.6, False)
    for folder_ in (SQUEEZE, SQUEEZE / "variants"):
        for entry in json.loads((folder_ / "manifest.json").read_text())["scenes"]:
            for whole in (False, True):
                yield (f"{entry['name']}{' whole' if whole else ''}", folder_ / entry["file"],
                       entry["mu"], whole)
    path = folder / "thin_dome.json"       # the longest last
    path.write_text(json.dumps(scene_to_dict(gen.dome(t_base=0.25, t_oculus=0.125))))
    yield "thin dome 14x10", path, 0.8, False


def run(tree: Path, todo: list, out: dict, path: Path) -> None:
    """Run ``todo`` in ``tree`` (one process: the imports once), adding to ``out`` and
    writing it to ``path`` as each case ends."""
    proc = subprocess.Popen([str(ROOT / ".venv" / "bin" / "python"), "-c", RUNNER,
                             json.dumps([[n, str(p), mu, whole] for n, p, mu, whole in todo])],
                            stdout=subprocess.PIPE, text=True, cwd=tree,
                            env=os.environ | {"PYTHONPATH": str(tree)})
    for line in proc.stdout:
        result = json.loads(line)
        out[result.pop("name")] = result
        print(list(out)[-1], f"{result['cpu']:.2f} s", flush=True)
        path.write_text(json.dumps(out, indent=1))
    proc.wait()


def compare(a: dict, b: dict) -> int:
    differ = 0
    total = [0.0, 0.0]
    for name in a:
        if name not in b:
            continue
        sa, sb = a[name].get("statuses"), b[name].get("statuses")
        steps = [k for k, (x, y) in enumerate(zip(sa or [], sb or [])) if x != y]
        if sa is None or sb is None or len(sa) != len(sb) or steps:
            differ += 1
            print(f"DIFFER {name}: steps {steps[:10]} "
                  f"{[(sa[k], sb[k]) for k in steps[:5]] if steps else (a[name], b[name])}")
        if "cpu" in a[name] and "cpu" in b[name]:
            total[0] += a[name]["cpu"]
            total[1] += b[name]["cpu"]
            if a[name]["cpu"] > 0.5:
                print(f"{name}: {a[name]['cpu']:.2f} s -> {b[name]['cpu']:.2f} s "
                      f"({b[name]['cpu'] / a[name]['cpu']:.2f}x), {len(sa)} steps")
    print(f"{len(set(a) & set(b))} cases, {differ} differ; processor time {total[0]:.1f} s -> "
          f"{total[1]:.1f} s")
    return 1 if differ else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", type=Path, help="a checkout of rbe_ros (its package is run)")
    parser.add_argument("--out", type=Path, help="where to write the statuses (JSON)")
    parser.add_argument("--only", nargs="*", default=(), help="cases whose name holds a word")
    parser.add_argument("--compare", nargs=2, type=Path, metavar=("A", "B"))
    args = parser.parse_args()
    if args.compare:
        return compare(*(json.loads(p.read_text()) for p in args.compare))
    out = {}
    with tempfile.TemporaryDirectory() as folder:
        todo = [case for case in cases(Path(folder))
                if not args.only or any(w in case[0] for w in args.only)]
        run(args.tree.resolve(), todo, out, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
