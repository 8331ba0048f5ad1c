"""Cost of the stability margin and throughput of the Monte Carlo study: docs/MARGIN.md.

Every figure is a ratio measured in this one run, on this machine (the machine is shared, so
each time is the best of several repeats):

* margin_g over 8 directions against one check, on the 140-block dome and the 291-block wall
  (the bar of issue 13: at most 3x);
* Monte Carlo samples per second with 2 worker processes against one process (bar: >= 1.8x);
* the same study as Ray tasks on a local 2-CPU Ray instance against the pool (bar: within 20%).

    python benchmarks/margin.py [--samples N] [--repeats R]      (make bench-margin)
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import ray
from machine import machine_summary

from rbe_ros import generators as gen
from rbe_ros.analysis.executors import ProcessPool, ray_cluster
from rbe_ros.analysis.margin import stability_margin
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.perturb import PoseNoise
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.analysis.robust import RobustJob, estimate, serial
from rbe_ros.analysis.validate import validated_assembly

ROOT = Path(__file__).resolve().parents[1]


def best(f, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        f()
        times.append(time.perf_counter() - start)
    return min(times)


def margin_rows(repeats: int) -> list[str]:
    rows = []
    options = CheckOptions()
    for name, scene in (("dome 14x10 (140 blocks)", gen.dome()),
                        ("running-bond wall 20x14 (291 blocks)", gen.running_bond_wall(20, 14))):
        assembly = validated_assembly(scene, options.limits, options.contact)
        t_check = best(lambda: check_scene(scene, options), repeats)
        margin = stability_margin(assembly, options.solve)
        t_margin = best(lambda: stability_margin(assembly, options.solve), repeats)
        rows.append(f"| {name} | {1e3 * t_check:.0f} | {1e3 * t_margin:.0f} | "
                    f"{t_margin / t_check:.1f}x | {margin.margin_g:.4f} |")
    return rows


def throughput_rows(samples: int, repeats: int) -> list[str]:
    job = RobustJob(gen.two_blocks(shift=0.45), PoseNoise(0.02, 1.0), 1, CheckOptions())
    job_seq = RobustJob(gen.stack(6, height=0.3), PoseNoise(0.01, 1.0), 1, CheckOptions(), True)
    rows = []
    pool, on_ray = ProcessPool(2), ray_cluster(None, num_cpus=2)
    for j in (job, job_seq):                         # start the workers first
        for executor in (pool, on_ray):
            estimate(j, 8, executor, 4)
    for label, j in (("two blocks, whole", job), ("tower of 6, per step", job_seq)):
        t_one = best(lambda: estimate(j, samples, serial, 16), repeats)
        t_pool = best(lambda: estimate(j, samples, pool, 16), repeats)
        t_ray = best(lambda: estimate(j, samples, on_ray, 16), repeats)
        results = {estimate(j, samples, e, 16).p_stable for e in (serial, pool, on_ray)}
        rows.append(f"| {label} | {samples} | {samples / t_one:.0f} | {samples / t_pool:.0f} | "
                    f"{t_one / t_pool:.2f}x | {samples / t_ray:.0f} | {t_pool / t_ray:.2f} | "
                    f"{'yes' if len(results) == 1 else 'NO'} |")
    pool.close()
    ray.shutdown()
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=400)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    load = os.getloadavg()[0]
    margin = margin_rows(args.repeats)
    throughput = throughput_rows(args.samples, args.repeats)
    text = "\n".join([
        "# Stability margin and Monte Carlo throughput", "",
        "Made by `make bench-margin` (`benchmarks/margin.py`; also run by `make bench`). "
        "Ratios measured in one run, each time the best of "
        f"{args.repeats}, on a shared machine.", "",
        "Machine: " + machine_summary() + f"; load average {load:.1f} at the start (the "
        "worker processes compete with it: on a busy 2-core machine the pool cannot gain).", "",
        "## margin_g over 8 directions against one check", "",
        "One check: `check_scene` (validation, contacts, solve, resultants). The margin: 8 "
        "load-multiplier solves (Clarabel) on the assembly's model, contacts already detected.",
        "", "| scene | check ms | margin ms | ratio | margin_g |", "|---|---|---|---|---|",
        *margin, "",
        "Issue 13 asks for at most 3x. Not met: each direction is a conic solve about as costly "
        "as the check's own. Tried and dropped (rbe_ros/analysis/margin.py): HiGHS's dual "
        "simplex kept warm across directions (the directions differ only in the right-hand "
        "side, but the cold start on the dome's degenerate LP took over a minute), and cutting "
        "planes for the exact cone on that LP (they wander over degenerate faces).", "",
        "## Monte Carlo throughput (samples per second)", "",
        "In-process against a spawned pool of 2 worker processes and Ray tasks on a local "
        "2-CPU Ray instance (both started and warmed up before timing), batches of 16 samples; the p_stable of "
        "the three must be equal (seed per sample).", "",
        "| study | samples | 1 process /s | 2 workers /s | pool / one | Ray /s | Ray / pool | "
        "same p_stable |", "|---|---|---|---|---|---|---|---|", *throughput, "",
        "Bars of issue 13: pool / one >= 1.8, Ray / pool >= 0.8.", ""])
    out = ROOT / "docs" / "MARGIN.md"
    out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
