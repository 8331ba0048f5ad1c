"""~/plan for a robot cell over DDS: the 7-voussoir arch planned for the three robots of the
node's ``cell_file`` (a goal with an empty cell) and of a goal's own cell text (YAML) gives
the timeline ``rbe-ros plan --cell --json`` gives (actions, robots, grip poses as
PoseStamped, states checked); a goal with a cell the plan cannot use is ABORTED with the
reason, the node keeps answering; the node's bag replays every goal, its cell with it.
Long (a node of its own: about 20 s)."""
from __future__ import annotations

import json
from types import SimpleNamespace

import pytest
import yaml
from action_msgs.msg import GoalStatus
from rbe_msgs.action import PlanSequence

from rbe_ros import generators
from rbe_ros.cli import main
from rbe_ros.io.replay import PLAN, read_runs
from rbe_ros.io.scene_json import scene_to_dict
from rbe_ros.ros.convert import message_to_dict

from rbe_client import node_and_client, state_msg

TOOL = {"box": [0.1, 0.1, 0.15], "tcp": [0.0, 0.0, 0.15], "mass": 2.0}
pytestmark = pytest.mark.long

CELL = {"robots": [
    {"name": n, "base": b, "reach": 3.0, "payload_force": 3000, "payload_torque": 1500,
     "tool": TOOL} for n, b in (("r1", [1.5, -1.5, 0.0]), ("r2", [-1.5, -1.5, 0.0]),
                                ("r3", [0.0, 1.5, 0.0]))]}


@pytest.fixture(scope="module")
def rbe(rclpy_context, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rbe_plan_cell")
    cell = tmp / "cell.yaml"
    cell.write_text(yaml.safe_dump(CELL))
    bag = tmp / "bag"
    with node_and_client(rclpy_context, ["-p", f"mcap_path:={bag}", "-p",
                                         f"cell_file:={cell}"], tmp / "node.log") \
            as (proc, client):
        yield SimpleNamespace(proc=proc, client=client, bag=bag, tmp=tmp, cell=cell)


def cli_timeline(rbe, capsys) -> dict:
    path = rbe.tmp / "arch.json"
    path.write_text(json.dumps(scene_to_dict(generators.semicircular_arch(7))))
    capsys.readouterr()
    assert main(["plan", str(path), "--cell", str(rbe.cell), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def same_timeline(result, expected: dict) -> None:
    sent = [message_to_dict(a) for a in result.timeline]
    assert list(result.robots) == expected["robots"] == ["r1", "r2", "r3"]
    keys = ("action", "robot", "block", "step", "stable", "status")
    assert [[a[k] for k in keys] for a in sent] == [[a[k] for k in keys]
                                                   for a in expected["timeline"]]
    for a, b in zip(sent, expected["timeline"]):
        for frame in ("grip", "pre_grip", "approach"):
            pa, pb = a[frame]["pose"], b[frame]["pose"]
            assert [pa["position"][k] for k in "xyz"] == pytest.approx(
                [pb["position"][k] for k in "xyz"], abs=1e-9)
            assert [pa["orientation"][k] for k in "xyzw"] == pytest.approx(
                [pb["orientation"][k] for k in "xyzw"], abs=1e-9)
        force = [a["wrench_tool"]["force"][k] for k in "xyz"]
        assert force == pytest.approx([b["wrench_tool"]["force"][k] for k in "xyz"],
                                      rel=1e-3, abs=0.5)


def test_the_cell_plan_over_dds_equals_the_cli(rbe, capsys):
    expected = cli_timeline(rbe, capsys)
    arch = generators.semicircular_arch(7)
    # the node's cell_file (an empty goal cell), then the goal's own cell as YAML text
    for cell in ("", yaml.safe_dump(CELL)):
        goal = PlanSequence.Goal(assembly=state_msg(arch), cell=cell)
        status, result = rbe.client.result(rbe.client.send_plan(goal, []), timeout=120.0)
        assert status == GoalStatus.STATUS_SUCCEEDED and result.feasible
        assert list(result.order) == expected["order"]
        same_timeline(result, expected)
        assert result.timeline[0].grip.header.frame_id == "world"


def test_a_bad_cell_goal_is_aborted_with_the_reason(rbe):
    bad = json.loads(json.dumps(CELL))
    bad["robots"][1]["payload_force"] = -5
    for text, reason in ((json.dumps(bad), "invalid input: cell: robot 'r2': 'payload_force' "
                          "must be a number >= 0, got -5"),
                         ("robots: [{name: r1\n base", "invalid input: cell: YAML does not "
                          "parse")):
        goal = PlanSequence.Goal(assembly=state_msg(generators.semicircular_arch(7)),
                                 cell=text)
        status, result = rbe.client.result(rbe.client.send_plan(goal, []))
        assert status == GoalStatus.STATUS_ABORTED
        assert result.message.startswith(reason) and not result.feasible
    # the node keeps planning (an empty goal cell: the node's cell_file)
    goal = PlanSequence.Goal(assembly=state_msg(generators.semicircular_arch(7)), max_held=2)
    status, result = rbe.client.result(rbe.client.send_plan(goal, []))
    assert status == GoalStatus.STATUS_SUCCEEDED and result.feasible
    assert list(result.robots) == ["r1", "r2", "r3"] and result.timeline


def test_the_bag_replays_the_cell_plans(rbe, capsys):
    runs = [r for r in read_runs(rbe.bag) if r.kind == PLAN]
    assert len(runs) == 5
    # the goal planned with the node's cell_file was recorded with that cell
    assert yaml.safe_load(runs[0].state["cell"])["robots"][2]["name"] == "r3"
    assert [len(r.reports[0]["timeline"]) for r in runs[:2]] == [18, 18]
    capsys.readouterr()
    assert main(["replay", str(rbe.bag), "--compare", "-o", str(rbe.tmp / "replayed")]) == 0
    assert "all recorded reports reproduced" in capsys.readouterr().out
    # the bag's view: the cell plans with their robots' table
    page = rbe.tmp / "view.html"
    assert main(["view", str(rbe.bag), "-o", str(page)]) == 0
    view = json.loads(page.read_text().split('type="application/json">')[1]
                      .split("</script>")[0].replace("<\\/", "</"))
    assert len(view["robot_tables"]) == 3           # the goals planned (two aborted)
    assert view["robot_tables"][0]["rows"][4] == [4, "release v01", "-", "place v02; hold v02"]
