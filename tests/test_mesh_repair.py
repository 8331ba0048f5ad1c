"""Meshes as they come (issue 28, item 4): open or inconsistently wound meshes repaired at
load with a warning naming the block, checked as the intact meshes are (trimesh the oracle
of closedness and volume); a mesh that cannot be closed stays INVALID_INPUT with the
reason; an overlap's message names the pose uncertainty that accepts it, and with it the
check runs."""
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
import trimesh

from rbe_ros.cli import main
from rbe_ros.generators import semicircular_arch
from rbe_ros.geometry.block import pose_block, signed_volume
from rbe_ros.geometry.repair import repair_mesh
from rbe_ros.interlock import cradle
from rbe_ros.io.messages import scene_from_state_dict, state_to_dict
from rbe_ros.io.scene_json import scene_from_dict, scene_to_dict
from rbe_ros.scene import SceneError, make_block

ROBOTS = (Path(__file__).parents[1] / ".venv/lib/python3.11/site-packages/compas_fab/data/"
          "robot_library")
#: An ABB IRB 4600 link as compas_fab ships it: two holes in its visual mesh.
OPEN_AS_SHIPPED = ROBOTS / "abb_irb4600_40_255/abb_irb4600_40_255/meshes/visual/link_2.stl"
#: Its base: edges of more than two faces, which no repair closes.
NOT_REPAIRABLE = ROBOTS / "abb_irb4600_40_255/abb_irb4600_40_255/meshes/visual/base_link.stl"
#: A closed convex collision mesh (IRB 120 base).
CONVEX = ROBOTS / "abb_irb120_3_58/abb_irb120_support/meshes/irb120_3_58/collision/base_link.stl"


def _triangles(faces):
    return np.array([(f[0], f[i], f[i + 1]) for f in faces for i in range(1, len(f) - 1)])


def _trimesh(block) -> trimesh.Trimesh:
    return trimesh.Trimesh(block.vertices, _triangles(block.faces), process=False)


def _soup(block, drop: int, flip: int) -> dict:
    """The block's mesh as an exporter may write it: a triangle soup (every vertex repeated
    per triangle), triangle ``drop`` missing (an open edge loop) and ``flip`` wound inward."""
    tri = _triangles(block.faces)
    vertices = block.vertices[tri.ravel()]
    faces = np.arange(len(vertices)).reshape(-1, 3)
    faces[flip] = faces[flip][::-1]
    return {"vertices": vertices.tolist(), "faces": np.delete(faces, drop, axis=0).tolist()}


def _check(capsys, path, *more) -> tuple[int, dict, str]:
    code = main(["check", str(path), "--json", *more])
    out = capsys.readouterr()
    return code, (json.loads(out.out) if out.out else {}), out.err


def test_every_voussoir_of_a_nine_voussoir_arch_open_is_repaired_and_checked_as_intact(
        tmp_path, capsys):
    intact = semicircular_arch(9)
    doc = scene_to_dict(intact)
    for k, raw in enumerate(doc["blocks"]):
        if raw["support"]:
            continue
        block = intact.block(raw["id"])
        if k % 2:       # a face deleted from the polygon mesh (a quad hole)
            raw["mesh"]["faces"] = raw["mesh"]["faces"][1:]
        else:           # a triangle soup with a triangle missing and one turned over
            raw["mesh"] = _soup(block, drop=k % 12, flip=(k + 5) % 11)
    scene = scene_from_dict(doc)
    named = [re.match(r"block '(\w+)': mesh repaired", w).group(1) for w in scene.warnings]
    assert named == [b.id for b in intact.blocks if not b.support]
    assert all("filled 1 hole" in w for w in scene.warnings)
    # 12 triangles of 3 vertices each, 8 corners: 28 duplicates, in 5 soups
    assert sum("merged 28 duplicate vertices" in w for w in scene.warnings) == 5
    for repaired in scene.blocks:
        mesh, truth = _trimesh(repaired), _trimesh(intact.block(repaired.id))
        assert mesh.is_watertight and mesh.is_winding_consistent
        assert mesh.volume == pytest.approx(truth.volume, rel=1e-12)
    path = tmp_path / "arch.json"
    path.write_text(json.dumps(doc))
    code, out, err = _check(capsys, path, "--sequence")
    assert code == 0 and err.count("rbe-ros: warning: block 'v0") == 9
    assert len(out["warnings"]) == 9
    (tmp_path / "intact.json").write_text(json.dumps(scene_to_dict(intact)))
    _, truth, _ = _check(capsys, tmp_path / "intact.json", "--sequence")
    assert [r["status"] for r in out["reports"]] == [r["status"] for r in truth["reports"]]
    last, last_truth = out["reports"][-1], truth["reports"][-1]
    assert last["stable"] and len(last["interfaces"]) == len(last_truth["interfaces"]) == 10
    assert [i["normal_resultant"] for i in last["interfaces"]] == pytest.approx(
        [i["normal_resultant"] for i in last_truth["interfaces"]], rel=1e-6)


