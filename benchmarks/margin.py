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
from dataclasses import replace
from pathlib import Path

import highspy
import numpy as np
import ray
import scipy.sparse as sp
import scs
from machine import machine_summary
from timing import best_of

from rbe_ros import generators as gen
from rbe_ros.analysis.executors import ProcessPool, ray_cluster
from rbe_ros.analysis.margin import horizontal_directions, stability_margin
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.perturb import PoseNoise
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.analysis.robust import RobustJob, estimate, serial
from rbe_ros.analysis.validate import validated_assembly
from rbe_ros.rbe.model import build_model
from rbe_ros.rbe.solver import LoadMultipliers, solve, solver_timing

ROOT = Path(__file__).resolve().parents[1]


def best(f, repeats: int) -> float:
    """The fastest of ``repeats`` runs of ``f``, in s (benchmarks/timing.py)."""
    return best_of(repeats, f)[1]


def best_in_solver(f, repeats: int) -> float:
    """The least time spent inside the conic solver over ``repeats`` calls of ``f``."""
    spent = []
    for _ in range(repeats):
        with solver_timing() as t:
            f()
        spent.append(t[0])
    return min(spent)


def margin_rows(repeats: int) -> tuple[list[str], float]:
    """The margin as rbe_ros computes it against one check, and against the plain method it
    replaced: every direction solved, each by a solver of its own (lambda form). Also the
    time inside the conic solver: the check's one solve against one direction's."""
    rows, floor = [], 0.0
    options = CheckOptions()
    for name, scene in (("dome 14x10 (140 blocks)", gen.dome()),
                        ("running-bond wall 20x14 (291 blocks)", gen.running_bond_wall(20, 14))):
        assembly = validated_assembly(scene, options.limits, options.contact)
        t_check = best(lambda: check_scene(scene, options), repeats)
        t_margin = best(lambda: stability_margin(assembly, options.solve), repeats)
        t_plain = best(lambda: _every_direction_alone(assembly, options.solve), repeats)
        in_check = best_in_solver(lambda: check_scene(scene, options), repeats)
        in_margin = best_in_solver(lambda: stability_margin(assembly, options.solve), repeats)
        margin = stability_margin(assembly, options.solve)
        solved = int(np.count_nonzero(~np.isnan(margin.per_direction)))
        rows.append(f"| {name} | {1e3 * t_check:.0f} | {1e3 * in_check:.0f} | "
                    f"{1e3 * t_margin:.0f} | {solved} of 8 | "
                    f"{1e3 * in_margin / solved:.0f} | **{t_margin / t_check:.1f}x** | "
                    f"{1e3 * t_plain:.0f} | {t_plain / t_check:.1f}x | "
                    f"{margin.margin_g:.4f} |")
        if name.startswith("dome"):                 # 8 solves of the solver alone
            floor = 8 * in_margin / solved / t_check
    return rows, floor


def _every_direction_alone(assembly, options) -> float:
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    g = float(np.linalg.norm(assembly.gravity))
    return min(solve(model, options, live_load=model.load(g * d)).multiplier
               for d in horizontal_directions(assembly.gravity))


def alternative_rows(directions: int = 3) -> list[str]:
    """Methods that keep more than the ordering from one direction to the next, tried on the
    dome's first directions: HiGHS's dual simplex kept warm across right-hand sides on the
    pyramid4 LP, and SCS (first order, its factorisation kept) warm-started, on the exact
    cone; rbe_ros' LoadMultipliers on the same problems for the values and times."""
    scene, options = gen.dome(), CheckOptions()
    assembly = validated_assembly(scene, options.limits, options.contact)
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    g = float(np.linalg.norm(assembly.gravity))
    loads = [model.load(g * d) for d in horizontal_directions(assembly.gravity)][:directions]
    rows = []
    for label, cone, run in (("HiGHS dual simplex, warm (pyramid4 LP)", "pyramid4", _highs),
                             ("SCS, warm start, factorisation kept (exact cone)", "soc", _scs)):
        mu = options.solve.mu
        ours = LoadMultipliers(model, replace(options.solve, cone=cone))
        start = time.perf_counter()
        reference = [ours(p).multiplier for p in loads]
        t_ours = (time.perf_counter() - start) / directions
        for k, (lam, seconds, iterations) in enumerate(run(model, mu, loads)):
            rows.append(f"| {label} | {k + 1} | {lam:.4f} | {reference[k]:.4f} | "
                        f"{iterations} | {1e3 * seconds:.0f} | {1e3 * t_ours:.0f} |")
    return rows


def _s_form_equilibrium(model) -> sp.csc_matrix:
    """The equilibrium rows of min s: A_eq f' + s p_dead = -p_live, over fn, fu, fv
    (friction-net, fn- left out) and s."""
    nv = model.num_vertices
    a_eq = sp.csc_matrix(model.a_eq)
    return sp.hstack([a_eq[:, :nv], a_eq[:, 2 * nv:],
                      sp.csc_matrix(model.dead_load[:, None])]).tocsc()


