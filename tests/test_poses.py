"""Design once, then measured poses: the merge (core), its accumulation, and the CLI's
``--poses``; oracles: closed forms of a block on a support and the same geometry built
directly."""
import json
import math

import numpy as np
import pytest

from rbe_ros import generators as gen
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.cli import main
from rbe_ros.io.poses import AsBuilt, poses_from_json, scene_at_poses
from rbe_ros.rbe.result import Status
from rbe_ros.scene import SceneError
from rbe_ros.io.scene_json import scene_to_dict

IDENTITY = [0.0, 0.0, 0.0, 1.0]


def _yaw(deg: float) -> list[float]:
    h = math.radians(deg) / 2
    return [0.0, 0.0, math.sin(h), math.cos(h)]


def test_the_as_built_scene_holds_the_supports_and_the_measured_blocks_at_their_poses():
    design = gen.stack(4)
    scene = scene_at_poses(design, {"b01": ([0.0, 0.0, 0.75], IDENTITY),
                                    "b00": ([0.05, 0.0, 0.25], _yaw(3.0))})
    assert [b.id for b in scene.blocks] == ["ground", "b00", "b01"]       # design order
    assert scene.sequence == ("b00", "b01")
    assert scene.block("b00").position == pytest.approx([0.05, 0, 0.25])
    assert scene.block("b00").orientation == pytest.approx(_yaw(3.0))
    assert scene.block("ground") is design.block("ground")
    # nothing measured: the supports alone
    assert [b.id for b in scene_at_poses(design, {}).blocks] == ["ground"]


def test_an_unknown_id_or_a_bad_pose_is_refused_naming_it():
    design = gen.stack(2)
    with pytest.raises(SceneError, match="not in the design .*'b07'"):
        scene_at_poses(design, {"b00": ([0, 0, 0], IDENTITY), "b07": ([0, 0, 0], IDENTITY)})
    with pytest.raises(SceneError, match="block 'b01'.*unit norm"):
        scene_at_poses(design, {"b01": ([0, 0, 0], [0, 0, 0, 2])})
    with pytest.raises(SceneError, match="block 'b00'.*NaN"):
        scene_at_poses(design, {"b00": ([0, float("nan"), 0], IDENTITY)})


@pytest.mark.parametrize("shift", [0.0, 0.2, 0.45])
def test_a_measured_offset_gives_the_forces_of_that_geometry(shift):
    """The top block measured ``shift`` m off its design pose stands on the base with its
    whole weight through its centroid (closed form), and the report is that of the same
    geometry built directly (second computation)."""
    report = check_scene(scene_at_poses(gen.two_blocks(), {"top": ([shift, 0, 0.75], IDENTITY)}))
    assert report.status == Status.STABLE
    (it,) = report.interfaces
    weight = 1.0 * 1.0 * 0.5 * 2000 * 9.81
    assert it.normal_resultant == pytest.approx(weight, rel=1e-6)
    assert it.centre_of_pressure[0] == pytest.approx(shift, abs=1e-6)
    direct = check_scene(gen.two_blocks(shift=shift))
    assert np.allclose(sorted(report.interfaces[0].normal_forces),
                       sorted(direct.interfaces[0].normal_forces), atol=1e-6 * weight)


def test_a_block_measured_beyond_the_edge_tips():
    report = check_scene(scene_at_poses(gen.two_blocks(), {"top": ([0.55, 0, 0.75], IDENTITY)}))
    assert report.status == Status.TENSION_REQUIRED and report.unstable_blocks == ("top",)


