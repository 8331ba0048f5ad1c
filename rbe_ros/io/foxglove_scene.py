"""Live view in the Foxglove app without ROS: the markers of each report as a Foxglove
SceneUpdate, served over foxglove-sdk's WebSocket server (``rbe_node`` parameter
``foxglove_port``; foxglove_bridge is not on PyPI).

The Foxglove app connects to ``ws://HOST:PORT`` ("Open connection", Foxglove WebSocket) and
its 3D panel shows the topic ``/rbe_node/scene``: one entity ``assembly`` (in the report's
frame) holding what the markers hold (:mod:`rbe_ros.io.markers`): a triangle list per block
(or per colour), the force, interface and kern line lists, the insertion arrow, and the
caption. Each update
replaces the entity; a client that subscribes later gets the latest one at once.
ROS-free; the server runs in foxglove-sdk's own threads.
"""
from __future__ import annotations

import threading
from collections.abc import Mapping

import foxglove
from foxglove.channels import SceneUpdateChannel
import numpy as np
from foxglove.messages import (ArrowPrimitive, Color, LinePrimitive, LinePrimitiveLineType,
                               Point3, Pose, Quaternion, SceneEntity, SceneUpdate, TextPrimitive,
                               Timestamp, TriangleListPrimitive, Vector3)

from .markers import ARROW, LINE_LIST, TEXT_VIEW_FACING, TRIANGLE_LIST

SCENE_TOPIC = "/rbe_node/scene"
ENTITY = "assembly"


def _colour(m: Mapping) -> Color:
    return Color(**{k: float(m["color"][k]) for k in "rgba"})


def _points(m: Mapping) -> list[Point3]:
    return [Point3(x=x, y=y, z=z) for x, y, z in m["points"].tolist()]


def x_onto(direction) -> np.ndarray:
    """The unit quaternion (x, y, z, w) turning the x axis onto unit ``direction`` (a
    Foxglove arrow points along its pose's x axis)."""
    d = np.asarray(direction, dtype=float)
    if d[0] < -1.0 + 1e-12:                     # opposite: half a turn about z
        return np.array([0.0, 0.0, 1.0, 0.0])
    q = np.array([0.0, -d[2], d[1], 1.0 + d[0]])     # (x cross d, 1 + x . d)
    return q / np.linalg.norm(q)


def _arrow(m: Mapping) -> ArrowPrimitive:
    tail, tip = np.asarray(m["points"], dtype=float)
    length = float(np.linalg.norm(tip - tail))
    head = min(float(m["scale"]["z"]), length)
    x, y, z, w = (float(c) for c in x_onto((tip - tail) / length))
    return ArrowPrimitive(
        pose=Pose(position=Vector3(x=float(tail[0]), y=float(tail[1]), z=float(tail[2])),
                  orientation=Quaternion(x=x, y=y, z=z, w=w)),
        shaft_length=length - head, shaft_diameter=float(m["scale"]["x"]),
        head_length=head, head_diameter=float(m["scale"]["y"]), color=_colour(m))


def scene_update(markers: Mapping) -> SceneUpdate:
    """The SceneUpdate of a MarkerArray dict (:func:`rbe_ros.io.markers.report_markers`)."""
    items = [m for m in markers["markers"] if m["ns"]]
    header = items[0]["header"] if items else {"stamp": {"sec": 0, "nanosec": 0},
                                                 "frame_id": ""}
    triangles, lines, texts, arrows = [], [], [], []
    for m in items:
        if m["type"] == TRIANGLE_LIST:
            triangles.append(TriangleListPrimitive(points=_points(m), color=_colour(m)))
        elif m["type"] == LINE_LIST:
            lines.append(LinePrimitive(type=LinePrimitiveLineType.LineList,
                                       thickness=float(m["scale"]["x"]), scale_invariant=False,
                                       points=_points(m), color=_colour(m)))
        elif m["type"] == ARROW:
            arrows.append(_arrow(m))
        elif m["type"] == TEXT_VIEW_FACING:
            p = m["pose"]["position"]
            texts.append(TextPrimitive(
                pose=Pose(position=Vector3(x=p["x"], y=p["y"], z=p["z"]),
                          orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
                billboard=True, font_size=float(m["scale"]["z"]), scale_invariant=False,
                color=_colour(m), text=m["text"]))
    stamp = Timestamp(sec=int(header["stamp"]["sec"]), nsec=int(header["stamp"]["nanosec"]))
    return SceneUpdate(entities=[SceneEntity(
        timestamp=stamp, frame_id=header["frame_id"], id=ENTITY, frame_locked=False,
        triangles=triangles, lines=lines, texts=texts, arrows=arrows)])


class SceneServer:
    """foxglove-sdk's WebSocket server on ``host:port`` (0: any free port, see ``port``)
    with the channel :data:`SCENE_TOPIC`, in a context of its own."""

    def __init__(self, port: int, host: str = "127.0.0.1", name: str = "rbe_node"):
        self._lock = threading.Lock()
        self._latest: SceneUpdate | None = None
        self._context = foxglove.Context()
        self._channel = SceneUpdateChannel(SCENE_TOPIC, context=self._context)
        self._server = foxglove.start_server(name=name, host=host, port=port,
                                             context=self._context, server_listener=self)

    @property
    def port(self) -> int:
        return self._server.port

    def publish(self, markers: Mapping) -> None:
        """Send the scene of a MarkerArray dict to every subscribed client."""
        update = scene_update(markers)
        with self._lock:
            self._latest = update
        self._channel.log(update)

    # foxglove.websocket.ServerListener
    def on_subscribe(self, client, channel) -> None:
        """A new subscriber gets the latest scene at once (as a latched topic would)."""
        with self._lock:
            latest = self._latest
        if latest is not None:
            self._channel.log(latest)

    def stop(self) -> None:
        self._server.stop()


__all__ = ["ENTITY", "SCENE_TOPIC", "SceneServer", "scene_update"]
