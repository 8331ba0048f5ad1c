"""rbe-ros robust: p_stable against the closed form Phi(delta / sigma) of an overhang, the
Wilson interval, the same numbers on every executor (in-process, process pool, Ray)."""
from __future__ import annotations

import json
import math

import pytest

from rbe_ros import generators as gen
from rbe_ros.analysis.executors import ProcessPool, ray_cluster
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.perturb import PoseNoise
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.analysis.robust import RobustJob, estimate, sample_options, wilson_interval
from rbe_ros.cli import main
from rbe_ros.io.scene_json import load_scene

SIGMA = 0.01     # m, position noise per axis; the blocks are 1 m wide


def _phi(x: float) -> float:
    return 0.5 * (1 + math.erf(x / math.sqrt(2)))


def _overhang_job(ratio: float, seed: int) -> RobustJob:
    """The top block overhangs the support's edge by 0.5 w - delta, delta = ratio sigma: it
    stands while its x error is below delta, with probability Phi(delta / sigma)."""
    return RobustJob(gen.two_blocks(shift=0.5 - ratio * SIGMA), PoseNoise(SIGMA, 0.0), seed,
                     CheckOptions())


@pytest.mark.parametrize("ratio, seed", [(-1.0, 11), (0.0, 12), (1.0, 13), (2.0, 14)])
def test_p_stable_of_an_overhang_is_phi_of_delta_over_sigma(ratio, seed):
    result = estimate(_overhang_job(ratio, seed), 400, batch_size=100)
    lo, hi = result.interval
    assert lo <= _phi(ratio) <= hi, (result.p_stable, _phi(ratio))
    assert result.samples == 400


def test_wilson_interval_closed_forms():
    """At 0 of n the upper end is z^2 / (n + z^2); symmetric about 1/2 at n/2."""
    z2 = 1.959963984540054 ** 2
    assert wilson_interval(0, 10) == (0.0, pytest.approx(z2 / (10 + z2)))
    lo, hi = wilson_interval(50, 100)
    assert lo + hi == pytest.approx(1.0) and hi - lo == pytest.approx(0.1924, abs=1e-4)


def test_samples_declare_three_sigma_and_search_no_holds():
    options = sample_options(RobustJob(gen.two_blocks(), PoseNoise(0.002, 0.4), 0, CheckOptions()))
    assert options.contact.pose_uncertainty_m == pytest.approx(0.006)
    assert options.contact.pose_uncertainty_deg == pytest.approx(1.2)
    assert not options.holds.enabled


def test_process_pool_and_ray_give_the_serial_numbers():
    """Seeds are per sample: batches in another order, on other processes, same tally."""
    job = _overhang_job(0.0, 5)
    job = RobustJob(job.scene, PoseNoise(SIGMA, 0.5), 5, job.options)
    serial = estimate(job, 24, batch_size=5)
    with ProcessPool(2) as pool:
        pooled = estimate(job, 24, pool, batch_size=3)
    assert (pooled.p_stable, pooled.closest_failure) == (serial.p_stable, serial.closest_failure)
    assert 0.0 < serial.p_stable < 1.0
    import ray
    try:
        on_ray = estimate(job, 24, ray_cluster(None, num_cpus=2), batch_size=4)
    finally:
        ray.shutdown()
    assert (on_ray.p_stable, on_ray.closest_failure) == (serial.p_stable, serial.closest_failure)


def test_cli_robust_sequence_json_and_worst_sample(tmp_path, capsys):
    """Per-step p_stable of a tower whose top overhangs by half its width (about 1/2); -o
    writes the failing sample closest to the design, which fails when checked."""
    scene = tmp_path / "stack.json"
    assert main(["generate", "stack", "-p", "n=2", "-p", "height=0.2", "-p",
                 "offsets=[0,0.5]", "-o", str(scene)]) == 0
    capsys.readouterr()
    worst = tmp_path / "worst.json"
    assert main(["robust", str(scene), "--pose-sigma", f"{SIGMA / 2}", "--samples", "40",
                 "--seed", "3", "--sequence", "--json", "-o", str(worst)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["samples"] == 40 and [s["step"] for s in out["steps"]] == [0, 1]
    assert out["steps"][0]["p_stable"] == 1.0            # one box on the ground: far from failing
    assert 0.0 < out["p_stable"] == out["steps"][1]["p_stable"] < 1.0
    lo, hi = out["interval"]
    assert lo <= out["p_stable"] <= hi
    assert not check_scene(load_scene(worst), CheckOptions()).stable
