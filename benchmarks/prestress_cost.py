"""Cost of the prestress test (docs/METHOD.md, "Prestress") against the whole check.

For each assembly: the best of ``--repeats`` times of ``verdict.check`` (which runs the test
when the deciding field is stable) and of the test alone (``prestress.squeeze`` on that
field), in this one run; the added cost is check / (check - test). The machine is shared:
read the ratios, not the times.

    python benchmarks/prestress_cost.py [--repeats R]
"""
from __future__ import annotations

import argparse
import os

from timing import best_of

from rbe_ros import generators as gen
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.verdict import check
from rbe_ros.io.compas import compas_samples_dir, load_compas_assembly
from rbe_ros.rbe.model import build_model
from rbe_ros.rbe.prestress import squeeze, unopened
from rbe_ros.rbe.solver import SolveOptions, solve


def _held_dome() -> Assembly:
    """The 14 x 10 dome up to course 4, and four blocks of course 5, two of them held."""
    dome = gen.dome()
    course = {b.id: int(b.id[6:b.id.index("_")]) for b in dome.blocks if b.id.startswith("course")}
    present = {b.id for b in dome.blocks if course.get(b.id, 0) < 5}
    present |= {f"course5_slice{k:02d}" for k in range(4)}
    return Assembly.from_scene(dome).subset(present, held={"course5_slice00", "course5_slice01"})


def cases():
    yield "dome 14 x 10", Assembly.from_scene(gen.dome()), 0.6
    yield "running-bond wall 20 x 14", Assembly.from_scene(gen.running_bond_wall(20, 14)), 0.6
    yield "dome, 2 held in course 5", _held_dome(), 0.6
    samples = compas_samples_dir()
    for name, supports, mu in (("A", ["0", "1"], 0.84), ("type-a", ["0", "1"], 0.84),
                               ("bridge", ["0", "1"], 0.9), ("shelf", ["0"], 0.9)):
        if samples is not None:
            scene = load_compas_assembly(samples / f"{name}.json", supports=supports)
            yield f"compas_cra {name}", Assembly.from_scene(scene), mu


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    print("| assembly | blocks | closed interfaces | check | test | added | verdict |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for name, assembly, mu in cases():
        options = CheckOptions(solve=SolveOptions(mu=mu))
        model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
        field = solve(model, options.deciding)
        closed = int(unopened(model, mu).sum())
        t_check = best_of(args.repeats, lambda: check(assembly, options))[1]
        t_test = best_of(args.repeats, lambda: squeeze(model, options.deciding, field))[1]
        status = check(assembly, options).status.name
        print(f"| {name} | {len(assembly.blocks)} | {closed} of {len(model.interfaces)} |"
              f" {1e3 * t_check:.1f} ms | {1e3 * t_test:.2f} ms |"
              f" {t_check / max(t_check - t_test, 1e-9):.2f}x | {status} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
