"""The equilibrium model, the solver and the verdict's rules against closed forms, written for
mutants that survived the rest of the suite (docs/MUTATION.md): known wrenches on a box,
sliding boxes on slopes (tan alpha), the sliding flags, failed solves, the names of
floating blocks and the CSC helper."""
import math
from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp

from rbe_ros.analysis import verdict
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.analysis.verdict import _flag_sliding, infeasible_report, stable_forces
from rbe_ros.geometry.contacts import ContactOptions
from rbe_ros.rbe.cones import pyramid_facets
from rbe_ros.rbe.model import build_model
from rbe_ros.rbe.resultants import interface_results
from rbe_ros.rbe.result import Status
from rbe_ros.rbe.solver import LoadMultipliers, Solution, SolveOptions, _Csc
from rbe_ros.generators import squeeze
from rbe_ros.scene import box_block, make_block, make_scene

from helpers import DENSITY, checked, inclined_block, stacked_boxes
from test_core_units import slopes_and_flat
from test_mass_properties import extrude, prism_faces

G = 9.81


def two_boxes_on_the_ground():
    return make_scene("two", [
        box_block("ground", (6, 2, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        box_block("a", (1, 1, 1), (-1.5, 0, 0.5), density=DENSITY),
        box_block("b", (1, 1, 1), (1.5, 0, 0.5), density=DENSITY)])


@pytest.mark.parametrize("force, mx, my", [(0.0, 0.0, 0.0), (3000.0, 0.0, 0.0),
                                           (2000.0, 500.0, -800.0)])
def test_a_known_wrench_moves_the_resultant_by_its_moment_over_the_normal_force(force, mx, my):
    """A downward force F and a moment (Mx, My) about b's centroid, on top of the weights:
    b's base carries N = m g + F at the centroid shifted by (My / N, -Mx / N) (moment
    balance about the centroid); a, not loaded, keeps m g at its own centroid."""
    assembly = Assembly.from_scene(two_boxes_on_the_ground())
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    b = [blk.id for blk in assembly.blocks].index("b")
    wrench = {b: np.array([0.0, 0.0, -force, mx, my, 0.0])}
    found = stable_forces(model, CheckOptions(), model.dead_load + model.wrench_load(wrench))
    assert found is not None
    by_block = {r.block_b: r for r in found[1]}
    weight = DENSITY * G
    n = weight + force
    assert by_block["b"].normal_resultant == pytest.approx(n, rel=1e-7)
    assert np.allclose(by_block["b"].centre_of_pressure, [1.5 + my / n, -mx / n, 0.0],
                       rtol=0, atol=1e-7)
    assert by_block["a"].normal_resultant == pytest.approx(weight, rel=1e-7)
    assert np.allclose(by_block["a"].centre_of_pressure, [-1.5, 0.0, 0.0], rtol=0, atol=1e-7)


def test_sliding_flags_every_interface_over_the_cone_even_under_a_higher_threshold():
    """Boxes on 20 and 25 deg slopes need mu >= tan 20 = 0.364 and tan 25 = 0.466: at
    mu 0.3 both slide, and both are flagged although the post-check threshold (2) flags
    neither; the box on flat ground is not."""
    report = checked(slopes_and_flat(), CheckOptions(SolveOptions(mu=0.3), mu_threshold=2.0))
    assert report.status == Status.FRICTION_EXCEEDED
    flags = {r.block_b: r.friction_exceeded for r in report.interfaces}
    assert flags == {"s20_box": True, "s25_box": True, "flat": False}
    ratios = {r.block_b: r.friction_ratio for r in report.interfaces}
    assert ratios["s20_box"] == pytest.approx(math.tan(math.radians(20)), rel=1e-6)
    assert ratios["s25_box"] == pytest.approx(math.tan(math.radians(25)), rel=1e-6)


def test_sliding_through_torsion_alone_flags_the_highest_ratio():
    """When the vertex cones fail while no resultant exceeds the capacity (torsion), the
    interface asking most friction is the one flagged; none for no interfaces."""
    results = [r for r in checked(slopes_and_flat()).interfaces]
    ratios = [0.2, 0.5, 0.1]
    results = [replace(r, friction_ratio=q, friction_exceeded=False)
               for r, q in zip(results, ratios)]
    flagged = _flag_sliding(results, 0.6)
    assert [r.friction_exceeded for r in flagged] == [False, True, False]
    assert [r.friction_exceeded for r in _flag_sliding(results, 0.15)] == [True, True, False]
    assert _flag_sliding([], 0.6) == []


def test_a_failed_solve_is_no_infeasibility_to_explain():
    """A solve out of time is a failure, not a proof that the assembly cannot stand."""
    options = CheckOptions(SolveOptions(time_limit=1e-9))
    assert infeasible_report(Assembly.from_scene(inclined_block(10.0)), options) is None


def test_a_glued_solve_that_fails_is_reported_as_failed(monkeypatch):
    """Boxes that tip (no equilibrium without tension, none with unlimited friction): when
    the glued friction+ solve that would show where fails, the report is SOLVER_FAILED with
    the solver's status, not a verdict."""
    real = verdict.solve

    def glue_fails(model, options, **kwargs):
        if options.friction == "plus":
            return Solution("failed", "MaxTime", np.zeros((4, model.num_vertices)), 0.0)
        return real(model, options, **kwargs)

    monkeypatch.setattr(verdict, "solve", glue_fails)
    report = infeasible_report(Assembly.from_scene(stacked_boxes(0.6)), CheckOptions())
    assert report.status == Status.SOLVER_FAILED
    assert report.message == "solver failed: MaxTime"


@pytest.mark.parametrize("mu, stands", [(0.3, False), (0.4, True)])
def test_stable_forces_solve_with_the_options_mu(mu, stands):
    """A box on a 20 deg slope needs mu >= tan 20 = 0.364, whatever the post-check threshold
    (2 here) would let through."""
    assembly = Assembly.from_scene(inclined_block(20.0))
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    found = stable_forces(model, CheckOptions(SolveOptions(mu=mu), mu_threshold=2.0))
    assert (found is not None) is stands
    if stands:
        assert found[1][0].friction_ratio == pytest.approx(math.tan(math.radians(20)), rel=1e-6)


@pytest.mark.parametrize("count, shown", [(5, "blocks f0, f1, f2, f3, f4 not"),
                                          (6, "blocks f0, f1, f2, f3, f4 and 1 more not")])
def test_five_floating_blocks_are_named_in_full_and_a_sixth_is_counted(count, shown):
    report = checked(make_scene("s", [
        box_block("ground", (20, 20, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        *[box_block(f"f{k}", (1, 1, 1), (3.0 * k, 0, 3.0), density=DENSITY)
          for k in range(count)]]))
    assert report.message == f"no equilibrium: {shown} connected to a support by any contact"


def test_a_diagonal_with_trailing_zeros_keeps_its_shape():
    d = np.array([1.0, 0.0, 2.0, 0.0])
    csc = _Csc.diagonal(d).tocsc()
    assert csc.shape == (4, 4) and (csc != sp.diags(d).tocsc()).nnz == 0


def test_interfaces_count_for_friction_from_a_hundredth_of_the_mean_free_weight():
    """With a declared pose uncertainty, |V|/N counts on interfaces carrying at least 1 % of
    the mean free block's weight (m g of the unit boxes, from their density); all count on
    design geometry and when nothing is free."""
    assembly = Assembly.from_scene(two_boxes_on_the_ground())
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    least = 0.01 * DENSITY * G
    results = [replace(r, normal_resultant=n) for r, n in
               zip(checked(two_boxes_on_the_ground()).interfaces * 2,
                   [least * 0.999, least, least * 1.001, 0.0])]
    uncertain = CheckOptions(contact=ContactOptions(pose_uncertainty_m=0.002))
    assert verdict._loaded(model, results, uncertain) == [False, True, True, False]
    assert verdict._loaded(model, results, CheckOptions()) == [True] * 4
    held = replace(model, free=model.free[:0])
    assert verdict._loaded(held, results, uncertain) == [True] * 4


@pytest.mark.parametrize("scene, message", [
    (lambda: make_scene("one", two_boxes_on_the_ground().blocks[:2]), "stable: 1 interface in"),
    (two_boxes_on_the_ground, "stable: 2 interfaces in")])
def test_the_stable_message_counts_its_interfaces(scene, message):
    assert checked(scene()).message.startswith(message + " compression, worst |V|/N 0.000")


def test_the_friction_message_names_the_cone_or_the_threshold():
    """Sliding beyond the cone (mu 0.3: both slopes slide) names the blocks that slide (the
    faster first: tan 25), the interfaces they slide across (the more loaded first: cos 20),
    the cone and mu; a
    solution within the cone over the threshold (mu 0.6, threshold 0.4) names the
    threshold; the worst interface is the 25 deg slope's (|V|/N = tan 25)."""
    slides = checked(slopes_and_flat(), CheckOptions(SolveOptions(mu=0.3)))
    assert slides.message == ("friction exceeded: blocks s25_box, s20_box would slide at"
                              " interface s20_slope|s20_box (and s25_slope|s25_box): |V|/N ="
                              " 0.364 there, more than the soc cone allows with mu 0.3")
    over = checked(slopes_and_flat(), CheckOptions(mu_threshold=0.4))
    assert over.message == ("friction exceeded: block s25_box would slide at interface"
                            " s25_slope|s25_box: |V|/N = 0.466 there, more than the threshold"
                            " 0.4")
    assert over.worst_friction_ratio == pytest.approx(math.tan(math.radians(25)), rel=1e-6)


def test_a_sliding_message_quotes_only_a_ratio_beyond_the_cone():
    """The pressed shelf: a board under a fixed block, against a wall, nothing below it.
    With unlimited friction its field carries the weight by shear on the wall (|V|/N there
    within mu 0.6: W / N) and balances the wall's push by shear on the block above, which
    gravity pulls the board away from (no normal force). The board slides down the wall;
    the message does not quote the wall's ratio as "more than the cone allows"."""
    scene = squeeze("shelf-pressed", overhang=0.5)
    report = check_scene(scene, CheckOptions(SolveOptions(mu=0.6)))
    assert report.status == Status.FRICTION_EXCEEDED and report.unstable_blocks == ("board",)
    assert report.message == ("friction exceeded: block board would slide at interface"
                              " wall|board: standing needs more friction than the soc cone"
                              " allows with mu 0.6")


def test_a_pair_meeting_at_two_interfaces_is_named_once():
    """compas_cra's snake: block 3 slides across two interfaces with block 2 (faces in two
    planes); the message read "at interface 2|3 (and 2|3)"."""
    from types import SimpleNamespace as NS
    model = NS(blocks=[NS(id=str(k)) for k in range(5)],
               interfaces=[NS(a=2, b=3), NS(a=2, b=3), NS(a=1, b=3), NS(a=0, b=4), NS(a=1, b=4),
                           NS(a=3, b=4)])
    assert verdict._motion(model, NS(moving=[3], sliding=[0, 1])) == \
        "block 3 would slide at interface 2|3"
    assert verdict._motion(model, NS(moving=[3, 4], sliding=[0, 1, 2, 3, 4, 5])) == \
        "blocks 3, 4 would slide at interface 2|3 (and 1|3, 0|4 and 2 more)"


def test_sliding_on_a_pyramid_cone_is_judged_against_its_capacity():
    """The inscribed 8-sided pyramid holds mu cos(pi/8) = 0.342 at mu 0.37: the 20 deg slope
    (tan 20 = 0.364) exceeds it, so both slopes are flagged (mu / cos(pi/8) would spare it)."""
    report = checked(slopes_and_flat(), CheckOptions(SolveOptions(mu=0.37, cone="pyramid8"),
                                                     mu_threshold=2.0))
    assert report.status == Status.FRICTION_EXCEEDED
    assert {r.block_b for r in report.interfaces if r.friction_exceeded} == {"s20_box",
                                                                            "s25_box"}


def test_a_failed_primary_solve_is_reported_with_the_solvers_status(monkeypatch):
    """Only the first (deciding) solve fails: the report is that failure, not an
    explanation from the solves after it; it counts the blocks as any other (set by check,
    and by the explained reports too)."""
    real, calls = verdict.solve, []

    def first_fails(model, options, **kwargs):
        calls.append(options)
        if len(calls) == 1:
            return Solution("failed", "NumericalError", np.zeros((4, model.num_vertices)), 0.0)
        return real(model, options, **kwargs)

    monkeypatch.setattr(verdict, "solve", first_fails)
    report = verdict.check(Assembly.from_scene(two_boxes_on_the_ground()), CheckOptions())
    assert report.status == Status.SOLVER_FAILED and len(calls) == 1
    assert report.message == "solver failed: NumericalError" and report.num_blocks == 3
    monkeypatch.undo()
    tips = infeasible_report(Assembly.from_scene(stacked_boxes(0.6)), CheckOptions())
    assert tips.num_blocks == 3 and tips.status == Status.TENSION_REQUIRED


def test_only_supports_are_stable_with_nothing_to_carry():
    report = check_scene(make_scene("bare", two_boxes_on_the_ground().blocks[:1]))
    assert report.status == Status.STABLE and report.interfaces == ()
    assert report.max_tension == 0.0 and report.worst_friction_ratio == 0.0
    assert report.message == "stable: 0 interfaces in compression, worst |V|/N 0.000 (mu 0.6)"


def test_unloaded_interfaces_do_not_decide_friction_under_a_pose_uncertainty(monkeypatch):
    """Two boxes on the ground, their results replaced: a's base carries its weight at
    |V|/N 0.1, b's next to nothing (below 1 % of the mean free weight) at 0.9, flagged by
    the threshold 0.6. Declared poses: stable, b's flag cleared, worst ratio a's 0.1;
    design poses: b's flag decides (FRICTION_EXCEEDED, worst 0.9); a's own flag (at 0.7)
    stands either way."""
    assembly = Assembly.from_scene(two_boxes_on_the_ground())
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    solution = verdict.solve(model)
    base = {r.block_b: r for r in checked(two_boxes_on_the_ground()).interfaces}
    crafted = [replace(base["a"], friction_ratio=0.1),
               replace(base["b"], normal_resultant=1.0, friction_ratio=0.9,
                       friction_exceeded=True)]
    monkeypatch.setattr(verdict, "interface_results", lambda *args, **kwargs: crafted)
    uncertain = CheckOptions(contact=ContactOptions(pose_uncertainty_m=0.002))
    report = verdict._report(model, solution, uncertain)
    assert report.status == Status.STABLE and report.worst_friction_ratio == 0.1
    assert [r.friction_exceeded for r in report.interfaces] == [False, False]
    design = verdict._report(model, solution, CheckOptions())
    assert design.status == Status.FRICTION_EXCEEDED and design.worst_friction_ratio == 0.9
    assert [r.friction_exceeded for r in design.interfaces] == [False, True]
    crafted[0] = replace(crafted[0], friction_ratio=0.7, friction_exceeded=True)
    loaded = verdict._report(model, solution, uncertain)      # a's own flag stands
    assert loaded.status == Status.FRICTION_EXCEEDED and loaded.worst_friction_ratio == 0.7
    assert [r.friction_exceeded for r in loaded.interfaces] == [True, False]


def test_the_tension_message_names_the_interface_needing_most():
    """Two overhanging stacks, 0.6 and 0.8 of the lower box's width: the upper boxes tip,
    the message's interface is the one of the larger overhang."""
    blocks = [*stacked_boxes(0.6).blocks,
              *[replace(b, id=f"{b.id}2", position=b.position + [5.0, 0, 0])
                for b in stacked_boxes(0.8).blocks]]
    report = checked(make_scene("two stacks", blocks))
    assert report.status == Status.TENSION_REQUIRED
    assert " at interface a2|b2 (" in report.message


@pytest.mark.parametrize("field, value, message", [
    ("objective", "ls", "objective must be one of qp, lp, not 'ls'"),
    ("friction", "glue", "friction must be one of net, plus, not 'glue'"),
    ("cone", "cube", "cone must be one of soc, pyramid8, pyramid8-outer, pyramid4, not 'cube'"),
    ("mu", 0.0, "friction coefficient mu must be positive, not 0.0"),
    ("mu", -0.5, "friction coefficient mu must be positive, not -0.5")])
def test_invalid_solve_options_name_the_field_and_the_choices(field, value, message):
    with pytest.raises(ValueError) as raised:
        SolveOptions(**{field: value})
    assert str(raised.value) == message
    assert SolveOptions(mu=0.5).mu == 0.5 and SolveOptions(mu=1.5).mu == 1.5


def test_a_box_on_a_slope_carries_tan_alpha_and_slides_against_a_smaller_mu():
    """A box on a 20 deg slope solved at mu 0.6: N = m g cos 20, |V| = m g sin 20; no
    tension even with a zero tolerance; read against mu 0.1 it slides (sin 20 > 0.1 cos 20
    by far more than the 1e-9 margin), against mu 0.4 it does not."""
    assembly = Assembly.from_scene(inclined_block(20.0))
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    solution = verdict.solve(model)
    weight = sum(b.mass for b in assembly.blocks if not b.support) * G
    assert solution.solver_status == "Solved" and solution.time > 0
    [r] = interface_results(model, solution, mu_threshold=math.inf, tension_tol=0.0, mu=0.1)
    assert r.normal_resultant == pytest.approx(weight * math.cos(math.radians(20)), rel=1e-7)
    assert np.linalg.norm(r.shear) == pytest.approx(weight * math.sin(math.radians(20)), rel=1e-6)
    assert r.tension is False and r.friction_exceeded is True
    [r] = interface_results(model, solution, mu_threshold=math.inf, tension_tol=1e-5, mu=0.4)
    assert r.friction_exceeded is False



@pytest.mark.parametrize("cone", ["soc", "pyramid4", "pyramid8"])
def test_the_lp_objective_spends_no_friction_on_self_equilibrated_shear(cone):
    """The LP objective (paper Eq. 16) prices each vertex's friction magnitude t, at least
    its tangential force in the cone's own norm (Euclidean, or the largest projection on the
    pyramid's facet normals): on a 20 deg slope, where the shear to carry is m g sin 20 and
    N = m g cos 20 whatever the spread, no friction is spent on shear that cancels out, so
    the vertices' magnitudes add up to the magnitude of their sum."""
    assembly = Assembly.from_scene(inclined_block(20.0))
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    solution = verdict.solve(model, SolveOptions(objective="lp", cone=cone))
    assert solution.solved
    weight = sum(b.mass for b in assembly.blocks if not b.support) * G
    shear = solution.forces[2][:, None] * model.u + solution.forces[3][:, None] * model.v
    assert np.linalg.norm(shear.sum(axis=0)) == pytest.approx(
        weight * math.sin(math.radians(20)), rel=1e-6)
    tangential = solution.forces[2:4].T                     # (fu, fv): one interface frame
    if cone == "soc":
        magnitude = np.linalg.norm(tangential, axis=-1)
    else:
        angles = pyramid_facets(cone)[0]
        magnitude = (tangential @ np.stack((np.cos(angles), np.sin(angles)))).max(axis=-1)
    total = tangential.sum(axis=0)
    assert magnitude.sum() == pytest.approx(
        np.linalg.norm(total) if cone == "soc" else
        (total @ np.stack((np.cos(angles), np.sin(angles)))).max(), rel=1e-6)
    assert solution.forces[0].sum() == pytest.approx(weight * math.cos(math.radians(20)),
                                                     rel=1e-6)


def _wedge_in_a_groove(slope_deg: float):
    """A wedge whose two faces rise at ``slope_deg`` from its lowest edge, 1 m deep, resting
    in a V-groove of two supports whose top faces are those faces."""
    a = 0.5
    h = a * math.tan(math.radians(slope_deg))
    wedge = [(-a, h), (0.0, 0.0), (a, h)]
    left, right = [(0.0, 0.0), (-a, h), (-a, -0.3), (0.0, -0.3)], \
        [(0.0, 0.0), (0.0, -0.3), (a, -0.3), (a, h)]
    blocks = []
    for bid, outline, support in (("wedge", wedge, False), ("left", left, True),
                                  ("right", right, True)):
        vertices = extrude(outline, 1.0)
        blocks.append(make_block(bid, vertices, prism_faces(vertices), density=DENSITY,
                                 support=support))
    return make_scene("groove", blocks)


@pytest.mark.parametrize("cone", ["soc", "pyramid4", "pyramid8"])
def test_the_lp_objective_prices_friction_in_a_groove(cone):
    """The LP objective (paper Eq. 16, unit weights) in a 30 deg V-groove: carrying the weight
    W by the faces' normal forces alone costs W / cos 30 = 1.155 W; leaning on friction at
    mu 0.6 costs (1 + mu) W / (cos 30 + mu sin 30) = 1.372 W. So the LP carries it without
    friction: N = W / (2 cos 30) on each face, no shear. (With friction priced lower, or not
    at all, friction would lower the cost and take part.)"""
    scene = _wedge_in_a_groove(30.0)
    options = CheckOptions(solve=SolveOptions(objective="lp", cone=cone))
    report = checked(scene, options)
    weight = sum(b.mass for b in Assembly.from_scene(scene).blocks if not b.support) * G
    assert report.status == Status.STABLE and len(report.interfaces) == 2
    for r in report.interfaces:
        assert r.normal_resultant == pytest.approx(weight / (2 * math.cos(math.radians(30))),
                                                   rel=1e-4)
        assert np.linalg.norm(r.shear) < 1e-4 * weight


def test_the_model_scales_are_the_free_weight_and_the_assembly_extent():
    """W: the free blocks' weight (m g of each unit box); L: the larger of the spread of the
    block centroids (3 m between the boxes, 1.5 m from a box to the ground's centre) and the
    largest block size (the ground's, the cube root of 6 x 2 x 0.2); a free 0.1 m box of
    0.1 kg weighs 0.981 N; held alone, it has its own size; 1 and 1 for nothing."""
    blocks = two_boxes_on_the_ground().blocks
    pebble = box_block("pebble", (0.1, 0.1, 0.1), (0, 0, 0.05), density=100.0)
    for scene_blocks, weight, length in ((blocks, 2 * DENSITY * G, 3.0),
                                         (blocks[:2], DENSITY * G, 1.5),
                                         (blocks[:1], 1.0, 2.4 ** (1 / 3)),
                                         ([blocks[0], pebble], 0.1 * G, 2.4 ** (1 / 3)),
                                         ([replace(pebble, support=True)], 1.0, 0.1)):
        assembly = Assembly.from_scene(make_scene("s", scene_blocks))
        model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
        assert model.force_scale == pytest.approx(weight, rel=1e-12)
        assert model.length_scale == pytest.approx(length, rel=1e-12)
    empty = build_model((), (), [0.0, 0.0, -G])
    assert (empty.force_scale, empty.length_scale) == (1.0, 1.0)


@pytest.mark.parametrize("size, mu, limit", [((1, 1, 2), 0.6, 0.5), ((1, 1, 0.5), 0.3, 0.3)])
def test_load_multipliers_are_the_tipping_or_sliding_limit_of_a_box(size, mu, limit):
    """A box on the ground under a horizontal live load lambda m g (in x and in -y): it
    tips at lambda = width / height or slides at lambda = mu, whichever comes first; one
    LoadMultipliers serves both loads and agrees with solve's load-multiplier problem."""
    scene = make_scene("box", [two_boxes_on_the_ground().blocks[0],
                               box_block("b", size, (0, 0, size[2] / 2), density=DENSITY)])
    assembly = Assembly.from_scene(scene)
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    options = SolveOptions(mu=mu)
    multipliers = LoadMultipliers(model, options)
    for direction in ([G, 0, 0], [0, -G, 0]):
        live = model.load(np.array(direction))
        found = multipliers(live)
        assert found.solved and found.multiplier == pytest.approx(limit, rel=1e-5)
        assert found.multiplier == pytest.approx(
            verdict.solve(model, options, live_load=live).multiplier, rel=1e-5)
        assert np.abs(model.a_eq @ found.forces.ravel() / model.force_scale
                      + model.dead_load + found.multiplier * live).max() < 1e-6
