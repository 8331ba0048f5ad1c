"""Physics engines as stability checkers: what sequence planners use instead of RBE.

A check simulates the assembly for ``T`` seconds from rest and calls it collapsed when any
free block's centre moved more than ``disp_tol`` times its size (cube root of its volume, as
rbe_ros defines it) or turned by more than ``rot_tol_deg``; the simulation stops as soon as
that happens (checked every ``1/20`` s), as a planner would. Parameters (documented in
docs/BENCHMARKS.md):

* PyBullet (``engine="pybullet"``): boxes as box shapes, every other convex block as the
  convex hull of its vertices (``GEOM_MESH``), supports static (mass 0); every body gets
  lateral friction sqrt(mu), because Bullet multiplies the two bodies' coefficients (so a
  contact has mu); collision margin 0 for hulls (:data:`HULL_MARGIN`); restitution 0, rolling and spinning friction 0; time step ``1/hz``, solver
  iterations ``iterations`` (PyBullet's default 50 unless given), everything else default.
  The body frame is the block's centre of mass; inertia is Bullet's own (box: exact; convex
  hull: that of its bounding box, which changes the dynamics, not the statics).
* MuJoCo (``engine="mujoco"``, optional): the same bodies as ``box`` / ``mesh`` geoms (meshes
  are convex hulls in MuJoCo anyway), free joints, condim 3 with friction mu (MuJoCo takes
  the larger of the two geoms' coefficients), elliptic cones, time step ``1/hz``, default
  solver otherwise; mass and inertia given explicitly from the mesh.

The input is a list of plain dicts (see :func:`bodies_from_scene`), so this module needs
neither rbe_ros nor anything but numpy and the engine to run a check.
"""
from __future__ import annotations

import math
import time

import numpy as np

CHECK_EVERY = 0.05          # s between the collapse tests during a simulation
#: Collision margin of convex-hull bodies in PyBullet. Its default, 1 mm, inflates hulls that
#: touch exactly so that they start interpenetrating: at 1 kHz that kicks a 15-voussoir arch
#: at t/R = 0.15 apart within 50 ms. 0 keeps them quiet (a choice in PyBullet's favour).
HULL_MARGIN = 0.0


def bodies_from_scene(scene) -> list[dict]:
    """The scene's blocks as plain dicts: world centroid, vertices relative to it, mass,
    support flag, size, and for a box its half extents and orientation (x, y, z, w)."""
    from rbe_ros.geometry.block import pose_block

    out = []
    for block in scene.blocks:
        posed = pose_block(block)
        body = {"id": block.id, "support": bool(block.support), "mass": float(posed.mass),
                "volume": float(posed.volume), "size": float(posed.size),
                "centroid": posed.centroid.tolist(),
                "vertices": (posed.vertices - posed.centroid).tolist()}
        half = _box_half_extents(np.asarray(block.vertices, dtype=float))
        if half is not None:
            body["box"] = half.tolist()
            body["orientation"] = [float(q) for q in block.orientation]
        out.append(body)
    return out


def _box_half_extents(local: np.ndarray):
    """Half extents if the block-frame vertices are the 8 corners of a box centred on the
    block origin and aligned with its axes, else None."""
    if local.shape != (8, 3):
        return None
    half = np.abs(local).max(axis=0)
    if np.any(half <= 0) or not np.allclose(np.abs(local), half, rtol=1e-9, atol=1e-12):
        return None
    signs = {tuple(s) for s in np.sign(local).astype(int)}
    return half if len(signs) == 8 else None


def _inertia_principal(body) -> np.ndarray:
    """Diagonal inertia of a solid box with the block's bounding box in its frame (for MuJoCo
    meshes, which need one; statics do not depend on it)."""
    v = np.asarray(body["vertices"])
    ext = v.max(axis=0) - v.min(axis=0)
    m = body["mass"]
    return m / 12.0 * np.array([ext[1] ** 2 + ext[2] ** 2, ext[0] ** 2 + ext[2] ** 2,
                                ext[0] ** 2 + ext[1] ** 2])


