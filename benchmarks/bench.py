"""Speed against accuracy: rbe_ros side by side with what users would pick instead.

    .venv/bin/python benchmarks/bench.py            (or: make bench; about 30-40 minutes)
    .venv/bin/python benchmarks/bench.py --quick    (under 3 minutes; writes out/bench-quick/)

Methods, all run in this one process run, scene by scene (compas_cra in a subprocess of its
own venv, see _bench_cra_driver.py):

* ours in each configuration: objective QP / LP x friction cone exact (soc) / 8-sided
  inscribed / 8-sided circumscribed / 4-sided (``rbe_ros.analysis.pipeline.check_scene``,
  interface detection included; tilt capacities with ``tilt_capacity``);
* the default problem stated in cvxpy (``_cvxpy_rbe.py``), same detection and matrices;
* compas_cra 0.8.0 ``rbe_solve`` (IPOPT), on the same scenes exported with
  ``rbe_ros.io.compas.save_compas_assembly``;
* PyBullet at 240 Hz and at 1 kHz, MuJoCo at 1 kHz (``_physics.py``);
* LMGC90 (non-smooth contact dynamics, ``rbe_ros/io/lmgc90.py``, in a venv of its own made by
  make lmgc90), the accuracy reference, also on compas_cra's samples (docs/lmgc90_verdicts.json)
  and on the squeeze suite (tests/data/squeeze/lmgc90_verdicts.json).

Writes docs/BENCHMARKS.md, docs/bench/*.png and docs/bench/results.json. Every number is
measured in the run that writes it; rerunning refreshes all of them.
``--only lmgc90`` (make bench-lmgc90) runs LMGC90 and ours (for the time ratio) alone and
merges them into the last full run's results.json before writing the same files.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT / "tests"))   # the independent references (tests/oracles/)

import compas_compare  # noqa: E402
import _physics as physics  # noqa: E402
from machine import machine_summary  # noqa: E402
from oracles import arch_limit  # noqa: E402
from timing import best_of  # noqa: E402

from rbe_ros import generators as gen  # noqa: E402
from rbe_ros.analysis.assembly import Assembly  # noqa: E402
from rbe_ros.analysis.options import CheckOptions  # noqa: E402
from rbe_ros.analysis.pipeline import check_scene  # noqa: E402
from rbe_ros.analysis.tilt import horizontal, tilt_capacity  # noqa: E402
from rbe_ros.io import lmgc90  # noqa: E402
from rbe_ros.io.compas import EXAMPLE_AXES, rotated_as_example  # noqa: E402
from rbe_ros.geometry.contacts import ContactOptions  # noqa: E402
from rbe_ros.rbe.model import build_model  # noqa: E402
from rbe_ros.rbe.solver import SolveOptions  # noqa: E402
from rbe_ros.scene import Scene, box_block, gravity_down, make_scene  # noqa: E402

G = 9.81
#: Ours: (objective, cone); the first is the default configuration.
OURS = [("qp", "soc"), ("qp", "pyramid8"), ("qp", "pyramid8-outer"), ("qp", "pyramid4"),
        ("lp", "soc"), ("lp", "pyramid8"), ("lp", "pyramid8-outer"), ("lp", "pyramid4")]
DEFAULT = "ours-qp-soc"
#: Physics settings: id -> (engine, rate Hz, solver iterations or None for the default).
PHYSICS = {"pybullet-240": ("pybullet", 240.0, None), "pybullet-1k": ("pybullet", 1000.0, 100),
           "mujoco-1k": ("mujoco", 1000.0, None)}
PHYS_T = 1.0                 # s simulated
PHYS_DISP = 0.1              # x block size
PHYS_ROT = 5.0               # deg
#: On larger scenes only PyBullet at 240 Hz simulates the full second; PyBullet and MuJoCo
#: at 1 kHz are timed on a short run only (no verdict), to keep make bench within its time.
PHYS_1K_FULL_MAX = 100
#: compas_cra: tension above this share of the free weight means "not stable" (as ours).
CRA_TENSION_TOL = 1e-5
#: compas_cra's own interface detection, timed once per scene (its examples' nmax; tmax and
#: amin in metres and square metres, for our metre-sized blocks).
CRA_DETECT = {"nmax": 10, "tmax": 1e-3, "amin": 1e-4}
TILT_TOL = 0.01              # deg, every method's tilt bisection
ARMADILLO_CONTACT = ContactOptions(distance_tol=5e-2, angle_tol_deg=5.0)
ARMADILLO_MU = 0.84          # rbe_solve's default mu
#: Runs of each of our timings on the armadillo (best kept; a run is 0.3 s, compas_cra's 5 s,
#: which gets 3: the machine is shared, and a short run is more often hit by other load).
ARMADILLO_REPEAT = 5
#: LMGC90's tilt capacities are bisected on these families only (a simulation per trial).
LMGC90_TILT_FAMILIES = ("single block", "yawed block")
#: compas_cra's samples for LMGC90 (docs/lmgc90_verdicts.json), set up as compas_cra's example
#: scripts set them up (compas_compare.SAMPLES: supports, mu, the bridge's 3.51 x density on
#: nodes 11-15); type-a..d as examples/05_wedge.py loads them: the two side blocks are the
#: supports, mu 0.84, and also turned 90 deg about the y, x and xy30 axes as it turns them
#: (rotate_assembly after detecting the interfaces: the same contacts).
LMGC90_SAMPLES = {name: compas_compare.SAMPLES[name]
                  for name in ("A", "H", "shelf", "cubes", "snake", "bridge")} | {
    f"type-{c}": {"file": f"type-{c}.json", "supports": [0, 1], "mu": 0.84} for c in "abcd"} | {
    f"type-{c} rot90 {axis}": {"file": f"type-{c}.json", "supports": [0, 1], "mu": 0.84,
                               "rotation": {"axis": list(EXAMPLE_AXES[axis]), "deg": 90.0}}
    for c in "abcd" for axis in EXAMPLE_AXES}
#: The squeeze suite (issue 29; scripts/squeeze_suite.py): LMGC90's verdicts go beside it.
SQUEEZE = ROOT / "tests" / "data" / "squeeze"


def method_label(mid: str) -> str:
    if mid.startswith("ours-"):
        _, obj, cone = mid.split("-", 2)
        cone = {"soc": "exact cone", "pyramid8": "8-pyramid inner", "pyramid8-outer": "8-pyramid outer",
                "pyramid4": "4-pyramid"}[cone]
        return f"ours {obj.upper()} {cone}" + (" (default)" if mid == DEFAULT else "")
    return {"cvxpy-qp-soc": "cvxpy QP exact cone", "compas_cra": "compas_cra rbe_solve",
            "pybullet-240": "PyBullet 240 Hz", "pybullet-1k": "PyBullet 1 kHz",
            "mujoco-1k": "MuJoCo 1 kHz", "lmgc90": "LMGC90"}[mid]


# ----------------------------------------------------------------------------- scenes

def block_on_base(size, yaw_deg: float = 0.0, density: float = 2000.0) -> Scene:
    """A box ``size`` (x, y, z) standing on a 4 x 4 x 0.2 support slab, turned by ``yaw_deg``
    about the vertical."""
    sx, sy, sz = size
    q = Rotation.from_euler("z", yaw_deg, degrees=True).as_quat()
    base = box_block("base", (4.0, 4.0, 0.2), (0, 0, -0.1), density=density, support=True)
    top = box_block("block", size, (0, 0, sz / 2), q, density=density)
    return make_scene(f"block {sx:g}x{sy:g}x{sz:g} yaw {yaw_deg:g}", [base, top])


def tilted(scene: Scene, alpha_deg: float, direction: str = "x") -> Scene:
    """``scene`` with gravity turned by ``alpha_deg`` towards ``direction``."""
    g = np.asarray(scene.gravity, dtype=float)
    h = horizontal(direction, g)
    a = math.radians(alpha_deg)
    gravity = np.linalg.norm(g) * (math.cos(a) * g / np.linalg.norm(g) + math.sin(a) * h)
    return replace(scene, gravity=gravity)


# ----------------------------------------------------------------------------- cases

@dataclass
class Case:
    name: str
    family: str
    kind: str                    # "verdict" or "tilt"
    scene: Scene
    mu: float
    exact: object                # bool (stands?) or degrees
    source: str
    note: str = ""
    physics: bool = True         # run the physics engines on it
    cra: bool = True
    results: dict = field(default_factory=dict)


def near_limit_cases(quick: bool) -> list[Case]:
    cases: list[Case] = []
    # single block on a tilting base: tipping atan(b/h), sliding atan(mu)
    cases.append(Case("block 0.5x0.5x1.0, mu 0.8: tips", "single block", "tilt",
                      block_on_base((0.5, 0.5, 1.0)), 0.8, math.degrees(math.atan(0.5)),
                      "atan(b/h) = atan(0.5/1.0) (tipping; sliding atan 0.8 = 38.7 deg is later)"))
    cases.append(Case("block 1.0x1.0x0.5, mu 0.5: slides", "single block", "tilt",
                      block_on_base((1.0, 1.0, 0.5)), 0.5, math.degrees(math.atan(0.5)),
                      "atan(mu) = atan(0.5) (sliding; tipping atan 2 = 63.4 deg is later)"))
    for yaw in (0.0, 22.5, 45.0):
        cases.append(Case(f"flat block yawed {yaw:g} deg, mu 0.5", "yawed block", "tilt",
                          block_on_base((1.0, 1.0, 0.2), yaw), 0.5, math.degrees(math.atan(0.5)),
                          "atan(mu) whatever the yaw (isotropic Coulomb friction)",
                          note="circumscribed square pyramid at 45 deg: atan(mu sqrt 2) = 35.3 deg"))
    for n in (10, 20, 40):
        h = 0.5 * n
        cases.append(Case(f"tower of {n} boxes: tilt", "tower tilt", "tilt", gen.stack(n), 0.6,
                          math.degrees(math.atan(1.0 / h)),
                          f"atan(b/H) = atan(1/{h:g}) (the whole tower tips about its base)",
                          physics=not quick or n <= 10, cra=not quick or n <= 10))
    # verdicts
    for shift, ok in ((0.499, True), (0.501, False)):
        cases.append(Case(f"overhang {100 * shift:.1f}% of the width", "overhang", "verdict",
                          gen.two_blocks(shift=shift), 0.6, ok,
                          "statics: stands while the centre of mass is over the support (50%)"))
    for n in (5, 10, 20):
        for scale, ok in ((0.98, True), (1.02, False)):
            cases.append(Case(f"harmonic stack {n}, offsets x{scale:g}", "harmonic stack", "verdict",
                              gen.harmonic_stack(n, scale), 0.6, ok,
                              "Paterson & Zwick 2009: overhangs 1/(2k) are exactly marginal",
                              physics=not quick or n <= 10, cra=True))
    for n in (10, 20, 40):
        cases.append(Case(f"tower of {n} boxes", "tower", "verdict", gen.stack(n), 0.6, True,
                          "statics: a straight stack on the ground stands",
                          physics=not quick or n <= 20))
    theta = 23.6
    for f, ok in ((1.01, True), (0.99, False)):
        mu = f * math.tan(math.radians(theta))
        cases.append(Case(f"inclined interface {theta:g} deg, mu = tan x{f:g}", "inclined interface",
                          "verdict", gen.two_blocks(incline_deg=theta), mu, ok,
                          "mu >= tan(theta) (Kao et al. 2021, Sec. 3.1.2)"))
    return cases


def arch_cases(quick: bool) -> tuple[list[Case], dict]:
    """Near-limit arch cases with their exact limits from the thrust-line LP."""
    cases, info = [], {"t_min": {}, "continuous": 0.107426}
    mu = 0.8
    for n in (10, 15, 20):
        t = arch_limit.minimum_thickness(n, mu)
        info["t_min"][n] = t
        for f, ok in ((1.01, True), (0.99, False)):
            cases.append(Case(f"arch {n} voussoirs, t = t_min x{f:g}", "arch thickness", "verdict",
                              gen.semicircular_arch(n, f * t), mu, ok,
                              f"t_min/R = {t:.6f} for n = {n} (thrust-line LP, tests/oracles/arch_limit.py;"
                              f" continuous 0.107426, Cocchetti & Rizzi 2020)",
                              physics=not quick or n == 15))
    n, ratio = 15, 0.15
    mu_min = arch_limit.minimum_friction(n, ratio)
    info["mu_min_15_0.15"] = mu_min
    for f, ok in ((1.01, True), (0.99, False)):
        cases.append(Case(f"arch 15, t/R 0.15, mu = mu_min x{f:g}", "arch friction", "verdict",
                          gen.semicircular_arch(n, ratio), f * mu_min, ok,
                          f"mu_min = {mu_min:.5f} (thrust-line LP; continuous arch: the limit rises"
                          f" below mu 0.396, Cocchetti & Rizzi 2020)"))
    info["t_min_15_mu0.30"] = arch_limit.minimum_thickness(15, 0.30)
    cases.append(Case("arch 15, t/R 0.25, mu 0.30", "arch friction", "verdict",
                      gen.semicircular_arch(15, 0.25), 0.30, False,
                      "no thickness stands below mu 0.309 (Cocchetti & Rizzi 2020; thrust-line"
                      " LP for n = 15: none up to t/R 1.9)"))
    return cases, info


def paper_cases(quick: bool) -> list[Case]:
    """The paper's buttressed arch and dome, upright and tilted to 0.9 and 1.1 x the
    paper's tilt capacity (12 deg and 32 deg)."""
    out = []
    structures = [("buttressed arch", gen.buttressed_arch(), 0.8, 12.0, False)]
    if not quick:
        structures.append(("dome", gen.dome(), 0.6, 32.0, True))
    for name, scene, mu, cap, big in structures:
        for f in (0.0, 0.9, 1.1):
            alpha = f * cap
            out.append(Case(f"{name}, tilt {alpha:.1f} deg", "paper structures", "verdict",
                            tilted(scene, alpha), mu, f < 1.0,
                            f"Kao et al. 2021: stands upright, tilt capacity {cap:g} deg (our geometry"
                            f" choices may move it; see docs/PAPER.md)",
                            physics=not quick and not (big and f > 0)))
    return out


