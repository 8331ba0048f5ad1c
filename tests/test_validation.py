"""Input validation (issue 7): one clear reason per problem, from the core and the CLI;
interpenetration; solver time limits."""
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rbe_ros import generators as gen
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.analysis.pipeline import check_sequence
from rbe_ros.analysis.validate import validated_assembly
from rbe_ros.cli import main
from rbe_ros.geometry.overlap import find_penetration
from rbe_ros.rbe.result import Status
from rbe_ros.rbe.solver import SolveOptions
from rbe_ros.scene import (SceneError, ValidationLimits, box_block, make_block, make_scene,
                           validate_scene)
from rbe_ros.io.scene_json import load_scene, scene_from_dict

from helpers import DENSITY, stacked_boxes

GROUND = dict(id="g", support=True, density=2000, box=[3, 3, 0.2], position=[0, 0, -0.1])


def scene_of(*blocks, **extra):
    return {"blocks": [GROUND, *blocks], **extra}


def box(bid="a", size=(1, 1, 1), position=(0, 0, 0.5), **kw):
    return {"id": bid, "box": list(size), "position": list(position), **({"density": 2000} | kw)}


TETRA = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
         "faces": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]}

#: scene dict -> words the one error line must contain
BAD = {
    "nan position": (scene_of(box(position=[0, math.nan, 0.5])), ["'a'", "NaN"]),
    "inf position": (scene_of(box(position=[math.inf, 0, 0.5])), ["'a'", "infinity"]),
    "zero quaternion": (scene_of(box(orientation=[0, 0, 0, 0])), ["'a'", "unit norm"]),
    "non-unit quaternion": (scene_of(box(orientation=[0, 0, 0, 2])), ["'a'", "unit norm"]),
    "duplicate ids": (scene_of(box(), box(position=[0, 0, 1.5])), ["duplicate", "'a'"]),
    "unknown sequence id": (scene_of(box(), sequence=["x"]), ["'x'", "not in the scene"]),
    "empty assembly": ({"blocks": []}, ["no blocks"]),
    "no support": ({"blocks": [box()]}, ["no support"]),
    "open mesh": (scene_of({"id": "t", "density": 2000, "position": [0, 0, 0],
                            "mesh": {**TETRA, "faces": TETRA["faces"][:3]}}), ["'t'"]),
    "zero volume": (scene_of({"id": "t", "density": 2000, "position": [0, 0, 0], "mesh": {
        "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]],
        "faces": [[0, 2, 1], [1, 2, 3], [0, 1, 3], [0, 3, 2]]}}), ["'t'"]),
    "tiny block": (scene_of(box(size=[1, 1, 0.0005], position=[0, 0, 0.00025])),
                   ["'a'", "size", "0.0005", "sane range"]),
    "huge block": (scene_of(box(size=[200, 1, 1])), ["'a'", "200", "sane range"]),
    "zero-size box": (scene_of(box(size=[1, 0, 1])), ["'a'", "positive"]),
    "light density": (scene_of(box(density=0.5)), ["'a'", "density 0.5", "sane range"]),
    "heavy density": (scene_of(box(density=50000)), ["'a'", "density 50000"]),
    "absurd mass": (scene_of({**box(), "density": 0, "mass": 1e9}), ["'a'", "mass 1e+09",
                                                                      "density of 1e+09"]),
    "far away": (scene_of(box(position=[1e5, 0, 0.5])), ["'a'", "farther"]),
    "absurd gravity": (scene_of(box(), gravity=[0, 0, -1e6]), ["gravity", "sane range"]),
    "interpenetration": (scene_of(box(), box("b", position=[0.5, 0, 0.9])),
                         ["'a' and 'b'", "interpenetrate", "by 0.5 m"]),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_each_problem_gives_one_clear_reason(case):
    data, words = BAD[case]
    with pytest.raises(SceneError) as info:
        check_scene(scene_from_dict(data))
    message = str(info.value)
    assert "\n" not in message and all(w in message for w in words), message


@pytest.mark.parametrize("case", ["interpenetration", "absurd mass", "tiny block",
                                  "non-unit quaternion"])
def test_cli_gives_one_line_and_exit_2(case, tmp_path, capsys):
    data, words = BAD[case]
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    for command in (["check"], ["check", "--sequence"], ["tilt"], ["min-friction"]):
        assert main([command[0], str(path), *command[1:]]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("rbe-ros: error:")
        assert all(w in err[0] for w in words), err


def test_floating_block_is_a_verdict_not_an_error():
    report = check_scene(scene_from_dict(scene_of(box(), box("f", position=[0, 0, 3]))))
    assert report.status == Status.INFEASIBLE and report.unstable_blocks == ("f",)
    assert "not connected to a support" in report.message


def test_block_limit_from_options_and_cli(tmp_path, capsys):
    scene = gen.stack(n=4)
    limits = ValidationLimits(max_blocks=4)
    with pytest.raises(SceneError, match="5 blocks, more than the limit of 4"):
        check_scene(scene, CheckOptions(limits=limits))
    with pytest.raises(SceneError, match="more than the limit of 4"):
        check_sequence(scene, CheckOptions(limits=limits))
    assert check_scene(scene, CheckOptions(limits=ValidationLimits(max_blocks=5))).stable
    assert check_scene(scene, CheckOptions(limits=None)).stable
    path = tmp_path / "stack.json"
    assert main(["generate", "stack", "-p", "n=4", "-o", str(path)]) == 0
    capsys.readouterr()
    assert main(["check", str(path), "--max-blocks", "4"]) == 2
    assert "more than the limit of 4 (max_blocks)" in capsys.readouterr().err
    assert main(["check", str(path), "--max-blocks", "5", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["stable"] is True


def test_limits_are_configurable():
    data = scene_of(box(density=50000))
    with pytest.raises(SceneError):
        validate_scene(scene_from_dict(data))
    validate_scene(scene_from_dict(data), ValidationLimits(max_density=60000))
    # a mass-given block: the implied density is checked against the same range
    scene = scene_from_dict(scene_of({**box(), "density": 0, "mass": 50000}))
    with pytest.raises(SceneError, match="density of 50000"):
        validated_assembly(scene)
    validated_assembly(scene, ValidationLimits(max_density=60000))


def test_every_generator_and_example_passes_validation():
    for make in gen.GENERATORS.values():
        validated_assembly(make())          # raises on any problem
    for path in (Path(__file__).parents[1] / "examples").glob("*.json"):
        validated_assembly(load_scene(path))


def test_touching_and_nearly_touching_blocks_are_not_interpenetrating():
    # face contact, contact within the tolerance, a gap, and a shift along the contact plane
    for dz in (0.0, 0.004, -0.004, 0.2):
        for dx in (0.0, 0.3):
            validated_assembly(stacked_boxes(dx + 0.0) if dz == 0 else make_scene("s", [
                box_block("ground", (3, 3, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
                box_block("a", (1, 1, 1), (0, 0, 0.5), density=DENSITY),
                box_block("b", (1, 1, 1), (dx, 0, 1.5 + dz), density=DENSITY)]))


def edge_to_edge(gap: float):
    """Two cubes turned 45 deg about y and about x, ridge over ridge at ``gap``: no face
    normal separates them, only an edge-edge axis does."""
    qa = Rotation.from_euler("y", 45, degrees=True).as_quat()
    qb = Rotation.from_euler("x", 45, degrees=True).as_quat()
    return make_scene("ridges", [
        box_block("g", (4, 4, 0.2), (0, 0, -5), support=True, density=DENSITY),
        box_block("a", (1, 1, 1), (0, 0, 0), qa, density=DENSITY),
        box_block("b", (1, 1, 1), (0, 0, math.sqrt(2) + gap), qb, density=DENSITY)])


@pytest.mark.parametrize("gap, depth", [(0.05, None), (0.001, None), (-0.008, None),
                                        (-0.02, 0.02), (-0.3, 0.3)])
def test_edge_to_edge_depth_is_exact(gap, depth):
    blocks = list(Assembly.from_scene(edge_to_edge(gap)).blocks)
    hit = find_penetration(blocks, 0.01)
    if depth is None:
        assert hit is None
    else:
        assert (hit.a, hit.b) == (1, 2) and hit.depth == pytest.approx(depth, rel=1e-6)


def test_non_convex_blocks_are_not_tested():
    # an L-shaped block with a box in its notch: their hulls overlap, the blocks do not
    verts = [[0, 0, 0], [2, 0, 0], [2, 0, 1], [1, 0, 1], [1, 0, 2], [0, 0, 2]]
    verts = verts + [[x, 1, z] for x, _, z in verts]
    faces = [[0, 5, 4, 3, 2, 1], [6, 7, 8, 9, 10, 11], [0, 1, 7, 6], [1, 2, 8, 7], [2, 3, 9, 8],
             [3, 4, 10, 9], [4, 5, 11, 10], [5, 0, 6, 11]]
    faces = [f[::-1] for f in faces]
    ell = make_block("L", np.array(verts, float) - [1, 0.5, 1], faces, (0, 0, 1), density=2000)
    scene = make_scene("notch", [box_block("g", (4, 4, 0.2), (0, 0, -0.1), support=True,
                                           density=2000), ell,
                                 box_block("c", (0.9, 0.9, 0.9), (0.5, 0, 1.5), density=2000)])
    blocks = list(validated_assembly(scene).blocks)
    assert find_penetration(blocks, 0.01) is None
    assert find_penetration([blocks[0], blocks[2]], 0.01) is None     # convex, apart


def test_time_limit_gives_solver_failed_naming_the_stage():
    wall = gen.running_bond_wall(4, 4)
    report = check_scene(wall, CheckOptions(solve=SolveOptions(time_limit=1e-7)))
    assert report.status == Status.SOLVER_FAILED and not report.stable
    assert report.message == "solver failed: time limit of 1e-07 s exceeded in the geometry stage"
    assert check_scene(wall, CheckOptions(solve=SolveOptions(time_limit=60.0))).stable
    reports = check_sequence(wall, CheckOptions(solve=SolveOptions(time_limit=1e-7)))
    assert len(reports) == len(wall.sequence)
    assert {r.status for r in reports} == {Status.SOLVER_FAILED}


def test_cli_time_limit(tmp_path, capsys):
    path = tmp_path / "wall.json"
    assert main(["generate", "running-bond-wall", "-p", "courses=4", "-o", str(path)]) == 0
    capsys.readouterr()
    out = json.loads(capsys.readouterr().out if main(["check", str(path), "--json",
                                                      "--time-limit", "1e-7"]) == 0 else "{}")
    assert out["status"] == Status.SOLVER_FAILED and "time limit of 1e-07 s" in out["message"]
    assert main(["check", str(path), "--time-limit", "-1"]) == 2
    assert "--time-limit" in capsys.readouterr().err
