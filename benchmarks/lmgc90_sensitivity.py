"""Does LMGC90 decide a squeeze scene? Its verdict under varied numerics (issue 29).

Each scene is run from rest with LMGC90's settings varied one at a time from those of
``make bench-lmgc90`` (rbe_ros/io/lmgc90.py: dt 1 ms, 1 s, the contact solver NLGS as
compas_lmgc90 0.1.11 builds it: tolerance 1.666e-4 (QM/16), relaxation 0.1, at most 500 x 50
iterations; contact detection distance 1 mm): the time step halved and doubled, 5 s, the
tolerance 100x tighter (with 10x the iterations), the relaxation 0.2, 0.5 and 1 (plain
Gauss-Seidel), the detection distance 10x smaller and larger, the theta scheme at 1
(implicit Euler). Each run records every free block's displacement / size every 50 ms
(rbe_ros/io/lmgc90_driver.py's ``trace``).

LMGC90 decides a scene when every setting gives the same verdict and no standing run creeps
(its largest displacement at the end of the 5 s run below the 1% threshold and grown by less
than 1e-4 x size over its last half). Relaxation and tolerance do not change the problem a
step solves, only how NLGS iterates to a solution: a verdict that flips with them is a
contact problem with more than one solution (rigid frictional contact is not unique: a
block between two faces can slide or be squeezed), of which NLGS's path picks one.

    nice -n 10 python benchmarks/lmgc90_sensitivity.py [--scenes NAME ... | all]
        [--settings NAME ...] [--write]
    python benchmarks/lmgc90_sensitivity.py --table      # docs/BENCHMARKS.md's table

``--write`` adds each scene's ``sensitivity`` (verdict per setting) and ``decides`` to the
committed tests/data/squeeze[/variants]/lmgc90_verdicts.json; the traces go to
docs/bench/lmgc90_sensitivity.json.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from rbe_ros.io import lmgc90  # noqa: E402
from rbe_ros.io.scene_json import load_scene  # noqa: E402
from rbe_ros.scene import gravity_down  # noqa: E402

SUITES = (ROOT / "tests" / "data" / "squeeze", ROOT / "tests" / "data" / "squeeze" / "variants")
TRACES = ROOT / "docs" / "bench" / "lmgc90_sensitivity.json"
#: name: (simulated s, request overrides); "base" is make bench-lmgc90's verdict
SETTINGS = {
    "base": (1.0, {}),
    "dt/2": (1.0, {"dt": lmgc90.DT / 2}),
    "2dt": (1.0, {"dt": lmgc90.DT * 2}),
    "5s": (5.0, {}),
    "tol/100": (1.0, {"nlgs": {"tol": 1.666e-6, "gs_it2": 5000}}),
    "relax0.2": (1.0, {"nlgs": {"relax": 0.2}}),
    "relax0.5": (1.0, {"nlgs": {"relax": 0.5}}),
    "relax1": (1.0, {"nlgs": {"relax": 1.0}}),
    "alert/10": (1.0, {"alert": 1e-4}),
    "alertx10": (1.0, {"alert": 1e-2}),
    "theta1": (1.0, {"theta": 1.0}),
}
#: the disagreements of issue 29's suites and their nearest controls
SCENES = (
    "leaning_posts15_mu1.20", "leaning_posts15_mu5.00", "v_leaning_posts15_mu3.00",
    "v_leaning_posts15_mu4.00", "v_leaning20_mu1.30", "v_leaning20_mu1.60",
    "v_leaning20_mu3.00",
    "incline_pressed30_mu0.50", "incline_pressed30_mu0.70", "v_incline_pressed30_mu0.53",
    "v_incline_pressed30_mu0.55", "v_incline_pressed30_mu0.57", "v_incline_pressed30_mu0.62",
    "v_incline_pressed25_mu0.44", "v_incline_pressed25_mu0.50",
    "v_incline_pressed30_suite_mu0.55", "v_incline_pressed40_suite_mu0.78",
    "v_incline_pressed40_suite_mu0.81", "incline_pressed40_mu1.00",
    "v_incline_pressed50_suite_mu1.04", "v_incline_pressed60_suite_mu1.25",
    "v_incline_pressed60_suite_mu1.35", "v_incline30_mu0.55", "v_incline_freebar30_mu0.62",
    "v_shelf60_suite_mu10.00", "v_shelf60_suite_mu13.00", "shelf45_mu0.60",
    "v_type_b_roty+90_mu0.60", "wedged_arch30_mu0.20", "v_wedged_arch20_mu0.60",
)
CREEP = 1e-4                # x size over the last half of the long run


def _where(name: str) -> Path:
    return SUITES[1] if name.startswith("v_") else SUITES[0]


def _word(res: dict) -> str:
    return "failed" if res.get("failed") else ("stands" if res["stable"] else "falls")


def run(name: str, setting: str, python) -> dict:
    """One run of ``name`` (at its manifest's mu) under ``setting``, with its trace."""
    folder = _where(name)
    entry = next(e for e in json.loads((folder / "manifest.json").read_text())["scenes"]
                 if e["name"] == name)
    T, numerics = SETTINGS[setting]
    scene = gravity_down(load_scene(folder / entry["file"]))
    res = lmgc90.check(scene, entry["mu"], python, T=T, numerics=numerics | {"trace": True})
    out = {"verdict": _word(res), "time_process": res["time_process"]}
    if not res.get("failed"):
        trace = res["trace"]
        half = trace[len(trace) // 2 - 1][1] if len(trace) > 1 else trace[-1][1]
        out |= {"moved": res["moved"], "at": res["simulated"], "final": trace[-1][0],
                "disp_end": max(d for d, _ in trace[-1][1].values()),
                "growth_last_half": max(trace[-1][1][b][0] - half[b][0] for b in half),
                "trace": [[t, {b: round(d, 9) for b, (d, _) in v.items()}]
                          for t, v in trace]}
    else:
        out["error"] = res["error"]
    return out


def decides(runs: dict) -> bool:
    """Every setting the same verdict, and the long run, if standing, does not creep."""
    verdicts = {r["verdict"] for r in runs.values()}
    if len(verdicts) != 1 or verdicts == {"failed"}:
        return False
    long = runs.get("5s")
    return not (long and long["verdict"] == "stands" and long["growth_last_half"] > CREEP)


def table() -> list[str]:
    """docs/BENCHMARKS.md's table: the verdict per setting of every scene run under more
    than the five settings of the whole sweep, or whose verdict changes, from the
    committed traces."""
    data = json.loads(TRACES.read_text())["scenes"]
    names = list(data)
    lines = ["| scene | mu | " + " | ".join(SETTINGS) + " | decides | largest motion at"
             " the end of 5 s (x size) |", "|---|---|" + "---|" * (len(SETTINGS) + 2)]
    for n in names:
        runs = data[n]["runs"]
        if len(runs) <= 5 and data[n]["decides"]:
            continue
        mu = n.rsplit("_mu", 1)[1]
        cells = [{"stands": "S", "falls": "F"}.get(runs[s]["verdict"], "?") if s in runs
                 else "" for s in SETTINGS]
        long = runs.get("5s")
        end = f"{long['disp_end']:.1e}" if long and "disp_end" in long else "-"
        lines.append(f"| {n} | {mu} | " + " | ".join(cells) +
                     f" | {'yes' if data[n]['decides'] else '**no**'} | {end} |")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="*", default=list(SCENES),
                        help="scene names, or all (both suites)")
    parser.add_argument("--settings", nargs="*", default=list(SETTINGS))
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--write", action="store_true",
                        help="write the verdict files and the traces")
    parser.add_argument("--table", action="store_true",
                        help="print docs/BENCHMARKS.md's table from the traces instead")
    args = parser.parse_args(argv)
    if args.table:
        print("\n".join(table()))
        return 0
    python = lmgc90.installed_python()
    if args.scenes == ["all"]:
        args.scenes = [e["name"] for folder in SUITES
                       for e in json.loads((folder / "manifest.json").read_text())["scenes"]]
    old = json.loads(TRACES.read_text()) if TRACES.exists() else {"scenes": {}}
    results = {n: dict(old["scenes"].get(n, {}).get("runs", {})) for n in args.scenes}
    jobs = [(n, s) for n in args.scenes for s in args.settings]

    def one(job):
        n, s = job
        r = run(n, s, python)
        print(f"[sensitivity] {n} {s}: {r['verdict']} (at {r.get('at')}, end"
              f" {r.get('disp_end', float('nan')):.1e}, last-half growth"
              f" {r.get('growth_last_half', float('nan')):.1e}, {r['time_process']:.1f} s)",
              flush=True)
        return job, r
    with ThreadPoolExecutor(args.jobs) as pool:
        for (n, s), r in pool.map(one, jobs):
            results[n][s] = r
    for n in args.scenes:
        row = " ".join(f"{s}={results[n][s]['verdict']}" for s in SETTINGS if s in results[n])
        print(f"{n}: decides={decides(results[n])} {row}")
    if not args.write:
        return 0
    TRACES.parent.mkdir(parents=True, exist_ok=True)
    old = json.loads(TRACES.read_text()) if TRACES.exists() else {"scenes": {}}
    for n in args.scenes:               # runs of other settings made meanwhile stay
        results[n] = old["scenes"].get(n, {}).get("runs", {}) | results[n]
    old["scenes"] |= {n: {"runs": results[n], "decides": decides(results[n])}
                      for n in args.scenes}
    old |= {"source": "benchmarks/lmgc90_sensitivity.py", "settings": {
        s: {"T": T} | numerics for s, (T, numerics) in SETTINGS.items()},
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    TRACES.write_text(json.dumps(old) + "\n")
    for folder in SUITES:
        path = folder / "lmgc90_verdicts.json"
        data = json.loads(path.read_text())
        for n, rec in old["scenes"].items():
            if n in data["scenes"]:
                data["scenes"][n]["sensitivity"] = {s: r["verdict"]
                                                    for s, r in rec["runs"].items()}
                data["scenes"][n]["decides"] = rec["decides"]
        data["decides"] = ("benchmarks/lmgc90_sensitivity.py: a scene with `decides` false"
                           " changes its verdict with LMGC90's numerics (or creeps); one"
                           " without `decides` was not run there")
        path.write_text(json.dumps(data, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
