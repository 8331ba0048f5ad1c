"""The paper's method against closed forms: kern, tilting test, sliding and minimum friction."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.friction import minimum_friction
from rbe_ros.analysis.tilt import tilt_capacity
from rbe_ros.geometry.kern import kern
from rbe_ros.rbe.solver import SolveOptions
from rbe_ros.scene import box_block, make_scene

from helpers import DENSITY, inclined_block


def test_kern_of_rectangle_is_the_middle_third_rhombus():
    b, h = 3.0, 1.2
    rect = np.array([[-b / 2, -h / 2], [b / 2, -h / 2], [b / 2, h / 2], [-b / 2, h / 2]]) + [5.0, -2.0]
    k = kern(rect) - [5.0, -2.0]
    expected = {(-b / 6, 0.0), (0.0, -h / 6), (b / 6, 0.0), (0.0, h / 6)}
    assert len(k) == 4
    for p in k:
        assert min(np.hypot(p[0] - e[0], p[1] - e[1]) for e in expected) < 1e-12


def test_kern_of_64_gon_has_radius_quarter_r():
    r = 2.5
    t = np.arange(64) * 2 * np.pi / 64
    k = kern(np.column_stack((r * np.cos(t), r * np.sin(t))))
    assert np.allclose(np.linalg.norm(k, axis=1), r / 4, rtol=5e-3)


def test_kern_of_concave_polygon_is_that_of_its_hull():
    l_shape = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], dtype=float)
    hull = np.array([[0, 0], [2, 0], [2, 1], [1, 2], [0, 2]], dtype=float)
    assert np.allclose(np.sort(kern(l_shape), axis=0), np.sort(kern(hull), axis=0))


def block_on_base(b: float, h: float, yaw_deg: float = 0.0):
    q = Rotation.from_euler("z", yaw_deg, degrees=True).as_quat()
    return Assembly.from_scene(make_scene("tilt", [
        box_block("base", (6, 6, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        box_block("block", (b, b, h), (0.2, -0.1, h / 2), q, density=DENSITY),
    ]))


@pytest.mark.parametrize("b_over_h", [0.2, 0.5, 1.0, 1.5])
def test_tilt_capacity_of_a_block_is_atan_b_over_h(b_over_h):
    result = tilt_capacity(block_on_base(0.6 * b_over_h, 0.6), CheckOptions(SolveOptions(mu=10.0)))
    exact = math.degrees(math.atan(b_over_h))
    assert result.tilt_deg == pytest.approx(exact, abs=0.05)
    assert result.tilt_deg_multiplier == pytest.approx(exact, abs=0.05)
    assert result.multiplier == pytest.approx(b_over_h, rel=1e-5)


@pytest.mark.parametrize("yaw", [0.0, 10.0, 22.5, 45.0])
@pytest.mark.parametrize("direction", ["x", "-y"])
def test_flat_block_slides_at_atan_mu_with_the_exact_cone_at_any_yaw(yaw, direction):
    mu = 0.5
    result = tilt_capacity(block_on_base(1.0, 0.2, yaw), CheckOptions(SolveOptions(mu=mu)), direction)
    exact = math.degrees(math.atan(mu))
    assert result.tilt_deg == pytest.approx(exact, abs=0.05)
    assert result.tilt_deg_multiplier == pytest.approx(exact, abs=0.05)


def radial_extent(cone: str, phi: float) -> float:
    """Friction capacity of a pyramid in direction phi (rad from its first facet normal), per mu."""
    n, h = {"pyramid4": (4, 1.0), "pyramid8-outer": (8, 1.0),
            "pyramid8": (8, math.cos(math.pi / 8))}[cone]
    step = 2 * math.pi / n
    off = (phi + step / 2) % step - step / 2
    return h / math.cos(off)


@pytest.mark.parametrize("cone", ["pyramid4", "pyramid8-outer", "pyramid8"])
@pytest.mark.parametrize("yaw", [0.0, 22.5, 45.0])
def test_pyramid_cones_are_off_by_their_radial_extent(cone, yaw):
    """Documents the linearisation error: with the load at angle yaw to the contact axes a
    pyramid slides at atan(mu * r(yaw)) instead of atan(mu). At mu = 0.5 (26.57 deg exact):
    pyramid4 33.15 deg at 22.5 and 35.26 deg at 45; pyramid8-outer 28.44 deg at 22.5;
    pyramid8 (inscribed) 24.79 deg at 0 and 45."""
    mu = 0.5
    result = tilt_capacity(block_on_base(1.0, 0.2, yaw),
                           CheckOptions(SolveOptions(mu=mu, cone=cone)), "x")
    expected = math.degrees(math.atan(mu * radial_extent(cone, math.radians(yaw))))
    assert result.tilt_deg == pytest.approx(expected, abs=0.05)
    assert result.tilt_deg_multiplier == pytest.approx(expected, abs=0.05)


def test_minimum_friction_on_an_incline_is_tan_alpha():
    for alpha in (10.0, 23.6, 35.0):
        mu = minimum_friction(Assembly.from_scene(inclined_block(alpha)))
        assert mu == pytest.approx(math.tan(math.radians(alpha)), abs=1e-3)


def test_minimum_friction_is_infinite_when_the_block_tips():
    scene = make_scene("tip", [
        box_block("base", (4, 4, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        box_block("low", (1, 1, 1), (0, 0, 0.5), density=DENSITY),
        box_block("over", (1, 1, 1), (0.6, 0, 1.5), density=DENSITY),
    ])
    assert minimum_friction(Assembly.from_scene(scene)) == math.inf
