"""The node and replay make their reports through one dispatch
(:func:`rbe_ros.analysis.pipeline.check_state`): the same states, fed to an in-process RbeNode
and to replay, give the same reports, field by field (all but the wall time). States: every
run of the stack_tips and wall_misplaced bags (steps that stand, tip, need holds; a whole
assembly), the example build sequence as a whole and step by step, and a state that cannot
be read."""
from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from rbe_msgs.msg import AssemblyState, StabilityReport
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message

from rbe_ros.io.messages import report_header, state_to_dict
from rbe_ros.io.replay import Run, read_runs, replay_run
from rbe_ros.io.scene_json import load_scene
from rbe_ros.ros.convert import dict_to_message, message_to_dict
from rbe_ros.ros.node import RbeNode

REPO = Path(__file__).resolve().parents[2]


def _states() -> dict[str, dict]:
    states = {f"{bag}[{i}]": run.state for bag in ("stack_tips", "wall_misplaced")
              for i, run in enumerate(read_runs(REPO / "bags" / bag))}
    example = state_to_dict(load_scene(REPO / "examples" / "build_sequence.json"), "site", 7)
    states["example sequence"] = example
    states["example whole"] = {**example, "sequence": []}
    bad = json.loads(json.dumps(example))
    bad["blocks"][1]["pose"]["position"]["x"] = math.nan
    states["NaN position"] = bad
    return states


STATES = _states()


@pytest.fixture(scope="module")
def node(rclpy_context):
    node = RbeNode(namespace="/rbe_dispatch_test", context=rclpy_context,
                   parameter_overrides=[Parameter("frame_id", value="world")])
    yield node
    node.destroy_node()


def _without_time(report: dict) -> dict:
    return {k: v for k, v in report.items() if k != "solve_time"}


@pytest.mark.parametrize("name", list(STATES))
def test_node_and_replay_give_the_same_reports(node, name):
    state = STATES[name]
    msg = dict_to_message(state, AssemblyState)
    header = report_header(state["header"])
    _, sent = node.check(msg, header, bool(state.get("sequence")))
    by_node = [message_to_dict(deserialize_message(d, StabilityReport)) for d in sent]
    by_replay = replay_run(Run(state, 0))
    assert len(by_node) == len(by_replay) >= 1
    if state.get("sequence") and name != "NaN position":
        assert len(by_node) == len(state["sequence"])
    for n, r in zip(by_node, by_replay):
        assert _without_time(n) == _without_time(r), (name, n["step_index"])
