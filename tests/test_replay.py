"""The recorded bags of bags/: they replay offline, a perturbed force fails the replay with a
diff naming it, they read back with rosbags, and they show what they were made to show."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import shapely
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from ruamel.yaml import YAML

from oracles import plane_blocks, stacks
from rbe_ros.io import bag
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.cli import main
from rbe_ros.io.replay import (OPTIONS_KEY, Tolerances, bag_options, compare_report, free_weights,
                               options_from_json, options_to_json, read_runs, replay_bag,
                               write_runs)
from rbe_ros.io.testing import assert_bag_replays, bag_paths, parametrize_bags

REPO = Path(__file__).resolve().parents[1]
BAGS = REPO / "bags"
NAMES = ["arch_centring", "dome_courses", "stack_tips", "wall_misplaced"]


@pytest.fixture(scope="module")
def runs():
    """The runs of every bag, read once."""
    return {p.name: read_runs(p) for p in bag_paths(BAGS)}


def test_the_four_bags_are_there():
    assert [p.name for p in bag_paths(BAGS)] == NAMES


@parametrize_bags(BAGS)
def test_bag_replays_offline(bag):
    result = assert_bag_replays(bag)
    assert sum(len(r) for r in result.replayed) == sum(len(r.reports) for r in result.runs)


@pytest.mark.parametrize("name", NAMES)
def test_bag_reads_with_rosbags_and_has_metadata(name):
    path = BAGS / name
    meta = YAML(typ="safe").load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["storage_identifier"] == "mcap" and meta["relative_file_paths"] == [f"{name}_0.mcap"]
    topics = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    assert set(topics) == {"/rbe_node/assembly", "/rbe_node/report", "/rbe_node/markers"}
    for t in topics.values():
        (qos,) = t["topic_metadata"]["offered_qos_profiles"]
        assert qos["reliability"] == "reliable"
    assert options_from_json(meta["custom_data"][OPTIONS_KEY]) == CheckOptions()
    with AnyReader([path], default_typestore=bag.typestore()) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == {
            "/rbe_node/assembly": "rbe_msgs/msg/AssemblyState",
            "/rbe_node/report": "rbe_msgs/msg/StabilityReport",
            "/rbe_node/markers": "visualization_msgs/msg/MarkerArray"}
        counts = {"/rbe_node/assembly": 0, "/rbe_node/report": 0, "/rbe_node/markers": 0}
        for conn, _stamp, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            counts[conn.topic] += 1
            if conn.topic == "/rbe_node/report":
                assert msg.solve_time == 0.0 and msg.header.frame_id == "world"
    assert counts == {k: t["message_count"] for k, t in topics.items()}
    with (path / f"{name}_0.mcap").open("rb") as f:
        summary = make_reader(f).get_summary()
    for channel in summary.channels.values():
        assert "offered_qos_profiles" in channel.metadata
        assert channel.metadata["topic_type_hash"].startswith("RIHS01_")


def steps(run):
    return [(r["step_index"], r["block_placed"]) for r in run.reports]


def unstable(run):
    return [r["step_index"] for r in run.reports if not r["stable"]]


def test_stack_tips_at_step_3(runs):
    seq, whole = runs["stack_tips"]
    assert steps(seq) == [(k, f"b{k:02d}") for k in range(5)]
    # derived by the overhang rule (tests/oracles/stacks.py) from the bag's documented
    # stack: five 1 x 1 x 0.5 m boxes, each 0.3 m further along x, on a wide ground
    boxes = [stacks.StackBox("ground", shapely.box(-5, -5, 5, 5), (0, 0, -0.25), -0.5, 0.0)]
    boxes += [stacks.StackBox(f"b{k:02d}", shapely.box(0.3 * k - 0.5, -0.5, 0.3 * k + 0.5, 0.5),
                              (0.3 * k, 0.0, 0.5 * k + 0.25), 0.5 * k, 1000.0) for k in range(5)]
    derived = [k for k in range(5)
               if stacks.verdicts(boxes[:k + 2], (0, 0, -9.81), 0.6, "soc", "net")
               != {"STABLE"}]
    assert unstable(seq) == derived == [3, 4]
    tip = seq.reports[3]
    assert tip["status"] == 1 and "b00|b01" in tip["message"]       # TENSION_REQUIRED
    assert len(tip["suggested_holds"]) == 1 and tip["max_tension"] > 10.0
    assert whole.state["sequence"] == [] and len(whole.reports) == 1
    assert whole.reports[0]["step_index"] == -1 and whole.reports[0]["status"] == 1


def test_arch_centring_release_step_and_holds(runs):
    released, early, bare, held = runs["arch_centring"]
    voussoirs = ["v00", "v14", "v01", "v13", "v02", "v12", "v03", "v11", "v04", "v10", "v05",
                 "v09", "v06", "v08", "v07"]
    for run in (released, early, bare, held):
        assert [b for _, b in steps(run)] == voussoirs
    # the centring (15 supports) stands until the key-stone's step 14, then it is taken away
    centring = {h["block"]: (h["from_step"], h["until_step"]) for h in released.state["holds"]}
    assert len(centring) == 15 and set(centring.values()) == {(0, 14)}
    assert unstable(released) == []
    assert any("centring_06" in (i["block_a"], i["block_b"])
               for i in released.reports[13]["interfaces"])
    assert not any("centring" in i["block_a"] + i["block_b"] for i in released.reports[14]["interfaces"])
    # one step earlier is too early: the half arches fall
    assert {h["until_step"] for h in early.state["holds"]} == {13} and unstable(early) == [13]
    assert early.reports[13]["status"] == 1
    # without centring: the steps that fail and the smallest holds, derived by the plane
    # rigid-block LP from the arch's dimensions (tests/oracles/plane_blocks.py): the half
    # arches fail from the fourth voussoir on (steps 6-13); before the key-stone a robot has
    # to hold the two voussoirs next to it, and no other pair (nor one block) will do
    blocks, joints, supports = plane_blocks.buttressed_arch()
    order = plane_blocks.key_order(15)
    buttresses = set(blocks) - set(order)
    derived = [k for k in range(15)
               if not plane_blocks.stands(blocks, joints, buttresses | set(order[:k + 1]),
                                          supports)]
    assert bare.state["holds"] == [] and unstable(bare) == derived == list(range(6, 14))
    smallest = plane_blocks.smallest_holds(blocks, joints, buttresses | set(order[:14]),
                                           supports)
    assert [set(bare.reports[13]["suggested_holds"])] == smallest == [{"v06", "v08"}]
    assert bare.reports[14]["stable"] and bare.reports[14]["suggested_holds"] == []
    # holding what the reports suggest at every step, every step stands
    assert unstable(held) == []
    assert held.reports[13]["held_blocks"] == ["v06", "v08"]
    assert max(len(r["held_blocks"]) for r in held.reports) == 2
    assert held.reports[14]["held_blocks"] == []


def test_dome_courses(runs):
    *courses, planned = runs["dome_courses"]
    assert [len(r.state["blocks"]) for r in courses] == [16, 24, 32, 40]
    assert all(r.reports[0]["stable"] and r.reports[0]["step_index"] == -1 for r in courses)
    assert len(planned.reports) == 32 and unstable(planned) == []
    held = [r["held_blocks"] for r in planned.reports]
    assert max(map(len, held)) == 2 and held[24] == ["course4_slice00"]
    assert planned.reports[-1]["held_blocks"] == []


def test_wall_misplaced_brick(runs):
    misplaced, good = runs["wall_misplaced"]
    assert unstable(misplaced) == [12, 13, 14, 15, 16] and unstable(good) == []
    bad = misplaced.reports[12]
    assert bad["block_placed"] == "course02_brick03" and bad["status"] == 1
    assert all(r["suggested_holds"] == ["course02_brick03"] for r in misplaced.reports[12:17])
    assert misplaced.reports[17]["block_placed"] == "course03_brick04"   # pins it down


def perturbed_copy(tmp_path, name, factor):
    """A copy of bag ``name`` whose first recorded report with interfaces has the normal
    force of its first interface's first vertex multiplied by ``factor``."""
    runs = read_runs(BAGS / name)
    report = next(r for run in runs for r in run.reports if r["interfaces"])
    iface = report["interfaces"][0]
    iface["normal_forces"][0] *= factor
    path = tmp_path / f"{name}_perturbed"
    write_runs(path, runs, [r.reports for r in runs], bag_options(BAGS / name))
    return path, report, iface


