"""Inverse kinematics of a cell's grips with a robot's URDF (pinocchio).

A robot with a ``urdf`` reaches a grip when some joint configuration within the model's
limits puts its tip link (``tip``, default ``tool0``, else the last frame) at the flange
pose of the grip: the tool frame moved back by the TCP offset, in the robot's base frame
(its ``base``, turned by ``base_yaw`` about z). Solved by damped least squares on the
SE(3) error from a few fixed seeds, so the answer is the same on every machine.
"""
from __future__ import annotations

import os
import sys
from contextlib import contextmanager
from functools import lru_cache

import numpy as np
import pinocchio as pin

from ..cell import CellError, Robot

#: Pose error (m, and rad of the log) below which a configuration reaches the target.
IK_TOL = 1e-4
IK_ITERATIONS = 300
DAMPING = 1e-6
#: Seeds of the search: the model's neutral pose and joint offsets (rad) from it.
SEEDS = ((0.0,) * 6, (0.0, -1.0, 1.0, -1.0, -1.0, 0.0), (1.5, -1.5, 1.5, 0.0, 1.5, 0.0),
         (-1.5, -1.5, -1.5, 0.0, -1.5, 0.0), (3.0, -0.5, 2.0, -1.5, 1.0, 1.0))


@contextmanager
def _parser_quiet():
    """The process's stderr (fd 2) closed to urdfdom, which prints its parse errors there
    from C++ before pinocchio raises: a bad URDF is then the CellError's one line."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


@lru_cache(maxsize=16)
def _load(path: str, tip: str):
    if not os.path.isfile(path):
        raise CellError(f"cell: 'urdf' {path} does not load: no such file")
    try:
        with _parser_quiet():
            model = pin.buildModelFromUrdf(path)
    except (ValueError, RuntimeError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise CellError(f"cell: 'urdf' {path} does not load: {first}") from None
    name = tip or ("tool0" if model.existFrame("tool0") else model.frames[-1].name)
    if not model.existFrame(name):
        raise CellError(f"cell: 'tip' {name!r} is not a frame of {path}")
    return model, model.getFrameId(name)


def load_arm(robot: Robot):
    """(pinocchio model, tip frame id) of ``robot``'s URDF (CellError naming the field)."""
    return _load(robot.urdf, robot.tip)


def flange_target(robot: Robot, point, rotation) -> pin.SE3:
    """The tip link's pose for the TCP at ``point`` with tool axes ``rotation`` (world), in
    ``robot``'s base frame."""
    rotation = np.asarray(rotation, dtype=float)
    flange = np.asarray(point, dtype=float) - rotation @ np.asarray(robot.tool.tcp)
    c, s = np.cos(robot.base_yaw), np.sin(robot.base_yaw)
    base = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return pin.SE3(base.T @ rotation, base.T @ (flange - np.asarray(robot.base)))


def solve_ik(robot: Robot, point, rotation) -> np.ndarray | None:
    """Joint angles of ``robot`` putting its TCP at ``point`` with tool axes ``rotation``
    (world), within the joint limits, or None when none of the seeds converges."""
    model, tip = load_arm(robot)
    data = model.createData()
    target = flange_target(robot, point, rotation)
    low, high = model.lowerPositionLimit, model.upperPositionLimit
    for seed in SEEDS:
        q = pin.neutral(model).copy()
        q[:min(len(seed), model.nq)] += np.asarray(seed[:model.nq])
        for _ in range(IK_ITERATIONS):
            pin.framesForwardKinematics(model, data, q)
            offset = target.actInv(data.oMf[tip])     # the tip in the target's frame
            error = pin.log6(offset).vector
            if np.linalg.norm(error) < IK_TOL:
                if np.all(q >= low - 1e-9) and np.all(q <= high + 1e-9):
                    return q
                break
            jac = pin.computeFrameJacobian(model, data, q, tip, pin.LOCAL)
            jac = pin.Jlog6(offset) @ jac
            step = -jac.T @ np.linalg.solve(jac @ jac.T + DAMPING * np.eye(6), error)
            q = np.clip(pin.integrate(model, q, step), low, high)
    return None


__all__ = ["IK_TOL", "flange_target", "load_arm", "solve_ik"]