def _rotation_angle_deg(q0, q1) -> float:
    """Angle between two unit quaternions (x, y, z, w), in degrees."""
    d = abs(float(np.dot(q0, q1)))
    return math.degrees(2.0 * math.acos(min(1.0, d)))


# ----------------------------------------------------------------------------- PyBullet

_CLIENT = None


def _pybullet():
    global _CLIENT
    import pybullet as p
    if _CLIENT is None:
        _CLIENT = p.connect(p.DIRECT)
    return p, _CLIENT


def pybullet_parameters(hz: float, iterations: int | None) -> dict:
    """The engine parameters a check with these settings runs with (for the write-up)."""
    p, c = _pybullet()
    p.resetSimulation(physicsClientId=c)
    _pybullet_settings(p, c, hz, iterations)
    params = p.getPhysicsEngineParameters(physicsClientId=c)
    return {k: (float(v) if isinstance(v, float) else v) for k, v in params.items()}


def _pybullet_settings(p, c, hz, iterations):
    kwargs = {"fixedTimeStep": 1.0 / hz, "numSubSteps": 0}
    if iterations is not None:
        kwargs["numSolverIterations"] = int(iterations)
    p.setPhysicsEngineParameter(physicsClientId=c, **kwargs)


def _pybullet_check(bodies, hz, T, mu, gravity, iterations, disp_tol, rot_tol_deg):
    p, c = _pybullet()
    p.resetSimulation(physicsClientId=c)
    _pybullet_settings(p, c, hz, iterations)
    p.setGravity(*gravity, physicsClientId=c)
    lateral = math.sqrt(mu)
    ids, free = [], []
    for body in bodies:
        if "box" in body:
            shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=body["box"], physicsClientId=c)
            orientation = body["orientation"]
        else:
            shape = p.createCollisionShape(p.GEOM_MESH, vertices=body["vertices"], physicsClientId=c)
            orientation = [0, 0, 0, 1]
        mass = 0.0 if body["support"] else body["mass"]
        uid = p.createMultiBody(baseMass=mass, baseCollisionShapeIndex=shape,
                                basePosition=body["centroid"], baseOrientation=orientation,
                                physicsClientId=c)
        extra = {} if "box" in body else {"collisionMargin": HULL_MARGIN}
        p.changeDynamics(uid, -1, lateralFriction=lateral, restitution=0.0, rollingFriction=0.0,
                         spinningFriction=0.0, physicsClientId=c, **extra)
        ids.append(uid)
        if not body["support"]:
            free.append((uid, np.asarray(body["centroid"]), np.asarray(orientation, dtype=float),
                         body["size"]))
    steps = int(round(T * hz))
    every = max(1, int(round(CHECK_EVERY * hz)))
    done = 0
    worst = (0.0, 0.0)
    collapsed = False
    while done < steps:
        n = min(every, steps - done)
        for _ in range(n):
            p.stepSimulation(physicsClientId=c)
        done += n
        worst, collapsed = _pybullet_motion(p, c, free, disp_tol, rot_tol_deg)
        if collapsed:
            break
    return collapsed, worst, done / hz


def _pybullet_motion(p, c, free, disp_tol, rot_tol_deg):
    disp = rot = 0.0
    collapsed = False
    for uid, x0, q0, size in free:
        x, q = p.getBasePositionAndOrientation(uid, physicsClientId=c)
        d = float(np.linalg.norm(np.asarray(x) - x0)) / size
        r = _rotation_angle_deg(q0, np.asarray(q))
        disp, rot = max(disp, d), max(rot, r)
        collapsed |= d > disp_tol or r > rot_tol_deg
    return (disp, rot), collapsed


# ----------------------------------------------------------------------------- MuJoCo