def test_perturbed_force_fails_the_replay_with_a_diff_naming_it(tmp_path):
    path, report, iface = perturbed_copy(tmp_path, "stack_tips", 1.001)
    with pytest.raises(AssertionError) as err:
        assert_bag_replays(path)
    text = str(err.value)
    pair = f"{iface['block_a']}|{iface['block_b']}"
    assert f"step {report['step_index']} ({report['block_placed']}) interface {pair}: " \
           "normal_forces[0]: recorded" in text
    assert "1 field(s)" in text


def test_perturbation_within_tolerance_passes(tmp_path):
    path, _, _ = perturbed_copy(tmp_path, "stack_tips", 1 + 1e-9)
    assert_bag_replays(path)


def test_compare_report_tolerances():
    run = read_runs(BAGS / "stack_tips")[0]
    rec = run.reports[2]
    weight = free_weights(run.state)[2]
    assert weight == pytest.approx(3 * 2000 * 0.5 * 9.81)          # three boxes of 1 x 1 x 0.5 m
    new = json.loads(json.dumps(rec))
    new["interfaces"][0]["normal_resultant"] += 0.5e-6 * weight     # inside 1e-6 W
    new["interfaces"][0]["centre_of_pressure"]["x"] += 0.5e-6       # inside 1e-6 m
    new["solve_time"] = 123.0                                       # never compared
    new["interfaces"] = new["interfaces"][::-1][::-1]
    assert compare_report(rec, new, free_weight=weight) == []
    new["interfaces"][0]["normal_resultant"] += 2e-6 * weight
    new["status"] = 2
    new["message"] = rec["message"].replace("0.000", "0.001")
    diffs = compare_report(rec, new, free_weight=weight)
    assert [d.field for d in diffs] == ["status", "normal_resultant"]
    diffs = compare_report(rec, new, free_weight=weight, tolerances=Tolerances(message=1e-3))
    assert [d.field for d in diffs] == ["status", "message", "normal_resultant"]
    assert compare_report(rec, new, free_weight=weight, tolerances=Tolerances(force=1e-3))[0].field \
        == "status"