# ----------------------------------------------------------------------------- methods

def ours_options(obj: str, cone: str, mu: float, contact=None) -> CheckOptions:
    return CheckOptions(SolveOptions(objective=obj, cone=cone, mu=mu), contact=contact or ContactOptions())


def run_ours(case: Case, repeat: int) -> None:
    for obj, cone in OURS:
        mid = f"ours-{obj}-{cone}"
        opts = ours_options(obj, cone, case.mu)
        report, t = best_of(repeat, lambda: check_scene(case.scene, opts))
        res = {"time": t, "stable": bool(report.stable), "status": report.status.name,
               "failed": report.status.name == "SOLVER_FAILED"}
        if case.kind == "tilt":
            assembly = Assembly.from_scene(case.scene)
            tr = tilt_capacity(assembly, opts, "x", tol_deg=TILT_TOL)
            res.update(capacity=tr.tilt_deg, capacity_multiplier=tr.tilt_deg_multiplier,
                       trials=tr.trials, time_bisection=tr.time_bisection,
                       time_multiplier=tr.time_multiplier)
        case.results[mid] = res


def run_cvxpy(case: Case, repeat: int) -> None:
    import _cvxpy_rbe as cx
    (ok, t_in), t = best_of(repeat, lambda: cx.check_scene(case.scene, case.mu))
    res = {"time": t, "stable": bool(ok)}
    if case.kind == "tilt":
        assembly = Assembly.from_scene(case.scene)
        model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
        problem = cx.CvxpyRBE(model, case.mu)
        g = np.asarray(case.scene.gravity, dtype=float)
        h = horizontal("x", g)
        down, mag = g / np.linalg.norm(g), float(np.linalg.norm(g))
        start = time.perf_counter()

        def stands(alpha):
            a = math.radians(alpha)
            return problem.stands(model.load(mag * (math.cos(a) * down + math.sin(a) * h)))
        res["capacity"], res["trials"] = bisect_tilt(stands)
        res["time_bisection"] = time.perf_counter() - start
    case.results["cvxpy-qp-soc"] = res