def test_as_built_accumulates_updates_and_refuses_a_bad_one_whole():
    built = AsBuilt()
    with pytest.raises(SceneError, match="no design yet"):
        built.update({"b00": ([0, 0, 0], IDENTITY)})
    assert [b.id for b in built.set_design(gen.stack(3)).blocks] == ["ground"]
    built.update({"b00": ([0, 0, 0], IDENTITY)})
    scene = built.update({"b01": ([0.1, 0, 0], IDENTITY)})
    assert [b.id for b in scene.blocks] == ["ground", "b00", "b01"]
    scene = built.update({"b00": ([0.02, 0, 0.25], IDENTITY)})             # re-measured
    assert scene.block("b00").position[0] == 0.02 and scene.block("b01").position[0] == 0.1
    with pytest.raises(SceneError, match="'nope'"):
        built.update({"b02": ([0, 0, 0], IDENTITY), "nope": ([0, 0, 0], IDENTITY)})
    assert set(built.measured) == {"b00", "b01"}                            # unchanged
    assert [b.id for b in built.set_design(gen.stack(3)).blocks] == ["ground"]   # forgotten
    with pytest.raises(SceneError, match="the design is invalid: bad mesh"):
        built.set_design(None, "bad mesh")


def test_poses_json_format_is_checked():
    assert poses_from_json({"poses": {"a": {"position": [1, 2, 3], "orientation": IDENTITY}}}) \
        == {"a": ([1, 2, 3], IDENTITY)}
    with pytest.raises(SceneError, match="poses file is"):
        poses_from_json({"a": {}})
    with pytest.raises(SceneError, match="block 'a' needs exactly a position"):
        poses_from_json({"poses": {"a": {"position": [0, 0, 0]}}})


def test_cli_check_design_with_poses(tmp_path, capsys):
    design = tmp_path / "design.json"
    design.write_text(json.dumps(scene_to_dict(gen.stack(3))))
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps({"poses": {
        "b00": {"position": [0.0, 0.0, 0.25], "orientation": IDENTITY},
        "b01": {"position": [0.3, 0.0, 0.75], "orientation": IDENTITY}}}))
    assert main(["check", str(design), "--poses", str(poses), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == Status.STABLE and out["num_blocks"] == 3
    top = next(i for i in out["interfaces"] if i["block_b"] == "b01" or i["block_a"] == "b01")
    # b01 (1 x 1 x 0.5 m, 2000 kg/m^3) rests on b00 with its centroid 0.3 m out
    assert top["normal_resultant"] == pytest.approx(1000 * 9.81, rel=1e-6)
    assert top["centre_of_pressure"]["x"] == pytest.approx(0.3, abs=1e-6)
    # per step: the measured blocks in the design's sequence
    assert main(["check", str(design), "--poses", str(poses), "--sequence", "--json"]) == 0
    assert [s["block_placed"] for s in json.loads(capsys.readouterr().out)["reports"]] == ["b00", "b01"]
    poses.write_text(json.dumps({"poses": {"b9": {"position": [0, 0, 0],
                                                  "orientation": IDENTITY}}}))
    assert main(["check", str(design), "--poses", str(poses)]) == 2
    assert "not in the design" in capsys.readouterr().err


def test_cli_design_file_declaration_applies_to_measured_poses(tmp_path, capsys):
    """A 1 mm penetration among measured poses: no verdict of standing under the design rule,
    a contact under the design file's declared pose uncertainty (3 mm, 0.15 deg), which
    --poses keeps."""
    stack = gen.stack(2)
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps({"poses": {
        "b00": {"position": [0.0, 0.0, 0.25], "orientation": IDENTITY},
        "b01": {"position": [0.0, 0.0, 0.749], "orientation": IDENTITY}}}))
    design = tmp_path / "design.json"
    design.write_text(json.dumps(scene_to_dict(stack)))
    assert main(["check", str(design), "--poses", str(poses), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["status"] != Status.STABLE
    declared = scene_to_dict(stack) | {"pose_uncertainty": [0.003, 0.15]}
    design.write_text(json.dumps(declared))
    assert main(["check", str(design), "--poses", str(poses), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == Status.STABLE
    top = next(i for i in out["interfaces"] if "b01" in (i["block_a"], i["block_b"]))
    assert top["normal_resultant"] == pytest.approx(1000 * 9.81, rel=1e-6)
