"""Verdicts against independent references: the arch's thrust-line LP and closed forms of the
virtual interfaces (paper Sec. 3.2.2, 3.3.2).

tests/oracles/arch_limit.py finds the exact limits of the semicircular arch by a thrust line
(no rbe_ros code). Its minimum thickness must be ours to 0.1 %, and kern-fitting, which
keeps every joint's resultant in the joint's kern (the middle third of a rectangular joint,
along the thrust line's plane), must match its LP with the thrust line in the middle third.
The base fittings are pinned on single prisms whose load line is known in closed form.
"""
import math

import numpy as np
import pytest

from rbe_ros import generators as gen
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.analysis.verdict import check
from rbe_ros.analysis.friction import minimum_friction
from rbe_ros.analysis.virtual import virtual_assembly
from rbe_ros.rbe.result import Status
from rbe_ros.rbe.solver import SolveOptions
from rbe_ros.scene import box_block, make_block, make_scene

from helpers import DENSITY, assert_physical
from oracles import arch_limit, plane_blocks
from test_mass_properties import extrude, prism_faces

MU = 0.6
OPTIONS = CheckOptions(SolveOptions(mu=MU))


@pytest.mark.parametrize("n", [15, 16])
def test_arch_minimum_thickness_is_the_thrust_line_limit_to_0_1_percent(n):
    t_min = arch_limit.minimum_thickness(n, MU)            # 0.106068 (15), 0.107076 (16)
    above = check_scene(gen.semicircular_arch(n, t_min * 1.001), OPTIONS)
    below = check_scene(gen.semicircular_arch(n, t_min * 0.999), OPTIONS)
    assert above.status == Status.STABLE, above.message
    assert below.status == Status.TENSION_REQUIRED, below.message
    assert_physical(gen.semicircular_arch(n, t_min * 1.001), above, MU)


@pytest.mark.parametrize("n, mu", [(7, 0.6), (9, math.inf), (12, 0.6)])
def test_the_two_arch_oracles_agree_on_the_minimum_thickness(n, mu):
    """The plane rigid-block LP (joint end forces, every voussoir's equilibrium) and the
    thrust-line LP (one symmetric thrust) are two formulations of the same arch: their
    minimum t/R agree to 1e-4 (bisection)."""
    lo, hi = 0.01, 0.5
    while hi - lo > 1e-5:
        mid = (lo + hi) / 2
        blocks, joints, supports = plane_blocks.semicircular_arch(n, mid)
        lo, hi = (lo, mid) if plane_blocks.stands(blocks, joints, set(blocks), supports,
                                                  mu) else (mid, hi)
    assert hi == pytest.approx(arch_limit.minimum_thickness(n, mu), abs=1e-4)


@pytest.mark.parametrize("n", [15, 16])
def test_arch_kern_fitting_is_the_thrust_line_in_the_middle_thirds(n):
    """The kern of a joint (a rectangle t x depth) is the rhombus whose diagonal along the
    thrust line's plane is the middle third of t: kern-fitting stands exactly when a thrust
    line runs within the middle third of every joint (the LP with band 1/3, 3.01 times the
    plain limit for n = 15: the weights are those of the full arch)."""
    t_kern = arch_limit.minimum_thickness(n, MU, band=1 / 3)     # 0.319426 (15)
    for ratio, expected in ((t_kern * 1.01, Status.STABLE), (t_kern * 0.99, Status.TENSION_REQUIRED)):
        scene = gen.semicircular_arch(n, ratio)
        report = check(virtual_assembly(Assembly.from_scene(scene), "kern-fitting"), OPTIONS)
        assert report.status == expected, (ratio, report.message)
        # the plain arch stands at both thicknesses: only the kern makes the difference
        assert check_scene(scene, OPTIONS).status == Status.STABLE


@pytest.mark.parametrize("ratio", [0.15, 0.3])
def test_arch_minimum_friction_is_the_thrust_line_limit(ratio):
    """0.348376 at t / R = 0.15, 0.308988 at 0.3 (thrust-line LP with |V| <= mu N: any
    admissible field). The minimum friction of blocks set in place without pre-load
    (rbe/prestress.py) is bounded below by it and within 3e-4 of it here (its fixed point
    near the limit)."""
    exact = arch_limit.minimum_friction(15, ratio)
    ours = minimum_friction(Assembly.from_scene(gen.semicircular_arch(15, ratio)), tol=1e-6)
    assert exact * (1 - 1e-6) <= ours <= exact * (1 + 1e-3)