def bisect_tilt(stands, tol: float = TILT_TOL, hi: float = 90.0) -> tuple[float, int]:
    """Largest angle known to stand, to ``tol``; nan if it does not stand upright."""
    trials = 1
    if not stands(0.0):
        return math.nan, trials
    lo = 0.0
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        trials += 1
        lo, hi = (mid, hi) if stands(mid) else (lo, mid)
    return lo, trials


def run_physics(case: Case, engines: list[str], tilt_engines: list[str]) -> None:
    bodies = physics.bodies_from_scene(case.scene)
    for mid in engines:
        engine, hz, it = PHYSICS[mid]
        if mid != "pybullet-240" and len(bodies) > PHYS_1K_FULL_MAX:
            res = physics_time(bodies, mid, False, gravity=tuple(case.scene.gravity), mu=case.mu)
            case.results[mid] = res
            continue
        kw = dict(engine=engine, hz=hz, iterations=it, T=PHYS_T, mu=case.mu,
                  disp_tol=PHYS_DISP, rot_tol_deg=PHYS_ROT)
        r = physics.check(bodies, gravity=tuple(case.scene.gravity), **kw)
        res = {"time": r["time"], "stable": r["stable"], "max_disp": r["max_disp"],
               "max_rot_deg": r["max_rot_deg"], "simulated": r["simulated"]}
        if case.kind == "tilt" and mid in tilt_engines:
            g = np.asarray(case.scene.gravity, dtype=float)
            h = horizontal("x", g)
            down = g / np.linalg.norm(g)
            start = time.perf_counter()

            def stands(alpha):
                a = math.radians(alpha)
                grav = G * (math.cos(a) * down + math.sin(a) * h)
                return physics.check(bodies, gravity=tuple(grav), **kw)["stable"]
            res["capacity"], res["trials"] = bisect_tilt(stands)
            res["time_bisection"] = time.perf_counter() - start
        case.results[mid] = res


