"""As-built noise suite: verdicts and forces of perturbed poses against the design's.

Scenes that stand as designed with a clear margin (running-bond wall, two arches, the
140-block dome, a stack, a tower) get Gaussian pose noise (rbe_ros.analysis.perturb:
sigma per axis, rotation 0.05 deg per mm of sigma about a random axis), 50 samples per scene
and level with fixed seeds, and each noisy scene is checked under three contact rules:

* declared: the pose uncertainty declared as 3 sigma (the as-built rules);
* raised tolerance: the design rule (plane of one face, interpenetration beyond 1% of the
  size) with the distance tolerance raised to the same 6 sigma and the angle tolerance by the
  same 6 sigma of rotation: what a user could do before;
* defaults: today's defaults (0.001 of the size, 1 deg).

Agreement: the verdict (status) equals the design's. Force error: the largest difference of a
block pair's resultant (rbe_ros.analysis.perturb.resultant_error) over the free weight, on
the samples whose verdict agrees. Also the share of reports flagged verdict_sensitive and the
cost of design geometry now against the last commit without the as-built rules (BASE), each
timed in its own subprocess, alternately, in this run.

Writes docs/ASBUILT.md, its numbers (docs/ASBUILT.json) and docs/figures/asbuilt.png
(`make asbuilt`; about 15 minutes on 2 busy cores; --quick: 10 samples, out/asbuilt-quick/;
--render: the page again from the saved numbers).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tarfile
import tempfile
import time
from io import BytesIO
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from machine import machine_summary  # noqa: E402

from rbe_ros import generators as gen  # noqa: E402
from rbe_ros.analysis.asbuilt import sensitivity  # noqa: E402
from rbe_ros.analysis.options import CheckOptions, HoldSearch  # noqa: E402
from rbe_ros.analysis.perturb import PoseNoise, perturb_scene, resultant_error  # noqa: E402
from rbe_ros.analysis.pipeline import check_scene  # noqa: E402
from rbe_ros.analysis.validate import validated_assembly  # noqa: E402
from rbe_ros.analysis.verdict import check  # noqa: E402
from rbe_ros.geometry.block import pose_blocks  # noqa: E402
from rbe_ros.geometry.contacts import ContactOptions  # noqa: E402
from rbe_ros.scene import SceneError  # noqa: E402

SIGMAS_MM = (0.1, 0.25, 0.5, 1.0, 2.0)
DEG_PER_MM = 0.05
DECLARED_SIGMAS = 3.0
RULES = ("declared", "raised tolerance", "defaults")
#: The last commit of main without the as-built rules (design-geometry speed compares to it).
BASE = "db426a17e6b45aee0ab042a3223ce7038630e8bf"


def scenes() -> dict:
    return {"wall 6x5": gen.running_bond_wall(),
            "arch 15": gen.semicircular_arch(),
            "buttressed arch": gen.buttressed_arch(),
            "dome 14x10": gen.dome(),
            "stack 5": gen.stack(5),
            "tower 12": gen.stack(12, width=0.4, depth=0.4, height=0.2)}


def contact(rule: str, sigma_m: float, size: float) -> ContactOptions:
    """The contact options of ``rule`` at noise ``sigma_m`` (``size``: the scene's smallest
    block size, to which the design rule's tolerance is relative)."""
    bound, angle = DECLARED_SIGMAS * sigma_m, DECLARED_SIGMAS * DEG_PER_MM * sigma_m * 1e3
    if rule == "declared":
        return ContactOptions(pose_uncertainty_m=bound, pose_uncertainty_deg=angle)
    if rule == "raised tolerance":
        return ContactOptions(distance_tol=max(1e-3, 2 * bound / size),
                              angle_tol_deg=1.0 + 2 * angle)
    return ContactOptions()


def run_suite(samples: int, progress) -> list[dict]:
    rows = []
    no_holds = HoldSearch(enabled=False)
    for s_index, (name, scene) in enumerate(scenes().items()):
        design = check_scene(scene, CheckOptions(holds=no_holds))
        posed = pose_blocks(scene.blocks)
        weight = sum(b.mass for b in posed if not b.support) * float(np.linalg.norm(scene.gravity))
        size = min(b.size for b in posed)
        for l_index, sigma_mm in enumerate(SIGMAS_MM):
            sigma = sigma_mm * 1e-3
            rng = np.random.default_rng([16, s_index, l_index])
            noisy = [perturb_scene(scene, PoseNoise(sigma, DEG_PER_MM * sigma_mm), rng)
                     for _ in range(samples)]
            for rule in RULES:
                options = CheckOptions(holds=no_holds, contact=contact(rule, sigma, size))
                statuses, errors, sensitive, start = [], [], 0, time.perf_counter()
                for sc in noisy:
                    try:
                        report = check_scene(sc, options)
                    except SceneError:
                        statuses.append("INVALID_INPUT")
                        continue
                    statuses.append(report.status.name)
                    sensitive += report.verdict_sensitive
                    if report.status == design.status:
                        errors.append(resultant_error(report, design) / weight)
                agree = sum(s == design.status.name for s in statuses)
                rows.append({"scene": name, "sigma_mm": sigma_mm, "rule": rule,
                             "samples": samples, "agree": agree,
                             "invalid": statuses.count("INVALID_INPUT"),
                             "force_error": max(errors, default=float("nan")),
                             "sensitive": sensitive,
                             "ms": 1e3 * (time.perf_counter() - start) / samples,
                             "verdicts": {s: statuses.count(s) for s in sorted(set(statuses))}})
                progress(rows[-1])
    return rows


_TIMER = """
import json, sys, time
sys.meta_path[:] = [f for f in sys.meta_path if "__editable__" not in repr(f)]
sys.path.insert(0, sys.argv[1])
import rbe_ros
from rbe_ros import generators as gen
from rbe_ros.analysis.options import CheckOptions, HoldSearch
from rbe_ros.analysis.pipeline import check_scene
assert rbe_ros.__file__.startswith(sys.argv[1]), rbe_ros.__file__
options = CheckOptions(holds=HoldSearch(enabled=False))
out = {}
for name, scene in (("wall 6x5", gen.running_bond_wall()), ("wall 20x15",
        gen.running_bond_wall(20, 15)), ("dome 14x10", gen.dome())):
    check_scene(scene, options)
    best = float("inf")
    for _ in range(int(sys.argv[2])):
        start = time.perf_counter()
        check_scene(scene, options)
        best = min(best, time.perf_counter() - start)
    out[name] = best
print(json.dumps(out))
"""


def design_speed(rounds: int, repeat: int) -> dict:
    """Best time of a design-geometry check (no hold search) per scene, of this tree and of
    BASE, timed alternately in subprocesses: {scene: (base s, now s)}."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", BASE, "rbe_ros"],
                             check=True, capture_output=True).stdout
    best: dict[str, list[float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "base"
        tarfile.open(fileobj=BytesIO(archive)).extractall(base, filter="data")
        for _ in range(rounds):
            for k, tree in enumerate((base, ROOT)):
                out = subprocess.run([sys.executable, "-c", _TIMER, str(tree), str(repeat)],
                                     check=True, capture_output=True, text=True).stdout
                for name, t in json.loads(out).items():
                    best.setdefault(name, [float("inf")] * 2)
                    best[name][k] = min(best[name][k], t)
    return {name: tuple(v) for name, v in best.items()}


def sensitivity_cost(repeat: int = 20) -> dict:
    """Best time (s) of the as-built stage of a check (near contacts and verdict_sensitive,
    :func:`rbe_ros.analysis.asbuilt.sensitivity`) on design geometry, per scene of :func:`design_speed`."""
    options = CheckOptions(holds=HoldSearch(enabled=False))
    out = {}
    for name, scene in (("wall 6x5", gen.running_bond_wall()),
                        ("wall 20x15", gen.running_bond_wall(20, 15)), ("dome 14x10", gen.dome())):
        assembly = validated_assembly(scene, options.limits, options.contact)
        report = check(assembly, options)
        out[name] = min(_timed(lambda: sensitivity(report, assembly, options))
                        for _ in range(repeat))
    return out


def _timed(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def pooled(rows, rule, up_to_mm=None, sigma_mm=None):
    sel = [r for r in rows if r["rule"] == rule
           and (up_to_mm is None or r["sigma_mm"] <= up_to_mm)
           and (sigma_mm is None or r["sigma_mm"] == sigma_mm)]
    n = sum(r["samples"] for r in sel)
    errors = [r["force_error"] for r in sel if r["force_error"] == r["force_error"]]
    return (sum(r["agree"] for r in sel) / n, sum(r["invalid"] for r in sel), n,
            max(errors, default=float("nan")))


def write(rows, speed, stages, samples: int, out: Path, figure: Path, elapsed: float
          ) -> None:
    ok_agree, invalid, n, worst = pooled(rows, "declared", up_to_mm=1.0)
    _, invalid_all, n_all, worst_all = pooled(rows, "declared")
    lines = ["# As-built poses: the noise suite", "",
             "Made by `benchmarks/asbuilt.py` (`make asbuilt`, "
             f"{elapsed / 60:.0f} min); ratios measured in one run.",
             "Machine: " + machine_summary(), "",
             f"Scenes that stand as designed; {samples} samples per scene and noise level "
             "(fixed seeds), Gaussian position noise sigma per axis and rotation "
             f"{DEG_PER_MM} deg per mm of sigma about a random axis "
             "(`rbe_ros.analysis.perturb`). Rules: **declared**: `--pose-uncertainty` "
             f"{DECLARED_SIGMAS:g} sigma; **raised tolerance**: the design rule with the "
             "distance and angle tolerances raised by the same amount (interpenetration "
             "still beyond 1% of the size); **defaults**: today's defaults. Agreement: the "
             "verdict equals the design's; force error: the largest difference of a block "
             "pair's resultant over the free weight, on the samples that agree.", "",
             "## Bars", "",
             f"- declared, up to 1 mm: verdict agrees in **{100 * ok_agree:.2f}%** of {n} "
             f"samples (bar 99%); INVALID_INPUT {invalid} (up to 2 mm: {invalid_all} of "
             f"{n_all}); largest force error **{100 * worst:.2f}%** of the free weight (bar "
             f"5%; up to 2 mm: {100 * worst_all:.2f}%).", ""]
    raised = pooled(rows, "raised tolerance", up_to_mm=2.0)
    declared_all = pooled(rows, "declared", up_to_mm=2.0)
    lines += ["## Which rule", "",
              "3DEC keeps contacts within a tolerance relative to the model size in a band "
              "around a common plane; compas_model (`mesh_mesh_contacts`) fits one frame to both "
              "faces; LMGC90 pairs faces within an angle tolerance and shrinks them slightly. "
              "The *raised tolerance* rule is the first with the plane of one face (what a user "
              "of this package could do before); *declared* is the second, a symmetric "
              "interface on the mid-plane, with tolerances from the declared pose uncertainty "
              "in physical units, per block (`delta + theta R`) instead of relative to the "
              "smaller block. Shrinking faces (LMGC90) was not tried: it only removes area, and "
              "the width and vertex filters already drop slivers.", "",
              f"Up to 2 mm, all scenes: declared agrees in {100 * declared_all[0]:.2f}% "
              f"(INVALID_INPUT {declared_all[1]}, force error up to "
              f"{100 * declared_all[3]:.2f}%), raised tolerance in {100 * raised[0]:.2f}% "
              f"(INVALID_INPUT {raised[1]}, force error up to {100 * raised[3]:.2f}%). Both "
              "converge to the design's forces as sigma goes to 0 (table below); on these "
              "scenes the choice of the plane changes the forces by less than the noise does, "
              "and what decides is that the tolerance covers the noise. The declared rule is "
              "kept for what does not show here: the interface is the same whichever block "
              "is a, the tolerance is in the units a robot cell knows, it grows with the lever "
              "arm of the angular error, and interpenetration is refused exactly beyond it.", ""]
    lines += ["## Agreement and force error against sigma (all scenes)", "",
              "| sigma mm | " + " | ".join(f"{r}: agree, invalid, force err" for r in RULES)
              + " |", "|---|" + "---|" * len(RULES)]
    for s in SIGMAS_MM:
        cells = []
        for rule in RULES:
            a, inv, _, err = pooled(rows, rule, sigma_mm=s)
            cells.append(f"{100 * a:.1f}%, {inv}, " + ("-" if err != err else f"{100 * err:.2f}%"))
        lines.append(f"| {s:g} | " + " | ".join(cells) + " |")
    lines += ["", "## By scene", "",
              "| scene | sigma mm | rule | agree | invalid | force err | sensitive | ms/check |"
              " verdicts |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        err = "-" if r["force_error"] != r["force_error"] else f"{100 * r['force_error']:.2f}%"
        verdicts = ", ".join(f"{k} {v}" for k, v in r["verdicts"].items())
        lines.append(f"| {r['scene']} | {r['sigma_mm']:g} | {r['rule']} | "
                     f"{r['agree']}/{r['samples']} | {r['invalid']} | {err} | {r['sensitive']} | "
                     f"{r['ms']:.0f} | {verdicts} |")
    lines += ["", "## Design geometry: cost of a check against the last commit without the "
              "as-built rules", "",
              f"`check_scene` without hold search, best of the runs, `{BASE[:10]}` and this tree "
              "each in its own subprocess, alternately (this tree holds the other work landed "
              "since, too). On a shared machine the best of runs of one tree still varies by "
              "10-20%; the as-built stage itself (near contacts, verdict_sensitive; nothing "
              "near the tolerance on design geometry, so no extra solve) is timed in process.",
              "", "| scene | before [ms] | now [ms] | now / before | as-built stage [ms] |",
              "|---|---|---|---|---|"]
    for name, (before, now) in speed.items():
        lines.append(f"| {name} | {1e3 * before:.1f} | {1e3 * now:.1f} | {now / before:.3f} | "
                     f"{1e3 * stages[name]:.3f} |")
    lines += ["", f"![agreement and force error against sigma]({figure.relative_to(out.parent)})",
              ""]
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines))
    plot(rows, figure)


def plot(rows, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4), dpi=120)
    for rule, style in zip(RULES, ("o-", "s--", "^:")):
        agree = [100 * pooled(rows, rule, sigma_mm=s)[0] for s in SIGMAS_MM]
        err = [100 * pooled(rows, rule, sigma_mm=s)[3] for s in SIGMAS_MM]
        left.semilogx(SIGMAS_MM, agree, style, label=rule)
        right.semilogx(SIGMAS_MM, err, style, label=rule)
    left.axhline(99, color="grey", lw=0.8)
    right.axhline(5, color="grey", lw=0.8)
    left.set(xlabel="pose noise sigma [mm]", ylabel="verdict = design's [% of samples]",
             ylim=(-3, 103))
    right.set(xlabel="pose noise sigma [mm]", ylabel="largest force error [% of free weight]")
    for ax in (left, right):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="10 samples, out/asbuilt-quick/")
    parser.add_argument("--render", action="store_true", help="rewrite the page and chart from "
                        "the numbers of the last run (ASBUILT.json beside the page)")
    args = parser.parse_args()
    samples = 10 if args.quick else 50
    out = (ROOT / "out" / "asbuilt-quick" / "ASBUILT.md" if args.quick
           else ROOT / "docs" / "ASBUILT.md")
    start = time.perf_counter()

    def progress(r):
        print(f"{r['scene']:16s} {r['sigma_mm']:5g} mm {r['rule']:16s} agree {r['agree']}/"
              f"{r['samples']} invalid {r['invalid']} force {100 * r['force_error']:.2f}% "
              f"{r['ms']:.0f} ms", flush=True)

    data = out.with_suffix(".json")
    if args.render:
        saved = json.loads(data.read_text())
        rows, samples, elapsed = saved["rows"], saved["samples"], saved["elapsed"]
        speed = {k: tuple(v) for k, v in saved["speed"].items()}
        stages = saved["stages"]
    else:
        rows = run_suite(samples, progress)
        speed = design_speed(2 if args.quick else 7, 3 if args.quick else 9)
        stages = sensitivity_cost()
        elapsed = time.perf_counter() - start
        data.parent.mkdir(parents=True, exist_ok=True)
        data.write_text(json.dumps({"samples": samples, "elapsed": elapsed, "rows": rows,
                                    "speed": speed, "stages": stages}, indent=1))
    for name, (before, now) in speed.items():
        print(f"design {name}: {1e3 * before:.1f} -> {1e3 * now:.1f} ms ({now / before:.3f})")
    write(rows, speed, stages, samples, out, out.parent / "figures" / "asbuilt.png", elapsed)
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
