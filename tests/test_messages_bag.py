"""Message dicts (rbe_ros.io.messages) and rosbag2 MCAP bags (rbe_ros.io.bag), without ROS."""
from __future__ import annotations

import math
import os
import random
import signal
import subprocess
import sys
import textwrap
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.interfaces import Nodetype
from ruamel.yaml import YAML

from rbe_ros.io import bag, cdr, messages
from rbe_ros.rbe.result import InterfaceResult, Report, Status
from rbe_ros.scene import SceneError, box_block, box_vertices, make_block, make_scene

REPO = Path(__file__).resolve().parents[1]
Q = np.array([0.0, 0.0, math.sin(0.3), math.cos(0.3)])  # 0.6 rad about z
TETRA = np.array([[0, 0, 0], [0.3, 0, 0], [0, 0.3, 0], [0, 0, 0.3]], dtype=float)
TETRA_FACES = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]


def scene():
    return make_scene("lab", [
        box_block("ground", (2, 2, 0.2), (0, 0, -0.1), support=True, mass=1.0),
        box_block("a", (0.2, 0.3, 0.4), (0.1, 0.0, 0.2), Q, density=2400.0),
        make_block("t", TETRA, TETRA_FACES, (0.5, 0.5, 0.0), mass=3.5),
    ], gravity=(0.0, 0.1, -9.8), sequence=["t", "a"])


def report():
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    iface = InterfaceResult(
        block_a="ground", block_b="a", normal=np.array([0.0, 0.0, 1.0]), polygon=square,
        normal_forces=np.array([10.0, 20.5, -1.25, 7.0]),
        tangential_forces=np.array([[0.1, 0, 0], [0, 0.2, 0], [0, 0, 0], [0.3, 0.3, 0]]),
        resultant=np.array([0.4, 0.5, 36.25]), normal_resultant=36.25,
        shear=np.array([0.4, 0.5, 0.0]), centre_of_pressure=np.array([0.45, 0.37, 0.0]),
        torque=-0.125, kern=square[:3] * 0.5, friction_ratio=math.inf, tension=True,
        friction_exceeded=False)
    return Report(status=Status.TENSION_REQUIRED, message="needs glue",
                  max_tension=1.25, worst_friction_ratio=0.0177, solve_time=0.004, num_blocks=3,
                  interfaces=[iface], unstable_blocks=["a"], step_index=1, block_placed="a")


# --- messages ---------------------------------------------------------------------------------

def test_state_round_trip():
    s = scene()
    d = messages.state_to_dict(s, "map", 1_500_000_000_123)
    assert d["header"] == {"stamp": {"sec": 1500, "nanosec": 123}, "frame_id": "map"}
    assert d["gravity"] == {"x": 0.0, "y": 0.1, "z": -9.8}
    assert len(d["blocks"][0]["mesh"]["triangles"]) == 12  # 6 quads fanned
    back = messages.scene_from_state_dict(d)
    assert back.name == "map" and back.sequence == ("t", "a")
    np.testing.assert_allclose(back.gravity, s.gravity)
    for a, b in zip(s.blocks, back.blocks):
        assert (a.id, a.mass, a.density, a.support) == (b.id, b.mass, b.density, b.support)
        np.testing.assert_allclose(b.vertices, a.vertices)
        np.testing.assert_allclose(b.position, a.position)
        np.testing.assert_allclose(b.orientation, a.orientation)
        assert all(len(f) == 3 for f in b.faces)


def test_box_primitive_and_defaults():
    d = {"blocks": [
        {"id": "g", "primitive": {"type": 1, "dimensions": [1.0, 1.0, 0.1]}, "mass": 5.0,
         "support": True},
        {"id": "b", "pose": {"position": {"x": 0.0, "y": 0.0, "z": 0.3}},
         "primitive": {"type": 1, "dimensions": [0.2, 0.2, 0.4]}, "density": 1000.0}]}
    s = messages.scene_from_state_dict(d)
    assert s.name == "assembly"
    np.testing.assert_allclose(s.gravity, [0, 0, -9.81])
    np.testing.assert_allclose(s.block("b").vertices, box_vertices((0.2, 0.2, 0.4)))
    np.testing.assert_allclose(s.block("b").orientation, [0, 0, 0, 1])


