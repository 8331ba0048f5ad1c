"""rclpy message <-> message dict conversion and the RViz markers, in-process (no DDS)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from rbe_msgs.msg import AssemblyState, StabilityReport
from rclpy.serialization import deserialize_message, serialize_message
from scipy.spatial.transform import Rotation
from std_msgs.msg import Header
from visualization_msgs.msg import Marker

from rbe_client import stacked_boxes
from rbe_ros.analysis.check import check_scene
from rbe_ros.geometry.block import pose_block
from rbe_ros.messages import header_dict, report_to_dict, state_to_dict
from rbe_ros.rbe.result import Report, Status
from rbe_ros.ros.convert import (dict_to_message, message_to_dict, report_to_msg,
                                 scene_from_msg)
from rbe_ros.ros.markers import report_markers
from rbe_ros.scene import SceneError, box_block, make_scene


def test_state_dict_round_trip_through_rclpy_and_cdr():
    scene = stacked_boxes(0.45)
    d = state_to_dict(scene, "map", 12_000_000_345)
    msg = dict_to_message(d, AssemblyState)
    assert msg.header.stamp.sec == 12 and msg.header.stamp.nanosec == 345
    assert len(msg.blocks) == 3 and msg.blocks[2].pose.position.x == 0.45
    back = deserialize_message(serialize_message(msg), AssemblyState)
    assert message_to_dict(back) == d
    got = scene_from_msg(back)
    assert [b.id for b in got.blocks] == ["ground", "a", "b"]
    assert np.array_equal(got.block("b").position, [0.45, 0.0, 1.5])
    assert got.blocks[0].support and got.block("a").density == 2000.0


def test_unknown_field_and_cast():
    with pytest.raises(ValueError, match="no field 'colour'"):
        dict_to_message({"colour": 1}, Marker)
    m = dict_to_message({"id": 3.0, "scale": {"x": 1}, "frame_locked": 1}, Marker)
    assert m.id == 3 and m.scale.x == 1.0 and m.frame_locked is True


def test_scene_from_msg_rejects_bad_input():
    msg = dict_to_message(state_to_dict(stacked_boxes(0.45)), AssemblyState)
    msg.blocks[1].pose.position.z = math.inf
    with pytest.raises(SceneError, match="'a'.*NaN or infinity"):
        scene_from_msg(msg)
    msg = dict_to_message(state_to_dict(stacked_boxes(0.45)), AssemblyState)
    msg.sequence = ["ghost"]
    with pytest.raises(SceneError, match="ghost"):
        scene_from_msg(msg)
    assert len(scene_from_msg(msg, sequence=False).blocks) == 3


def test_report_to_msg_matches_the_message_dict():
    report = check_scene(stacked_boxes(0.55))
    header = Header(frame_id="lab", stamp=Time(sec=5, nanosec=6))
    msg = report_to_msg(report, header)
    assert isinstance(msg, StabilityReport)
    assert message_to_dict(msg) == report_to_dict(report, header_dict("lab", 5_000_000_006))
    assert msg.status == StabilityReport.TENSION_REQUIRED and msg.unstable_blocks == ["b"]
    assert report_to_msg(report, header_dict("lab", 5_000_000_006)) == msg


# --- markers ----------------------------------------------------------------------------------

def _length(m) -> float:
    return float(np.linalg.norm([m.points[1].x - m.points[0].x, m.points[1].y - m.points[0].y,
                                 m.points[1].z - m.points[0].z]))


@pytest.mark.parametrize("shift", [0.45, 0.55])
def test_markers_of_a_report(shift):
    scene = stacked_boxes(shift)
    report = check_scene(scene)
    stamp = Time(sec=7, nanosec=8)
    markers = report_markers(scene, report, "map", stamp, max_length=0.5).markers
    assert markers[0].action == Marker.DELETEALL
    assert all(m.header.frame_id == "map" and m.header.stamp == stamp for m in markers)
    assert len({(m.ns, m.id) for m in markers}) == len(markers)
    assert {m.ns for m in markers[1:]} == ({"forces", "interfaces", "kerns"}
                                           | ({"unstable"} if shift > 0.5 else set()))
    arrows = [m for m in markers if m.ns == "forces"]
    forces = np.vstack([r.normal_forces[:, None] * r.normal + r.tangential_forces
                        for r in report.interfaces])
    normal = np.concatenate([r.normal_forces for r in report.interfaces])
    vertices = np.vstack([r.polygon for r in report.interfaces])
    assert len(arrows) == len(forces) == 8
    mags = np.linalg.norm(forces, axis=1)
    lengths = np.array([_length(m) for m in arrows])
    assert lengths.max() == pytest.approx(0.5)
    assert np.allclose(lengths, 0.5 * mags / mags.max())
    for m, v, f in zip(arrows, vertices, forces):
        assert np.allclose([m.points[0].x, m.points[0].y, m.points[0].z], v)
        end = np.array([m.points[1].x, m.points[1].y, m.points[1].z])
        assert np.allclose(end, v + 0.5 * f / mags.max())
    red = [m.color.r > 0.5 and m.color.g < 0.5 for m in arrows]
    assert red == [bool(f < 0) for f in normal]
    assert any(red) == (shift > 0.5)
    for ns in ("interfaces", "kerns"):
        strips = [m for m in markers if m.ns == ns]
        assert len(strips) == len(report.interfaces)
        assert all(m.type == Marker.LINE_STRIP and m.points[0] == m.points[-1] for m in strips)
    polygon = [m for m in markers if m.ns == "interfaces"][0]
    assert len(polygon.points) == len(report.interfaces[0].polygon) + 1


def test_unstable_block_mesh_is_posed():
    q = Rotation.from_euler("z", 0.3).as_quat()
    scene = make_scene("s", [box_block("g", (3, 3, 0.2), (0, 0, -0.1), support=True, mass=1),
                             box_block("x", (1, 0.5, 0.2), (0.2, 0.1, 0.1), q, density=1000)])
    report = Report(False, Status.TENSION_REQUIRED, "test", unstable_blocks=["x", "missing"])
    markers = report_markers(scene, report, "w", Time()).markers
    unstable = [m for m in markers if m.ns == "unstable"]
    assert len(unstable) == 1 and unstable[0].type == Marker.TRIANGLE_LIST
    pts = np.array([[p.x, p.y, p.z] for p in unstable[0].points])
    assert len(pts) == 36
    world = pose_block(scene.block("x")).vertices
    assert all(np.min(np.linalg.norm(world - p, axis=1)) < 1e-12 for p in pts)
    assert 0 < unstable[0].color.a < 1


def test_markers_of_an_invalid_input_report():
    report = Report(False, Status.INVALID_INPUT, "invalid input: x")
    markers = report_markers(None, report, "w", Time()).markers
    assert [m.action for m in markers] == [Marker.DELETEALL]
