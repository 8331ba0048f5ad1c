"""Insertion directions against closed forms (issue 22): the cone of a block on the ground,
in a corner, a keystone's wedge, a slot's axis, an enclosed block, a brick under a lintel;
the path check against an independent sampled sweep (trimesh's collision manager); a trapped
sequence and a plan that avoids it."""
from __future__ import annotations

import itertools
import json
import math
from dataclasses import replace

import numpy as np
import pytest
import shapely
import trimesh
from scipy.spatial import ConvexHull, Delaunay
from scipy.spatial.transform import Rotation

from rbe_ros import generators as gen
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.insertion import block_insertion, interface_normals
from rbe_ros.analysis.options import CheckOptions, InsertionOptions
from rbe_ros.analysis.pipeline import check_scene, check_sequence
from rbe_ros.analysis.validate import validate_assembly
from rbe_ros.analysis.planning import plan_sequence
from rbe_ros.cli import main
from rbe_ros.geometry import decompose
from rbe_ros.geometry import insertion as insertion_module
from rbe_ros.geometry.insertion import PathCheck, block_pieces, cone_directions, in_cone, shrunk
from rbe_ros.io.foxglove_scene import scene_update, x_onto
from rbe_ros.io.markers import ARROW, approach_markers, scene_meshes, step_markers
from rbe_ros.io.messages import scene_from_state_dict, state_to_dict
from rbe_ros.io.scene_json import scene_from_dict, scene_to_dict
from rbe_ros.io.table import approach_text, format_table
from rbe_ros.scene import SceneError, box_block, box_vertices, make_block, make_scene

from helpers import sweep_free

DOWN = np.array([0.0, 0.0, -1.0])
RHO = 2000.0