def _state(**change):
    d = messages.state_to_dict(scene())
    for path, value in change.items():
        *keys, last = path.split("__")
        target = d
        for k in keys:
            target = target[int(k)] if isinstance(target, list) else target[k]
        target[int(last) if isinstance(target, list) else last] = value
    return d


@pytest.mark.parametrize("d, reason", [
    (_state(blocks__1__pose__position__y=math.nan), "position must be finite, got NaN"),
    (_state(blocks__1__pose__orientation={"x": 0.0, "y": 0.0, "z": 0.0, "w": 0.0}), "unit norm"),
    (_state(blocks__2__id="a"), "duplicate block id 'a'"),
    (_state(sequence=["t", "ghost"]), "sequence names block 'ghost'"),
    (_state(blocks__2__mesh={"triangles": [], "vertices": []}), "block 't': no shape"),
    (_state(blocks__2__mesh__triangles__0={"vertex_indices": [0, 1]}), "3 vertex indices"),
    (_state(blocks__2__mesh__triangles__0={"vertex_indices": [0, 1, 9]}), "existing vertices"),
    (_state(blocks__2__mass=0.0), "exactly one of a positive density"),
    (_state(blocks__2__mass="heavy"), "mass must be a number"),
    (_state(blocks__2__mesh__triangles__0={"vertex_indices": 7}), "vertex_indices must be a list"),
    (_state(blocks__1__primitive={"type": 1, "dimensions": [0.2, -1.0, 0.1]},
            blocks__1__mesh={"triangles": [], "vertices": []}), "3 positive finite dimensions"),
    (_state(blocks__0__pose="nope"), "pose must be a mapping"),
    (_state(blocks__0__id=""), "block #0 has no id"),
    (_state(blocks=[]), "no blocks"),
    ([], "must be a mapping"),
])
def test_malformed_state(d, reason):
    with pytest.raises(SceneError) as err:
        messages.scene_from_state_dict(d)
    assert reason in str(err.value) and "\n" not in str(err.value)


def test_report_round_trip():
    r = report()
    d = messages.report_to_dict(r, messages.header_dict("world", 42))
    assert d["status"] == 1 and isinstance(d["status"], int)
    assert d["interfaces"][0]["polygon"][2] == {"x": 1.0, "y": 1.0, "z": 0.0}
    assert d["interfaces"][0]["normal_forces"] == [10.0, 20.5, -1.25, 7.0]
    back = messages.report_from_dict(d)
    assert back.status is Status.TENSION_REQUIRED and back.unstable_blocks == ("a",)
    assert (back.step_index, back.block_placed, back.num_blocks) == (1, "a", 3)
    a, b = r.interfaces[0], back.interfaces[0]
    for name in ("normal", "polygon", "normal_forces", "tangential_forces", "resultant", "shear",
                 "centre_of_pressure", "kern"):
        np.testing.assert_array_equal(getattr(b, name), getattr(a, name))
    assert b.polygon.shape == (4, 3) and b.kern.shape == (3, 3)
    assert (b.friction_ratio, b.torque, b.tension) == (math.inf, -0.125, True)


# --- bags -------------------------------------------------------------------------------------

def _assert_matches(obj, expected, where="msg"):
    """A rosbags/mcap_ros2 object equals a message dict, field by field (independent of bag.py)."""
    if isinstance(expected, dict):
        for key, value in expected.items():
            _assert_matches(getattr(obj, key), value, f"{where}.{key}")
    elif isinstance(expected, list):
        items = obj.tolist() if isinstance(obj, np.ndarray) else list(obj)
        assert len(items) == len(expected), where
        for i, (o, e) in enumerate(zip(items, expected)):
            _assert_matches(o, e, f"{where}[{i}]")
    else:
        assert obj == expected, f"{where}: {obj!r} != {expected!r}"


