"""The LMGC90 section of docs/BENCHMARKS.md and docs/lmgc90_verdicts.json from bench.py's results:
which method agrees with the non-smooth contact dynamics reference on which near-limit case."""
from __future__ import annotations

import json
import statistics
import sys

from bench import DEFAULT, SQUEEZE, method_label

#: Columns of the agreement table, in order (those present in the results).
COLUMNS = (DEFAULT, "lmgc90", "pybullet-240", "pybullet-1k", "mujoco-1k")
#: LMGC90's words on a sample that decide it (else "failed" or "not comparable").
DECIDED = ("stands", "falls")


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
    info, rechecked = result.get("lmgc90"), result.get("ours_rechecked")
    L = [] if not info or not info.get("merged") else [
        f"The LMGC90 column comes from `make bench-lmgc90` ({info['date']}, load average"
        f" {info['load_average_1min'][0]:.2f}), merged into this run's results; its time ratios"
        " are against ours re-timed in that run.", ""]
    if rechecked:
        scope = rechecked.get("scope") or (
            "every configuration's, tilt capacities included, and those on compas_cra's"
            " samples, the squeeze suite and its variants")
        L += [f"**rbe_ros's verdicts** ({scope}) are this"
              f" tree's: re-checked by `make bench-verdicts` (`benchmarks/bench.py --only ours`)"
              f" at commit {rechecked['commit']}, {rechecked['date']} (load average"
              f" {rechecked['load_average_1min'][0]:.1f} at the start). Every other method's"
              " answer and every time (ours included) are the runs' named above, made on the"
              " code of their day: read the verdicts as today's, the times as then. Verdicts"
              " of ours that changed from the stored run: "
              + ("; ".join(rechecked["changed"]) or "none") + ".", ""]
    return L


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
    decided = {k: r for k, r in samples.items() if r.get("lmgc90") in DECIDED}
    differ = [f"{k} (LMGC90 {r['lmgc90']}, ours {r['rbe_ros']})" for k, r in decided.items()
              if (r["lmgc90"] == "stands") != r["rbe_ros_stable"]]
    if samples:
        line += (f". On compas_cra's samples ours differs from LMGC90 on {len(differ)} of the"
                 f" {len(decided)} it decides" + (": " + ", ".join(differ) if differ else ""))
        undecided = sorted(set(samples) - set(decided))
        if undecided:
            line += f" (not comparable: {', '.join(undecided)})"
    rows = result["lmgc90"].get("squeeze") or []
    if rows:
        unsafe, alarms, decided_rows = _squeeze_misses(rows)
        line += (f". On the squeeze suite ours is unsafe (STABLE where LMGC90's blocks fall) on"
                 f" {len(unsafe)} and a false alarm on {len(alarms)} of the {len(decided_rows)}"
                 f" scenes LMGC90 decides")
    return [line + "."]


def _squeeze_misses(rows: list[dict]) -> tuple[list[str], list[str], list[dict]]:
    """(unsafe STABLE, false alarms, decided rows) of ours against LMGC90 on the suite: a
    scene whose verdict changes with LMGC90's numerics (``decides`` false,
    benchmarks/lmgc90_sensitivity.py) is not decided."""
    decided = [r for r in rows if r["lmgc90"] in DECIDED and r.get("decides", True)]
    unsafe = [r["name"] for r in decided if r["rbe_ros_stable"] and r["lmgc90"] == "falls"]
    alarms = [r["name"] for r in decided if not r["rbe_ros_stable"] and r["lmgc90"] == "stands"]
    return unsafe, alarms, decided


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
          "- LMGC90 reaches one solution of a contact problem that may have several (rigid"
          " frictional contact is not unique: a block between two faces can slide, or be squeezed"
          " by any normal force), and which one hangs on how its solver iterates: where its"
          " verdict changes with the NLGS relaxation the scene is not decided"
          " (benchmarks/lmgc90_sensitivity.py; the squeeze sections below).",
          "- The dome's tilted cases are not run (as for the physics engines: 140 blocks, a"
          " simulation per case).", ""]
    L += _samples(info)
    L += _squeeze(info)
    L += _variants()
    return L


