"""The LMGC90 section of docs/BENCHMARKS.md and docs/lmgc90_verdicts.json from bench.py's results:
which method agrees with the non-smooth contact dynamics reference on which near-limit case."""
from __future__ import annotations

import statistics

from bench import DEFAULT, method_label

#: Columns of the agreement table, in order (those present in the results).
COLUMNS = (DEFAULT, "lmgc90", "pybullet-240", "pybullet-1k", "mujoco-1k")


def _answer(case: dict, m: str) -> str | None:
    """A method's answer on a case as a word (stands / falls / failed) or, on a tilt case it
    was bisected on, its capacity in degrees; None where it did not run or was timed only."""
    r = case["results"].get(m)
    if r is None or r.get("stable") is None and not r.get("failed"):
        return None
    if case["kind"] == "tilt" and "capacity" in r:
        return f"{r['capacity']:.2f} deg"
    if r.get("failed"):
        return "failed"
    return "stands" if r["stable"] else "falls"


def _agree(case: dict, a: str, b: str) -> bool | None:
    """Whether methods a and b agree on a case: the same verdict, or on a tilt case both
    capacities within 0.05 deg of the exact one or both not (None: not comparable)."""
    ra, rb = case["results"].get(a, {}), case["results"].get(b, {})
    if case["kind"] == "tilt":
        if "correct" in ra and "correct" in rb and "capacity" in ra and "capacity" in rb:
            return ra["correct"] == rb["correct"]
        return None
    if "correct" not in ra or "correct" not in rb:
        return None
    return ra["stable"] == rb["stable"] and not ra.get("failed") and not rb.get("failed")


def _counts(cases: list[dict], m: str, ref: str | None) -> tuple[int, int]:
    """(agreeing, compared) of method m with method ref, or with the exact answer (ref None)."""
    got = [(c["results"][m].get("correct") if ref is None else _agree(c, m, ref))
           for c in cases if m in c["results"] and "correct" in c["results"][m]]
    got = [g for g in got if g is not None]
    return sum(bool(g) for g in got), len(got)


def _time_ratios(cases: list[dict], key: str = "time") -> list[float]:
    """LMGC90's time (``key``) over ours on each case, both measured in the same run."""
    return [c["results"]["lmgc90"][key] / c["results"]["lmgc90"]["time_ours"] for c in cases
            if c["results"]["lmgc90"].get(key) and c["results"]["lmgc90"].get("time_ours")]


def merged_note(result: dict) -> list[str]:
    """Where the LMGC90 column comes from a run of its own (make bench-lmgc90)."""
    info = result.get("lmgc90")
    if not info or not info.get("merged"):
        return []
    return [f"The LMGC90 column comes from `make bench-lmgc90` ({info['date']}, load average"
            f" {info['load_average_1min'][0]:.2f}), merged into this run's results; its time ratios"
            " are against ours re-timed in that run.", ""]


def summary(result: dict) -> list[str]:
    """The done-when line: agreement with LMGC90, the time ratio, the samples' verdicts."""
    cases = [c for c in result["cases"] if "lmgc90" in c["results"]]
    if not result.get("lmgc90") or not cases:
        return ["- LMGC90: not run (`make bench-lmgc90`)."]
    agree, n = _counts(cases, DEFAULT, "lmgc90")
    right, scored = _counts(cases, "lmgc90", None)
    ratios = _time_ratios(cases)
    line = (f"- **Against LMGC90 (section 4)**: ours agrees with LMGC90 on {agree} of {n} near-limit"
            f" cases; LMGC90 is right on {right} of {scored}")
    if ratios:
        line += f"; LMGC90 takes a median {statistics.median(ratios):.0f}x ours' time"
    samples = result["lmgc90"].get("samples") or {}
    differ = [f"{k} (LMGC90 {r['lmgc90']}, ours {r['rbe_ros']})" for k, r in samples.items()
              if "lmgc90" in r and (r["lmgc90"] == "stands") != r["rbe_ros_stable"]]
    if samples:
        line += (f". On compas_cra's samples ours differs from LMGC90 on {len(differ)} of"
                 f" {len(samples)}" + (": " + ", ".join(differ) if differ else ""))
    return [line + "."]