def _highs(model, mu, loads):
    nv, inf = model.num_vertices, highspy.kHighsInf
    eye = sp.identity(nv, format="csc")
    zero = sp.csc_matrix((nv, 1))
    facets = sp.vstack([sp.hstack([-mu * eye, sign * eye, 0 * eye, zero]) for sign in (1, -1)]
                       + [sp.hstack([-mu * eye, 0 * eye, sign * eye, zero]) for sign in (1, -1)])
    equilibrium = _s_form_equilibrium(model)
    a = sp.vstack([equilibrium, facets]).tocsc()
    neq = equilibrium.shape[0]
    lp = highspy.HighsLp()
    lp.num_col_, lp.num_row_ = a.shape[1], a.shape[0]
    lp.col_cost_ = np.r_[np.zeros(3 * nv), 1.0]
    lp.col_lower_ = np.r_[np.zeros(nv), np.full(2 * nv, -inf), 1e-3]
    lp.col_upper_ = np.full(a.shape[1], inf)
    lp.row_lower_ = np.r_[-loads[0], np.full(4 * nv, -inf)]
    lp.row_upper_ = np.r_[-loads[0], np.zeros(4 * nv)]
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_, lp.a_matrix_.index_, lp.a_matrix_.value_ = a.indptr, a.indices, a.data
    highs = highspy.Highs()
    highs.setOptionValue("output_flag", False)
    highs.setOptionValue("solver", "simplex")
    highs.passModel(lp)
    for k, p in enumerate(loads):
        start = time.perf_counter()
        if k:
            highs.changeRowsBounds(neq, np.arange(neq, dtype=np.int32), -p, -p)
        highs.run()
        info = highs.getInfo()
        yield (1.0 / info.objective_function_value, time.perf_counter() - start,
               info.simplex_iteration_count)


def _scs(model, mu, loads):
    nv = model.num_vertices
    equilibrium = _s_form_equilibrium(model)
    rows = []                 # (mu fn, fu, fv) in the second-order cone: slack = -A x, b = 0
    for i in range(nv):
        rows += [(3 * i, i, -mu), (3 * i + 1, nv + i, -1.0), (3 * i + 2, 2 * nv + i, -1.0)]
    r, c, v = map(np.array, zip(*rows))
    cones = sp.csc_matrix((v, (r, c)), shape=(3 * nv, 3 * nv + 1))
    bound = sp.csc_matrix(([-1.0], ([0], [3 * nv])), shape=(1, 3 * nv + 1))
    a = sp.vstack([equilibrium, bound, cones]).tocsc()
    neq = equilibrium.shape[0]
    b = np.r_[-loads[0], -1e-3, np.zeros(3 * nv)]
    solver = scs.SCS(dict(A=a, b=b, c=np.r_[np.zeros(3 * nv), 1.0]),
                     dict(z=neq, l=1, q=[3] * nv), eps_abs=1e-5, eps_rel=1e-5, verbose=False,
                     max_iters=100_000)
    solution = None
    for p in loads:
        start = time.perf_counter()
        b[:neq] = -p
        solver.update(b=b)
        solution = (solver.solve() if solution is None else
                    solver.solve(warm_start=True, x=solution["x"], y=solution["y"],
                                 s=solution["s"]))
        yield (1.0 / solution["x"][-1], time.perf_counter() - start, solution["info"]["iter"])


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
    margin, floor = margin_rows(args.repeats)
    alternatives = alternative_rows()
    throughput = throughput_rows(args.samples, args.repeats)
    text = "\n".join([
        "# Stability margin and Monte Carlo throughput", "",
        "Made by `make bench-margin` (`benchmarks/margin.py`; also run by `make bench`). "
        "Ratios measured in one run, each time the best of "
        f"{args.repeats}, on a shared machine.", "",
        "Machine: " + machine_summary() + f"; load average {load:.1f} at the start (the "
        "worker processes compete with it: on a busy 2-core machine the pool cannot gain).", "",
        "## margin_g over 8 directions against one check", "",
        "One check: `check_scene` (validation, contacts, solve, resultants). The margin: "
        "`stability_margin` on the assembly, contacts already detected: one Clarabel solver for "
        "every direction (the load-multiplier problem with s = 1 / lambda, where directions "
        "differ only in the right-hand side), and directions the convex hull of the solved "
        "points proves no smaller than the minimum left out. Beside it, the plain method it "
        "replaced: each of the 8 directions solved by a solver of its own.", "",
        "| scene | check ms | its solve ms | margin ms | directions solved | solve ms per "
        "direction | margin / check | every direction alone ms | alone / check | margin_g |",
        "|---|---|---|---|---|---|---|---|---|---|", *margin, "",
        "Issue 13 asks for at most 3x: met by the wall, which needs its four axis directions "
        "only (the hull of (0.6, 0), (0, 0.1), (-0.6, 0), (0, -0.1) reaches 0.12 on the "
        "diagonals, above the minimum 0.1). Not met by the dome, and not within reach of a "
        "method that solves each needed direction: its margins differ by less than 0.2% "
        "between directions, so every direction is needed (points on a near-circle bound the "
        "directions between them at 0.71 of their radius), and one direction's solve costs "
        "more than the check's own (the columns 'its solve' and 'solve per direction': a "
        "load-multiplier problem, an LP objective on the cones, takes more interior-point "
        "iterations than the check's QP, each factorising the same equilibrium rows). The "
        f"solver time of the eight directions alone is {floor:.1f} checks.", "",
        "### Methods that keep more than the ordering across directions", "",
        "The dome's first directions (`alternative_rows`); rbe_ros' value and time per "
        "direction beside each (LoadMultipliers on the same cone).", "",
        "| method | direction | lambda | rbe_ros lambda | iterations | ms | rbe_ros ms |",
        "|---|---|---|---|---|---|---|", *alternatives, "",
        "A warm dual simplex needs thousands of pivots per direction on this degenerate LP, "
        "and SCS thousands of iterations at 1e-5: both far slower than an interior-point "
        "solve per direction.", "",
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
