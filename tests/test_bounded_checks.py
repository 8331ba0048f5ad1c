"""Bounded checks: the shape analysis of large meshes, and a time limit on the whole check."""
import math
import time
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from rbe_ros import generators as gen
from rbe_ros.analysis import incremental
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.pipeline import check_scene, check_sequence
from rbe_ros.analysis.steps import sequence_step, sequence_steps, step_count
from rbe_ros.deadline import CheckTimeout, checkpoint, stage, time_budget
from rbe_ros.geometry import block as block_module
from rbe_ros.geometry.block import ANGLE_TOL, PLANE_TOL, _group_planes, pose_block
from rbe_ros.geometry.support import projection_extents
from rbe_ros.rbe.result import Status
from rbe_ros.rbe.solver import SolveOptions
from rbe_ros.scene import Hold

from helpers import stacked_boxes

DENSITY = 2000.0
RADIUS = 0.3            # of the domes' base (convex_domes' default)


def test_a_10000_vertex_convex_mesh_is_checked_in_under_2_s():
    scene = gen.convex_domes(density=DENSITY)
    block_module._shape.cache_clear()
    # CPU time of this process: the bound is on the work, not on the load of a shared machine
    start = time.process_time()
    report = check_scene(scene)
    spent = time.process_time() - start
    assert spent < 2.0, f"{spent:.2f} s"
    # oracles: weight and centre of mass from the hull's tetrahedra (scipy's triangulation),
    # which the one interface carries (the dome on its flat base, inside the 1000-gon)
    dome = scene.blocks[1]
    hull = ConvexHull(dome.vertices + dome.position)
    tets = hull.points[hull.simplices]
    apex = hull.points.mean(axis=0)
    tet_volumes = np.abs(np.einsum("ij,ij->i", tets[:, 0] - apex,
                                   np.cross(tets[:, 1] - apex, tets[:, 2] - apex))) / 6
    centroid = (tet_volumes[:, None] * (tets.sum(axis=1) + apex) / 4).sum(axis=0) / hull.volume
    assert tet_volumes.sum() == pytest.approx(hull.volume, rel=1e-12)
    assert report.status == Status.STABLE and len(report.interfaces) == 1
    it = report.interfaces[0]
    assert it.normal_resultant == pytest.approx(DENSITY * hull.volume * 9.81, rel=1e-6)
    assert np.allclose(it.centre_of_pressure[:2], centroid[:2], atol=1e-6)
    assert np.allclose(it.polygon[:, 2], 0.0, atol=1e-12)
    assert np.linalg.norm(it.polygon[:, :2], axis=1).max() <= RADIUS * (1 + 1e-9)
    # cached per distinct mesh: a second check does not analyse the shape again
    start = time.process_time()
    check_scene(scene)
    assert time.process_time() - start < 0.5 * spent


def linear_scan(normals, offsets, plane_tol):
    """The plane of each face as the quadratic scan grouped them (the oracle)."""
    planes, group = [], []
    for n, d in zip(normals, offsets):
        for k, (gn, gd) in enumerate(planes):
            if gn @ n > math.cos(ANGLE_TOL) and abs(gd - d) <= plane_tol:
                group.append(k)
                break
        else:
            group.append(len(planes))
            planes.append((n, d))
    return np.array(group)