def section(result: dict) -> list[str]:
    info = result.get("lmgc90")
    cases = [c for c in result["cases"] if "lmgc90" in c["results"]]
    if not info or not cases:
        return []
    s = info["settings"]
    cols = [m for m in COLUMNS if any(m in c["results"] for c in cases)]
    L = ["## 4. LMGC90 as the accuracy reference", "",
         f"LMGC90 (compas_lmgc90 {info['versions'].get('compas_lmgc90', '?')}; non-smooth contact"
         " dynamics: rigid blocks, unilateral contacts, Coulomb friction, no compliance) on every"
         f" near-limit case the physics engines run, measured {info['date']} (load average"
         f" {info['load_average_1min'][0]:.2f} at the start, {info['load_average_1min'][1]:.2f} at the"
         f" end; {info['runtime_s'] / 60:.1f} minutes). Verdict: simulate {s['T']:g} s from rest, time"
         f" step {1e3 * s['dt']:g} ms (theta {s['theta']:g}), law {s['law']} (inelastic quasi-shock,"
         f" Coulomb mu); falls when a free block's centre of inertia moves more than {s['disp_tol']:g}"
         f" x its size or it turns more than {s['rot_tol_deg']:g} deg (tested every"
         f" {1e3 * s['check_every']:g} ms, stopping at the first fall). The thresholds sit between what"
         " LMGC90 does on this suite: standing cases move at most 3.4e-3 x size and 0.02 deg within"
         " 1 s (the tower of 40 boxes, whose contact solution jitters), falling ones at least 2.5e-2"
         " x size (sliding on the inclined interface) or 5 deg (tipping) by then; the physics"
         " engines' thresholds (0.1 x size, 5 deg) are 10 and 5 times coarser. Tilt capacities of the"
         f" single-block families by bisection on this verdict, simulating {s['T_tilt']:g} s per trial"
         " (creep beyond a sliding limit grows as t^2: 1 s would resolve a sliding capacity to only"
         " about 0.08 deg).", "",
         "| case | exact | " + " | ".join(method_label(m) for m in cols) + " |",
         "|---|---|" + "---|" * len(cols)]
    for c in cases:
        exact = (f"{c['exact']:.2f} deg" if c["kind"] == "tilt" else ("stands" if c["exact"] else "falls"))
        cells = []
        for m in cols:
            word = _answer(c, m)
            r = c["results"].get(m, {})
            mark = "" if "correct" not in r else ("✓ " if r["correct"] else "✗ ")
            cells.append("-" if word is None else mark + word)
        L.append(f"| {c['name']} | {exact} | " + " | ".join(cells) + " |")
    L += ["", "Agreement (cases compared: both gave a verdict, or on tilt cases both were bisected;"
          " a tilt capacity counts as right within 0.05 deg):", "",
          "| method | right (against the exact answer) | agrees with LMGC90 |", "|---|---|---|"]
    for m in cols:
        right, n = _counts(cases, m, None)
        agree = "-" if m == "lmgc90" else "{} of {}".format(*_counts(cases, m, "lmgc90"))
        L.append(f"| {method_label(m)} | {right} of {n} | {agree} |")
    ratios = _time_ratios(cases)
    if ratios:
        L += ["", f"Time: LMGC90's check (set-up and simulation, in its process; Python start-up"
              f" excluded) over ours (full check) on the same case in the same run:"
              f" median {statistics.median(ratios):.0f}x, from {min(ratios):.1f}x to {max(ratios):.0f}x"
              f" over {len(ratios)} cases. LMGC90 stops at the first fall, so on falling cases it is"
              " quicker than on standing ones."]
        whole = _time_ratios(cases, "time_process")
        if whole:
            L[-1] += (" With its process (Python start-up, imports, the request), as this benchmark runs"
                      f" it: median {statistics.median(whole):.0f}x.")
    L += ["", "Not comparable, or compared with care:",
          "- LMGC90 decides by motion within a finite time, as the physics engines do: a case far"
          " closer to its limit than 1% would creep below the threshold and read as standing. Its"
          " tilt capacities are scored like everyone's (within 0.05 deg); the towers' tilt cases are"
          " not bisected (a simulation per trial on up to 41 blocks), only their upright verdict is"
          " shown, and they are left out of the counts.",
          f"- Blocks go in as convex hulls of their vertices ({_convexified(cases)}). A"
          " non-convex support is replaced by convex slabs under the contact polygons our detection"
          f" finds on it ({s['slab_depth']:g} x the smaller block's size deep): LMGC90 then sees the"
          " same contact faces but not the support's other faces; a non-convex free block would go in"
          " as its hull (not comparable; listed in results.json under `hulls`).",
          "- LMGC90 knows gravity along -z only: a tilted case is the whole scene turned the other way"
          " (as for compas_cra).",
          "- The dome's tilted cases are not run (as for the physics engines: 140 blocks, a"
          " simulation per case).", ""]
    L += _samples(info)
    return L