@pytest.fixture
def written(tmp_path):
    state = messages.state_to_dict(scene(), "world", 1_000)
    rep = messages.report_to_dict(report(), messages.header_dict("world", 1_000))
    path = tmp_path / "rec"
    with bag.BagWriter(path) as w:
        w.add_topic("/rbe/assembly", "rbe_msgs/msg/AssemblyState", transient_local=True)
        w.add_topic("/rbe/report", "rbe_msgs/msg/StabilityReport")
        w.write("/rbe/assembly", state, 2_000)
        w.write("/rbe/report", rep, 3_000)
        # raw CDR bytes, as the node passes them
        w.write("/rbe/report", cdr.encode(bag.typestore(), "rbe_msgs/msg/StabilityReport", rep),
                4_000)
    return path, state, rep


def test_bag_reads_with_rosbags(written):
    path, state, rep = written
    with AnyReader([path]) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == {
            "/rbe/assembly": "rbe_msgs/msg/AssemblyState",
            "/rbe/report": "rbe_msgs/msg/StabilityReport"}
        got = [(c.topic, t, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages()]
    assert [(topic, t) for topic, t, _ in got] == [
        ("/rbe/assembly", 2_000), ("/rbe/report", 3_000), ("/rbe/report", 4_000)]
    _assert_matches(got[0][2], state)
    _assert_matches(got[1][2], rep)
    _assert_matches(got[2][2], rep)
    msg = got[1][2]
    assert msg.status == 1 == msg.TENSION_REQUIRED and msg.stable is False
    assert msg.interfaces[0].normal_forces[2] == -1.25
    assert (msg.interfaces[0].centre_of_pressure.x, msg.interfaces[0].centre_of_pressure.y) == (0.45, 0.37)
    assert math.isinf(msg.interfaces[0].friction_ratio)
    assert got[0][2].blocks[2].mass == 3.5 and got[0][2].blocks[1].pose.orientation.w == pytest.approx(Q[3], abs=1e-15)


def test_bag_mcap_layout(written):
    path, state, _ = written
    mcap_file = path / "rec_0.mcap"
    assert sorted(p.name for p in path.iterdir()) == ["metadata.yaml", "rec_0.mcap"]
    with mcap_file.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary.statistics.message_count == 3
        schemas = {s.name: s for s in summary.schemas.values()}
        assert set(schemas) == {"rbe_msgs/msg/AssemblyState", "rbe_msgs/msg/StabilityReport"}
        for s in schemas.values():
            assert s.encoding == "ros2msg"
            text = s.data.decode()
            assert "=" * 80 + "\nMSG: std_msgs/Header\n" in text
            assert "\nMSG: geometry_msgs/Point\n" in text
        assert "\nMSG: rbe_msgs/Block\n" in schemas["rbe_msgs/msg/AssemblyState"].data.decode()
        assert "\nMSG: rbe_msgs/InterfaceForces\n" in schemas["rbe_msgs/msg/StabilityReport"].data.decode()
        durability = {}
        for ch in summary.channels.values():
            assert ch.message_encoding == "cdr"
            assert ch.metadata["topic_type_hash"].startswith("RIHS01_")
            (qos,) = YAML(typ="safe").load(ch.metadata["offered_qos_profiles"])
            assert (qos["reliability"], qos["history"], qos["depth"]) == ("reliable", "keep_last", 10)
            durability[ch.topic] = qos["durability"]
        assert durability == {"/rbe/assembly": "transient_local", "/rbe/report": "volatile"}
        # a second, independent decoder (mcap_ros2, what Foxglove-like tools use)
        decoded = [m for _, _, _, m in reader.iter_decoded_messages(topics=["/rbe/assembly"])]
    _assert_matches(decoded[0], state)

    meta = YAML(typ="safe").load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert (meta["version"], meta["storage_identifier"], meta["message_count"]) == (9, "mcap", 3)
    assert meta["relative_file_paths"] == ["rec_0.mcap"]
    assert (meta["starting_time"]["nanoseconds_since_epoch"], meta["duration"]["nanoseconds"]) == (2_000, 2_000)
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]}
    assert counts == {"/rbe/assembly": 1, "/rbe/report": 2}


