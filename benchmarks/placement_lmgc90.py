"""LMGC90's verdicts on the placement test's scenes (tests/placement_scenes.py): each scene
at each mu simulated from rest (benchmarks/_lmgc90.py: 1 s, a block falls when it moves more
than 1% of its size), written to tests/data/placement/lmgc90.json, which
tests/test_prestress.py compares with our verdicts.

    nice -n 10 python benchmarks/placement_lmgc90.py
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent / "tests")]

import _lmgc90  # noqa: E402
import placement_scenes as scenes  # noqa: E402


OUT = HERE.parent / "tests" / "data" / "placement" / "lmgc90.json"


def main() -> int:
    python = _lmgc90.ensure_venv()
    out = {"settings": _lmgc90.settings(), "command": __doc__.strip().splitlines()[-1].strip(),
           "cases": []}
    for name, scene, mu in scenes.lmgc90_cases():
        answer = _lmgc90.check(scene, mu, python)
        record = {"name": name, "mu": mu, "stable": answer.get("stable"),
                  "failed": answer.get("failed"), "time_process": answer.get("time_process")}
        print(json.dumps(record), flush=True)
        out["cases"].append(record)
    OUT.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
