"""No STABLE verdict for a field that stands only by prestress (rbe/prestress.py).

Closed forms on prisms in the xz plane (rigid blocks, Coulomb friction without dilatancy,
unstressed before gravity is applied): a bar touching two posts only on vertical faces falls
for any mu (no load presses its faces); on a base it stands; a wedge in a V that narrows
downward stands for any mu (its normal forces alone carry it: N = W / (2 sin a) per face
without friction); one in an opening that widens downward falls (gravity opens its faces;
the RBE field, feasible for mu > tan a, squeezes it); a block on an incline pressed by a
top bar stands exactly when tan(theta) <= mu (the bar carries nothing). compas_cra's samples
A, H, shelf and snake fall by its own CRA (``cra_solve``: infeasible), A, H and shelf by
LMGC90 too (issue 24; it cannot take snake's non-convex blocks: tests/test_lmgc90_reference.py).
"""
import functools
import math
from dataclasses import replace

import numpy as np
import pytest

from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.incremental import StepChecker
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.pipeline import check_scene, check_sequence
from rbe_ros.analysis import verdict as verdict_module
from rbe_ros.analysis.steps import gripped
from rbe_ros.analysis.verdict import check, is_stable
from rbe_ros.generators import _box, _prism, dome, running_bond_wall, two_blocks
from rbe_ros.io.compas import load_compas_assembly
from rbe_ros.rbe.model import build_model
from rbe_ros.rbe import prestress
from rbe_ros.rbe.prestress import squeeze, unopened
from rbe_ros.rbe.result import Status
from rbe_ros.rbe.solver import SolveOptions, solve
from rbe_ros.scene import make_scene

DENSITY = 2000.0
G = 9.81


def _quad(block_id, corners_xz, support=False):
    """A prism 1 m deep (y) over a quadrilateral in the xz plane."""
    return _prism(block_id, [(x, y, z) for y in (-0.5, 0.5) for x, z in corners_xz],
                  density=DENSITY, support=support)


def bar_between_posts(base: bool):
    blocks = [_quad("left", [(-0.7, 0), (-0.5, 0), (-0.5, 1), (-0.7, 1)], True),
              _quad("right", [(0.5, 0), (0.7, 0), (0.7, 1), (0.5, 1)], True),
              _quad("bar", [(-0.5, 0.4), (0.5, 0.4), (0.5, 0.6), (-0.5, 0.6)])]
    if base:
        blocks.append(_quad("base", [(-0.5, 0.0), (0.5, 0.0), (0.5, 0.4), (-0.5, 0.4)], True))
    return make_scene("bar between posts", blocks)


def wedge(angle_deg: float, narrowing: bool, height=0.5):
    """A trapezoid between two supports whose faces are ``angle_deg`` from the vertical."""
    s = height * math.tan(math.radians(angle_deg))
    top, bottom = (0.5, 0.5 - s) if narrowing else (0.5 - s, 0.5)
    z0, z1 = 0.5, 0.5 + height
    return make_scene("wedge", [
        _quad("wedge", [(-bottom, z0), (bottom, z0), (top, z1), (-top, z1)]),
        _quad("left", [(-bottom - 0.5, z0), (-bottom, z0), (-top, z1), (-top - 0.5, z1)], True),
        _quad("right", [(bottom, z0), (bottom + 0.5, z0), (top + 0.5, z1), (top, z1)], True)])


def incline_with_bar(incline_deg: float):
    """two_blocks' block on an incline, a support bar touching its horizontal top."""
    blocks = list(two_blocks(incline_deg=incline_deg).blocks)
    blocks.append(_box("bar", (-0.8, -0.5, 1.0), (0.8, 0.5, 1.2), density=DENSITY, support=True))
    return make_scene("incline with bar", blocks)


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
    assert "without prestress" in report.message and "block bar stands only squeezed" \
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


def _pairs(model, mask):
    return sorted(tuple(sorted((model.blocks[it.a].id, model.blocks[it.b].id)))
                  for it, m in zip(model.interfaces, mask) if m)