def _variants() -> list[str]:
    """The squeeze variants' table (scripts/squeeze_variants.py --table, LMGC90's committed
    verdicts beside them, ours checked by this tree while the page is written)."""
    folder = SQUEEZE / "variants"
    if not (folder / "lmgc90_verdicts.json").exists():
        return []
    sys.path.insert(0, str(SQUEEZE.parents[2] / "scripts"))
    import squeeze_variants
    table = squeeze_variants.table(folder)
    stored = json.loads((folder / "lmgc90_verdicts.json").read_text())
    scenes = stored["scenes"]
    decided = [k for k, r in scenes.items() if r["lmgc90"] in DECIDED]
    same = sum(scenes[k].get("lmgc90_2T") == scenes[k]["lmgc90"] for k in decided)
    off = [k for k in decided if scenes[k].get("closed_form") not in (None, scenes[k]["lmgc90"])]
    cells = [[c.strip() for c in row.strip("|").split("|")] for row in table[2:]]
    wrong = [(c[0], c[6].split()[-1]) for c in cells if c[6].startswith("✗")]
    unsafe = [name for name, status in wrong if status == "STABLE"]
    alarms = [name for name, status in wrong if status != "STABLE"]
    return ["### The squeeze variants", "",
            f"{len(scenes)} scenes made apart from the suite's generator the way a held-out suite"
            " would differ (tests/data/squeeze/variants/, written by scripts/squeeze_variants.py:"
            " other proportions, 0.4 m deep, mu near each limit, copies turned 90 deg about the"
            " vertical, compas_cra's type-b turned 90 deg about y at 0.5-0.84, the suite's shelf"
            " and inclines at other mu). LMGC90 as above (`python scripts/squeeze_variants.py"
            f" --lmgc90`, {stored['date']}, compas_lmgc90"
            f" {stored['versions'].get('compas_lmgc90', '?')}; lmgc90_verdicts.json beside them):"
            f" it decides {len(decided)} of {len(scenes)}, the same at 1 s and 2 s on {same}, and"
            f" differs from the closed form on {len(off)} ({', '.join(off) or 'none'}): where its"
            " blocks jam (a block under a fixed bar parallel to its incline from about 0.93 tan"
            " theta, the shelf beyond its tipping limit from mu 13; docs/METHOD.md's limits)."
            " rbe_ros (this tree, checked while this page was written,"
            " `scripts/squeeze_variants.py --table tests/data/squeeze/variants`):"
            f" {len(unsafe)} unsafe STABLE{' (' + ', '.join(unsafe) + ')' if unsafe else ''},"
            f" {len(alarms)} false alarms ({', '.join(alarms) or 'none'})."
            " tests/test_squeeze_suite.py holds rbe_ros to these.", "", *table, ""]


def _convexified(cases: list[dict]) -> str:
    """Which cases needed slabs or hulls (see rbe_ros.io.lmgc90.bodies), in words."""
    changed = [c["name"] for c in cases
               if c["results"]["lmgc90"].get("slabs") or c["results"]["lmgc90"].get("hulls")]
    return ("every block of this suite is convex" if not changed else
            "made convex in: " + ", ".join(changed))


def _samples(info: dict) -> list[str]:
    samples = info.get("samples") or {}
    if not samples:
        return ["compas_cra's samples: not run (no .venv-compas).", ""]
    L = ["### compas_cra's samples", "",
         "Supports, mu and relative densities as compas_cra's example scripts set them (type-a..d"
         " have none: the two side blocks are the supports, mu as A and H), density"
         f" {_density(samples)} kg/m^3; verdicts also in `docs/lmgc90_verdicts.json` for tests to"
         " cite (tests/test_lmgc90_reference.py). A sample whose free blocks are not convex is"
         " not comparable: compas_lmgc90 takes one convex polyhedron per body (no clusters of"
         " them; a non-convex one stops it in POLYR::read_bodies, \"impossible to create the HE"
         " structure\"), so such a block goes in as its convex hull, which overlaps its"
         " neighbours where the blocks interlock.", "",
         "`rot90 y` (x, xy30): the sample turned 90 deg about the y axis (x, [sqrt 3, 1, 0])"
         " through the origin after its interfaces are found, as compas_cra's"
         " examples/05_wedge.py turns type-a..d.", "",
         "| sample | blocks | supports | mu | LMGC90 | largest motion (x size, deg) | rbe_ros (default) |",
         "|---|---|---|---|---|---|---|"]
    for name, r in samples.items():
        if "error" in r and "lmgc90" not in r:
            L.append(f"| {name} | - | - | - | {r['error']} | - | - |")
            continue
        motion = (f"{r['max_disp']:.1e}, {r['max_rot_deg']:.2g}" if r.get("max_disp") is not None
                  else r.get("error", "-"))
        notes = [f"{k}: {v} slabs" for k, v in (r.get("slabs") or {}).items()]
        if r.get("on_hulls"):
            notes.append(f"free blocks {', '.join(r['hulls'])} not convex; on their convex hulls,"
                         f" which overlap the neighbours, it {r['on_hulls']} within"
                         f" {r['simulated']:g} s")
        heavier = {}
        for k, v in (r.get("densities") or {}).items():
            heavier.setdefault(v, []).append(k)
        notes += [f"{v:g} kg/m^3 on {', '.join(ks)}" for v, ks in heavier.items()]
        L.append(f"| {name} | {r['blocks']} | {r['supports']} | {r['mu']} | {r['lmgc90']}"
                 f"{' (' + '; '.join(notes) + ')' if notes else ''} | {motion} | {r['rbe_ros']} |")
    L.append("")
    return L


def _density(samples: dict) -> str:
    """The samples' base density in words (the one they share, else each)."""
    found = {r["density"] for r in samples.values() if r.get("density")}
    return ", ".join(f"{d:g}" for d in sorted(found)) or "?"


