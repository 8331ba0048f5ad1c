"""rbe_ros.io.cdr against rclpy: the bytes of ``serialize_message``, read back by
``deserialize_message`` as the same message (no DDS).

rclpy's ``serialize_message`` leaves the padding bytes of its buffer uninitialised: heap
garbage that changes from run to run (in the report of a 117-block wall ~8800 of 168k bytes,
all padding; a buffer fresh from mmap is zeros). rbe_ros.io.cdr writes zeros there, as rosbags
does. So rclpy's bytes are made in a process whose malloc returns zeroed memory
(:func:`rclpy_bytes`), where they are reproducible; :func:`test_rclpy_differs_only_in_padding`
shows the difference otherwise.
"""
from __future__ import annotations

import dataclasses
import math
import os
import pickle
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rbe_msgs.msg import AssemblyState, StabilityReport
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from rbe_client import stacked_boxes
from rbe_ros.io import bag, cdr
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.generators import running_bond_wall
from rbe_ros.io.messages import header_dict, report_to_dict, state_to_dict
from rbe_ros.rbe.result import InterfaceResult, Report, Status
from rbe_ros.ros.convert import dict_to_message, message_to_dict
from rbe_ros.io.markers import step_markers
from rbe_ros.scene import Hold, box_block, make_scene

REPO = Path(__file__).resolve().parents[2]
REPORT = "rbe_msgs/msg/StabilityReport"
#: glibc malloc without the per-thread cache (which hands out chunks as they were freed) and
#: with every allocation filled with 0xff ^ 0xff: zeroed memory (mmap'ed chunks are zeros)
ZEROED_MALLOC = "glibc.malloc.tcache_count=0:glibc.malloc.perturb=255"
_SERIALIZE = """
import importlib, pickle, sys
from rclpy.serialization import serialize_message
from rbe_ros.ros.convert import dict_to_message
out = []
for msgtype, values in pickle.load(sys.stdin.buffer):
    package, _, name = msgtype.split("/")
    cls = getattr(importlib.import_module(package + ".msg"), name)
    out.append(bytes(serialize_message(dict_to_message(values, cls))))
pickle.dump(out, sys.stdout.buffer)
"""