def _directions(count=4000, seed=1):
    d = np.random.default_rng(seed).normal(size=(count, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _cone(scene, block):
    """The interface normals into ``block`` from every other block of ``scene``."""
    assembly = Assembly.from_scene(scene)
    ids = [b.id for b in assembly.blocks]
    k = ids.index(block)
    others = np.ones(len(ids), dtype=bool)
    others[k] = False
    return interface_normals(assembly, k, others)


def _insertion(scene, block, **kw):
    assembly = Assembly.from_scene(scene)
    return block_insertion(assembly, [b.id for b in scene.blocks], block, CheckOptions(), **kw)


def _ground(*blocks):
    return make_scene("s", [box_block("ground", (4, 4, 0.2), (0, 0, -0.1), support=True,
                                      density=RHO), *blocks])


def test_block_on_ground_lower_half_space_and_straight_down():
    scene = _ground(box_block("b", (0.4, 0.2, 0.2), (0, 0, 0.1), density=RHO))
    normals = _cone(scene, "b")
    d = _directions()
    inside = np.array([in_cone(x, normals) for x in d])
    np.testing.assert_array_equal(inside, d[:, 2] <= 0)
    found = _insertion(scene, "b")
    assert found.insertable
    np.testing.assert_allclose(found.direction, DOWN, atol=1e-12)


def test_corner_down_and_never_through_the_wall():
    # wall at -x: the block may move towards it or along it, never come out of it (d_x > 0)
    scene = _ground(box_block("wall", (0.2, 2, 1), (-0.3, 0, 0.5), support=True, density=RHO),
                    box_block("b", (0.4, 0.2, 0.2), (0, 0, 0.1), density=RHO))
    normals = _cone(scene, "b")
    d = _directions()
    inside = np.array([in_cone(x, normals) for x in d])
    np.testing.assert_array_equal(inside, (d[:, 2] <= 0) & (d[:, 0] <= 0))
    found = _insertion(scene, "b")
    np.testing.assert_allclose(found.direction, DOWN, atol=1e-12)
    assert not _insertion(scene, "b", given=np.array([1.0, 0, -1])).insertable



def test_wall_off_vertical_within_the_angle_tolerance_keeps_down():
    """A block-high wall leaning 0.5 deg over the block (within the 1 deg contact tolerance):
    its normal points slightly down, so the exact cone's closest direction runs down along
    the wall's face, 0.5 deg off vertical, yet the block comes straight down (its path is free: the wall overhangs by less
    than the clearance)."""
    lean = math.radians(0.5)
    q = [0.0, math.sin(lean / 2), 0.0, math.cos(lean / 2)]
    scene = _ground(box_block("wall", (0.2, 2, 0.2), (-0.3, 0, 0.101), q, support=True,
                              density=RHO),
                    box_block("b", (0.4, 0.2, 0.2), (0, 0, 0.1), density=RHO))
    exact = cone_directions(_cone(scene, "b"), DOWN)[0]
    np.testing.assert_allclose(exact, [-math.sin(lean), 0, -math.cos(lean)], atol=1e-6)
    found = _insertion(scene, "b")
    np.testing.assert_allclose(found.direction, DOWN, atol=1e-12)


def _prism(block_id, outline, depth, caps=None, **kw):
    """A prism of the xz ``outline`` extruded over y in [-depth/2, depth/2], its faces
    turned outward whichever way the outline runs; ``caps``: the end faces as triangles of
    outline indices (a non-convex outline), else the outline itself."""
    n = len(outline)
    v = np.array([(x, -depth / 2, z) for x, z in outline] + [(x, depth / 2, z) for x, z in outline])
    caps = [tuple(range(n))] if caps is None else caps
    faces = [tuple(c) for c in caps] + [tuple(n + i for i in c[::-1]) for c in caps]
    faces += [(i, i + n, (i + 1) % n + n, (i + 1) % n) for i in range(n)]
    volume = sum(float(v[f[0]] @ np.cross(v[f[i]], v[f[i + 1]]))
                 for f in faces for i in range(1, len(f) - 1))
    if volume < 0:
        faces = [f[::-1] for f in faces]
    return make_block(block_id, v, faces, density=RHO, **kw)


def _keystone(a):
    """A keystone (bottom 0.2, height 0.3) between two voussoirs whose faces lean at +-a."""
    h, wb = 0.3, 0.2
    wt = wb + 2 * h * math.tan(a)
    key = [(-wb / 2, 0), (wb / 2, 0), (wt / 2, h), (-wt / 2, h)]
    left = [(-0.6, 0), (-wb / 2, 0), (-wt / 2, h), (-0.6, h)]
    right = [(wb / 2, 0), (0.6, 0), (0.6, h), (wt / 2, h)]
    return make_scene("keystone", [_prism("left", left, 0.3, support=True),
                                   _prism("right", right, 0.3, support=True),
                                   _prism("key", key, 0.3)])


@pytest.mark.parametrize("a_deg", [10.0, 25.0])
def test_keystone_exactly_the_wedge(a_deg):
    a = math.radians(a_deg)
    scene = _keystone(a)
    normals = _cone(scene, "key")
    assert len(normals) == 2
    phi = np.linspace(-math.pi, math.pi, 721)
    for p in phi:                   # in the xz-plane, p from straight down towards +x
        d = np.array([math.sin(p), 0.0, -math.cos(p)])
        if abs(abs(p) - a) > 1e-6:
            assert in_cone(d, normals) == (abs(p) < a), p
    found = _insertion(scene, "key")
    np.testing.assert_allclose(found.direction, DOWN, atol=1e-9)
    for p in (-0.9 * a, 0.9 * a):   # inside the wedge: the path is free too
        assert _insertion(scene, "key", given=np.array([math.sin(p), 0, -math.cos(p)])).insertable
    for p in (-1.3 * a, 1.3 * a):
        assert not _insertion(scene, "key",
                              given=np.array([math.sin(p), 0, -math.cos(p)])).insertable


def _slot(closed_ends=False):
    blocks = [box_block("left", (0.6, 0.2, 0.2), (0, -0.2, 0.1), support=True, density=RHO),
              box_block("right", (0.6, 0.2, 0.2), (0, 0.2, 0.1), support=True, density=RHO),
              box_block("top", (0.6, 0.6, 0.1), (0, 0, 0.25), support=True, density=RHO),
              box_block("b", (0.4, 0.2, 0.2), (0, 0, 0.1), density=RHO)]
    if closed_ends:
        blocks += [box_block("end1", (0.2, 0.6, 0.3), (0.3 + 0.0, 0, 0.15), support=True,
                             density=RHO),
                   box_block("end2", (0.2, 0.6, 0.3), (-0.3, 0, 0.15), support=True,
                             density=RHO)]
        blocks[0] = box_block("left", (0.4, 0.2, 0.2), (0, -0.2, 0.1), support=True, density=RHO)
        blocks[1] = box_block("right", (0.4, 0.2, 0.2), (0, 0.2, 0.1), support=True, density=RHO)
        blocks[2] = box_block("top", (0.4, 0.6, 0.1), (0, 0, 0.25), support=True, density=RHO)
    return _ground(*blocks)


def test_slot_only_its_axis():
    scene = _slot()
    normals = _cone(scene, "b")
    candidates = cone_directions(normals, DOWN)
    assert {tuple(np.round(c, 12)) for c in candidates} == {(1.0, 0, 0), (-1.0, 0, 0)}
    d = _directions()
    off_axis = np.abs(d[:, 0]) < 0.9999
    assert not any(in_cone(x, normals) for x in d[off_axis])
    found = _insertion(scene, "b")
    assert found.insertable and abs(found.direction[0]) == pytest.approx(1.0)


def test_enclosed_not_insertable():
    found = _insertion(_slot(closed_ends=True), "b")
    assert not found.insertable
    np.testing.assert_array_equal(found.direction, np.zeros(3))
    assert "enclosed" in found.reason


def _lintel(gap=0.05):
    """A brick on the ground between two pillars, under a lintel it does not touch."""
    return _ground(box_block("p1", (0.2, 0.4, 0.6), (-0.4, 0, 0.3), density=RHO),
                   box_block("p2", (0.2, 0.4, 0.6), (0.4, 0, 0.3), density=RHO),
                   box_block("lintel", (1.0, 0.4, 0.2), (0, 0, 0.7), density=RHO),
                   box_block("brick", (0.4, 0.2, 0.6 - gap), (0, 0, (0.6 - gap) / 2),
                             density=RHO))


def test_brick_under_lintel_refused_down_inserted_sideways():
    scene = _lintel()
    assembly = Assembly.from_scene(scene)
    brick = next(b for b in assembly.blocks if b.id == "brick")
    others = [b for b in assembly.blocks if b.id != "brick"]
    assert PathCheck(brick, others, 1.2, 0.002).blockers(DOWN) == ("lintel",)
    found = _insertion(scene, "brick")
    assert found.insertable
    assert found.direction[2] == pytest.approx(0.0, abs=1e-12)
    assert abs(found.direction[1]) == pytest.approx(1.0)     # the pillars close +-x
    assert _independent_sweep_free(scene, [b.id for b in scene.blocks], "brick",
                                   found.direction)
    assert not _independent_sweep_free(scene, [b.id for b in scene.blocks], "brick", DOWN)


def test_non_convex_neighbour_is_its_true_shape():
    """A block in the notch of a U-shaped neighbour (its caps triangulated) comes straight
    down, as the sampled sweep of the true shapes says (the U's hull would cover the notch),
    and not from the side (through an arm)."""
    u = [(-0.3, 0), (0.3, 0), (0.3, 0.3), (0.1, 0.3), (0.1, 0.1), (-0.1, 0.1), (-0.1, 0.3),
         (-0.3, 0.3)]
    caps = [(0, 1, 4), (0, 4, 5), (1, 2, 3), (1, 3, 4), (0, 5, 6), (0, 6, 7)]
    scene = make_scene("u", [_prism("u", u, 0.3, caps, support=True),
                             box_block("b", (0.2, 0.3, 0.2), (0, 0, 0.2), density=RHO)])
    assert _independent_sweep_free(scene, ["u", "b"], "b", DOWN)     # truly free
    found = _insertion(scene, "b")
    assert found.insertable
    np.testing.assert_allclose(found.direction, DOWN, atol=1e-12)
    side = _insertion(scene, "b", given=np.array([0.0, 0.6, -0.8]))
    assert side.insertable == _independent_sweep_free(scene, ["u", "b"], "b", [0, 0.6, -0.8])
    assert side.insertable      # along the open ends and down
    assert not _insertion(scene, "b", given=np.array([0.6, 0.0, -0.8])).insertable


def test_non_convex_moving_block_is_its_true_shape():
    """A non-convex moving block too: an inverted U coming down over a post that fits its
    notch comes straight down (its hull would sweep through the post), as the sampled sweep
    of the true shape says."""
    u = [(-0.3, 0.3), (-0.3, 0), (-0.1, 0), (-0.1, 0.2), (0.1, 0.2), (0.1, 0), (0.3, 0),
         (0.3, 0.3)]
    scene = _ground(box_block("post", (0.1, 0.3, 0.15), (0, 0, 0.075), support=True,
                              density=RHO),
                    _prism("u", u, 0.3, [(0, 1, 2), (0, 2, 3), (0, 3, 7), (3, 4, 7), (4, 5, 6),
                                         (4, 6, 7)]))
    assert _independent_sweep_free(scene, ["ground", "post", "u"], "u", DOWN)
    found = _insertion(scene, "u")
    assert found.insertable
    np.testing.assert_allclose(found.direction, DOWN, atol=1e-12)


def _independent_sweep_free(scene, present, block, direction, samples=40) -> bool:
    """The oracle: the block's mesh, scaled by 0.98 about its centroid, at sampled positions
    along its path over twice its longest extent, collides with no present mesh."""
    def mesh(b):
        posed = Assembly.from_scene(scene.subset([b.id])).blocks[0]
        tris = [(f[0], f[i], f[i + 1]) for f in b.faces for i in range(1, len(f) - 1)]
        return trimesh.Trimesh(posed.vertices, tris, process=False)
    manager = trimesh.collision.CollisionManager()
    for b in scene.blocks:
        if b.id in present and b.id != block:
            manager.add_object(b.id, mesh(b))
    moving = mesh(scene.block(block))
    centre = moving.vertices.mean(axis=0)
    moving.vertices = centre + 0.98 * (moving.vertices - centre)
    extent = float(np.max(np.ptp(moving.vertices, axis=0)))
    for t in np.linspace(0.0, 2.0 * extent / 0.98, samples):
        tf = np.eye(4)
        tf[:3, 3] = -t * np.asarray(direction)
        if manager.in_collision_single(moving, transform=tf):
            return False
    return True


def test_pocket_under_a_cap_blocked_by_the_cap():
    """A block in a pocket (walls on four sides) may only come down, and a cap above it that
    it does not touch blocks that path: not insertable, the cap named."""
    scene = _ground(box_block("b", (0.2, 0.2, 0.15), (0, 0, 0.075), density=RHO),
                    box_block("w1", (0.2, 0.6, 0.2), (-0.2, 0, 0.1), density=RHO),
                    box_block("w2", (0.2, 0.6, 0.2), (0.2, 0, 0.1), density=RHO),
                    box_block("w3", (0.2, 0.2, 0.2), (0, 0.2, 0.1), density=RHO),
                    box_block("w4", (0.2, 0.2, 0.2), (0, -0.2, 0.1), density=RHO),
                    box_block("cap", (0.6, 0.6, 0.1), (0, 0, 0.25), density=RHO))
    assert cone_directions(_cone(scene, "b"), DOWN) == [pytest.approx(DOWN)]
    found = _insertion(scene, "b")
    assert not found.insertable and found.blocked_by == ("cap",)
    assert found.reason == "1 direction blocked by cap"
    without_cap = scene.subset([b.id for b in scene.blocks if b.id != "cap"])
    np.testing.assert_allclose(_insertion(without_cap, "b").direction, DOWN)


def test_trapped_sequence_reported_and_planned_around():
    """A block placed after the four walls and the cap around it cannot get in; the planner
    orders it before them."""
    blocks = [box_block("b", (0.2, 0.2, 0.2), (0, 0, 0.1), density=RHO),
              box_block("w1", (0.2, 0.6, 0.2), (-0.2, 0, 0.1), density=RHO),
              box_block("w2", (0.2, 0.6, 0.2), (0.2, 0, 0.1), density=RHO),
              box_block("w3", (0.2, 0.2, 0.2), (0, 0.2, 0.1), density=RHO),
              box_block("w4", (0.2, 0.2, 0.2), (0, -0.2, 0.1), density=RHO),
              box_block("cap", (0.6, 0.6, 0.1), (0, 0, 0.25), density=RHO)]
    scene = _ground(*blocks)
    trapped = make_scene("trap", scene.blocks, sequence=["w1", "w2", "w3", "w4", "cap", "b"])
    reports = check_sequence(trapped)
    assert [r.insertable for r in reports] == [True] * 5 + [False]
    assert all(r.stable for r in reports)
    assert "not insertable: b" in reports[-1].message
    np.testing.assert_array_equal(reports[-1].insertion_direction, np.zeros(3))
    off = check_sequence(trapped, CheckOptions(insertion=InsertionOptions(enabled=False)))
    assert off[-1].insertable and not np.any(off[-1].insertion_direction)
    whole = check_scene(trapped)        # the whole assembly: its last block's insertion
    assert not whole.insertable
    plan = plan_sequence(trapped, max_held=0)
    assert plan.feasible, plan.message
    assert plan.order.index("b") < plan.order.index("cap")
    assert all(r.insertable for r in plan.reports)
    np.testing.assert_allclose(plan.scene.approach[plan.order.index("b")], DOWN, atol=1e-12)
    prefix = make_scene("trap", scene.blocks, sequence=["w1", "w2", "w3", "w4", "cap"])
    stuck = plan_sequence(prefix, max_held=0, keep_sequence=True)
    assert not stuck.feasible and stuck.failed_step == 5
    assert "b cannot be inserted: enclosed" in stuck.message, stuck.message
    # the planned scene's directions are checked, not chosen, when it is checked again
    again = check_sequence(plan.scene)
    for r, d in zip(again, plan.scene.approach):
        np.testing.assert_allclose(r.insertion_direction, d)


GENERATED = {
    "wall": lambda: gen.running_bond_wall(3, 3),
    "arch": lambda: gen.semicircular_arch(7),
    "buttressed arch": lambda: gen.buttressed_arch(7),
    "stack": lambda: gen.stack(4),
    "harmonic stack": lambda: gen.harmonic_stack(4),
    "dome": lambda: gen.dome(6, 2),
}


@pytest.mark.parametrize("name", sorted(GENERATED))
def test_plans_of_generated_scenes_are_insertable(name):
    """Every step of a plan is insertable along its reported direction, by the sampled
    sweep of the oracle."""
    scene = GENERATED[name]()
    plan = plan_sequence(scene, max_held=2)
    assert plan.reports
    for r in plan.reports:
        if not r.block_placed:
            continue
        assert r.insertable, r.message
        assert np.linalg.norm(r.insertion_direction) == pytest.approx(1.0)
        k = plan.order.index(r.block_placed)
        present = [b.id for b in plan.scene.blocks if b.support] + plan.order[:k + 1]
        assert _independent_sweep_free(plan.scene, present, r.block_placed,
                                       r.insertion_direction), r.block_placed


def test_given_approach_round_trips_scene_json_and_assembly_state():
    """A scene's "approach" survives the scene JSON and the AssemblyState dict (a zero vector
    there: choose), and the check keeps a given direction."""
    scene = _lintel()
    seq = ["p1", "p2", "lintel", "brick"]
    given = make_scene("g", scene.blocks, sequence=seq,
                       approach=[None, None, [0, 0, -2], [0, -1, 0]])
    for back in (scene_from_dict(scene_to_dict(given)),
                 scene_from_state_dict(state_to_dict(given))):
        assert back.approach[:2] == (None, None)
        np.testing.assert_allclose(back.approach[2], DOWN)
        np.testing.assert_allclose(back.approach[3], [0, -1, 0])
    reports = check_sequence(given)
    np.testing.assert_allclose(reports[3].insertion_direction, [0, -1, 0])
    refused = make_scene("g", scene.blocks, sequence=seq, approach=[None, None, None, DOWN])
    last = check_sequence(refused)[-1]
    assert not last.insertable and "the given approach blocked by lintel" in last.message
    with pytest.raises(SceneError, match="one entry per step"):
        make_scene("g", scene.blocks, sequence=seq, approach=[None])
    with pytest.raises(SceneError, match="non-zero"):
        make_scene("g", scene.blocks, sequence=seq, approach=[None, None, None, [0, 0, 0]])


def test_table_approach_column_and_marker_arrow():
    """The table says down / side / the vector / none, and the markers' arrow ends at the
    placed block's centre, pointing along its direction."""
    scene = make_scene("g", _lintel().blocks, sequence=["p1", "p2", "lintel", "brick"])
    reports = check_sequence(scene)
    assert [approach_text(r) for r in reports] == ["down", "down", "down", "side -y"]
    assert "approach" in format_table(reports).splitlines()[0]
    tilted = replace(reports[3], insertion_direction=np.array([0.6, 0.0, -0.8]))
    assert approach_text(tilted) == "(0.6, 0, -0.8)"
    off_axis = replace(reports[3], insertion_direction=np.array([-2.6e-7, -1.0, -2.9e-7]))
    assert approach_text(off_axis) == "side -y"             # compas_cra's shelf-s1, as found
    assert approach_text(replace(reports[3], insertable=False,
                                 insertion_direction=np.zeros(3))) == "none"
    header = {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "world"}
    (arrow,) = approach_markers(scene_meshes(scene), reports[3], header)
    assert arrow["type"] == ARROW and arrow["ns"] == "insertion"
    tail, tip = arrow["points"]
    np.testing.assert_allclose(tip, [0, 0, (0.6 - 0.05) / 2], atol=1e-9)     # the centre
    np.testing.assert_allclose((tip - tail) / np.linalg.norm(tip - tail),
                               reports[3].insertion_direction, atol=1e-12)
    assert scene_update(step_markers(scene, reports[3], header)).encode()      # Foxglove too


@pytest.mark.parametrize("d", [(0, 0, -1), (0, -1, 0), (-1, 0, 0), (1, 0, 0), (0.6, 0, -0.8)])
def test_foxglove_arrow_turns_x_onto_the_direction(d):
    """The Foxglove arrow's orientation turns its x axis onto the direction (checked with
    scipy's rotation, an independent computation)."""
    turned = Rotation.from_quat(x_onto(np.array(d, dtype=float))).apply([1.0, 0.0, 0.0])
    np.testing.assert_allclose(turned, d, atol=1e-12)


def test_shrunk_box_is_the_box_offset_inwards():
    """The clearance moves every face of a box in by exactly that much (closed form)."""
    corners = box_vertices((0.4, 0.2, 0.1)) + [1.0, 2.0, 3.0]
    inner = shrunk(corners, 0.01)
    np.testing.assert_allclose(np.sort(np.unique(np.round(inner - [1, 2, 3], 12), axis=0), 0),
                               np.sort(box_vertices((0.38, 0.18, 0.08)), 0), atol=1e-12)
    # capped at a quarter of the least face distance (here 0.05 / 4)
    np.testing.assert_allclose(np.ptp(shrunk(corners, 1.0), axis=0), [0.375, 0.175, 0.075])


def test_ten_thousand_vertex_block_comes_down():
    """A 10,000-vertex convex dome on the ground: straight down (the shrink and the path are
    linear in the hull's size, no vertex-by-face table)."""
    scene = gen.convex_domes(1)
    found = _insertion(scene, "dome0")
    assert found.insertable
    np.testing.assert_allclose(found.direction, DOWN, atol=1e-12)


def _declared(m=0.0, deg=0.0) -> CheckOptions:
    options = CheckOptions()
    return replace(options, contact=replace(options.contact, pose_uncertainty_m=m,
                                            pose_uncertainty_deg=deg))


def _as_built(scene, block, options):
    """The insertion of ``block`` with every block present, and whether the scene passes the
    interpenetration validation, both under ``options``' declared uncertainty."""
    assembly = Assembly.from_scene(scene, options.contact)
    try:
        validate_assembly(assembly, options.limits, options.contact)
        valid = True
    except SceneError:
        valid = False
    return block_insertion(assembly, [b.id for b in scene.blocks], block, options), valid


@pytest.mark.parametrize("overlap, m, insertable", [
    (0.03, 0.0, False),     # beyond 2 x penetration_tol x size = 0.02 m: invalid, and blocked
    (0.03, 0.02, True),     # within 0.01 + 2 x 0.02 declared: a contact, the path free
    (0.08, 0.02, False),    # beyond 0.02 + 2 x 0.02 too: invalid, and still blocked
])
def test_as_built_neighbour_overlapping_within_the_declaration_does_not_block(
        overlap, m, insertable):
    """Two 1 m cubes side by side on the ground overlapping by ``overlap`` (the dome's
    failure: neighbours overlapping by what their pose uncertainty explains blocked every
    path). The rule is the validation's: the pair may overlap by penetration_tol x 1 m plus
    each block's allowance (here m, no angle); the path check shrinks the moving block by
    2 x that design tolerance plus its allowance and the present one by its allowance, so a
    valid scene comes straight down and an invalid one stays blocked by the neighbour."""
    scene = _ground(box_block("a", (1, 1, 1), (0, 0, 0.5), density=RHO),
                    box_block("b", (1, 1, 1), (1 - overlap, 0, 0.5), density=RHO))
    found, valid = _as_built(scene, "b", _declared(m))
    assert valid == insertable
    assert found.insertable == insertable
    if insertable:
        np.testing.assert_allclose(found.direction, DOWN, atol=1e-12)
    else:
        assert found.blocked_by == ("a",)


def _overhang(a):
    """A 0.2 m high block under a support whose shared face leans ``a`` over it (the
    interface normal into the block points down by ``a``)."""
    t = 0.2 * math.tan(a)
    ground = box_block("ground", (4, 4, 0.2), (0, 0, -0.1), support=True, density=RHO)
    return make_scene("overhang", [
        ground, _prism("wall", [(-0.2, 0), (0, 0), (t, 0.2), (-0.2, 0.2)], 0.3, support=True),
        _prism("b", [(0, 0), (0.4, 0), (0.4, 0.2), (t, 0.2)], 0.3)])


def test_overhang_within_the_declared_angle_comes_straight_down():
    """The face leans 2 deg, beyond the 1 deg design tolerance: by design the block slides
    in along the face, 2 deg off vertical (the cone's closest direction); with 1 deg declared
    the contact detection takes faces up to 1 + 2 x 1 = 3 deg from opposite as facing and the
    cone the same, so down is feasible, and its path is free: the wall's corner overhangs by
    0.2 m x sin 2 deg = 7.0 mm, less than 2 x 0.01 x size 0.288 m plus the two allowances
    (1 deg x radius: 4.7 mm and 3.6 mm). 4 deg (beyond 3) keeps the slide along the face."""
    lean = math.radians(2.0)
    along = [-math.sin(lean), 0, -math.cos(lean)]
    design, _ = _as_built(_overhang(lean), "b", _declared())
    np.testing.assert_allclose(design.direction, along, atol=1e-9)
    declared, valid = _as_built(_overhang(lean), "b", _declared(deg=1.0))
    assert valid
    np.testing.assert_allclose(declared.direction, DOWN, atol=1e-12)
    steep = math.radians(4.0)
    beyond, _ = _as_built(_overhang(steep), "b", _declared(deg=1.0))
    np.testing.assert_allclose(beyond.direction, [-math.sin(steep), 0, -math.cos(steep)],
                               atol=1e-9)


# ---------------------------------------------------------------- non-convex closed forms
# (issue 28): polycube blocks, every face axis-aligned, against a sampled sweep of the true
# meshes (trimesh's collision manager) whose moving mesh is offset inward exactly

VOXEL = 0.1
LATTICE = [np.array(v, dtype=float) / np.linalg.norm(v)
           for v in itertools.product((-1, 0, 1), repeat=3) if any(v)]


def _sweep_free(scene, block_id, direction, distance=None, step=0.004) -> bool:
    """The oracle (:func:`helpers.sweep_free`): the block's true mesh, faces moved in by
    0.5 mm, at positions every ``step`` m along its path (from where it is clear of every
    other block's bounding box along the direction, or over ``distance``) collides with no
    other block's true mesh."""
    others = [b.id for b in scene.blocks if b.id != block_id]
    return sweep_free(Assembly.from_scene(scene), others, block_id, direction, spacing=step,
                      distance=distance)


def _free_of_lattice(scene, block_id, options=CheckOptions()):
    """The lattice directions (26: axes, face and body diagonals) along which the block can
    come in, by our check (each given in turn) and by the oracle."""
    assembly = Assembly.from_scene(scene)
    present = [b.id for b in scene.blocks]
    ours = {tuple(np.round(d, 6)) for d in LATTICE
            if block_insertion(assembly, present, block_id, options, given=d).insertable}
    oracle = {tuple(np.round(d, 6)) for d in LATTICE if _sweep_free(scene, block_id, d)}
    return ours, oracle


def _axes(*vectors):
    return {tuple(np.round(np.array(v, dtype=float) / np.linalg.norm(v), 6)) for v in vectors}


def _cells(nx, ny, nz, minus=()):
    return [c for c in itertools.product(range(nx), range(ny), range(nz)) if c not in minus]


def _polycube_scene(name, parts):
    return make_scene(name, [gen.polycube(b, cells, VOXEL, support=support)
                             for b, cells, support in parts])


def test_l_block_in_an_l_notch_exactly_the_notchs_open_axes():
    """An L prism set into an L-shaped notch cut through a base (open along y, its foot
    under the base's overhang): interfaces +-x, +-z, so the cone is the line +-y, and the
    true shapes leave exactly the notch's open axes +-y (the bar is open upwards, the foot
    is not); the base's hull would cover the notch."""
    notch = [(1, y, z) for y in range(3) for z in (1, 2, 3)] + \
        [(x, y, 1) for x in (2, 3) for y in range(3)]
    scene = _polycube_scene("l-notch", [("base", _cells(5, 3, 4, notch), True),
                                        ("l", notch, False)])
    ours, oracle = _free_of_lattice(scene, "l")
    assert oracle == _axes((0, 1, 0), (0, -1, 0))
    assert ours == oracle
    found = _insertion(scene, "l")
    assert found.insertable and abs(found.direction[1]) == pytest.approx(1.0)


def test_tetromino_in_a_planar_wall_along_the_walls_normal_both_ways():
    """A T tetromino locked in its plane by three other T's and the ground (a 4 x 4 square):
    interfaces +-x, +-z, the cone's lineality the wall's normal y: it comes in along +-y,
    both ways, nothing else; with --approach-max-angle 30 it is refused (no direction within
    30 deg of down leaves its interfaces); the top piece, free above, comes down."""
    scene = gen.tetromino_wall(1, 1, VOXEL)
    locked = "t01"      # cells (x, z) (1, 0), (2, 0), (3, 0), (2, 1): under the others
    box = Assembly.from_scene(scene.subset([locked])).blocks[0].aabb
    np.testing.assert_allclose(box, [[0.1, 0, 0], [0.4, 0.1, 0.2]], atol=1e-12)
    ours, oracle = _free_of_lattice(scene, locked)
    assert oracle == _axes((0, 1, 0), (0, -1, 0))
    assert ours == oracle
    found = _insertion(scene, locked)
    assert found.insertable and abs(found.direction[1]) == pytest.approx(1.0)
    options = replace(CheckOptions(), insertion=InsertionOptions(approach_max_angle=30.0))
    assembly = Assembly.from_scene(scene)
    refused = block_insertion(assembly, [b.id for b in scene.blocks], locked, options)
    assert not refused.insertable
    assert refused.reason == "no direction within 30 deg of straight down leaves every interface"
    top = block_insertion(assembly, [b.id for b in scene.blocks], "t03", options)
    np.testing.assert_allclose(top.direction, DOWN, atol=1e-12)


def test_block_in_a_u_cradle_down_and_along_the_open_ends():
    """A bar in a U-shaped cradle's groove (open above and at both ends): interfaces +z,
    +-x, so the cone is {d_x = 0, d_z <= 0}, and every lattice direction of it is free by
    the true shapes: down, +-y and the diagonals between; it comes straight down."""
    groove = [(1, y, 1) for y in range(3)]
    scene = _polycube_scene("cradle", [("cradle", _cells(3, 3, 2, groove), True),
                                       ("bar", groove, False)])
    ours, oracle = _free_of_lattice(scene, "bar")
    assert oracle == _axes((0, 0, -1), (0, 1, 0), (0, -1, 0), (0, 1, -1), (0, -1, -1))
    assert ours == oracle
    np.testing.assert_allclose(_insertion(scene, "bar").direction, DOWN, atol=1e-12)


def test_peg_in_a_blind_hole_only_along_its_axis():
    """A peg in a blind square hole, standing out above it: interfaces +z and +-x, +-y, the
    cone the ray down; only straight down is free (the hole's axis)."""
    scene = _polycube_scene("hole", [
        ("base", _cells(3, 3, 2, [(1, 1, 1)]), True), ("peg", [(1, 1, 1), (1, 1, 2)], False)])
    ours, oracle = _free_of_lattice(scene, "peg")
    assert oracle == _axes((0, 0, -1)) == ours
    assert cone_directions(_cone(scene, "peg"), DOWN) == [pytest.approx(DOWN)]


def _lidded_channel():
    """A 1.3 m channel (0.2 x 0.2 inside, along x) under a lid, a block filling it at each
    end, and a 0.1 m block in the middle touching floor, walls and lid: its cone is the
    channel's axis, and both ways the end blocks are 0.5 m away."""
    return _ground(box_block("w1", (1.3, 0.1, 0.2), (0, -0.15, 0.1), support=True, density=RHO),
                   box_block("w2", (1.3, 0.1, 0.2), (0, 0.15, 0.1), support=True, density=RHO),
                   box_block("lid", (1.3, 0.4, 0.1), (0, 0, 0.25), support=True, density=RHO),
                   box_block("end1", (0.1, 0.2, 0.2), (-0.6, 0, 0.1), density=RHO),
                   box_block("end2", (0.1, 0.2, 0.2), (0.6, 0, 0.1), density=RHO),
                   box_block("b", (0.1, 0.2, 0.2), (0, 0, 0.1), density=RHO))


def test_lidded_channel_refused_unless_a_shorter_approach_is_given():
    """The block cannot get in (a path must be free until the block is clear of every
    present block, and both ends of the channel are filled), though over twice its size
    (0.4 m, the former path) it would "slide in"; --approach-distance 0.4 accepts it."""
    scene = _lidded_channel()
    assert not _sweep_free(scene, "b", (1, 0, 0)) and not _sweep_free(scene, "b", (-1, 0, 0))
    assert _sweep_free(scene, "b", (1, 0, 0), distance=0.4)
    found = _insertion(scene, "b")
    assert not found.insertable and set(found.blocked_by) == {"end1", "end2"}
    options = replace(CheckOptions(), insertion=InsertionOptions(approach_distance=0.4))
    short = block_insertion(Assembly.from_scene(scene), [b.id for b in scene.blocks], "b",
                            options)
    assert short.insertable and abs(short.direction[0]) == pytest.approx(1.0)


def test_cli_approach_options(tmp_path, capsys):
    """The flags reach the check: the channel's block refused by default, accepted with
    --approach-distance 0.4; the tetromino refused with --approach-max-angle 30."""
    channel = tmp_path / "channel.json"
    scene = _lidded_channel()
    channel.write_text(json.dumps(scene_to_dict(make_scene(
        "c", scene.blocks, sequence=["end1", "end2", "b"]))))
    wall = tmp_path / "wall.json"
    t = gen.tetromino_wall(1, 1, VOXEL)
    wall.write_text(json.dumps(scene_to_dict(make_scene("w", t.blocks,
                                                        sequence=["t00", "t02", "t01"]))))
    for path, extra, insertable in ((channel, [], False), (channel, ["--approach-distance",
                                                                     "0.4"], True),
                                    (wall, [], True), (wall, ["--approach-max-angle", "30"],
                                                       False)):
        assert main(["check", str(path), "--sequence", "--json", *extra]) == 0
        last = json.loads(capsys.readouterr().out)["reports"][-1]
        assert last["insertable"] is insertable, (path.name, extra)


def _chevron():
    """A non-convex prism with slanted faces (a chevron, its caps triangulated), posed
    turned about an oblique axis."""
    outline = [(-0.3, 0), (0, 0.15), (0.3, 0), (0.3, 0.12), (0, 0.27), (-0.3, 0.12)]
    caps = [(0, 1, 4), (0, 4, 5), (1, 2, 3), (1, 3, 4)]
    block = _prism("chevron", outline, 0.2, caps)
    q = Rotation.from_rotvec([0.3, -0.5, 0.8]).as_quat()
    return replace(block, orientation=q, position=np.array([0.4, -0.2, 1.0]))


@pytest.mark.parametrize("name", ["chevron", "blind hole", "cradle comb", "T"])
def test_convex_pieces_are_exactly_the_block(name):
    """The decomposition of a non-convex block is exact, by an independent oracle: the
    pieces' volumes sum to trimesh's volume of the mesh, and 1,500 random points are in the
    posed mesh (the parity of a ray's crossings of its triangles) exactly when they are in
    some posed piece (scipy's Delaunay of the piece)."""
    block = {"chevron": _chevron,
             "blind hole": lambda: gen.polycube("h", _cells(3, 3, 2, [(1, 1, 1)]), VOXEL),
             "cradle comb": lambda: gen.cradle_row(3).block("cradle"),
             "T": lambda: gen.tetromino_wall(1, 1).block("t01")}[name]()
    posed = Assembly.from_scene(make_scene("one", [replace(block, support=True)])).blocks[0]
    assert not posed.convex
    pieces = block_pieces(posed)
    mesh = trimesh.Trimesh(posed.vertices, posed.triangles, process=False)
    assert mesh.is_volume
    assert sum(ConvexHull(p).volume for p in pieces) == pytest.approx(mesh.volume, rel=1e-9)
    low, high = mesh.bounds
    points = np.random.default_rng(3).uniform(low, high, size=(1500, 3))
    in_piece = np.any([Delaunay(p).find_simplex(points) >= 0 for p in pieces], axis=0)
    np.testing.assert_array_equal(in_piece, _ray_parity(mesh.triangles, points))
    assert len(pieces) <= {"chevron": 3, "blind hole": 6, "cradle comb": 5, "T": 2}[name]


def _ray_parity(triangles, points):
    """Whether each point is inside the closed mesh: its ray along a fixed generic direction
    crosses an odd number of triangles (Moller-Trumbore)."""
    d = np.array([0.2311, 0.4173, 0.8789])
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    e1, e2 = b - a, c - a
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    s = points[:, None, :] - a[None]
    u = np.einsum("nij,ij->ni", s, p) / det
    q = np.cross(s, e1[None])
    v = np.einsum("k,nik->ni", d, q) / det
    t = np.einsum("nik,ik->ni", q, e2) / det
    return ((u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)).sum(axis=1) % 2 == 1


def test_without_a_decomposition_present_is_its_mesh_moving_its_hull(monkeypatch):
    """A non-convex block with no decomposition within the limits: present, it is its
    triangle mesh (exact): the block in the U's notch comes straight down or along the
    notch (the U's hull would hold it from every side); moving, it is its
    convex hull (conservative): the inverted U lowered over a post that fits its notch is
    refused, though the sampled sweep of the true shapes is free."""
    monkeypatch.setattr(decompose, "MAX_PIECES", 1)
    decompose._pieces.cache_clear()
    insertion_module._PRESENT.clear()
    try:
        u = [(-0.3, 0), (0.3, 0), (0.3, 0.3), (0.1, 0.3), (0.1, 0.1), (-0.1, 0.1),
             (-0.1, 0.3), (-0.3, 0.3)]
        caps = [(0, 1, 4), (0, 4, 5), (1, 2, 3), (1, 3, 4), (0, 5, 6), (0, 6, 7)]
        scene = make_scene("u", [_prism("u", u, 0.3, caps, support=True),
                                 box_block("b", (0.2, 0.3, 0.2), (0, 0, 0.2), density=RHO)])
        assert decompose.convex_pieces(*_local_mesh(scene, "u")) is None
        found = _insertion(scene, "b")
        np.testing.assert_allclose(found.direction, DOWN, atol=1e-12)
        assert _insertion(scene, "b", given=np.array([0.0, 1.0, 0.0])).insertable
        inverted = [(-0.3, 0.3), (-0.3, 0), (-0.1, 0), (-0.1, 0.2), (0.1, 0.2), (0.1, 0),
                    (0.3, 0), (0.3, 0.3)]
        over = _ground(box_block("post", (0.1, 0.3, 0.15), (0, 0, 0.075), support=True,
                                 density=RHO),
                       _prism("n", inverted, 0.3, [(0, 1, 2), (0, 2, 3), (0, 3, 7), (3, 4, 7),
                                                    (4, 5, 6), (4, 6, 7)]))
        assert _independent_sweep_free(over, ["ground", "post", "n"], "n", DOWN)
        refused = _insertion(over, "n")
        assert not refused.insertable and "post" in refused.blocked_by
    finally:
        decompose._pieces.cache_clear()
        insertion_module._PRESENT.clear()


def _local_mesh(scene, block_id):
    posed = Assembly.from_scene(scene.subset([block_id])).blocks[0]
    return posed.local_vertices, posed.triangles


def test_exported_meshes_with_rounding_noise_keep_their_true_shapes():
    """Every vertex of the tetromino wall moved by up to 1 micrometre (a mesh as exported,
    its faces not quite planar): each piece still has a decomposition (at the exported
    tolerance, 1e-4 of its diagonal, far below the 2% clearance), and the locked piece still
    comes in along the wall's normal."""
    wall = gen.tetromino_wall(1, 1, VOXEL)
    rng = np.random.default_rng(5)
    noisy = make_scene("noisy", [replace(b, vertices=b.vertices + rng.uniform(
        -1e-6, 1e-6, b.vertices.shape)) if not b.support else b for b in wall.blocks])
    assembly = Assembly.from_scene(noisy)
    for b in assembly.blocks[1:]:
        assert not b.convex
        assert decompose.convex_pieces(b.local_vertices, b.triangles) is not None, b.id
    found = block_insertion(assembly, [b.id for b in noisy.blocks], "t01", CheckOptions())
    assert found.insertable and abs(found.direction[1]) == pytest.approx(1.0)


def _curved_cradle(facets=16):
    """A support "cradle" (0.6 x 0.4 x 0.3) with a half-cylindrical groove of radius 0.2
    along y, ``facets`` flat facets, and a half-round "bar" filling the groove: a non-convex
    base whose faces are not axis-aligned."""
    arc = [(0.2 * math.cos(math.pi * (1 + i / facets)), 0.3 + 0.2 * math.sin(
        math.pi * (1 + i / facets))) for i in range(facets + 1)]
    outline = [(-0.3, 0.0), (0.3, 0.0), (0.3, 0.3), *arc[::-1], (-0.3, 0.3)]
    index = {p: i for i, p in enumerate(outline)}
    caps = []
    for t in shapely.constrained_delaunay_triangles(shapely.Polygon(outline)).geoms:
        tri = [index[min(index, key=lambda q: (q[0] - x) ** 2 + (q[1] - z) ** 2)]
               for x, z in t.exterior.coords[:3]]
        (ax, az), (bx, bz), (cx, cz) = (outline[i] for i in tri)
        caps.append(tuple(tri if (bx - ax) * (cz - az) - (bz - az) * (cx - ax) > 0
                          else tri[::-1]))
    return make_scene("curved", [_prism("cradle", outline, 0.4, caps, support=True),
                                 _prism("bar", arc, 0.4)])


def test_bar_in_a_curved_groove_down_and_along_it():
    """A half-round bar in a 16-facet groove of a cradle: interfaces on every facet, so it
    can come down or slide along the groove (+-y), nothing across; the cradle is cut into
    one piece per facet's wedge, and the sampled sweep of the true shapes agrees on each
    lattice direction our check accepts, and on the two across it refuses."""
    scene = _curved_cradle()
    posed = Assembly.from_scene(scene.subset(["cradle"])).blocks[0]
    assert len(block_pieces(posed)) == 16
    found = _insertion(scene, "bar")
    np.testing.assert_allclose(found.direction, DOWN, atol=1e-12)
    for d in ((0, 1, 0), (0, -1, 0), (0, 0.6, -0.8)):
        assert _insertion(scene, "bar", given=np.array(d, dtype=float)).insertable, d
        assert _independent_sweep_free(scene, ["cradle", "bar"], "bar", d)
    for d in ((1, 0, -1), (-1, 0, -1)):
        assert not _insertion(scene, "bar", given=np.array(d, dtype=float)).insertable
        assert not _independent_sweep_free(scene, ["cradle", "bar"], "bar", d)