def _verdict_file(info: dict, key: str, rows: dict, fields: tuple[str, ...]) -> dict:
    """A committed verdict file: where it comes from, the run's settings, ``fields`` of each
    of ``rows`` under ``key``."""
    return {"source": "make bench-lmgc90 (benchmarks/bench.py --only lmgc90); docs/BENCHMARKS.md"
                      " section 4 says how a verdict is decided",
            "date": info["date"], "versions": info["versions"], "settings": info["settings"],
            key: {name: {k: r.get(k) for k in fields} for name, r in rows.items()}}


def verdicts(result: dict) -> dict | None:
    """docs/lmgc90_verdicts.json: LMGC90's verdict per compas_cra sample, with its set-up
    (``rbe_ros``: ours, from the run that last checked them)."""
    info = result.get("lmgc90")
    if not info or not info.get("samples"):
        return None
    rechecked = result.get("ours_rechecked")
    return _verdict_file(info, "samples", info["samples"], (
        "file", "supports", "mu", "density", "densities", "rotation", "lmgc90", "stable",
        "max_disp", "max_rot_deg", "simulated", "slabs", "hulls", "on_hulls", "rbe_ros")) | (
            {"rbe_ros_checked": {k: rechecked[k] for k in ("date", "commit")}} if rechecked
            else {})


def _squeeze(info: dict) -> list[str]:
    """The squeeze suite's table: closed form, LMGC90 and ours on every scene, times."""
    rows = info.get("squeeze") or []
    if not rows:
        return []
    unsafe, alarms, decided = _squeeze_misses(rows)
    closed = [r for r in decided if r["closed_form"]]
    off = [r["name"] for r in closed if r["closed_form"] != r["lmgc90"]]
    ratios = [r["time_process"] / r["time_ours"] for r in decided if r.get("time_ours")]
    twice = [r for r in decided if r.get("lmgc90_2T") in DECIDED]
    same = sum(r["lmgc90_2T"] == r["lmgc90"] for r in twice)
    L = ["### The squeeze suite", "",
         f"{len(rows)} scenes where friction could hold blocks only if they were squeezed"
         " (pre-loaded), which blocks set one at a time never are, and their controls, each at"
         " mu on both sides of its limit (issue 29; tests/data/squeeze/, written by"
         " scripts/squeeze_suite.py, each scene's closed form and why in its manifest.json;"
         " LMGC90's verdicts in tests/data/squeeze/lmgc90_verdicts.json, which"
         " tests/test_squeeze_suite.py holds rbe_ros to). LMGC90 decides (the same verdict"
         " under every setting of benchmarks/lmgc90_sensitivity.py)"
         f" {len(decided)} of {len(rows)}; it differs from the closed form on {len(off)} of"
         f" {len(closed)}{': ' + ', '.join(off) if off else ''}. rbe_ros (this run's default"
         f" check): {len(unsafe)} unsafe STABLE{' (' + ', '.join(unsafe) + ')' if unsafe else ''},"
         f" {len(alarms)} false alarms{' (' + ', '.join(alarms) + ')' if alarms else ''}."
         + (f" Simulated twice as long ({2 * info['settings']['T']:g} s), LMGC90 gives the same"
            f" verdict on {same} of {len(twice)}: the verdicts do not hang on the duration."
            if twice else "")
         + (f" Time: LMGC90 (its whole process) over ours, median"
            f" {statistics.median(ratios):.0f}x." if ratios else ""), "",
         "| scene | mu | closed form | LMGC90 | largest motion (x size, deg) | moved | rbe_ros |"
         " LMGC90 s | rbe_ros ms |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        motion = (f"{r['max_disp']:.1e}, {r['max_rot_deg']:.2g}" if r.get("max_disp") is not None
                  else r.get("error") or "-")
        mark = "" if r["lmgc90"] not in DECIDED or not r.get("decides", True) else (
            "✓ " if r["rbe_ros_stable"] == (r["lmgc90"] == "stands") else "✗ ")
        L.append(f"| {r['name']} | {r['mu']:g} | {r['closed_form'] or '-'} | {r['lmgc90']} |"
                 f" {motion} | {', '.join(r.get('moved') or []) or '-'} | {mark}{r['rbe_ros']} |"
                 f" {r['time_process']:.2f} | {1e3 * r['time_ours']:.1f} |")
    L.append("")
    return L


def squeeze_verdicts(result: dict) -> dict | None:
    """tests/data/squeeze/lmgc90_verdicts.json: LMGC90's verdict per squeeze scene."""
    info = result.get("lmgc90")
    if not info or not info.get("squeeze"):
        return None
    return _verdict_file(info, "scenes", {r["name"]: r for r in info["squeeze"]}, (
        "mu", "closed_form", "lmgc90", "stable", "moved", "max_disp", "max_rot_deg",
        "simulated", "time_process", "lmgc90_2T", "sensitivity", "decides"))


def squeeze_target(out):
    """Where the squeeze verdicts go: beside the suite for a run that writes docs/, else
    into that run's own folder."""
    if out.resolve() == (SQUEEZE.parents[2] / "docs").resolve():
        return SQUEEZE / "lmgc90_verdicts.json"
    return out / "squeeze_lmgc90_verdicts.json"
