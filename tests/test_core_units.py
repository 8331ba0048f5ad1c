"""Small parts of the core against their definitions, each written for mutants that survived
the rest of the suite (docs/MUTATION.md): the cones' facets, the verdict's messages and named
blocks, the sliding flags, kerns of several polygons, ring widths, renumbered interfaces,
a non-convex contact face and a solver that runs out of time."""
import math
from dataclasses import replace

import numpy as np
import pytest

from rbe_ros.analysis.assembly import Assembly
from rbe_ros.geometry.kern import kern, kerns
from rbe_ros.geometry.polygon import ring_widths
from rbe_ros.rbe.cones import cone_capacity, pyramid_facets
from rbe_ros.rbe.model import build_model
from rbe_ros.rbe.result import Status
from rbe_ros.rbe.solver import SolveOptions
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.verdict import infeasible_report, is_stable, stable_forces
from rbe_ros.scene import box_block, make_block, make_scene

from helpers import DENSITY, checked, inclined_block, stacked_boxes
from test_mass_properties import prism_faces


@pytest.mark.parametrize("cone, n, h", [("pyramid4", 4, 1.0), ("pyramid8-outer", 8, 1.0),
                                        ("pyramid8", 8, math.cos(math.pi / 8))])
def test_pyramid_facets_are_n_equal_angles_from_zero_with_their_inradius(cone, n, h):
    angles, inradius = pyramid_facets(cone)
    assert np.allclose(angles, 2 * math.pi * np.arange(n) / n, atol=1e-15)
    assert inradius == pytest.approx(h, abs=1e-15)
    assert cone_capacity(cone) == pytest.approx(h, abs=1e-15)


def test_exact_cone_has_full_capacity_and_no_facets():
    assert cone_capacity("soc") == 1.0
    with pytest.raises(ValueError, match="not a pyramid cone: 'soc'"):
        pyramid_facets("soc")


def ground(*blocks):
    return make_scene("s", [box_block("ground", (20, 20, 0.2), (0, 0, -0.1), support=True,
                                      density=DENSITY), *blocks])


def test_floating_blocks_are_named_in_full_up_to_five():
    one = checked(ground(box_block("f", (1, 1, 1), (0, 0, 3.0), density=DENSITY)))
    assert one.status == Status.INFEASIBLE
    assert one.message == "no equilibrium: block f not connected to a support by any contact"
    many = checked(ground(*[box_block(f"f{k}", (1, 1, 1), (3.0 * k, 0, 3.0), density=DENSITY)
                            for k in range(7)]))
    assert many.unstable_blocks == tuple(f"f{k}" for k in range(7))
    assert many.message == ("no equilibrium: blocks f0, f1, f2, f3, f4 and 2 more not connected"
                            " to a support by any contact")


def slopes_and_flat():
    """Boxes on a 20 deg and a 25 deg slope (they need mu >= 0.364 and 0.466) and a box on
    flat ground (it needs none), each on its own support."""
    blocks = []
    for name, alpha, x in (("s20", 20.0, 0.0), ("s25", 25.0, 8.0)):
        slope, box = inclined_block(alpha).blocks
        shift = np.array([x, 0.0, 0.0])
        blocks += [replace(slope, id=f"{name}_slope", position=slope.position + shift),
                   replace(box, id=f"{name}_box", position=box.position + shift)]
    return make_scene("slopes", [*blocks,
                                 box_block("flat_ground", (2, 2, 0.2), (-8, 0, -0.1), support=True,
                                           density=DENSITY),
                                 box_block("flat", (1, 1, 0.5), (-8, 0, 0.25), density=DENSITY)])


@pytest.mark.parametrize("mu, sliding", [(0.3, {"s20", "s25"}), (0.4, {"s25"})])
def test_exactly_the_sliding_interfaces_are_flagged(mu, sliding):
    report = checked(slopes_and_flat(), CheckOptions(SolveOptions(mu=mu)))
    assert report.status == Status.FRICTION_EXCEEDED
    flags = {(r.block_a, r.block_b): r.friction_exceeded for r in report.interfaces}
    assert flags == {("s20_slope", "s20_box"): "s20" in sliding,
                     ("s25_slope", "s25_box"): "s25" in sliding,
                     ("flat_ground", "flat"): False}
    assert report.unstable_blocks == tuple(sorted(f"{s}_box" for s in sliding))