def rclpy_bytes(cases: list[tuple[str, dict]]) -> list[bytes]:
    """``serialize_message`` of the message of each (msgtype, message dict), with zeros in
    its padding: made in a process with a zeroing malloc."""
    if platform.libc_ver()[0] != "glibc":
        pytest.skip("needs glibc (its malloc tunables)")
    env = dict(os.environ, GLIBC_TUNABLES=ZEROED_MALLOC,
               PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    done = subprocess.run([sys.executable, "-c", _SERIALIZE], input=pickle.dumps(cases),
                          capture_output=True, env=env, check=True, timeout=120)
    return pickle.loads(done.stdout)


def encode(msgtype: str, data) -> bytes:
    return cdr.encode(bag.typestore(), msgtype, data)


def _interface(block_a, block_b, polygon, kern=()):
    polygon = np.asarray(polygon, dtype=float).reshape(-1, 3)
    k = len(polygon)
    return InterfaceResult(
        block_a=block_a, block_b=block_b, normal=np.array([0.0, 0.6, 0.8]), polygon=polygon,
        normal_forces=np.linspace(-1.5, 2.0, k), tangential_forces=np.full((k, 3), 1e-300),
        resultant=np.array([0.1, -0.2, 3.0]), normal_resultant=2.5,
        shear=np.array([0.1, -0.2, 0.0]), centre_of_pressure=np.array([1.0, 2.0, 3.0]),
        torque=-0.0, kern=np.asarray(kern, dtype=float).reshape(-1, 3), friction_ratio=math.inf,
        tension=k % 2 == 1, friction_exceeded=True)


def _reports() -> dict[str, Report]:
    unstable = check_scene(stacked_boxes(0.55))
    return {
        "stable wall": check_scene(running_bond_wall(4, 5)),
        "unstable": unstable,
        "holds": dataclasses.replace(unstable, held_blocks=["a"], suggested_holds=["b", "a"],
                                     step_index=2, block_placed="b", model="local 2",
                                     dropped_states=7),
        "error": Report(Status.INVALID_INPUT, "invalid input: no blocks"),
        "unicode": Report(Status.FRICTION_EXCEEDED, "glisse: ä ≠ 石 🧱", max_tension=0.5,
                          num_blocks=3, unstable_blocks=["石", "🧱x"], interfaces=[
                              _interface("Stein-ä", "石", [[0, 0, 0], [1, 0, 0], [0, 1, 0]]),
                              _interface("🧱x", "b", [], kern=[[0.5, 0.5, 0.0]]),
                              _interface("b", "c" * 7, np.arange(15.0), kern=np.eye(3))]),
    }


def _cases() -> dict[str, tuple[str, dict, list]]:
    """name: (msgtype, message dict, other forms of the same message)."""
    header = header_dict("world", 1_700_000_000_123_456_789)
    cases = {}
    for name, report in _reports().items():
        h = dict(header, frame_id="wörld") if name == "unicode" else header
        cases[f"report {name}"] = (REPORT, report_to_dict(report, h),
                                   [report_to_dict(report, h, arrays=True)])
    wall = check_scene(running_bond_wall(8, 14))        # 117 blocks: ~168 kB of CDR
    cases["report 117 blocks"] = (REPORT, report_to_dict(wall, header),
                                  [report_to_dict(wall, header, arrays=True)])
    cases["report partial"] = (REPORT, {
        "step_index": 3, "message": "x", "status": 2.0,
        "interfaces": [{"block_a": "a", "polygon": [{"x": 1}, {}], "normal_forces": [1, "2.5"],
                        "kern": [{"x": 1.0, "y": 1.0, "z": 1.0}] * 2}]},
        [{"step_index": 3, "message": "x", "status": 2,
          "interfaces": [{"block_a": "a", "polygon": np.array([[1, 0, 0], [0, 0, 0]]),
                          "normal_forces": np.array([1.0, 2.5]), "kern": np.ones((2, 3))}]}])

    s = stacked_boxes(0.45)
    scene = make_scene("lab", [*s.blocks, box_block("s", (0.2, 0.3, 0.5), (2, 0, 0.25),
                                                   support=True, mass=1.0)],
                       (0.0, 0.5, -9.8), ["a", "b"], [Hold("a", 1), Hold("s", 0, 2)])
    state = state_to_dict(scene, "läb", 12_000_000_345)
    state["blocks"].append({"id": "p", "primitive": {"type": 1, "dimensions": [0.1, 0.2, 0.3]},
                            "pose": {"orientation": {"w": 1.0}}, "density": 100.0})
    cases["state"] = ("rbe_msgs/msg/AssemblyState", state, [])
    tipping = stacked_boxes(0.55)
    cases["markers"] = ("visualization_msgs/msg/MarkerArray",
                        step_markers(tipping, check_scene(tipping), header_dict("map", 3 * 10**9 + 4)),
                        [])
    cases["header"] = ("std_msgs/msg/Header", {"stamp": {"sec": -1, "nanosec": 5},
                                               "frame_id": "ä"}, [])
    return cases


CASES = _cases()
CLASSES = {REPORT: StabilityReport, "rbe_msgs/msg/AssemblyState": AssemblyState,
           "visualization_msgs/msg/MarkerArray": MarkerArray, "std_msgs/msg/Header": Header}


@pytest.fixture(scope="module")
def expected() -> dict[str, bytes]:
    """rclpy's bytes of every case (one process)."""
    return dict(zip(CASES, rclpy_bytes([(t, d) for t, d, _ in CASES.values()])))


@pytest.mark.parametrize("name", list(CASES))
def test_bytes_are_rclpys(name, expected):
    """The message dict, and its other forms (for reports the node's: report_to_dict with
    arrays=True), give rclpy's bytes of the message; rclpy reads them back as the message
    (through CDR: float32 fields rounded)."""
    msgtype, values, forms = CASES[name]
    cls = CLASSES[msgtype]
    data = encode(msgtype, values)
    assert data == expected[name]
    assert all(encode(msgtype, form) == data for form in forms)
    msg = deserialize_message(data, cls)
    assert msg == deserialize_message(serialize_message(dict_to_message(values, cls)), cls)
    if msgtype == REPORT and name != "report partial":
        assert message_to_dict(msg) == values


def test_rclpy_differs_only_in_padding():
    """In this process (a malloc that recycles memory) rclpy's bytes have our length and
    differ from ours, if at all, only where ours are zero: the padding it leaves as it
    found it."""
    msgtype, values, _ = CASES["report 117 blocks"]
    msg = dict_to_message(values, StabilityReport)
    ours = np.frombuffer(encode(msgtype, values), dtype=np.uint8)
    for _ in range(3):
        theirs = np.frombuffer(bytes(serialize_message(msg)), dtype=np.uint8)
        assert len(theirs) == len(ours) and not ours[theirs != ours].any()
