"""Blocks set one at a time without pre-load (rbe/prestress.py): the placement test.

Closed forms on prisms in the xz plane (rigid blocks, Coulomb friction without dilatancy,
unstressed before gravity comes on; tests/placement_scenes.py): a bar touching two posts, or
two free pillars, only on vertical faces falls for any mu (no load presses its faces); on a
base it stands; a flat arch of three blocks with vertical joints falls for any mu, one whose
joints fan out stands; a wedge in a V that narrows downward stands for any mu (N = W /
(2 sin a) per face); one in an opening that widens downward falls; a block on an incline
pressed by a bar above it (its top horizontal or parallel to the incline) stands exactly when
tan(theta) <= mu (the bar carries nothing). compas_cra's samples A, H, shelf and snake fall by
its own CRA, A, H and shelf by LMGC90 too; type-b turned 90 deg about y stands (LMGC90 and
cra_solve). LMGC90's verdicts on the scenes here: tests/data/placement/lmgc90.json
(benchmarks/placement_lmgc90.py).
"""
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation
from trimesh.triangles import mass_properties

from placement_scenes import (bar_between_free_pillars, bar_between_leaning_posts,
                              bar_between_posts, flat_arch, incline_with_bar, leaning_block,
                              lmgc90_cases,
                              quad, rotated, wedged_flat_arch)
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.friction import minimum_friction
from rbe_ros.analysis.incremental import StepChecker
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.pipeline import check_scene, check_sequence
from rbe_ros.analysis.steps import gripped
from rbe_ros.analysis.verdict import check, is_stable
from rbe_ros.generators import _box, running_bond_wall, squeeze, two_blocks
from rbe_ros.io.compas import load_compas_assembly, rotated_as_example
from rbe_ros.io.inputs import load_design
from rbe_ros.rbe.model import Grip, build_model
from rbe_ros.rbe.prestress import accelerations, inertia_metric, placed
from rbe_ros.rbe.result import Status
from rbe_ros.rbe.solver import SolveOptions, solve
from rbe_ros.scene import make_scene

DATA = Path(__file__).parent / "data" / "placement"
DENSITY = 2000.0
G = 9.81


def wedge(angle_deg: float, narrowing: bool, height=0.5):
    """A trapezoid between two supports whose faces are ``angle_deg`` from the vertical."""
    s = height * math.tan(math.radians(angle_deg))
    top, bottom = (0.5, 0.5 - s) if narrowing else (0.5 - s, 0.5)
    z0, z1 = 0.5, 0.5 + height
    return make_scene("wedge", [
        quad("wedge", [(-bottom, z0), (bottom, z0), (top, z1), (-top, z1)]),
        quad("left", [(-bottom - 0.5, z0), (-bottom, z0), (-top, z1), (-top - 0.5, z1)], True),
        quad("right", [(bottom, z0), (bottom + 0.5, z0), (top + 0.5, z1), (top, z1)], True)])


def options(mu):
    return CheckOptions(solve=SolveOptions(mu=mu))


def rbe_alone_solves(scene, mu) -> bool:
    """Whether the plain RBE problem (the deciding solve, no prestress test) has a field."""
    a = Assembly.from_scene(scene)
    return solve(build_model(a.blocks, a.interfaces, a.gravity), options(mu).deciding).solved


def resultant(report, a, b):
    """Force (N, world) that block a exerts on block b at their interface."""
    for r in report.interfaces:
        if {r.block_a, r.block_b} == {a, b}:
            f = (r.normal_forces[:, None] * r.normal + r.tangential_forces).sum(axis=0)
            return f if r.block_a == a else -f
    raise AssertionError(f"no interface {a}|{b}")


@pytest.mark.parametrize("mu", [0.3, 0.84, 2.0, 10.0])
def test_bar_touching_posts_only_on_vertical_faces_falls_for_any_mu(mu):
    scene = bar_between_posts(base=False)
    assert rbe_alone_solves(scene, mu)             # RBE holds it by a horizontal squeeze
    report = check_scene(scene, options(mu))
    assert report.status == Status.FRICTION_EXCEEDED
    assert report.unstable_blocks == ("bar",)
    assert "without prestress" in report.message and "block bar would slide at interface" \
        in report.message
    assert not is_stable(Assembly.from_scene(scene), options(mu))


@pytest.mark.parametrize("mu", [0.3, 0.84, 2.0])
def test_bar_on_a_base_between_posts_stands_on_the_base(mu):
    """It stands; the reported field is RBE's QP optimum, which shares the weight between
    the base and the posts' friction (the test decides the verdict, not the field)."""
    report = check_scene(bar_between_posts(base=True), options(mu))
    assert report.status == Status.STABLE
    weight = DENSITY * 1.0 * 0.2 * G
    total = sum(resultant(report, s, "bar") for s in ("base", "left", "right"))
    assert total == pytest.approx([0, 0, weight], abs=1e-6 * weight)
    assert 0 < resultant(report, "base", "bar")[2] <= weight * (1 + 1e-9)


