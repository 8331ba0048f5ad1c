"""rclpy message <-> message dict conversion, in-process (no DDS); the markers are tested in
tests/test_markers.py."""
from __future__ import annotations

import array
import math

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Polygon
from rbe_msgs.msg import AssemblyState, InterfaceForces, StabilityReport
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Header
from visualization_msgs.msg import Marker

from rbe_client import canonical, stacked_boxes
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.generators import running_bond_wall
from rbe_ros.io.messages import header_dict, report_to_dict, state_to_dict
from rbe_ros.ros.convert import (dict_to_message, message_to_dict, scene_from_msg,
                                 set_message_fields)
from rbe_ros.scene import SceneError


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


def test_fast_paths_keep_the_general_behaviour():
    """Arrays of all-float messages and float64[] sequences take fast paths; what they do not
    take (partial or bad dicts, strings, other types) behaves as in the general path."""
    m = dict_to_message({"points": [{"x": 1, "y": "2.5", "z": 3}, {"x": 4.0}, {}]}, Marker)
    assert [(p.x, p.y, p.z) for p in m.points] == [(1.0, 2.5, 3.0), (4.0, 0.0, 0.0),
                                                   (0.0, 0.0, 0.0)]
    assert all(type(v) is float for p in m.points for v in (p.x, p.y, p.z))
    for bad, error, match in (({"x": 1.0, "y": 2.0, "w": 3.0}, ValueError, "no field 'w'"),
                              ({"x": 1.0, "q": 0.0}, ValueError, "no field 'q'"),
                              ([1.0, 2.0, 3.0], TypeError, "Point: expected a message dict"),
                              ({"x": "one", "y": 0.0, "z": 0.0}, ValueError, "one")):
        with pytest.raises(error, match=match):
            dict_to_message({"points": [bad]}, Marker)

    f = dict_to_message({"normal_forces": [1, 2.5, "-3"]}, InterfaceForces)
    assert isinstance(f.normal_forces, array.array) and f.normal_forces.typecode == "d"
    assert f.normal_forces.tolist() == [1.0, 2.5, -3.0]
    f = dict_to_message({"normal_forces": np.array([0.1, -2.0])}, InterfaceForces)
    assert f.normal_forces.tolist() == [0.1, -2.0]
    f = dict_to_message({"normal_forces": (x for x in (1, "2"))}, InterfaceForces)
    assert f.normal_forces.tolist() == [1.0, 2.0]
    with pytest.raises(ValueError):
        dict_to_message({"normal_forces": ["x"]}, InterfaceForces)

    # (n, k) arrays for sequences of all-float messages: rows in field order
    rows = np.array([[0.1, 0.2, 0.3], [-1.0, 2.0, 1e300]])
    f = dict_to_message({"polygon": rows, "kern": np.array([[1, 2, 3]])}, InterfaceForces)
    assert [(p.x, p.y, p.z) for p in f.polygon] == [tuple(r) for r in rows.tolist()]
    assert all(type(p) is Point for p in f.polygon) and (f.kern[0].x, f.kern[0].z) == (1.0, 3.0)
    assert type(f.kern[0].x) is float
    assert dict_to_message({"points": np.zeros((2, 3))}, Polygon).points[1].z == 0.0  # Point32
    with pytest.raises(ValueError, match=r"expected an \(n, 3\) array.*\(4,\)"):
        dict_to_message({"polygon": np.zeros(4)}, InterfaceForces)

    # the one-call constructor path and the in-place path give the same message
    values = {"header": {"frame_id": "f", "stamp": {"sec": 1}}, "ns": "n", "id": 2,
              "points": [{"x": 1.5, "y": -2.0, "z": 0.25}], "colors": [{"r": 1, "a": 0.5}],
              "scale": {"x": 0.1}}
    assert dict_to_message(values, Marker) == set_message_fields(Marker(), values)


def test_report_message_of_a_wall_is_the_plain_dicts_message():
    """The numpy form of a report's dict (fast paths) gives the message of the plain message
    dict, field for field and in CDR."""
    report = check_scene(running_bond_wall(4, 5))
    assert len(report.interfaces) > 20
    header = header_dict("wall", 3_000_000_004)
    msg = dict_to_message(report_to_dict(report, header, arrays=True), StabilityReport)
    plain = report_to_dict(report, header)
    assert canonical(msg) == canonical(plain)
    reference = set_message_fields(StabilityReport(), plain)      # the in-place path
    assert msg == reference
    assert deserialize_message(serialize_message(msg), StabilityReport) == reference


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


def test_report_message_matches_the_message_dict():
    report = check_scene(stacked_boxes(0.55))
    header = message_to_dict(Header(frame_id="lab", stamp=Time(sec=5, nanosec=6)))
    assert header == header_dict("lab", 5_000_000_006)
    msg = dict_to_message(report_to_dict(report, header, arrays=True), StabilityReport)
    assert message_to_dict(msg) == report_to_dict(report, header)
    assert msg.status == StabilityReport.TENSION_REQUIRED and msg.unstable_blocks == ["b"]
