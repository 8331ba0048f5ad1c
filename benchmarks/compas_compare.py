"""Our RBE solve against the authors' own, compas_cra 0.8.0 ``rbe_solve``, on its samples.

    python3 benchmarks/compas_compare.py [--venv /tmp/rbe-compas-venv] [--samples cubes,shelf]

Any python will do. The script (a) makes a scratch venv with ``compas-cra==0.8.0`` (once;
compas-cra is no dependency of this project and never enters its venv), (b) runs
``_compas_driver.py`` in it: compas_cra loads each sample as its example script does, detects
the interfaces and solves, (c) in the project's interpreter (``.venv/bin/python`` unless this
one can import rbe_ros) builds our model on the very same interface polygons, with the
settings compas_cra uses (friction+, circumscribed 8-sided pyramid in the interface frame,
weights 1 / 1e6 / 1), and again from the blocks alone with our own contact detection, and
compares the normal resultant of every interface, (d) writes docs/COMPAS.md and
docs/compas_compare.json.

The comparison functions are importable (tests/test_compas_cra.py uses them); this module
needs only the standard library until a comparison runs.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DRIVER = HERE / "_compas_driver.py"
DOCS = ROOT / "docs"
PROJECT_PYTHON = ROOT / ".venv" / "bin" / "python"
DEFAULT_VENV = Path("/tmp/rbe-compas-venv")
CRA_VERSION = "0.8.0"
CRA_REQUIREMENT = f"compas-cra=={CRA_VERSION}"
VENV_ENV = "RBE_COMPAS_VENV"
#: Acceptance: normal resultants within this share of the largest one.
TOLERANCE = 0.01

#: The samples, set up as compas_cra's example scripts set them up (supports, interface
#: detection tolerances, densities, mu). ``contact`` is our own detection's tolerances
#: (relative to the block size) where the defaults do not fit the sample.
SAMPLES = {
    "cubes": dict(file="cubes.json", supports=[0], mu=0.84, nmax=10, amin=1e-2, tmax=1e-2,
                  example="examples/02_cubes.py (mu: rbe_solve's default)"),
    "shelf": dict(file="shelf.json", supports=[0], mu=0.9, nmax=10, amin=1e-6, tmax=1e-4,
                  example="examples/07_shelf.py"),
    "snake": dict(file="snake.json", supports=[0], mu=0.7, nmax=10, amin=1e-4, tmax=1e-2,
                  example="examples/08_snake.py"),
    "bridge": dict(file="bridge.json", supports=[0, 1], mu=0.9, nmax=10, amin=1e-6, tmax=1e-4,
                   density={str(k): 3.51 for k in range(11, 16)}, example="examples/09_bridge.py"),
    "armadillo": dict(file="armadillo_cra.json", supports=None, mu=0.84, detect=False,
                      contact=dict(distance_tol=0.05, angle_tol_deg=5.0),
                      example="examples/10_armadillo.py (stored interfaces and supports;"
                              " it shows a stored CRA result, so mu is rbe_solve's default)"),
}
DEFAULT_SAMPLES = ("cubes", "shelf", "snake", "bridge", "armadillo")
#: The test's choice: small and quick (snake's detection alone takes compas_cra ~15 s).
TEST_SAMPLES = ("cubes", "shelf", "bridge")


# ----------------------------------------------------------------------------- compas_cra side

def venv_python(venv) -> Path:
    return Path(venv) / "bin" / "python"


def has_cra(python) -> bool:
    """Whether ``python`` imports compas_cra of the pinned version."""
    code = f"import sys, compas_cra; sys.exit(compas_cra.__version__ != {CRA_VERSION!r})"
    try:
        return subprocess.run([str(python), "-c", code], capture_output=True, timeout=120).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


def ensure_venv(venv=DEFAULT_VENV, base_python=None) -> Path:
    """The python of a venv with compas-cra, made (and filled) if it is not there yet."""
    python = venv_python(venv)
    if python.exists() and has_cra(python):
        return python
    if not python.exists():
        print(f"[venv] creating {venv}", file=sys.stderr, flush=True)
        subprocess.run([base_python or sys.executable, "-m", "venv", str(venv)], check=True)
    print(f"[venv] pip install {CRA_REQUIREMENT} into {venv}", file=sys.stderr, flush=True)
    subprocess.run([str(python), "-m", "pip", "install", "--quiet", CRA_REQUIREMENT], check=True)
    if not has_cra(python):
        raise RuntimeError(f"{python} still cannot import compas_cra {CRA_VERSION}")
    return python


def cra_python_from_env() -> Path | None:
    """A python with compas_cra: that of $RBE_COMPAS_VENV, else this one if it has it."""
    env = os.environ.get(VENV_ENV)
    if env:
        python = venv_python(env)
        return python if python.exists() and has_cra(python) else None
    try:
        found = importlib.util.find_spec("compas_cra") is not None
    except (ImportError, ValueError):
        found = False
    return Path(sys.executable) if found else None


def run_driver(python, names, out=None, repeat: int = 1, timeout: float = 1800) -> dict:
    """compas_cra's results for the samples ``names`` (run by ``python``), as a dict."""
    with tempfile.TemporaryDirectory(prefix="rbe-compas-") as tmp:
        spec = Path(tmp) / "spec.json"
        spec.write_text(json.dumps({"repeat": repeat,
                                    "samples": [{"name": n, **SAMPLES[n]} for n in names]}))
        out = Path(out) if out else Path(tmp) / "cra.json"
        subprocess.run([str(python), str(DRIVER), "--spec", str(spec), "--out", str(out)],
                       check=True, timeout=timeout)
        return json.loads(out.read_text())


