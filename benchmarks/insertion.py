"""Cost of the insertion check against the stability check of each step: docs/INSERTION.md.

Per step of the 140-block dome's sequence and of a 1,000-block running-bond wall (every step,
in sequence order), the time of the step's stability check (``StepChecker.check``, as
``check_sequence`` makes it) and of the placed block's insertion (cone and swept path,
:func:`rbe_ros.analysis.insertion.block_insertion`), measured in the same loop so both see
the same load, in CPU time of this process (``time.process_time``: the machine is shared, and
wall time counts the other users' load). The bar of issue 22: insertion at most 0.5x the stability check.

    python benchmarks/insertion.py [--out docs]      (make bench-insertion, part of make bench)
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
from machine import machine_summary

from rbe_ros import generators as gen
from rbe_ros.analysis.incremental import StepChecker
from rbe_ros.analysis.insertion import block_insertion
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.steps import sequence_step, step_count
from rbe_ros.analysis.validate import validated_assembly

ROOT = Path(__file__).resolve().parents[1]


def step_times(scene, options: CheckOptions) -> tuple[np.ndarray, np.ndarray, int]:
    """(stability s, insertion s) per step, and the steps whose block is insertable."""
    full = validated_assembly(scene, options.limits, options.contact)
    checker = StepChecker(options, local=not options.full_solve)
    stability, insertion, insertable = [], [], 0
    for k in range(step_count(scene)):
        step = sequence_step(scene, k)
        assembly = full.subset(step.present, step.held)
        start = time.process_time()
        checker.check(assembly)
        middle = time.process_time()
        found = block_insertion(full, step.present, step.block, options)
        stability.append(middle - start)
        insertion.append(time.process_time() - middle)
        insertable += found.insertable
    return np.array(stability), np.array(insertion), insertable


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs")
    args = parser.parse_args(argv)
    rows = []
    for name, scene in (("dome 14x10 (140 blocks)", gen.dome()),
                        ("wall 40x25 running bond (1,020 blocks)",
                         gen.running_bond_wall(courses=40, bricks_per_course=25))):
        stability, insertion, insertable = step_times(scene, CheckOptions())
        ratio = insertion / stability
        rows.append(f"| {name} | {len(stability)} | {insertable} | {1e3 * stability.sum():.0f} "
                    f"| {1e3 * insertion.sum():.0f} | {insertion.sum() / stability.sum():.3f} "
                    f"| {np.median(ratio):.3f} | {np.percentile(ratio, 95):.3f} |")
        print(rows[-1], flush=True)
    load = os.getloadavg()[0]
    text = "\n".join([
        "# Insertion check: cost against the stability check",
        "",
        "Made by `python benchmarks/insertion.py` (`make bench-insertion`, part of `make bench`).",
        "Per step, in sequence order: the step's stability check (`StepChecker.check`, local",
        "models as `check_sequence` uses them) and the placed block's insertion (cone of its",
        "interface normals, swept path over twice its longest extent, python-fcl after a",
        "bounding-box broad phase), timed in the same loop in CPU time of the process. Bar",
        "(issue 22): insertion <= 0.5x. Step ratios are of single steps (a step whose stability",
        "check is answered locally in about a millisecond makes a large ratio of a small time).",
        "",
        "| sequence | steps | insertable | stability ms | insertion ms | total ratio "
        "| median step ratio | 95th pct step ratio |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
        *rows,
        "",
        f"Load average at the end of the run: {load:.1f} (a shared machine: ratios, not times).",
        "",
        machine_summary(),
        ""])
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "INSERTION.md").write_text(text)
    print(f"wrote {args.out / 'INSERTION.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