@pytest.mark.parametrize("angle", [5.0, 10.0, 20.0, 30.0, 45.0])
@pytest.mark.parametrize("mu", [0.3, 0.6, 1.0])
def test_wedge_narrowing_downward_is_wedged_by_gravity(angle, mu):
    scene = wedge(angle, narrowing=True)
    report = check_scene(scene, options(mu))
    assert report.status == Status.STABLE
    a = math.radians(angle)
    weight = DENSITY * 0.5 * (1.0 - 0.5 * math.tan(a)) * G
    up = sum(resultant(report, side, "wedge") for side in ("left", "right"))
    assert up == pytest.approx([0, 0, weight], abs=1e-6 * weight)
    for side, n in (("left", (math.cos(a), 0, math.sin(a))), ("right", (-math.cos(a), 0,
                                                                         math.sin(a)))):
        f = resultant(report, side, "wedge")
        normal = f @ np.array(n)
        assert normal > 0 and np.linalg.norm(f - normal * np.array(n)) <= mu * normal * (1 + 1e-6)


@pytest.mark.parametrize("angle", [5.0, 10.0, 20.0, 30.0, 45.0])
@pytest.mark.parametrize("mu", [0.3, 0.6, 1.0])
def test_wedge_widening_downward_falls(angle, mu):
    scene = wedge(angle, narrowing=False)
    squeezable = mu > math.tan(math.radians(angle)) + 1e-9    # RBE's field: friction > N tan a
    assert rbe_alone_solves(scene, mu) == squeezable
    report = check_scene(scene, options(mu))
    assert report.status == Status.FRICTION_EXCEEDED and report.unstable_blocks == ("wedge",)
    assert ("without prestress" in report.message) == squeezable


@pytest.mark.parametrize("theta", [15.0, 25.0, 35.0])
@pytest.mark.parametrize("mu", [0.4, 0.6])
def test_block_on_incline_pressed_by_a_top_bar_stands_only_within_the_friction_angle(theta, mu):
    scene = incline_with_bar(theta)
    report = check_scene(scene, options(mu))
    stands = math.tan(math.radians(theta)) <= mu
    assert report.stable == stands
    if stands:          # the bar carries nothing: the block's weight goes into the incline
        weight = DENSITY * 0.5 * G
        assert np.abs(resultant(report, "bar", "top")).max() < 1e-6 * weight
    else:
        assert report.unstable_blocks == ("top",)
    # RBE alone holds it squeezed when the wedge of angle theta between incline and bar is
    # self-locking: a self-stress with both contacts at the cone exists iff theta <= 2 atan(mu)
    squeezed = math.radians(theta) < 2 * math.atan(mu)
    assert rbe_alone_solves(scene, mu) == (stands or squeezed)


def _model(scene):
    a = Assembly.from_scene(scene)
    return build_model(a.blocks, a.interfaces, a.gravity)


def wall_with_squeezed_bar():
    """A 5 x 5 running-bond wall (x in [0, 2]) and, placed last, a bar between two support
    posts beside its end, touching only their vertical faces (and not the wall)."""
    wall = running_bond_wall(5, 5)
    bar = _box("bar", (2.2, -0.1, 0.2), (2.5, 0.1, 0.3), density=DENSITY)
    posts = [_box(f"post{k}", (x, -0.1, 0.0), (x + 0.2, 0.1, 0.5), density=DENSITY, support=True)
             for k, x in enumerate((2.0, 2.5))]
    return make_scene("wall and bar", list(wall.blocks) + posts + [bar],
                      sequence=list(wall.sequence) + ["bar"])


def test_step_checker_uses_the_same_criterion():
    """Sequence checks give the verdict of the full solve (at the bar's step the local
    regions of the 27-block wall, which apply the test through stable_forces, do not settle
    it): the wall stands at every step, the bar does not."""
    scene = wall_with_squeezed_bar()
    local = check_sequence(scene, options(0.6))
    full = check_sequence(scene, replace(options(0.6), full_solve=True))
    walls = len(scene.sequence) - 1
    assert [r.stable for r in local] == [r.stable for r in full] == [True] * walls + [False]
    assert local[-1].status == full[-1].status == Status.FRICTION_EXCEEDED
    assert StepChecker(options(0.6)).check(Assembly.from_scene(scene)).status \
        == Status.FRICTION_EXCEEDED


#: compas_cra's samples with the supports and mu of its example scripts; whether they stand
#: by compas_cra's CRA (cra_solve, run in .venv-compas: A, H, snake infeasible, shelf
#: restoration failed; cubes and type-a solved) and by LMGC90 for A, H and shelf (issue 24).
COMPAS = [("A", ["0", "1"], 0.84, False), ("H", ["0", "1"], 0.84, False),
          ("shelf", ["0"], 0.9, False), ("snake", ["0"], 0.7, False),
          ("cubes", ["0"], 0.84, True), ("type-a", ["0", "1"], 0.84, True),
          ("type-b", ["0", "1"], 0.84, True), ("type-c", ["0", "1"], 0.84, True),
          ("type-d", ["0", "1"], 0.84, True)]


