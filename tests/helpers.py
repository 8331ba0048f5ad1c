"""Small scene builders and independent checks shared by the tests."""
from __future__ import annotations

import math

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.scene import box_block, make_scene

from oracles.mass import mass_centroid

DENSITY = 2000.0
G = 9.81


def stacked_boxes(shift: float, width: float = 1.0, height: float = 1.0):
    """A support slab, a box on it, and a second box shifted by ``shift`` (share of the width)."""
    return make_scene("stack", [
        box_block("ground", (3, 3, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        box_block("a", (width, width, height), (0, 0, height / 2), density=DENSITY),
        box_block("b", (width, width, height), (shift * width, 0, 1.5 * height), density=DENSITY),
    ])


def equilibrium_residual(scene, report) -> float:
    """Largest force or moment imbalance of any free block, from the reported forces alone,
    relative to the total free weight (moments over weight times scene size). Masses and
    centroids come from tests/oracles/mass.py, not from the code under test; blocks the
    report holds as supports are not balanced."""
    g = np.asarray(scene.gravity)
    held = set(report.held_blocks)
    props = {b.id: mass_centroid(b) for b in scene.blocks}
    free = [b.id for b in scene.blocks if not b.support and b.id not in held]
    total = sum(props[bid][0] for bid in free) * np.linalg.norm(g)
    corners = np.vstack([Rotation.from_quat(b.orientation).apply(b.vertices) + b.position
                         for b in scene.blocks])
    size = max(np.ptp(corners, axis=0))
    worst = 0.0
    for bid in free:
        mass, centroid = props[bid]
        force = mass * g
        moment = np.zeros(3)
        for r in report.interfaces:
            sign = 1.0 if r.block_b == bid else -1.0 if r.block_a == bid else 0.0
            if sign == 0.0:
                continue
            f = sign * (r.normal_forces[:, None] * r.normal + r.tangential_forces)
            force = force + f.sum(axis=0)
            moment = moment + np.cross(r.polygon - centroid, f).sum(axis=0)
        worst = max(worst, np.abs(force).max() / total, np.abs(moment).max() / (total * size))
    return worst


def cone_excess(report, mu: float, cone: str = "soc") -> float:
    """Largest violation of the friction-net cone at any vertex, in N: tension (-fn), or
    tangential force beyond mu fn (the circle, or the pyramid's facets, its inradius
    cos(pi/8) mu fn for the inscribed "pyramid8", mu fn for the others)."""
    facets = {"pyramid4": (4, 1.0), "pyramid8": (8, math.cos(math.pi / 8)),
              "pyramid8-outer": (8, 1.0)}
    worst = 0.0
    for r in report.interfaces:
        fn, ft = r.normal_forces, r.tangential_forces
        worst = max(worst, float(np.max(-fn, initial=0.0)))
        if cone == "soc":
            reach = np.linalg.norm(ft, axis=1)
        else:
            # the pyramid's facet normals lie along the interface's own (u, v) axes; any
            # frame in the plane bounds the facet reach from above by the circumscribed
            # circle, so check the circle of radius mu fn / cos(pi / n) (an upper bound)
            n, h = facets[cone]
            reach = np.linalg.norm(ft, axis=1) * math.cos(math.pi / n) / h
        worst = max(worst, float(np.max(reach - mu * fn, initial=0.0)))
    return worst


def checked(scene, options: CheckOptions = CheckOptions()):
    """check_scene, its report put through :func:`assert_physical` before it is returned."""
    report = check_scene(scene, options)
    assert_physical(scene, report, options.solve.mu, options.solve.cone)
    return report


def assert_physical(scene, report, mu: float = 0.6, cone: str = "soc", tol: float = 1e-6):
    """The shared oracle of every fixed physics test: the reported forces balance every free
    block (masses and centroids from tests/oracles/mass.py) and, when STABLE, lie inside the
    friction cone of ``mu`` at every vertex with no tension, to ``tol`` of the free weight."""
    assert report.interfaces or not report.stable, report.message
    if not report.interfaces:
        return
    assert equilibrium_residual(scene, report) < tol, report.message
    if report.stable and math.isfinite(mu):
        g = float(np.linalg.norm(scene.gravity))
        weight = g * sum(mass_centroid(b)[0] for b in scene.blocks if not b.support)
        assert cone_excess(report, mu, cone) <= tol * weight, report.message


def inclined_block(angle_deg: float):
    """A box resting on a support slab, both tilted by ``angle_deg`` about y."""
    rot = Rotation.from_euler("y", angle_deg, degrees=True)
    q = rot.as_quat()
    return make_scene("incline", [
        box_block("slope", (4, 4, 0.2), rot.apply([0, 0, -0.1]), q, support=True, density=DENSITY),
        box_block("box", (1, 1, 0.5), rot.apply([0, 0, 0.25]), q, density=DENSITY),
    ])


def true_mesh(block) -> trimesh.Trimesh:
    """The mesh of a posed block, each face a fan of triangles (exact for convex faces, as
    all of the interlocking suite's are)."""
    return trimesh.Trimesh(block.vertices, block.triangles, process=False)


def _inward(mesh: trimesh.Trimesh, offset: float) -> trimesh.Trimesh:
    """``mesh`` with every face moved in by ``offset``: each vertex solves n . m = 1 over the
    distinct planes of its faces (exact where at most three meet, as at every vertex of a
    polycube or a prism) and moves by -offset m."""
    normals = np.round(mesh.face_normals, 9)
    moved = mesh.vertices.copy()
    for v, faces in enumerate(mesh.vertex_faces):
        distinct = np.unique(normals[faces[faces >= 0]], axis=0)
        m = np.linalg.lstsq(distinct, np.ones(len(distinct)), rcond=None)[0]
        moved[v] -= offset * m
    return trimesh.Trimesh(moved, mesh.faces, process=False)


def sweep_free(assembly, present: list[str], block: str, direction, hulls: bool = False,
               offset: float = 5e-4, spacing: float = 5e-3,
               distance: float | None = None) -> bool:
    """The oracle of an insertion path (trimesh's collision manager, not our convex
    decomposition): ``block``'s true mesh, its faces moved in by ``offset`` (m), at every
    ``spacing`` (m) along its path (arriving along ``direction``) from where it is clear of
    the present blocks' boxes (or over ``distance``), collides with no present block's true
    mesh (``hulls``: every mesh its convex hull, as the check before issue 28 swept them)."""
    by_id = {b.id: b for b in assembly.blocks}
    manager = trimesh.collision.CollisionManager()
    for bid in present:
        mesh = true_mesh(by_id[bid])
        manager.add_object(bid, mesh.convex_hull if hulls else mesh)
    moving = _inward(true_mesh(by_id[block]), offset)
    if hulls:
        moving = moving.convex_hull
    d = np.asarray(direction, dtype=float)
    if distance is None:
        corners = np.array([[x, y, z] for bid in present for lo, hi in [by_id[bid].aabb]
                            for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                            for z in (lo[2], hi[2])])
        distance = max(0.0, float(np.max(corners @ -d) - np.min(moving.vertices @ -d)))
    for t in np.append(np.arange(0.0, distance, spacing), distance):
        shift = np.eye(4)
        shift[:3, 3] = -t * d
        if manager.in_collision_single(moving, transform=shift):
            return False
    return True


#: A cell of one robot: a plan for it holds nothing (K = 0), so only an order repairs it.
ONE_ROBOT = {"robots": [{"name": "r1", "base": [0.8, -0.8, 0.0], "reach": 2.0,
                         "payload_force": 300, "payload_torque": 60,
                         "tool": {"box": [0.08, 0.08, 0.1], "tcp": [0.0, 0.0, 0.1],
                                  "mass": 1.0}}]}
#: The stack: which block each rests on.
RESTS = {"s1": "ground", "s2": "s1", "s3": "s2", "c": "s2"}


def overhang_stack():
    """A stack near its overhang limit: s1 on the ground, s2 on s1 reaching 0.122 m out, s3
    on s2 0.15 m further out: s2 and s3 together 3 mm inside s1's edge (the common centroid
    of two equal boxes, 0.122 + 0.15 / 2 = 0.197 of 0.2 m). The counterweight c on s2's left
    end (half their mass) goes last; placed before s3 it keeps s2 and s3 well inside."""
    blocks = [box_block("ground", (1.2, 0.6, 0.1), (0, 0, -0.05), support=True,
                        density=DENSITY),
              box_block("s1", (0.4, 0.3, 0.1), (0, 0, 0.05), density=DENSITY),
              box_block("s2", (0.4, 0.3, 0.1), (0.122, 0, 0.15), density=DENSITY),
              box_block("s3", (0.4, 0.3, 0.1), (0.272, 0, 0.25), density=DENSITY),
              box_block("c", (0.1, 0.3, 0.2), (-0.028, 0, 0.3), density=DENSITY)]
    return make_scene("stack", blocks, sequence=["s1", "s2", "s3", "c"])


def footprint(design, block: str, poses: dict):
    """The outline (shapely) of a box seen from above at its measured pose (else design)."""
    from shapely.geometry import MultiPoint

    b = design.block(block)
    p, q = poses.get(block, (b.position, b.orientation))
    return MultiPoint((Rotation.from_quat(q).apply(b.vertices) + p)[:, :2]).convex_hull


def stack_stands(design, poses: dict, free: list[str]) -> bool:
    """Closed form (the oracle): boxes of one density stacked on flat faces stand iff at each
    interface the common centroid of the block above and of all resting on it lies within
    the interface (where the two boxes overlap, seen from above)."""
    from shapely.geometry import Point

    volume = {b.id: float(np.prod(np.ptp(b.vertices, axis=0))) for b in design.blocks}
    at = {b: np.asarray(poses.get(b, (design.block(b).position,))[0]) for b in free}

    def load(b):
        on = [b] + [x for y in free if RESTS.get(y) == b for x in load(y)]
        return on

    for b in free:
        on = load(b)
        w = np.array([volume[x] for x in on])
        centre = (w[:, None] * np.array([at[x] for x in on])).sum(0) / w.sum()
        contact = footprint(design, b, poses).intersection(footprint(design, RESTS[b], poses))
        if not contact.contains(Point(centre[:2])):
            return False
    return True


#: The ledge scene's plate centroid is LEDGE_INSIDE m inside the ledge's edge; its declared
#: pose uncertainty is 3 LEDGE_SIGMA in position, none in angle.
LEDGE_INSIDE, LEDGE_SIGMA, LEDGE_EDGE = 0.001, 0.002, 1.15


def ledge(pose_uncertainty=(3 * LEDGE_SIGMA, 0.0)):
    """Where ranking by margin and by p_stable disagree: a ground slab, a ledge (a support)
    and two free blocks that stand alone, a slender column on the ground (margin 0.05 / 0.4 =
    0.125 g) and a thin plate whose centroid is LEDGE_INSIDE from the ledge's edge (margin
    LEDGE_INSIDE / 0.005 = 0.2 g towards the edge; it falls when noise moves it over)."""
    return make_scene("ledge", [
        box_block("ground", (3, 3, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        box_block("ledge", (0.3, 0.3, 0.1), (LEDGE_EDGE - 0.15, 0, 0.05), support=True,
                  density=DENSITY),
        box_block("column", (0.1, 0.1, 0.8), (-0.8, 0, 0.4), density=DENSITY),
        box_block("plate", (0.2, 0.2, 0.01), (LEDGE_EDGE - LEDGE_INSIDE, 0, 0.105),
                  density=DENSITY),
    ], pose_uncertainty=pose_uncertainty)