def test_faces_are_grouped_by_plane_as_a_linear_scan_groups_them():
    rng = np.random.default_rng(3)
    # few planes, many faces each, normals and offsets jittered around the tolerances
    base = rng.normal(size=(40, 3))
    base /= np.linalg.norm(base, axis=1)[:, None]
    pick = rng.integers(0, 40, 3000)
    normals = base[pick] + rng.normal(scale=0.4 * ANGLE_TOL, size=(3000, 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    offsets = rng.integers(0, 3, 40)[pick] + rng.normal(scale=0.6 * PLANE_TOL, size=3000)
    group, first = _group_planes(normals, offsets, PLANE_TOL)
    expected = linear_scan(normals, offsets, PLANE_TOL)
    assert np.array_equal(group, expected)
    assert np.array_equal(first, [np.flatnonzero(expected == k)[0] for k in range(len(first))])
    assert 40 < len(first) < 3000          # the jitter splits some planes, not all


def test_projection_extents_equal_the_full_product():
    rng = np.random.default_rng(4)
    dome = gen.convex_domes(vertices=3000, rim=100, seed=4).blocks[1]
    inside = rng.uniform(-0.1, 0.1, size=(500, 3))
    points = np.vstack((dome.vertices, inside))    # points inside the hull change nothing
    axes = rng.normal(size=(5000, 3))
    product = points @ axes.T
    extents = projection_extents(points, axes)
    assert np.allclose(extents[:, 0], product.min(axis=0), rtol=0, atol=1e-14)
    assert np.allclose(extents[:, 1], product.max(axis=0), rtol=0, atol=1e-14)
    assert pose_block(dome).convex


def test_the_deadline_names_the_stage_and_nests():
    with time_budget(math.inf):
        checkpoint()                                   # no bound
    with time_budget(0.0), stage("geometry"):
        time.sleep(0.001)
        with pytest.raises(CheckTimeout, match="time limit of 0 s exceeded in the geometry"):
            checkpoint()
        with time_budget(10.0):                        # the earlier deadline applies
            with pytest.raises(CheckTimeout):
                checkpoint()
    checkpoint()                                       # no budget after the block


def test_a_time_limit_bounds_the_geometry_stage():
    """Twelve distinct 10,000-vertex meshes: about 7 s of shape analysis unbounded (see
    docs/BOUNDED_CHECKS.md); with a 0.5 s limit the answer comes after at most 1 s of work.
    The limit is wall time, so the bound is on this process's CPU time (which a shared
    machine's load does not stretch: under load the limit stops the work sooner) and, as
    wall time, far below the unbounded 7 s."""
    scene = gen.convex_domes(12)
    block_module._shape.cache_clear()
    start, cpu = time.perf_counter(), time.process_time()
    report = check_scene(scene, CheckOptions(solve=SolveOptions(time_limit=0.5)))
    elapsed, spent = time.perf_counter() - start, time.process_time() - cpu
    assert spent < 1.0, f"{spent:.2f} s of CPU"
    assert elapsed < 4.0, f"{elapsed:.2f} s"
    assert report.status == Status.SOLVER_FAILED and not report.stable
    assert report.message == "solver failed: time limit of 0.5 s exceeded in the geometry stage"


def test_a_time_limit_bounds_each_step_of_a_sequence(monkeypatch):
    scene = gen.convex_domes(3, vertices=2000)
    block_module._shape.cache_clear()
    reports = check_sequence(scene, CheckOptions(solve=SolveOptions(time_limit=1e-4)))
    assert [r.step_index for r in reports] == [0, 1, 2]
    assert {r.status for r in reports} == {Status.SOLVER_FAILED}
    assert all(r.message.endswith("exceeded in the geometry stage") for r in reports)
    # a step whose solve starts after its budget is spent (the geometry is not): that step
    # only is SOLVER_FAILED, and the next steps are checked (a limit of 1 s: the first step,
    # a few ms idle, must finish within it on a loaded machine too)
    boxes = stacked_boxes(0.1)
    original = incremental.StepChecker.check

    def slow_second_step(self, assembly):
        if len(assembly.blocks) == 3:
            time.sleep(1.2)
        return original(self, assembly)

    monkeypatch.setattr(incremental.StepChecker, "check", slow_second_step)
    reports = check_sequence(boxes, CheckOptions(solve=SolveOptions(time_limit=1.0)))
    assert [r.status for r in reports] == [Status.STABLE, Status.SOLVER_FAILED]
    assert reports[1].message == "solver failed: time limit of 1 s exceeded in the solve stage"
    assert reports[1].step_index == 1 and reports[1].block_placed == "b"


def test_one_step_is_made_as_the_whole_list_makes_it():
    """sequence_step(k) (the cost of one step) against sequence_steps()[k], with holds and a
    release step after the last placement."""
    wall = gen.running_bond_wall(3, 3)
    last = wall.sequence[-1]
    scene = replace(wall, holds=(Hold(last, 0, len(wall.sequence)), Hold(wall.sequence[2], 1, 4)))
    steps = sequence_steps(scene)
    assert step_count(scene) == len(steps) == len(wall.sequence) + 1
    assert [sequence_step(scene, k) for k in range(len(steps))] == steps
    assert steps[-1].block == "" and last not in steps[-1].held and last in steps[-2].held
