"""Cost of the shape analysis of large convex meshes, and the time limit of a check:
docs/BOUNDED_CHECKS.md (``make bounded``, about a minute).

In one run: planes grouped through the k-d tree against the linear scan over the planes found
so far (the former method), extents on many axes by climbing the hull against the full
product, and whole checks of convex-domes scenes without and with a 0.5 s time limit.
"""
from __future__ import annotations

import math
import os
import platform
import time
from pathlib import Path

import numpy as np

from rbe_ros import generators as gen
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.geometry import block
from rbe_ros.geometry.support import projection_extents
from rbe_ros.rbe.solver import SolveOptions

OUT = Path(__file__).resolve().parents[1] / "docs" / "BOUNDED_CHECKS.md"


def cpu(fn):
    start = time.process_time()
    out = fn()
    return time.process_time() - start, out


def linear_scan(normals, offsets, plane_tol):
    """The former grouping: each face against every plane found so far."""
    planes = []
    for n, d in zip(normals, offsets):
        for gn, gd in planes:
            if gn @ n > math.cos(block.ANGLE_TOL) and abs(gd - d) <= plane_tol:
                break
        else:
            planes.append((n, d))
    return len(planes)


def face_planes(dome):
    """Unit normals and offsets of a dome's faces."""
    tri = dome.vertices[np.array(dome.faces)]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    return n, np.einsum("ij,ij->i", n, tri.mean(axis=1))


def main() -> None:
    rows = []
    small = gen.convex_domes(vertices=2000, rim=200).blocks[1]
    normals, offsets = face_planes(small)
    t_tree, (_, first) = cpu(lambda: block._group_planes(normals, offsets, block.PLANE_TOL))
    t_scan, count = cpu(lambda: linear_scan(normals, offsets, block.PLANE_TOL))
    assert count == len(first)
    rows.append(("group the 3,996 faces of a 2,000-vertex dome by plane", t_scan, t_tree))
    big = gen.convex_domes().blocks[1]
    normals, _ = face_planes(big)

    def product():
        projected = big.vertices @ normals.T
        return np.column_stack((projected.min(axis=0), projected.max(axis=0)))

    t_climb, climbed = cpu(lambda: projection_extents(big.vertices, normals))
    t_product, full = cpu(product)
    assert np.allclose(climbed, full, rtol=0, atol=1e-14)
    rows.append(("extents of a 10,000-vertex dome on its 19,996 face normals", t_product,
                 t_climb))

    checks = []
    for count, limit in ((1, math.inf), (12, math.inf), (12, 0.5)):
        scene = gen.convex_domes(count)
        block._shape.cache_clear()
        wall = time.perf_counter()
        spent, report = cpu(lambda: check_scene(
            scene, CheckOptions(solve=SolveOptions(time_limit=limit))))
        checks.append((count, limit, spent, time.perf_counter() - wall,
                       report.message.replace("|", r"\|")))   # a table cell

    lines = [
        "# Bounded checks: large meshes and the check time limit",
        "",
        "Made by `make bounded` (`benchmarks/bounded_checks.py`), CPU seconds of one process"
        f" on {platform.machine()} with {os.cpu_count()} cores (load average"
        f" {os.getloadavg()[0]:.1f} at the end: the machine is shared, wall times vary).",
        "",
        "| work | former method s | now s | ratio |",
        "|---|---:|---:|---:|",
        *(f"| {what} | {old:.3f} | {new:.3f} | {old / max(new, 1e-9):.0f} |"
          for what, old, new in rows),
        "",
        "Whole checks of `rbe-ros generate convex-domes` scenes (10,000-vertex convex domes on a"
        " ground slab; each dome a distinct mesh, the shape cache cleared first):",
        "",
        "| domes | time limit s | CPU s | wall s | message |",
        "|---:|---:|---:|---:|---|",
        *(f"| {count} | {'none' if math.isinf(limit) else limit} | {spent:.2f} | {wall:.2f} |"
          f" {message} |" for count, limit, spent, wall, message in checks),
        "",
    ]
    OUT.write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
