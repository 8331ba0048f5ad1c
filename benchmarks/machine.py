"""The machine a benchmark ran on: CPU, cores, the versions that matter, the commit measured
and the load when it is asked (the machine may be shared: a doc says how busy it was)."""
from __future__ import annotations

import os
import platform
import subprocess
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


def commit() -> str:
    """The commit of this tree (short), "+ local changes" when the tree differs from it."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    try:
        head = subprocess.run(["git", "-C", root, "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True, timeout=30).stdout.strip()
        dirty = subprocess.run(["git", "-C", root, "status", "--porcelain", "--untracked-files=no",
                                "--", "rbe_ros", "benchmarks"],
                               capture_output=True, text=True, timeout=30).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown commit"
    return (head or "unknown commit") + (" + local changes" if dirty else "")


def machine_summary() -> str:
    versions = []
    for name in PACKAGES:
        try:
            versions.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            continue
    return (f"{cpu_model()}, {os.cpu_count()} cores, Python {platform.python_version()},"
            f" {', '.join(versions)}; commit {commit()}; load average"
            f" {os.getloadavg()[0]:.1f} when this line was written")
