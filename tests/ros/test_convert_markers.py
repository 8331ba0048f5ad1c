"""rclpy message <-> message dict conversion and the RViz markers, in-process (no DDS)."""
from __future__ import annotations

import array
import math

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Polygon
from rbe_msgs.msg import AssemblyState, InterfaceForces, StabilityReport
from rclpy.serialization import deserialize_message, serialize_message
from scipy.spatial.transform import Rotation
from std_msgs.msg import Header
from visualization_msgs.msg import Marker

from rbe_client import canonical, stacked_boxes
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.generators import running_bond_wall
from rbe_ros.geometry.block import pose_block
from rbe_ros.io.messages import header_dict, report_to_dict, state_to_dict
from rbe_ros.rbe.result import InterfaceResult, Report, Status
from rbe_ros.ros.convert import (dict_to_message, message_to_dict, scene_from_msg,
                                 set_message_fields)
from rbe_ros.ros.markers import (COMPRESSION, INTERFACE, INTERFACE_FRICTION, INTERFACE_TENSION,
                                 KERN, TENSION, report_markers)
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


# --- markers ----------------------------------------------------------------------------------

def _segments(marker) -> np.ndarray:
    """(n, 2, 3) start and end of each segment of a LINE_LIST."""
    assert marker.type == Marker.LINE_LIST and len(marker.points) % 2 == 0
    return np.array([[p.x, p.y, p.z] for p in marker.points]).reshape(-1, 2, 3)


def _segment_colours(marker) -> list[tuple]:
    """The colour of each segment of a LINE_LIST with per-point colours (both ends alike)."""
    colours = [(c.r, c.g, c.b, c.a) for c in marker.colors]
    assert len(colours) == len(marker.points) and colours[0::2] == colours[1::2]
    return colours[0::2]


def _outline(polygon) -> np.ndarray:
    """The edges of a closed polygon outline, (k, 2, 3)."""
    polygon = np.asarray(polygon)
    return np.stack([polygon, np.roll(polygon, -1, axis=0)], axis=1)


@pytest.mark.parametrize("shift", [0.45, 0.55])
def test_markers_of_a_report(shift):
    scene = stacked_boxes(shift)
    report = check_scene(scene)
    stamp = Time(sec=7, nanosec=8)
    markers = report_markers(scene, report, "map", stamp, max_length=0.5).markers
    assert markers[0].action == Marker.DELETEALL
    assert all(m.header.frame_id == "map" and m.header.stamp == stamp for m in markers)
    assert len({(m.ns, m.id) for m in markers}) == len(markers)
    assert [(m.ns, m.type) for m in markers[1:]] == (
        [("forces", Marker.LINE_LIST), ("interfaces", Marker.LINE_LIST),
         ("kerns", Marker.LINE_LIST)] + ([("unstable", Marker.TRIANGLE_LIST)] if shift > 0.5
                                         else []))
    forces_marker, interfaces_marker, kerns_marker = markers[1:4]

    # forces: a segment per interface vertex, from the vertex along the force
    forces = np.vstack([r.normal_forces[:, None] * r.normal + r.tangential_forces
                        for r in report.interfaces])
    normal = np.concatenate([r.normal_forces for r in report.interfaces])
    vertices = np.vstack([r.polygon for r in report.interfaces])
    segments = _segments(forces_marker)
    assert len(segments) == len(forces) == 8
    mags = np.linalg.norm(forces, axis=1)
    assert np.array_equal(segments[:, 0], vertices)
    assert np.allclose(segments[:, 1], vertices + 0.5 * forces / mags.max())
    lengths = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
    assert lengths.max() == pytest.approx(0.5)
    colours = _segment_colours(forces_marker)
    assert colours == [TENSION if f < 0 else COMPRESSION for f in normal]
    assert forces_marker.scale.x == pytest.approx(0.025)
    # the largest force: on the ground, straight up, max_length long, green
    longest = int(np.argmax(lengths))
    assert segments[longest, 0, 2] == 0.0 and colours[longest] == COMPRESSION
    assert np.allclose(segments[longest, 1] - segments[longest, 0], [0.0, 0.0, 0.5])
    # the top interface a|b: (shift - 0.5, +-0.5, 1) is its vertex over the edge of a
    top = next(r for r in report.interfaces if (r.block_a, r.block_b) == ("a", "b"))
    edge = [i for i, v in enumerate(vertices)
            if np.allclose(v, [shift - 0.5, 0.5, 1.0]) or np.allclose(v, [shift - 0.5, -0.5, 1.0])]
    assert len(edge) == 2
    for i in edge:
        fn = top.normal_forces[int(np.flatnonzero(np.all(top.polygon == vertices[i], axis=1))[0])]
        assert segments[i, 1] == pytest.approx(vertices[i] + [0.0, 0.0, 0.5 * fn / mags.max()])
        if shift > 0.5:     # tension: red, pointing down out of b
            assert colours[i] == TENSION and fn < 0 and segments[i, 1, 2] < 1.0
        else:
            assert colours[i] == COMPRESSION and fn > 0 and segments[i, 1, 2] > 1.0
    assert (TENSION in colours) == (shift > 0.5)

    # interfaces: the closed outline of every polygon, red where tension is needed
    edges = _segments(interfaces_marker)
    assert np.array_equal(edges, np.concatenate([_outline(r.polygon)
                                                 for r in report.interfaces]))
    assert _segment_colours(interfaces_marker) == [
        INTERFACE_TENSION if r.tension else INTERFACE
        for r in report.interfaces for _ in r.polygon]
    assert (INTERFACE_TENSION in _segment_colours(interfaces_marker)) == (shift > 0.5)
    # kerns: the closed outline of every kern, blue, thinner
    assert np.array_equal(_segments(kerns_marker),
                          np.concatenate([_outline(r.kern) for r in report.interfaces]))
    assert list(kerns_marker.colors) == []
    colour = kerns_marker.color
    assert (colour.r, colour.g, colour.b, colour.a) == KERN
    assert 0 < kerns_marker.scale.x < interfaces_marker.scale.x


