"""LMGC90 (non-smooth contact dynamics, the DEM masonry researchers trust) as a second opinion.

LMGC90 comes from the ``compas-lmgc90`` wheel, in a venv of its own (``.venv-lmgc90`` in the
source tree, or ``$RBE_LMGC90_VENV``; made from requirements/lmgc90.txt by ``make lmgc90``,
:func:`ensure_venv`): the wheel pulls compas_viewer and PySide6, which have no place beside the
ROS wheels. Each check runs ``lmgc90_driver.py`` in a process of its own with that venv's
python (LMGC90 keeps one simulation per process and a Fortran STOP ends the process). Used by
``rbe-ros check --second-opinion lmgc90``, the node's ``second_opinion`` parameter and
``make bench-lmgc90`` (benchmarks/bench.py): one harness.

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
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull

from ..analysis.assembly import Assembly
from ..analysis.options import CheckOptions
from ..analysis.steps import final_state, sequence_step
from ..geometry.block import pose_blocks
from ..rbe.result import Report
from ..scene import Scene, gravity_down

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]                      # the source tree (requirements/, .venv-lmgc90)
DRIVER = HERE / "lmgc90_driver.py"
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
ENGINES = ("lmgc90",)


class NotInstalled(RuntimeError):
    """LMGC90's venv is not there; the message says so in one line and how to install it."""


def venv_path(venv=None) -> Path:
    """The LMGC90 venv: ``venv``, else ``$RBE_LMGC90_VENV``, else .venv-lmgc90 in the tree."""
    return Path(venv or os.environ.get(VENV_ENV) or DEFAULT_VENV)


def venv_python(venv) -> Path:
    """The python of ``venv``."""
    return Path(venv) / "bin" / "python"


def _stamp(venv) -> Path:
    return Path(venv) / ".lmgc90-stamp"


def installed_python(venv=None) -> Path:
    """The python of an installed LMGC90 venv (made by :func:`ensure_venv`, which leaves its
    stamp); :class:`NotInstalled` otherwise."""
    venv = venv_path(venv)
    python = venv_python(venv)
    if not (python.exists() and _stamp(venv).exists()):
        raise NotInstalled(f"LMGC90 is not installed in {venv}: run `make lmgc90` in the rbe_ros"
                           f" source tree (about 1 GB, a few minutes), or set {VENV_ENV} to the"
                           f" venv it made")
    return python


def _pins(text: str) -> list[str]:
    """The requirement lines of a requirements file (comments and blank lines left out)."""
    return [line.strip() for line in text.splitlines() if line.strip()
            and not line.lstrip().startswith("#")]