@pytest.mark.parametrize("name, supports, mu, stands", COMPAS, ids=[c[0] for c in COMPAS])
def test_compas_cra_samples(samples, name, supports, mu, stands):
    scene = load_compas_assembly(samples / f"{name}.json", supports=supports)
    report = check_scene(scene, options(mu))
    assert report.stable == stands, report.message
    if not stands:
        assert report.status == Status.FRICTION_EXCEEDED and "without prestress" in report.message
        assert report.unstable_blocks and all(b in report.message for b in
                                               report.unstable_blocks[:5])
    if name == "shelf":         # the two blocks that move, not the six in the loop
        assert report.unstable_blocks == ("10", "9")


@pytest.mark.parametrize("cone", ["soc", "pyramid8", "pyramid4"])
def test_friction_cap_bounds_the_interface_friction_resultant(cone):
    """solve's friction_cap on a block on a 20 deg incline (two_blocks): the interface must
    carry W sin 20 along the slope, so a cap 1 % above that is feasible and 1 % below is
    not, whatever the vertex cones allow (mu 2 > tan 20); the cap is in the cone's norm (an
    inscribed pyramid's facets over its inradius), and the slope lies along a facet normal
    (0 deg) for every pyramid here."""
    model = _model(two_blocks(incline_deg=20.0))
    weight = DENSITY * 0.5 * G
    needed = weight * math.sin(math.radians(20.0))
    h = math.cos(math.pi / 8) if cone == "pyramid8" else 1.0
    options = SolveOptions(mu=2.0, cone=cone)
    assert solve(model, options, friction_cap=np.array([needed * 1.01 / h])).solved
    assert not solve(model, options, friction_cap=np.array([needed * 0.99 / h])).solved
    assert solve(model, options, friction_cap=np.array([math.inf])).solved


@pytest.mark.parametrize("cone", ["soc", "pyramid4"])
def test_normal_cap_bounds_the_interface_normal_resultant(cone):
    """solve's normal_cap on the same block: the interface must carry W cos 20 normal to
    the slope, so a cap 1 % above that is feasible (and met to the solver's accuracy) and
    1 % below is not."""
    model = _model(two_blocks(incline_deg=20.0))
    needed = DENSITY * 0.5 * G * math.cos(math.radians(20.0))
    options = SolveOptions(mu=2.0, cone=cone)
    found = solve(model, options, normal_cap=np.array([needed * 1.01]))
    assert found.solved and found.forces[0].sum() == pytest.approx(needed, rel=1e-6)
    assert not solve(model, options, normal_cap=np.array([needed * 0.99])).solved




@pytest.mark.parametrize("mu", [0.6, 0.84, 2.0])
def test_a_bar_between_free_pillars_falls_for_any_mu(mu):
    """Nothing presses the pillars onto the bar: no normal force, no friction (issue 29:
    the dilation gate let RBE's field stand, LMGC90's bar falls)."""
    report = check_scene(bar_between_free_pillars(), options(mu))
    assert report.status == Status.FRICTION_EXCEEDED and report.unstable_blocks == ("bar",)


@pytest.mark.parametrize("mu", [0.84, 1.2, 2.0])
def test_a_flat_arch_with_vertical_joints_falls_and_one_with_fanned_joints_stands(mu):
    """Every joint vertical: the three blocks slide down together, no joint closes. The
    joints fanned out 15 deg from the vertical wedge the key (LMGC90: both as here)."""
    report = check_scene(flat_arch(), options(mu))
    assert report.status == Status.FRICTION_EXCEEDED
    assert report.unstable_blocks == ("a", "b", "c")
    assert check_scene(wedged_flat_arch(), options(mu)).stable


@pytest.mark.parametrize("mu, stands", [(0.2, False), (0.5, False), (0.6, True), (0.7, True)])
def test_a_block_on_a_30_deg_incline_pressed_by_a_parallel_bar_stands_iff_mu_above_tan30(
        mu, stands):
    report = check_scene(incline_with_bar(30.0, parallel=True), options(mu))
    assert report.stable == stands
    if not stands:     # it slides on the incline, the bar's face alongside
        assert report.unstable_blocks == ("block",)
        assert "would slide at interface incline|block" in report.message


@pytest.mark.parametrize("mu", [0.6, 3.0])
def test_a_bar_between_leaning_posts_falls(mu):
    assert check_scene(bar_between_leaning_posts(20.0), options(mu)).status \
        == Status.FRICTION_EXCEEDED


def test_a_leaner_names_the_interface_that_slides():
    """A slab leaning on a wall at mu 0.1 slides at its foot on the ground (the most loaded
    sliding interface), not '|V|/N = inf at wall|leaner'."""
    report = check_scene(leaning_block(), options(0.1))
    assert report.status == Status.FRICTION_EXCEEDED and report.unstable_blocks == ("leaner",)
    assert "block leaner would slide at interface ground|leaner" in report.message
    assert "inf" not in report.message
    assert check_scene(leaning_block(), options(0.6)).stable


