"""Pose noise (rbe_ros.analysis.perturb): the distributions it promises, against closed forms."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rbe_ros import generators as gen
from rbe_ros.analysis.perturb import PoseNoise, perturb_poses, perturb_scene
from rbe_ros.scene import BOX_FACES, box_block, box_vertices, make_block, make_scene


def test_position_and_angle_distributions():
    n = 20000
    base = Rotation.from_euler("xyz", [10, 20, 30], degrees=True).as_quat()
    pos, quat = perturb_poses(np.ones((n, 3)), np.tile(base, (n, 1)),
                              PoseNoise(0.002, 0.1), np.random.default_rng(1))
    shift = pos - 1.0
    # per axis N(0, sigma^2): standard error of the std about sigma / sqrt(2n) = 1e-5 m
    assert np.allclose(shift.std(axis=0), 0.002, rtol=0.03)
    assert np.allclose(shift.mean(axis=0), 0.0, atol=1e-4)
    assert abs(np.corrcoef(shift.T)[0, 1]) < 0.03
    # the noise rotation (applied in the scene frame): angle half-normal, axis uniform
    noise = Rotation.from_quat(quat) * Rotation.from_quat(base).inv()
    rotvec = noise.as_rotvec()
    angle = np.degrees(np.linalg.norm(rotvec, axis=1))
    assert angle.mean() == pytest.approx(0.1 * math.sqrt(2 / math.pi), rel=0.03)
    assert np.sqrt((angle ** 2).mean()) == pytest.approx(0.1, rel=0.03)
    axis = rotvec / np.linalg.norm(rotvec, axis=1, keepdims=True)
    assert np.allclose(np.abs(axis).mean(axis=0), 0.5, atol=0.02)   # E|x| of a uniform axis


def test_scene_noise_is_seeded_and_keeps_supports():
    scene = gen.running_bond_wall(courses=2, bricks_per_course=3)
    noise = PoseNoise(0.001, 0.05)
    one = perturb_scene(scene, noise, np.random.default_rng(7))
    two = perturb_scene(scene, noise, np.random.default_rng(7))
    for a, b, c in zip(scene.blocks, one.blocks, two.blocks):
        assert np.array_equal(b.position, c.position)
        assert np.array_equal(b.orientation, c.orientation)
        if a.support:
            assert b is a
        else:
            assert 0 < np.linalg.norm(b.position - a.position) < 0.01
            assert np.linalg.norm(b.orientation) == pytest.approx(1.0, abs=1e-12)
    zero = perturb_scene(scene, PoseNoise(), np.random.default_rng(7))
    assert all(np.allclose(a.position, b.position, atol=0)
               for a, b in zip(scene.blocks, zero.blocks))


def test_blocks_turn_about_their_own_centre():
    """A mesh given in scene coordinates 10 m from its frame origin (as COMPAS files are):
    the noise turns it about its vertex mean, which stays put without position noise, while
    its vertices turn by the angle about it."""
    vertices = box_vertices((0.4, 0.2, 0.1)) + [10.0, 0.0, 0.05]
    scene = make_scene("far", [box_block("ground", (30, 1, 0.1), (10, 0, -0.05), support=True,
                                         density=2000.0),
                               make_block("b", vertices, BOX_FACES, density=2000.0)])
    noisy = perturb_scene(scene, PoseNoise(0.0, 1.0), np.random.default_rng(2)).blocks[1]
    world = Rotation.from_quat(noisy.orientation).apply(vertices) + noisy.position
    assert np.allclose(world.mean(axis=0), [10.0, 0.0, 0.05], atol=1e-12)
    rotvec = Rotation.from_quat(noisy.orientation).as_rotvec()
    angle, axis = np.linalg.norm(rotvec), rotvec / np.linalg.norm(rotvec)
    assert 0 < np.degrees(angle) < 5
    r = vertices - vertices.mean(axis=0)
    r_perp = r - np.outer(r @ axis, axis)        # each vertex moves on a circle about the axis
    assert np.allclose(np.linalg.norm(world - vertices, axis=1),
                       2 * math.sin(angle / 2) * np.linalg.norm(r_perp, axis=1), atol=1e-12)


def test_noise_must_be_finite_and_non_negative():
    with pytest.raises(ValueError, match="position_sigma"):
        PoseNoise(-1.0)
    with pytest.raises(ValueError, match="angle_sigma_deg"):
        PoseNoise(0.0, math.nan)
