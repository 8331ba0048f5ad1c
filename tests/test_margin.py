"""margin_g against closed forms: boxes of several aspect ratios, friction and yaw, towers,
a block on an incline (rbe_ros.analysis.margin)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rbe_ros import generators as gen
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.analysis.margin import horizontal_directions, hull_bounds, stability_margin
from rbe_ros.cli import main
from rbe_ros.io.messages import header_dict, report_from_dict, report_to_dict
from rbe_ros.rbe.model import build_model
from rbe_ros.rbe.solver import LoadMultipliers, SolveOptions, solve
from rbe_ros.rbe.result import Status
from rbe_ros.io.scene_json import load_scene
from rbe_ros.scene import box_block, make_scene

REL = 5e-3      # the bar: within 0.5%
ANGLES = 2 * np.pi * np.arange(8) / 8


def _box_on_ground(sx, sy, sz, yaw_deg):
    q = Rotation.from_euler("z", yaw_deg, degrees=True).as_quat()
    return make_scene("box", [
        box_block("ground", (6, 6, 0.2), (0, 0, -0.1), support=True, density=2000.0),
        box_block("box", (sx, sy, sz), (0.1, -0.2, sz / 2), orientation=q, density=2000.0)])


@pytest.mark.parametrize("sx, sy, sz, mu, yaw", [
    (1.0, 1.0, 2.0, 0.6, 0.0),      # tips along the axes (b/h = 0.5), slides on the diagonals
    (0.4, 1.0, 2.0, 0.6, 0.0),      # slender along x: b/h = 0.2
    (1.0, 0.6, 0.5, 0.6, 0.0),      # squat: slides everywhere (mu)
    (1.0, 0.6, 0.5, 1.5, 0.0),      # squat, high friction: tips (b/h 1.2 along y)
    (0.5, 1.2, 1.5, 0.8, 30.0),     # yawed: the half-width along d is that of the rectangle
    (0.8, 0.3, 1.0, 0.9, 65.0),
])
def test_box_margin_is_min_of_half_width_over_height_and_mu(sx, sy, sz, mu, yaw):
    assembly = Assembly.from_scene(_box_on_ground(sx, sy, sz, yaw))
    margin = stability_margin(assembly, SolveOptions(mu=mu), every_direction=True)
    rel = ANGLES - math.radians(yaw)
    with np.errstate(divide="ignore"):
        b = np.minimum(sx / 2 / np.abs(np.cos(rel)), sy / 2 / np.abs(np.sin(rel)))
    expected = np.minimum(b / (sz / 2), mu)
    np.testing.assert_allclose(margin.per_direction, expected, rtol=REL)
    assert margin.margin_g == pytest.approx(expected.min(), rel=REL)
    # directions that tie in the closed form are one minimum: the first of them is reported
    k = int(np.flatnonzero(np.isclose(expected, expected.min(), rtol=1e-9))[0])
    np.testing.assert_allclose(margin.direction, horizontal_directions((0, 0, -9.81))[k])
    assert np.linalg.norm(margin.direction) == pytest.approx(1.0)


@pytest.mark.parametrize("n, height, mu", [(2, 0.5, 0.6), (4, 0.4, 0.6), (6, 0.2, 0.5), (3, 0.1, 0.6)])
def test_tower_of_n_boxes_tips_at_its_base(n, height, mu):
    """n unit-wide boxes: the resultant of all of them, at height n h / 2 above the ground,
    leaves the base first: min(0.5 / (n h / 2), mu) along the axes."""
    assembly = Assembly.from_scene(gen.stack(n, width=1.0, depth=1.0, height=height))
    margin = stability_margin(assembly, SolveOptions(mu=mu))
    expected = min(0.5 / (n * height / 2), mu)
    assert margin.margin_g == pytest.approx(expected, rel=REL)
    assert margin.per_direction[0] == pytest.approx(expected, rel=REL)


def _incline_sliding(alpha: float, mu: float, theta: float) -> float:
    """Largest lambda before a block on a plane rising at ``alpha`` along x slides under the
    body force m g (lambda (cos theta, sin theta, 0) - z): |shear| = mu N, a quadratic."""
    ca, sa, ct, st = math.cos(alpha), math.sin(alpha), math.cos(theta), math.sin(theta)
    # (l ca ct - sa)^2 + (l st)^2 - mu^2 (ca + l sa ct)^2 = 0
    a2 = (ca * ct) ** 2 + st ** 2 - (mu * sa * ct) ** 2
    a1 = -2 * ca * ct * sa - 2 * mu ** 2 * ca * sa * ct
    a0 = sa ** 2 - (mu * ca) ** 2
    roots = np.roots([a2, a1, a0])
    return float(min(r.real for r in roots if abs(r.imag) < 1e-12 and r.real > 0))


@pytest.mark.parametrize("incline, mu", [(10.0, 0.6), (20.0, 0.5)])
def test_block_on_incline_slides_at_the_closed_form(incline, mu):
    """Downhill the closed form is tan(atan(mu) - alpha); every direction of the eight
    against the quadratic of the sliding condition."""
    assembly = Assembly.from_scene(gen.two_blocks(incline_deg=incline))
    margin = stability_margin(assembly, SolveOptions(mu=mu), every_direction=True)
    alpha = math.radians(incline)
    expected = np.array([_incline_sliding(alpha, mu, t) for t in ANGLES])
    np.testing.assert_allclose(margin.per_direction, expected, rtol=REL)
    assert margin.margin_g == pytest.approx(math.tan(math.atan(mu) - alpha), rel=REL)
    np.testing.assert_allclose(margin.direction, [-1.0, 0.0, 0.0], atol=1e-12)


def test_hull_bounds_of_a_square_and_a_rectangle():
    """Points on the axes at 1: a diagonal ray leaves the square's hull at 1 / sqrt(2).
    At (0.6, 0.1) the diagonal meets x / 0.6 + y / 0.1 = 1 at x = y = 0.6 / 7."""
    square = np.array([1.0, np.nan, 1.0, np.nan, 1.0, np.nan, 1.0, np.nan])
    np.testing.assert_allclose(hull_bounds(square)[1::2], 1 / math.sqrt(2))
    np.testing.assert_array_equal(hull_bounds(square)[::2], 1.0)
    wall = np.array([0.6, np.nan, 0.1, np.nan, 0.6, np.nan, 0.1, np.nan])
    np.testing.assert_allclose(hull_bounds(wall)[1::2], math.sqrt(2) * 0.6 / 7)
    one_side = np.array([1.0, np.nan, 1.0, np.nan, np.nan, np.nan, np.nan, np.nan])
    np.testing.assert_allclose(hull_bounds(one_side)[[1, 3, 4, 5, 6, 7]],
                               [1 / math.sqrt(2), 0, 0, 0, 0, 0])


@pytest.mark.parametrize("scene, solved", [
    (_box_on_ground(0.4, 1.0, 2.0, 0.0), 4),           # tips along x (0.2), y: 0.5
    (gen.running_bond_wall(10, 8), 4),                 # out of plane 0.2, in plane 0.6
    (gen.two_blocks(incline_deg=10.0), 6),             # uphill far from the minimum downhill
    (gen.stack(3), 8),                                 # slides at mu: a circle, every one
])
def test_skipped_directions_cannot_hold_the_minimum(scene, solved):
    """The margin with directions skipped by the hull bound equals the smallest of all eight
    solved one by one; every skipped direction's margin is at least that minimum."""
    assembly = Assembly.from_scene(scene)
    every = stability_margin(assembly, every_direction=True)
    fast = stability_margin(assembly)
    assert fast.margin_g == pytest.approx(every.per_direction.min(), rel=1e-9)
    np.testing.assert_array_equal(fast.direction, every.direction)
    skipped = np.isnan(fast.per_direction)
    assert np.count_nonzero(~skipped) == solved
    assert (every.per_direction[skipped] >= fast.margin_g).all()
    np.testing.assert_allclose(fast.per_direction[~skipped], every.per_direction[~skipped])