def test_an_exported_base_with_open_edges_is_repaired_and_named(tmp_path, capsys):
    """The cradle's non-convex base exported as STL with three triangles missing: the
    warning names it, the repaired base is closed with the intact volume, and the blocks set
    into it stand as on the intact one."""
    scene = cradle(slots=2)
    base = scene.block("base")
    mesh = _trimesh(base)
    mesh.update_faces(np.setdiff1d(np.arange(len(mesh.faces)), [3, 17, 40]))
    assert not mesh.is_watertight
    mesh.export(tmp_path / "base.stl")
    doc = scene_to_dict(scene)
    raw = next(b for b in doc["blocks"] if b["id"] == "base")
    del raw["mesh"]
    raw["mesh_file"] = "base.stl"
    (tmp_path / "cradle.json").write_text(json.dumps(doc))
    code, out, err = _check(capsys, tmp_path / "cradle.json")
    assert code == 0 and out["stable"]
    (warning,) = out["warnings"]
    assert warning == "block 'base': mesh repaired: filled 3 holes"    # trimesh merged the STL
    assert f"rbe-ros: warning: {warning}" in err
    repaired = scene_from_dict(doc, tmp_path).block("base")
    fixed = _trimesh(repaired)
    # STL stores float32 coordinates: the volume agrees to their precision
    assert fixed.is_watertight and fixed.volume == pytest.approx(_trimesh(base).volume,
                                                                 rel=1e-6)
    (tmp_path / "intact.json").write_text(json.dumps(scene_to_dict(scene)))
    _, truth, _ = _check(capsys, tmp_path / "intact.json")
    assert truth["warnings"] == [] and len(out["interfaces"]) == len(truth["interfaces"])


def test_a_robot_link_open_as_shipped_is_closed():
    """Data we did not make: compas_fab's IRB 4600 link 2 has two holes as shipped (trimesh
    says it is not watertight); repaired it is, with the volume trimesh finds for it."""
    shipped = trimesh.load(OPEN_AS_SHIPPED, force="mesh")
    assert not shipped.is_watertight
    scene = scene_from_dict({"blocks": [
        {"id": "ground", "support": True, "density": 2000, "box": [2, 2, 0.1],
         "position": [0, 0, -1]},
        {"id": "link_2", "density": 2000, "mesh_file": str(OPEN_AS_SHIPPED)}]})
    assert scene.warnings == ("block 'link_2': mesh repaired: filled 2 holes",)
    fixed = _trimesh(scene.block("link_2"))
    assert fixed.is_watertight and fixed.is_winding_consistent
    # the holes are small: the closed volume is the open mesh's within a thousandth
    assert fixed.volume == pytest.approx(shipped.volume, rel=1e-3)


def test_a_convex_part_with_missing_triangles_becomes_its_hull():
    """compas_fab's IRB 120 base collision mesh (closed, convex) with three triangles
    deleted: filled and replaced by its hull, whose volume is the intact mesh's."""
    intact = trimesh.load(CONVEX, force="mesh")
    assert intact.is_watertight
    faces = np.delete(intact.faces, [0, 10, 20], axis=0)
    scene = scene_from_dict({"blocks": [
        {"id": "ground", "support": True, "density": 2000, "box": [2, 2, 0.1],
         "position": [0, 0, -1]},
        {"id": "irb120_base", "density": 2000,
         "mesh": {"vertices": intact.vertices.tolist(), "faces": faces.tolist()}}]})
    (warning,) = scene.warnings
    assert warning.startswith("block 'irb120_base': mesh repaired: filled ")
    assert warning.endswith("replaced by its convex hull (volumes agree within 0.0001)")
    hull = _trimesh(scene.block("irb120_base"))
    assert hull.volume == pytest.approx(intact.volume, rel=1e-9)
    assert hull.volume == pytest.approx(intact.convex_hull.volume, rel=1e-12)


def test_a_mesh_that_cannot_be_closed_stays_invalid_input_with_the_reason(tmp_path, capsys):
    doc = {"blocks": [{"id": "ground", "support": True, "density": 2000, "box": [2, 2, 0.1],
                       "position": [0, 0, -1]},
                      {"id": "base_link", "density": 2000, "mesh_file": str(NOT_REPAIRABLE)}]}
    with pytest.raises(SceneError, match=r"block 'base_link': mesh is not closed: .*cannot be "
                                         r"repaired") as err:
        scene_from_dict(doc)
    assert err.value.blocks == ("base_link",)
    (tmp_path / "s.json").write_text(json.dumps(doc))
    code, _, stderr = _check(capsys, tmp_path / "s.json")
    assert code == 2 and stderr.startswith("rbe-ros: error: block 'base_link': mesh is not "
                                           "closed")


