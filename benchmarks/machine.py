"""The machine a benchmark ran on: CPU, cores, memory and the versions that matter."""
from __future__ import annotations

import os
import platform
from importlib import metadata

PACKAGES = ("numpy", "scipy", "clarabel", "cvxpy", "shapely", "trimesh")


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def machine_summary() -> str:
    versions = []
    for name in PACKAGES:
        try:
            versions.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            continue
    return (f"{cpu_model()}, {os.cpu_count()} cores, Python {platform.python_version()},"
            f" {', '.join(versions)}")
