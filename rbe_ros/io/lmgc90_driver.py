"""LMGC90's side of rbe_ros/io/lmgc90.py: one stability check by non-smooth contact dynamics.

Runs inside the venv with compas-lmgc90 (made by ``make lmgc90``; no rbe_ros here), one check
per process, because LMGC90 keeps one simulation per process and stops the
whole process (a Fortran STOP) on some bad inputs: a crash then costs one case, not the run.

    <venv>/bin/python rbe_ros/io/lmgc90_driver.py < request.json

The request (one JSON object on stdin): ``{"bodies": [{"support", "density", "size",
"vertices", "faces"}], "mu", "dt", "theta", "T", "check_every", "disp_tol", "rot_tol_deg"}``
with world vertices (m) of closed convex polyhedra, faces wound outwards; gravity is LMGC90's
own, along -z (the caller turns a tilted scene). The answer (one JSON line on stdout):
``{"stable", "moved", "max_disp", "max_rot_deg", "simulated", "time", "time_setup",
"versions"}``:
collapsed when a free body's centre of inertia moved more than ``disp_tol`` x its size or it
turned more than ``rot_tol_deg`` (tested every ``check_every`` s; the run stops at the first
collapse; ``moved``: the ids of the free bodies beyond a threshold then). ``time`` is the wall
time of set-up and simulation (Python start-up and imports excluded, as for the other methods).
"""
from __future__ import annotations

import json
import math
import os
import sys
import time

import numpy as np


def _angle_deg(frame0: np.ndarray, frame1: np.ndarray) -> float:
    """Angle of the rotation between two body frames (3 x 3), in degrees."""
    c = 0.5 * (float(np.trace(frame1.T @ frame0)) - 1.0)
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def check(request: dict) -> dict:
    """Simulate the request from rest and answer as the module docstring says."""
    from compas_lmgc90.solver import Solver

    bodies = request["bodies"]
    dt = float(request["dt"])
    start = time.perf_counter()
    solver = Solver(dt=dt, theta=float(request.get("theta", 0.5)))
    solver.geometry_from_v_f([{"vertices": b["vertices"], "faces": b["faces"]} for b in bodies],
                             density=[float(b["density"]) for b in bodies])
    for i, b in enumerate(bodies):
        if b["support"]:                      # all six velocities driven to zero (as set_supports)
            solver.v_drvdof[i] = {dof: np.zeros(6) for dof in range(1, 7)}
    solver.contact_law("IQS_CLB", float(request["mu"]))
    solver.preprocess()
    init = solver.lmgc90.get_initial_state()
    free = [(b.get("id", str(i)), i, np.array(init.init_bodies[i]),
             np.array(init.init_body_frames[i]).reshape(3, 3), float(b["size"]))
            for i, b in enumerate(bodies) if not b["support"]]
    time_setup = time.perf_counter() - start
    steps = int(round(float(request["T"]) / dt))
    every = max(1, int(round(float(request["check_every"]) / dt)))
    disp_tol, rot_tol = float(request["disp_tol"]), float(request["rot_tol_deg"])
    done, worst, collapsed, moved = 0, (0.0, 0.0), False, []
    while done < steps and not collapsed:
        for _ in range(min(every, steps - done)):
            state = solver.lmgc90.compute_one_step()   # the Solver's run() minus its mesh updates
            done += 1
        disp = rot = 0.0
        moved = []
        for name, i, x0, f0, size in free:
            d = float(np.linalg.norm(np.array(state.bodies[i]) - x0)) / size
            r = _angle_deg(f0, np.array(state.body_frames[i]).reshape(3, 3))
            disp, rot = max(disp, d), max(rot, r)
            if d > disp_tol or r > rot_tol:
                moved.append(str(name))
        collapsed = bool(moved)
        worst = (disp, rot)
    elapsed = time.perf_counter() - start
    solver.finalize()
    return {"stable": not collapsed, "moved": moved, "max_disp": worst[0], "max_rot_deg": worst[1],
            "simulated": done * dt, "steps": done, "time": elapsed, "time_setup": time_setup}


def versions() -> dict:
    """The versions of the packages that make the verdict."""
    from importlib import metadata
    out = {}
    for name in ("compas_lmgc90", "compas", "numpy"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    return out


def main() -> int:
    """Read the request on stdin, write the answer as one JSON line on stdout."""
    out = os.fdopen(os.dup(1), "w")           # the answer goes here ...
    os.dup2(2, 1)                             # ... LMGC90's Fortran chatter on fd 1 to stderr
    sys.stdout = sys.stderr
    answer = check(json.loads(sys.stdin.read()))
    answer["versions"] = versions()
    out.write(json.dumps(answer) + "\n")
    out.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
