"""LMGC90 (non-smooth contact dynamics, the DEM masonry researchers trust) as a stability check.

LMGC90 comes from the ``compas-lmgc90`` wheel, in a scratch venv of its own
(``.venv-lmgc90``, from requirements/lmgc90.txt, made by :func:`ensure_venv`): the wheel pulls
compas_viewer and PySide6, which have no place beside the ROS wheels. Each check runs
``_lmgc90_driver.py`` in a process of its own (LMGC90 keeps one simulation per process and a
Fortran STOP ends the process).

The verdict (documented in docs/BENCHMARKS.md): simulate from rest with time step :data:`DT`
(theta scheme, :data:`THETA`), law IQS_CLB (inelastic quasi-shock, Coulomb friction mu);
"falls" when a free block's centre of inertia moves more than :data:`DISP_TOL` x its size
(cube root of its volume) or it turns more than :data:`ROT_TOL_DEG` within :data:`T`, tested
every :data:`CHECK_EVERY` s. The thresholds sit between what LMGC90 does on the near-limit
suite at 1 ms: standing cases move at most 3.4e-3 x size and 0.02 deg within 1 s (the tower
of 40 boxes, whose contact solution jitters; 2 ms steps double that), falling ones (1% beyond
a limit) at least 2.5e-2 x size (the slowest, sliding on the inclined interface) or 5 deg.

Blocks go in as convex polyhedra (the convex hull of their vertices). A non-convex support is
replaced by convex slabs, one per interface our detection finds on it (the contact polygon
extruded into the support by :data:`SLAB_DEPTH` x the smaller block's size): the free blocks
touch the same faces, but the support's other faces are not there if a block moves onto them.
A non-convex free block goes in as its hull, and the case is marked not comparable.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull

from rbe_ros.analysis.assembly import Assembly
from rbe_ros.geometry.block import pose_blocks

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
REQUIREMENTS = ROOT / "requirements" / "lmgc90.txt"
DEFAULT_VENV = ROOT / ".venv-lmgc90"
VENV_ENV = "RBE_LMGC90_VENV"

DT = 1e-3                    # s
THETA = 0.5
T = 1.0                      # s simulated
#: s simulated per trial of a tilt bisection: creep beyond a sliding limit grows as t^2, and
#: 1 s resolves a sliding tilt capacity to only about 0.08 deg (of mu = 0.5), 3 s to 0.01 deg.
T_TILT = 3.0
CHECK_EVERY = 0.05           # s
DISP_TOL = 1e-2              # x block size
ROT_TOL_DEG = 1.0
SLAB_DEPTH = 0.1             # x the smaller block's size
DENSITY = 2000.0             # kg/m^3 where the scene gives masses only
TIMEOUT = 1800.0             # s per check
SINGLE_THREAD = {k: "1" for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}


def venv_python(venv) -> Path:
    return Path(venv) / "bin" / "python"


def _stamp(venv) -> Path:
    return Path(venv) / ".lmgc90-stamp"


def ensure_venv(venv=None) -> Path:
    """The python of the LMGC90 venv, made from requirements/lmgc90.txt (and checked with pip
    check) when missing or when the requirements changed since it was made."""
    venv = Path(venv or os.environ.get(VENV_ENV) or DEFAULT_VENV)
    python = venv_python(venv)
    wanted = REQUIREMENTS.read_text()
    if python.exists() and _stamp(venv).exists() and _stamp(venv).read_text() == wanted:
        return python
    if not python.exists():
        print(f"[lmgc90] creating {venv}", file=sys.stderr, flush=True)
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    print(f"[lmgc90] pip install -r {REQUIREMENTS.relative_to(ROOT)} into {venv} (about 1 GB)",
          file=sys.stderr, flush=True)
    pip = [str(python), "-m", "pip", "--disable-pip-version-check"]
    subprocess.run([*pip, "install", "--quiet", "-r", str(REQUIREMENTS)], check=True)
    subprocess.run([*pip, "check"], check=True)
    subprocess.run([str(python), "-c", "import compas_lmgc90.solver"], check=True)
    _stamp(venv).write_text(wanted)
    return python


def _hull_faces(points: np.ndarray) -> list[list[int]]:
    """Triangles of the convex hull of ``points``, wound outwards, indexing ``points``."""
    hull = ConvexHull(points)
    centre = points[hull.vertices].mean(axis=0)
    faces = []
    for tri in hull.simplices:
        a, b, c = points[tri]
        if np.dot(np.cross(b - a, c - a), a - centre) < 0:
            tri = tri[::-1]
        faces.append([int(i) for i in tri])
    return faces


def _polyhedron(points: np.ndarray) -> dict:
    hull = ConvexHull(points)
    keep = points[hull.vertices]
    return {"vertices": keep.tolist(), "faces": _hull_faces(keep)}


def bodies(scene) -> tuple[list[dict], dict]:
    """The scene's blocks as LMGC90 bodies (see the module docstring), and what was changed
    to make them convex: ``{"slabs": {support id: pieces}, "hulls": [free block ids]}``."""
    g = np.asarray(scene.gravity, dtype=float)
    if not np.allclose(g / np.linalg.norm(g), [0.0, 0.0, -1.0]):
        raise ValueError("LMGC90's gravity is along -z: turn the scene first")
    posed = pose_blocks(scene.blocks)
    out, slabs, hulls = [], {}, []
    interfaces = None
    for i, block in enumerate(posed):
        density = block.mass / block.volume if block.volume > 0 else DENSITY
        body = {"id": block.id, "support": bool(block.support), "density": float(density),
                "size": float(block.size)}
        if block.convex or not block.support:
            if not block.convex:
                hulls.append(block.id)
            out.append(body | _polyhedron(block.vertices))
            continue
        if interfaces is None:
            interfaces = Assembly.from_scene(scene).interfaces
        pieces = 0
        for it in interfaces:
            if i not in (it.a, it.b):
                continue
            other = posed[it.b if it.a == i else it.a]
            depth = SLAB_DEPTH * min(block.size, other.size)
            into = -it.frame.n if it.a == i else it.frame.n     # n points from a into b
            slab = np.vstack([it.points, it.points + depth * into])
            out.append(body | {"id": f"{block.id}#{pieces}"} | _polyhedron(slab))
            pieces += 1
        slabs[block.id] = pieces
    return out, {"slabs": slabs, "hulls": hulls}


def check(scene, mu: float, python: Path, T: float = T) -> dict:
    """One LMGC90 verdict of ``scene`` (gravity along -z) with friction ``mu``: the driver's
    answer plus ``time_process`` (wall time of the whole process) and what was made convex;
    ``failed`` with the error when the process died."""
    body_list, convexified = bodies(scene)
    request = {"bodies": body_list, "mu": float(mu), "dt": DT, "theta": THETA, "T": float(T),
               "check_every": CHECK_EVERY, "disp_tol": DISP_TOL, "rot_tol_deg": ROT_TOL_DEG}
    start = time.perf_counter()
    try:
        proc = subprocess.run([str(python), str(HERE / "_lmgc90_driver.py")],
                              input=json.dumps(request), capture_output=True, text=True,
                              timeout=TIMEOUT, env=os.environ | SINGLE_THREAD)
    except subprocess.TimeoutExpired:
        proc = None
    elapsed = time.perf_counter() - start
    lines = proc.stdout.strip().splitlines() if proc else []
    if proc is None or proc.returncode != 0 or not lines:
        error = (f"no answer within {TIMEOUT:g} s" if proc is None else f"exit {proc.returncode}: "
                 + " | ".join(proc.stderr.strip().splitlines()[-3:]))
        return {"failed": True, "stable": None, "error": error, "time": elapsed,
                "time_process": elapsed} | convexified
    answer = json.loads(lines[-1])
    answer["time_process"] = elapsed
    answer["failed"] = False
    return answer | convexified


def settings() -> dict:
    return {"dt": DT, "theta": THETA, "T": T, "T_tilt": T_TILT, "check_every": CHECK_EVERY, "disp_tol": DISP_TOL,
            "rot_tol_deg": ROT_TOL_DEG, "slab_depth": SLAB_DEPTH, "law": "IQS_CLB"}
