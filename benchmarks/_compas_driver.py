"""compas_cra's side of benchmarks/compas_compare.py: run its ``rbe_solve`` on its samples.

Runs inside a venv that has compas-cra (never the project's; no rbe_ros here):

    <venv>/bin/python benchmarks/_compas_driver.py --spec spec.json --out cra.json

``spec.json`` holds ``{"repeat": n, "samples": [{"name", "file", "supports", "mu", "nmax",
"amin", "tmax", "density": {node: value}, "detect": true, "variants": true}, ...]}`` (the
settings of compas_cra's example scripts; ``supports`` null keeps the file's flags, ``detect``
false its stored interfaces, ``variants`` false skips the diagnostic re-solves).

For every sample it loads the assembly as the examples do (``compas.json_load``,
``copy(cls=CRA_Assembly)``, ``set_boundary_conditions``, ``density_setup``), detects the
interfaces with ``assembly_interfaces_numpy``, solves with ``rbe_solve(mu, density=1)`` and
writes, per interface in compas_cra's own order (edges, then interfaces of an edge): the two
node keys, the points, the frame and the per-point forces ``c_np, c_nn, c_u, c_v``; per node
the density, volume and centre it used; and the wall times of detection and solve (best of
``repeat``). To tell its quirks apart from anything else it then solves the same interfaces
again (untimed) with the objective weights corrected (every fv weighted, see
``_tilde_weights``), with strict IPOPT tolerances, and with both (``forces_<variant>``).
"""
from __future__ import annotations

import argparse
import contextlib
import gzip
import io
import json
import os
import platform
import sys
import time
from importlib import metadata


def _load(spec: dict):
    import compas
    import compas_cra
    from compas_cra.datastructures import CRA_Assembly
    from compas_cra.equilibrium import density_setup

    path = os.path.join(compas_cra.SAMPLE, spec["file"])    # an absolute file stays as it is
    if path.endswith(".gz"):
        with gzip.open(path, "rt") as f:
            assembly = compas.json_loads(f.read())
    else:
        assembly = compas.json_load(path)
    assembly = assembly.copy(cls=CRA_Assembly)
    if spec.get("supports") is not None:        # else the file's own is_support flags
        assembly.set_boundary_conditions(spec["supports"])
    density = {int(k): float(v) for k, v in (spec.get("density") or {}).items()}
    if density:
        density_setup(assembly, density)
    return path, assembly


def _detect(assembly, spec: dict) -> float | None:
    """Interface detection as the example does it (None: the file's stored interfaces)."""
    from compas_cra.algorithms import assembly_interfaces_numpy

    if not spec.get("detect", True):
        return None
    start = time.perf_counter()
    assembly_interfaces_numpy(assembly, nmax=spec.get("nmax", 10), amin=spec["amin"], tmax=spec["tmax"])
    return time.perf_counter() - start


#: IPOPT options of the "strict" re-solves: no bound relaxation (IPOPT's default relaxes every
#: bound by 1e-8 absolute, which is not small next to forces of order volume x density 1)
#: and a tight tolerance.
STRICT = {"tol": 1e-10, "bound_relax_factor": 0.0}

#: The variants solved after the timed one: (label, every fv weighted, strict IPOPT options).
VARIANTS = (("fixed_weights", True, False), ("strict", False, True), ("fixed_weights_strict", True, True))


def _solve(assembly, mu: float, fixed_weights: bool = False, strict: bool = False) -> tuple[float, str]:
    """rbe_solve, its chatter on stdout swallowed. ``fixed_weights``: every fv weighted (not
    two vertices in three, as ``_tilde_weights`` does); ``strict``: IPOPT options STRICT."""
    import numpy as np
    from compas_cra.equilibrium import cra_native, cra_nlp, rbe_solve

    tilde_weights, solve_nlp = cra_nlp._tilde_weights, cra_native.solve_nlp

    def full(v_count, w_comp, w_tens, w_fric):
        return np.tile([w_comp, w_tens, w_fric, w_fric], v_count).astype(float)

    def strict_nlp(problem, backend=None, options=None, verbose=False):
        return solve_nlp(problem, backend=backend, options={**(options or {}), **STRICT}, verbose=verbose)

    chatter = io.StringIO()
    if fixed_weights:
        cra_nlp._tilde_weights = full
    if strict:
        cra_native.solve_nlp = strict_nlp
    try:
        with contextlib.redirect_stdout(chatter):
            start = time.perf_counter()
            rbe_solve(assembly, mu=mu, density=1.0)
            elapsed = time.perf_counter() - start
    finally:
        cra_nlp._tilde_weights, cra_native.solve_nlp = tilde_weights, solve_nlp
    status = [line for line in chatter.getvalue().splitlines() if line.startswith("result:")]
    return elapsed, (status[-1].split(":", 1)[1].strip() if status else "?")