@pytest.mark.parametrize("mu", [5.0, 10.0])
def test_a_shelf_beyond_its_tipping_limit_falls_for_any_mu(mu):
    """The squeeze suite's shelf60: a board 0.6 m long on a 0.15 m corbel against a wall, a
    block on it over the corbel. The weights tip it about the corbel's edge (0.08 x 0.6 x
    0.15 against 0.06 x 0.075 per unit rho g depth) and the wall's face carries nothing
    without pre-load: falls for any mu (LMGC90: falls at 3, 5 and 10, tests/data/squeeze/
    variants). The frictionless first step pressed the wall (the board slides on its corbel
    towards it), and the caps of that step held the blocks still from mu 3.5 on; with the
    corbel's friction the board tips away from the wall, which the step from rest without
    friction at the wall shows, and the caps come down to it."""
    scene = squeeze("shelf", overhang=0.6)
    assert 0.08 * 0.6 * (0.3 - 0.15) > 0.06 * (0.15 - 0.075)          # it tips
    report = check_scene(scene, options(mu))
    assert rbe_alone_solves(scene, mu)          # a squeezed field holds it: RBE says stands
    assert report.status == Status.FRICTION_EXCEEDED, report.message
    assert "top" in report.unstable_blocks


@pytest.mark.parametrize("degrees", [90.0, -90.0])
@pytest.mark.parametrize("mu", [0.6, 0.84])
def test_type_b_turned_about_y_stands(samples, degrees, mu):
    """As compas_cra's example turns it: the load's moment presses the upper face (LMGC90
    and cra_solve stand; the stick field of the old gate carried that face by shear alone)."""
    scene = rotated(load_compas_assembly(samples / "type-b.json", supports=["0", "1"]),
                    (0, 1, 0), degrees)
    report = check_scene(scene, options(mu))
    assert report.stable, report.message


def penalty_motion(block, faces, gravity, mu, duration, stiffness=1e9, creep=1e-4):
    """An explicit simulation, independent of the solver: the block from rest on the
    support planes of ``faces`` [(its vertices there, the plane's normal, pushing along
    it)], each vertex a spring-dashpot contact (half-critical damping) with Coulomb friction
    regularised below ``creep`` m/s, rigid-body motion with trimesh's inertia of the block's
    mesh, semi-implicit Euler at 1/20 of the contact period. Returns the displacement (m)
    and the rotation (deg) after ``duration`` s."""
    inertia = np.asarray(mass_properties(block.vertices[block.triangles],
                                         density=block.mass / block.volume)["inertia"])
    mass = block.mass
    arms = np.array([q - block.centroid for points, _ in faces for q in points])
    normals = np.array([n for points, n in faces for _ in points])
    origins = block.centroid + arms
    damping = math.sqrt(stiffness * mass / len(arms))
    dt = 0.05 * math.sqrt(mass / stiffness)
    x, v, turn, w = np.zeros(3), np.zeros(3), np.eye(3), np.zeros(3)
    for _ in range(int(duration / dt)):
        r = arms @ turn.T
        velocity = v + np.cross(w, r)
        gap = np.einsum("ij,ij->i", block.centroid + x + r - origins, normals)
        closing = np.einsum("ij,ij->i", velocity, normals)
        normal = np.where(gap < 0, np.maximum(0.0, -stiffness * gap - damping * closing), 0.0)
        slip = velocity - closing[:, None] * normals
        speed = np.sqrt(np.einsum("ij,ij->i", slip, slip) + creep ** 2)
        force = normal[:, None] * normals - (mu * normal / speed)[:, None] * slip
        world = turn @ inertia @ turn.T
        v += dt * (np.asarray(gravity) + force.sum(axis=0) / mass)
        w += dt * np.linalg.solve(world, np.cross(r, force).sum(axis=0)
                                  - np.cross(w, world @ w))
        x += dt * v
        turn = Rotation.from_rotvec(w * dt).as_matrix() @ turn
    return np.linalg.norm(x), math.degrees(np.linalg.norm(Rotation.from_matrix(turn).as_rotvec()))