def test_a_closed_mesh_is_kept_exactly_and_warns_nothing():
    scene = semicircular_arch(9)
    again = scene_from_dict(scene_to_dict(scene))
    assert again.warnings == ()
    for a, b in zip(scene.blocks, again.blocks):
        assert a.faces == b.faces and np.array_equal(a.vertices, b.vertices)


def test_an_overlap_names_the_pose_uncertainty_that_accepts_it(tmp_path, capsys):
    """Two 0.2 m cubes side by side on the ground, overlapping by 5.5 mm: beyond the
    validation's 1% of 0.2 m = 2 mm. A contact needs the overlap within the contact
    tolerance (0.1% of 0.2 m) plus both allowances: (5.5 - 0.2) / 2 = 2.65 mm each, 2.7 on
    the 0.1 mm grid; with 0.2 deg declared, each allowance has 0.2 deg times the cube's
    half diagonal (0.1 sqrt 3 m) already: (5.5 - 0.2 - 1.209) / 2 = 2.05 mm, 2.1."""
    doc = {"blocks": [
        {"id": "ground", "support": True, "density": 2000, "box": [2, 1, 0.1],
         "position": [0, 0, -0.05]},
        {"id": "a", "density": 2000, "box": [0.2, 0.2, 0.2], "position": [-0.09725, 0, 0.1]},
        {"id": "b", "density": 2000, "box": [0.2, 0.2, 0.2], "position": [0.09725, 0, 0.1]}]}
    (tmp_path / "s.json").write_text(json.dumps(doc))
    code, _, err = _check(capsys, tmp_path / "s.json")
    assert code == 2
    assert ("blocks 'a' and 'b' interpenetrate: they overlap by 0.0055 m, more than the "
            "tolerance 0.002 m; --pose-uncertainty 0.0027 would make it a contact") in err

    def touching(*more) -> bool:
        code, out, err = _check(capsys, tmp_path / "s.json", *more)
        assert code == 0 and out["stable"] and err == ""
        return any({i["block_a"], i["block_b"]} == {"a", "b"} for i in out["interfaces"])

    assert touching("--pose-uncertainty", "0.0027")
    # 0.1 mm less: valid, but not a contact (the suggestion is the least on its grid)
    assert not touching("--pose-uncertainty", "0.0026")
    # with an angle declared, it is kept and the position needs less
    code, _, err = _check(capsys, tmp_path / "s.json", "--pose-uncertainty", "0,0.2")
    assert code == 2 and "--pose-uncertainty 0.0021,0.2 would make it a contact" in err
    assert touching("--pose-uncertainty", "0.0021,0.2")
    assert not touching("--pose-uncertainty", "0.002,0.2")


def test_an_overlap_of_turned_faces_names_the_angle_too(tmp_path, capsys):
    """A 0.4 x 0.4 x 0.2 m box turned 4.3 deg about x on an equal box, its low edge 8 mm
    into it: the overlap is 8 mm (along the lower box's normal; the turned box's lowest
    point is at -d), the faces are 4.3 deg from opposite (the turn). Beyond the contact
    angle (1 deg) no position makes them touch (what the 527-block dome's hint said and
    INFEASIBLE followed): the hint names the least angle on the 0.1 deg grid with
    1 + 2 angle > 4.3, 1.7 deg, and the position that then makes it a contact."""
    alpha, d = math.radians(4.3), 0.008
    z = -d + 0.2 * math.sin(alpha) + 0.1 * math.cos(alpha)     # lowest vertex at z = -d
    doc = {"blocks": [
        {"id": "base", "support": True, "density": 2000, "box": [0.4, 0.4, 0.2],
         "position": [0, 0, -0.1]},
        {"id": "top", "density": 2000, "box": [0.4, 0.4, 0.2], "position": [0, 0, z],
         "orientation": [math.sin(alpha / 2), 0, 0, math.cos(alpha / 2)]}]}
    (tmp_path / "s.json").write_text(json.dumps(doc))
    code, _, err = _check(capsys, tmp_path / "s.json")
    assert code == 2
    assert f"they overlap by {d:.4g} m" in err and "their faces 4.3 deg from opposite" in err
    hint = re.search(r"--pose-uncertainty ([0-9.]+),1\.7 would make it a contact", err)
    assert hint, err
    position = float(hint.group(1))
    assert position > 0        # the turned face rises off the other: a gap to accept too

    def touching(*more) -> bool:
        code, out, err = _check(capsys, tmp_path / "s.json", "--pose-uncertainty", *more)
        assert code in (0, 1, 2), err
        return any({i["block_a"], i["block_b"]} == {"base", "top"}
                   for i in out.get("interfaces", []))

    assert touching(f"{position:g},1.7")
    code, out, _ = _check(capsys, tmp_path / "s.json", "--pose-uncertainty", f"{position:g},1.7")
    assert code == 0 and out["stable"]
    assert not touching(f"{position:g},1.6")               # the faces too far from opposite
    assert not touching(f"{position + 0.01:g}")            # a position alone never does
    assert not touching(f"{position - 1e-4:g},1.7")        # the least position on its grid