# ----------------------------------------------------------------------------- our side

def solve_options(mu: float):
    """compas_cra's rbe_solve settings in our terms."""
    from rbe_ros.rbe.solver import SolveOptions, Weights
    return SolveOptions(objective="qp", friction="plus", cone="pyramid8-outer", mu=mu,
                        weights=Weights(1.0, 1e6, 1.0))


def our_scene(record: dict):
    """The sample as our scene: same file, supports and per-node densities; and the map
    node key -> block index."""
    from dataclasses import replace

    from rbe_ros.compas_io import load_compas_assembly

    supports = record.get("supports")
    scene = load_compas_assembly(record["path"], supports=supports, density=1.0)
    keys = sorted((n["key"] for n in record["nodes"]), key=int)   # load_compas_assembly's order
    index = {k: i for i, k in enumerate(keys)}
    density = {n["key"]: n["density"] for n in record["nodes"]}
    blocks = list(scene.blocks)
    for key, i in index.items():
        blocks[i] = replace(blocks[i], density=density[key], mass=0.0)
    if supports is None:    # compas_cra's flags, as it read them
        for n in record["nodes"]:
            blocks[index[n["key"]]] = replace(blocks[index[n["key"]]], support=n["support"])
    return replace(scene, blocks=tuple(blocks)), index


def cra_interfaces(record: dict, index: dict):
    """compas_cra's interfaces as ours: same points, frame u = its xaxis, n = its zaxis (from
    block a into b, the side its forces push). Points are put counter-clockwise about n; the
    permutations give compas' order back."""
    import numpy as np

    from rbe_ros.geometry.contacts import Interface
    from rbe_ros.geometry.polygon import PlaneFrame

    out, orders = [], []
    for it in record["interfaces"]:
        f = it["frame"]
        frame = PlaneFrame(*(np.asarray(f[k], dtype=float) for k in ("point", "xaxis", "yaxis", "zaxis")))
        pts = np.asarray(it["points"], dtype=float)
        xy = frame.to_2d(pts)
        signed = 0.5 * np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1])
        order = np.arange(len(pts)) if signed >= 0 else np.arange(len(pts))[::-1]
        out.append(Interface(index[it["a"]], index[it["b"]], frame, pts[order], float(it["size"])))
        orders.append(order)
    return out, orders