@pytest.mark.parametrize("mu, falls", [(0.84, True), (1.3, True), (2.5, False)])
def test_type_b_turned_about_xy30_falls_as_the_block_slides_out_of_its_self_locking_groove(
        samples, mu, falls):
    """compas_cra's type-b turned 90 deg about [sqrt 3, 1, 0] (its examples/05_wedge.py).
    The block lies on support 0's face, 64.3 deg steep (tan 2.08), under support 1's face,
    which gravity alone pulls it away from; the faces make a 60 deg groove, self-locking
    for mu > tan 30 (a squeeze holds the block there: RBE's field), but no load makes the
    squeeze. LMGC90 (docs/lmgc90_verdicts.json; 1.3 and 2.5 run by hand with
    ``rbe-ros check --second-opinion lmgc90``): at mu 0.84 it moves 1.6% of its size and
    0.75 deg in 0.1 s and falls, at 1.3 it falls, at 1.6 and above it jams within 1 cm and
    stands. An explicit penalty simulation (penalty_motion, trimesh's inertia) gives 1.7%
    and 0.7 deg at 0.1 s at mu 0.84 and 15% at 0.3 s (LMGC90 15%), 6% at 1.3, at 2.5 0.2%. The
    fixed point of the caps, started from none, crept instead into the squeeze (at 0.84 in
    12 steps): friction turns the block onto support 1's face, whose normal force raises the
    friction on support 0's, which raises it again, the caps growing by ever larger steps
    (at 0.84 from the fifth change, at 1.3 from the third); the test stops there: a loop of
    friction that feeds itself is a squeeze."""
    scene = rotated_as_example(load_compas_assembly(samples / "type-b.json",
                                                    supports=["0", "1"], density=2000.0),
                               [math.sqrt(3.0), 1.0, 0.0], 90.0)
    a = Assembly.from_scene(scene)
    model = build_model(a.blocks, a.interfaces, a.gravity)
    lower, upper = model.interfaces
    assert (lower.a, lower.b, upper.a, upper.b) == (0, 2, 1, 2)
    assert math.degrees(math.acos(lower.frame.n[2])) == pytest.approx(64.34, abs=0.01)
    assert math.degrees(math.acos(-lower.frame.n @ upper.frame.n)) == pytest.approx(60.0)
    block = model.blocks[2]
    faces = [(np.asarray(lower.points), lower.frame.n),
             (np.asarray(upper.points), upper.frame.n)]
    moved, _ = penalty_motion(block, faces, a.gravity, mu, 0.3)
    assert (moved > 0.01 * block.size) == falls
    if mu == 0.84:
        assert moved / block.size == pytest.approx(0.15, abs=0.01)
        moved, turned = penalty_motion(block, faces, a.gravity, mu, 0.1)
        assert moved / block.size == pytest.approx(0.016, abs=0.002)
        assert turned == pytest.approx(0.75, abs=0.1)
    assert rbe_alone_solves(scene, mu)
    report = check_scene(scene, options(mu))
    assert report.stable != falls, report.message
    if falls:
        assert report.status == Status.FRICTION_EXCEEDED and report.unstable_blocks == ("2",)


def test_our_verdicts_are_lmgc90s_on_the_scenes_it_ran(samples):
    """tests/data/placement/lmgc90.json (benchmarks/placement_lmgc90.py): every verdict but
    one agrees. The exception: the 30 deg incline pressed by a parallel bar at mu 0.5 stands
    in LMGC90 (its block jams between the planes within 1 s; rigid statics and ours: it
    slides, tan 30 = 0.577 > 0.5), the conservative side."""
    record = json.loads((DATA / "lmgc90.json").read_text())
    scenes = {(name, mu): scene for name, scene, mu in lmgc90_cases()}
    differ = []
    for case in record["cases"]:
        ours = check_scene(scenes[case["name"], case["mu"]], options(case["mu"])).stable
        if ours != case["stable"]:
            differ.append((case["name"], case["mu"], ours))
    assert len(record["cases"]) == 14
    assert differ == [("incline 30 pressed by a parallel bar", 0.5, False)]


@pytest.mark.parametrize("scene, mu_min", [(incline_with_bar(30.0, parallel=True),
                                            math.tan(math.radians(30.0))),
                                           (leaning_block(), None)], ids=["incline", "leaner"])
def test_min_friction_is_consistent_with_check(scene, mu_min):
    """check at mu just below the minimum friction fails, just above it stands; where a
    closed form exists (the incline: tan 30) it is that."""
    found = minimum_friction(Assembly.from_scene(scene))
    if mu_min is not None:
        assert found == pytest.approx(mu_min, abs=2e-4)
    assert not check_scene(scene, options(found * 0.995)).stable
    assert check_scene(scene, options(found * 1.005)).stable


def test_min_friction_of_a_bar_between_posts_is_infinite():
    assert minimum_friction(Assembly.from_scene(bar_between_posts())) == math.inf


def test_a_held_dome_block_beyond_its_capacity_is_hold_exceeded_with_the_wrench_it_needs():
    """tests/data/issue31/dome10x8_state40.json (issue 31): its held block, held still, is a
    support for the placement test; nothing leans on it, so the robot carries its weight,
    m g = 3084 N, torque 0 at the centroid (RBE's least field: 1163 N, the block resting and
    rubbing on its neighbours). Capped at 1200 N / 200 N m it is HOLD_EXCEEDED naming that
    wrench; with 1% more it stands, with 1% less it does not."""
    scene = load_design(DATA.parent / "issue31" / "dome10x8_state40.json")
    scene = scene[0] if isinstance(scene, tuple) else scene
    (hold,) = scene.holds
    block = next(b for b in Assembly.from_scene(scene).blocks if b.id == hold.block)
    free = check_scene(scene, CheckOptions())
    assert free.stable
    needed = np.linalg.norm(free.hold_wrenches[0].force)
    torque = np.linalg.norm(free.hold_wrenches[0].torque)
    assert needed == pytest.approx(block.mass * G, rel=1e-3) and torque < 1.0
    capped = check_scene(scene, CheckOptions(hold_force_max=1200.0, hold_torque_max=200.0))
    assert capped.status == Status.HOLD_EXCEEDED
    assert f"needs |F| {needed:.4g} N (capacity 1200 N)" in capped.message
    assert np.allclose(capped.hold_wrenches[0].force, free.hold_wrenches[0].force)
    assert check_scene(scene, CheckOptions(hold_force_max=0.99 * needed,
                                           hold_torque_max=200.0)).status == \
        Status.HOLD_EXCEEDED
    assert check_scene(scene, CheckOptions(hold_force_max=1.01 * needed,
                                           hold_torque_max=200.0)).stable


