"""Probability of standing under placement error: Monte Carlo over perturbed poses.

Sample k perturbs every free block of the design with its own generator, seeded by
(seed, k) (:mod:`rbe_ros.analysis.perturb`), and is checked with the pose uncertainty
declared at 3 sigma (the as-built contact rules): so a sample's verdict depends on the seed
and k only, never on which process, machine or batch checked it. Samples run in batches on
an executor (a process pool, Ray, or in-process); the tally is the same whatever the
executor. p_stable comes with its Wilson 95% interval.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace

import numpy as np

from ..scene import Scene, SceneError
from .options import CheckOptions, HoldSearch
from .perturb import PoseNoise, perturb_scene
from .pipeline import check_scene, check_sequence, slim
from .steps import gripped, sequence_steps
from .validate import validated_assembly
from .verdict import check

#: Declared pose uncertainty of a sample, in standard deviations of the noise.
DECLARED_SIGMAS = 3.0
#: Normal quantile of a two-sided 95% interval.
Z95 = 1.959963984540054


@dataclass(frozen=True)
class RobustJob:
    """What every batch needs: the design, the noise, the check and whether per step."""

    scene: Scene
    noise: PoseNoise
    seed: int
    options: CheckOptions
    sequence: bool = False


@dataclass(frozen=True)
class SampleResult:
    """The verdicts of one perturbed sample."""

    index: int
    stands: bool                 # the whole check, or every step
    steps: tuple[bool, ...]      # per step (with sequence); () otherwise
    distance: float              # of the perturbation from the design, in sigmas (RMS)


@dataclass(frozen=True)
class RobustResult:
    """The probability of standing over the samples, with its interval, per step."""

    p_stable: float
    interval: tuple[float, float]
    samples: int
    steps: list[dict]            # with sequence: {"step", "block", "p_stable", "interval"}
    closest_failure: int | None  # sample index of the failing sample closest to the design


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (exact at 0 and n, unlike Wald's)."""
    if n <= 0:
        return (0.0, 1.0)
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (0.0 if successes == 0 else centre - half, 1.0 if successes == n else centre + half)


def sample_options(job: RobustJob) -> CheckOptions:
    """The check of a sample: the uncertainty declared at DECLARED_SIGMAS sigma, no hold
    search (only the verdict is counted)."""
    n = job.noise
    contact = replace(job.options.contact,
                      pose_uncertainty_m=DECLARED_SIGMAS * n.position_sigma,
                      pose_uncertainty_deg=DECLARED_SIGMAS * n.angle_sigma_deg)
    return replace(job.options, contact=contact, holds=HoldSearch(enabled=False),
                   margin_directions=0)


def sample_scene(job: RobustJob, index: int) -> Scene:
    """Sample ``index``'s perturbed scene (its generator seeded by (seed, index))."""
    return perturb_scene(job.scene, job.noise, np.random.default_rng([job.seed, index]))


def _distance(design: Scene, sample: Scene, noise: PoseNoise) -> float:
    """RMS over free blocks and pose components of the deviation in sigmas."""
    terms = []
    for a, b in zip(design.blocks, sample.blocks):
        if a.support:
            continue
        if noise.position_sigma > 0:
            terms.extend(((b.position - a.position) / noise.position_sigma) ** 2)
        if noise.angle_sigma_deg > 0:
            dot = min(1.0, abs(float(np.dot(a.orientation, b.orientation))))
            terms.append((math.degrees(2 * math.acos(dot)) / noise.angle_sigma_deg) ** 2)
    return math.sqrt(sum(terms) / len(terms)) if terms else 0.0