def _interfaces(assembly) -> list[dict]:
    out = []
    for u, v in assembly.graph.edges():
        for it in assembly.graph.edge_attribute((u, v), "interfaces"):
            frame = it.frame
            out.append({
                "a": str(u), "b": str(v),
                "points": [[float(c) for c in p[:3]] for p in it.points],
                "size": float(it.size),
                "frame": {"point": list(map(float, frame.point)), "xaxis": list(map(float, frame.xaxis)),
                          "yaxis": list(map(float, frame.yaxis)), "zaxis": list(map(float, frame.zaxis))},
                "forces": [[f["c_np"], f["c_nn"], f["c_u"], f["c_v"]] for f in it.forces],
            })
    return out


def run_sample(spec: dict, repeat: int) -> dict:
    from compas_cra.equilibrium import cra_nlp, num_vertices

    detect_times, solve_times = [], []
    for _ in range(max(1, repeat)):
        path, assembly = _load(spec)
        detect_times.append(_detect(assembly, spec))
        elapsed, status = _solve(assembly, spec["mu"])
        solve_times.append(elapsed)
    interfaces = _interfaces(assembly)
    nv = num_vertices(assembly)
    fv_weighted = [bool(w) for w in cra_nlp._tilde_weights(nv, 1.0, 1e6, 1.0)[3::4]]

    statuses = {"": status}
    for label, fixed, strict in VARIANTS if spec.get("variants", True) else ():   # same interfaces
        try:
            _, statuses[label] = _solve(assembly, spec["mu"], fixed_weights=fixed, strict=strict)
        except ValueError as exc:                   # rbe_solve raises when IPOPT fails
            statuses[label] = f"failed: {exc}"
            for rec in interfaces:
                rec["forces_" + label] = None
            continue
        for rec, it in zip(interfaces, _interfaces(assembly)):
            rec["forces_" + label] = it["forces"]

    nodes = []
    for key in assembly.graph.nodes():      # the order of compas_cra's equilibrium rows
        block = assembly.node_block(key)
        nodes.append({"key": str(key), "support": bool(assembly.graph.node_attribute(key, "is_support")),
                      "density": float(block.attributes.get("density", 1.0)),
                      "volume": float(block.volume()), "center": list(map(float, block.center()))})
    return {**spec, "path": path, "status": status, "statuses": statuses,
            "nodes": nodes, "interfaces": interfaces, "fv_weighted": fv_weighted, "num_vertices": nv,
            "time_detect": None if None in detect_times else min(detect_times),
            "time_solve": min(solve_times), "times_detect": detect_times, "times_solve": solve_times}


def _warm_up() -> None:
    """One small untimed detection and solve, so that the timed ones do not pay for lazy
    imports and first calls (ours run in a process that has done the same)."""
    _, assembly = _load({"file": "A.json", "supports": [0, 1]})
    _detect(assembly, {"amin": 1e-2, "tmax": 1e-2})
    _solve(assembly, 0.84)


def versions() -> dict:
    out = {"python": platform.python_version()}
    for name in ("compas", "compas_assembly", "compas_cra", "numpy", "scipy", "shapely"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    try:
        from compas_cra._native import IPOPT_VERSION
        out["ipopt"] = str(IPOPT_VERSION)
    except ImportError:
        pass
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spec", required=True, help="JSON file with the samples and their settings")
    parser.add_argument("--out", required=True, help="JSON file to write")
    args = parser.parse_args(argv)
    with open(args.spec) as f:
        spec = json.load(f)
    _warm_up()
    samples = {}
    for sample in spec["samples"]:
        print(f"[compas_cra] {sample['name']} ...", file=sys.stderr, flush=True)
        samples[sample["name"]] = run_sample(sample, int(spec.get("repeat", 1)))
    with open(args.out, "w") as f:
        json.dump({"versions": versions(), "samples": samples}, f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