@pytest.mark.parametrize("slope, stands", [(0.45, True), (0.55, False), (1.2, False)])
def test_a_block_under_a_held_block_on_an_incline_stands_as_under_a_fixed_one(slope, stands):
    """A box F (1000 kg) on level ground under gravity tilted to the slope tan(theta), an
    equal box H on it held still by a robot (unbounded grip) or fixed (a support), mu 0.5.
    Set from rest F slides parallel to H's face: that contact gets no normal force, so F
    stands exactly when tan(theta) <= mu, and the robot carries H's weight, -m g (closed
    form, both ways). Before, the grip as a free block with the least wrench let H's weight
    rest on F and its friction hold F, up to tan(theta) = mu (1 + 2 m_H / m_F) = 1.5."""
    theta = math.atan(slope)
    gravity = G * np.array([math.sin(theta), 0.0, -math.cos(theta)])
    ground = _box("ground", (-1.5, -1.5, -0.2), (1.5, 1.5, 0), density=2000.0, support=True)
    low = _box("F", (-0.5, -0.5, 0), (0.5, 0.5, 0.5), density=2000.0)
    high = _box("H", (-0.5, -0.5, 0.5), (0.5, 0.5, 1.0), density=2000.0)
    full = Assembly.from_scene(make_scene("under_held", [ground, low, high], gravity))
    options = CheckOptions(solve=SolveOptions(mu=0.5))
    ids = {"ground", "F", "H"}
    held = check(gripped(full, ids, ("H",)), options)
    fixed = check(full.subset(ids, ("H",)), options)
    assert held.stable == fixed.stable == stands
    if stands:
        weight = 1000.0 * gravity
        np.testing.assert_allclose(held.hold_wrenches[0].force, -weight, atol=1e-3 * G * 1000)
        np.testing.assert_allclose(held.hold_wrenches[0].torque, 0.0, atol=1e-3 * G * 1000)
    else:
        assert held.status == fixed.status == Status.FRICTION_EXCEEDED
        assert held.unstable_blocks == fixed.unstable_blocks == ("F",)


def _beam_on_posts(gravity=(0.0, 0.0, -G), held_post=(0.0, 0.0)) -> Assembly:
    """A slab B (x in [-1, 0.6], 0.2 m thick, 640 kg) over a fixed post P (x in [-1, 0]) and
    a post H (x in [0, 1], 1 m cubes, 2000 kg) on the ground, to be held; ``held_post``:
    H's x and z from (0, 0) (a gap to P, to the ground)."""
    x, z = held_post
    blocks = [_box("ground", (-1.5, -1.5, -0.2), (1.5, 1.5, 0), density=2000.0, support=True),
              _box("P", (-1.0, -0.5, 0), (0.0, 0.5, 1.0), density=2000.0, support=True),
              _box("H", (x, -0.5, z), (1.0, 0.5, 1.0), density=2000.0),
              _box("B", (-1.0, -0.5, 1.0), (0.6, 0.5, 1.2), density=2000.0)]
    return Assembly.from_scene(make_scene("beam_on_posts", blocks, gravity))


@pytest.mark.parametrize("mu", [0.5, math.inf])
def test_a_beam_on_a_held_post_rests_on_the_fixed_one_and_the_robot_carries_its_post(mu):
    """B over P and H, H held still at its centroid: B's centroid is above P's face, so it
    stands on P alone, and of the fields the test accepts (no friction needed: caps 0),
    the least wrench carries H's weight alone, F = m_H g up, M = 0 (closed form), without
    a friction limit too (the test's, not the check's field: that one rests H on the
    ground and squeezes it against P). The field of least forces spreads B's weight over
    both posts and loads the robot with 2.76 kN and 637 N m more. Capacities 1% above H's
    weight and 1 N m stand."""
    step = gripped(_beam_on_posts(), {"ground", "P", "H", "B"}, ("H",))
    options = CheckOptions(solve=SolveOptions(mu=mu))
    report = check(step, options)
    assert report.stable
    weight = 2000.0 * G
    np.testing.assert_allclose(report.hold_wrenches[0].force, [0, 0, weight],
                               atol=1e-6 * weight)
    np.testing.assert_allclose(report.hold_wrenches[0].torque, 0.0, atol=1e-6 * weight)
    assert check(step, replace(options, hold_force_max=1.01 * weight,
                               hold_torque_max=1.0)).stable


@pytest.mark.parametrize("mu", [0.5, math.inf])
def test_a_beam_pinned_at_its_centroid_over_a_held_post_rests_on_neither(mu):
    """B pinned at its centroid, H held still: B's weight has no moment about the pin, so
    B neither turns nor moves and no contact closes: the pin carries m_B g = 6278 N (its
    reaction, not the least wrench, which would rest B on P), the robot m_H g, no torques
    (closed form; without a friction limit too)."""
    step = _beam_on_posts().subset({"ground", "P", "H", "B"}, {"H", "B"},
                                   (Grip("H"), Grip("B", max_torque=0.0)))
    report = check(step, CheckOptions(solve=SolveOptions(mu=mu)))
    assert report.stable
    held, pin = report.hold_wrenches
    assert (held.block, pin.block) == ("H", "B")
    np.testing.assert_allclose(held.force, [0, 0, 2000.0 * G], atol=1e-6 * 2000.0 * G)
    np.testing.assert_allclose(held.torque, 0.0, atol=1e-6 * 2000.0 * G)
    np.testing.assert_allclose(pin.force, [0, 0, 640.0 * G], atol=1e-3 * 640.0 * G)
    np.testing.assert_array_equal(pin.torque, 0.0)