def run_batch(job: RobustJob, indices: Iterable[int]) -> list[SampleResult]:
    """Check the samples ``indices`` (the unit of work an executor runs)."""
    options = sample_options(job)
    count = len(sequence_steps(job.scene)) if job.sequence else 0
    out = []
    for k in indices:
        scene = sample_scene(job, k)
        try:
            if job.sequence:
                steps = tuple(r.stable for r in check_sequence(scene, options, keep=slim))
                stands = all(steps)
            else:
                steps, stands = (), check_scene(scene, options).stable
        except SceneError:
            # blocks that interpenetrate beyond the declared uncertainty: a placement the
            # robot could not have made, counted as failing at every step
            steps, stands = (False,) * count, False
        out.append(SampleResult(k, stands, steps, _distance(job.scene, scene, job.noise)))
    return out


def declared_noise(options: CheckOptions) -> PoseNoise:
    """The pose noise whose DECLARED_SIGMAS sigma is ``options``' declared uncertainty."""
    contact = options.contact
    return PoseNoise(contact.pose_uncertainty_m / DECLARED_SIGMAS,
                     contact.pose_uncertainty_deg / DECLARED_SIGMAS)


class StepSamples:
    """p_stable of the steps of a plan being made (``plan --robust N``): sample k of
    ``scene`` as :func:`sample_scene` draws it under ``options``' declared uncertainty, its
    contacts detected once, and a step (blocks present, held ones gripped at their
    centroids) checked in each sample. A planned scene places every block of ``scene`` in
    scene order, so its samples are these: ``robust --sequence`` on it gives each step the
    same p_stable. Every candidate meets the same samples (common random numbers: a ranking
    by p_stable is not one of sampling luck)."""

    def __init__(self, scene: Scene, options: CheckOptions, samples: int, seed: int = 0):
        if samples < 1:
            raise ValueError(f"samples must be at least 1, not {samples}")
        job = RobustJob(scene, declared_noise(options), seed, options, sequence=True)
        self.samples, self.options = samples, sample_options(job)
        self.assemblies: list = []
        for k in range(samples):
            try:
                self.assemblies.append(validated_assembly(
                    sample_scene(job, k), self.options.limits, self.options.contact))
            except SceneError:      # as run_batch: a placement no robot could make, failing
                self.assemblies.append(None)

    def p_stable(self, present, held=()) -> float:
        """The share of samples in which the step with ``present`` and ``held`` stands."""
        stood = sum(check(gripped(a, present, held), self.options).stable
                    for a in self.assemblies if a is not None)
        return stood / self.samples


def batches(samples: int, size: int) -> list[range]:
    """Sample indices in consecutive batches of ``size``."""
    return [range(i, min(i + size, samples)) for i in range(0, samples, size)]


#: An executor: maps run_batch over (job, batch) pairs, yielding each batch's results.
Executor = Callable[[RobustJob, list[range]], Iterable[list[SampleResult]]]


def serial(job: RobustJob, parts: list[range]) -> Iterable[list[SampleResult]]:
    """In this process, batch after batch."""
    return (run_batch(job, part) for part in parts)


def estimate(job: RobustJob, samples: int, executor: Executor = serial, batch_size: int = 16,
             on_batch: Callable[[int, int], None] | None = None) -> RobustResult:
    """p_stable of ``samples`` samples of ``job``, run by ``executor`` in batches;
    ``on_batch(done, total)`` after each batch (progress)."""
    if samples < 1:
        raise ValueError(f"samples must be at least 1, not {samples}")
    results: list[SampleResult] = []
    for part in executor(job, batches(samples, batch_size)):
        results.extend(part)
        if on_batch is not None:
            on_batch(len(results), samples)
    results.sort(key=lambda r: r.index)
    stood = sum(r.stands for r in results)
    steps = []
    if job.sequence:
        for k, step in enumerate(sequence_steps(job.scene)):
            ok = sum(r.steps[k] for r in results)
            steps.append({"step": step.index, "block": step.block, "p_stable": ok / samples,
                          "interval": list(wilson_interval(ok, samples))})
    failures = [r for r in results if not r.stands]
    closest = min(failures, key=lambda r: (r.distance, r.index)).index if failures else None
    return RobustResult(stood / samples, wilson_interval(stood, samples), samples, steps, closest)
