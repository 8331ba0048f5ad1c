"""The harness of the benchmarks that run checkouts of rbe_ros against each other in one
run (rule4_cost.py, placement_window.py): each measurement a process of its own with its
tree's package first on the path, the trees alternating, so that the load of a shared
machine falls on all of them alike."""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

from machine import machine_summary

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
PYTHON = ROOT / ".venv" / "bin" / "python"
#: The 14 x 10 dome's plan that ``make bench-repair`` keeps (benchmarks/repair.py).
PLAN = ROOT / "build" / "repair" / "dome14x10.pkl"
#: The start of a snippet run in a tree: the tree's rbe_ros, then this folder's repair.py
#: (``half_built``), the plan loaded; the snippet's arguments from sys.argv[3].
PROLOGUE = """
import json, os, pickle, sys, time
import rbe_ros
sys.path.insert(0, sys.argv[1])
from repair import half_built     # after rbe_ros: it puts its own tree first
assert rbe_ros.__file__.startswith(os.getcwd()), rbe_ros.__file__
plan, _ = pickle.load(open(sys.argv[2], "rb"))
"""


def in_tree(tree: Path, snippet: str, *args, plan: Path = PLAN) -> dict:
    """The JSON line that ``snippet`` (after PROLOGUE, ``plan`` loaded) prints last, run by
    ``tree``."""
    out = subprocess.run([str(PYTHON), "-c", PROLOGUE + snippet, str(HERE), str(plan),
                          *map(str, args)], capture_output=True, text=True, cwd=tree,
                         env=os.environ | {"PYTHONPATH": str(tree)}, check=True)
    return json.loads(out.stdout.splitlines()[-1])


def arguments(doc: str) -> argparse.ArgumentParser:
    """The command line's parser: the trees and the repeats (best of), more to add."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("trees", nargs="+", type=Path, help="checkouts of rbe_ros")
    parser.add_argument("--repeats", type=int, default=1)
    return parser


def started(args) -> list[Path] | None:
    """The trees of ``args``, the machine printed; None (why on stderr) without the plan."""
    if not PLAN.exists():
        print(f"no plan at {PLAN}: run make bench-repair first", file=sys.stderr)
        return None
    print(machine_summary(), flush=True)
    return [t.resolve() for t in args.trees]