def test_infeasible_report_explains_only_what_cannot_stand():
    """None for a standing assembly (and for one friction alone would hold, a question of the
    threshold); the explained report when the deciding problem has no solution."""
    options = CheckOptions(SolveOptions(mu=0.3))
    stands = Assembly.from_scene(inclined_block(10.0))
    assert infeasible_report(stands, options) is None
    slides = infeasible_report(Assembly.from_scene(inclined_block(20.0)), options)
    assert slides.status == Status.FRICTION_EXCEEDED and slides.unstable_blocks == ("box",)
    tips = infeasible_report(Assembly.from_scene(stacked_boxes(0.6)), options)
    assert tips.status == Status.TENSION_REQUIRED and tips.unstable_blocks == ("b",)
    floating = infeasible_report(Assembly.from_scene(make_scene("f", [
        box_block("ground", (4, 4, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        box_block("f", (1, 1, 1), (0, 0, 3.0), density=DENSITY)])), options)
    assert floating.status == Status.INFEASIBLE and floating.unstable_blocks == ("f",)


def test_the_block_that_tips_is_the_upper_one_whichever_is_listed_first():
    """The interface runs from the block listed first to the other: listing the upper box
    first turns its normal downwards, and the upper box must still be the one named."""
    for order in (("low", "top"), ("top", "low")):
        boxes = {"low": box_block("low", (1, 1, 1), (0, 0, 0.5), density=DENSITY),
                 "top": box_block("top", (1, 1, 1), (0.6, 0, 1.5), density=DENSITY)}
        report = checked(ground(*(boxes[k] for k in order)))
        assert report.status == Status.TENSION_REQUIRED
        assert report.unstable_blocks == ("top",), order


def test_a_block_hanging_under_a_support_is_the_one_that_falls():
    """Glued under a fixed slab it needs tension; the slab (the upper block) cannot move, so
    the hanging block is named."""
    scene = make_scene("hang", [
        box_block("ceiling", (3, 3, 0.2), (0, 0, 2.1), support=True, density=DENSITY),
        box_block("hanging", (1, 1, 1), (0, 0, 1.5), density=DENSITY)])
    report = checked(scene)
    assert report.status == Status.TENSION_REQUIRED
    assert report.unstable_blocks == ("hanging",)
    (it,) = report.interfaces
    assert -it.normal_resultant == pytest.approx(DENSITY * 9.81, rel=1e-6)   # pure tension


def test_kerns_of_several_polygons_are_each_polygons_kern():
    polys = [[[0, 0], [3, 0], [3, 3], [0, 3]], [[0, 0], [6, 0], [0, 6]],
             [[1, 0], [2, 1], [1, 2], [0, 1]], [[0, 0], [4, 0], [4, 1], [0, 1]]]
    out = kerns(polys)
    assert len(out) == 4
    for got, poly in zip(out, polys):
        assert np.allclose(got, kern(np.array(poly, dtype=float)))
    # the square's kern: the rhombus through the middle-third points (1, 1.5), (1.5, 1), ...
    assert sorted(map(tuple, np.round(out[0], 12))) == [(1.0, 1.5), (1.5, 1.0), (1.5, 2.0), (2.0, 1.5)]


def test_ring_widths_are_the_minimum_widths():
    """A 4 x 1 rectangle (a repeated vertex: a zero-length edge) is 1 wide; a triangle's
    width is its smallest height, 2 area / longest side."""
    rect = [[0, 0], [4, 0], [4, 0], [4, 1], [0, 1]]
    tri = [[0, 0], [5, 0], [1, 2]]
    widths = ring_widths(np.array(rect + tri, dtype=float), [5, 3])
    area = 0.5 * 5 * 2
    assert widths == pytest.approx([1.0, 2 * area / 5.0])                   # longest side: 5


def test_renumbered_interface_keeps_its_polygon_area_and_kern():
    it = Assembly.from_scene(inclined_block(10.0)).interfaces[0]
    moved = it.between(7, 3)
    assert (moved.a, moved.b) == (7, 3)
    assert moved.area == pytest.approx(1.0) and moved.area == it.area
    assert moved.kern is it.kern and moved.points is it.points


def test_a_non_convex_face_contact_is_the_whole_l():
    """An L-shaped prism (3 unit squares) on the ground: one interface of area 3, its
    resultant at the L's centroid (5/6, 5/6)."""
    ring = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], dtype=float)
    vertices = np.vstack([np.column_stack((ring, np.full(6, z))) for z in (0.0, 0.5)])
    scene = ground(make_block("L", vertices, prism_faces(vertices), density=DENSITY))
    assembly = Assembly.from_scene(scene)
    (it,) = assembly.interfaces
    assert it.area == pytest.approx(3.0)
    report = checked(scene)
    assert report.status == Status.STABLE
    assert np.allclose(report.interfaces[0].centre_of_pressure, [5 / 6, 5 / 6, 0.0], atol=1e-9)
    assert report.interfaces[0].normal_resultant == pytest.approx(1.5 * DENSITY * 9.81, rel=1e-9)


def test_a_solver_out_of_time_is_reported_as_failed():
    report = checked(inclined_block(10.0), CheckOptions(SolveOptions(time_limit=1e-9)))
    assert report.status == Status.SOLVER_FAILED
    assert report.message.startswith("solver failed: ")
    assert report.stable is False


def test_is_stable_is_the_verdict_without_its_explanation():
    options = CheckOptions(SolveOptions(mu=0.6))
    for scene, expected in ((stacked_boxes(0.3), True), (stacked_boxes(0.6), False),
                            (inclined_block(40.0), False)):
        assert is_stable(Assembly.from_scene(scene), options) is expected
    floating = make_scene("f", [
        box_block("ground", (4, 4, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        box_block("f", (1, 1, 1), (0, 0, 3.0), density=DENSITY)])
    assert is_stable(Assembly.from_scene(floating), options) is False


def test_stable_forces_take_the_load_and_the_options_given():
    """Twice the dead load gives twice the forces; a slope of 20 deg has none at mu 0.3 (the
    default 0.6 would hold it); friction+ that needs glue to stand is not stable."""
    assembly = Assembly.from_scene(inclined_block(20.0))
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    options = CheckOptions(SolveOptions(mu=0.6))
    once, _ = stable_forces(model, options)
    twice, results = stable_forces(model, options, 2.0 * model.dead_load)
    assert np.allclose(twice.forces, 2.0 * once.forces, atol=1e-6 * np.abs(once.forces).max())
    assert results[0].normal_resultant == pytest.approx(
        2.0 * DENSITY * 0.5 * 9.81 * math.cos(math.radians(20.0)), rel=1e-6)
    assert stable_forces(model, CheckOptions(SolveOptions(mu=0.3))) is None
    tipping = Assembly.from_scene(stacked_boxes(0.6))
    glued = build_model(tipping.blocks, tipping.interfaces, tipping.gravity)
    assert stable_forces(glued, CheckOptions(SolveOptions(friction="plus"))) is None
