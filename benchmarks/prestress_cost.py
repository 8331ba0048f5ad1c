"""Cost of the placement test (docs/METHOD.md, "Placement without pre-load") against the
check before any prestress test (670975d, run from a git worktree as plan_bench.py does).

For each assembly the best of ``--repeats`` times of ``verdict.check`` on the same assembly
(contacts detected before the clock starts) by this tree and by 670975d, alternating, in
this one run; each in a process of its own. The machine is shared: read the ratios, and
under load those of the processor time (the process's own, which waiting for a core does
not count) beside those of the wall-clock time.

    nice -n 10 python benchmarks/prestress_cost.py [--repeats R] [--also REV]

``--also REV`` times a third tree (a git revision, from a worktree as 670975d) in the same
alternation and adds its processor time's ratio to 670975d: a change's before and after in
one run.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from machine import machine_summary

from rbe_ros import generators as gen
from rbe_ros.interlock import keyed_vault
from rbe_ros.io.scene_json import scene_to_dict

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
BEFORE = "670975d"
VAULT = ROOT / "tests" / "data" / "compas_assembly" / "crossvault_assembly.json.gz"
#: Run in each tree: load the scene, detect contacts, time check (best of R), print JSON.
TIMER = """
import json, sys, time
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.verdict import check
from rbe_ros.geometry.contacts import ContactOptions
from rbe_ros.io.inputs import load_design
from rbe_ros.rbe.solver import SolveOptions
path, mu, repeats, accuracy = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
scene = load_design(path)
scene = scene[0] if isinstance(scene, tuple) else scene
contact = ContactOptions(pose_uncertainty_m=accuracy)
assembly = Assembly.from_scene(scene, contact)
options = CheckOptions(solve=SolveOptions(mu=mu), contact=contact)
best = cpu = None
for _ in range(repeats):
    start, start_cpu = time.perf_counter(), time.process_time()
    report = check(assembly, options)
    elapsed, used = time.perf_counter() - start, time.process_time() - start_cpu
    best = elapsed if best is None else min(best, elapsed)
    cpu = used if cpu is None else min(cpu, used)
print(json.dumps({"time": best, "cpu": cpu, "status": report.status.name,
                  "blocks": len(assembly.blocks), "interfaces": len(assembly.interfaces)}))
"""


def cases(folder: Path):
    """(name, scene file, mu, modelling accuracy in m): the generators' wall, arches, dome
    and barrel vault (keyed-vault -p rings=2: two rings in bond), the compas cross vault with its modelling accuracy declared (1 mm: every one of
    its stored interfaces found; the design tolerance misses the crown joint 11|12,
    tests/test_compas_files.py, and its two crown blocks then hang by friction alone)."""
    for name, scene in (("running-bond wall 20 x 14", gen.running_bond_wall(20, 14)),
                        ("semicircular arch", gen.semicircular_arch()),
                        ("buttressed arch", gen.buttressed_arch()),
                        ("dome 14 x 10", gen.dome()),
                        ("keyed barrel vault 2 rings", keyed_vault(rings=2))):
        path = folder / f"{name.split()[0]}-{name.split()[1]}.json"
        path.write_text(json.dumps(scene_to_dict(scene)))
        yield name, path, 0.6, 0.0
    yield "compas cross vault", VAULT, 0.84, 0.001


def timed(code: Path, path: Path, mu: float, repeats: int, accuracy: float) -> dict:
    proc = subprocess.run([sys.executable, "-c", TIMER, str(path), str(mu), str(repeats),
                           str(accuracy)],
                          capture_output=True, text=True, cwd=code,
                          env=os.environ | {"PYTHONPATH": str(code)})
    if proc.returncode != 0:
        raise SystemExit(f"{code}: {proc.stderr.strip().splitlines()[-1]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--also", metavar="REV", help="a third tree timed in the same run")
    args = parser.parse_args(argv)
    print(machine_summary())
    print(f"load average {os.getloadavg()[0]:.1f}")
    also = f" | processor time {args.also} | ratio" if args.also else ""
    print("| assembly | blocks | interfaces | before (670975d) | now | ratio | processor time"
          f" before | now | ratio{also} | verdict before | verdict now |")
    print("| --- " * (11 + 2 * bool(args.also)) + "|")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        trees = {BEFORE: tmp / "before"} | ({args.also: tmp / "also"} if args.also else {})
        for rev, where in trees.items():
            subprocess.run(["git", "worktree", "add", "--detach", "--force", str(where), rev],
                           cwd=ROOT, check=True, capture_output=True)
        try:
            for name, path, mu, accuracy in cases(tmp):
                old = timed(trees[BEFORE], path, mu, args.repeats, accuracy)
                third = timed(trees[args.also], path, mu, args.repeats, accuracy) \
                    if args.also else None
                new = timed(ROOT, path, mu, args.repeats, accuracy)
                extra = (f" {1e3 * third['cpu']:.1f} ms | {third['cpu'] / old['cpu']:.2f}x |"
                         if third else "")
                print(f"| {name} | {new['blocks']} | {new['interfaces']} |"
                      f" {1e3 * old['time']:.1f} ms | {1e3 * new['time']:.1f} ms |"
                      f" {new['time'] / old['time']:.2f}x | {1e3 * old['cpu']:.1f} ms |"
                      f" {1e3 * new['cpu']:.1f} ms | {new['cpu'] / old['cpu']:.2f}x |{extra}"
                      f" {old['status']} | {new['status']} |",
                      flush=True)
        finally:
            for where in trees.values():
                subprocess.run(["git", "worktree", "remove", "--force", str(where)], cwd=ROOT,
                               check=False, capture_output=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
