"""Pose noise: the as-built poses a robot or a camera reports, drawn around the design.

One model of measurement error, shared by every study that perturbs poses (the as-built
noise suite, Monte Carlo margins): each free block's position gets independent Gaussian
noise per axis, and its orientation a rotation about a uniformly random axis through the
block's centre (the mean of its vertices, as rbe_ros.geometry.uncertainty takes it) by a
Gaussian angle. Supports stay where they are (the ground, a scaffold
are the reference the poses are measured in). Draws come from the caller's numpy Generator
in a fixed order (all positions, then all axes, then all angles), so a seed gives the same
scene on every machine. The forces of a perturbed check compare with the design's by block
pair (:func:`resultant_error`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from ..rbe.result import Report
from ..scene import Scene


@dataclass(frozen=True)
class PoseNoise:
    """Standard deviations of the pose error of one block."""

    position_sigma: float = 0.0     # m, per axis
    angle_sigma_deg: float = 0.0    # deg, of the rotation angle about a random axis

    def __post_init__(self):
        for name in ("position_sigma", "angle_sigma_deg"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"pose noise {name} must be a finite number >= 0, not {value!r}")


def perturb_poses(positions: np.ndarray, orientations: np.ndarray, noise: PoseNoise,
                  rng: np.random.Generator, centres: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Noisy copies of ``positions`` (n, 3) and unit quaternions ``orientations`` (n, 4,
    x y z w): the noise rotation is applied in the scene frame, about each block's point of
    ``centres`` (n, 3; default the positions)."""
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    orientations = np.asarray(orientations, dtype=float).reshape(-1, 4)
    n = len(positions)
    shift = rng.normal(0.0, noise.position_sigma, size=(n, 3))
    axis = rng.normal(size=(n, 3))
    axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-300)
    angle = np.radians(rng.normal(0.0, noise.angle_sigma_deg, size=n))
    if not n:
        return positions.copy(), orientations.copy()
    turn = Rotation.from_rotvec(axis * angle[:, None])
    centres = positions if centres is None else np.asarray(centres, dtype=float).reshape(-1, 3)
    moved = centres + turn.apply(positions - centres) + shift
    return moved, (turn * Rotation.from_quat(orientations)).as_quat()


def perturb_scene(scene: Scene, noise: PoseNoise, rng: np.random.Generator) -> Scene:
    """``scene`` with the pose of every free block perturbed about its centre (the mean of
    its vertices; supports kept exactly)."""
    free = [k for k, b in enumerate(scene.blocks) if not b.support]
    if not free:
        return scene
    blocks = list(scene.blocks)
    positions = np.array([blocks[k].position for k in free])
    orientations = np.array([blocks[k].orientation for k in free])
    centres = positions + Rotation.from_quat(orientations).apply(
        np.array([blocks[k].vertices.mean(axis=0) for k in free]))
    pos, quat = perturb_poses(positions, orientations, noise, rng, centres)
    for k, p, q in zip(free, pos, quat):
        blocks[k] = replace(blocks[k], position=p, orientation=q)
    return replace(scene, blocks=tuple(blocks))


def pair_resultants(report: Report) -> dict[tuple[str, str], np.ndarray]:
    """The total force (N) each block pair's interfaces carry, keyed by the sorted pair and
    pointing from the first block into the second: the forces of a check on perturbed poses
    match those of the design by pair, whichever faces and polygons the noise made."""
    out: dict[tuple[str, str], np.ndarray] = {}
    for r in report.interfaces:
        key, sign = ((r.block_a, r.block_b), 1.0) if r.block_a <= r.block_b else \
            ((r.block_b, r.block_a), -1.0)
        out[key] = out.get(key, 0.0) + sign * np.asarray(r.resultant, dtype=float)
    return out


def resultant_error(report: Report, reference: Report) -> float:
    """The largest difference (N) of a pair's resultant between two checks of one assembly
    (a pair in one only: against zero)."""
    a, b = pair_resultants(report), pair_resultants(reference)
    return max((float(np.linalg.norm(a.get(k, 0.0) - b.get(k, 0.0))) for k in a.keys() | b.keys()),
               default=0.0)