def test_read_bag_returns_what_was_written(written):
    path, state, rep = written
    out = list(bag.read_bag(path))
    assert [(m.topic, m.msgtype, m.stamp_ns) for m in out] == [
        ("/rbe/assembly", "rbe_msgs/msg/AssemblyState", 2_000),
        ("/rbe/report", "rbe_msgs/msg/StabilityReport", 3_000),
        ("/rbe/report", "rbe_msgs/msg/StabilityReport", 4_000)]
    assert out[0].data == state and out[1].data == rep and out[2].data == rep
    back = messages.report_from_dict(out[1].data)
    np.testing.assert_array_equal(back.interfaces[0].normal_forces, [10.0, 20.5, -1.25, 7.0])
    assert messages.scene_from_state_dict(out[0].data).block("t").mass == 3.5


def test_writer_refuses_existing_dir_and_unknown_topic(tmp_path):
    with pytest.raises(FileExistsError):
        bag.BagWriter(tmp_path)
    with bag.BagWriter(tmp_path / "b") as w:
        with pytest.raises(KeyError):
            w.write("/nope", {}, 0)
        with pytest.raises(KeyError):
            w.add_topic("/x", "rbe_msgs/msg/Nope")


def test_killed_recording_is_recoverable(tmp_path):
    """Messages written before a SIGKILL are on disk and read back (no footer, no close)."""
    path = tmp_path / "killed"
    script = textwrap.dedent(f"""
        import sys, time
        from rbe_ros.io import bag, messages
        w = bag.BagWriter({str(path)!r})
        w.add_topic("/rbe/report", "rbe_msgs/msg/StabilityReport")
        for i in range(5):
            w.write("/rbe/report", {{"step_index": i, "message": "step %d" % i}}, 1000 + i)
        print("written", flush=True)
        time.sleep(60)
    """)
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, env=env, text=True)
    try:
        assert proc.stdout.readline().strip() == "written"
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert (path / "metadata.yaml").exists()
    out = list(bag.read_bag(path))
    assert [(m.topic, m.stamp_ns, m.data["step_index"], m.data["message"]) for m in out] == [
        ("/rbe/report", 1000 + i, i, f"step {i}") for i in range(5)]


def test_holds_and_hold_report_fields_round_trip():
    from rbe_ros.scene import Hold

    s = scene()
    held = make_scene(s.name, s.blocks, s.gravity, s.sequence,
                      [Hold("a", 1), Hold("t", 0, 1), Hold("ground", 0, 2)])
    d = messages.state_to_dict(held, "map", 7)
    plain = {"max_force": 0.0, "max_torque": 0.0, "grip": {"x": 0.0, "y": 0.0, "z": 0.0},
             "has_grip": False}     # the check's capacities, the centroid
    assert d["holds"] == [{"block": "a", "from_step": 1, "until_step": -1, **plain},
                          {"block": "t", "from_step": 0, "until_step": 1, **plain},
                          {"block": "ground", "from_step": 0, "until_step": 2, **plain}]
    assert messages.scene_from_state_dict(d).holds == held.holds
    assert messages.scene_from_state_dict(messages.state_to_dict(s)).holds == ()
    bad = dict(d, holds=[{"block": "a", "from_step": 0, "until_step": -2}])
    with pytest.raises(SceneError, match="until_step must be -1"):
        messages.scene_from_state_dict(bad)
    with pytest.raises(SceneError, match="no such block"):
        messages.scene_from_state_dict(dict(d, holds=[{"block": "ghost"}]))
    r = replace(report(), held_blocks=("t",), suggested_holds=("a",))
    rd = messages.report_to_dict(r, messages.header_dict("world", 1))
    assert (rd["held_blocks"], rd["suggested_holds"]) == (["t"], ["a"])
    back = messages.report_from_dict(rd)
    assert (back.held_blocks, back.suggested_holds) == (("t",), ("a",))
    # through a bag (CDR) and back
    store = bag.typestore()
    raw = cdr.encode(store, "rbe_msgs/msg/AssemblyState", d)
    obj = store.deserialize_cdr(raw, "rbe_msgs/msg/AssemblyState")
    assert bag.to_dict(store, "rbe_msgs/msg/AssemblyState", obj)["holds"] == d["holds"]


