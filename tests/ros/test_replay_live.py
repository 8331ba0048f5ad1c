"""Every bag of bags/ replayed through a live rbe_node (one node process for the module, in
the test run's ROS_DOMAIN_ID): the node's reports match the recorded ones; a perturbed
recorded force fails the live replay the same way it fails offline."""
from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient

from rbe_client import NodeProcess
from rbe_ros.cli import main
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.io.replay import bag_options, options_to_json, read_runs, write_runs
from rbe_ros.io.testing import assert_bag_replays, parametrize_bags
from rbe_ros.ros.live import live_recheck, live_reports

REPO = Path(__file__).resolve().parents[2]
BAGS = REPO / "bags"
NAME = "rbe_replay_test"


@pytest.fixture(scope="module")
def node(rclpy_context, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rbe_replay")
    proc = NodeProcess(["-r", f"__node:={NAME}"], tmp / "node.log")
    try:
        yield SimpleNamespace(proc=proc, name=NAME, context=rclpy_context)
    finally:
        proc.stop()
        out = proc.output()
        assert "Traceback" not in out, out


@parametrize_bags(BAGS)
def test_bag_replays_live(node, bag):
    result = assert_bag_replays(bag, recheck=live_recheck(node.name, node.context))
    assert [len(r) for r in result.replayed] == [len(run.reports) for run in result.runs]
    assert node.proc.proc.poll() is None


def test_running_node_gets_its_parameters_back(node):
    """A replay through a running node sets its parameters to the recorded settings (mu 0.6,
    frame world) and puts back those it had (mu 0.45, frame cell) when it ends."""
    client = Node("rbe_replay_params_test", context=node.context)
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(client)
    parameters = AsyncParameterClient(client, "/" + NAME)

    def call(future):
        executor.spin_until_future_complete(future, timeout_sec=30.0)
        assert future.done()
        return future.result()

    try:
        assert parameters.wait_for_services(30.0)
        mine = [Parameter("friction_coefficient", value=0.45), Parameter("frame_id", value="cell")]
        assert all(r.successful for r in call(parameters.set_parameters(mine)).results)
        runs = read_runs(BAGS / "stack_tips")
        for run in runs:                      # as a node records them: ~/settings
            run.settings = {"options": json.loads(options_to_json(CheckOptions())),
                            "frame_id": "world"}
        replayed = [r for _, r in live_reports(runs, CheckOptions(), node_name=node.name,
                                               context=node.context)]
        assert [r["stable"] for r in replayed[0]] == [r["stable"] for r in runs[0].reports]
        values = call(parameters.get_parameters(["friction_coefficient", "frame_id"])).values
        assert [parameter_value_to_python(v) for v in values] == [0.45, "cell"]
        call(parameters.set_parameters([Parameter("friction_coefficient", value=0.6),
                                        Parameter("frame_id", value="world")]))
    finally:
        executor.shutdown()
        client.destroy_node()


def test_perturbed_force_fails_the_live_replay(node, tmp_path):
    runs = read_runs(BAGS / "stack_tips")
    report = runs[0].reports[3]                        # the stack tips
    iface = report["interfaces"][-1]
    iface["normal_resultant"] *= 1.001
    path = tmp_path / "perturbed"
    write_runs(path, runs, [r.reports for r in runs], bag_options(BAGS / "stack_tips"))
    with pytest.raises(AssertionError) as err:
        assert_bag_replays(path, recheck=live_recheck(node.name, node.context))
    text = str(err.value)
    assert "(live)" in text and "1 field(s)" in text
    assert (f"step 3 (b03) interface {iface['block_a']}|{iface['block_b']}: "
            "normal_resultant: recorded") in text


def test_cli_live_starts_its_own_node(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["replay", str(BAGS / "stack_tips"), "--live", "--compare", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "6 reports, live" in text and "all recorded reports reproduced" in text
    assert (out / "metadata.yaml").is_file()
