"""rbe_node as a separate process, driven over DDS: topic, service, action, markers, bag.

One node process for the whole module (started by the ``rbe`` fixture with a bag path);
the last test stops it with SIGINT and reads its bag back with rosbags.
"""
from __future__ import annotations

import math
import threading
import time
from collections import Counter
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from action_msgs.msg import GoalStatus
from geometry_msgs.msg import Quaternion
from rbe_msgs.msg import StabilityReport
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from rosbags.highlevel import AnyReader
from visualization_msgs.msg import Marker

from rbe_client import (TIMEOUT, Client, NodeProcess, canonical, stacked_boxes, state_msg,
                        tower, wait_future, wait_until)
from rbe_ros.io import bag
from rbe_ros.io.scene_json import load_scene

REPO = Path(__file__).resolve().parents[2]
WEIGHT = 2000.0 * 1.0 * 9.81   # one 1 m box of density 2000 under g = 9.81


@pytest.fixture(scope="module")
def rbe(rclpy_context, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rbe_node")
    proc = NodeProcess(["-p", f"mcap_path:={tmp / 'bag'}", "-p", "friction_coefficient:=0.6"],
                       tmp / "node.log")
    client = Client(rclpy_context)
    try:
        client.wait_ready(proc)
        yield SimpleNamespace(proc=proc, client=client, bag=tmp / "bag",
                              start_ns=time.time_ns())
    finally:
        client.close()
        proc.stop()


def interface(report, a: str, b: str):
    found = [i for i in report.interfaces if (i.block_a, i.block_b) == (a, b)]
    assert len(found) == 1, [(i.block_a, i.block_b) for i in report.interfaces]
    return found[0]


def xyz(v) -> np.ndarray:
    return np.array([v.x, v.y, v.z])


def is_red(colour) -> bool:
    """A std_msgs/ColorRGBA is red (tension)."""
    return colour.r > 0.5 and colour.g < 0.5


def check_stack_report(r, shift: float) -> None:
    """The verdict and forces of the stack whose top box is shifted by ``shift``."""
    top = interface(r, "a", "b")
    assert r.num_blocks == 3 and r.step_index == -1 and r.block_placed == ""
    assert len(top.polygon) == 4
    if shift < 0.5:
        assert r.stable and r.status == StabilityReport.STABLE, r.message
        assert r.unstable_blocks == []
        assert top.normal_resultant == pytest.approx(WEIGHT, rel=1e-6)
        assert sum(top.normal_forces) == pytest.approx(WEIGHT, rel=1e-6)
        # centre of pressure straight under the top box's centroid, on the interface
        assert np.abs(xyz(top.centre_of_pressure) - [shift, 0.0, 1.0]).max() < 1e-6
        assert np.allclose(xyz(top.normal), [0, 0, 1])
        assert not top.tension and not top.friction_exceeded
    else:
        assert not r.stable and r.status == StabilityReport.TENSION_REQUIRED
        assert "a|b" in r.message and "tension" in r.message
        assert r.unstable_blocks == ["b"]
        assert top.tension and min(top.normal_forces) < 0
        assert r.max_tension > 0.01 * WEIGHT


@pytest.mark.parametrize("shift", [0.45, 0.55])
def test_topic_report_and_markers(rbe, shift):
    state = state_msg(stacked_boxes(shift))          # empty frame: the node's frame_id
    rbe.client.publish(state)
    r = rbe.client.report_for(state)
    assert r.header.frame_id == "world"
    assert r.header.stamp == state.header.stamp
    check_stack_report(r, shift)

    markers = rbe.client.markers_for(r).markers
    assert markers[0].action == Marker.DELETEALL
    assert all(m.header.frame_id == "world" for m in markers)
    assert len({(m.ns, m.id) for m in markers}) == len(markers)
    by_ns = {}
    for m in markers[1:]:
        by_ns.setdefault(m.ns, []).append(m)
    # every block a mesh, the tipping one red
    blocks = {m.text: m for m in by_ns["blocks"]}
    assert list(blocks) == ["ground", "a", "b"]
    assert all(m.type == Marker.TRIANGLE_LIST and len(m.points) == 36 for m in blocks.values())
    assert is_red(blocks["b"].color) == (shift > 0.5) and not is_red(blocks["a"].color)
    assert max(p.x for p in blocks["b"].points) == pytest.approx(shift + 0.5)
    # a segment per interface vertex, tension in a red marker of its own
    forces = by_ns["forces"]
    assert all(m.type == Marker.LINE_LIST for m in forces)
    assert sum(len(m.points) for m in forces) == 2 * sum(len(i.polygon)
                                                        for i in r.interfaces) == 16
    red = [(m.points[k], m.points[k + 1]) for m in forces if is_red(m.color)
           for k in range(0, len(m.points), 2)]
    strips = by_ns["interfaces"]
    assert sum(len(m.points) for m in strips) == 2 * sum(len(i.polygon) for i in r.interfaces)
    [kerns] = by_ns["kerns"]
    assert kerns.type == Marker.LINE_LIST and 0 < kerns.scale.x < strips[0].scale.x
    [text] = by_ns["text"]
    assert text.text.endswith(r.message)
    if shift < 0.5:
        assert red == [] and not any(is_red(m.color) for m in strips)
    else:
        top = interface(r, "a", "b")
        assert len(red) == sum(f < 0 for f in top.normal_forces) == 2
        # the red segments start at the tension vertices and point down, out of block b
        starts = {tuple(np.round(xyz(start), 9)) for start, _ in red}
        assert starts == {tuple(np.round(xyz(p), 9))
                          for p, f in zip(top.polygon, top.normal_forces) if f < 0}
        assert all(end.z < start.z for start, end in red)
        # the edges of the tension interface a|b are red, the others not
        assert sum(len(m.points) for m in strips if is_red(m.color)) == 2 * len(top.polygon)


def test_topic_sequence_reports_every_step(rbe):
    scene = load_scene(REPO / "examples" / "build_sequence.json")
    state = state_msg(scene, "site")
    rbe.client.publish(state)
    last = rbe.client.report_for(state, step=5)
    assert last.block_placed == "cap" and last.status == StabilityReport.TENSION_REQUIRED
    assert last.header.frame_id == "site"
    with rbe.client.lock:
        steps = [r.step_index for r in rbe.client.reports
                 if r.header.stamp == state.header.stamp]
    assert steps == sorted(set(steps)) and steps[-1] == 5


def test_service_round_trip(rbe):
    for shift in (0.45, 0.55):
        state = state_msg(stacked_boxes(shift), "lab")
        r = rbe.client.call_check(state)
        assert r.header.frame_id == "lab" and r.header.stamp == state.header.stamp
        check_stack_report(r, shift)


def test_service_ignores_the_sequence(rbe):
    scene = load_scene(REPO / "examples" / "build_sequence.json")
    r = rbe.client.call_check(state_msg(scene))
    assert r.step_index == -1 and r.num_blocks == len(scene.blocks)
    assert r.status == StabilityReport.TENSION_REQUIRED and "cap" in r.unstable_blocks


def test_invalid_input_does_not_kill_the_node(rbe):
    nan = state_msg(stacked_boxes(0.45))
    nan.blocks[1].pose.position.x = math.nan
    r = rbe.client.call_check(nan)
    assert r.status == StabilityReport.INVALID_INPUT and not r.stable
    assert "'a'" in r.message and "NaN" in r.message and r.interfaces == []

    zero_q = state_msg(stacked_boxes(0.45))
    zero_q.blocks[2].pose.orientation = Quaternion(x=0.0, y=0.0, z=0.0, w=0.0)
    r = rbe.client.call_check(zero_q)
    assert r.status == StabilityReport.INVALID_INPUT and "'b'" in r.message
    assert "unit norm" in r.message
    # the markers show the block at fault (drawn unrotated) and the reason
    markers = rbe.client.markers_for(r).markers
    colours = {m.text: m.color for m in markers if m.ns == "blocks"}
    assert list(colours) == ["ground", "a", "b"]
    assert [k for k, c in colours.items() if c.r > 0.9 and c.b > 0.9] == ["b"]
    assert [m.text for m in markers if m.ns == "text"][0].endswith(r.message)

    no_shape = state_msg(stacked_boxes(0.45))
    no_shape.blocks[1].mesh.triangles = []
    rbe.client.publish(no_shape)
    r = rbe.client.report_for(no_shape)
    assert r.status == StabilityReport.INVALID_INPUT and "BOX" in r.message
    markers = rbe.client.markers_for(r).markers     # the shapeless block cannot be drawn
    assert [m.text for m in markers if m.ns == "blocks"] == ["ground", "b"]

    assert rbe.proc.proc.poll() is None
    check_stack_report(rbe.client.call_check(state_msg(stacked_boxes(0.45))), 0.45)


def test_action_build_sequence(rbe):
    scene = load_scene(REPO / "examples" / "build_sequence.json")
    feedback: list = []
    handle = rbe.client.send_goal(state_msg(scene), feedback)
    # every feedback before the result is asked for: rclpy's action client drops a goal's
    # feedback taken with or after its result (a busy client takes them together)
    wait_until(lambda: len(feedback) == 6, what="6 feedback messages")
    status, result = rbe.client.result(handle)
    assert status == GoalStatus.STATUS_SUCCEEDED
    assert [r.step_index for r in result.reports] == list(range(6))
    assert [r.block_placed for r in result.reports] == list(scene.sequence)
    assert [r.num_blocks for r in result.reports] == [2, 3, 4, 5, 6, 7]
    assert all(r.stable for r in result.reports[:5])
    assert result.first_failing_step == 5
    cap = result.reports[5]
    assert cap.status == StabilityReport.TENSION_REQUIRED and cap.unstable_blocks == ["cap"]
    assert "lintel|cap" in cap.message
    assert [f.steps_done for f in feedback] == [1, 2, 3, 4, 5, 6]
    assert {f.steps_total for f in feedback} == {6}
    assert [canonical(f.last_report) for f in feedback] == [canonical(r) for r in result.reports]


def test_action_invalid_goal_aborts(rbe):
    state = state_msg(stacked_boxes(0.45))
    state.sequence = ["nonexistent"]
    handle = rbe.client.send_goal(state, [])
    status, result = rbe.client.result(handle)
    assert status == GoalStatus.STATUS_ABORTED
    assert len(result.reports) == 1 and result.first_failing_step == -1
    assert result.reports[0].status == StabilityReport.INVALID_INPUT
    assert "nonexistent" in result.reports[0].message


def test_action_cancel(rbe):
    n = 50
    feedback: list = []
    first = threading.Event()
    handle = rbe.client.send_goal(state_msg(tower(n)), feedback, lambda _f: first.set())
    assert first.wait(TIMEOUT), "no feedback"
    cancel = rbe.client.cancel(handle)
    assert len(cancel.goals_canceling) == 1
    status, result = rbe.client.result(handle)
    assert status == GoalStatus.STATUS_CANCELED
    k = len(result.reports)
    assert 1 <= k < n
    assert [r.step_index for r in result.reports] == list(range(k))
    assert all(r.stable for r in result.reports) and result.first_failing_step == -1


def test_parameters_are_validated(rbe):
    client = rbe.client.node.create_client(SetParameters, "/rbe_node/set_parameters")
    try:
        assert client.wait_for_service(timeout_sec=TIMEOUT)

        def set_(name, value):
            req = SetParameters.Request(parameters=[Parameter(name, value=value)
                                                    .to_parameter_msg()])
            return wait_future(client.call_async(req), what="set_parameters").results[0]

        bad = set_("objective", "simplex")
        assert not bad.successful and "qp, lp" in bad.reason
        bad = set_("friction_cone", "cube")
        assert not bad.successful and "pyramid8-outer" in bad.reason
        assert not set_("friction_coefficient", 0.0).successful
        assert not set_("friction_coefficient", 11.0).successful
        assert not set_("tension_tolerance", -1.0).successful
        assert not set_("mcap_path", "/tmp/elsewhere").successful   # read-only
        assert set_("friction_coefficient", 0.6).successful
    finally:
        rbe.client.node.destroy_client(client)


def test_bag_holds_every_state_and_report(rbe):
    """Must run last: stops the node (SIGINT) and reads its bag with rosbags."""
    client = rbe.client
    if not client.sent_states:  # when run alone
        state = state_msg(stacked_boxes(0.45))
        client.publish(state)
        client.report_for(state)
    assert rbe.proc.stop() == 0, rbe.proc.output()
    end_ns = time.time_ns()
    output = rbe.proc.output()
    assert "Traceback" not in output and "ERROR" not in output, output

    states, reports = [], []
    with AnyReader([rbe.bag], default_typestore=bag.typestore()) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        assert topics == {"/rbe_node/assembly": "rbe_msgs/msg/AssemblyState",
                          "/rbe_node/report": "rbe_msgs/msg/StabilityReport",
                          "/rbe_node/markers": "visualization_msgs/msg/MarkerArray",
                          "/rbe_node/settings": "std_msgs/msg/String"}
        markers = 0
        for conn, stamp, raw in reader.messages():
            assert rbe.start_ns - 60e9 < stamp <= end_ns
            if conn.topic == "/rbe_node/markers":
                markers += 1        # one array per report (record_markers: true)
                continue
            if conn.topic == "/rbe_node/settings":   # tests/ros/test_settings_replay.py
                continue
            d = bag.to_dict(reader.typestore, conn.msgtype, reader.deserialize(raw, conn.msgtype))
            (states if conn.topic == "/rbe_node/assembly" else reports).append(d)
    assert markers == len(reports)

    assert Counter(map(canonical, states)) == Counter(map(canonical, client.sent_states))
    recorded = [canonical(r) for r in reports]
    assert len(recorded) == len(set(recorded))
    received = {canonical(r) for r in client.reports + client.other_reports}
    assert set(recorded) == received
