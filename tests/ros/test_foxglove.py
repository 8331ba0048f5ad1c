"""rbe_node's Foxglove WebSocket server (parameter foxglove_port): a plain WebSocket client
speaks the Foxglove protocol to it, subscribes to /rbe_node/scene and decodes the SceneUpdate
with protobuf from the schema the server advertises (not with foxglove-sdk)."""
from __future__ import annotations

import base64
import json
import socket
import struct

import pytest
import websocket
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from rbe_msgs.srv import CheckAssembly
from rclpy.parameter import Parameter

from rbe_ros.io.messages import state_to_dict
from rbe_ros.ros.convert import dict_to_message
from rbe_ros.ros.node import RbeNode
from rbe_client import stacked_boxes
from rbe_msgs.msg import AssemblyState


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def decoder(channel: dict):
    """The protobuf message class of an advertised channel (its FileDescriptorSet)."""
    assert channel["encoding"] == "protobuf" and channel["schemaEncoding"] == "protobuf"
    files = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for f in files.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))


def next_json(ws, op: str) -> dict:
    for _ in range(20):
        frame = ws.recv()
        if isinstance(frame, str) and json.loads(frame)["op"] == op:
            return json.loads(frame)
    raise AssertionError(f"no {op} message")


@pytest.mark.timeout(120)
def test_scene_update_over_websocket(rclpy_context):
    port = free_port()
    node = RbeNode(namespace="/rbe_foxglove_test", context=rclpy_context, parameter_overrides=[
        Parameter("foxglove_port", value=port)])
    try:
        assert node.foxglove.port == port
        state = dict_to_message(state_to_dict(stacked_boxes(0.55), "lab", 3), AssemblyState)
        report = node._on_check(CheckAssembly.Request(assembly=state),
                                CheckAssembly.Response()).report

        ws = websocket.create_connection(f"ws://127.0.0.1:{port}",
                                         subprotocols=["foxglove.sdk.v1"], timeout=20)
        try:
            [channel] = [c for c in next_json(ws, "advertise")["channels"]
                         if c["topic"] == "/rbe_node/scene"]
            assert channel["schemaName"] == "foxglove.SceneUpdate"
            ws.send(json.dumps({"op": "subscribe",
                                "subscriptions": [{"id": 7, "channelId": channel["id"]}]}))
            while True:                     # the latest scene comes at once
                frame = ws.recv()
                if isinstance(frame, bytes) and frame[0] == 1:
                    break
        finally:
            ws.close()
        subscription, _time = struct.unpack_from("<IQ", frame, 1)
        assert subscription == 7
        update = decoder(channel).FromString(frame[13:])
    finally:
        node.destroy_node()

    [entity] = update.entities
    assert entity.id == "assembly" and entity.frame_id == "lab" and entity.timestamp.nanos == 3
    assert len(entity.triangles) == 3                   # ground, a, b
    assert all(len(t.points) == 36 for t in entity.triangles)
    red = [t for t in entity.triangles if t.color.r > 0.9 and t.color.g < 0.2]
    assert len(red) == 1 and max(p.x for p in red[0].points) == pytest.approx(1.05)
    vertices = sum(len(i.polygon) for i in report.interfaces)
    forces = [line for line in entity.lines if line.thickness > 0.02]
    assert sum(len(line.points) for line in forces) == 2 * vertices == 16
    [text] = entity.texts
    assert text.text.endswith(report.message) and "TENSION_REQUIRED" in text.text
