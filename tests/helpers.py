"""Small scene builders and independent checks shared by the tests."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from rbe_ros.scene import box_block, make_scene

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
    relative to the total free weight (moments over weight times scene size)."""
    g = np.asarray(scene.gravity)
    from rbe_ros.geometry.block import pose_block
    posed = {b.id: pose_block(b) for b in scene.blocks}
    total = sum(p.mass for p in posed.values() if not p.support) * np.linalg.norm(g)
    size = max(np.ptp(np.vstack([p.vertices for p in posed.values()]), axis=0))
    worst = 0.0
    for bid, p in posed.items():
        if p.support:
            continue
        force = p.mass * g
        moment = np.zeros(3)
        for r in report.interfaces:
            sign = 1.0 if r.block_b == bid else -1.0 if r.block_a == bid else 0.0
            if sign == 0.0:
                continue
            f = sign * (r.normal_forces[:, None] * r.normal + r.tangential_forces)
            force = force + f.sum(axis=0)
            moment = moment + np.cross(r.polygon - p.centroid, f).sum(axis=0)
        worst = max(worst, np.abs(force).max() / total, np.abs(moment).max() / (total * size))
    return worst


def inclined_block(angle_deg: float):
    """A box resting on a support slab, both tilted by ``angle_deg`` about y."""
    rot = Rotation.from_euler("y", angle_deg, degrees=True)
    q = rot.as_quat()
    return make_scene("incline", [
        box_block("slope", (4, 4, 0.2), rot.apply([0, 0, -0.1]), q, support=True, density=DENSITY),
        box_block("box", (1, 1, 0.5), rot.apply([0, 0, 0.25]), q, density=DENSITY),
    ])
