"""Bags that replay after run-time changes: the node records its settings (check options and
frame_id) at the start and after every parameter change, and an offline replay checks each
state with the settings it was checked with."""
from __future__ import annotations

from rbe_msgs.msg import StabilityReport

from rbe_ros.io.replay import read_runs, replay_bag
from rbe_ros.ros.live import NodeProcess

from rbe_client import Client, state_msg
from test_node_params import slope
from test_robustness import set_parameter


def test_replay_compare_after_a_run_time_change_of_friction_and_a_frame_id(rclpy_context,
                                                                          tmp_path):
    bag = tmp_path / "bag"
    proc = NodeProcess(["-p", f"mcap_path:={bag}", "-p", "frame_id:=cell_frame"],
                       tmp_path / "node.log")
    client = Client(rclpy_context, markers=False)
    try:
        client.wait_ready(proc)
        before = state_msg(slope(0.45))             # needs |V|/N = 0.45: stands at mu 0.6
        client.publish(before)
        first = client.report_for(before)
        assert set_parameter(client, "friction_coefficient", 0.3).successful
        after = state_msg(slope(0.45))              # slides at mu 0.3
        client.publish(after)
        second = client.report_for(after)
    finally:
        client.close()
        assert proc.stop() == 0
    assert first.status == StabilityReport.STABLE
    assert second.status == StabilityReport.FRICTION_EXCEEDED
    assert first.header.frame_id == second.header.frame_id == "cell_frame"
    runs = read_runs(bag)
    assert [run.settings["options"]["solve"]["mu"] for run in runs] == [0.6, 0.3]
    assert {run.settings["frame_id"] for run in runs} == {"cell_frame"}
    result = replay_bag(bag, write=False)
    assert result.matches, result.diff()
    assert [r["header"]["frame_id"] for run in result.replayed for r in run] == ["cell_frame"] * 2
    assert [r["status"] for run in result.replayed for r in run] == [
        StabilityReport.STABLE, StabilityReport.FRICTION_EXCEEDED]