def run_lmgc90(case: Case, python: Path) -> None:
    """LMGC90's verdict (gravity turned to -z, as it only knows that), and on the tilt families
    of :data:`LMGC90_TILT_FAMILIES` its tilt capacity by bisection on its verdict."""
    res = lmgc90.check(gravity_down(case.scene), case.mu, python)
    res["time_ours"] = case.results[DEFAULT]["time"]
    if case.kind == "tilt" and case.family in LMGC90_TILT_FAMILIES and not res["failed"]:
        start = time.perf_counter()
        res["capacity"], res["trials"] = bisect_tilt(lambda a: lmgc90.check(
            gravity_down(tilted(case.scene, a)), case.mu, python, T=lmgc90.T_TILT)["stable"])
        res["time_bisection"] = time.perf_counter() - start
    case.results["lmgc90"] = res


def sample_densities(spec: dict) -> dict[str, float]:
    """kg/m^3 of a sample's blocks whose density is not :data:`rbe_ros.io.lmgc90.DENSITY` (the example
    script's relative densities times it), by block id (the node key)."""
    return {key: lmgc90.DENSITY * float(rel) for key, rel in (spec.get("density") or {}).items()
            if float(rel) != 1.0}


def lmgc90_samples(python: Path, samples_dir: Path) -> dict:
    """LMGC90's and our verdicts on compas_cra's samples (:data:`LMGC90_SAMPLES`), density
    :data:`rbe_ros.io.lmgc90.DENSITY` (their files give none) times the example script's relative one.
    A sample with a non-convex free block is not comparable: compas_lmgc90 takes one convex
    polyhedron per body, and such a block goes in as its hull (see rbe_ros.io.lmgc90.bodies), which
    overlaps its neighbours where the blocks interlock."""
    out = {}
    for name, spec in LMGC90_SAMPLES.items():
        path = samples_dir / spec["file"]
        if not path.exists():
            out[name] = {"error": f"{path} not found"}
            continue
        supports, mu, densities = spec["supports"], spec["mu"], sample_densities(spec)
        scene = sample_scene(spec, samples_dir)
        ours = check_scene(scene, ours_options("qp", "soc", mu))
        res = lmgc90.check(scene, mu, python)
        word = _word(res)
        if res.get("hulls") and not res.get("failed"):     # its verdict on the hulls, kept apart
            res["on_hulls"], res["stable"], word = word, None, "not comparable"
        out[name] = {"file": path.name, "supports": supports, "mu": mu,
                     "density": lmgc90.DENSITY, "densities": densities,
                     **({"rotation": spec["rotation"]} if spec.get("rotation") else {}),
                     "blocks": len(scene.blocks), "lmgc90": word, "rbe_ros": ours.status.name,
                     "rbe_ros_stable": bool(ours.stable)} | {
                         k: res.get(k) for k in ("stable", "max_disp", "max_rot_deg", "simulated",
                                                 "time", "slabs", "hulls", "on_hulls", "error")}
        print(f"[lmgc90] sample {name}: LMGC90 {word}, rbe_ros {ours.status.name}", flush=True)
    return out


def sample_scene(spec: dict, samples_dir: Path) -> Scene:
    """A compas_cra sample of :data:`LMGC90_SAMPLES` as LMGC90 and we check it: its example
    script's supports and relative densities, turned as its example turns it."""
    from rbe_ros.io.compas import load_compas_assembly
    densities = sample_densities(spec)
    scene = load_compas_assembly(samples_dir / spec["file"], supports=spec["supports"],
                                 density=lmgc90.DENSITY)
    scene = replace(scene, blocks=tuple(replace(b, density=densities.get(b.id, b.density))
                                        for b in scene.blocks))
    if spec.get("rotation"):
        scene = rotated_as_example(scene, spec["rotation"]["axis"], spec["rotation"]["deg"])
    return scene


def lmgc90_squeeze(python: Path) -> list[dict]:
    """LMGC90's and our verdicts on the squeeze suite (:data:`SQUEEZE`, its manifest's mu per
    scene), our check timed in the same run (best of 3); LMGC90's verdict simulating twice as
    long beside it (``lmgc90_2T``: whether a verdict hangs on the duration)."""
    from rbe_ros.io.scene_json import load_scene
    rows = []
    committed = SQUEEZE / "lmgc90_verdicts.json"
    before = json.loads(committed.read_text())["scenes"] if committed.exists() else {}
    for entry in json.loads((SQUEEZE / "manifest.json").read_text())["scenes"]:
        scene = load_scene(SQUEEZE / entry["file"])
        ours, t = best_of(3, lambda: check_scene(scene, ours_options("qp", "soc", entry["mu"])))
        res = lmgc90.check(scene, entry["mu"], python)
        longer = lmgc90.check(scene, entry["mu"], python, T=2 * lmgc90.T)
        rows.append({k: entry[k] for k in ("name", "kind", "mu", "closed_form")} | {
            "lmgc90": _word(res), "lmgc90_2T": _word(longer), "rbe_ros": ours.status.name, "rbe_ros_stable": bool(ours.stable),
            "time_ours": t} | {k: res.get(k) for k in ("stable", "moved", "max_disp", "max_rot_deg",
                                                       "simulated", "time", "time_process",
                                                       "error")})
        # whether LMGC90 decides (benchmarks/lmgc90_sensitivity.py), kept while it still holds
        kept = before.get(entry["name"], {})
        if "decides" in kept and kept["mu"] == entry["mu"] and kept["lmgc90"] == rows[-1]["lmgc90"]:
            rows[-1] |= {k: kept[k] for k in ("sensitivity", "decides")}
        print(f"[lmgc90] squeeze {entry['name']}: closed form {entry['closed_form']}, LMGC90"
              f" {rows[-1]['lmgc90']}, rbe_ros {ours.status.name}", flush=True)
    return rows


