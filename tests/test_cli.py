"""The command line: JSON outputs with real values, one-line errors for bad input."""
import json
import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

from rbe_ros.io.bag import read_bag
from rbe_ros.cli import main
from rbe_ros.rbe.result import Status

EXAMPLE = Path(__file__).parents[1] / "examples" / "build_sequence.json"


def run_json(capsys, *argv):
    assert main(list(argv)) == 0
    return json.loads(capsys.readouterr().out)


def test_check_sequence_json_names_the_failing_step_and_interface(capsys):
    out = run_json(capsys, "check", str(EXAMPLE), "--sequence", "--json")
    steps = out["reports"]
    assert [s["block_placed"] for s in steps] == ["pillar_left", "pillar_right", "lintel", "block_left",
                                           "wedge", "cap"]
    assert [s["stable"] for s in steps] == [True] * 5 + [False]
    assert out["first_failing_step"] == 5
    last = steps[-1]
    assert last["status"] == Status.TENSION_REQUIRED and "lintel|cap" in last["message"]
    assert last["max_tension"] > 100.0
    flagged = [i for i in last["interfaces"] if i["tension"]]
    assert [(i["block_a"], i["block_b"]) for i in flagged] == [("lintel", "cap")]
    # the lintel (1.2 x 0.2 x 0.2 m, 2000 kg/m^3) and what it carries rest on the pillars
    first = steps[0]["interfaces"][0]
    assert first["normal_resultant"] == pytest.approx(0.2 * 0.2 * 0.6 * 2000 * 9.81, rel=1e-6)


def test_check_whole_assembly_json_has_the_documented_fields(capsys):
    out = run_json(capsys, "check", str(EXAMPLE), "--json")
    assert {"stable", "status", "max_tension", "interfaces"} <= set(out)
    it = out["interfaces"][0]
    assert {"block_a", "block_b", "normal_resultant", "shear_resultant", "centre_of_pressure",
            "tension", "friction_exceeded"} <= set(it)
    assert set(it["shear_resultant"]) == set(it["centre_of_pressure"]) == {"x", "y", "z"}


def test_readme_lists_every_key_of_the_json_report(capsys):
    """The README's key list of `check --json` is the message dict's, no more, no less."""
    readme = (Path(__file__).parents[1] / "README.md").read_text()
    text = readme[readme.index("`check --json` prints"):readme.index("With `--sequence`,")]
    listed = set(re.findall(r'"(\w+)"', text))
    out = run_json(capsys, "check", str(EXAMPLE), "--json")
    keys = set(out) | set(out["interfaces"][0]) | set(out["header"]) | {"x", "y", "z"}
    keys |= {"block_a", "block_b", "gap", "overlap_area"}      # of each near contact
    keys |= {"block", "force", "torque", "grip_point", "utilisation"}    # each hold wrench
    assert listed == keys - {"stamp", "frame_id"}


def test_check_records_a_bag_that_reads_back(tmp_path, capsys):
    bag = tmp_path / "run"
    assert main(["check", str(EXAMPLE), "--sequence", "--bag", str(bag)]) == 0
    messages = list(read_bag(bag))
    assert [m.topic for m in messages] == ["/rbe_node/assembly"] + [
        "/rbe_node/report", "/rbe_node/markers"] * 6
    assert len(messages[0].data["blocks"]) == 7
    assert messages[-2].data["status"] == 1 and messages[-2].data["block_placed"] == "cap"
    # a step a second after the state, the markers at their report's time
    assert [m.stamp_ns - messages[0].stamp_ns for m in messages[1:]] == [
        k * 10**9 for k in range(1, 7) for _ in range(2)]
    assert [m["text"] for m in messages[-1].data["markers"] if m["ns"] == "blocks"] == [
        "ground", "pillar_left", "pillar_right", "lintel", "block_left", "wedge", "cap"]
    assert main(["check", str(EXAMPLE), "--bag", str(bag)]) == 2      # exists: refuses
    assert "exists" in capsys.readouterr().err
    lean = tmp_path / "lean"
    assert main(["check", str(EXAMPLE), "--sequence", "--bag", str(lean), "--no-markers"]) == 0
    assert {m.topic for m in read_bag(lean)} == {"/rbe_node/assembly", "/rbe_node/report"}