def _interface(polygon, normal_forces, *, tension=False, friction=False, kern=()):
    polygon = np.asarray(polygon, dtype=float).reshape(-1, 3)
    return InterfaceResult(
        block_a="a", block_b="b", normal=np.array([0.0, 0.0, 1.0]), polygon=polygon,
        normal_forces=np.asarray(normal_forces, dtype=float),
        tangential_forces=np.zeros((len(polygon), 3)), resultant=np.zeros(3),
        normal_resultant=0.0, shear=np.zeros(3), centre_of_pressure=np.zeros(3), torque=0.0,
        kern=np.asarray(kern, dtype=float).reshape(-1, 3), friction_ratio=0.0,
        tension=tension, friction_exceeded=friction)


def test_markers_of_degenerate_polygons_and_default_length():
    """A 2-vertex contact is one edge, a point contact none; the default max_length is half
    the largest polygon extent; tension within tension_tol of the largest force is green."""
    triangle = [[0, 0, 0], [2, 0, 0], [0, 1, 0]]
    report = Report(Status.STABLE, "ok", interfaces=[
        _interface(triangle, [100.0, 50.0, -1e-4], friction=True,
                   kern=[[0.2, 0.2, 0], [0.4, 0.2, 0]]),
        _interface([[5, 0, 1], [5, 1, 1]], [10.0, -20.0], tension=True),
        _interface([[9, 9, 9]], [25.0], kern=[[9, 9, 9]]),
    ])
    markers = report_markers(None, report, "w", Time()).markers
    assert [m.ns for m in markers[1:]] == ["forces", "interfaces", "kerns"]
    forces_marker, interfaces_marker, kerns_marker = markers[1:]
    segments = _segments(forces_marker)     # max_length: half the triangle's extent 2 m
    assert np.allclose(segments[:, 1] - segments[:, 0],
                       [[0, 0, 1.0], [0, 0, 0.5], [0, 0, -1e-6], [0, 0, 0.1], [0, 0, -0.2],
                        [0, 0, 0.25]])
    assert _segment_colours(forces_marker) == [COMPRESSION] * 3 + [COMPRESSION, TENSION,
                                                                   COMPRESSION]
    assert np.array_equal(_segments(interfaces_marker), np.concatenate(
        [_outline(triangle), [[[5, 0, 1], [5, 1, 1]]]]))
    assert _segment_colours(interfaces_marker) == [INTERFACE_FRICTION] * 3 + [INTERFACE_TENSION]
    assert np.array_equal(_segments(kerns_marker), [[[0.2, 0.2, 0], [0.4, 0.2, 0]]])

    still = Report(Status.STABLE, "ok", interfaces=[_interface(triangle, [0.0] * 3)])
    forces_marker = report_markers(None, still, "w", Time(), max_length=0.3).markers[1]
    segments = _segments(forces_marker)     # no force at all: zero-length segments
    assert np.array_equal(segments[:, 0], segments[:, 1]) and len(segments) == 3


def test_unstable_block_mesh_is_posed():
    q = Rotation.from_euler("z", 0.3).as_quat()
    scene = make_scene("s", [box_block("g", (3, 3, 0.2), (0, 0, -0.1), support=True, mass=1),
                             box_block("x", (1, 0.5, 0.2), (0.2, 0.1, 0.1), q, density=1000)])
    report = Report(Status.TENSION_REQUIRED, "test", unstable_blocks=["x", "missing"])
    markers = report_markers(scene, report, "w", Time()).markers
    unstable = [m for m in markers if m.ns == "unstable"]
    assert len(unstable) == 1 and unstable[0].type == Marker.TRIANGLE_LIST
    pts = np.array([[p.x, p.y, p.z] for p in unstable[0].points])
    assert len(pts) == 36
    world = pose_block(scene.block("x")).vertices
    assert all(np.min(np.linalg.norm(world - p, axis=1)) < 1e-12 for p in pts)
    assert 0 < unstable[0].color.a < 1


def test_markers_of_an_invalid_input_report():
    report = Report(Status.INVALID_INPUT, "invalid input: x")
    markers = report_markers(None, report, "w", Time()).markers
    assert [m.action for m in markers] == [Marker.DELETEALL]