def _word(res: dict) -> str:
    return "failed" if res.get("failed") else ("stands" if res["stable"] else "falls")


def cra_samples_dir(cra_venv: Path) -> Path | None:
    """compas_cra's sample folder in its venv (None if that venv is not there)."""
    import compas_compare
    python = compas_compare.venv_python(cra_venv)
    if not python.exists():
        return None
    out = subprocess.run([str(python), "-c", "import compas_cra; print(compas_cra.SAMPLE)"],
                         capture_output=True, text=True, timeout=120)
    return Path(out.stdout.strip()) if out.returncode == 0 else None


class Cra:
    """The compas_cra verdict server (``_bench_cra_driver.py`` in the scratch venv)."""

    def __init__(self, venv: Path, tmp: Path):
        import compas_compare
        python = compas_compare.ensure_venv(venv)
        self.proc = subprocess.Popen([str(python), str(HERE / "_bench_cra_driver.py")],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.DEVNULL, text=True, bufsize=1)
        hello = json.loads(self.proc.stdout.readline())
        self.versions = hello["versions"]
        self.tmp = tmp
        self.count = 0

    def ask(self, **request) -> dict:
        self.proc.stdin.write(json.dumps(request) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError("the compas_cra driver died")
        return json.loads(line)

    def export(self, scene: Scene, interfaces: bool) -> str:
        from rbe_ros.io.compas import save_compas_assembly
        self.count += 1
        path = self.tmp / f"scene{self.count:04d}.json"
        save_compas_assembly(gravity_down(scene), path, interfaces=interfaces)
        return str(path)

    def verdict(self, scene: Scene, mu: float, repeat: int = 1) -> dict:
        """rbe_solve on the interfaces our detection found (written into its JSON)."""
        r = self.ask(file=self.export(scene, True), mu=mu, detect=False, repeat=repeat)
        ok = r.get("status") == "optimal"
        r["stable"] = bool(ok and r["max_tension_rel"] <= CRA_TENSION_TOL)
        r["failed"] = not ok
        return r

    def detect_time(self, scene: Scene, repeat: int = 1) -> dict:
        """compas_cra's own detection (assembly_interfaces_numpy), timed, with no solve."""
        return self.ask(file=self.export(scene, False), detect=True, solve=False, repeat=repeat,
                        **CRA_DETECT)

    def close(self):
        if self.proc.poll() is None:
            self.proc.stdin.close()
            self.proc.wait(timeout=60)


def run_cra(case: Case, cra: Cra, detect_cache: dict | None) -> None:
    """``detect_cache`` None: its own detection is not timed (quick mode)."""
    key = id(case.scene.blocks)
    if detect_cache is None:
        d = {}
    elif key not in detect_cache:
        d = detect_cache[key] = cra.detect_time(case.scene)
    else:
        d = detect_cache[key]
    r = cra.verdict(case.scene, case.mu)
    res = {"time_solve": r.get("time_solve"), "time_detect": d.get("time_detect"),
           "interfaces_own": d.get("interfaces"), "interfaces_ours": r.get("interfaces"),
           "stable": r["stable"], "failed": r["failed"], "max_tension_rel": r.get("max_tension_rel"),
           "status": r.get("status")}
    res["time"] = (res["time_solve"] or 0.0) + (res["time_detect"] or 0.0)
    if case.kind == "tilt":
        start = time.perf_counter()
        res["capacity"], res["trials"] = bisect_tilt(
            lambda a: cra.verdict(tilted(case.scene, a), case.mu)["stable"])
        res["time_bisection"] = time.perf_counter() - start
    case.results["compas_cra"] = res


def score(case: Case) -> None:
    for mid, res in case.results.items():
        if res.get("stable") is None:          # timed only
            continue
        if case.kind == "verdict":
            res["correct"] = bool(res["stable"] == case.exact and not res.get("failed"))
        elif "capacity" in res:
            cap = res["capacity"]
            res["error"] = abs(cap - case.exact) if cap == cap else math.inf
            res["correct"] = res["error"] <= 0.05


# ----------------------------------------------------------------------------- arch bisection

def arch_thickness(args, cra, engines) -> dict:
    """Minimum thickness of the 15-voussoir arch (mu 0.8) by each method's bisection on t/R."""
    n, mu = 15, 0.8
    exact = arch_limit.minimum_thickness(n, mu)
    tol, tol_physics = 1e-6, (4e-3 if args.quick else 1e-3)
    out = {"n": n, "mu": mu, "exact": exact, "tol": tol, "tol_physics": tol_physics, "methods": {}}

    def bisect(stands, lo=0.05, hi=0.25, tol=tol):
        trials = 0
        start = time.perf_counter()
        while hi - lo > tol:
            mid = 0.5 * (lo + hi)
            trials += 1
            lo, hi = (lo, mid) if stands(mid) else (mid, hi)
        return hi, trials, time.perf_counter() - start

    opts = ours_options("qp", "soc", mu)
    t, trials, el = bisect(lambda r: check_scene(gen.semicircular_arch(n, r), opts).stable, tol=1e-7)
    out["methods"][DEFAULT] = {"t_min": t, "trials": trials, "time": el}
    import _cvxpy_rbe as cx
    t, trials, el = bisect(lambda r: cx.check_scene(gen.semicircular_arch(n, r), mu)[0])
    out["methods"]["cvxpy-qp-soc"] = {"t_min": t, "trials": trials, "time": el}
    if cra is not None:
        t, trials, el = bisect(lambda r: cra.verdict(gen.semicircular_arch(n, r), mu)["stable"])
        out["methods"]["compas_cra"] = {"t_min": t, "trials": trials, "time": el}
    for mid in engines:
        engine, hz, it = PHYSICS[mid]
        t, trials, el = bisect(lambda r: physics.check(
            physics.bodies_from_scene(gen.semicircular_arch(n, r)), engine=engine, hz=hz,
            iterations=it, T=PHYS_T, mu=mu, disp_tol=PHYS_DISP, rot_tol_deg=PHYS_ROT)["stable"],
            tol=tol_physics)
        out["methods"][mid] = {"t_min": t, "trials": trials, "time": el}
    for res in out["methods"].values():
        res["rel_error"] = res["t_min"] / exact - 1.0
        res["time_per_check"] = res["time"] / max(1, res["trials"])
    out["by_n"] = {}
    for k in (5, 8, 10, 12, 15, 20, 40, 100, 1000):
        out["by_n"][k] = arch_limit.minimum_thickness(k, mu)
    return out


# ----------------------------------------------------------------------------- scaling

WALLS = [(3, 3), (5, 5), (10, 9), (20, 14), (40, 24)]     # 11, 28, 96, 291, 981 blocks


def physics_time(bodies, mid, full: bool, gravity=(0, 0, -G), mu=0.6) -> dict:
    """Wall time of a 1 s check: simulated in full, or from a short run (set-up + steps,
    extrapolated linearly in the number of steps)."""
    engine, hz, it = PHYSICS[mid]
    kw = dict(engine=engine, hz=hz, iterations=it, mu=mu, gravity=gravity, disp_tol=PHYS_DISP,
              rot_tol_deg=PHYS_ROT)
    steps = int(round(PHYS_T * hz))
    if full:
        r = physics.check(bodies, T=PHYS_T, **kw)
        return {"time": r["time"], "stable": r["stable"], "extrapolated": False}
    short = 24 if hz < 500 else 25
    r1 = physics.check(bodies, T=1.0 / hz, **kw)
    r2 = physics.check(bodies, T=short / hz, **kw)
    per_step = max(0.0, (r2["time"] - r1["time"]) / (short - 1))
    return {"time": r1["time"] + per_step * (steps - 1), "stable": None, "extrapolated": True,
            "steps_run": short}


def scaling(args, cra, engines) -> list[dict]:
    rows = []
    walls = WALLS[:3] if args.quick else WALLS
    configs = [("qp", "soc"), ("lp", "soc"), ("qp", "pyramid8-outer")]
    import _cvxpy_rbe as cx
    for courses, bricks in walls:
        scene = gen.running_bond_wall(courses, bricks)
        n = len(scene.blocks)
        repeat = 3 if n < 150 else 1
        row = {"scene": scene.name, "blocks": n, "methods": {}}
        for obj, cone in configs:
            opts = ours_options(obj, cone, 0.6)
            report, t = best_of(repeat, lambda: check_scene(scene, opts))
            row["methods"][f"ours-{obj}-{cone}"] = {"time": t, "stable": report.stable}
            if (obj, cone) == ("qp", "soc"):
                a, t_det = best_of(repeat, lambda: Assembly.from_scene(scene))
                row["interfaces"] = len(a.interfaces)
                row["time_detect_ours"] = t_det
        (ok, _), t = best_of(repeat, lambda: cx.check_scene(scene, 0.6))
        row["methods"]["cvxpy-qp-soc"] = {"time": t, "stable": ok}
        if cra is not None:
            d = cra.detect_time(scene)
            v = cra.verdict(scene, 0.6)
            row["methods"]["compas_cra"] = {"time": (d.get("time_detect") or 0) + (v.get("time_solve") or 0),
                                            "time_detect": d.get("time_detect"),
                                            "time_solve": v.get("time_solve"),
                                            "interfaces_own": d.get("interfaces"),
                                            "stable": v["stable"]}
        bodies = physics.bodies_from_scene(scene)
        for mid in engines:
            full = n <= (40 if args.quick else 120)
            row["methods"][mid] = physics_time(bodies, mid, full)
        rows.append(row)
        print(f"[scaling] {n} blocks: " + ", ".join(f"{k} {v['time']:.3g}s" for k, v in row["methods"].items()),
              flush=True)
    return rows


# ----------------------------------------------------------------------------- armadillo

def armadillo(cra, engines) -> dict | None:
    """compas_cra's largest sample: rbe_solve on its stored interfaces against our full check."""
    from rbe_ros.io.compas import load_compas_assembly
    if cra is None:
        return None
    path = Path(cra.versions["samples"]) / "armadillo_cra.json"
    out = {"file": path.name, "mu": ARMADILLO_MU}
    r = cra.ask(file=str(path), mu=ARMADILLO_MU, detect=False, repeat=3)
    out["cra"] = r
    scene = load_compas_assembly(path, density=1.0)
    out["blocks"] = len(scene.blocks)
    out["free_blocks"] = sum(not b.support for b in scene.blocks)
    runs = {"ours-qp-soc": SolveOptions(mu=ARMADILLO_MU),
            "ours-cra-settings": SolveOptions(mu=ARMADILLO_MU, friction="plus", cone="pyramid8-outer")}
    for mid, so in runs.items():
        opts = CheckOptions(so, contact=ARMADILLO_CONTACT)
        report, t = best_of(ARMADILLO_REPEAT, lambda: check_scene(scene, opts))
        out[mid] = {"time": t, "status": report.status.name, "interfaces": len(report.interfaces)}
    a, t_det = best_of(ARMADILLO_REPEAT, lambda: Assembly.from_scene(scene, ARMADILLO_CONTACT))
    out["time_detect_ours"] = t_det
    out["interfaces_ours"] = len(a.interfaces)
    model, t_model = best_of(ARMADILLO_REPEAT, lambda: build_model(a.blocks, a.interfaces, a.gravity))
    from rbe_ros.rbe.solver import solve
    sol, t_solve = best_of(ARMADILLO_REPEAT, lambda: solve(model, runs["ours-qp-soc"]))
    out["breakdown"] = {"detect": t_det, "model": t_model, "solve": t_solve, "clarabel": sol.time,
                        "vertices": model.num_vertices, "vertices_cra": r.get("vertices")}
    bodies = physics.bodies_from_scene(scene)
    for mid in engines:
        out[mid] = physics_time(bodies, mid, False, mu=ARMADILLO_MU)
    return out


# ----------------------------------------------------------------------------- main

def warm_up(engines) -> None:
    """One untimed check per method on a small scene, so that first-call costs (imports,
    caches) land in no measurement."""
    import _cvxpy_rbe as cx
    scene = gen.two_blocks(shift=0.3)
    for obj, cone in OURS:
        check_scene(scene, ours_options(obj, cone, 0.6))
    cx.check_scene(scene, 0.6)
    bodies = physics.bodies_from_scene(scene)
    for mid in engines:
        engine, hz, it = PHYSICS[mid]
        physics.check(bodies, engine=engine, hz=hz, iterations=it, T=0.05)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a subset in under 3 minutes")
    parser.add_argument("--out", type=Path, help="docs folder (default docs/, or out/bench-quick with --quick)")
    parser.add_argument("--no-cra", action="store_true", help="leave compas_cra out")
    parser.add_argument("--no-physics", action="store_true", help="leave the physics engines out")
    parser.add_argument("--cra-venv", type=Path, default=Path(os.environ.get("RBE_COMPAS_VENV", ROOT / ".venv-compas")))
    parser.add_argument("--no-lmgc90", action="store_true", help="leave LMGC90 out")
    parser.add_argument("--lmgc90-venv", type=Path, default=None,
                        help=f"LMGC90's scratch venv (default ${lmgc90.VENV_ENV} or .venv-lmgc90)")
    parser.add_argument("--only", choices=["lmgc90", "ours"],
                        help="lmgc90: run LMGC90 (and ours, for the time ratio) alone and merge it"
                        " into the last full run's docs/bench/results.json (make bench-lmgc90);"
                        " ours: re-check our verdicts alone, every other answer and every time"
                        " kept (make bench-verdicts)")
    args = parser.parse_args(argv)
    out = args.out or (ROOT / "out" / "bench-quick" if args.quick else ROOT / "docs")
    if args.only == "lmgc90":
        return only_lmgc90(args, out)
    if args.only == "ours":
        return only_ours(args, out)
    t0 = time.perf_counter()
    load0 = os.getloadavg()[0]

    engines = [] if args.no_physics else [m for m in PHYSICS if physics.available(PHYSICS[m][0])]
    tilt_engines = list(engines)
    tmp = Path(tempfile.mkdtemp(prefix="rbe-bench-"))
    cra = None
    if not args.no_cra:
        try:
            cra = Cra(args.cra_venv, tmp)
        except Exception as exc:                     # no venv, no PyPI: run without it
            print(f"[bench] compas_cra unavailable: {exc}", file=sys.stderr)
    lmgc_py = None
    if not args.no_lmgc90:
        try:
            lmgc_py = lmgc90.ensure_venv(args.lmgc90_venv)
        except Exception as exc:                     # no PyPI, no wheel for this machine
            print(f"[bench] LMGC90 unavailable: {exc}", file=sys.stderr)
    repeat = 1 if args.quick else 3
    try:
        warm_up(engines)
        cases = near_limit_cases(args.quick)
        a_cases, arch_info = arch_cases(args.quick)
        cases += a_cases + paper_cases(args.quick)
        detect_cache: dict | None = None if args.quick else {}
        for case in cases:
            start = time.perf_counter()
            r = repeat if len(case.scene.blocks) <= 100 else 1
            run_ours(case, r)
            run_cvxpy(case, r)
            if cra is not None and case.cra:
                run_cra(case, cra, detect_cache)
            if case.physics and engines:
                run_physics(case, engines, tilt_engines if not args.quick or
                            case.family == "single block" else [])
            if lmgc_py is not None and case.physics:
                run_lmgc90(case, lmgc_py)
            score(case)
            print(f"[case] {case.name}: " + ", ".join(
                f"{k} {'ok' if v.get('correct') else 'WRONG' if 'correct' in v else '-'}"
                for k, v in case.results.items()) + f"  ({time.perf_counter() - start:.1f} s)", flush=True)
        arch = arch_thickness(args, cra, engines if not args.quick else engines[:1])
        arch["info"] = arch_info
        print("[arch] " + ", ".join(f"{k} {v['t_min']:.5f}" for k, v in arch["methods"].items()), flush=True)
        rows = scaling(args, cra, engines)
        arm = None if args.quick else armadillo(cra, engines)
        if arm:
            print(f"[armadillo] ours {arm['ours-qp-soc']['time']:.2f} s, cra solve {arm['cra'].get('time_solve')}",
                  flush=True)
        lmgc = None
        if lmgc_py is not None:
            lmgc = lmgc90_run_info(lmgc_py, args, cases, load0, t0)
    finally:
        if cra is not None:
            cra.close()
    result = {
        "machine": machine_summary(), "quick": args.quick,
        "cra_versions": cra.versions if cra is not None else None,
        "physics_versions": physics_versions(engines),
        "pybullet_parameters": {m: physics.pybullet_parameters(PHYSICS[m][1], PHYSICS[m][2])
                                for m in engines if m.startswith("pybullet")},
        "load_average_1min": [load0, os.getloadavg()[0]],
        "runtime_s": time.perf_counter() - t0,
        "settings": {"physics_T": PHYS_T, "physics_disp": PHYS_DISP, "physics_rot_deg": PHYS_ROT,
                     "cra_tension_tol": CRA_TENSION_TOL, "cra_detect": CRA_DETECT, "tilt_tol": TILT_TOL,
                     "repeat": repeat, "armadillo_repeat": ARMADILLO_REPEAT},
        "cases": [{k: v for k, v in vars(c).items() if k != "scene"} | {"blocks": len(c.scene.blocks)}
                  for c in cases],
        "arch": arch, "scaling": rows, "armadillo": arm, "lmgc90": lmgc,
    }
    import _bench_report
    _bench_report.write(result, out)
    print(f"[bench] wrote {out / 'BENCHMARKS.md'} in {time.perf_counter() - t0:.0f} s")
    return 0


def lmgc90_run_info(python: Path, args, cases: list[Case], load0: float, t0: float) -> dict:
    """LMGC90's part of results.json: settings, versions, its run's load and time, and its
    verdicts on compas_cra's samples (also written to docs/lmgc90_verdicts.json)."""
    samples_dir = cra_samples_dir(args.cra_venv)
    samples = lmgc90_samples(python, samples_dir) if samples_dir else {}
    squeeze = lmgc90_squeeze(python)
    answered = [c.results["lmgc90"] for c in cases if "versions" in c.results.get("lmgc90", {})]
    return {"settings": lmgc90.settings(), "versions": answered[0]["versions"] if answered else {},
            "samples": samples, "squeeze": squeeze, "load_average_1min": [load0, os.getloadavg()[0]],
            "runtime_s": time.perf_counter() - t0, "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}


def only_lmgc90(args, out: Path) -> int:
    """LMGC90 alone on the near-limit suite, ours re-timed beside it (the time ratio comes
    from one run), merged into the last full run's results (``out``/bench/results.json)."""
    import _bench_report
    t0 = time.perf_counter()
    load0 = os.getloadavg()[0]
    stored = ROOT / "docs" / "bench" / "results.json"
    result = json.loads(stored.read_text())
    python = lmgc90.ensure_venv(args.lmgc90_venv)
    cases = near_limit_cases(result["quick"]) + arch_cases(result["quick"])[0] + paper_cases(result["quick"])
    by_name = {c["name"]: c for c in result["cases"]}
    for case in cases:
        record = by_name.get(case.name)
        if record is None or not case.physics:
            continue
        start = time.perf_counter()
        report, t = best_of(1 if len(case.scene.blocks) > 100 else 3,
                            lambda: check_scene(case.scene, ours_options("qp", "soc", case.mu)))
        case.results[DEFAULT] = {"time": t, "stable": bool(report.stable)}
        run_lmgc90(case, python)
        score(case)
        record["results"]["lmgc90"] = case.results["lmgc90"]
        res = case.results["lmgc90"]
        print(f"[case] {case.name}: LMGC90 {_word(res)}"
              f" ({'ok' if res.get('correct') else 'WRONG' if 'correct' in res else 'not scored'})"
              f"  ({time.perf_counter() - start:.1f} s)", flush=True)
    result["lmgc90"] = lmgc90_run_info(python, args, cases, load0, t0) | {"merged": True}
    _bench_report.write(result, out)
    print(f"[bench] wrote {out / 'BENCHMARKS.md'} (LMGC90 merged) in {time.perf_counter() - t0:.0f} s")
    return 0


#: Fields of our results that are times: kept from the run that measured them.
TIMES = ("time", "time_bisection", "time_multiplier", "time_ours")


def only_ours(args, out: Path) -> int:
    """Our verdicts alone, re-checked by this tree on every case of the stored results (each
    configuration, tilt capacities bisected again) and on LMGC90's compas_cra samples and
    squeeze suite; every other method's answer and every time kept as measured (minutes,
    against the hours of make bench and make bench-lmgc90 on a shared machine). What a
    change of the check does to the tables; ``ours_rechecked`` in results.json says when."""
    import _bench_report
    t0, load0 = time.perf_counter(), os.getloadavg()[0]
    stored = ROOT / "docs" / "bench" / "results.json"
    result = json.loads(stored.read_text())
    by_name = {c["name"]: c for c in result["cases"]}
    changed = []
    for case in near_limit_cases(result["quick"]) + arch_cases(result["quick"])[0] \
            + paper_cases(result["quick"]):
        record = by_name.get(case.name)
        if record is None:
            continue
        run_ours(case, 1)
        score(case)
        for mid, new in case.results.items():
            old = record["results"].get(mid, {})
            if old.get("stable") != new["stable"] or old.get("capacity") != new.get("capacity"):
                changed.append(f"{case.name} {mid}: {_said(old)} -> {_said(new)}")
            record["results"][mid] = new | {k: old[k] for k in TIMES if k in old}
        print(f"[ours] {case.name}: {_said(case.results[DEFAULT])}", flush=True)
    info = result.get("lmgc90") or {}
    samples_dir = cra_samples_dir(args.cra_venv)
    for name, row in (info.get("samples") or {}).items():
        if samples_dir is None or "error" in row and "lmgc90" not in row:
            continue
        spec = LMGC90_SAMPLES[name]
        ours = check_scene(sample_scene(spec, samples_dir), ours_options("qp", "soc", spec["mu"]))
        if row["rbe_ros"] != ours.status.name:
            changed.append(f"sample {name}: {row['rbe_ros']} -> {ours.status.name}")
        row.update(rbe_ros=ours.status.name, rbe_ros_stable=bool(ours.stable))
        print(f"[ours] sample {name}: {ours.status.name}", flush=True)
    from rbe_ros.io.scene_json import load_scene
    files = {e["name"]: e["file"] for e in json.loads((SQUEEZE / "manifest.json").read_text())["scenes"]}
    for row in info.get("squeeze") or []:
        ours = check_scene(load_scene(SQUEEZE / files[row["name"]]),
                           ours_options("qp", "soc", row["mu"]))
        if row["rbe_ros"] != ours.status.name:
            changed.append(f"squeeze {row['name']}: {row['rbe_ros']} -> {ours.status.name}")
        row.update(rbe_ros=ours.status.name, rbe_ros_stable=bool(ours.stable))
        print(f"[ours] squeeze {row['name']}: {ours.status.name}", flush=True)
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True).stdout.strip()
    result["ours_rechecked"] = {
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "commit": commit,
        "load_average_1min": [load0, os.getloadavg()[0]],
        "runtime_s": time.perf_counter() - t0, "changed": changed}
    _bench_report.write(result, out)
    print("[bench] verdicts changed:\n  " + "\n  ".join(changed or ["none"]))
    print(f"[bench] wrote {out / 'BENCHMARKS.md'} (our verdicts re-checked) in"
          f" {time.perf_counter() - t0:.0f} s")
    return 0


def _said(res: dict) -> str:
    """A method's answer on a case in words: its tilt capacity, failed, stands or falls."""
    if "capacity" in res:
        return f"{res['capacity']:.2f} deg"
    return "failed" if res.get("failed") else "stands" if res.get("stable") else "falls"


def physics_versions(engines) -> dict:
    from importlib import metadata
    out = {}
    for name in ("pybullet", "mujoco"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    return out


if __name__ == "__main__":
    sys.exit(main())