def _cra_forces(record: dict, key: str = "forces"):
    """(4, nv) compas_cra forces [fn+, fn-, fu, fv] in its vertex order."""
    import numpy as np
    return np.concatenate([np.asarray(it[key], dtype=float) for it in record["interfaces"]]).T


def _per_interface(values, counts):
    import numpy as np
    return np.add.reduceat(values, np.cumsum([0] + counts[:-1])) if counts else np.zeros(0)


def _best_of(repeat: int, fn):
    best, value = math.inf, None
    for _ in range(max(1, repeat)):
        start = time.perf_counter()
        value = fn()
        best = min(best, time.perf_counter() - start)
    return value, best


def compare_sample(record: dict, repeat: int = 3) -> dict:
    """Ours against compas_cra on one sample (``record``: the driver's output for it)."""
    import numpy as np

    from rbe_ros.analysis.check import CheckOptions, check_scene
    from rbe_ros.geometry.block import pose_block
    from rbe_ros.geometry.contacts import ContactOptions
    from rbe_ros.rbe.model import build_model
    from rbe_ros.rbe.solver import solve

    name = record["name"]
    scene, index = our_scene(record)
    options = solve_options(record["mu"])
    g = float(np.linalg.norm(scene.gravity))
    blocks = tuple(pose_block(b) for b in scene.blocks)

    # the blocks as compas_cra sees them
    nodes = record["nodes"]
    vol = np.array([blocks[index[n["key"]]].volume for n in nodes])
    cen = np.array([blocks[index[n["key"]]].centroid for n in nodes])
    size = max(b.size for b in blocks)
    volume_err = float(np.max(np.abs(vol / [n["volume"] for n in nodes] - 1)))
    centroid_err = float(np.max(np.linalg.norm(cen - [n["center"] for n in nodes], axis=1)) / size)

    # 1. the same interface polygons, frames and vertex order
    interfaces, orders = cra_interfaces(record, index)
    counts = [len(it.points) for it in interfaces]
    starts = np.cumsum([0] + counts[:-1])
    to_cra = np.concatenate([s + o for s, o in zip(starts, orders)]) if counts else np.zeros(0, int)

    def model_and_solve():
        model = build_model(blocks, interfaces, scene.gravity)
        return model, solve(model, options)

    (model, solution), t_solve = _best_of(repeat, model_and_solve)
    if not solution.solved:
        raise RuntimeError(f"{name}: our solve on compas_cra's interfaces: {solution.solver_status}")
    ours = np.empty_like(solution.forces)
    ours[:, to_cra] = solution.forces / g                       # compas' order and units
    cra, cra_fixed = _cra_forces(record), _cra_forces(record, "forces_fixed_weights")
    fn_ours, fn_cra, fn_fixed = (f[0] - f[1] for f in (ours, cra, cra_fixed))
    n_ours, n_cra, n_fixed = (_per_interface(f, counts) for f in (fn_ours, fn_cra, fn_fixed))
    scale_n, scale_fn = float(np.abs(n_cra).max()), float(np.abs(fn_cra).max())

    # compas_cra's forces in our equilibrium equations (same problem?) and both objectives
    x_cra = cra[:, to_cra]                                      # our vertex order
    residual = model.a_eq @ (x_cra * g / model.force_scale).ravel() + model.dead_load
    w_full = np.array([1.0, 1e6, 1.0, 1.0])[:, None] * np.ones_like(cra)
    w_quirk = w_full.copy()
    w_quirk[3] = np.asarray(record["fv_weighted"], dtype=float)
    objective = {f"{wn}({fname})": float(np.sum(w * f ** 2))
                 for wn, w in (("full", w_full), ("quirk", w_quirk))
                 for fname, f in (("ours", ours), ("cra", cra), ("cra_fixed", cra_fixed))}

    # 2. from the blocks alone: our own contact detection, the full check
    contact = ContactOptions(**record.get("contact", {}))
    report, t_full = _best_of(repeat, lambda: check_scene(scene, CheckOptions(options, contact=contact)))
    own = _match_own(record, interfaces, index, scene, report, g)

    detect = record.get("time_detect")
    cra_total = None if detect is None else detect + record["time_solve"]
    return {
        "sample": name, "file": record["file"], "example": record.get("example", ""),
        "mu": record["mu"], "supports": record.get("supports"),
        "blocks": len(blocks), "free_blocks": int(sum(not b.support for b in blocks)),
        "interfaces": len(interfaces), "vertices": int(sum(counts)),
        "cra_status": record["status"],
        "agreement": float(np.abs(n_ours - n_cra).max() / scale_n),
        "agreement_fixed_weights": float(np.abs(n_ours - n_fixed).max() / float(np.abs(n_fixed).max())),
        "cra_quirk_vs_fixed": float(np.abs(n_cra - n_fixed).max() / scale_n),
        "vertex_agreement": float(np.abs(fn_ours - fn_cra).max() / scale_fn),
        "vertex_agreement_fixed_weights": float(np.abs(fn_ours - fn_fixed).max() / float(np.abs(fn_fixed).max())),
        "max_normal_resultant": scale_n,
        "cra_residual_in_our_model": float(np.abs(residual).max()),
        "our_residual": float(solution.residual),
        "objectives": objective,
        "volume_rel_err": volume_err, "centroid_err_rel_size": centroid_err,
        "own_detection": own,
        "time_cra_detect": detect, "time_cra_solve": record["time_solve"], "time_cra_total": cra_total,
        "time_ours_full": t_full, "time_ours_solve": t_solve, "time_ours_clarabel": solution.time,
        "speed_ratio_full": None if cra_total is None else cra_total / t_full,
        "speed_ratio_solve": record["time_solve"] / t_solve,
        "normal_resultants": {"cra": n_cra.tolist(), "cra_fixed_weights": n_fixed.tolist(),
                              "ours": n_ours.tolist(),
                              "pairs": [[it["a"], it["b"]] for it in record["interfaces"]]},
    }