def _convexified(cases: list[dict]) -> str:
    """Which cases needed slabs or hulls (see _lmgc90.bodies), in words."""
    changed = [c["name"] for c in cases
               if c["results"]["lmgc90"].get("slabs") or c["results"]["lmgc90"].get("hulls")]
    return ("every block of this suite is convex" if not changed else
            "made convex in: " + ", ".join(changed))


def _samples(info: dict) -> list[str]:
    samples = info.get("samples") or {}
    if not samples:
        return ["compas_cra's samples: not run (no .venv-compas).", ""]
    L = ["### compas_cra's samples", "",
         "Supports and mu as compas_cra's example scripts set them (type-a..d have none: the two"
         " side blocks are the supports, mu as A and H), uniform density; verdicts also in"
         " `docs/lmgc90_verdicts.json` for tests to cite:", "",
         "| sample | blocks | supports | mu | LMGC90 | largest motion (x size, deg) | rbe_ros (default) |",
         "|---|---|---|---|---|---|---|"]
    for name, r in samples.items():
        if "error" in r and "lmgc90" not in r:
            L.append(f"| {name} | - | - | - | {r['error']} | - | - |")
            continue
        motion = (f"{r['max_disp']:.1e}, {r['max_rot_deg']:.2g}" if r.get("max_disp") is not None
                  else r.get("error", "-"))
        slabs = ", ".join(f"{k}: {v} slabs" for k, v in (r.get("slabs") or {}).items())
        L.append(f"| {name} | {r['blocks']} | {r['supports']} | {r['mu']} | {r['lmgc90']}"
                 f"{' (' + slabs + ')' if slabs else ''} | {motion} | {r['rbe_ros']} |")
    L.append("")
    return L


def verdicts(result: dict) -> dict | None:
    """docs/lmgc90_verdicts.json: LMGC90's verdict per compas_cra sample, with its set-up."""
    info = result.get("lmgc90")
    if not info or not info.get("samples"):
        return None
    return {"source": "make bench-lmgc90 (benchmarks/bench.py --only lmgc90); docs/BENCHMARKS.md"
                      " section 4 says how a verdict is decided",
            "date": info["date"], "versions": info["versions"], "settings": info["settings"],
            "samples": {name: {k: r.get(k) for k in ("file", "supports", "mu", "lmgc90", "stable",
                                                       "max_disp", "max_rot_deg", "simulated",
                                                       "slabs", "hulls", "rbe_ros")}
                        for name, r in info["samples"].items()}}