# --- CDR (rbe_ros.io.cdr) ------------------------------------------------------------------------

REPORT = "rbe_msgs/msg/StabilityReport"
_NUMPY = {"bool": np.bool_, "byte": np.uint8, "char": np.uint8, "int8": np.int8,
          "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16, "int32": np.int32,
          "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64, "float32": np.float32,
          "float64": np.float64}


def _random_message(store, msgtype: str, rng: random.Random, zero: bool):
    """A rosbags message object with random values (``zero``: zeros, "" and empty)."""
    def scalar(typ: str):
        if typ == "string":
            return "" if zero else "".join(rng.choice("ab€😀") for _ in range(rng.randrange(6)))
        if zero or typ == "bool":
            return False if zero else rng.random() < 0.5
        if typ.startswith("float"):
            return float(np.array(rng.uniform(-1e3, 1e3), dtype=_NUMPY[typ]))
        if typ == "byte":
            return rng.randrange(128)   # rosbags packs byte as int8; ROS 2 (and cdr): uint8
        info = np.iinfo(_NUMPY[typ])
        return rng.randint(int(info.min), int(info.max))

    def value(desc):
        kind, detail = desc
        if kind == Nodetype.BASE:
            return scalar(detail[0])
        if kind == Nodetype.NAME:
            return message(detail)
        sub, length = detail
        if kind == Nodetype.SEQUENCE:
            length = 0 if zero else rng.randrange(4)
        items = [value(sub) for _ in range(length)]
        if sub[0] == Nodetype.BASE and sub[1][0] != "string":
            return np.array(items, dtype=_NUMPY[sub[1][0]])
        return items

    def message(t: str):
        return store.types[t](**{name: value(desc) for name, desc in store.fielddefs[t][1]})
    return message(msgtype)


def test_cdr_of_every_type_is_rosbags_cdr():
    """Every type of the typestore (ROS 2 Jazzy's and rbe_msgs), with random values (strings
    of 0-5 characters of 1-4 UTF-8 bytes, sequences of 0-3 items: every alignment case) and
    all zero: the CDR of the message dict is rosbags' CDR of the message, byte for byte
    (padding zeros in both), and an empty dict is the all-zero message."""
    store = bag.typestore()
    rng = random.Random(7)
    assert len(store.fielddefs) > 150
    for msgtype in sorted(store.fielddefs):
        for zero in (True, False, False, False):
            obj = _random_message(store, msgtype, rng, zero)
            expected = bytes(store.serialize_cdr(obj, msgtype))
            assert cdr.encode(store, msgtype, bag.to_dict(store, msgtype, obj)) == expected, msgtype
            if zero:
                assert cdr.encode(store, msgtype, {}) == expected, msgtype