def _match_own(record, interfaces, index, scene, report, g) -> dict:
    """Our own detection's interfaces matched to compas_cra's: same node pair, parallel
    normals, nearest centroid. Normal resultants (compression positive, so the orientation
    of either does not matter) compared per matched interface and per node pair."""
    import numpy as np

    key_of = {i: k for k, i in index.items()}
    id_to_key = {b.id: key_of[i] for i, b in enumerate(scene.blocks)}
    n_cra = _per_interface(_cra_forces(record)[0] - _cra_forces(record)[1],
                           [len(it["points"]) for it in record["interfaces"]])
    ours = [(frozenset((id_to_key[r.block_a], id_to_key[r.block_b])), r) for r in report.interfaces]
    used, matched, same_points, diffs = set(), 0, 0, []
    for i, (it, n) in enumerate(zip(interfaces, n_cra)):
        pair = frozenset((record["interfaces"][i]["a"], record["interfaces"][i]["b"]))
        centre = it.points.mean(axis=0)
        reach = math.sqrt(max(it.area, 1e-300))
        best = None
        for j, (p, r) in enumerate(ours):
            if j in used or p != pair or abs(float(r.normal @ it.frame.n)) < math.cos(math.radians(5)):
                continue
            d = float(np.linalg.norm(r.polygon.mean(axis=0) - centre))
            if d < 0.25 * reach and (best is None or d < best[0]):
                best = (d, j)
        if best is None:
            continue
        j = best[1]
        used.add(j)
        matched += 1
        r = ours[j][1]
        diffs.append(abs(r.normal_resultant / g - n))
        tol = 1e-6 * reach
        same_points += (len(r.polygon) == len(it.points) and all(
            np.min(np.linalg.norm(it.points - p, axis=1)) < tol for p in r.polygon))
    pair_cra: dict = {}
    for it, n in zip(record["interfaces"], n_cra):
        key = frozenset((it["a"], it["b"]))
        pair_cra[key] = pair_cra.get(key, 0.0) + n
    pair_ours: dict = {}
    for p, r in ours:
        pair_ours[p] = pair_ours.get(p, 0.0) + r.normal_resultant / g
    scale = max(abs(v) for v in pair_cra.values())
    pair_err = max(abs(pair_ours.get(k, 0.0) - pair_cra.get(k, 0.0)) for k in set(pair_cra) | set(pair_ours))
    complete = matched == len(interfaces) == len(ours)
    return {"status": report.status.name, "interfaces": len(ours), "matched": matched,
            "cra_only": len(interfaces) - matched, "ours_only": len(ours) - matched,
            "same_vertex_sets": int(same_points),
            "pairs_cra": len(pair_cra), "pairs_ours": len(pair_ours),
            "agreement_pairs": float(pair_err / scale),
            "agreement": float(max(diffs) / float(np.abs(n_cra).max())) if complete else None}