def test_tilt_and_min_friction_json(tmp_path, capsys):
    scene = tmp_path / "incline.json"
    assert main(["generate", "two-blocks", "-p", "incline_deg=23.6", "-o", str(scene)]) == 0
    capsys.readouterr()
    mu = run_json(capsys, "min-friction", str(scene), "--json")["mu_min"]
    assert mu == pytest.approx(math.tan(math.radians(23.6)), abs=2e-3)
    flat = tmp_path / "flat.json"
    assert main(["generate", "stack", "-p", "n=1", "-p", "height=0.25", "-o", str(flat)]) == 0
    capsys.readouterr()
    out = run_json(capsys, "tilt", str(flat), "--direction=-y", "--mu", "0.5", "--json")
    assert out["tilt_deg"] == pytest.approx(math.degrees(math.atan(0.5)), abs=0.05)
    assert out["multiplier"] == pytest.approx(0.5, rel=1e-5)


BAD_SCENES = {
    "nan position": ({"blocks": [{"id": "g", "support": True, "density": 1, "box": [1, 1, 1],
                                  "position": [0, "NaN", 0]}]}, "NaN"),
    "zero quaternion": ({"blocks": [{"id": "g", "support": True, "density": 1, "box": [1, 1, 1],
                                     "orientation": [0, 0, 0, 0]}]}, "unit norm"),
    "duplicate ids": ({"blocks": [{"id": "g", "support": True, "density": 1, "box": [1, 1, 1]},
                                  {"id": "g", "density": 1, "box": [1, 1, 1]}]}, "duplicate"),
    "no support": ({"blocks": [{"id": "a", "density": 1, "box": [1, 1, 1]}]}, "support"),
    # a fin on a tetrahedron's edge: three faces on one edge, no repair closes it
    "open mesh": ({"blocks": [{"id": "g", "support": True, "density": 1,
                               "mesh": {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1],
                                                     [1, 1, 1]],
                                        "faces": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3],
                                                  [1, 3, 4]]}}]},
                  "closed"),
    "unknown sequence id": ({"blocks": [{"id": "g", "support": True, "density": 1, "box": [1, 1, 1]}],
                             "sequence": ["x"]}, "not in the scene"),
}


@pytest.mark.parametrize("case", sorted(BAD_SCENES))
def test_bad_scene_gives_one_line_error_and_exit_2(case, tmp_path):
    data, words = BAD_SCENES[case]
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data).replace('"NaN"', "NaN"))
    proc = subprocess.run([sys.executable, "-m", "rbe_ros.cli", "check", str(path)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rbe-ros: error:") and words in lines[0]
    assert "Traceback" not in proc.stderr


def test_unreadable_and_invalid_files(tmp_path, capsys):
    assert main(["check", str(tmp_path / "missing.json")]) == 2
    assert "cannot read scene" in capsys.readouterr().err
    (tmp_path / "broken.json").write_text("{not json")
    assert main(["check", str(tmp_path / "broken.json")]) == 2
    assert "invalid JSON at line 1" in capsys.readouterr().err


def test_contact_options_from_the_command_line(tmp_path, capsys):
    """A box 5 mm above the slab (0.5% of its size): floating at the default distance
    tolerance, resting on the slab with --distance-tol 0.01; a negative tolerance is refused."""
    from rbe_ros.scene import box_block, make_scene
    from rbe_ros.io.scene_json import scene_to_dict
    scene = make_scene("gap", [box_block("ground", (4, 4, 0.2), (0, 0, -0.1), support=True,
                                         density=2000),
                               box_block("box", (1, 1, 1), (0, 0, 0.505), density=2000)])
    path = tmp_path / "gap.json"
    path.write_text(json.dumps(scene_to_dict(scene)))
    assert run_json(capsys, "check", str(path), "--json")["status"] == Status.INFEASIBLE
    out = run_json(capsys, "check", str(path), "--json", "--distance-tol", "0.01")
    assert out["status"] == Status.STABLE
    assert out["interfaces"][0]["normal_resultant"] == pytest.approx(2000 * 9.81, rel=1e-6)
    assert main(["check", str(path), "--vertex-tol", "-1"]) == 2
    assert "--vertex-tol" in capsys.readouterr().err
