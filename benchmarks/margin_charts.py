"""Where methods fail: p_stable against placement noise for near-limit families, ours beside
PyBullet given the same perturbed poses: docs/MARGIN_CHARTS.md and docs/figures/p_stable_*.png.

Families just inside their limit: a block overhanging by 0.45 of its width, a 5-block
harmonic stack at 0.95 of the marginal overhangs, a 15-voussoir semicircular arch at
t/R = 0.12 (limit 0.1074), a leaning tower of 5 boxes each 0.18 w further out (limit 0.2).
For each noise level sigma (position per axis; rotation 50 sigma deg, i.e. 0.5 deg at 1 cm),
the same samples (seed per sample, rbe_ros.analysis.robust) are checked by rbe_ros (the pose
uncertainty declared at 3 sigma) and by PyBullet at 1 kHz (benchmarks/_physics.py: settle
for 1 s from rest, collapsed past 10% of the block size or 5 deg).

    python benchmarks/margin_charts.py [--samples N]      (make bench-margin-charts)
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import matplotlib
import _physics as physics
from machine import machine_summary

from rbe_ros import generators as gen
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.perturb import PoseNoise
from rbe_ros.analysis.robust import RobustJob, run_batch, sample_scene, wilson_interval

matplotlib.use("Agg")
import matplotlib.pyplot as plt

ROOT = Path(__file__).resolve().parents[1]
SIGMAS = (0.002, 0.005, 0.01, 0.02, 0.04)
FAMILIES = {
    "overhang 0.45 w": gen.two_blocks(shift=0.45),
    "harmonic stack 5, scale 0.95": gen.harmonic_stack(5, scale=0.95),
    "arch t/R 0.12": gen.semicircular_arch(15, thickness_ratio=0.12),
    "leaning tower 5 x 0.18 w": gen.stack(5, height=0.5, offsets=[0.18 * k for k in range(5)]),
}


def study(scene, sigma: float, samples: int, seed: int) -> dict:
    job = RobustJob(scene, PoseNoise(sigma, 50 * sigma), seed, CheckOptions())
    start = time.perf_counter()
    ours = sum(r.stands for r in run_batch(job, range(samples)))
    t_ours = time.perf_counter() - start
    start = time.perf_counter()
    bullet = sum(physics.check(physics.bodies_from_scene(sample_scene(job, k)), engine="pybullet",
                               hz=1000.0, iterations=100, T=1.0, mu=0.6)["stable"]
                 for k in range(samples))
    t_bullet = time.perf_counter() - start
    return {"ours": ours, "bullet": bullet, "t_ours": t_ours, "t_bullet": t_bullet}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=40)
    args = parser.parse_args()
    n = args.samples
    fig, axes = plt.subplots(1, len(FAMILIES), figsize=(4 * len(FAMILIES), 3.4), sharey=True)
    rows = []
    for ax, (name, scene) in zip(axes, FAMILIES.items()):
        got = [study(scene, s, n, 1) for s in SIGMAS]
        for key, label, marker in (("ours", "rbe_ros (3 sigma declared)", "o"),
                                   ("bullet", "PyBullet 1 kHz", "s")):
            p = [g[key] / n for g in got]
            lo, hi = zip(*(wilson_interval(g[key], n) for g in got))
            ax.errorbar([s * 1e3 for s in SIGMAS], p,
                        yerr=[[a - b for a, b in zip(p, lo)], [b - a for a, b in zip(p, hi)]],
                        marker=marker, capsize=3, label=label)
        ax.set_xscale("log")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("position sigma (mm)")
        for s, g in zip(SIGMAS, got):
            rows.append(f"| {name} | {1e3 * s:g} | {g['ours'] / n:.2f} | {g['bullet'] / n:.2f} | "
                        f"{1e3 * g['t_ours'] / n:.0f} | {1e3 * g['t_bullet'] / n:.0f} |")
    axes[0].set_ylabel("p_stable")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    figure = ROOT / "docs" / "figures" / "p_stable_near_limit.png"
    fig.savefig(figure, dpi=110)
    text = "\n".join([
        "# p_stable near the limit: rbe_ros beside PyBullet", "",
        "Made by `make bench-margin-charts` (`benchmarks/margin_charts.py`), "
        f"{n} samples per point, the same perturbed poses for both (seed 1).", "",
        "Machine: " + machine_summary(), "",
        "![p_stable against sigma](figures/p_stable_near_limit.png)", "",
        "| family | sigma mm | p_stable rbe_ros | p_stable PyBullet | ms per sample ours | "
        "ms per sample PyBullet |", "|---|---|---|---|---|---|", *rows, ""])
    (ROOT / "docs" / "MARGIN_CHARTS.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