def test_an_assembly_state_with_an_open_mesh_is_repaired_as_a_file_is():
    """The node's and replay's input (an rbe_msgs/AssemblyState dict: meshes as triangles)
    goes through the same repair: a voussoir with a triangle missing is closed, named, and
    has the intact voussoir's volume."""
    intact = semicircular_arch(9)
    state = state_to_dict(intact, "world")
    raw = next(b for b in state["blocks"] if b["id"] == "v04")
    raw["mesh"]["triangles"] = raw["mesh"]["triangles"][2:]     # a quad face gone
    scene = scene_from_state_dict(state)
    assert scene.warnings == ("block 'v04': mesh repaired: filled 1 hole; replaced by its "
                              "convex hull (volumes agree within 0.0001)",)
    assert _trimesh(scene.block("v04")).volume == pytest.approx(
        _trimesh(intact.block("v04")).volume, rel=1e-12)


def test_triangles_missing_across_an_edge_are_filled_in_their_planes():
    """Two triangles of different faces missing along a shared edge of the cradle's base:
    the hole is not planar; the fan whose triangles lie in the faces' planes closes it, with
    the intact volume (trimesh); a tent over the edge would not."""
    base = cradle(slots=2).block("base")
    mesh = _trimesh(base)
    square = np.abs(mesh.face_adjacency_angles - np.pi / 2) < 1e-9
    for pair in mesh.face_adjacency[square][:3]:          # three different edges
        faces = np.delete(mesh.faces, pair, axis=0)
        fixed = repair_mesh(mesh.vertices, faces)
        assert fixed.notes == ("filled 1 hole",)
        closed = trimesh.Trimesh(fixed.vertices, _triangles(fixed.faces), process=False)
        assert closed.is_watertight and closed.volume == pytest.approx(mesh.volume, rel=1e-12)


def test_copies_of_a_vertex_a_little_apart_are_one():
    """A triangle soup whose copies of each corner differ by up to 1e-8 m (float noise of an
    export, below the merge tolerance of 1e-6 of the extent): every copy is merged (by
    distance: rounding would split copies either side of a rounding boundary), closed."""
    block = semicircular_arch(9).block("v04")
    soup = _soup(block, drop=0, flip=0)
    soup["faces"] = [list(f) for f in np.arange(len(soup["vertices"])).reshape(-1, 3)]
    noisy = np.array(soup["vertices"]) + np.random.default_rng(3).uniform(
        -1e-8, 1e-8, (len(soup["vertices"]), 3))
    fixed = repair_mesh(noisy, soup["faces"])
    assert fixed.notes[0] == "merged 28 duplicate vertices" and len(fixed.vertices) == 8
    assert _trimesh(make_block("v04", fixed.vertices, fixed.faces, density=1.0)).volume == \
        pytest.approx(_trimesh(block).volume, rel=1e-6)


def test_an_open_mesh_with_non_convex_polygon_faces_keeps_their_shape():
    """A U-shaped prism exported with its caps as single polygons (non-convex) and one side
    face missing: the caps are triangulated in their planes for the repair (a fan from the
    first corner would cover the notch), so each cap keeps the U's area, 5 (shoelace), and
    the volume is 5 x depth (trimesh)."""
    u = [(0, 0), (3, 0), (3, 2), (2, 2), (2, 1), (1, 1), (1, 2), (0, 2)]
    n = len(u)
    vertices = np.array([(x, 0, z) for x, z in u] + [(x, 1, z) for x, z in u], dtype=float)
    faces = [tuple(range(n)), tuple(range(2 * n - 1, n - 1, -1))]
    faces += [(i, n + i, n + (i + 1) % n, (i + 1) % n) for i in range(n)]
    if signed_volume(vertices, faces) < 0:
        faces = [f[::-1] for f in faces]
    fixed = repair_mesh(vertices, faces[:4] + faces[5:])
    assert fixed.notes == ("filled 1 hole",)
    posed = pose_block(make_block("u", fixed.vertices, fixed.faces, density=1.0))
    caps = [f.outline.area for f in posed.faces if abs(abs(f.frame.n[1]) - 1) < 1e-9]
    assert caps == pytest.approx([5.0, 5.0], abs=1e-12)
    closed = trimesh.Trimesh(posed.vertices, posed.triangles, process=False)
    assert closed.is_watertight and closed.volume == pytest.approx(5.0, abs=1e-12)
    assert not posed.convex
