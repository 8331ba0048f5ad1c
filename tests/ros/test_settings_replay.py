"""Bags that replay after run-time changes: the node records its settings (check options and
frame_id) at the start and after every parameter change, and a replay, offline or live (the
live node's parameters set to each state's settings), checks each state with the settings it
was checked with. A bag recorded with non-default options (full solve, contact detection)
replays live through a node started with them."""
from __future__ import annotations

from dataclasses import replace

from rbe_msgs.msg import StabilityReport

from rbe_ros import generators
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.io.messages import state_to_dict
from rbe_ros.io.replay import bag_options, read_runs, record_bag, replay_bag, state_reports
from rbe_ros.ros.live import NodeProcess, live_recheck

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
    for recheck in (None, live_recheck(context=rclpy_context, timeout=60.0)):
        result = replay_bag(bag, write=False, **({"recheck": recheck} if recheck else {}))
        assert result.matches, result.diff()
        assert [r["header"]["frame_id"] for run in result.replayed for r in run] == [
            "cell_frame"] * 2
        assert [r["status"] for run in result.replayed for r in run] == [
            StabilityReport.STABLE, StabilityReport.FRICTION_EXCEEDED]


def test_live_replay_of_a_bag_recorded_with_full_solve_and_contact_options(rclpy_context,
                                                                           tmp_path):
    # unit boxes 0.5 m high (size: the cube root of 0.5 m^3), each 0.4 m along x off the one
    # below: overlaps of 0.6 m^2 = 0.945 size^2, the ground contact 1 m^2 = 1.59 size^2; a
    # min_area of 1 keeps the ground contact only, so the upper boxes have no support
    base = CheckOptions()
    options = replace(base, full_solve=True, contact=replace(base.contact, min_area=1.0))
    scene = generators.stack(3, offsets=[0.0, 0.4, 0.0])
    assert [r.status for r in state_reports(state_to_dict(scene), base)] == [0, 0, 0]
    bag = tmp_path / "bag"
    record_bag(bag, [(scene, "world", 1_000_000_000)], options, markers=False)
    assert bag_options(bag) == options
    result = replay_bag(bag, write=False, recheck=live_recheck(context=rclpy_context,
                                                               timeout=60.0))
    assert result.matches, result.diff()
    reports = result.replayed[0]
    assert [r["model"] for r in reports] == ["full"] * 3
    assert [r["status"] for r in reports] == [StabilityReport.STABLE] + [
        StabilityReport.INFEASIBLE] * 2
    assert [len(r["interfaces"]) for r in reports] == [1, 0, 0]
