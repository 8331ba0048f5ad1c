"""The stability check on scenes with known answers (ROS-free core)."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rbe_ros.analysis.options import CheckOptions
from rbe_ros.rbe.result import Status
from rbe_ros.rbe.solver import SolveOptions
from rbe_ros.scene import box_block, make_scene

from helpers import DENSITY, G, checked, equilibrium_residual, inclined_block, stacked_boxes

TOP_WEIGHT = DENSITY * 1.0 * G


def top_interface(report):
    return next(r for r in report.interfaces if {r.block_a, r.block_b} == {"a", "b"})


def test_shift_45_percent_is_stable_with_resultant_under_centroid():
    scene = stacked_boxes(0.45)
    report = checked(scene)
    assert report.stable and report.status == Status.STABLE
    top = top_interface(report)
    assert top.normal_resultant == pytest.approx(TOP_WEIGHT, rel=1e-6)
    assert np.allclose(top.centre_of_pressure[:2], [0.45, 0.0], atol=1e-6)
    assert top.centre_of_pressure[2] == pytest.approx(1.0, abs=1e-9)
    assert np.linalg.norm(top.shear) < 1e-6 * TOP_WEIGHT
    assert report.max_tension < 1e-3
    assert equilibrium_residual(scene, report) < 1e-6


def test_shift_55_percent_needs_tension_at_the_named_interface():
    report = checked(stacked_boxes(0.55))
    assert not report.stable
    assert report.status == Status.TENSION_REQUIRED
    assert "a|b" in report.message
    assert report.unstable_blocks == ("b",)
    top = top_interface(report)
    assert top.tension and not top_interface(checked(stacked_boxes(0.45))).tension
    assert report.max_tension > 0.01 * TOP_WEIGHT


def test_verdict_and_forces_invariant_under_rigid_motion():
    base = stacked_boxes(0.3)
    rot = Rotation.from_euler("xyz", [20, -35, 70], degrees=True)
    shift = np.array([5.0, -2.0, 1.0])
    moved = []
    for b in base.blocks:
        q = (rot * Rotation.from_quat(b.orientation)).as_quat()
        moved.append(type(b)(b.id, b.vertices, b.faces, rot.apply(b.position) + shift, q,
                             b.density, b.mass, b.support))
    scene = make_scene("moved", moved, gravity=rot.apply(base.gravity))
    r0, r1 = checked(base), checked(scene)
    assert r1.status == r0.status == Status.STABLE
    n0 = sorted(r.normal_resultant for r in r0.interfaces)
    n1 = sorted(r.normal_resultant for r in r1.interfaces)
    assert np.allclose(n0, n1, rtol=1e-6)
    assert equilibrium_residual(scene, r1) < 1e-6


# capacity along a facet normal (the load here runs along an edge of the square interface)
FACET_CAPACITY = {"soc": 1.0, "pyramid8": math.cos(math.pi / 8), "pyramid8-outer": 1.0, "pyramid4": 1.0}


@pytest.mark.parametrize("cone", sorted(FACET_CAPACITY))
def test_block_on_incline_slides_beyond_tan_alpha(cone):
    alpha = 20.0
    mu_crit = math.tan(math.radians(alpha)) / FACET_CAPACITY[cone]
    scene = inclined_block(alpha)
    above = checked(scene, CheckOptions(SolveOptions(mu=mu_crit * 1.01, cone=cone)))
    below = checked(scene, CheckOptions(SolveOptions(mu=mu_crit * 0.99, cone=cone)))
    assert above.status == Status.STABLE
    assert below.status == Status.FRICTION_EXCEEDED
    assert "slope|box" in below.message and below.unstable_blocks == ("box",)


def test_friction_threshold_post_check():
    alpha = 20.0
    scene = inclined_block(alpha)
    ratio = math.tan(math.radians(alpha))
    ok = checked(scene, CheckOptions(SolveOptions(mu=0.8), mu_threshold=0.6))
    flagged = checked(scene, CheckOptions(SolveOptions(mu=0.8), mu_threshold=0.3))
    assert ok.stable and ok.worst_friction_ratio == pytest.approx(ratio, rel=1e-6)
    assert flagged.status == Status.FRICTION_EXCEEDED
    assert flagged.interfaces[0].friction_exceeded


def test_block_touching_nothing_is_infeasible_and_named():
    scene = make_scene("float", [
        box_block("ground", (2, 2, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        box_block("a", (1, 1, 1), (0, 0, 0.5), density=DENSITY),
        box_block("flying", (1, 1, 1), (0, 0, 3.0), density=DENSITY),
    ])
    report = checked(scene)
    assert report.status == Status.INFEASIBLE
    assert report.unstable_blocks == ("flying",) and "flying" in report.message


def test_yawed_box_contact_polygon_is_the_face_intersection():
    yaw = Rotation.from_euler("z", 45, degrees=True).as_quat()
    scene = make_scene("yaw", [
        box_block("ground", (4, 4, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        box_block("a", (1, 1, 1), (0, 0, 0.5), density=DENSITY),
        box_block("b", (1, 1, 1), (0, 0, 1.5), yaw, density=DENSITY),
    ])
    report = checked(scene)
    top = top_interface(report)
    assert len(top.polygon) == 8          # a square cut by a square turned 45 deg: an octagon
    assert report.stable and top.normal_resultant == pytest.approx(TOP_WEIGHT, rel=1e-6)
    assert np.allclose(top.centre_of_pressure, [0, 0, 1], atol=1e-6)


def test_lp_and_qp_resultants_agree_on_a_statically_determinate_stack():
    qp = checked(stacked_boxes(0.3))
    lp = checked(stacked_boxes(0.3), CheckOptions(SolveOptions(objective="lp")))
    assert lp.stable
    for a, b in zip(qp.interfaces, lp.interfaces):
        assert a.normal_resultant == pytest.approx(b.normal_resultant, rel=1e-6)
        assert np.allclose(a.centre_of_pressure, b.centre_of_pressure, atol=1e-6)