def _mujoco_xml(bodies, hz, mu, gravity, iterations):
    assets, world = [], []
    for k, body in enumerate(bodies):
        pos = " ".join(f"{v:.12g}" for v in body["centroid"])
        if "box" in body:
            x, y, z, w = body["orientation"]
            geom = (f'<geom type="box" size="{" ".join(f"{h:.12g}" for h in body["box"])}"'
                    f' quat="{w:.12g} {x:.12g} {y:.12g} {z:.12g}"')
        else:
            verts = " ".join(f"{v:.12g}" for p in body["vertices"] for v in p)
            assets.append(f'<mesh name="m{k}" vertex="{verts}"/>')
            geom = f'<geom type="mesh" mesh="m{k}"'
        geom += f' friction="{mu:.12g} 0 0" condim="3"/>'
        if body["support"]:
            world.append(f'<body pos="{pos}">{geom}</body>')
        else:
            inertia = " ".join(f"{v:.12g}" for v in _inertia_principal(body))
            world.append(f'<body name="b{k}" pos="{pos}"><freejoint/>'
                         f'<inertial pos="0 0 0" mass="{body["mass"]:.12g}" diaginertia="{inertia}"/>'
                         f'{geom}</body>')
    it = f' iterations="{int(iterations)}"' if iterations else ""
    g = " ".join(f"{v:.12g}" for v in gravity)
    return (f'<mujoco><option timestep="{1.0 / hz:.12g}" gravity="{g}" cone="elliptic"{it}/>'
            f'<compiler inertiafromgeom="false"/><asset>{"".join(assets)}</asset>'
            f'<worldbody>{"".join(world)}</worldbody></mujoco>')


def _mujoco_check(bodies, hz, T, mu, gravity, iterations, disp_tol, rot_tol_deg):
    import mujoco

    model = mujoco.MjModel.from_xml_string(_mujoco_xml(bodies, hz, mu, gravity, iterations))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    free = [(model.body(f"b{k}").id, np.asarray(b["centroid"]), b["size"])
            for k, b in enumerate(bodies) if not b["support"]]
    q0 = {bid: data.xquat[bid].copy() for bid, _, _ in free}
    steps = int(round(T * hz))
    every = max(1, int(round(CHECK_EVERY * hz)))
    done, worst, collapsed = 0, (0.0, 0.0), False
    while done < steps:
        n = min(every, steps - done)
        mujoco.mj_step(model, data, nstep=n)
        done += n
        disp = rot = 0.0
        for bid, x0, size in free:
            d = float(np.linalg.norm(data.xpos[bid] - x0)) / size
            w, x, y, z = q0[bid]
            w1, x1, y1, z1 = data.xquat[bid]
            r = _rotation_angle_deg((x, y, z, w), (x1, y1, z1, w1))
            disp, rot = max(disp, d), max(rot, r)
            collapsed |= d > disp_tol or r > rot_tol_deg
        worst = (disp, rot)
        if collapsed:
            break
    return collapsed, worst, done / hz


# ----------------------------------------------------------------------------- API

def check(bodies, *, engine: str = "pybullet", hz: float = 240.0, T: float = 1.0, mu: float = 0.6,
          gravity=(0.0, 0.0, -9.81), iterations: int | None = None, disp_tol: float = 0.1,
          rot_tol_deg: float = 5.0) -> dict:
    """One physics check: ``stable``, the largest displacement (share of the block size) and
    rotation (deg) of a free block, the simulated and the wall time (s, set-up included)."""
    start = time.perf_counter()
    run = _pybullet_check if engine == "pybullet" else _mujoco_check
    collapsed, (disp, rot), simulated = run(bodies, hz, T, mu, tuple(gravity), iterations,
                                            disp_tol, rot_tol_deg)
    return {"stable": not collapsed, "max_disp": disp, "max_rot_deg": rot,
            "simulated": simulated, "time": time.perf_counter() - start}


def available(engine: str) -> bool:
    try:
        __import__(engine)
    except ImportError:
        return False
    return True