def test_the_dilation_leaves_closed_exactly_the_interfaces_a_squeeze_can_load():
    """A squeeze between the posts loads their vertical faces (a self-equilibrated
    compression: horizontal forces, equal and opposite); the base and the incline open."""
    posts = [("bar", "left"), ("bar", "right")]
    for scene, closed in ((bar_between_posts(False), posts), (bar_between_posts(True), posts),
                          (two_blocks(incline_deg=20.0), [])):
        model = _model(scene)
        assert _pairs(model, unopened(model, 0.6)) == closed
    for base in (True, False):                   # squeezable, yet the base holds it
        model = _model(bar_between_posts(base))
        found = squeeze(model, SolveOptions(mu=0.6), solve(model, SolveOptions(mu=0.6)))
        assert found is not None and found.stands == base


@pytest.mark.parametrize("scene", [running_bond_wall(10, 8), dome()], ids=["wall", "dome"])
def test_walls_and_domes_on_the_ground_have_every_interface_opened(scene):
    """The dilation settles them without a solve: the prestress test costs them nothing
    (docs/METHOD.md gives the measured share)."""
    model = _model(scene)
    assert not unopened(model, 0.6).any()
    assert squeeze(model, SolveOptions(mu=0.6), solve(model, SolveOptions(mu=0.6))) is None


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


def _held_dome_step(placed_in_ring: int):
    """The 8 x 5 dome with its first two rings and ``placed_in_ring`` blocks of the third,
    the last of them held by a robot's grip (as the planner holds the newest block)."""
    scene = dome(8, 5)
    full = Assembly.from_scene(scene)
    ring = [f"course3_slice{k:02d}" for k in range(placed_in_ring)]
    present = [b.id for b in scene.blocks if b.support or b.id.startswith(("course1",
                                                                           "course2"))]
    return gripped(full, present + ring, ring[-1:])


def _no_shortcut(model, shut):
    return np.full(len(shut), -1.0)     # a negative cap: that field never exists


@pytest.mark.parametrize("case", ["bar", "bar on base", "incline 15", "incline 35",
                                  "held ring 1", "held ring 2", "held ring 3"])
def test_a_field_without_friction_on_closed_interfaces_decides_as_the_whole_test(case,
                                                                                 monkeypatch):
    """The first solve of the test (friction resultant 0 on every closed interface, within
    any Tresca cap) gives the verdict of the test without it, in one solve where it has a
    field: beside the held block of a dome ring of one or three blocks it decides (2 solves
    in all: RBE's field and this one); with two the field needs friction there and the stick
    field decides (a third solve); on the squeezed bar neither can."""
    if case.startswith("held"):
        assembly = _held_dome_step(int(case[-1]))
    else:
        scene = {"bar": bar_between_posts(False), "bar on base": bar_between_posts(True),
                 "incline 15": incline_with_bar(15.0),
                 "incline 35": incline_with_bar(35.0)}[case]
        assembly = Assembly.from_scene(scene)
    calls = []
    counted = functools.partial(_counting, calls)
    monkeypatch.setattr(prestress, "solve", counted)
    monkeypatch.setattr(verdict_module, "solve", counted)
    with_shortcut = check(assembly, options(0.6))
    solves = len(calls)
    monkeypatch.setattr(prestress, "_least_caps", _no_shortcut)
    without = check(assembly, options(0.6))
    assert (with_shortcut.status, with_shortcut.stable) == (without.status, without.stable)
    expected = {"bar": False, "bar on base": True, "incline 15": True, "incline 35": False}
    if case in expected:
        assert with_shortcut.stable == expected[case]
    else:                       # the held ring stands
        assert with_shortcut.stable, with_shortcut.message
        assert (solves == 2) == (case != "held ring 2"), solves


def _counting(calls, *args, **kwargs):
    calls.append(kwargs.get("friction_cap") is not None)
    return solve(*args, **kwargs)


def test_a_grip_and_a_support_can_differ_beside_a_squeeze():
    """The stick field of a held block with a grip carries the robot's wrench at a cost, a
    support's for free: beside the held second block of the 8 x 5 dome's third ring the
    step stands with a grip and is squeezed with a support (README, holds)."""
    assembly = _held_dome_step(2)
    held = [g.block for g in assembly.grips]
    assert held == ["course3_slice01"]
    assert check(assembly, options(0.6)).stable
    as_support = check(assembly.subset([b.id for b in assembly.blocks], held), options(0.6))
    assert as_support.status == Status.FRICTION_EXCEEDED
    assert "without prestress" in as_support.message