@pytest.mark.parametrize("cone", ["soc", "pyramid4", "pyramid8"])
def test_load_multipliers_equal_the_lambda_form(cone):
    """LoadMultipliers (s = 1 / lambda, the live load on the right-hand side, one solver for
    every load) against the load-multiplier problem stated with lambda, one solve per load:
    the same lambda and loads carried in equilibrium."""
    assembly = Assembly.from_scene(gen.running_bond_wall(4, 3))
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    options = SolveOptions(cone=cone, mu=0.5)
    multipliers = LoadMultipliers(model, options)
    for d in horizontal_directions(assembly.gravity, 5):
        live = model.load(9.81 * d)
        ours, reference = multipliers(live), solve(model, options, live_load=live)
        assert ours.solved and reference.solved
        assert ours.multiplier == pytest.approx(reference.multiplier, rel=1e-5)
        residual = model.a_eq @ (ours.forces / model.force_scale).ravel() + model.dead_load \
            + ours.multiplier * live
        assert np.abs(residual).max() < 1e-6


def test_cli_margin_per_step_in_json_and_message_dicts(tmp_path, capsys):
    """--margin: each step's margin_g is that of its partial assembly (a tower of k unit-wide
    boxes 2 m high: 0.5 / k), 0 once a step does not stand; the message dict keeps both."""
    scene = tmp_path / "stack.json"
    assert main(["generate", "stack", "-p", "n=3", "-p", "height=2.0", "-o", str(scene)]) == 0
    capsys.readouterr()
    assert main(["check", str(scene), "--sequence", "--margin", "--json"]) == 0
    steps = json.loads(capsys.readouterr().out)["reports"]
    for k, step in enumerate(steps):
        assert step["margin_g"] == pytest.approx(0.5 / (k + 1), rel=REL)
        assert abs(step["margin_direction"]["x"]) == pytest.approx(1.0) or \
            abs(step["margin_direction"]["y"]) == pytest.approx(1.0)
    report = check_scene(load_scene(scene), CheckOptions(margin_directions=8))
    back = report_from_dict(report_to_dict(report, header_dict("world", 0)))
    assert back.margin_g == report.margin_g == pytest.approx(0.5 / 3, rel=REL)
    np.testing.assert_array_equal(back.margin_direction, report.margin_direction)

    tipping = tmp_path / "tips.json"
    assert main(["generate", "two-blocks", "-p", "shift=0.6", "-o", str(tipping)]) == 0
    capsys.readouterr()
    assert main(["check", str(tipping), "--margin", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == Status.TENSION_REQUIRED and out["margin_g"] == 0.0
    assert main(["check", str(tipping), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["margin_g"] == -1.0      # not computed