def test_cdr_of_a_report_in_both_forms():
    """A report as plain message dict and in the numpy form of report_to_dict(arrays=True):
    the same bytes, which rosbags reads back as the plain dict and writes again identically."""
    store = bag.typestore()
    r = replace(report(), held_blocks=("t",), suggested_holds=("a", "g"), model="local 3",
                dropped_states=4)
    header = messages.header_dict("wörld", 1_500_000_000_123)
    plain = messages.report_to_dict(r, header)
    data = cdr.encode(store, REPORT, plain)
    assert data[:4] == b"\x00\x01\x00\x00" and data[4:8] == (1500).to_bytes(4, "little")
    assert cdr.encode(store, REPORT, messages.report_to_dict(r, header, arrays=True)) == data
    obj = store.deserialize_cdr(data, REPORT)
    assert bag.to_dict(store, REPORT, obj) == plain
    assert bytes(store.serialize_cdr(obj, REPORT)) == data
    empty = messages.report_to_dict(Report(Status.INVALID_INPUT, "invalid: ∅"), header)
    obj = store.deserialize_cdr(cdr.encode(store, REPORT, empty), REPORT)
    assert bag.to_dict(store, REPORT, obj) == empty and obj.interfaces == []


def test_cdr_fills_in_missing_fields_and_casts():
    store = bag.typestore()
    partial = {"step_index": "3", "stable": 1, "num_blocks": 2.0, "header": {"frame_id": 5},
               "interfaces": [{"block_a": "a",
                               "polygon": [{"x": 1}, {"y": "2.5", "z": np.float32(0.5)}],
                               "normal_forces": (v for v in (1, "2")),
                               "kern": np.array([[1, 2, 3]], dtype=np.int64)}],
               "unstable_blocks": ("a",), "model": None}
    data = cdr.encode(store, REPORT, partial)
    got = bag.to_dict(store, REPORT, store.deserialize_cdr(data, REPORT))
    assert (got["step_index"], got["stable"], got["num_blocks"], got["model"]) == (3, True, 2, "")
    assert got["header"] == {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "5"}
    assert got["unstable_blocks"] == ["a"] and got["held_blocks"] == []
    (iface,) = got["interfaces"]
    assert iface["polygon"] == [{"x": 1.0, "y": 0.0, "z": 0.0}, {"x": 0.0, "y": 2.5, "z": 0.5}]
    assert iface["normal_forces"] == [1.0, 2.0]
    assert iface["kern"] == [{"x": 1.0, "y": 2.0, "z": 3.0}]
    assert (iface["block_b"], iface["tangential_forces"], iface["tension"]) == ("", [], False)
    assert iface["normal"] == {"x": 0.0, "y": 0.0, "z": 0.0}
    assert cdr.encode(store, REPORT, got) == data           # the complete dict: same bytes

    # arrays of any dtype numpy casts safely, non-contiguous ones too: the bytes of the lists
    forces = "rbe_msgs/msg/InterfaceForces"
    rows = np.arange(12.0).reshape(3, 4)[:, :3]
    lists = {"polygon": [dict(zip("xyz", row)) for row in rows.tolist()],
             "normal_forces": [1.0, -2.0], "kern": []}
    assert cdr.encode(store, forces, {"polygon": rows, "normal_forces": np.array([1, -2], np.int8),
                                      "kern": np.zeros((0, 3), np.float32)}) \
        == cdr.encode(store, forces, lists)
    image = "sensor_msgs/msg/CompressedImage"       # uint8[]: bytes, numbers, a float array
    assert cdr.encode(store, image, {"data": b"\x01\xff"}) \
        == cdr.encode(store, image, {"data": [1, 255]}) \
        == cdr.encode(store, image, {"data": np.array([1.0, 255.0])})

    # the typestore has no .msg default values: a missing Quaternion.w is 0 (rclpy's is 1)
    q = "geometry_msgs/msg/Quaternion"
    assert store.deserialize_cdr(cdr.encode(store, q, {"x": 0.5}), q).w == 0.0
    # a string ends at its first NUL, as rclpy's C strings do
    text = "std_msgs/msg/String"
    assert cdr.encode(store, text, {"data": "ab\x00c"}) == cdr.encode(store, text, {"data": "ab"})