def wedge_on_ground(p: float = 1.0, q: float = 0.8, depth: float = 1.0):
    """A right-triangle prism (legs p along x, q up) standing on its leg p on a support: its
    centroid, and so its load line, is at x = p / 3 from its vertical face (x = 0)."""
    vertices = extrude([(0, 0), (0, q), (p, 0)], depth) - [0.0, depth / 2, 0.0]
    wedge = make_block("wedge", vertices, prism_faces(vertices), density=DENSITY)
    return make_scene("wedge", [box_block("ground", (4, 4, 0.2), (0, 0, -0.1), support=True,
                                          density=DENSITY), wedge])


@pytest.mark.parametrize("factor, inner, outer", [
    (0.4, Status.STABLE, Status.TENSION_REQUIRED),
    (0.2, Status.TENSION_REQUIRED, Status.TENSION_REQUIRED),
    (0.7, Status.STABLE, Status.STABLE)])
def test_base_fitting_keeps_the_strip_at_the_inner_or_outer_edge(factor, inner, outer):
    """The wedge's load line is at p / 3 from its vertical face, the base edge nearest to it
    (the long edges' midpoints are at sqrt((p/6)^2 + (d/2)^2) = 0.53 p, the far edge at
    2p/3). Inner fitting keeps the strip of width factor p along x = 0: it holds the load line
    iff factor > 1/3; outer fitting keeps the strip along x = p: iff factor > 2/3."""
    scene = wedge_on_ground()
    assembly = Assembly.from_scene(scene)
    for side, expected in (("inner", inner), ("outer", outer)):
        report = check(virtual_assembly(assembly, f"{side}-base-fitting", factor), OPTIONS)
        assert report.status == expected, (side, factor, report.message)
        if expected == Status.STABLE:
            (it,) = report.interfaces
            assert it.centre_of_pressure[0] == pytest.approx(1 / 3, abs=1e-6)
            assert it.normal_resultant == pytest.approx(
                DENSITY * 9.81 * 0.5 * 1.0 * 0.8 * 1.0, rel=1e-6)


@pytest.mark.parametrize("s, expected", [(0.1, Status.STABLE), (-0.3, Status.TENSION_REQUIRED)])
def test_kern_fitting_of_a_trapezoidal_prism_is_the_middle_third_rule(s, expected):
    """Bottom [0, 1], top [s, s + 0.2]: the load line at x = (1.24 + 1.4 s) / 3.6, 0.383 for
    s = 0.1 (inside the middle third [1/3, 2/3] of the base) and 0.228 for s = -0.3 (outside,
    though inside the base: the plain check stands)."""
    vertices = extrude([(0, 0), (s, 0.7), (s + 0.2, 0.7), (1.0, 0)], 1.0) - [0.0, 0.5, 0.0]
    scene = make_scene("trapezoid", [
        box_block("ground", (4, 4, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        make_block("t", vertices, prism_faces(vertices), density=DENSITY)])
    assert check_scene(scene, OPTIONS).status == Status.STABLE
    report = check(virtual_assembly(Assembly.from_scene(scene), "kern-fitting"), OPTIONS)
    assert report.status == expected, report.message
    if expected == Status.STABLE:
        (it,) = report.interfaces
        assert it.centre_of_pressure[0] == pytest.approx((1.24 + 1.4 * s) / 3.6, abs=1e-6)
        assert_physical(scene, report, MU)


def test_max_thrust_moves_the_crown_resultants_to_the_intrados():
    """max-thrust shrinks the key-stone's joints to 10 % strips at their lowest edge: the
    resultants there sit in those strips, below the joints' mid-points (the thrust of the
    plain QP answer runs near the middle)."""
    scene = gen.semicircular_arch(15, 0.3)
    assembly = Assembly.from_scene(scene)
    report = check(virtual_assembly(assembly, "max-thrust"), OPTIONS)
    assert report.status == Status.STABLE, report.message
    key = [r for r in report.interfaces if "v07" in (r.block_a, r.block_b)]
    assert len(key) == 2
    t = 0.3
    for r in key:
        radius = math.hypot(r.centre_of_pressure[0], r.centre_of_pressure[2] - t)
        assert 1 - t / 2 - 1e-9 <= radius <= 1 - t / 2 + 0.1 * t + 1e-9
    assert_physical(scene, report, MU)
    plain = check(assembly, OPTIONS)
    crown = [r for r in plain.interfaces if "v07" in (r.block_a, r.block_b)]
    assert all(math.hypot(r.centre_of_pressure[0], r.centre_of_pressure[2] - t) > 1 - t / 2 + 0.1 * t
               for r in crown)
    assert np.isfinite([r.normal_resultant for r in crown]).all()