def test_vertex_order_does_not_matter():
    rec = read_runs(BAGS / "stack_tips")[0].reports[1]
    new = json.loads(json.dumps(rec))
    for i in new["interfaces"]:
        for key in ("polygon", "normal_forces", "tangential_forces", "kern"):
            i[key] = i[key][1:] + i[key][:1]
    assert compare_report(rec, new, free_weight=1e4) == []


def test_options_round_trip():
    options = CheckOptions()
    assert options_from_json(options_to_json(options)) == options


def test_cli_replay_writes_a_bag_and_refuses_to_overwrite(tmp_path, capsys):
    src = tmp_path / "stack"
    shutil.copytree(BAGS / "stack_tips", src)
    assert main(["replay", str(src), "--compare"]) == 0
    out = capsys.readouterr().out
    assert "all recorded reports reproduced" in out
    replayed = list(bag.read_bag(tmp_path / "stack_replay"))
    step = ["/rbe_node/report", "/rbe_node/markers"]
    assert [m.topic for m in replayed] == (["/rbe_node/assembly"] + step * 5
                                           + ["/rbe_node/assembly"] + step)
    assert [m.data["step_index"] for m in replayed if m.msgtype.endswith("Report")] == \
        [0, 1, 2, 3, 4, -1]
    assert bag.read_custom_data(tmp_path / "stack_replay")[OPTIONS_KEY] == options_to_json(
        CheckOptions())
    assert main(["replay", str(src)]) == 2
    assert "exists already" in capsys.readouterr().err


def test_cli_replay_mismatch_exits_1_with_a_readable_diff(tmp_path, capsys):
    path, report, iface = perturbed_copy(tmp_path, "stack_tips", 1.01)
    assert main(["replay", str(path), "--compare", "-o", str(tmp_path / "out")]) == 1
    out = capsys.readouterr().out
    assert "MISMATCH: 1 field(s)" in out
    assert f"interface {iface['block_a']}|{iface['block_b']}: normal_forces[0]" in out
    assert "run 0: state stamp 1704067200.000000000 s" in out
    # without --compare the replay only writes the bag
    assert main(["replay", str(path), "-o", str(tmp_path / "out2")]) == 0


def test_check_bag_replays(tmp_path, capsys):
    scene = REPO / "examples" / "build_sequence.json"
    assert main(["check", str(scene), "--sequence", "--bag", str(tmp_path / "seq")]) == 0
    assert main(["check", str(scene), "--bag", str(tmp_path / "whole")]) == 0
    capsys.readouterr()
    for name in ("seq", "whole"):
        result = assert_bag_replays(tmp_path / name)
        assert len(result.runs) == 1
    assert [len(r) for r in replay_bag(tmp_path / "seq", write=False).replayed] == [6]


def test_make_bags_is_deterministic(tmp_path, capsys):
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_bags", REPO / "scripts" / "make_bags.py")
    make_bags = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make_bags)
    for out in ("a", "b"):
        assert make_bags.main(["--out", str(tmp_path / out), "--only", "stack_tips"]) == 0
        assert "stack_tips: 2 runs, 6 reports" in capsys.readouterr().out
    for f in ("metadata.yaml", "stack_tips_0.mcap"):
        assert (tmp_path / "a" / "stack_tips" / f).read_bytes() == \
            (tmp_path / "b" / "stack_tips" / f).read_bytes()