def ensure_venv(venv=None) -> Path:
    """The python of the LMGC90 venv, made from requirements/lmgc90.txt (and checked with pip
    check) when missing or when its pins changed since it was made."""
    venv = venv_path(venv)
    python = venv_python(venv)
    wanted = REQUIREMENTS.read_text()
    if (python.exists() and _stamp(venv).exists()
            and _pins(_stamp(venv).read_text()) == _pins(wanted)):
        return python
    if not python.exists():
        print(f"[lmgc90] creating {venv}", file=sys.stderr, flush=True)
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    print(f"[lmgc90] pip install -r {REQUIREMENTS} into {venv} (about 1 GB)",
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


def bodies(scene: Scene) -> tuple[list[dict], dict]:
    """The scene's blocks as LMGC90 bodies (see the module docstring), and what was changed
    to make them convex: ``{"slabs": {support id: pieces}, "hulls": [free block ids]}``."""
    g = np.asarray(scene.gravity, dtype=float)
    if not np.allclose(g / np.linalg.norm(g), [0.0, 0.0, -1.0]):
        raise ValueError("LMGC90's gravity is along -z: turn the scene first (gravity_down)")
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


def check(scene: Scene, mu: float, python: Path, T: float = T,
          timeout: float = TIMEOUT, numerics: dict | None = None) -> dict:
    """One LMGC90 verdict of ``scene`` (gravity along -z) with friction ``mu``: the driver's
    answer (``stable``, ``moved``: the free blocks beyond the thresholds, ``max_disp``, ...)
    plus ``time_process`` (wall time of the whole process) and what was made convex;
    ``failed`` with the error when the process died or ran out of ``timeout`` s.
    ``numerics`` overrides the request (``dt`` and the driver's optional keys: a
    sensitivity run, benchmarks/lmgc90_sensitivity.py)."""
    body_list, convexified = bodies(scene)
    request = {"bodies": body_list, "mu": float(mu), "dt": DT, "theta": THETA, "T": float(T),
               "check_every": CHECK_EVERY, "disp_tol": DISP_TOL, "rot_tol_deg": ROT_TOL_DEG
               } | (numerics or {})
    start = time.perf_counter()
    try:
        # -I: isolated, above all without the driver's folder on sys.path (rbe_ros/io has a
        # compas.py that would shadow the compas package there)
        proc = subprocess.run([str(python), "-I", str(DRIVER)], input=json.dumps(request),
                              capture_output=True, text=True, timeout=timeout,
                              env=os.environ | SINGLE_THREAD)
    except subprocess.TimeoutExpired:
        proc = None
    elapsed = time.perf_counter() - start
    lines = proc.stdout.strip().splitlines() if proc else []
    if proc is None or proc.returncode != 0 or not lines:
        error = (f"no answer within {timeout:g} s" if proc is None else f"exit {proc.returncode}: "
                 + " | ".join(proc.stderr.strip().splitlines()[-3:]))
        return {"failed": True, "stable": None, "error": error, "time": elapsed,
                "time_process": elapsed} | convexified
    answer = json.loads(lines[-1])
    answer["time_process"] = elapsed
    answer["failed"] = False
    return answer | convexified


def settings() -> dict:
    """The criterion and the integrator's settings, as results record them."""
    return {"dt": DT, "theta": THETA, "T": T, "T_tilt": T_TILT, "check_every": CHECK_EVERY,
            "disp_tol": DISP_TOL, "rot_tol_deg": ROT_TOL_DEG, "slab_depth": SLAB_DEPTH,
            "law": "IQS_CLB"}


def second_opinion(scene: Scene, mu: float, stable: bool, *, venv=None,
                   timeout: float = TIMEOUT) -> dict:
    """LMGC90's verdict on the state ``scene`` (turned so that gravity is along -z) beside
    ours (``stable``): ``{"engine", "stable", "moved", "agrees", "time_s", ...}``; ``stable``
    and ``agrees`` are None where LMGC90 cannot decide (a non-convex free block goes in as its
    hull; the run failed: ``error``). :class:`NotInstalled` when LMGC90 is not there."""
    python = installed_python(venv)
    res = check(gravity_down(scene), mu, python, timeout=timeout)
    decided = not res["failed"] and not res.get("hulls")
    lmgc = bool(res["stable"]) if decided else None
    out = {"engine": "lmgc90", "stable": lmgc, "moved": list(res.get("moved", [])),
           "agrees": None if lmgc is None else lmgc == bool(stable),
           "time_s": float(res["time_process"]), "simulated_s": res.get("simulated"),
           "max_disp": res.get("max_disp"), "max_rot_deg": res.get("max_rot_deg")}
    if res.get("hulls"):
        out["error"] = ("not comparable: LMGC90 takes one convex polyhedron per block, and "
                        + ", ".join(res["hulls"]) + " went in as convex hulls")
    elif res["failed"]:
        out["error"] = f"LMGC90 failed: {res['error']}"
    return out


def state_of(scene: Scene, report: Report, sequence: bool) -> Scene:
    """The state a report is about: a step's blocks (of a sequence) or the final state, the
    held blocks as supports (LMGC90 knows no robot's wrench: a hold is rigid there)."""
    if sequence and report.step_index >= 0:
        step = sequence_step(scene, report.step_index)
        present, held = step.present, step.held
    else:
        present, held = final_state(scene)
    held = set(held)
    state = scene.subset(present)
    return replace(state, blocks=tuple(replace(b, support=True) if b.id in held else b
                                       for b in state.blocks))


def second_opinions(scene: Scene, reports, options: CheckOptions, sequence: bool,
                    venv=None, on_state=None) -> list[dict]:
    """:func:`second_opinion` of each report's state (``options.second_opinion`` names the
    engine; only LMGC90 here), at the check's mu, each within the check's time limit;
    ``on_state(k, total)`` before each (progress)."""
    if options.second_opinion not in ENGINES:
        return []
    venv = installed_python(venv).parents[1]       # NotInstalled before any simulation
    timeout = min(TIMEOUT, options.solve.time_limit)
    out = []
    for k, report in enumerate(reports):
        if on_state is not None:
            on_state(k, len(reports))
        out.append(second_opinion(state_of(scene, report, sequence), options.solve.mu,
                                  report.stable, venv=venv, timeout=timeout))
    return out


def describe(opinion: dict, ours_time_s: float, ours_status: str) -> str:
    """One line for the text report: LMGC90's verdict, what moved, the times, the agreement."""
    head = (f"second opinion (LMGC90, {T:g} s from rest): ")
    times = f"{opinion['time_s']:.2f} s, ours {ours_time_s:.3f} s"
    if opinion["stable"] is None:
        return head + f"undecided: {opinion.get('error', '')} ({times})"
    word = "stands" if opinion["stable"] else "falls, moved: " + ", ".join(opinion["moved"])
    verdict = "agrees with" if opinion["agrees"] else "DISAGREES with"
    return head + f"{word} ({times}); {verdict} rbe_ros ({ours_status})"
