"""compas_cra's side of benchmarks/bench.py: a verdict server around ``rbe_solve``.

Runs inside the scratch venv with compas-cra (made by ``compas_compare.ensure_venv``; no
rbe_ros here) and reuses the loading, detection and solve of ``_compas_driver.py``:

    <venv>/bin/python benchmarks/_bench_cra_driver.py

It reads one JSON request per line on stdin: ``{"file": path, "supports": null | [keys],
"mu": 0.6, "nmax": 10, "amin": 1e-4, "tmax": 1e-3, "detect": true, "solve": true, "repeat": 1}`` and
answers one JSON line per request: ``{"status", "time_detect", "time_solve", "interfaces",
"vertices", "blocks", "free_blocks", "free_weight", "max_tension", "max_tension_rel"}``.
Tension is compas_cra's ``c_nn`` (the penalised fn-, friction+); ``max_tension_rel`` is its
largest vertex value over the free weight (volume x density, compas_cra's units, g = 1).
Times are the best of ``repeat`` runs of loading + detection + solve (only detection and
solve are timed). IPOPT's own chatter goes to stderr, so that stdout carries only answers.
"""
from __future__ import annotations

import json
import os
import sys
import traceback

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)


def _answer(request: dict) -> dict:
    from _compas_driver import _detect, _load, _solve
    from compas_cra.equilibrium import num_vertices

    spec = {"file": request["file"], "supports": request.get("supports"),
            "nmax": request.get("nmax", 10), "amin": request.get("amin", 1e-4),
            "tmax": request.get("tmax", 1e-3), "detect": request.get("detect", True)}
    best = None
    for _ in range(max(1, int(request.get("repeat", 1)))):
        _, assembly = _load(spec)
        detect = _detect(assembly, spec)
        n_if = sum(len(assembly.graph.edge_attribute(e, "interfaces") or [])
                   for e in assembly.graph.edges())
        if not request.get("solve", True):        # detection only
            if best is None or detect < best[0]:
                best = (detect, detect, None, "detected", assembly, n_if)
            continue
        try:
            solve, status = _solve(assembly, float(request.get("mu", 0.84)))
        except (ValueError, IndexError, KeyError) as exc:       # rbe_solve raises when IPOPT fails
            return {"status": f"failed: {exc}", "time_detect": detect, "interfaces": n_if}
        total = (detect or 0.0) + solve
        if best is None or total < best[0]:
            best = (total, detect, solve, status, assembly, n_if)
    _, detect, solve, status, assembly, n_if = best
    if solve is None:
        return {"status": status, "time_detect": detect, "interfaces": n_if}
    graph = assembly.graph
    free_weight = 0.0
    free = 0
    for node in graph.nodes():
        if graph.node_attribute(node, "is_support"):
            continue
        block = graph.node_attribute(node, "block")
        free += 1
        free_weight += float(block.volume()) * float(block.attributes.get("density", 1.0))
    tension = 0.0
    for edge in graph.edges():
        for it in graph.edge_attribute(edge, "interfaces") or []:
            for f in it.forces or []:
                tension = max(tension, float(f["c_nn"]))
    return {"status": status, "time_detect": detect, "time_solve": solve, "interfaces": n_if,
            "vertices": int(num_vertices(assembly)), "blocks": graph.number_of_nodes(),
            "free_blocks": free, "free_weight": free_weight, "max_tension": tension,
            "max_tension_rel": tension / free_weight if free_weight > 0 else 0.0}


def main() -> int:
    out = os.fdopen(os.dup(1), "w")           # answers go here ...
    os.dup2(2, 1)                             # ... and anything else printed to fd 1 to stderr
    sys.stdout = sys.stderr
    from importlib import metadata
    versions = {}
    for name in ("compas", "compas_assembly", "compas_cra", "numpy", "scipy", "shapely"):
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    try:
        import compas_cra
        versions["samples"] = compas_cra.SAMPLE
        from compas_cra._native import IPOPT_VERSION
        versions["ipopt"] = str(IPOPT_VERSION)
    except ImportError:
        pass
    out.write(json.dumps({"ready": True, "versions": versions}) + "\n")
    out.flush()
    for line in sys.stdin:
        if not line.strip():
            continue
        try:
            answer = _answer(json.loads(line))
        except Exception as exc:                  # report, keep serving
            traceback.print_exc()
            answer = {"status": f"error: {type(exc).__name__}: {exc}"}
        out.write(json.dumps(answer) + "\n")
        out.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