def test_a_held_blocks_least_wrench_is_of_a_field_the_report_accepts():
    """The pyramid4 cone (|fu|, |fv| <= mu fn) with gravity tilted along the diagonal of B's
    faces (tan 0.3 each way: |V|/N 0.42 on level faces, within mu = 0.5), H held still in
    the air (clear of P and the ground): the least wrench the test admits rubs B on H at
    the pyramid's corner, |V|/N = sqrt 2 mu there, which the report's friction test (|V|
    Euclidean, whatever the cone) flags. So the check keeps the field that stands: its
    report is stable and the robot's wrench is what holds H against it (Newton on H from
    the reported forces; with the least's wrench the report would show RBE's forces)."""
    t = 0.3
    gravity = G * np.array([t, t, -1.0]) / math.sqrt(1 + 2 * t * t)
    step = gripped(_beam_on_posts(gravity, (0.05, 0.2)), {"ground", "P", "H", "B"}, ("H",))
    report = check(step, CheckOptions(solve=SolveOptions(mu=0.5, cone="pyramid4")))
    assert report.stable
    assert all(r.friction_ratio <= 0.5 * (1 + 1e-6) for r in report.interfaces)
    (wrench,) = report.hold_wrenches
    (joint,) = [r for r in report.interfaces if {r.block_a, r.block_b} == {"B", "H"}]
    on_h = (joint.normal_forces[:, None] * joint.normal + joint.tangential_forces) \
        * (1.0 if joint.block_b == "H" else -1.0)          # B's forces on H per vertex
    mass = 2000.0 * 0.95 * 0.8
    np.testing.assert_allclose(wrench.force + on_h.sum(axis=0) + mass * gravity, 0.0,
                               atol=1e-4 * mass * G)
    moment = np.cross(joint.polygon - wrench.grip_point, on_h).sum(axis=0)
    np.testing.assert_allclose(wrench.torque + moment, 0.0, atol=1e-4 * mass * G)
    assert np.linalg.norm(on_h.sum(axis=0)) > 0.1 * mass * G     # B leans on H


@pytest.mark.parametrize("slope, stands", [(0.45, True), (0.8, False)])
def test_a_block_under_a_pinned_block_on_an_incline_stands_as_under_a_fixed_one(slope, stands):
    """As above with H pinned at its centroid (torque capacity 0): its weight has no moment
    about the pin, so H neither turns nor moves, and F set from rest slides parallel to H's
    face: that contact gets no normal force. F stands exactly when tan(theta) <= mu = 0.5
    (at 0.8 it slides, a = g (sin - mu cos) = 0.23 g), and the pin carries H's weight, -m g,
    no torque (closed form). Before, the pin's force was a costed load and H's weight rested
    on F, whose friction held F beyond mu."""
    theta = math.atan(slope)
    gravity = G * np.array([math.sin(theta), 0.0, -math.cos(theta)])
    blocks = [_box("ground", (-1.5, -1.5, -0.2), (1.5, 1.5, 0), density=2000.0, support=True),
              _box("F", (-0.5, -0.5, 0), (0.5, 0.5, 0.5), density=2000.0),
              _box("H", (-0.5, -0.5, 0.5), (0.5, 0.5, 1.0), density=2000.0)]
    full = Assembly.from_scene(make_scene("under_pinned", blocks, gravity))
    pinned = full.subset({"ground", "F", "H"}, {"H"}, (Grip("H", max_torque=0.0),))
    report = check(pinned, CheckOptions(solve=SolveOptions(mu=0.5)))
    assert report.stable == stands
    if stands:
        np.testing.assert_allclose(report.hold_wrenches[0].force, -1000.0 * gravity,
                                   atol=1e-3 * G * 1000)
        np.testing.assert_array_equal(report.hold_wrenches[0].torque, 0.0)
    else:
        assert report.status == Status.FRICTION_EXCEEDED
        assert report.unstable_blocks == ("F",)