@pytest.mark.parametrize("msgtype, data, error, match", [
    (REPORT, {"colour": 1}, ValueError,
     r"^rbe_msgs/msg/StabilityReport: rbe_msgs/msg/StabilityReport has no field 'colour'$"),
    (REPORT, {"interfaces": [{}, {"polygon": [{"x": 1.0, "w": 0.0}]}]}, ValueError,
     r"^rbe_msgs/msg/StabilityReport\.interfaces\[1\]\.polygon\[0\]: geometry_msgs/msg/Point "
     r"has no field 'w'$"),
    (REPORT, {"interfaces": [{"polygon": np.zeros((4, 2))}]}, ValueError,
     r"StabilityReport\.interfaces\[0\]\.polygon: expected an \(n, 3\) array of "
     r"geometry_msgs/msg/Point field values, got shape \(4, 2\)"),
    (REPORT, {"interfaces": [{"kern": np.zeros(3)}]}, ValueError,
     r"interfaces\[0\]\.kern: expected an \(n, 3\) array .*got shape \(3,\)"),
    (REPORT, {"interfaces": [{"normal_forces": np.zeros((2, 2))}]}, ValueError,
     r"interfaces\[0\]\.normal_forces: expected a 1-D array, got shape \(2, 2\)"),
    (REPORT, {"interfaces": [{"normal_forces": [1.0, "x"]}]}, ValueError,
     r"interfaces\[0\]\.normal_forces\[1\]: 'x' is not a valid float64"),
    (REPORT, {"status": 300}, ValueError, r"StabilityReport\.status: 300 is not a valid uint8"),
    (REPORT, {"solve_time": [1.0]}, TypeError, r"StabilityReport\.solve_time: \[1\.0\] is not a "
                                               r"float64"),
    (REPORT, {"header": [1, 2]}, TypeError,
     r"StabilityReport\.header: expected a message dict \(std_msgs/msg/Header\), got list"),
    (REPORT, {"unstable_blocks": "ab"}, TypeError,
     r"StabilityReport\.unstable_blocks: expected a sequence, got str"),
    (REPORT, {"interfaces": np.zeros((1, 15))}, TypeError,
     r"StabilityReport\.interfaces: rbe_msgs/msg/InterfaceForces items cannot be given as an "
     r"array"),
    (REPORT, "report", TypeError, r"^rbe_msgs/msg/StabilityReport: expected a message dict "
                                  r"\(rbe_msgs/msg/StabilityReport\), got str$"),
    ("shape_msgs/msg/MeshTriangle", {"vertex_indices": [0, 1]}, ValueError,
     r"MeshTriangle\.vertex_indices: fixed array needs 3 items, got 2"),
    ("shape_msgs/msg/MeshTriangle", {"vertex_indices": [0, 1, -1]}, ValueError,
     r"MeshTriangle\.vertex_indices\[2\]: -1 is not a valid uint32"),
])
def test_cdr_errors_name_the_field(msgtype, data, error, match):
    with pytest.raises(error, match=match):
        cdr.encode(bag.typestore(), msgtype, data)


def test_cdr_refuses_unknown_types_and_bag_writes_nothing_bad(tmp_path):
    with pytest.raises(KeyError, match="unknown message type 'rbe_msgs/msg/Nope'"):
        cdr.encoder(bag.typestore(), "rbe_msgs/msg/Nope")
    with bag.BagWriter(tmp_path / "b") as w:
        w.add_topic("/r", REPORT)
        with pytest.raises(ValueError, match="has no field 'colour'"):
            w.write("/r", {"colour": 1}, 1)
        w.write("/r", {"step_index": 2}, 2)
    assert [(m.stamp_ns, m.data["step_index"]) for m in bag.read_bag(tmp_path / "b")] == [(2, 2)]
