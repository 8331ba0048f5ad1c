"""RViz markers of a stability report: contact forces, interfaces, kerns, unstable blocks.

:func:`report_markers` is a pure function of the scene, the report, the frame and the stamp.
A report of a 1000-block wall has ~12k interface vertices, so the many small primitives are
aggregated, as usual for RViz: one LINE_LIST per kind (a segment per force or edge, colours
per segment in ``Marker.colors``), built from numpy arrays in bulk. Namespaces:

* ``forces``: one LINE_LIST, a segment per interface vertex, from the vertex along the force
  that block_a exerts on block_b there (normal plus tangential part); length proportional to
  the force magnitude over the largest vertex force of the report (that one is ``max_length``
  long). Compression green, tension (normal force below ``-tension_tol`` times the largest
  force) red.
* ``interfaces``: one LINE_LIST of the edges of every contact polygon (its closed outline;
  grey, red when the interface needs tension, orange when its friction is exceeded).
* ``kerns``: one thinner LINE_LIST of the edges of every kern outline (blue).
* ``unstable``: every block of ``report.unstable_blocks`` as a red translucent TRIANGLE_LIST
  of its mesh.

The first marker is a DELETEALL, so markers of an earlier report vanish. A LINE_LIST with
nothing to draw is left out. To halve the number of rclpy objects made, equal points and
colours are shared objects: a polygon vertex is one ``Point`` in the force segment that
starts there and in the edges that meet there, and the entries of one colour in
``Marker.colors`` are one ``ColorRGBA`` (the array is for publishing, not for editing in
place).
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

    ``max_length``: length in m of the segment of the largest vertex force (default: half the
    largest interface polygon diameter, at least 0.05 m).
    """
    header = Header(frame_id=str(frame_id), stamp=stamp)
    markers = [Marker(header=header, action=Marker.DELETEALL)]
    interfaces = list(report.interfaces)
    polygons = [_rows(r.polygon) for r in interfaces]
    vertices = _concat(polygons)
    normal_forces = np.concatenate([np.asarray(r.normal_forces, dtype=float).reshape(-1)
                                    for r in interfaces]) if interfaces else np.empty(0)
    counts = [len(r.normal_forces) for r in interfaces]
    normals = np.repeat(_rows([r.normal for r in interfaces]), counts, axis=0)
    forces = (normal_forces[:, None] * normals
              + _concat([_rows(r.tangential_forces) for r in interfaces]))
    f_ref = float(np.linalg.norm(forces, axis=1).max(initial=0.0))
    if max_length is None:
        max_length = max(0.5 * _largest_diameter(polygons), 0.05)
    width = 0.05 * max_length

    corners = _points(vertices)        # the polygon vertices, shared by forces and edges
    if corners:
        scale = max_length / f_ref if f_ref > 0 else 0.0
        tension = normal_forces < -tension_tol * f_ref
        m = _marker(header, "forces", len(markers), Marker.LINE_LIST, COMPRESSION)
        m.scale.x = width
        m.points = _interleave(corners, _points(vertices + scale * forces))
        m.colors = _colours((COMPRESSION, TENSION), np.repeat(tension.astype(int), 2))
        markers.append(m)

    line = 0.01 * max_length
    ends, owner = _edges([len(p) for p in polygons])
    if len(ends):
        kind = np.array([2 if r.tension else 1 if r.friction_exceeded else 0
                         for r in interfaces], dtype=int)
        m = _marker(header, "interfaces", len(markers), Marker.LINE_LIST, INTERFACE)
        m.scale.x = 2.0 * line
        m.points = [corners[i] for i in ends.tolist()]
        m.colors = _colours((INTERFACE, INTERFACE_FRICTION, INTERFACE_TENSION),
                            np.repeat(kind[owner], 2))
        markers.append(m)
    kerns = [_rows(r.kern) for r in interfaces]
    ends, _ = _edges([len(k) for k in kerns])
    if len(ends):
        m = _marker(header, "kerns", len(markers), Marker.LINE_LIST, KERN)
        m.scale.x = line
        kern_points = _points(_concat(kerns))
        m.points = [kern_points[i] for i in ends.tolist()]
        markers.append(m)

    by_id = {b.id: b for b in scene.blocks} if scene is not None else {}
    for bid in report.unstable_blocks:
        block = by_id.get(bid)
        if block is None:
            continue
        m = _marker(header, "unstable", len(markers), Marker.TRIANGLE_LIST, UNSTABLE)
        m.scale.x = m.scale.y = m.scale.z = 1.0
        m.points = _points(_world_triangles(block))
        m.text = bid
        markers.append(m)
    return MarkerArray(markers=markers)


def _marker(header: Header, ns: str, marker_id: int, kind: int, colour) -> Marker:
    m = Marker(header=header, ns=ns, id=marker_id, type=kind, action=Marker.ADD)
    m.pose.orientation.w = 1.0
    m.color = _colour(colour)
    return m


def _colour(c) -> ColorRGBA:
    return ColorRGBA(r=c[0], g=c[1], b=c[2], a=c[3])


def _colours(palette, index: np.ndarray) -> list[ColorRGBA]:
    """``Marker.colors``: ``palette[i]`` for each ``i`` of ``index`` (one object per colour)."""
    table = [_colour(c) for c in palette]
    return [table[i] for i in index.tolist()]


def _rows(a) -> np.ndarray:
    return np.asarray(a, dtype=float).reshape(-1, 3)


def _concat(arrays: list[np.ndarray]) -> np.ndarray:
    return np.concatenate(arrays) if arrays else np.empty((0, 3))


def _points(rows: np.ndarray) -> list[Point]:
    return [Point(x=x, y=y, z=z) for x, y, z in rows.tolist()]


def _largest_diameter(polygons: list[np.ndarray]) -> float:
    """The largest extent along an axis of a polygon of ``polygons`` (0 if there is none)."""
    polygons = [p for p in polygons if len(p)]
    if not polygons:
        return 0.0
    vertices = np.concatenate(polygons)
    starts = np.cumsum([0] + [len(p) for p in polygons[:-1]])
    extent = (np.maximum.reduceat(vertices, starts, axis=0)
              - np.minimum.reduceat(vertices, starts, axis=0))
    return float(extent.max())


def _interleave(a: list, b: list) -> list:
    """``a[0], b[0], a[1], b[1], ...``"""
    out = [None] * (len(a) + len(b))
    out[0::2], out[1::2] = a, b
    return out


def _edges(counts: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """The edges of the closed outlines of polygons of ``counts`` vertices, the polygons'
    vertices one after another (fewer than 2 vertices: no edge, 2 vertices: one): the
    indices of the two ends of each edge into those vertices, edge after edge (2e,), and the
    index of the polygon of each edge (e,)."""
    counts = np.asarray(counts, dtype=int)
    last = np.cumsum(counts) - 1
    first = last - counts + 1
    owner = np.repeat(np.arange(len(counts)), counts)
    start = np.arange(int(counts.sum()))
    end = start + 1
    end[last[counts > 0]] = first[counts > 0]       # close each outline
    keep = counts[owner] >= 2
    keep[last[counts == 2]] = False                 # a 2-gon is one edge, not two
    return np.stack([start[keep], end[keep]], axis=1).reshape(-1), owner[keep]


def _world_triangles(block) -> np.ndarray:
    """Vertices of the fan-triangulated faces of ``block`` in the scene frame, 3 per triangle."""
    world = Rotation.from_quat(block.orientation).apply(block.vertices) + block.position
    idx = [i for f in block.faces for k in range(1, len(f) - 1) for i in (f[0], f[k], f[k + 1])]
    return world[idx]