def _pinned_box(grip, wall_top: float, ground: bool, mu: float = 0.6) -> tuple:
    """A 0.6 x 0.5 x 0.4 m box (x in [0, 0.6], z in [z0, z0 + 0.4], 240 kg) touching a wall
    (a support, x < 0) with its left face, on the ground (z0 = 0) or hanging (z0 = 1),
    pinned at ``grip`` (relative to its top face's centre): (the check's report at ``mu``,
    m g, the box's interfaces by the other block's id)."""
    z0 = 0.0 if ground else 1.0
    blocks = [_box("wall", (-0.3, -0.5, 0.0), (0.0, 0.5, wall_top), density=DENSITY,
                   support=True),
              _box("box", (0.0, -0.25, z0), (0.6, 0.25, z0 + 0.4), density=DENSITY)]
    if ground:
        blocks.insert(0, _box("ground", (-1, -1, -0.2), (1, 1, 0), density=DENSITY,
                              support=True))
    full = Assembly.from_scene(make_scene("pinned_box", blocks))
    point = np.array([0.3, 0.0, z0 + 0.4]) + np.asarray(grip, dtype=float)
    ids = {b.id for b in blocks}
    report = check(full.subset(ids, {"box"}, (Grip("box", point, max_torque=0.0),)),
                   CheckOptions(solve=SolveOptions(mu=mu)))
    contacts = {(it.block_a if it.block_b == "box" else it.block_b): it
                for it in report.interfaces}
    return report, DENSITY * 0.6 * 0.5 * 0.4 * G, contacts


@pytest.mark.parametrize("mu", [0.6, math.inf])
def test_a_box_pinned_at_its_top_centre_rests_against_nothing(mu):
    """A box on the ground beside a wall, touching both, pinned at its top centre: its
    weight has no moment about the pin, so it neither turns nor moves, no contact closes,
    and the pin carries m g = 2354 N, no torque; the ground and the wall carry nothing
    (closed form; without a friction limit too). The least wrench would rest it on the
    ground (a wrench of 0)."""
    report, weight, contacts = _pinned_box((0.0, 0.0, 0.0), 1.0, ground=True, mu=mu)
    assert report.stable
    (w,) = report.hold_wrenches
    np.testing.assert_allclose(w.force, [0.0, 0.0, weight], atol=1e-3 * weight)
    np.testing.assert_array_equal(w.torque, 0.0)
    assert set(contacts) == {"ground", "wall"}
    for it in contacts.values():
        assert np.abs(it.normal_forces).sum() < 1e-3 * weight
        assert np.abs(it.tangential_forces).sum() < 1e-3 * weight


def test_a_box_pinned_off_its_centroid_turns_into_the_wall_beside_it():
    """The box hanging beside the wall, pinned on its top face d = 0.2 m left of its
    centroid: the weight's moment about the pin, m g d, turns it (its right side down), and
    its left face below the pin moves into the wall. Moments about the pin: the wall's
    normal force N at the bottom edge (lever b = 0.4 m below the pin; the top edge has
    none) balances it, N = m g d / b = m g / 2; frictionless at the first step, which
    leaves no motion. The pin: F = (-N, 0, m g), no torque (hand calculation)."""
    report, weight, contacts = _pinned_box((-0.2, 0.0, 0.0), 1.8, ground=False)
    assert report.stable
    (w,) = report.hold_wrenches
    normal = weight * 0.2 / 0.4
    np.testing.assert_allclose(w.force, [-normal, 0.0, weight], atol=1e-3 * weight)
    np.testing.assert_array_equal(w.torque, 0.0)
    (wall,) = contacts.values()
    assert wall.normal_forces.sum() == pytest.approx(normal, rel=1e-3)
    bottom = wall.polygon[:, 2] < 1.0 + 1e-9
    assert wall.normal_forces[bottom].sum() == pytest.approx(normal, rel=1e-3)
    assert np.abs(wall.tangential_forces).sum() < 1e-3 * weight


def test_the_step_from_rest_accelerates_a_frictionless_block_down_an_incline_at_g_sin():
    """The first step (no friction): the block on a 20 deg incline slides with g sin 20
    along it (closed form), the incline's normal force W cos 20."""
    scene = two_blocks(incline_deg=20.0)
    a = Assembly.from_scene(scene)
    model = build_model(a.blocks, a.interfaces, a.gravity)
    result = placed(model, SolveOptions(mu=0.1))
    assert not result.stands and result.moving == (1,)
    assert 0.1 < math.tan(math.radians(20.0))
    # mu 0.1: the slide is resisted by mu N: a = g (sin 20 - 0.1 cos 20)
    linear, angular = accelerations(model, result.motion)
    t = math.radians(20.0)
    expected = G * (math.sin(t) - 0.1 * math.cos(t))
    assert np.linalg.norm(linear[0]) == pytest.approx(expected, rel=1e-3)
    assert np.linalg.norm(angular[0]) < 1e-3


def test_the_inertia_of_a_box_is_trimeshs():
    """A box's inertia from its vertices over 3 (inertia_metric) against trimesh's."""
    box = _box("b", (0.0, 0.0, 0.0), (0.4, 0.2, 0.1), density=DENSITY)
    scene = make_scene("box", [_box("ground", (-1, -1, -0.1), (1, 1, 0), density=DENSITY,
                                    support=True), box])
    a = Assembly.from_scene(scene)
    model = build_model(a.blocks, a.interfaces, a.gravity)
    metric = inertia_metric(model).toarray() / 1e6
    block = model.blocks[1]
    inertia = trimesh.convex.convex_hull(block.vertices).moment_inertia * DENSITY
    mean = block.mass
    expected = mean * model.length_scale ** 2 * np.linalg.inv(inertia)
    assert metric[3:, 3:] == pytest.approx(expected, rel=1e-6)
