"""RViz markers of a stability report: contact forces, interfaces, kerns, unstable blocks.

:func:`report_markers` is a pure function of the scene, the report, the frame and the stamp.
Namespaces:

* ``forces``: one ARROW per interface vertex, from the vertex along the force that block_a
  exerts on block_b there (normal plus tangential part); length proportional to the force
  magnitude over the largest vertex force of the report (that one is ``max_length`` long).
  Compression green, tension (normal force below ``-tension_tol`` times the largest force) red.
* ``interfaces``: each contact polygon as a closed LINE_STRIP (grey; red when the interface
  needs tension, orange when its friction is exceeded).
* ``kerns``: each kern outline as a thinner closed LINE_STRIP (blue).
* ``unstable``: every block of ``report.unstable_blocks`` as a red translucent TRIANGLE_LIST
  of its mesh.

The first marker is a DELETEALL, so markers of an earlier report vanish.
"""
from __future__ import annotations

import numpy as np
from geometry_msgs.msg import Point
from scipy.spatial.transform import Rotation
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from ..rbe.result import Report
from ..scene import Scene

COMPRESSION = (0.1, 0.75, 0.2, 1.0)
TENSION = (0.9, 0.1, 0.1, 1.0)
INTERFACE = (0.8, 0.8, 0.8, 1.0)
INTERFACE_TENSION = (0.9, 0.1, 0.1, 1.0)
INTERFACE_FRICTION = (1.0, 0.55, 0.0, 1.0)
KERN = (0.2, 0.4, 1.0, 1.0)
UNSTABLE = (1.0, 0.0, 0.0, 0.45)


def report_markers(scene: Scene | None, report: Report, frame_id: str, stamp, *,
                   max_length: float | None = None, tension_tol: float = 1e-5) -> MarkerArray:
    """The MarkerArray of ``report`` (``stamp``: a builtin_interfaces/Time). ``scene`` gives
    the meshes of the unstable blocks (``None``: no block meshes, e.g. for invalid input).

    ``max_length``: length in m of the arrow of the largest vertex force (default: half the
    largest interface polygon diameter, at least 0.05 m).
    """
    header = Header(frame_id=str(frame_id), stamp=stamp)
    markers = [Marker(header=header, action=Marker.DELETEALL)]
    interfaces = list(report.interfaces)
    forces = [r.normal_forces[:, None] * r.normal[None, :] + r.tangential_forces
              for r in interfaces]
    magnitudes = [np.linalg.norm(f, axis=1) for f in forces]
    f_ref = max((float(m.max(initial=0.0)) for m in magnitudes), default=0.0)
    if max_length is None:
        diameters = [float(np.ptp(r.polygon, axis=0).max(initial=0.0)) if len(r.polygon) else 0.0
                     for r in interfaces]
        max_length = max(0.5 * max(diameters, default=0.0), 0.05)
    width = 0.05 * max_length

    for r, f, mags in zip(interfaces, forces, magnitudes):
        for vertex, force, fn in zip(r.polygon, f, r.normal_forces):
            scale = max_length / f_ref if f_ref > 0 else 0.0
            colour = TENSION if fn < -tension_tol * f_ref else COMPRESSION
            m = _marker(header, "forces", len(markers), Marker.ARROW, colour)
            m.scale.x, m.scale.y, m.scale.z = width, 2.0 * width, 3.0 * width
            m.points = [_point(vertex), _point(vertex + scale * force)]
            markers.append(m)

    line = 0.01 * max_length
    for r in interfaces:
        if len(r.polygon) < 2:
            continue
        colour = (INTERFACE_TENSION if r.tension else
                  INTERFACE_FRICTION if r.friction_exceeded else INTERFACE)
        m = _marker(header, "interfaces", len(markers), Marker.LINE_STRIP, colour)
        m.scale.x = 2.0 * line
        m.points = _closed(r.polygon)
        markers.append(m)
    for r in interfaces:
        if len(r.kern) < 2:
            continue
        m = _marker(header, "kerns", len(markers), Marker.LINE_STRIP, KERN)
        m.scale.x = line
        m.points = _closed(r.kern)
        markers.append(m)

    by_id = {b.id: b for b in scene.blocks} if scene is not None else {}
    for bid in report.unstable_blocks:
        block = by_id.get(bid)
        if block is None:
            continue
        m = _marker(header, "unstable", len(markers), Marker.TRIANGLE_LIST, UNSTABLE)
        m.scale.x = m.scale.y = m.scale.z = 1.0
        m.points = [_point(p) for p in _world_triangles(block)]
        m.text = bid
        markers.append(m)
    return MarkerArray(markers=markers)


def _marker(header: Header, ns: str, marker_id: int, kind: int, colour) -> Marker:
    m = Marker(header=header, ns=ns, id=marker_id, type=kind, action=Marker.ADD)
    m.pose.orientation.w = 1.0
    m.color = ColorRGBA(r=colour[0], g=colour[1], b=colour[2], a=colour[3])
    return m


def _point(p) -> Point:
    return Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def _closed(points) -> list[Point]:
    pts = [_point(p) for p in points]
    return pts + [pts[0]]


def _world_triangles(block) -> np.ndarray:
    """Vertices of the fan-triangulated faces of ``block`` in the scene frame, 3 per triangle."""
    world = Rotation.from_quat(block.orientation).apply(block.vertices) + block.position
    idx = [i for f in block.faces for k in range(1, len(f) - 1) for i in (f[0], f[k], f[k + 1])]
    return world[idx]