# ----------------------------------------------------------------------------- report

def _fmt_pct(x) -> str:
    return "n/a" if x is None else f"{100 * x:.2g} %" if x >= 1e-4 else f"{100 * x:.1e} %"


def _fmt_t(x) -> str:
    return "n/a" if x is None else f"{x:.3f} s" if x < 10 else f"{x:.1f} s"


def _fmt_r(x) -> str:
    return "n/a" if x is None else f"{x:.1f}x"


def write_docs(results: list[dict], versions: dict, repeat: int, docs: Path = DOCS) -> None:
    sys.path.insert(0, str(HERE))
    from machine import machine_summary

    machine = machine_summary()
    docs.mkdir(parents=True, exist_ok=True)
    (docs / "compas_compare.json").write_text(json.dumps(
        {"machine": machine, "cra_versions": versions, "repeat": repeat, "tolerance": TOLERANCE,
         "samples": results}, indent=1) + "\n")
    ok = [r for r in results if r["agreement"] <= TOLERANCE]
    lines = [
        "# Against compas_cra 0.8.0 `rbe_solve`",
        "",
        "Generated by `benchmarks/compas_compare.py` (numbers: `docs/compas_compare.json`). Each",
        "sample is set up as compas_cra's example script sets it up (supports, detection tolerances,",
        "densities, mu); compas_cra detects its interfaces and solves; we solve the same problem",
        "(friction+, circumscribed 8-sided pyramid in the interface frame, weights 1 / 1e6 / 1) on",
        "its very interface polygons (frame u = its xaxis, n = its zaxis), and once more from the",
        "blocks alone with our own contact detection.",
        "",
        f"**Acceptance** (normal resultants within {TOLERANCE:.0%} of the largest, on at least three",
        f"samples): {'met' if len(ok) >= 3 else 'NOT met'} on {len(ok)} of {len(results)}"
        f" ({', '.join(r['sample'] for r in ok) or 'none'}).",
        "",
        "| sample | blocks (free) | interfaces (vertices) | agreement | agreement, cra weights fixed"
        " | own detection: interfaces, agreement | time cra | time ours | speed ratio |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        own = r["own_detection"]
        own_txt = (f"{own['interfaces']} ({own['matched']} matched, {own['ours_only']} extra,"
                   f" {own['cra_only']} missing), {_fmt_pct(own['agreement'] if own['agreement'] is not None else own['agreement_pairs'])}"
                   + ("" if own["agreement"] is not None else " per block pair"))
        lines.append(
            f"| {r['sample']} | {r['blocks']} ({r['free_blocks']}) | {r['interfaces']} ({r['vertices']})"
            f" | {_fmt_pct(r['agreement'])} | {_fmt_pct(r['agreement_fixed_weights'])} | {own_txt}"
            f" | {_fmt_t(r['time_cra_total'])} | {_fmt_t(r['time_ours_full'])}"
            f" | {_fmt_r(r['speed_ratio_full'])} |")
    lines += [
        "",
        "Agreement: max over interfaces |N_ours - N_cra| / max |N_cra|, N the normal resultant",
        "(sum of fn+ - fn- over the interface's vertices, in compas_cra's units: volume x density).",
        "\"cra weights fixed\": the same against compas_cra re-run with every fv weighted (see below).",
        "Times: compas_cra = `assembly_interfaces_numpy` + `rbe_solve` (its problem set-up and IPOPT);",
        "ours = `check_scene` (contact detection, model, Clarabel, resultants). Speed ratio = time",
        f"cra / time ours, both best of {repeat} in the same run.",
        "",
        "Solve alone (from the interfaces: compas_cra `rbe_solve`; ours `build_model` + `solve` on the",
        "same polygons, and the Clarabel call inside it):",
        "",
        "| sample | cra rbe_solve | ours model + solve | ours Clarabel | ratio |",
        "|---|---|---|---|---|",
    ]
    for r in results:
        lines.append(f"| {r['sample']} | {_fmt_t(r['time_cra_solve'])} | {_fmt_t(r['time_ours_solve'])}"
                     f" | {_fmt_t(r['time_ours_clarabel'])} | {_fmt_r(r['speed_ratio_solve'])} |")
    lines += ["", "Checks that the two solve the same problem:", "",
              "| sample | cra forces in our equilibrium (residual / weight) | volumes | centroids"
              " | objective sum w f^2, all fv weighted: ours / cra | with cra's weights: ours / cra |",
              "|---|---|---|---|---|---|"]
    for r in results:
        o = r["objectives"]
        lines.append(f"| {r['sample']} | {r['cra_residual_in_our_model']:.1e} | {r['volume_rel_err']:.1e}"
                     f" | {r['centroid_err_rel_size']:.1e} | {o['full(ours)']:.6g} / {o['full(cra)']:.6g}"
                     f" | {o['quirk(ours)']:.6g} / {o['quirk(cra)']:.6g} |")
    lines += ["", *_findings(results), "",
              "## Samples and their settings", ""]
    for r in results:
        spec = SAMPLES[r["sample"]]
        extra = "".join(f", {k} {spec[k]}" for k in ("amin", "tmax") if k in spec)
        dens = ", density 3.51 on nodes 11-15 (1 elsewhere)" if spec.get("density") else ""
        sup = "the file's is_support flags" if r["supports"] is None else f"nodes {r['supports']}"
        lines.append(f"- {r['sample']} (`{r['file']}`, {spec['example']}): supports {sup},"
                     f" mu {r['mu']}{extra}{dens}.")
    v = ", ".join(f"{k} {val}" for k, val in versions.items())
    lines += ["", "## Machine", "", f"- ours: {machine}", f"- compas_cra venv: {v}", ""]
    (docs / "COMPAS.md").write_text("\n".join(lines))


def _findings(results: list[dict]) -> list[str]:
    out = ["## What the numbers say", ""]
    for r in results:
        q = r["cra_quirk_vs_fixed"]
        own = r["own_detection"]
        bits = [f"agreement {_fmt_pct(r['agreement'])}"]
        if q > TOLERANCE / 10:
            bits.append(f"compas_cra's own answer moves by {_fmt_pct(q)} when its fv weights are fixed,"
                        f" and ours agrees with the fixed one to {_fmt_pct(r['agreement_fixed_weights'])}")
        if own["ours_only"] or own["cra_only"] or own["same_vertex_sets"] < own["matched"]:
            bits.append(f"our detection: {own['interfaces']} interfaces against {r['interfaces']},"
                        f" {own['same_vertex_sets']} of {own['matched']} matched ones with the same"
                        f" vertices")
        out.append(f"- {r['sample']}: " + "; ".join(bits) + ".")
    out += [
        "",
        "compas_cra weights its fv components by an index rule that skips two vertices in three",
        "(`_tilde_weights`: fv of vertex k counts only when k is a multiple of 3). On those vertices fv",
        "is free of cost, so its QP is a different one from ours wherever tangential forces carry load",
        "(inclined joints, the bridge's voussoirs); the fn it returns are still unique, but they are",
        "the minimisers of its objective, not ours. The objectives above show each solver finds the",
        "lower value of its own objective. On flat horizontal joints under gravity nothing needs",
        "friction and the quirk changes nothing.",
    ]
    return out


# ----------------------------------------------------------------------------- main

def _can_compare() -> bool:
    try:
        import clarabel  # noqa: F401
        import numpy  # noqa: F401
        import rbe_ros  # noqa: F401
    except ImportError:
        return False
    return True


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Compare our RBE solve with compas_cra's rbe_solve.")
    parser.add_argument("--venv", type=Path, default=DEFAULT_VENV,
                        help=f"scratch venv for compas-cra (default {DEFAULT_VENV})")
    parser.add_argument("--base-python", help="python that creates the venv (default: this one)")
    parser.add_argument("--samples", default=",".join(DEFAULT_SAMPLES),
                        help=f"comma-separated, of {', '.join(SAMPLES)}")
    parser.add_argument("--repeat", type=int, default=3, help="timings: best of this many runs")
    parser.add_argument("--cra-json", type=Path, help="use this driver output instead of running it")
    parser.add_argument("--docs", type=Path, default=DOCS, help="where COMPAS.md and the JSON go")
    args = parser.parse_args(argv)
    names = [n.strip() for n in args.samples.split(",") if n.strip()]
    unknown = [n for n in names if n not in SAMPLES]
    if unknown:
        parser.error(f"unknown samples {unknown}; known: {', '.join(SAMPLES)}")

    if args.cra_json is None:
        python = ensure_venv(args.venv, args.base_python)
        args.cra_json = Path(tempfile.mkstemp(prefix="rbe-compas-cra-", suffix=".json")[1])
        run_driver(python, names, args.cra_json, args.repeat)
    if not _can_compare():
        if not PROJECT_PYTHON.exists():
            print(f"cannot import rbe_ros here and {PROJECT_PYTHON} is missing", file=sys.stderr)
            return 2
        forward = [str(PROJECT_PYTHON), str(Path(__file__).resolve()), "--samples", ",".join(names),
                   "--repeat", str(args.repeat), "--cra-json", str(args.cra_json), "--docs", str(args.docs)]
        return subprocess.run(forward).returncode
    sys.path.insert(0, str(ROOT))

    cra = json.loads(args.cra_json.read_text())
    results = []
    for name in names:
        r = compare_sample(cra["samples"][name], args.repeat)
        results.append(r)
        own = r["own_detection"]
        print(f"{name:10s} {r['blocks']:4d} blocks {r['interfaces']:5d} interfaces"
              f"  agreement {r['agreement']:.2e} (cra weights fixed {r['agreement_fixed_weights']:.2e})"
              f"  own detection {own['interfaces']} ifs, {own['agreement'] if own['agreement'] is not None else own['agreement_pairs']:.2e}"
              f"  cra {_fmt_t(r['time_cra_total'])} ours {_fmt_t(r['time_ours_full'])}"
              f"  solve cra {_fmt_t(r['time_cra_solve'])} ours {_fmt_t(r['time_ours_solve'])}", flush=True)
    write_docs(results, cra["versions"], args.repeat, args.docs)
    print(f"wrote {args.docs / 'COMPAS.md'} and {args.docs / 'compas_compare.json'}")
    ok = sum(r["agreement"] <= TOLERANCE for r in results)
    return 0 if ok >= min(3, len(results)) else 1


if __name__ == "__main__":
    sys.exit(main())
