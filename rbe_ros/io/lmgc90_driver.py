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

Optional keys, for the sensitivity of a verdict to LMGC90's numerics
(benchmarks/lmgc90_sensitivity.py; absent, the verdict is the one above): ``alert`` (m, the
contact detection distance, compas_lmgc90's default 1e-3), ``nlgs`` (``{"tol", "relax",
"gs_it1", "gs_it2"}``: the contact solver's settings, which compas_lmgc90 0.1.11 fixes at
1.666e-4, 0.1, 50 and 500 in its wrapper's data; they are set in a patched copy of the
extension, :func:`_patched_build`), ``trace`` (run on to ``T`` after a collapse, until a block
moved ``trace_stop`` x its size, and answer ``trace``: each free block's displacement / size
at each test).
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import struct
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: the contact solver's settings in compas_lmgc90 0.1.11's extension (its wrapper's module
#: data, in this order from ``tol``): name, byte offset, struct format, value as built
NLGS_DATA = (("tol", 0x00, "<d", float(np.float32(1.666e-4))),
             ("relax", 0x10, "<d", float(np.float32(0.1))),
             ("detection", 0x20, "<3s", b"STO"), ("norm", 0x35, "<5s", b"QM/16"),
             ("gs_it2", 0x50, "<i", 500), ("gs_it1", 0x54, "<i", 50))


def _patched_build(nlgs: dict) -> Path:
    """A folder holding a copy of compas_lmgc90 whose extension has the contact solver's
    settings ``nlgs`` (made once per setting under the temp dir). The settings are found by
    their built values in the extension's data, all of them, or this refuses."""
    import compas_lmgc90
    pkg = Path(compas_lmgc90.__file__).parent
    ext = next(pkg.glob("_lmgc90*.so"))
    data = bytearray(ext.read_bytes())
    tol = struct.pack("<d", NLGS_DATA[0][3])
    at = data.find(tol)
    if at < 0 or data.find(tol, at + 1) >= 0:
        raise RuntimeError(f"{ext.name}: the NLGS settings are not where 0.1.11 has them")
    for name, off, fmt, built in NLGS_DATA:
        if struct.unpack_from(fmt, data, at + off)[0] != built:
            raise RuntimeError(f"{ext.name}: {name} is not {built!r} at its place")
    for name, off, fmt, _ in NLGS_DATA:
        if name in nlgs:
            struct.pack_into(fmt, data, at + off, type(_)(nlgs[name]))
    # keyed by the installation too: the copy links its libraries, and a venv removed since
    # (another worktree's) would leave a copy that cannot load
    libs = (pkg.parent / "compas_lmgc90.libs").resolve()   # the extension's RPATH
    key = hashlib.sha1(json.dumps([nlgs, str(libs)], sort_keys=True).encode()).hexdigest()[:10]
    root = Path(tempfile.gettempdir()) / f"rbe_lmgc90_nlgs_{key}"
    if not (root / "compas_lmgc90" / ext.name).exists():
        tmp = Path(tempfile.mkdtemp(dir=tempfile.gettempdir()))
        shutil.copytree(pkg, tmp / "compas_lmgc90", ignore=shutil.ignore_patterns("__pycache__"))
        if libs.exists():
            (tmp / "compas_lmgc90.libs").symlink_to(libs)
        (tmp / "compas_lmgc90" / ext.name).write_bytes(bytes(data))
        try:
            tmp.rename(root)
        except OSError:                                       # made meanwhile by another run
            shutil.rmtree(tmp)
    return root


def _angle_deg(frame0: np.ndarray, frame1: np.ndarray) -> float:
    """Angle of the rotation between two body frames (3 x 3), in degrees."""
    c = 0.5 * (float(np.trace(frame1.T @ frame0)) - 1.0)
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def check(request: dict) -> dict:
    """Simulate the request from rest and answer as the module docstring says."""
    if request.get("nlgs"):
        sys.path.insert(0, str(_patched_build(request["nlgs"])))
        for name in [m for m in sys.modules if m.startswith("compas_lmgc90")]:
            del sys.modules[name]
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
    solver.contact_law("IQS_CLB", float(request["mu"]), alert=float(request.get("alert", 1e-3)))
    solver.preprocess()
    init = solver.lmgc90.get_initial_state()
    free = [(b.get("id", str(i)), i, np.array(init.init_bodies[i]),
             np.array(init.init_body_frames[i]).reshape(3, 3), float(b["size"]))
            for i, b in enumerate(bodies) if not b["support"]]
    time_setup = time.perf_counter() - start
    steps = int(round(float(request["T"]) / dt))
    every = max(1, int(round(float(request["check_every"]) / dt)))
    disp_tol, rot_tol = float(request["disp_tol"]), float(request["rot_tol_deg"])
    trace = [] if request.get("trace") else None
    stop = float(request.get("trace_stop", 0.2))
    done, worst, collapsed, moved = 0, (0.0, 0.0), False, []
    first = None                                  # the answer at the first collapse
    while done < steps and (not collapsed or (trace is not None and worst[0] < stop)):
        for _ in range(min(every, steps - done)):
            state = solver.lmgc90.compute_one_step()   # the Solver's run() minus its mesh updates
            done += 1
        disp = rot = 0.0
        moved = []
        if trace is not None:
            trace.append([done * dt, {}])
        for name, i, x0, f0, size in free:
            d = float(np.linalg.norm(np.array(state.bodies[i]) - x0)) / size
            r = _angle_deg(f0, np.array(state.body_frames[i]).reshape(3, 3))
            disp, rot = max(disp, d), max(rot, r)
            if d > disp_tol or r > rot_tol:
                moved.append(str(name))
            if trace is not None:
                trace[-1][1][str(name)] = [d, r]
        worst = (disp, rot)
        if moved and first is None:
            first = {"moved": moved, "max_disp": disp, "max_rot_deg": rot,
                     "simulated": done * dt}
        collapsed = first is not None
    elapsed = time.perf_counter() - start
    solver.finalize()
    out = {"stable": not collapsed, "moved": moved, "max_disp": worst[0],
           "max_rot_deg": worst[1], "simulated": done * dt, "steps": done, "time": elapsed,
           "time_setup": time_setup}
    if first is not None:
        out |= first
    if trace is not None:
        out |= {"trace": trace, "traced": done * dt}
    return out


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
